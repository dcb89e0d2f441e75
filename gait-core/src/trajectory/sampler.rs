//! The streaming sampler: every dt it yields the ZMP reference, the CoM position and velocity,
//! both feet and the support phase, with O(1) work and no allocation per sample.
//!
//! Time runs in integer nanoseconds (u64, no drift at any servo rate); each segment is evaluated
//! in its own local time (u32 ns → seconds), so nothing grows with the length of the walk.
//! The timeline: lead-in (standing, ZMP between the feet, CoM gets under way), the queued steps
//! (three ZMP segments each: double support, single support, double support), lead-out
//! (standing, CoM settles), then done (the final pose is held). Seed 000's t = 0 is the end of
//! the lead-in ([`Sampler::walk_start_ns`]).
//!
//! Per sample: two `exp` calls for the CoM (com.rs C1-C2), the swing-foot profile (swing.rs),
//! and the τ response (com.rs C6). At each segment boundary: one or two DCM back-steps (C4).

use crate::error::GaitError;
use crate::maths::real::Real;
use crate::robot::Side;
use crate::trajectory::com::{decay, ComSegment, TauResponse, ZmpSpan};
use crate::trajectory::plan::{Footstep, Place, Plan};
use crate::trajectory::swing::{swing_foot, FootSample};

/// Largest |τ| the sampler accepts, N·m; larger measured values are clamped (a kid-size upper
/// body with J = 0.026 kg·m² reaches this only at φ̈ ≈ 1900 rad/s², i.e. a sensor fault).
pub const TAU_LIMIT: f64 = 50.0;

/// Which feet carry the robot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SupportPhase {
    /// Standing on both feet before the first or after the last step.
    Standing,
    /// Double support inside a step.
    Double,
    /// Single support on the given foot (the other one swings).
    Single(Side),
}

impl SupportPhase {
    /// The swinging foot: the one not in support in single support, none otherwise.
    pub fn swing(self) -> Option<Side> {
        match self {
            SupportPhase::Single(stance) => Some(stance.other()),
            SupportPhase::Standing | SupportPhase::Double => None,
        }
    }
}

/// One sample of the gait.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaitSample<R> {
    /// Time since the start of the lead-in, ns.
    pub time_ns: u64,
    /// ZMP reference (x, y), m.
    pub zmp: [R; 2],
    /// CoM / pelvis point (x, y, z_c), m.
    pub com: [R; 3],
    /// CoM velocity (x, y), m/s.
    pub com_vel: [R; 2],
    /// Left and right foot (sole point), world frame.
    pub feet: [FootSample<R>; 2],
    /// Support phase.
    pub phase: SupportPhase,
    /// The support foot in this step (the one that does not swing); `None` while standing.
    pub support_foot: Option<Side>,
    /// Number of steps completed.
    pub steps_done: u32,
}

impl<R: Real> GaitSample<R> {
    /// A zero sample (time 0, everything at the origin, standing): storage that a real sample
    /// overwrites before it is read.
    #[inline]
    pub fn zero() -> Self {
        let zero = R::zero();
        let foot = FootSample {
            x: zero,
            y: zero,
            z: zero,
            yaw: zero,
        };
        GaitSample {
            time_ns: 0,
            zmp: [zero; 2],
            com: [zero; 3],
            com_vel: [zero; 2],
            feet: [foot; 2],
            phase: SupportPhase::Standing,
            support_foot: None,
            steps_done: 0,
        }
    }

    /// True when every number of the sample is finite.
    pub fn is_finite(&self) -> bool {
        self.zmp
            .iter()
            .chain(self.com.iter())
            .chain(self.com_vel.iter())
            .all(|v| v.is_finite())
            && self
                .feet
                .iter()
                .all(|f| f.x.is_finite() && f.y.is_finite() && f.z.is_finite() && f.yaw.is_finite())
    }
}

impl GaitSample<f32> {
    /// The left foot's share α of the weight the ZMP reference puts on the soles: its place
    /// along the segment from the right sole point to the left one,
    /// α = sat₀¹((p_ref − p_R)·(p_L − p_R)/|p_L − p_R|²); ½ when the soles coincide or a
    /// number is not finite. The right foot carries 1 − α.
    pub fn left_share(&self) -> f32 {
        let [l, r] = &self.feet;
        let (ax, ay) = (l.x - r.x, l.y - r.y);
        let n2 = ax * ax + ay * ay;
        let alpha = if n2 > 1e-8 {
            (((self.zmp[0] - r.x) * ax + (self.zmp[1] - r.y) * ay) / n2).clamp(0.0, 1.0)
        } else {
            0.5
        };
        if alpha.is_finite() {
            alpha
        } else {
            0.5
        }
    }

    /// The soles' loads the ZMP reference plans, as shares of the weight (left, right; they
    /// sum to 1): what a robot without foot sensors takes for the measured loads' split.
    pub fn planned_load_shares(&self) -> [f32; 2] {
        let a = self.left_share();
        [a, 1.0 - a]
    }
}

/// The three segments of one step (seed 000: 0 … t1 … t2 … T).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StepPhase {
    /// 0 … t1: double support, the swing foot still on its lift-off place.
    FirstDouble,
    /// t1 … t2: single support, the swing foot in the air.
    Single,
    /// t2 … T: double support, the swing foot on its touch-down place.
    SecondDouble,
}

impl StepPhase {
    /// The segment's index in the step's ZMP knots and phase durations (0, 1, 2).
    pub const fn index(self) -> usize {
        match self {
            StepPhase::FirstDouble => 0,
            StepPhase::Single => 1,
            StepPhase::SecondDouble => 2,
        }
    }

    /// The next segment of the same step (`None` after the second double support).
    pub const fn next(self) -> Option<StepPhase> {
        match self {
            StepPhase::FirstDouble => Some(StepPhase::Single),
            StepPhase::Single => Some(StepPhase::SecondDouble),
            StepPhase::SecondDouble => None,
        }
    }
}

/// The step being walked: which foot swings, from where to where, and in which segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentStep<R> {
    /// The swing foot.
    pub swing: Side,
    /// Its lift-off place.
    pub from: Place<R>,
    /// Its touch-down place.
    pub to: Place<R>,
    /// The segment of the step.
    pub phase: StepPhase,
}

/// Where the sampler is on the timeline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Stage {
    /// Standing before the first step.
    LeadIn,
    /// In the first queued step, in the given segment.
    Step(StepPhase),
    /// Standing after the last step.
    LeadOut,
    /// The walk is over; the final pose is held.
    Done,
}

/// The streaming gait sampler over a plan with room for `N` steps.
#[derive(Clone, Debug)]
pub struct Sampler<R, const N: usize> {
    plan: Plan<R, N>,
    stage: Stage,
    seg: ComSegment<R>,
    seg_start_ns: u64,
    seg_len_ns: u64,
    now_ns: u64,
    dt_ns: u64,
    decay_dt: R,
    decays: SegmentDecays<R>,
    tau: TauResponse<R>,
    feet: [Place<R>; 2],
    steps_done: u32,
    walk_start_ns: u64,
}

/// Seconds to nanoseconds, rounded to whole microseconds: an f32 duration ≤ 4 s is exact to
/// ±0.25 µs, so f32 and f64 plans switch phases on the same sample.
fn secs_to_ns<R: Real>(s: R) -> u64 {
    let v = s.to_f64() * 1e6;
    if v > 0.0 {
        libm::round(v) as u64 * 1000
    } else {
        0
    }
}

/// e^{−ωd} of the three phase durations (the DCM's back-propagation, C4) and of the segments
/// entered (lead-in, the three phases, lead-out; their durations rounded to the sample clock,
/// C5): computed once when the walk starts, so that a segment change costs no `exp` (a long
/// library call on cores without an FPU: it made the worst-case tick).
#[derive(Clone, Copy, Debug)]
struct SegmentDecays<R> {
    phases: [R; 3],
    stages: [R; 5],
}

impl<R: Real> SegmentDecays<R> {
    /// The decays for `omega` of the phase durations `phases` and of the lead-in and lead-out.
    fn of(omega: R, phases: [R; 3], lead_in: R, lead_out: R) -> Self {
        let [d1, d2, d3] = phases;
        SegmentDecays {
            phases: phases.map(|d| decay(omega, d)),
            stages: [lead_in, d1, d2, d3, lead_out].map(|d| decay(omega, clocked(d))),
        }
    }
}

/// A duration as the sampler walks it (s): rounded to the sample clock's whole µs
/// ([`secs_to_ns`]), back in `R`.
fn clocked<R: Real>(s: R) -> R {
    R::from_u32(secs_to_ns(s) as u32) * R::of(1e-9)
}

impl<R: Real, const N: usize> Sampler<R, N> {
    /// A sampler over `plan` at the servo period `dt` (1/1000 s ≤ dt ≤ 1/50 s, and no phase of
    /// the plan shorter than dt).
    pub fn new(plan: Plan<R, N>, dt: f64) -> Result<Self, GaitError> {
        let mut s = Sampler {
            plan,
            ..Sampler::idle()
        };
        s.restart(dt)?;
        Ok(s)
    }

    /// Storage for a sampler: an idle plan ([`Plan::idle`]), already done (never sampled).
    /// [`Sampler::rebuild`] makes it a sampler in place.
    // Inline: the storage is then written where it lives, not built on the stack and copied.
    #[inline(always)]
    pub fn idle() -> Self {
        Sampler {
            plan: Plan::idle(),
            stage: Stage::Done,
            seg: ComSegment::default(),
            seg_start_ns: 0,
            seg_len_ns: 0,
            now_ns: 0,
            dt_ns: 0,
            decay_dt: R::zero(),
            decays: SegmentDecays {
                phases: [R::zero(); 3],
                stages: [R::zero(); 5],
            },
            tau: TauResponse::default(),
            feet: [Place::default(); 2],
            steps_done: 0,
            walk_start_ns: 0,
        }
    }

    /// Makes this sampler, in place, the one [`Sampler::new`] would return for the plan that
    /// `fill` writes into its plan storage, at servo period `dt`. After an error it is done
    /// ([`Sampler::is_done`]) and must be rebuilt before use.
    pub fn rebuild(
        &mut self,
        fill: impl FnOnce(&mut Plan<R, N>) -> Result<(), GaitError>,
        dt: f64,
    ) -> Result<(), GaitError> {
        self.halt();
        fill(&mut self.plan)?;
        self.restart(dt)
    }

    /// Marks the walk over (an unusable sampler: a failed rebuild).
    pub(crate) fn halt(&mut self) {
        self.stage = Stage::Done;
    }

    /// Starts the walk of the present plan: the checks of [`Sampler::new`], then every field
    /// from the plan (the sampler stays done on an error).
    fn restart(&mut self, dt: f64) -> Result<(), GaitError> {
        if !dt.is_finite() {
            return Err(GaitError::NonFinite);
        }
        if !(1.0 / 1000.0 - 1e-12..=1.0 / 50.0 + 1e-12).contains(&dt) {
            return Err(GaitError::BadSampleTime);
        }
        let p = *self.plan.params();
        let t = p.timing;
        let shortest =
            t.t1.min(t.t2 - t.t1)
                .min(t.period - t.t2)
                .min(p.lead_in)
                .min(p.lead_out);
        if shortest.to_f64() < dt {
            return Err(GaitError::BadSampleTime);
        }
        let omega = p.model.omega;
        let start = self.plan.start_zmp();
        self.feet = self.plan.start_feet();
        self.stage = Stage::LeadIn;
        self.seg = ComSegment::default();
        self.seg_start_ns = 0;
        self.seg_len_ns = 0;
        self.now_ns = 0;
        self.dt_ns = libm::round(dt * 1e9) as u64;
        self.decay_dt = R::of(libm::exp(-omega.to_f64() * dt));
        self.decays = SegmentDecays::of(omega, self.phase_durations(), p.lead_in, p.lead_out);
        self.tau = TauResponse::default();
        self.steps_done = 0;
        self.walk_start_ns = secs_to_ns(p.lead_in);
        self.enter(Stage::LeadIn, start);
        Ok(())
    }

    /// The plan (its queue shrinks as steps are walked).
    pub fn plan(&self) -> &Plan<R, N> {
        &self.plan
    }
    /// Where the sampler is on the timeline.
    pub fn stage(&self) -> Stage {
        self.stage
    }
    /// The time of the next sample, ns.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }
    /// The servo period, ns.
    pub fn dt_ns(&self) -> u64 {
        self.dt_ns
    }
    /// The end of the lead-in (seed 000's t = 0), ns.
    pub fn walk_start_ns(&self) -> u64 {
        self.walk_start_ns
    }
    /// True once the lead-out is over.
    pub fn is_done(&self) -> bool {
        self.stage == Stage::Done
    }
    /// Start of the current segment, ns.
    pub fn segment_start_ns(&self) -> u64 {
        self.seg_start_ns
    }
    /// The current CoM segment (for tests and diagnostics).
    pub fn segment(&self) -> &ComSegment<R> {
        &self.seg
    }

    /// Appends a footstep while walking. Steps appended less than about 5·T_TF before they
    /// start change the CoM velocity slightly (the DCM sees its future late); append at least
    /// one step ahead. Refused once the lead-out has begun.
    pub fn push_step(&mut self, step: Footstep<R>) -> Result<(), GaitError> {
        if matches!(self.stage, Stage::LeadOut | Stage::Done) {
            return Err(GaitError::WalkEnded);
        }
        self.plan.push(step)?;
        // Re-anchor: the rest of the current segment becomes a segment of its own, starting
        // from the present CoM, with the DCM recomputed for the longer plan.
        let s = self.local_time();
        let (x, _) = self.seg.eval(self.plan.params().model.omega, s);
        let p_now = self.seg.zmp(s);
        let elapsed = self.now_ns.saturating_sub(self.seg_start_ns);
        self.seg_start_ns = self.now_ns;
        self.seg_len_ns = self.seg_len_ns.saturating_sub(elapsed);
        let knots = self.plan.knots(0);
        let (p1, xi1) = self.segment_end(self.stage, knots);
        let d = R::from_u32(self.seg_len_ns as u32) * R::of(1e-9);
        self.seg = ComSegment::new(self.plan.params().model.omega, p_now, p1, d, xi1, x);
        Ok(())
    }

    fn local_time(&self) -> R {
        let d = self
            .now_ns
            .saturating_sub(self.seg_start_ns)
            .min(self.seg_len_ns);
        R::from_u32(d as u32) * R::of(1e-9)
    }

    /// Durations of the three phases of a step, s.
    fn phase_durations(&self) -> [R; 3] {
        let t = self.plan.params().timing;
        [t.t1, t.t2 - t.t1, t.period - t.t2]
    }

    /// ZMP and DCM at the end of the segment of `stage`; `knots`: the first queued step's
    /// ([`Plan::knots`]`(0)`, computed once by the caller: each costs four sines and cosines).
    fn segment_end(&self, stage: Stage, knots: Option<[[R; 2]; 4]>) -> ([R; 2], [R; 2]) {
        let end = self.plan.end_zmp();
        match stage {
            Stage::LeadIn => (self.plan.start_zmp(), self.plan.dcm_at_first_step()),
            Stage::Step(ph) => match (knots, self.plan.step(0)) {
                (Some(k), Some(e)) => {
                    let durs = self.phase_durations();
                    let w = self.plan.params().model.omega;
                    let mut xi = e.dcm_end;
                    let mut j = 2usize;
                    while j > ph.index() {
                        let span = ZmpSpan {
                            p0: k[j],
                            p1: k[j + 1],
                            d: durs[j],
                            decay: self.decays.phases[j],
                        };
                        xi = span.dcm_back(w, xi);
                        j -= 1;
                    }
                    (k[ph.index() + 1], xi)
                }
                _ => (end, end),
            },
            Stage::LeadOut | Stage::Done => (end, end),
        }
    }

    /// Starts the segment of `stage` at the current segment end, CoM at `x0`.
    fn enter(&mut self, stage: Stage, x0: [R; 2]) {
        let p = *self.plan.params();
        let knots = match stage {
            Stage::Step(_) => self.plan.knots(0),
            _ => None,
        };
        // The start ZMP, the duration and the index of its decay in `decays.stages`.
        let (p0, dur, which) = match (stage, knots) {
            (Stage::LeadIn, _) => (self.plan.start_zmp(), p.lead_in, 0),
            (Stage::Step(ph), Some(k)) => (
                k[ph.index()],
                self.phase_durations()[ph.index()],
                1 + ph.index(),
            ),
            _ => (self.plan.end_zmp(), p.lead_out, 4),
        };
        let (p1, xi1) = self.segment_end(stage, knots);
        self.seg_len_ns = secs_to_ns(dur);
        let d = clocked(dur);
        let span = ZmpSpan {
            p0,
            p1,
            d,
            decay: self.decays.stages.get(which).copied().unwrap_or(R::zero()),
        };
        self.seg = ComSegment::over(p.model.omega, &span, xi1, x0);
        self.stage = stage;
    }

    /// Moves to the next segment when the current one is over.
    fn advance_segment(&mut self) {
        let omega = self.plan.params().model.omega;
        let x_end = self.seg.end_position(omega);
        let next = match self.stage {
            Stage::LeadIn => {
                if self.plan.is_empty() {
                    Stage::LeadOut
                } else {
                    Stage::Step(StepPhase::FirstDouble)
                }
            }
            Stage::Step(ph) => match ph.next() {
                Some(n) => Stage::Step(n),
                None => {
                    if let Some(e) = self.plan.pop_front() {
                        if let Some(f) = self.feet.get_mut(e.step.side.index()) {
                            *f = e.step.place;
                        }
                        self.steps_done = self.steps_done.saturating_add(1);
                    }
                    if self.plan.is_empty() {
                        Stage::LeadOut
                    } else {
                        Stage::Step(StepPhase::FirstDouble)
                    }
                }
            },
            Stage::LeadOut | Stage::Done => Stage::Done,
        };
        self.seg_start_ns = self.seg_start_ns.saturating_add(self.seg_len_ns);
        if next == Stage::Done {
            // Hold the final segment frozen at its end.
            self.stage = Stage::Done;
            self.seg_start_ns = self.seg_start_ns.saturating_sub(self.seg_len_ns);
            return;
        }
        self.enter(next, x_end);
    }

    /// Moves to the segment that contains the current time; true when the segment changed.
    pub fn sync(&mut self) -> bool {
        let mut changed = false;
        for _ in 0..4 {
            if self.stage == Stage::Done
                || self.now_ns < self.seg_start_ns.saturating_add(self.seg_len_ns)
            {
                break;
            }
            self.advance_segment();
            changed = true;
        }
        changed
    }

    /// Local time in the current segment, ns (clamped to the segment).
    pub fn local_ns(&self) -> u32 {
        self.now_ns
            .saturating_sub(self.seg_start_ns)
            .min(self.seg_len_ns) as u32
    }

    /// Moves the clock on by one servo period.
    pub fn tick(&mut self) {
        self.now_ns = self.now_ns.saturating_add(self.dt_ns);
    }

    /// Steps completed so far.
    pub fn steps_done(&self) -> u32 {
        self.steps_done
    }

    /// Feet on the ground (left, right) at the last step change.
    pub fn stance_feet(&self) -> [Place<R>; 2] {
        self.feet
    }

    /// The step being walked (`None` while standing).
    pub fn current_step(&self) -> Option<CurrentStep<R>> {
        match (self.stage, self.plan.step(0)) {
            (Stage::Step(phase), Some(e)) => Some(CurrentStep {
                swing: e.step.side,
                from: e.from,
                to: e.step.place,
                phase,
            }),
            _ => None,
        }
    }

    /// The exact solver's CoM position and velocity (x, y) at the time of the next sample,
    /// without the τ response (what [`Sampler::next`] adds it to).
    pub fn com_now(&mut self) -> ([R; 2], [R; 2]) {
        self.sync();
        self.seg
            .eval(self.plan.params().model.omega, self.local_time())
    }

    /// The sample at the current time, with the measured torque `tau` (N·m, τ = J·φ̈) held
    /// until the next sample; then advances by dt. A non-finite τ counts as 0.
    pub fn next(&mut self, tau: R) -> GaitSample<R> {
        self.sync();
        let p = *self.plan.params();
        let omega = p.model.omega;
        let lim = R::of(TAU_LIMIT);
        let tau = if tau.is_finite() {
            tau.clamp_to(-lim, lim)
        } else {
            R::zero()
        };
        self.tau.hold(tau, p.model.tau_to_offset);
        let s = self.local_time();
        let (x, v) = self.seg.eval(omega, s);
        let zmp = self.seg.zmp(s);
        let (phase, support, feet) = self.feet_now(s);
        let sample = GaitSample {
            time_ns: self.now_ns,
            zmp,
            com: [x[0] + self.tau.offset, x[1], p.model.z_c],
            com_vel: [v[0] + self.tau.velocity(omega), v[1]],
            feet,
            phase,
            support_foot: support,
            steps_done: self.steps_done,
        };
        self.tau.advance(self.decay_dt);
        self.tick();
        sample
    }

    /// Support phase and support foot now.
    pub fn phase(&self) -> (SupportPhase, Option<Side>) {
        match self.current_step() {
            Some(CurrentStep {
                swing,
                phase: StepPhase::Single,
                ..
            }) => (SupportPhase::Single(swing.other()), Some(swing.other())),
            Some(step) => (SupportPhase::Double, Some(step.swing.other())),
            None => (SupportPhase::Standing, None),
        }
    }

    fn feet_now(&self, s: R) -> (SupportPhase, Option<Side>, [FootSample<R>; 2]) {
        let mut feet = [
            FootSample::on_ground(&self.feet[0]),
            FootSample::on_ground(&self.feet[1]),
        ];
        match (self.stage, self.plan.step(0)) {
            (Stage::Step(ph), Some(e)) => {
                let side = e.step.side;
                let support = side.other();
                let phase = if ph == StepPhase::Single {
                    let u = if self.seg.duration > R::zero() {
                        s / self.seg.duration
                    } else {
                        R::one()
                    };
                    let f = swing_foot(
                        &self.plan.params().swing,
                        &e.from,
                        &e.step.place,
                        u,
                        R::of(side.sign()),
                    );
                    if let Some(slot) = feet.get_mut(side.index()) {
                        *slot = f;
                    }
                    SupportPhase::Single(support)
                } else {
                    if ph == StepPhase::SecondDouble {
                        if let Some(slot) = feet.get_mut(side.index()) {
                            *slot = FootSample::on_ground(&e.step.place);
                        }
                    }
                    SupportPhase::Double
                };
                (phase, Some(support), feet)
            }
            _ => (SupportPhase::Standing, None, feet),
        }
    }
}
