//! Footstep plans: seed 000's forward walk (eqs 6-8, Table 2) and any queue of footsteps.
//!
//! A plan is a start stance (both feet) and a queue of [`Footstep`]s. Step n moves the swing
//! foot `side` to `place` while the other foot supports; it lasts one step period T
//! (`T = T_SSP + T_DSP`, eq 9) split by `t1 < t2` into double support `[0, t1]`, single support
//! `(t1, t2]` and double support `(t2, T]` (the split of seed 000 eqs 10-11). The plan starts
//! from standing (a lead-in with the ZMP between the feet) and ends standing (a lead-out).
//!
//! Seed 000's forward walk, eqs 6-8, with S_first = −1 (left foot first, so the right foot
//! supports first): support foot of step n at `p^c_n = (n·S_L, S_first·S_W·(−1)^n)` for
//! n = 0..N−1. Our reading of the start and the stop (the paper gives neither): both feet start
//! side by side at x = 0, y = ±S_W; the first swing lands at S_L (stride S_L), the middle ones
//! stride 2·S_L, and the last swing foot lands beside the support foot (stride S_L) so that the
//! robot ends standing with its feet together at x = (N−1)·S_L.

use crate::error::GaitError;
use crate::maths::real::Real;
use crate::model::{Model, ModelKind};
use crate::robot::{Robot, Side};
use crate::trajectory::zmp::ZmpShape;
use heapless::Deque;

/// A foot place on the ground: sole point (x, y), m, and heading yaw, rad, in the world frame.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Place<R> {
    /// x, m.
    pub x: R,
    /// y, m.
    pub y: R,
    /// Heading about +z, rad.
    pub yaw: R,
}

impl<R: Real> Place<R> {
    /// A place from f64 numbers.
    pub fn new(x: f64, y: f64, yaw: f64) -> Self {
        Place {
            x: R::of(x),
            y: R::of(y),
            yaw: R::of(yaw),
        }
    }
    /// The point `along` metres forward along this foot's heading.
    pub fn ahead(&self, along: R) -> [R; 2] {
        self.ahead_with(along, self.yaw.sin_cos())
    }
    /// [`Place::ahead`] with the heading's (sin, cos) given (several points of one foot: one
    /// sine and cosine, a long library call without an FPU).
    pub fn ahead_with(&self, along: R, (sin, cos): (R, R)) -> [R; 2] {
        [self.x + along * cos, self.y + along * sin]
    }
    /// The horizontal position.
    pub fn xy(&self) -> [R; 2] {
        [self.x, self.y]
    }
    /// True when every number is finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.yaw.is_finite()
    }
}

/// One footstep: the swing foot `side` lands on `place`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footstep<R> {
    /// The foot that swings in this step.
    pub side: Side,
    /// Where it lands.
    pub place: Place<R>,
}

/// Step timing: switch times t1 < t2 inside the step period T, s (seed 000 eqs 9-11).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing<R> {
    /// End of the first double support (lift-off), s.
    pub t1: R,
    /// End of the single support (touch-down), s.
    pub t2: R,
    /// Step period T, s.
    pub period: R,
}

/// The swing-foot profile (seed 000 eq 27, or seed 001 Fig. 9).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SwingShape<R> {
    /// Seed 000 eq 27: cycloid, peak height `height` (H_z), lateral bulge `width` (W_y).
    Cycloid {
        /// Peak swing height H_z, m.
        height: R,
        /// Lateral bulge W_y (outward, peak at mid-swing), m.
        width: R,
    },
    /// Seed 001: half-cosine forward motion and a raised-cosine height of peak `height` (h_s).
    Sinusoid {
        /// Peak swing height h_s, m.
        height: R,
    },
}

/// Everything about the gait that is not a footstep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaitParams<R> {
    /// The pendulum model and its constants.
    pub model: Model<R>,
    /// Step timing.
    pub timing: Timing<R>,
    /// The ZMP reference shape.
    pub zmp: ZmpShape<R>,
    /// The swing-foot profile.
    pub swing: SwingShape<R>,
    /// Standing time before the first step, during which the CoM gets under way, s.
    pub lead_in: R,
    /// Standing time after the last step, during which the CoM settles, s.
    pub lead_out: R,
}

/// The longest segment the sampler accepts (its local time runs in u32 nanoseconds), s.
pub const MAX_SEGMENT: f64 = 4.0;

/// A duration rounded to whole microseconds (the sampler's time grid).
pub fn quantize<R: Real>(s: R) -> R {
    R::of(libm::round(s.to_f64() * 1e6) * 1e-6)
}

impl<R: Real> GaitParams<R> {
    /// The same parameters with every duration rounded to whole microseconds.
    pub fn quantized(&self) -> Self {
        let t = self.timing;
        GaitParams {
            timing: Timing {
                t1: quantize(t.t1),
                t2: quantize(t.t2),
                period: quantize(t.period),
            },
            lead_in: quantize(self.lead_in),
            lead_out: quantize(self.lead_out),
            ..*self
        }
    }

    /// Checks the parameters against the robot (phase times, ZMP offsets on the sole, …).
    pub fn validate(&self, robot: &Robot) -> Result<(), GaitError> {
        let t = &self.timing;
        let nums = [t.t1, t.t2, t.period, self.lead_in, self.lead_out];
        if nums.iter().any(|v| !v.is_finite()) {
            return Err(GaitError::NonFinite);
        }
        if t.period <= R::zero() || self.lead_in <= R::zero() || self.lead_out <= R::zero() {
            return Err(GaitError::NonPositivePeriod);
        }
        let max = R::of(MAX_SEGMENT);
        if t.period > max || self.lead_in > max || self.lead_out > max {
            return Err(GaitError::PeriodTooLong);
        }
        if !(t.t1 > R::zero() && t.t1 < t.t2 && t.t2 < t.period) {
            return Err(GaitError::BadPhaseTimes);
        }
        self.zmp.validate(robot)?;
        match self.swing {
            SwingShape::Cycloid { height, width } => {
                if !(height.is_finite() && width.is_finite()) {
                    return Err(GaitError::NonFinite);
                }
                if height < R::zero() || width < R::zero() {
                    return Err(GaitError::NonPositiveLength);
                }
            }
            SwingShape::Sinusoid { height } => {
                if !height.is_finite() {
                    return Err(GaitError::NonFinite);
                }
                if height < R::zero() {
                    return Err(GaitError::NonPositiveLength);
                }
            }
        }
        let m = &self.model;
        if !(m.omega.is_finite() && m.omega > R::zero()) {
            return Err(GaitError::NonPositiveParameter);
        }
        Ok(())
    }
}

/// How far a step may go, relative to the support foot's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepLimits {
    /// Largest forward or backward distance between the feet, m.
    pub max_length: f64,
    /// Smallest lateral distance between the feet (no collision), m.
    pub min_width: f64,
    /// Largest lateral distance between the feet, m.
    pub max_width: f64,
    /// Largest heading change between the feet, rad.
    pub max_turn: f64,
}

impl StepLimits {
    /// Limits from the leg geometry at CoM height `z_c`: with the pelvis midway between the
    /// feet, each ankle may sit at most √(L² − h²) from under its hip, L = 0.95·(thigh + calf),
    /// h = z_c − hip yaw joint's height − ankle height (the hip's roll and pitch axes lie that
    /// far below the pelvis point); the soles lie `sole_offset` outward of the ankles.
    pub fn for_robot(robot: &Robot, z_c: f64) -> StepLimits {
        let g = &robot.geometry;
        let l = 0.95 * (g.thigh + g.calf);
        let h = z_c - g.hip_yaw_height - g.ankle_height;
        let reach = if l > h {
            libm::sqrt(l * l - h * h)
        } else {
            0.0
        };
        let yaw = robot
            .joint_limits
            .first()
            .map(|j| j.max.min(-j.min))
            .unwrap_or(0.0);
        StepLimits {
            max_length: 2.0 * reach,
            min_width: g.sole_width + 0.01,
            max_width: 2.0 * (g.hip_offset_y + g.sole_offset[1]) + 2.0 * reach,
            max_turn: yaw,
        }
    }

    /// Checks `to` (a `side` foot) against the support foot at `support`.
    pub fn check<R: Real>(
        &self,
        side: Side,
        support: &Place<R>,
        to: &Place<R>,
    ) -> Result<(), GaitError> {
        if !to.is_finite() {
            return Err(GaitError::NonFinite);
        }
        // In the plan's own scalar type: no f64 trigonometry on the target.
        let dx = to.x - support.x;
        let dy = to.y - support.y;
        let (s, c) = (support.yaw.sin(), support.yaw.cos());
        let fwd = (c * dx + s * dy).to_f64();
        let lat = ((c * dy - s * dx) * R::of(side.sign())).to_f64();
        let turn = crate::trajectory::swing::wrap_pi(to.yaw - support.yaw).to_f64();
        if libm::fabs(fwd) > self.max_length
            || lat < self.min_width
            || lat > self.max_width
            || libm::fabs(turn) > self.max_turn
        {
            return Err(GaitError::StepOutOfReach);
        }
        Ok(())
    }
}

/// One queued step with what the sampler needs precomputed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepEntry<R> {
    /// The footstep.
    pub step: Footstep<R>,
    /// Where the swing foot lifts off.
    pub from: Place<R>,
    /// The support foot during this step.
    pub support: Place<R>,
    /// ZMP at the start of the step (the boundary point with the previous step), m.
    pub zmp_start: [R; 2],
    /// Divergent component of motion ξ = x + ẋ/ω at the end of the step, m.
    pub dcm_end: [R; 2],
}

/// A footstep plan with room for `N` queued steps.
#[derive(Clone, Debug)]
pub struct Plan<R, const N: usize> {
    params: GaitParams<R>,
    limits: StepLimits,
    /// Feet before the first queued step (left, right).
    start: [Place<R>; 2],
    /// Feet after the last queued step (left, right).
    end: [Place<R>; 2],
    steps: Deque<StepEntry<R>, N>,
}

impl<R: Real, const N: usize> Plan<R, N> {
    /// An empty plan standing on `left` and `right`.
    pub fn new(
        robot: &Robot,
        params: GaitParams<R>,
        left: Place<R>,
        right: Place<R>,
    ) -> Result<Self, GaitError> {
        let mut plan = Plan::idle();
        plan.reset(robot, params, left, right)?;
        Ok(plan)
    }

    /// Storage for a plan, not a plan: all-zero parameters that would not validate, no step.
    /// [`Plan::reset`] (or [`ForwardWalk::plan_into`]) makes it one in place. `no_std` has no
    /// `Box`: a firmware fills one plan where it lives instead of moving a plan of ≈ 56·N bytes
    /// up the stack through `Result`s.
    // Inline: the storage is then written where it lives, not built on the stack and copied.
    #[inline(always)]
    pub fn idle() -> Self {
        let zero = R::zero();
        Plan {
            params: GaitParams {
                model: Model {
                    kind: ModelKind::Lipm,
                    z_c: zero,
                    t_tf: zero,
                    omega: zero,
                    inv_c_tau_sq: zero,
                    tau_to_offset: zero,
                    inertia: zero,
                },
                timing: Timing {
                    t1: zero,
                    t2: zero,
                    period: zero,
                },
                zmp: ZmpShape::Natural {
                    d1: zero,
                    d2: zero,
                    a: zero,
                },
                swing: SwingShape::Cycloid {
                    height: zero,
                    width: zero,
                },
                lead_in: zero,
                lead_out: zero,
            },
            limits: StepLimits {
                max_length: 0.0,
                min_width: 0.0,
                max_width: 0.0,
                max_turn: 0.0,
            },
            start: [Place::default(); 2],
            end: [Place::default(); 2],
            steps: Deque::new(),
        }
    }

    /// Makes this plan, in place, the empty plan [`Plan::new`] would return (standing on `left`
    /// and `right`, no step queued). On an error it is left as it was.
    pub fn reset(
        &mut self,
        robot: &Robot,
        params: GaitParams<R>,
        left: Place<R>,
        right: Place<R>,
    ) -> Result<(), GaitError> {
        params.validate(robot)?;
        let params = params.quantized();
        params.validate(robot)?;
        if !(left.is_finite() && right.is_finite()) {
            return Err(GaitError::NonFinite);
        }
        let limits = StepLimits::for_robot(robot, params.model.z_c.to_f64());
        limits.check(Side::Left, &right, &left)?;
        self.params = params;
        self.limits = limits;
        self.start = [left, right];
        self.end = [left, right];
        self.steps.clear();
        Ok(())
    }

    /// The gait parameters.
    pub fn params(&self) -> &GaitParams<R> {
        &self.params
    }
    /// The reach limits the plan checks steps against.
    pub fn limits(&self) -> &StepLimits {
        &self.limits
    }
    /// Number of queued steps.
    pub fn len(&self) -> usize {
        self.steps.len()
    }
    /// True when no step is queued.
    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }
    /// Capacity of the queue.
    pub fn capacity(&self) -> usize {
        N
    }
    /// The queued step `i` (0 = the next or current one).
    pub fn step(&self, i: usize) -> Option<&StepEntry<R>> {
        self.steps.iter().nth(i)
    }
    /// Feet (left, right) before the first queued step.
    pub fn start_feet(&self) -> [Place<R>; 2] {
        self.start
    }
    /// Feet (left, right) after the last queued step.
    pub fn end_feet(&self) -> [Place<R>; 2] {
        self.end
    }
    /// ZMP while standing before the first queued step: the midpoint of the feet.
    pub fn start_zmp(&self) -> [R; 2] {
        midpoint(&self.start)
    }
    /// ZMP at rest after the last step: the midpoint of the final feet.
    pub fn end_zmp(&self) -> [R; 2] {
        midpoint(&self.end)
    }

    /// Appends a footstep to the queue (the plan is a queue: a host can steer step by step).
    pub fn push(&mut self, step: Footstep<R>) -> Result<(), GaitError> {
        let support = self.end[step.side.other().index()];
        self.limits.check(step.side, &support, &step.place)?;
        if self.steps.is_full() {
            return Err(GaitError::CapacityExceeded);
        }
        let from = self.end[step.side.index()];
        let zmp_start = match self.steps.back() {
            None => midpoint(&self.end),
            Some(prev) => self
                .params
                .zmp
                .boundary(&self.params.timing, &prev.support, &support),
        };
        let entry = StepEntry {
            step,
            from,
            support,
            zmp_start,
            dcm_end: [R::zero(); 2],
        };
        if self.steps.push_back(entry).is_err() {
            return Err(GaitError::CapacityExceeded);
        }
        if let Some(e) = self.end.get_mut(step.side.index()) {
            *e = step.place;
        }
        self.update_dcm();
        Ok(())
    }

    /// Removes the first queued step once it has been walked; the start stance moves on.
    pub fn pop_front(&mut self) -> Option<StepEntry<R>> {
        let e = self.steps.pop_front()?;
        if let Some(s) = self.start.get_mut(e.step.side.index()) {
            *s = e.step.place;
        }
        // The new first step starts from the boundary point it already has.
        Some(e)
    }

    /// ZMP knots of queued step `i`: at t = 0, t1, t2 and T (see [`crate::trajectory::zmp`]).
    pub fn knots(&self, i: usize) -> Option<[[R; 2]; 4]> {
        let e = self.step(i)?;
        let end = match self.step(i + 1) {
            Some(n) => n.zmp_start,
            None => self.end_zmp(),
        };
        let (a0, a1) = self.params.zmp.single_support_offsets();
        let sc = e.support.yaw.sin_cos();
        Some([
            e.zmp_start,
            e.support.ahead_with(-a0, sc),
            e.support.ahead_with(a1, sc),
            end,
        ])
    }

    /// Recomputes the divergent component of motion backward from the final rest state
    /// (ξ_end = p_end): the bounded solution of the ODE (see [`crate::trajectory::com`]).
    fn update_dcm(&mut self) {
        let mut xi = self.end_zmp();
        let n = self.steps.len();
        let (w, t) = (self.params.model.omega, self.params.timing);
        let durs = [t.t1, t.t2 - t.t1, t.period - t.t2];
        for i in (0..n).rev() {
            let knots = match self.knots(i) {
                Some(k) => k,
                None => return,
            };
            if let Some(e) = self.steps.iter_mut().nth(i) {
                e.dcm_end = xi;
            }
            for seg in (0..3).rev() {
                let (p0, p1, d) = (knots[seg], knots[seg + 1], durs[seg]);
                xi = crate::trajectory::com::dcm_back(w, p0, p1, d, xi);
            }
        }
    }

    /// The DCM at the start of the first queued step (or the rest point when empty).
    pub fn dcm_at_first_step(&self) -> [R; 2] {
        match self.knots(0) {
            None => self.end_zmp(),
            Some(k) => {
                let t = self.params.timing;
                let durs = [t.t1, t.t2 - t.t1, t.period - t.t2];
                let mut xi = self.steps.front().map(|e| e.dcm_end).unwrap_or(k[3]);
                for seg in (0..3).rev() {
                    xi = crate::trajectory::com::dcm_back(
                        self.params.model.omega,
                        k[seg],
                        k[seg + 1],
                        durs[seg],
                        xi,
                    );
                }
                xi
            }
        }
    }
}

fn midpoint<R: Real>(f: &[Place<R>; 2]) -> [R; 2] {
    let h = R::of(0.5);
    [(f[0].x + f[1].x) * h, (f[0].y + f[1].y) * h]
}

/// Seed 000's forward walk (eqs 6-8) with its Table 2 parameters as a preset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForwardWalk {
    /// Step length S_L, m (eq 6).
    pub step_length: f64,
    /// Half the distance between the feet S_W, m (eq 7).
    pub step_width: f64,
    /// S_first (eq 8): −1 left foot swings first (right foot supports first), +1 right first.
    pub s_first: i8,
    /// Number of steps N.
    pub steps: usize,
    /// d_1: ZMP start behind the support foot at t = 0, m (eq 10).
    pub d1: f64,
    /// d_2: ZMP end ahead of the support foot at t = T, m (eq 10).
    pub d2: f64,
    /// a: half the ZMP travel under the sole in single support, m (eq 10).
    pub a: f64,
    /// CoM height z_c, m.
    pub z_c: f64,
    /// Swing bulge W_y, m (eq 27).
    pub w_y: f64,
    /// Swing height H_z, m (eq 27).
    pub h_z: f64,
    /// t1, s.
    pub t1: f64,
    /// t2, s.
    pub t2: f64,
    /// Step period T, s.
    pub period: f64,
    /// Lead-in standing time, s.
    pub lead_in: f64,
    /// Lead-out standing time, s.
    pub lead_out: f64,
}

impl ForwardWalk {
    /// Seed 000 Table 2: S_L 0.02, S_W 0.045, S_first −1, d1 = d2 = 0.01, a 0.004, z_c 0.217,
    /// W_y 0, H_z 0.03, t1 0.15, t2 0.49, T 0.64, N 14; lead-in and lead-out 1.6 s (ours).
    pub const fn table2() -> ForwardWalk {
        ForwardWalk {
            step_length: 0.02,
            step_width: 0.045,
            s_first: -1,
            steps: 14,
            d1: 0.01,
            d2: 0.01,
            a: 0.004,
            z_c: 0.217,
            w_y: 0.0,
            h_z: 0.03,
            t1: 0.15,
            t2: 0.49,
            period: 0.64,
            lead_in: 1.6,
            lead_out: 1.6,
        }
    }

    /// The gait parameters of this walk for `model`.
    pub fn params<R: Real>(&self, model: Model<R>) -> GaitParams<R> {
        GaitParams {
            model,
            timing: Timing {
                t1: R::of(self.t1),
                t2: R::of(self.t2),
                period: R::of(self.period),
            },
            zmp: ZmpShape::Natural {
                d1: R::of(self.d1),
                d2: R::of(self.d2),
                a: R::of(self.a),
            },
            swing: SwingShape::Cycloid {
                height: R::of(self.h_z),
                width: R::of(self.w_y),
            },
            lead_in: R::of(self.lead_in),
            lead_out: R::of(self.lead_out),
        }
    }

    /// The plan of this walk for the pendulum model `kind` at this walk's z_c (model, gait
    /// parameters and footsteps in one call).
    pub fn model_plan<R: Real, const N: usize>(
        &self,
        robot: &Robot,
        kind: crate::ModelKind,
    ) -> Result<Plan<R, N>, GaitError> {
        let model = Model::<R>::new(kind, robot, self.z_c)?;
        self.plan(robot, self.params(model))
    }

    /// Support-foot location p^c_n of step n (eqs 6-7).
    pub fn support_location(&self, n: usize) -> (f64, f64) {
        let sign = if n.is_multiple_of(2) { 1.0 } else { -1.0 };
        (
            n as f64 * self.step_length,
            f64::from(self.s_first) * self.step_width * sign,
        )
    }

    /// Builds the plan (feet side by side at x = 0 to start; see the module doc).
    pub fn plan<R: Real, const N: usize>(
        &self,
        robot: &Robot,
        params: GaitParams<R>,
    ) -> Result<Plan<R, N>, GaitError> {
        let mut plan = Plan::idle();
        self.plan_into(robot, params, &mut plan)?;
        Ok(plan)
    }

    /// [`ForwardWalk::plan`] written into `plan` in place (its previous content is replaced;
    /// after an error it may hold part of the walk: rebuild it before use).
    pub fn plan_into<R: Real, const N: usize>(
        &self,
        robot: &Robot,
        params: GaitParams<R>,
        plan: &mut Plan<R, N>,
    ) -> Result<(), GaitError> {
        if self.steps == 0 {
            return Err(GaitError::EmptyPlan);
        }
        if self.steps > N {
            return Err(GaitError::CapacityExceeded);
        }
        if !(self.s_first == -1 || self.s_first == 1) {
            return Err(GaitError::BadStartFoot);
        }
        let w = self.step_width;
        plan.reset(
            robot,
            params,
            Place::new(0.0, w, 0.0),
            Place::new(0.0, -w, 0.0),
        )?;
        // S_first = −1: the right foot supports step 0, so the left foot swings first.
        let first_swing = if self.s_first < 0 {
            Side::Left
        } else {
            Side::Right
        };
        for n in 0..self.steps {
            let side = if n.is_multiple_of(2) {
                first_swing
            } else {
                first_swing.other()
            };
            let x = if n + 1 == self.steps {
                n as f64
            } else {
                (n + 1) as f64
            } * self.step_length;
            let y = side.sign() * w;
            plan.push(Footstep {
                side,
                place: Place::new(x, y, 0.0),
            })?;
        }
        Ok(())
    }
}
