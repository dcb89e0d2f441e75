//! Step adaptation: the catching step. When the capture point leaves what the ankles can hold,
//! the swing foot lands where the pushed body needs it, and the rest of the walk follows.
//!
//! [`CatchingStep`] is the catch (A1)–(A7); [`StepAdapter`], what the firmware runs, composes
//! it with the swing sole's levelling ([`crate::feedback::level`], (A10), on the catch's
//! attitude baseline) and the clock hold ([`crate::feedback::hold`], (A11), on the catch's
//! swing foot). One configuration, [`StepAdaptation`], carries the gains and limits of all three.
//!
//! # Capture-point error from the trunk's attitude
//! A push rotates the whole robot about its stance sole (stiff position servos hold the legs'
//! shape); the CoM at height z_c then moves by z_c times the trunk's rotation. With the
//! attitude filter's roll φ and pitch θ (rad), their baselines φ̄, θ̄ (the walk's own lean,
//! learnt slowly while no catch is needed), the gyro's rates φ̇, θ̇ (rad/s) and ω = √(g/z_c), the
//! DCM (capture point) error ξ − ξ_ref = (c − c_ref) + (ċ − ċ_ref)/ω in the trunk's frame is
//!
//! ```text
//!   e_x =  z_c·((θ − θ̄) + θ̇/ω)     e_y = −z_c·((φ − φ̄) + φ̇/ω)                        (A1)
//!   θ̄ ← θ̄ + dt/(T_b + dt)·(θ − θ̄),  φ̄ likewise, only while |e_x| ≤ m_x and |e_y| ≤ m_y   (A2)
//! ```
//!
//! # The catching step
//! The ankles hold a capture-point error up to m (the deadband, per axis: the part of the sole
//! the ZMP can still move to). Beyond it, in single support on the stance foot s with the
//! heading ψ_s, the swing foot's landing place moves by the excess:
//!
//! ```text
//!   Δ_b = k·dz(e, m)           dz(v, m) = sign(v)·max(|v| − m, 0), per axis           (A3)
//!   |Δ_b,x| ≤ Δx_max,   −Δy_in ≤ σ·Δ_b,y ≤ Δy_out     σ = +1 left swing, −1 right        (A4)
//!   d*_swing = d_s + R(ψ_s)·Δ_b                                                      (A5)
//! ```
//!
//! (A4) is the leg's reach forward/backward and outward, and the feet's self-collision inward:
//! with Δy_in = 0 (the default) the swing foot never moves toward the stance foot, so the step
//! never narrows below the plan's width; a push toward the stance side is caught by the next
//! step, when the other foot swings outward.
//!
//! # Offsets, not a new plan
//! The plan stays as it is; each foot carries an offset d_L, d_R (plan frame, m) and the body a
//! frame offset d_c. The sample the IK takes becomes
//!
//! ```text
//!   foot_i += d_i,   com += d_c,   zmp_ref += d_c                                   (A6)
//!   d_c* = d_s in single support on s;  α·d_L + (1 − α)·d_R in double support /
//!   standing, α = sat₀¹((p_ref − p_R)·(p_L − p_R)/|p_L − p_R|²) (the left foot's share) (A7)
//! ```
//!
//! Only the swing foot's offset moves (toward (A5)); feet on the ground keep theirs, so the
//! next step lands at the plan's place relative to the caught foot: the walk continues from
//! where the catching step put it (the remaining plan shifted by Δ). In the double support
//! after the catch the body offset moves to the new stance foot's, so the body is carried Δ
//! further, which is what absorbs the push. Every offset moves toward its target at most
//! v_max·dt per axis per tick (continuous joint targets), and |d| ≤ [`MAX_OFFSET_M`].
//!
//! # Landing where the plan puts the feet
//! A foot lands where the servos put it, not where its targets do: a leg that yields or lags
//! sets every step down a little long or short (more so the weaker, slower or stiffer the
//! servos), and over a walk the robot drifts from its plan. The leg odometry's survey of each
//! landing ([`crate::measure::odometry`]) gives ε_n, the new foot's surveyed place minus the place
//! its offset d_n put it (plan frame). Each foot keeps its distance from where the plan and the
//! catches want it,
//!
//! ```text
//!   e_n = d_n + ε_n − c_n          c: the catches' share of the offsets                   (A8)
//!   c_swing ← c_s + R(ψ_s)·Δ_b     along with (A5)
//! ```
//!
//! and in single support on s (both feet surveyed since they last landed) the swing foot's
//! landing place moves along the stance foot's heading ψ_s by the share k_l of the feet's
//! midpoint's distance,
//!
//! ```text
//!   ē = (e_s + e_swing)/2        e_swing: where the swing foot stood until it lifted
//!   u = h·clamp(−k_l·(h·ē), ±u_max) + n·clamp(−k_n·(n·ē), ±u_max),
//!       h = (cos ψ_s, sin ψ_s),  n = (−sin ψ_s, cos ψ_s)
//!   d*_swing = d_s + R(ψ_s)·Δ_b + u                 (in place of (A5))                    (A9)
//! ```
//!
//! (u_max = [`MAX_LANDING_SHIFT_M`]; the body follows by (A7)). Along h, a step that lands δ
//! off its targets leaves e_swing′ = e_s + u + δ: a δ repeated on every step (both feet long or
//! short, a servo's stiffness or lag) leaves e = δ/k_l, whatever the number of steps (k_l = 1:
//! the last step's δ alone), where without (A9) the δ add up. A δ that alternates between the
//! feet (one leg weaker than the other, or a trunk turned from the plan: the step width, turned,
//! puts one foot ahead and the other behind) leaves the midpoint where it is and asks no move:
//! the midpoint is where the robot stands, each foot alone is not. u enters the landing place
//! over T_u after lift-off (`landing_ramp_s`: the lifting foot is not slid along the floor).
//! Sideways (k_n = `landing_lateral`, 0 by default) the landing stays the plan's: the step
//! width sets the lateral sway the plan's ZMP was made for, and an inward move could bring the
//! feet together. With k_n > 0 the midpoint's sideways drift (both feet landing to one side)
//! is taken back the same way; the width, the feet's difference, asks no move. u is taken once per single
//! support; a foot's e is dropped when it lifts (a refused survey leaves no correction until
//! both feet are surveyed again). The online walk corrects its own footsteps instead
//! ([`crate::trajectory::online`], P1–P2) and does not feed (A8). The references the firmware
//! logs are in the odometry's world: the sample's minus the hold's share of the body offset
//! ([`CatchingStep::landing_body_shift`]).
//!
//! A missing or non-finite attitude or gyro sample gives e = 0 (no catch, offsets hold;
//! non-finite inputs never reach the state). g, the weight and every per-tick
//! factor (the baseline's k = dt/(T_b + dt), the offsets' steps v_max·dt) come from the robot
//! and the tick period once, in [`CatchingStep::new`]. Cost without a push: the error (A1), the
//! baseline (A2), the levelling (A10), the landing hold's move (A9: computed once a single
//! support) and the deadband test, then an early return while no offset and no landing move is
//! pending (the control tick's cost is in BENCHMARKS.md).

use crate::feedback::hold::{ClockHold, SwingFoot};
use crate::feedback::level::SoleLevel;
use crate::maths::real::Real;
use crate::robot::{Robot, Side, LEG_JOINTS};
use crate::trajectory::sampler::{GaitSample, SupportPhase};

/// Largest offset of a foot or of the body from the plan, m (the offsets are clamped to it).
pub const MAX_OFFSET_M: f32 = 2.0;

/// Largest move u of one landing place by the landing hold (A9), along the stance heading, m.
pub const MAX_LANDING_SHIFT_M: f32 = 0.02;

/// Gains and limits of the step adaptation: the catching step (module docs (A1)–(A7)), the
/// swing sole's levelling ([`crate::feedback::level`], (A10)) and the clock hold
/// ([`crate::feedback::hold`], (A11)); SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepAdaptation {
    /// Gain k of the capture-point excess on the landing place (A3); 0 turns the step
    /// adaptation off.
    pub gain: f32,
    /// Deadband m per axis (x, y), m: the capture-point error the ankles hold (A3).
    pub deadband_m: [f32; 2],
    /// Largest forward/backward move of the landing place, m (A4).
    pub max_x_m: f32,
    /// Largest outward move of the landing place, m (A4).
    pub max_out_m: f32,
    /// Largest inward move (toward the stance foot), m (A4; self-collision).
    pub max_in_m: f32,
    /// Largest speed of the swing foot's offset, m/s.
    pub speed_m_s: f32,
    /// Largest speed of the body's offset, m/s.
    pub body_speed_m_s: f32,
    /// Time constant T_b of the attitude baseline (A2), s.
    pub baseline_s: f32,
    /// Load on the swing foot, as a share of the robot's weight, from which it counts as
    /// landed: its offset stops moving (an early touchdown).
    pub touchdown_share: f32,
    /// Gain k_θ of the swing sole's levelling on the trunk's pitch off its baseline (A10;
    /// 0 = off, 1 = level).
    pub level_pitch: f32,
    /// Gain k_φ of the swing sole's levelling on the trunk's roll off its baseline (A10;
    /// 0 = off, 1 = level).
    pub level_roll: f32,
    /// Gain k_q of the swing sole's levelling on the swing leg's measured pitch lag e_q (A10;
    /// 0 = off; < 1, see [`crate::feedback::level`]; needs the servos' Present Position).
    pub level_joints: f32,
    /// Time T_r over which the levelling ramps in after lift-off and out after touchdown, s
    /// (A10).
    pub level_ramp_s: f32,
    /// Longest hold of the plan's clock in one single support while the caught swing foot is
    /// still on its way, s (A11; 0 = off).
    pub hold_max_s: f32,
    /// Time the held clock waits after the swing foot's offset arrived (the servos' lag), s
    /// (A11).
    pub hold_settle_s: f32,
    /// Distance of the measured swing sole from where its targets put it beyond which the
    /// clock holds in the landing (A11, the servos' lag), m (0 = off; needs the servos' Present
    /// Position).
    pub hold_lag_m: f32,
    /// Gain k_l of the landing hold: the share of the feet's midpoint's surveyed distance from
    /// where it should stand that the next landing place corrects (A8)–(A9; 0 = off; needs
    /// the leg odometry's surveys).
    pub landing_gain: f32,
    /// Gain of the landing hold across the stance foot's heading: the share of the feet's
    /// midpoint's sideways distance the next landing place corrects (A9; 0 = off: sideways the
    /// landing stays the plan's).
    pub landing_lateral: f32,
    /// Time over which the landing hold's move u enters the swing foot's landing place after
    /// lift-off, s (A9).
    pub landing_ramp_s: f32,
}

impl StepAdaptation {
    /// Off (gain 0, no levelling, no landing hold), with the default limits.
    pub const OFF: StepAdaptation = StepAdaptation {
        gain: 0.0,
        level_pitch: 0.0,
        level_roll: 0.0,
        level_joints: 0.0,
        landing_gain: 0.0,
        ..StepAdaptation::DEFAULT
    };

    /// The firmware's default (see `docs/beyond.md`, "The catching step"): k = 1, deadband
    /// 2 cm, up to 5 cm forward/backward, the lateral catch off (`max_out_m` = 0: an outward
    /// catch can turn a sideways push the ankles hold into a fall), 0.5 m/s, a 2 s baseline,
    /// touchdown at a fifth of the weight; the swing sole kept level in pitch and roll, ramped
    /// over 0.1 s (`docs/beyond.md`, "The swing sole kept level"); the clock held up to 0.15 s
    /// per single support while a caught foot is on its way (A11; `docs/beyond.md`, "The
    /// landing waits for the caught foot").
    pub const DEFAULT: StepAdaptation = StepAdaptation {
        gain: 1.0,
        deadband_m: [0.02, 0.02],
        max_x_m: 0.05,
        max_out_m: 0.0,
        max_in_m: 0.0,
        speed_m_s: 0.5,
        body_speed_m_s: 0.5,
        baseline_s: 2.0,
        touchdown_share: 0.2,
        level_pitch: 1.0,
        level_roll: 1.0,
        level_joints: 0.0,
        level_ramp_s: 0.1,
        hold_max_s: 0.15,
        hold_settle_s: 0.1,
        hold_lag_m: 0.0,
        landing_gain: 1.0,
        landing_lateral: 0.0,
        landing_ramp_s: 0.2,
    };

    /// Whether the step adaptation runs (finite positive gain).
    pub fn is_on(&self) -> bool {
        self.gain.is_finite() && self.gain > 0.0
    }

    /// Whether the swing sole's levelling runs (a finite positive gain on pitch, roll or the
    /// joints' lag).
    pub fn is_levelling(&self) -> bool {
        [self.level_pitch, self.level_roll, self.level_joints]
            .iter()
            .any(|k| k.is_finite() && *k > 0.0)
    }

    /// Every limit finite and ≥ 0 (a clamp with crossed or NaN bounds would panic): any other
    /// value counts as 0. `touchdown_share` is taken as it is.
    pub(crate) fn limited(&self) -> StepAdaptation {
        let limit = |v: f32| if v.is_finite() && v >= 0.0 { v } else { 0.0 };
        StepAdaptation {
            deadband_m: self.deadband_m.map(limit),
            max_x_m: limit(self.max_x_m),
            max_out_m: limit(self.max_out_m),
            max_in_m: limit(self.max_in_m),
            speed_m_s: limit(self.speed_m_s),
            body_speed_m_s: limit(self.body_speed_m_s),
            baseline_s: limit(self.baseline_s),
            gain: limit(self.gain),
            level_pitch: limit(self.level_pitch),
            level_roll: limit(self.level_roll),
            level_joints: limit(self.level_joints),
            level_ramp_s: limit(self.level_ramp_s),
            hold_max_s: limit(self.hold_max_s),
            hold_settle_s: limit(self.hold_settle_s),
            hold_lag_m: limit(self.hold_lag_m),
            landing_gain: limit(self.landing_gain),
            landing_lateral: limit(self.landing_lateral),
            landing_ramp_s: limit(self.landing_ramp_s),
            ..*self
        }
    }
}

/// Whether a CoM height `z_c` (m), a tick of `dt_s` seconds and gravity `g` (m/s²) can run the
/// step adaptation (finite and positive).
fn valid(z_c: f32, dt_s: f32, g: f32) -> bool {
    z_c.is_finite() && z_c > 0.0 && dt_s.is_finite() && dt_s > 0.0 && g > 0.0
}

/// The landing hold's move of one single support (A9).
#[derive(Clone, Copy, Debug, PartialEq)]
struct LandingShift {
    /// The swing foot.
    swing: Side,
    /// Its move along the stance foot's heading, m.
    forward: f32,
    /// u, plan frame, m.
    u: [f32; 2],
    /// The share of u entered so far (ramp).
    share: f32,
}

/// The catching step's state (A1)–(A7): the attitude baseline, the capture-point error and the
/// offsets of the feet and the body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CatchingStep {
    /// Gain k (A3); 0 when off.
    gain: f32,
    /// Deadband m per axis (x, y), m (A3).
    deadband_m: [f32; 2],
    /// Largest forward/backward, outward and inward moves of the landing place, m (A4).
    max_x_m: f32,
    max_out_m: f32,
    max_in_m: f32,
    z_c: f32,
    touchdown_n: f32,
    inv_omega: f32,
    /// The baseline's filter factor dt/(T_b + dt) (A2).
    baseline_k: f32,
    /// Largest move of the swing foot's and of the body's offset in one tick, m.
    steps: [f32; 2],
    /// Attitude baseline (roll, pitch), rad; `None` until the first attitude.
    baseline: Option<[f32; 2]>,
    /// Capture-point error of the last update, trunk frame, m.
    error: [f32; 2],
    /// Offsets of the left and right foot, plan frame, m.
    feet: [[f32; 2]; 2],
    /// Offset of the body (CoM and ZMP reference), plan frame, m.
    body: [f32; 2],
    /// Gain k_l of the landing hold (A9); 0 when off.
    landing_gain: f32,
    /// Its gain across the stance foot's heading (A9); 0 when off.
    landing_lateral: f32,
    /// The catches' share c of the left and right foot's offset (A8), plan frame, m.
    caught: [[f32; 2]; 2],
    /// Each foot's surveyed distance e from where it should stand (A8), plan frame, m; `None`
    /// until surveyed since it landed.
    landing_error: [Option<[f32; 2]>; 2],
    /// The landing hold's move (A9) of this single support.
    landing_shift: Option<LandingShift>,
    /// The share of u one tick adds while it enters (dt / T_u; 1 = at once).
    landing_ramp: f32,
    /// The catches' share of the body's offset ((A7) on `caught`), plan frame, m.
    caught_body: [f32; 2],
}

impl CatchingStep {
    /// A catching step for `robot` (its gravity and weight) walking at the CoM height `z_c`
    /// (m) with ticks of `dt_s` seconds; a non-positive or non-finite height or tick turns it
    /// off.
    pub fn new(cfg: &StepAdaptation, robot: &Robot, z_c: f32, dt_s: f32) -> Self {
        let g = robot.gravity as f32;
        let ok = valid(z_c, dt_s, g);
        let cfg = cfg.limited();
        CatchingStep {
            gain: if ok { cfg.gain } else { 0.0 },
            deadband_m: cfg.deadband_m,
            max_x_m: cfg.max_x_m,
            max_out_m: cfg.max_out_m,
            max_in_m: cfg.max_in_m,
            z_c: if ok { z_c } else { 0.0 },
            touchdown_n: cfg.touchdown_share * (robot.masses.total() * robot.gravity) as f32,
            inv_omega: if ok {
                crate::maths::fastmath::sqrt(z_c / g)
            } else {
                0.0
            },
            baseline_k: if ok {
                dt_s / (cfg.baseline_s + dt_s)
            } else {
                0.0
            },
            steps: if ok {
                [cfg.speed_m_s * dt_s, cfg.body_speed_m_s * dt_s]
            } else {
                [0.0; 2]
            },
            baseline: None,
            error: [0.0; 2],
            feet: [[0.0; 2]; 2],
            body: [0.0; 2],
            landing_gain: if ok { cfg.landing_gain } else { 0.0 },
            landing_lateral: if ok { cfg.landing_lateral } else { 0.0 },
            caught: [[0.0; 2]; 2],
            landing_error: [None; 2],
            landing_shift: None,
            landing_ramp: if ok && cfg.landing_ramp_s > dt_s {
                dt_s / cfg.landing_ramp_s
            } else {
                1.0
            },
            caught_body: [0.0; 2],
        }
    }

    /// The landing hold's share of the body's offset (A8)–(A9), plan frame, m: how far the
    /// frame the joints are commanded in stands from the world the leg odometry estimates (the
    /// robot's references in that world are the shifted sample's minus this).
    pub fn landing_body_shift(&self) -> [f32; 2] {
        [
            self.body[0] - self.caught_body[0],
            self.body[1] - self.caught_body[1],
        ]
    }

    /// Whether the catching step or the landing hold runs (a finite positive gain).
    pub fn is_on(&self) -> bool {
        [self.gain, self.landing_gain]
            .iter()
            .any(|k| k.is_finite() && *k > 0.0)
    }

    /// The survey of a landing (A8): foot `side` stands `surveyed` (surveyed place minus the
    /// place its offset put it, plan frame, m) off. Ignored with the landing hold off or when
    /// not finite.
    pub fn set_landing(&mut self, side: Side, surveyed: [f32; 2]) {
        if !(self.landing_gain > 0.0 && surveyed.iter().all(|v| v.is_finite())) {
            return;
        }
        let (d, c, e) = match side {
            Side::Left => (self.feet[0], self.caught[0], &mut self.landing_error[0]),
            Side::Right => (self.feet[1], self.caught[1], &mut self.landing_error[1]),
        };
        *e = Some([d[0] + surveyed[0] - c[0], d[1] + surveyed[1] - c[1]]);
    }

    /// The landing errors e of the left and right foot (A8), plan frame, m (`None`: not
    /// surveyed since it landed).
    pub fn landing_errors(&self) -> [Option<[f32; 2]>; 2] {
        self.landing_error
    }

    /// (A9): the landing hold's move u for the swing foot `swing` off the stance foot of heading
    /// `stance_yaw` (rad), taken once per single support.
    fn landing_move(&mut self, swing: Side, stance_yaw: f32) -> [f32; 2] {
        if let Some(l) = self.landing_shift.as_mut().filter(|l| l.swing == swing) {
            l.share = (l.share + self.landing_ramp).min(1.0);
            return [l.u[0] * l.share, l.u[1] * l.share];
        }
        let stance = swing.other();
        let (e_stance, e_swing) = match stance {
            Side::Left => (self.landing_error[0], &mut self.landing_error[1]),
            Side::Right => (self.landing_error[1], &mut self.landing_error[0]),
        };
        // The swing foot's distance is where it stood until now; stale once it lifts.
        let e_swing = e_swing.take();
        let (forward, u) = match (e_stance, e_swing) {
            (Some(a), Some(b)) if self.landing_gain > 0.0 => {
                // The feet's midpoint, along the stance foot's heading only.
                let (ex, ey) = (0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]));
                let (sn, cs) = crate::maths::fastmath::sin_cos(stance_yaw);
                let m = MAX_LANDING_SHIFT_M;
                let forward = (-self.landing_gain * (cs * ex + sn * ey)).clamp(-m, m);
                let side = (-self.landing_lateral * (cs * ey - sn * ex)).clamp(-m, m);
                let u = [cs * forward - sn * side, sn * forward + cs * side];
                if u.iter().all(|v| v.is_finite()) {
                    (forward, u)
                } else {
                    (0.0, [0.0; 2])
                }
            }
            _ => (0.0, [0.0; 2]),
        };
        let share = self.landing_ramp.min(1.0);
        self.landing_shift = Some(LandingShift {
            swing,
            forward,
            u,
            share,
        });
        [u[0] * share, u[1] * share]
    }

    /// The landing hold's move of the present single support (A9): the swing foot and its
    /// whole move along the stance foot's heading, m (before the ramp); `None` outside single
    /// support or with the hold off.
    pub fn landing_move_forward(&self) -> Option<(Side, f32)> {
        self.landing_shift.map(|l| (l.swing, l.forward))
    }

    /// The capture-point error of the last update (A1), trunk frame (x forward, y left), m.
    pub fn error(&self) -> [f32; 2] {
        self.error
    }

    /// The offsets of the left and right foot, plan frame, m.
    pub fn foot_offsets(&self) -> [[f32; 2]; 2] {
        self.feet
    }

    /// The body's offset (CoM and ZMP reference), plan frame, m.
    pub fn body_offset(&self) -> [f32; 2] {
        self.body
    }

    /// Whether any offset is non-zero (the sample needs (A6)).
    pub fn is_shifting(&self) -> bool {
        self.feet
            .iter()
            .chain([&self.body])
            .any(|d| d[0] != 0.0 || d[1] != 0.0)
    }

    /// (A1), (A2): the capture-point error from the attitude `roll_pitch` (rad) and the gyro's
    /// `rates` (roll, pitch rate, rad/s), both `None` when missing (e = 0), and the baseline
    /// one tick on. Returns the trunk's deviation from the baseline (pitch, roll), rad, for
    /// the levelling (A10), `None` without a finite attitude and rates.
    pub fn observe(
        &mut self,
        roll_pitch: Option<[f32; 2]>,
        rates: Option<[f32; 2]>,
    ) -> Option<[f32; 2]> {
        let finite = |v: &[f32; 2]| v[0].is_finite() && v[1].is_finite();
        let m = self.deadband_m;
        let mut deviation = None;
        self.error = match (roll_pitch.filter(finite), rates.filter(finite)) {
            (Some([roll, pitch]), Some([roll_rate, pitch_rate])) => {
                let [b_roll, b_pitch] = *self.baseline.get_or_insert([roll, pitch]);
                let e = [
                    self.z_c * ((pitch - b_pitch) + pitch_rate * self.inv_omega),
                    -self.z_c * ((roll - b_roll) + roll_rate * self.inv_omega),
                ];
                if e[0].abs() <= m[0] && e[1].abs() <= m[1] {
                    let k = self.baseline_k;
                    self.baseline = Some([
                        b_roll + k * (roll - b_roll),
                        b_pitch + k * (pitch - b_pitch),
                    ]);
                }
                deviation = Some([pitch - b_pitch, roll - b_roll]);
                if finite(&e) {
                    e
                } else {
                    [0.0; 2]
                }
            }
            _ => [0.0; 2],
        };
        deviation
    }

    /// (A3)–(A5), (A7) for the error of the last [`CatchingStep::observe`], with the present
    /// (unshifted) gait `sample` and the feet's measured loads `loads_n` (left, right; N, NaN
    /// when not measured): moves the offsets. Returns the landing move Δ_b (trunk frame) asked
    /// this tick, 0 when no catch is needed or outside single support, and, in single support
    /// while the swing foot has not landed, the swing foot for the clock hold (A11). A swing
    /// foot that already carries `touchdown_share` of the weight has landed early: its offset
    /// holds.
    pub fn step(
        &mut self,
        sample: &GaitSample<f32>,
        loads_n: [f32; 2],
    ) -> ([f32; 2], Option<SwingFoot>) {
        let finite = |v: &[f32; 2]| v[0].is_finite() && v[1].is_finite();
        let m = self.deadband_m;
        // (A9): the landing hold's move of this single support.
        let u = match sample.phase {
            SupportPhase::Single(stance) if self.landing_gain > 0.0 => {
                let stance_yaw = match stance {
                    Side::Left => sample.feet[0].yaw,
                    Side::Right => sample.feet[1].yaw,
                };
                self.landing_move(stance.other(), stance_yaw)
            }
            _ => {
                self.landing_shift = None;
                [0.0; 2]
            }
        };
        // Inside the deadband with every offset at 0 and no landing move nothing moves: the
        // common tick ends here.
        if self.error[0].abs() <= m[0]
            && self.error[1].abs() <= m[1]
            && !self.is_shifting()
            && u == [0.0; 2]
        {
            return ([0.0; 2], None);
        }
        let mut asked = [0.0; 2];
        let mut targets = self.feet;
        let mut caught_targets = self.caught;
        // (A11): the swing side and its planned sole height, while it has not landed.
        let mut swing_hold: Option<(Side, f32)> = None;
        let (body_target, caught_body_target) = match (sample.phase, sample.support_foot) {
            (SupportPhase::Single(stance), _) => {
                let swing = stance.other();
                // (A3), (A4)
                let dz = |v: f32, m: f32| v.signum() * (v.abs() - m).max(0.0);
                let k = self.gain;
                let sigma = if swing == Side::Left { 1.0 } else { -1.0 };
                // `clamp_to`: no panic when configured bounds cross (f32::clamp's).
                let dx = (k * dz(self.error[0], m[0])).clamp_to(-self.max_x_m, self.max_x_m);
                let dy = sigma
                    * (sigma * k * dz(self.error[1], m[1]))
                        .clamp_to(-self.max_in_m, self.max_out_m);
                asked = [dx, dy];
                // Constant indices (the left foot first): checked at compile time.
                let (ds, cs, swing_load, stance_yaw) = match stance {
                    Side::Left => (self.feet[0], self.caught[0], loads_n[1], sample.feet[0].yaw),
                    Side::Right => (self.feet[1], self.caught[1], loads_n[0], sample.feet[1].yaw),
                };
                let landed = swing_load > self.touchdown_n;
                let swing_z = match swing {
                    Side::Left => sample.feet[0].z,
                    Side::Right => sample.feet[1].z,
                };
                swing_hold = (!landed).then_some((swing, swing_z));
                if !landed {
                    // (A5): the stance foot's heading turns the trunk frame into the plan's
                    // (no sine and cosine while there is nothing to turn).
                    let [px, py] = if asked == [0.0; 2] {
                        [0.0; 2]
                    } else {
                        let (s, c) = crate::maths::fastmath::sin_cos(stance_yaw);
                        [c * dx - s * dy, s * dx + c * dy]
                    };
                    let [tl, tr] = &mut targets;
                    let t = if swing == Side::Left { tl } else { tr };
                    *t = [ds[0] + px + u[0], ds[1] + py + u[1]];
                    // (A8): the catches' share follows the catch alone.
                    let [cl, cr] = &mut caught_targets;
                    let c = if swing == Side::Left { cl } else { cr };
                    *c = [cs[0] + px, cs[1] + py];
                }
                (ds, cs)
            }
            _ => {
                // (A7): the reference ZMP's place between the feet.
                let a = sample.left_share();
                let blend = |[dl, dr]: [[f32; 2]; 2]| {
                    [a * dl[0] + (1.0 - a) * dr[0], a * dl[1] + (1.0 - a) * dr[1]]
                };
                (blend(self.feet), blend(self.caught))
            }
        };
        let toward = |d: [f32; 2], t: [f32; 2], step: f32| {
            [0, 1].map(|i| {
                (d[i] + (t[i] - d[i]).clamp_to(-step, step)).clamp(-MAX_OFFSET_M, MAX_OFFSET_M)
            })
        };
        for (d, t) in self.feet.iter_mut().zip(targets) {
            if finite(&t) {
                *d = toward(*d, t, self.steps[0]);
            }
        }
        // Moved as the feet are: without a landing hold the same numbers.
        for (c, t) in self.caught.iter_mut().zip(caught_targets) {
            if finite(&t) {
                *c = toward(*c, t, self.steps[0]);
            }
        }
        if finite(&body_target) {
            self.body = toward(self.body, body_target, self.steps[1]);
        }
        if finite(&caught_body_target) {
            self.caught_body = toward(self.caught_body, caught_body_target, self.steps[1]);
        }
        // (A11): how far the swing foot's offset still is from its target (|·|∞).
        let swing = swing_hold.map(|(swing, z_m)| {
            let gap_m = match (swing, self.feet, targets) {
                (Side::Left, [d, _], [t, _]) | (Side::Right, [_, d], [_, t]) => {
                    (t[0] - d[0]).abs().max((t[1] - d[1]).abs())
                }
            };
            SwingFoot {
                z_m,
                gap_m,
                lag_m: f32::NAN,
            }
        });
        (asked, swing)
    }

    /// (A6) on a sample: the feet by their offsets, the CoM and the ZMP reference by the body's.
    pub fn apply(&self, sample: &mut GaitSample<f32>) {
        for (f, d) in sample.feet.iter_mut().zip(self.feet) {
            f.x += d[0];
            f.y += d[1];
        }
        for i in 0..2 {
            sample.com[i] += self.body[i];
            sample.zmp[i] += self.body[i];
        }
    }
}

/// The step adaptation the firmware runs: the catching step ([`CatchingStep`]), the swing
/// sole's levelling ([`SoleLevel`]) and the clock hold ([`ClockHold`]), updated in that order
/// on one configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepAdapter {
    catch: CatchingStep,
    level: SoleLevel,
    hold: ClockHold,
    /// The swing sole's measured distance from where its targets put it, m (NaN: not
    /// measured).
    swing_lag_m: f32,
}

impl StepAdapter {
    /// A step adaptation for `robot` (its gravity and weight) walking at the CoM height `z_c`
    /// (m) with ticks of `dt_s` seconds; a non-positive or non-finite height or tick turns it
    /// off.
    pub fn new(cfg: &StepAdaptation, robot: &Robot, z_c: f32, dt_s: f32) -> Self {
        let cfg = if valid(z_c, dt_s, robot.gravity as f32) {
            *cfg
        } else {
            // Off: no catch, no levelling, no hold budget (every part at rest).
            StepAdaptation {
                gain: 0.0,
                level_pitch: 0.0,
                level_roll: 0.0,
                level_joints: 0.0,
                level_ramp_s: 0.0,
                hold_max_s: 0.0,
                hold_settle_s: 0.0,
                hold_lag_m: 0.0,
                landing_gain: 0.0,
                ..*cfg
            }
        };
        StepAdapter {
            catch: CatchingStep::new(&cfg, robot, z_c, dt_s),
            level: SoleLevel::new(&cfg, dt_s),
            hold: ClockHold::new(&cfg, dt_s),
            swing_lag_m: f32::NAN,
        }
    }

    /// The swing sole's measured distance from where its targets put it this tick, m (NaN
    /// when not measured): the clock hold's landing condition (A11).
    pub fn set_swing_lag_m(&mut self, lag_m: f32) {
        self.swing_lag_m = lag_m;
    }

    /// The survey of a landing for the landing hold (A8): foot `side` stands `surveyed`
    /// (surveyed place minus the place its offset put it, plan frame, m) off.
    pub fn set_landing(&mut self, side: Side, surveyed: [f32; 2]) {
        self.catch.set_landing(side, surveyed);
    }

    /// The landing errors e of the left and right foot (A8), plan frame, m (`None`: not
    /// surveyed since it landed).
    pub fn landing_errors(&self) -> [Option<[f32; 2]>; 2] {
        self.catch.landing_errors()
    }

    /// The landing hold's move of the present single support (A9)
    /// ([`CatchingStep::landing_move_forward`]).
    pub fn landing_move_forward(&self) -> Option<(Side, f32)> {
        self.catch.landing_move_forward()
    }

    /// The landing hold's share of the body's offset (A8)–(A9), plan frame, m
    /// ([`CatchingStep::landing_body_shift`]).
    pub fn landing_body_shift(&self) -> [f32; 2] {
        self.catch.landing_body_shift()
    }

    /// Whether the plan's clock should stand still for the next tick (A11): the caught swing
    /// foot is still on its way (or settling) as the plan would set it down.
    pub fn wants_hold(&self) -> bool {
        self.hold.wants_hold()
    }

    /// The swing sole's levelling (A10): the ankle corrections (pitch, roll) of the left and
    /// the right leg, rad, each within ±[`crate::feedback::level::MAX_LEVEL_RAD`].
    pub fn sole_level(&self) -> [[f32; 2]; 2] {
        self.level.corrections()
    }

    /// The swing legs' measured pitch lag e_q for the levelling (A10): per leg (left, right),
    /// rad (NaN when not measured: the last one holds).
    pub fn set_joint_lag(&mut self, lag: [f32; 2]) {
        self.level.set_joint_lag(lag);
    }

    /// Adds the levelling (A10) to the joint targets `q` (left leg then right leg, rad).
    pub fn apply_level(&self, q: &mut [f32; LEG_JOINTS]) {
        self.level.apply(q);
    }

    /// Whether it runs (the catching step, the landing hold or the levelling).
    pub fn is_on(&self) -> bool {
        self.catch.is_on() || self.level.is_on()
    }

    /// The capture-point error of the last update (A1), trunk frame (x forward, y left), m.
    pub fn error(&self) -> [f32; 2] {
        self.catch.error()
    }

    /// The offsets of the left and right foot, plan frame, m.
    pub fn foot_offsets(&self) -> [[f32; 2]; 2] {
        self.catch.foot_offsets()
    }

    /// The body's offset (CoM and ZMP reference), plan frame, m.
    pub fn body_offset(&self) -> [f32; 2] {
        self.catch.body_offset()
    }

    /// Whether any offset is non-zero (the sample needs (A6)).
    pub fn is_shifting(&self) -> bool {
        self.catch.is_shifting()
    }

    /// One tick (of the period given to [`StepAdapter::new`]): the attitude `roll_pitch` (rad)
    /// and the gyro's `rates` (roll, pitch rate, rad/s), both `None` when missing, the feet's
    /// measured loads `loads_n` (left, right; N, NaN when not measured), with the present
    /// (unshifted) gait `sample`: the error and the baseline (A1), (A2), the levelling (A10),
    /// the offsets (A3)–(A5), (A7), the clock hold (A11). Returns the landing move Δ_b (trunk
    /// frame) asked this tick, 0 when no catch is needed or outside single support. A swing
    /// foot that already carries `touchdown_share` of the weight has landed early: its offset
    /// holds.
    pub fn update(
        &mut self,
        sample: &GaitSample<f32>,
        roll_pitch: Option<[f32; 2]>,
        rates: Option<[f32; 2]>,
        loads_n: [f32; 2],
    ) -> [f32; 2] {
        if !self.is_on() {
            return [0.0; 2];
        }
        let deviation = self.catch.observe(roll_pitch, rates);
        self.level.update(deviation, sample.phase);
        let (asked, swing) = self.catch.step(sample, loads_n);
        let swing = self.with_lag(swing, sample, loads_n);
        self.hold.update(sample.phase, swing);
        asked
    }

    /// The swing foot for the clock hold with the measured lag: the catch's (or, in a single
    /// support without a catch, the plan's sole height and no offset gap) while the swing foot
    /// carries less than the touchdown load.
    fn with_lag(
        &self,
        swing: Option<SwingFoot>,
        sample: &GaitSample<f32>,
        loads_n: [f32; 2],
    ) -> Option<SwingFoot> {
        let lag_m = self.swing_lag_m;
        if !lag_m.is_finite() {
            return swing;
        }
        if let Some(foot) = swing {
            return Some(SwingFoot { lag_m, ..foot });
        }
        let SupportPhase::Single(stance) = sample.phase else {
            return None;
        };
        let (z_m, load) = match stance {
            Side::Left => (sample.feet[1].z, loads_n[1]),
            Side::Right => (sample.feet[0].z, loads_n[0]),
        };
        // An unmeasured (NaN) load has not landed.
        let landed = load > self.catch.touchdown_n;
        (!landed).then_some(SwingFoot {
            z_m,
            gap_m: 0.0,
            lag_m,
        })
    }

    /// (A6) on a sample: the feet by their offsets, the CoM and the ZMP reference by the body's.
    pub fn apply(&self, sample: &mut GaitSample<f32>) {
        self.catch.apply(sample);
    }
}
