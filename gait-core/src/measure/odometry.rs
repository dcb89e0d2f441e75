//! Leg odometry: where each landing foot really stands, from forward kinematics of the servos'
//! Present Position, and the soles' places the measured ZMP uses.
//!
//! The measured ZMP ([`crate::measure::zmp`]) places each foot's load cells at a sole place. The
//! plan's places are where the feet should be; a position servo that yields under load lands the
//! swing foot elsewhere (every step a little long, more so the faster the gait). A landed sole
//! does not move until it lifts again (a loaded sole barely slides), so one survey per landing is enough: in the double support after a single
//! support on foot s, once the new foot n carries load, the firmware reads the twelve Present
//! Positions q̂ (over two ticks, (O3′) below) and this module measures n from the stance foot s.
//!
//! A place `p = (x, y, ψ)` is a rigid motion of the floor; `⊕` composes two and `p⁻¹` inverts one:
//!
//! ```text
//!   a ⊕ b = (a_x + cos a_ψ·b_x − sin a_ψ·b_y,  a_y + sin a_ψ·b_x + cos a_ψ·b_y,  a_ψ + b_ψ)     (O1)
//!   p⁻¹   = (−cos ψ·x − sin ψ·y,  sin ψ·x − cos ψ·y,  −ψ)
//! ```
//!
//! Each foot k carries a correction `C_k` (a place; the identity at the start), and the sole
//! place the measured ZMP uses is
//!
//! ```text
//!   p̂_k = C_k ⊕ p_k                              p_k: the plan's place of foot k           (O2)
//! ```
//!
//! The survey: forward kinematics of both legs from q̂ with the pelvis at the origin
//! ([`LegKinematics::fk`]: sole points S and foot rotations R) gives the new sole seen from the
//! stance sole, which stands flat on the floor,
//!
//! ```text
//!   d = R_sᵀ·(S_n − S_s),   M = R_sᵀ·R_n,   r = (d_x, d_y, atan2(M₁₀, M₀₀))                   (O3)
//!   p̂_n = p̂_s ⊕ r,   C_n = p̂_n ⊕ p_n⁻¹          (so that C_n ⊕ p_n = p̂_n)                   (O4)
//! ```
//!
//! The firmware reads the two legs on two ticks (one BULK READ of six servos each, as the
//! bus allows at any rate): the stance leg first, while its sole is still where it stood (in the
//! landing's bounce the old foot may lift and come down elsewhere), the new leg on the next tick.
//! The pelvis moves in between; the new foot, which carries the weight, stays, so the new leg's
//! angles are carried back to the first read by the change of its goals (the gait's planned
//! motion over one tick):
//!
//! ```text
//!   q̂_n(t₁) ≈ q̂_n(t₂) − (q*_n(t₂) − q*_n(t₁)),   q̂_s(t₁) read           q*: the goals sent    (O3′)
//! ```
//!
//! accepted only when q̂ is finite and r is within `d_max` (per axis) and `ψ_max` of the plan's
//! relative place `r_plan = p_s⁻¹ ⊕ p_n` — a foot cannot land further from its plan than that
//! without a fall, so a larger r is a bad reading, and the correction stays as it was:
//!
//! ```text
//!   |r_x − r_plan,x| ≤ d_max,  |r_y − r_plan,y| ≤ d_max,  |r_ψ − r_plan,ψ| ≤ ψ_max              (O5)
//! ```
//!
//! Before its survey a landing foot stands where the plan puts it relative to the stance foot:
//! entering single support on s, the swing foot takes the stance foot's correction,
//!
//! ```text
//!   C_other(s) ← C_s                                                                         (O6)
//! ```
//!
//! The survey is due once per double support that follows a single support, on the first tick
//! the new foot carries at least the share `σ_min` of the feet's summed load: the new foot is then
//! down and stays (it takes the weight), while the old one often lifts for a few tens of
//! milliseconds in the landing's bounce and comes down a little elsewhere — measured later, the survey would chain that move into every landing
//! after it. A double support where the new foot never takes that share keeps (O6). A robot
//! without foot sensors takes the split its ZMP reference plans for the measured one
//! ([`crate::GaitSample::planned_load_shares`]): the survey then falls due once the reference
//! has moved σ_min of the way to the new foot. The corrections accumulate the landings'
//! errors (odometry drift, as a real robot's): the measured ZMP is in the world the firmware
//! estimates, as the physics' centre of pressure is in the true one. Every output is finite: a
//! non-finite result is rejected like an implausible one. Cost: two leg FKs and a few `atan2` /
//! `sin_cos` once per step; (O2) a tick is two compositions with the corrections' sines and
//! cosines kept (none while the corrections are the identity).

use crate::kinematics::leg::{LegKinematics, Pose};
use crate::maths::real::Real;
use crate::measure::support::heading_sin_cos;
use crate::measure::zmp::SolePose;
use crate::robot::{Side, JOINTS_PER_LEG, LEG_JOINTS};
use crate::trajectory::plan::Place;
use crate::trajectory::sampler::SupportPhase;
use crate::trajectory::swing::wrap_pi;

/// Limits of a survey (SI units; module docs (O5) and the due rule).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdometryLimits {
    /// Largest distance d_max of a landing from its plan, per axis, m.
    pub max_offset_m: f32,
    /// Largest heading error ψ_max of a landing, rad.
    pub max_yaw_rad: f32,
    /// Share σ_min of the summed load the new foot carries before the survey is due.
    pub min_load_share: f32,
}

impl OdometryLimits {
    /// The firmware's limits: a landing within 5 cm and 0.3 rad of its plan, the new foot ≥ 20 %.
    pub const DEFAULT: OdometryLimits = OdometryLimits {
        max_offset_m: 0.05,
        max_yaw_rad: 0.3,
        min_load_share: 0.2,
    };
}

/// Why a survey was not taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SurveyError {
    /// No survey is due (not in a double support after a single support, or done already).
    NotDue,
    /// A Present Position or the result is not finite.
    NonFinite,
    /// The landing is further from its plan than the limits (O5).
    Implausible,
}

/// A correction `C` of module docs (O2), with its heading's sine and cosine.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Correction<R> {
    place: Place<R>,
    sin: R,
    cos: R,
}

impl<R: Real> Correction<R> {
    fn identity() -> Self {
        Correction {
            place: Place {
                x: R::zero(),
                y: R::zero(),
                yaw: R::zero(),
            },
            sin: R::zero(),
            cos: R::one(),
        }
    }

    fn of(place: Place<R>) -> Self {
        let (sin, cos) = place.yaw.sin_cos();
        Correction { place, sin, cos }
    }

    /// `C ⊕ p` (O1) with the stored sine and cosine.
    fn apply(&self, p: &Place<R>) -> Place<R> {
        compose_with(&self.place, (self.sin, self.cos), p)
    }
}

/// `a ⊕ b`, module docs (O1).
pub fn compose<R: Real>(a: &Place<R>, b: &Place<R>) -> Place<R> {
    compose_with(a, a.yaw.sin_cos(), b)
}

/// `a ⊕ b` with `a`'s heading's (sin, cos) given.
fn compose_with<R: Real>(a: &Place<R>, (s, c): (R, R), b: &Place<R>) -> Place<R> {
    Place {
        x: a.x + c * b.x - s * b.y,
        y: a.y + s * b.x + c * b.y,
        yaw: a.yaw + b.yaw,
    }
}

/// `p⁻¹`, module docs (O1).
pub fn inverse<R: Real>(p: &Place<R>) -> Place<R> {
    let (s, c) = p.yaw.sin_cos();
    Place {
        x: -(c * p.x + s * p.y),
        y: s * p.x - c * p.y,
        yaw: -p.yaw,
    }
}

/// The sole of leg `new` seen from the sole of leg `stance` (module docs (O3)), from the twelve
/// joint angles `q` (rad, left leg then right leg).
pub fn relative_place<R: Real>(
    kin: &LegKinematics<R>,
    q: &[R; LEG_JOINTS],
    stance: Side,
    new: Side,
) -> Place<R> {
    let leg = |side: Side| -> [R; JOINTS_PER_LEG] {
        let at = match side {
            Side::Left => 0,
            Side::Right => JOINTS_PER_LEG,
        };
        core::array::from_fn(|j| q.get(at + j).copied().unwrap_or(R::zero()))
    };
    let origin = Pose::default();
    // Columns: (S, [x, y, z axes of the foot]); (R_sᵀ·v)_i = column i of R_s · v.
    let (ss, rs) = kin.sole_frame(stance, &origin, &leg(stance));
    let (sn, rn) = kin.sole_frame(new, &origin, &leg(new));
    let dot = |a: &[R; 3], b: &[R; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let d = [sn[0] - ss[0], sn[1] - ss[1], sn[2] - ss[2]];
    let [sx, sy, _] = &rs;
    let [nx, _, _] = &rn;
    Place {
        x: dot(sx, &d),
        y: dot(sy, &d),
        // M₁₀ = (R_s column 1)·(R_n column 0), M₀₀ = (R_s column 0)·(R_n column 0).
        yaw: dot(sy, nx).atan2(dot(sx, nx)),
    }
}

/// The twelve angles of one instant from two reads a tick apart (module docs (O3′)): the stance
/// leg's from the `first` read as they are, the new leg's from the `second` read moved back by
/// the change of its goals, `goals_second − goals_first` (the goals sent before each read). All
/// rad, left leg then right leg.
pub fn legs_at_first_read<R: Real>(
    stance: Side,
    first: &[R; LEG_JOINTS],
    second: &[R; LEG_JOINTS],
    goals_first: &[R; LEG_JOINTS],
    goals_second: &[R; LEG_JOINTS],
) -> [R; LEG_JOINTS] {
    let stance_leg = |j: usize| (j < JOINTS_PER_LEG) == (stance == Side::Left);
    let mut q = *first;
    for (j, v) in q.iter_mut().enumerate().filter(|(j, _)| !stance_leg(*j)) {
        if let (Some(&b), Some(&ga), Some(&gb)) =
            (second.get(j), goals_first.get(j), goals_second.get(j))
        {
            *v = b - (gb - ga);
        }
    }
    q
}

/// A sole's place from the odometry with its heading's sine and cosine (module docs (O2)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurveyedSole<R> {
    /// The place `C ⊕ p`.
    pub place: Place<R>,
    /// sin of its heading.
    pub sin: R,
    /// cos of its heading.
    pub cos: R,
}

impl<R: Real> SurveyedSole<R> {
    /// The plan's place `p` as it is (no correction).
    pub fn planned(place: Place<R>) -> Self {
        let (sin, cos) = heading_sin_cos(place.yaw);
        SurveyedSole { place, sin, cos }
    }
}

impl<R: Real> SolePose<R> for SurveyedSole<R> {
    fn sole_place(&self) -> Place<R> {
        self.place
    }

    fn heading_sin_cos(&self) -> Option<(R, R)> {
        Some((self.sin, self.cos))
    }
}

/// The leg odometry's state: one correction per foot, the survey's bookkeeping.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LegOdometry<R> {
    /// Corrections C of the left and right foot.
    corr: [Correction<R>; 2],
    /// The foot of the last single support (None before the first step).
    last_stance: Option<Side>,
    /// Whether the present double support's landing has had its survey.
    surveyed: bool,
    /// Whether the last phase was a double support.
    in_double: bool,
    /// The limits, in `R`.
    max_offset: R,
    max_yaw: R,
    min_share: R,
    /// Surveys taken and refused since the start.
    taken: u16,
    refused: u16,
}

impl<R: Real> LegOdometry<R> {
    /// Identity corrections; non-finite or negative limits become 0 (every survey refused).
    pub fn new(limits: &OdometryLimits) -> Self {
        let sane = |v: f32| {
            if v.is_finite() && v > 0.0 {
                R::of(f64::from(v))
            } else {
                R::zero()
            }
        };
        LegOdometry {
            corr: [Correction::identity(); 2],
            last_stance: None,
            surveyed: false,
            in_double: false,
            max_offset: sane(limits.max_offset_m),
            max_yaw: sane(limits.max_yaw_rad),
            min_share: sane(limits.min_load_share),
            taken: 0,
            refused: 0,
        }
    }

    /// Follows the gait's support phase (once a tick): (O6) on entering a single support.
    pub fn phase(&mut self, phase: SupportPhase) {
        match phase {
            SupportPhase::Single(s) => {
                if self.last_stance != Some(s) || self.in_double {
                    let c = *s.of(&self.corr);
                    *s.other().of_mut(&mut self.corr) = c;
                }
                self.last_stance = Some(s);
                self.surveyed = false;
                self.in_double = false;
            }
            SupportPhase::Double => self.in_double = true,
            SupportPhase::Standing => {
                // Before the first step nothing has landed; after the last one the final double
                // support's survey stands.
                self.in_double = self.last_stance.is_some();
            }
        }
    }

    /// The survey due now, `(stance, new)`: in the double support after a single support on
    /// `stance`, not yet taken, with the new foot carrying at least σ_min of `loads` (left and
    /// right, in any one unit: N measured, or the planned shares; non-finite = unloaded).
    pub fn survey_due(&self, loads: [R; 2]) -> Option<(Side, Side)> {
        let s = self.last_stance?;
        if !self.in_double || self.surveyed {
            return None;
        }
        let [l, r] = loads.map(|f| if f.is_finite() { f } else { R::zero() });
        let total = l + r;
        let new = match s {
            Side::Left => r,
            Side::Right => l,
        };
        (total > R::zero() && new >= self.min_share * total).then_some((s, s.other()))
    }

    /// Takes the due survey from the twelve Present Positions `q` (rad) and the plan's places of
    /// the feet `planned` (left, right): module docs (O3)–(O5). Once a double support, taken or
    /// refused.
    pub fn survey(
        &mut self,
        kin: &LegKinematics<R>,
        q: &[R; LEG_JOINTS],
        planned: &[Place<R>; 2],
    ) -> Result<Place<R>, SurveyError> {
        let Some(s) = self
            .last_stance
            .filter(|_| self.in_double && !self.surveyed)
        else {
            return Err(SurveyError::NotDue);
        };
        self.surveyed = true;
        let n = s.other();
        let result = self.measure(kin, q, planned, s, n);
        match result {
            Ok(_) => self.taken = self.taken.saturating_add(1),
            Err(_) => self.refused = self.refused.saturating_add(1),
        }
        result
    }

    fn measure(
        &mut self,
        kin: &LegKinematics<R>,
        q: &[R; LEG_JOINTS],
        planned: &[Place<R>; 2],
        s: Side,
        n: Side,
    ) -> Result<Place<R>, SurveyError> {
        if !q.iter().all(|v| v.is_finite()) {
            return Err(SurveyError::NonFinite);
        }
        let (ps, pn) = (*s.of(planned), *n.of(planned));
        let r = relative_place(kin, q, s, n);
        let r_plan = compose(&inverse(&ps), &pn);
        let dyaw = wrap_pi(r.yaw - r_plan.yaw);
        let within = |v: R, lim: R| v.is_finite() && v.abs() <= lim;
        if !(within(r.x - r_plan.x, self.max_offset)
            && within(r.y - r_plan.y, self.max_offset)
            && within(dyaw, self.max_yaw))
        {
            return Err(SurveyError::Implausible);
        }
        let measured_s = s.of(&self.corr).apply(&ps);
        let measured_n = compose(&measured_s, &r);
        let c = compose(&measured_n, &inverse(&pn));
        if !(c.x.is_finite() && c.y.is_finite() && c.yaw.is_finite()) {
            return Err(SurveyError::NonFinite);
        }
        *n.of_mut(&mut self.corr) = Correction::of(c);
        Ok(measured_n)
    }

    /// Where foot `side` stands when the plan puts it at `planned`: `C ⊕ p`, module docs (O2).
    pub fn place(&self, foot: Side, planned: &Place<R>) -> Place<R> {
        foot.of(&self.corr).apply(planned)
    }

    /// [`Self::place`] with its heading's sine and cosine, for the measured ZMP: from the
    /// correction's kept ones, without a sine or cosine of its own when the plan's heading is 0
    /// (a straight walk; otherwise one, as the plan's place needs).
    pub fn sole(&self, foot: Side, planned: &Place<R>) -> SurveyedSole<R> {
        let c = foot.of(&self.corr);
        let (sin, cos) = if planned.yaw == R::zero() {
            (c.sin, c.cos)
        } else {
            let (s, k) = planned.yaw.sin_cos();
            (c.sin * k + c.cos * s, c.cos * k - c.sin * s)
        };
        SurveyedSole {
            place: c.apply(planned),
            sin,
            cos,
        }
    }

    /// The correction C of foot `side` (module docs (O2)).
    pub fn correction(&self, foot: Side) -> Place<R> {
        foot.of(&self.corr).place
    }

    /// Surveys taken and refused since the start.
    pub fn counts(&self) -> (u16, u16) {
        (self.taken, self.refused)
    }
}
