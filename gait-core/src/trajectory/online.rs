//! Online walking: footsteps from velocity commands ([`crate::trajectory::command::StepGenerator`]) and the
//! CoM from a bounded preview of the divergent component of motion (DCM), one sample per tick,
//! in walk modes with explicit transitions (standing, starting, walking, stopping).
//!
//! # Model (LIPM, height z_c, ω = √(g/z_c))
//! CoM x (horizontal, per axis), ZMP p, DCM ξ = x + ẋ/ω:
//!
//! ```text
//!   ẍ = ω²(x − p),      ξ̇ = ω(ξ − p),      ẋ = ω(ξ − x)                           (D1)
//! ```
//!
//! **Reference (ZMP per step, transferred in double support).** Step i (period T, lift-off t1,
//! touch-down t2) stands on support point p_i (the support foot's sole point moved
//! [`OnlineParams::zmp_inset`] towards the other foot). Its ZMP reference runs in three linear
//! segments: from a_i (the feet's midpoint at the step's start) to p_i over [0, t1], p_i over
//! [t1, t2], from p_i to b_i (the midpoint once the swing foot landed, = a_{i+1}) over [t2, T]:
//! continuous. On a segment of duration Δ where the ZMP goes from p_a to p_b (slope
//! s = (p_b − p_a)/Δ), (D1) gives, from ξ at the segment's end,
//!
//! ```text
//!   ξ(τ) = p(τ) + s/ω + e^{ω(τ−Δ)}(ξ_end − p_b − s/ω)                                  (D2)
//! ```
//!
//! The preview holds the current step and the next [`PREVIEW_STEPS`] steps of the generator
//! under the present command (fewer once it stands under the zero command) and ends at rest:
//! after the last previewed step ξ rests on the final feet's midpoint. (D2) applied backwards
//! through the previewed steps' segments gives ξ_eos,0, the end of the current step, and
//! through the current step's segments ξ_ref(t) and p_ref(t) at its time t (at most three
//! exponentials per tick). The preview is computed again when a step starts and when the
//! command changes (at most 1 + [`PREVIEW_STEPS`] generator steps), never per tick; the
//! current step's landing place is never changed once the step began.
//!
//! **Tracking (DCM feedback).** The commanded ZMP is
//!
//! ```text
//!   p_cmd = p_ref + (1 + k/ω)(ξ − ξ_ref),   p_ref = ξ_ref − ξ̇_ref/ω                    (D3)
//! ```
//!
//! (k = ω), clamped per axis to [`ZMP_MARGIN`] around the support point in single support,
//! around the box of both feet on two feet. A re-plan
//! changes ξ_ref, never the state: the CoM is integrated exactly over one tick dt with the
//! constant p_cmd,
//!
//! ```text
//!   x⁺ = p + (x − p)·cosh ωdt + (ẋ/ω)·sinh ωdt,   ẋ⁺ = ω(x − p)·sinh ωdt + ẋ·cosh ωdt    (D4)
//! ```
//!
//! so CoM position and velocity are continuous whatever the commands: per tick
//! |Δẋ| ≤ ω·sinh(ωdt)·|x − p| + (cosh ωdt − 1)·|ẋ| (the bound the tests assert).
//!
//! **Modes.** [`Standing`]: ZMP reference on the feet's midpoint (D3 holds the CoM there);
//! a non-zero command (or a listed step) starts. [`Starting`]: one period T on both feet with a constant ZMP
//! p_s chosen so that ξ reaches the first step's ξ_ini at the end,
//! p_s = (ξ_ini − e^{ωT}ξ₀)/(1 − e^{ωT}) (from D1), clamped to the feet. [`Walking`]: steps
//! of the generator under the present command; a zero command at a step's end goes to
//! [`Stopping`]: steps under the zero command (the generator decelerates within its limits and
//! closes the feet) until it stands, then [`Standing`]; a non-zero command in stopping walks
//! again. Transitions happen at step boundaries only (the swing foot's landing is committed),
//! except Standing → Starting. (A catching step of the closed-loop issue would be one more
//! mode entered from any other, with its own preview.)
//!
//! **Footstep lists.** [`OnlineWalk::push_step`] queues explicit steps (at most
//! [`STEP_QUEUE_LEN`]): each is the swing foot's travel d of (S2) ([`StepGenerator::next_step_given`],
//! within the same limits), walked before the command's steps and previewed like them. A
//! standing walk starts with the first one's foot; a step queued for the foot that does not
//! swing next gets an in-place step first. With the zero command the walk stops after the last
//! listed step (the generator decelerates from the listed steps' velocity and closes the feet).
//!
//! **Heading hold.** The feet's planned yaw drifts from the robot's in the world when the
//! soles slip in yaw (turning, side steps). With the measured heading ψ (the gyro's yaw
//! integrated, [`OnlineWalk::set_heading`]), Σδ the corrections stepped so far and δ₋ the last
//! one, the commanded heading and its error when a walking step begins (both feet on the
//! ground) are
//!
//! ```text
//!   θ_c = mid(θ_L, θ_R) − Σδ + δ₋/2,      e = wrap(ψ − θ_c)                             (H1)
//! ```
//!
//! (mid: the feet's mean yaw; a correction enters every later footprint through the support
//! foot, so the feet's mean holds all of Σδ but half of the last one), and the step turns the
//! swing foot by
//!
//! ```text
//!   δ = clamp(−k·e, ±δ_max)      (k = `heading_gain`, δ_max = MAX_HEADING_TURN)          (H2)
//! ```
//!
//! on top of the command's turn ((S3) of [`crate::trajectory::command`]; scaled with the step by the
//! limits, the stepped λ·δ is what Σδ adds). Not in the start phase nor while stopping: a stop
//! ends with the feet parallel as commanded.
//!
//! **Position hold.** The feet land where the servos put them, not where the plan does (a
//! stance leg that yields under the robot's weight lands every step long, more so the faster
//! the walk): the walk drifts ahead of its commands. With the leg odometry's survey of each
//! landing ([`crate::measure::odometry`]; [`OnlineWalk::set_landing_offset`]: the surveyed place minus
//! the planned one, o, world frame) and Σc the position corrections stepped so far (world
//! frame), the support foot's distance from the commanded track when a walking step begins is
//!
//! ```text
//!   e = o_S + Σc                                                                         (P1)
//! ```
//!
//! (each correction moves every later footprint with it, so the planned feet are Σc off the
//! commanded track), and the step's travel is corrected by
//!
//! ```text
//!   c = R(−θ_S)·clamp(−k_p·e, ±c_max)   (k_p = `position_gain`, c_max = MAX_POSITION_SHIFT)     (P2)
//! ```
//!
//! ((S4) of [`crate::trajectory::command`], support-foot frame; the stepped λ·c, back in the world frame,
//! is what Σc adds). A landing error Δ that repeats every step leaves e = Δ/k_p: the feet keep
//! the commanded velocity, a fixed distance ahead. Only for a support foot surveyed since it
//! landed; not in the start phase, while stopping or for listed steps, like the heading hold.
//!
//! **Swing.** The swing foot follows [`crate::trajectory::swing::swing_foot`] between lift-off t1 and
//! touch-down t2 of the walk's timing; both feet are on the ground outside it.

use heapless::Deque;

use crate::error::GaitError;
use crate::maths::real::Real;
use crate::robot::{Robot, Side};
use crate::trajectory::command::{CommandLimits, StepGenerator, WalkCommand};
use crate::trajectory::plan::{Footstep, Place, SwingShape};
use crate::trajectory::sampler::{GaitSample, SupportPhase};
use crate::trajectory::swing::{swing_foot, FootSample};

/// Steps previewed beyond the current one.
pub const PREVIEW_STEPS: usize = 3;
/// Default inset of the single-support ZMP reference from the sole point towards the other
/// foot, m: the CoM swings less sideways (with Table 2's timing the LIPM swing is ≈ the full
/// half width w without it; 1.5 cm brings it near the paper walk's ±3.2 cm).
pub const DEFAULT_ZMP_INSET: f64 = 0.015;
/// Largest ZMP correction of the DCM feedback per axis, m.
pub const ZMP_MARGIN: f64 = 0.02;
/// Explicit steps the walk holds at most ([`OnlineWalk::push_step`]).
pub const STEP_QUEUE_LEN: usize = 8;

/// An explicit step of a footstep list: the swinging foot and its travel (S2's d: m, m, rad).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ListedStep<R> {
    /// The foot that swings.
    pub side: Side,
    /// Travel beyond the in-place step, in the support foot's frame (m, m, rad).
    pub d: [R; 3],
}

/// Largest heading correction of one step (H2), rad (≈ 2.9°).
pub const MAX_HEADING_TURN: f64 = 0.05;

/// Largest position correction of one step per axis (P2), m.
pub const MAX_POSITION_SHIFT: f64 = 0.02;

/// Timing and shape of the online steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OnlineParams {
    /// CoM height z_c, m.
    pub z_c: f64,
    /// Step period T, s.
    pub period: f64,
    /// Lift-off t1 and touch-down t2 inside the step, s.
    pub t1: f64,
    /// Touch-down, s.
    pub t2: f64,
    /// Nominal half width w, m.
    pub half_width: f64,
    /// Swing shape.
    pub swing: SwingShape<f64>,
    /// Command limits.
    pub limits: CommandLimits,
    /// Tick, s.
    pub dt: f64,
    /// Inset of the single-support ZMP reference towards the other foot, m.
    pub zmp_inset: f64,
    /// Heading hold (H1–H2): the share of the measured heading error each walking step turns
    /// back (0 = off, 1 = all of it), within ±[`MAX_HEADING_TURN`].
    pub heading_gain: f64,
    /// Position hold (P1–P2): the share of the surveyed feet's distance from the commanded
    /// track each walking step corrects (0 = off), within ±[`MAX_POSITION_SHIFT`].
    pub position_gain: f64,
}

/// Standing on both feet, CoM held on the feet's midpoint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Standing;

/// The weight shift before the first step: both feet down, constant ZMP `vrp`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Starting<R> {
    /// Time in the mode, s.
    pub t: R,
    /// The constant ZMP of the shift.
    pub vrp: [R; 2],
}

/// A step under way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step<R> {
    /// Time in the step, s.
    pub t: R,
    /// The support foot's place (ZMP reference p_0).
    pub support: Place<R>,
    /// The swinging foot.
    pub side: Side,
    /// Where the swing foot lifts off.
    pub from: Place<R>,
    /// Where it lands.
    pub to: Place<R>,
}

/// Walking under a non-zero command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Walking<R> {
    /// The step under way.
    pub step: Step<R>,
}

/// Walking under the zero command until the generator stands.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stopping<R> {
    /// The step under way.
    pub step: Step<R>,
}

/// The walk mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WalkMode<R> {
    /// See [`Standing`].
    Standing(Standing),
    /// See [`Starting`].
    Starting(Starting<R>),
    /// See [`Walking`].
    Walking(Walking<R>),
    /// See [`Stopping`].
    Stopping(Stopping<R>),
}

/// The online walk: modes, generator, preview, CoM state (see the module docs).
#[derive(Clone, Debug)]
pub struct OnlineWalk<R> {
    robot: Robot,
    p: OnlineParams,
    omega: R,
    /// The mode.
    mode: WalkMode<R>,
    /// The generator after the committed steps (its feet: where the feet will be at the end
    /// of the step under way).
    gen: StepGenerator<R>,
    /// The command.
    cmd: WalkCommand<R>,
    /// ξ at the end of the current step (or of the start phase), from the preview (D2).
    xi_eos: [R; 2],
    /// Feet on the ground now (left, right), before the step under way lands.
    feet: [Place<R>; 2],
    /// CoM position and velocity (x, y).
    x: [R; 2],
    v: [R; 2],
    /// The last commanded ZMP.
    zmp: [R; 2],
    /// Steps finished.
    steps_done: u32,
    /// Footsteps committed, not yet taken by [`OnlineWalk::take_footstep`] (the log).
    committed: Option<Footstep<R>>,
    time_ns: u64,
    /// The measured heading ψ (rad, same origin as the feet's yaw), if any.
    heading: Option<R>,
    /// The heading corrections stepped so far (Σδ of H2, after the limits), rad.
    turned: R,
    /// The correction λ·δ the last committed step stepped, rad (δ₋ of H1).
    stepped_turn: R,
    /// The correction δ requested for the last committed step (the generator's input), rad.
    requested_turn: R,
    /// Each foot's surveyed place minus its planned one since it landed (o of P1), m.
    landed: [Option<[R; 2]>; 2],
    /// The position corrections stepped so far (Σc of P1, world frame), m.
    shifted: [R; 2],
    /// The correction c requested for the last committed step (support frame), m.
    requested_shift: [R; 2],
    /// Explicit steps waiting (a footstep list), walked before the command's steps.
    queue: Deque<ListedStep<R>, STEP_QUEUE_LEN>,
    /// The travel of the last committed step if it was an explicit one (for the log).
    given: Option<[R; 3]>,
}

fn mid<R: Real>(a: &Place<R>, b: &Place<R>) -> [R; 2] {
    let h = R::of(0.5);
    [(a.x + b.x) * h, (a.y + b.y) * h]
}

impl<R: Real> OnlineWalk<R> {
    /// Standing with the feet at `feet` (left, right) and the CoM at rest on their midpoint.
    pub fn new(robot: &Robot, p: OnlineParams, feet: [Place<R>; 2]) -> Result<Self, GaitError> {
        let ok = [p.z_c, p.period, p.t1, p.t2, p.dt, p.half_width]
            .iter()
            .all(|v| v.is_finite())
            && p.z_c > 0.0
            && p.dt > 0.0
            && 0.0 <= p.t1
            && p.t1 < p.t2
            && p.t2 <= p.period;
        if !ok {
            return Err(GaitError::NonPositiveParameter);
        }
        let gen = Self::generator(robot, &p, feet, Side::Left)?;
        let m = mid(&feet[0], &feet[1]);
        Ok(OnlineWalk {
            robot: *robot,
            p,
            omega: R::of(libm::sqrt(robot.gravity / p.z_c)),
            mode: WalkMode::Standing(Standing),
            gen,
            cmd: WalkCommand::zero(),
            xi_eos: m,
            feet,
            x: m,
            v: [R::zero(); 2],
            zmp: m,
            steps_done: 0,
            committed: None,
            time_ns: 0,
            heading: None,
            turned: R::zero(),
            stepped_turn: R::zero(),
            requested_turn: R::zero(),
            landed: [None; 2],
            shifted: [R::zero(); 2],
            requested_shift: [R::zero(); 2],
            queue: Deque::new(),
            given: None,
        })
    }

    fn generator(
        robot: &Robot,
        p: &OnlineParams,
        feet: [Place<R>; 2],
        first: Side,
    ) -> Result<StepGenerator<R>, GaitError> {
        StepGenerator::new(
            robot,
            p.z_c,
            p.limits,
            R::of(p.half_width),
            R::of(p.period),
            feet,
            first,
        )
    }

    /// The mode.
    pub fn mode(&self) -> &WalkMode<R> {
        &self.mode
    }

    /// The walking velocity of the generator (m/s, m/s, rad/s).
    pub fn velocity(&self) -> [R; 3] {
        self.gen.velocity()
    }

    /// Steps finished.
    pub fn steps_done(&self) -> u32 {
        self.steps_done
    }

    /// The footstep committed since the last call (at most one per step), for the log.
    pub fn take_footstep(&mut self) -> Option<Footstep<R>> {
        self.committed.take()
    }

    /// Appends an explicit step (a footstep list's entry) to the walk: walked before the
    /// command's steps, in order; a standing walk starts with it (first swing = its side).
    /// False (nothing changes) when [`STEP_QUEUE_LEN`] steps wait or `d` is not finite.
    pub fn push_step(&mut self, step: ListedStep<R>) -> bool {
        if !step.d.iter().all(|v| v.is_finite()) || self.queue.push_back(step).is_err() {
            return false;
        }
        match self.mode {
            WalkMode::Standing(_) => self.start(),
            WalkMode::Stopping(st) => {
                self.mode = WalkMode::Walking(Walking { step: st.step });
                self.replan();
            }
            WalkMode::Walking(_) => self.replan(),
            WalkMode::Starting(_) => self.replan_start(),
        }
        true
    }

    /// Drops the explicit steps waiting (not the step under way, whose landing is committed):
    /// the walk goes on under the command alone; under the zero command it stops as
    /// [`OnlineWalk::set_command`] does (Walking → Stopping, decelerated, feet-closing steps).
    pub fn clear_steps(&mut self) {
        if self.queue.is_empty() {
            return;
        }
        self.queue.clear();
        match self.mode {
            WalkMode::Walking(w) if !self.wants_walk() => {
                self.mode = WalkMode::Stopping(Stopping { step: w.step });
                self.replan();
            }
            WalkMode::Walking(_) | WalkMode::Stopping(_) => self.replan(),
            WalkMode::Starting(_) => self.replan_start(),
            WalkMode::Standing(_) => {}
        }
    }

    /// Explicit steps waiting.
    pub fn queued(&self) -> usize {
        self.queue.len()
    }

    /// The travel (S2's d) of the last committed step if it was an explicit one, else `None`.
    pub fn last_given(&self) -> Option<[R; 3]> {
        self.given
    }

    /// The walk has somewhere to go: a non-zero command or explicit steps waiting.
    fn wants_walk(&self) -> bool {
        !self.cmd.is_zero() || !self.queue.is_empty()
    }

    /// The next step of generator `g`: the explicit step `listed` (if its side swings next; an
    /// in-place step to change feet if not: `true` = `listed` was used), else the command's
    /// with the heading correction `turn`. Returns the footstep, the correction stepped, the
    /// explicit travel and whether `listed` was consumed.
    fn next_of(
        &self,
        g: &mut StepGenerator<R>,
        listed: Option<&ListedStep<R>>,
        turn: R,
        shift: [R; 2],
    ) -> (Footstep<R>, R, [R; 2], Option<[R; 3]>, bool) {
        let none = [R::zero(); 2];
        match listed {
            Some(l) if l.side == g.next_swing() => {
                (g.next_step_given(l.d), R::zero(), none, Some(l.d), true)
            }
            Some(_) => {
                let z = [R::zero(); 3];
                (g.next_step_given(z), R::zero(), none, Some(z), false)
            }
            None => {
                let (f, t, c) = g.next_step_held(&self.cmd, turn, shift);
                (f, t, c, None, false)
            }
        }
    }

    /// The leg odometry's survey of foot `side`'s landing: its surveyed place minus the planned
    /// one (m, world frame; o of P1), for the position hold. Non-finite values are ignored.
    pub fn set_landing_offset(&mut self, side: Side, offset: [R; 2]) {
        if offset.iter().all(|v| v.is_finite()) {
            *side.of_mut(&mut self.landed) = Some(offset);
        }
    }

    /// The position correction c requested for the last committed step (P2, the input of
    /// [`StepGenerator::next_step_held`], support frame, whole µm), m: 0 unless the position
    /// hold moved it.
    pub fn last_shift(&self) -> [R; 2] {
        self.requested_shift
    }

    /// The position hold's correction for a step from support foot `support` (P1–P2): 0 when
    /// off, without a survey of that foot since it landed, or when not walking.
    fn position_shift(&self, side: Side, support: &Place<R>) -> [R; 2] {
        let k = self.p.position_gain;
        let (Some(o), WalkMode::Walking(_)) = (*side.of(&self.landed), &self.mode) else {
            return [R::zero(); 2];
        };
        if !(k > 0.0 && k.is_finite()) {
            return [R::zero(); 2];
        }
        let m = R::of(MAX_POSITION_SHIFT);
        let c = [0, 1].map(|i| {
            let e = o[i] + self.shifted[i];
            (-(e * R::of(k))).clamp_to(-m, m)
        });
        let (sin, cos) = support.yaw.sin_cos();
        // R(−θ_S)·c, a whole number of µm, as logged: the host replays the footsteps bit for bit.
        let local = [cos * c[0] + sin * c[1], cos * c[1] - sin * c[0]];
        local.map(|v| R::of(libm::round(v.to_f64() * 1e6) * 1e-6))
    }

    /// The measured heading ψ (rad, the feet's yaw origin: the gyro's yaw integrated since the
    /// walk stood at heading 0) for the heading hold; a non-finite value is ignored.
    pub fn set_heading(&mut self, psi: R) {
        if psi.is_finite() {
            self.heading = Some(psi);
        }
    }

    /// The heading correction δ requested for the last committed step (H2, the input of
    /// [`StepGenerator::next_step_turned`], a whole number of µrad), rad: 0 unless the heading
    /// hold turned it.
    pub fn last_turn(&self) -> R {
        self.requested_turn
    }

    /// The heading hold's correction for the step about to begin (H1–H2): 0 when off, without
    /// a measurement, or when not walking.
    fn heading_turn(&self) -> R {
        let k = self.p.heading_gain;
        let (Some(psi), WalkMode::Walking(_)) = (self.heading, &self.mode) else {
            return R::zero();
        };
        if !(k > 0.0 && k.is_finite()) {
            return R::zero();
        }
        let wrap = |a: R| a.sin().atan2(a.cos());
        let [l, r] = self.feet;
        let half = R::of(0.5);
        let commanded = l.yaw + wrap(r.yaw - l.yaw) * half - self.turned + self.stepped_turn * half;
        let e = wrap(psi - commanded);
        let m = R::of(MAX_HEADING_TURN);
        let turn = (-(e * R::of(k))).clamp_to(-m, m);
        // A whole number of µrad, as logged: the host replays the footsteps bit for bit.
        R::of(libm::round(turn.to_f64() * 1e6) * 1e-6)
    }

    /// Sets the command (non-finite components count as 0); the preview is re-planned.
    pub fn set_command(&mut self, cmd: WalkCommand<R>) {
        let f = |v: R| if v.is_finite() { v } else { R::zero() };
        let cmd = WalkCommand {
            vx: f(cmd.vx),
            vy: f(cmd.vy),
            yaw_rate: f(cmd.yaw_rate),
        };
        if cmd == self.cmd {
            return;
        }
        self.cmd = cmd;
        match self.mode {
            WalkMode::Standing(_) if !cmd.is_zero() => self.start(),
            WalkMode::Walking(w) if !self.wants_walk() => {
                self.mode = WalkMode::Stopping(Stopping { step: w.step });
                self.replan();
            }
            WalkMode::Stopping(s) if self.wants_walk() => {
                self.mode = WalkMode::Walking(Walking { step: s.step });
                self.replan();
            }
            WalkMode::Walking(_) | WalkMode::Stopping(_) => self.replan(),
            WalkMode::Starting(_) => self.replan_start(),
            WalkMode::Standing(_) => {}
        }
    }

    /// Standing → Starting: a generator from the present feet, the first swing chosen by the
    /// command (right first for a rightward or clockwise command).
    fn start(&mut self) {
        let right =
            self.cmd.vy < R::zero() || (self.cmd.vy == R::zero() && self.cmd.yaw_rate < R::zero());
        let first = match self.queue.front() {
            Some(l) => l.side,
            None if right => Side::Right,
            None => Side::Left,
        };
        if let Ok(g) = Self::generator(&self.robot, &self.p, self.feet, first) {
            self.gen = g;
            self.mode = WalkMode::Starting(Starting {
                t: R::zero(),
                vrp: self.x,
            });
            self.replan_start();
        }
    }

    /// The steps the generator makes from `gen` under the command (at most
    /// [`PREVIEW_STEPS`]; none once it stands under the zero command), and its feet after them.
    fn preview_steps(
        &self,
        gen: &StepGenerator<R>,
        skip: usize,
    ) -> ([Option<Step<R>>; PREVIEW_STEPS], [Place<R>; 2]) {
        let mut g = *gen;
        let mut out = [None; PREVIEW_STEPS];
        // The explicit steps waiting first (less the `skip` that `gen` made), then the command's.
        let mut next = skip;
        for slot in out.iter_mut() {
            let listed = self.queue.iter().nth(next);
            // Under the zero command the walk ends when the generator stands (as in the
            // transitions): no more steps.
            if listed.is_none() && self.cmd.is_zero() && g.is_standing() {
                break;
            }
            let side = g.next_swing();
            let [l, r] = g.feet();
            let (support, from) = match side {
                Side::Left => (r, l),
                Side::Right => (l, r),
            };
            let (fs, _, _, _, used) = self.next_of(&mut g, listed, R::zero(), [R::zero(); 2]);
            if used {
                next += 1;
            }
            *slot = Some(Step {
                t: R::zero(),
                support,
                side,
                from,
                to: fs.place,
            });
        }
        (out, g.feet())
    }

    /// ξ at the end of the step under way, whose generator state (after its own landing) is
    /// `gen`: the previewed steps, then rest on the final feet's midpoint (D2).
    fn preview(&self, gen: &StepGenerator<R>, skip: usize) -> [R; 2] {
        let (steps, [l, r]) = self.preview_steps(gen, skip);
        let mut xi = mid(&l, &r);
        for st in steps.iter().rev().flatten() {
            xi = self.step_back(st, xi, R::zero()).0;
        }
        xi
    }

    /// ξ_ref and the ZMP reference at time `t` of `step`, from ξ at its end (D2 through the
    /// step's three ZMP segments, backwards).
    fn step_back(&self, step: &Step<R>, xi_end: [R; 2], t: R) -> ([R; 2], [R; 2]) {
        let (t1, t2, period) = (R::of(self.p.t1), R::of(self.p.t2), R::of(self.p.period));
        let p = self.support_zmp(step);
        let a = mid(&step.support, &step.from);
        let b = mid(&step.support, &step.to);
        let segs = [(R::zero(), t1, a, p), (t1, t2, p, p), (t2, period, p, b)];
        let mut xi = xi_end;
        for &(t0, t_end, pa, pb) in segs.iter().rev() {
            let tau = if t >= t0 { t - t0 } else { R::zero() };
            let (x, zmp) = self.segment(xi, pa, pb, t_end - t0, tau);
            if t >= t0 {
                return (x, zmp);
            }
            xi = x;
        }
        (xi, a)
    }

    /// The single-support ZMP reference of `step`: the support foot's sole point moved
    /// [`OnlineParams::zmp_inset`] towards the other foot (lateral axis of the support foot).
    fn support_zmp(&self, step: &Step<R>) -> [R; 2] {
        let sup = step.support;
        // The support foot is the other side of the swing: inward is towards the swing side.
        let inward = R::of(step.side.sign() * self.p.zmp_inset);
        let (s, c) = (sup.yaw.sin(), sup.yaw.cos());
        [sup.x - s * inward, sup.y + c * inward]
    }

    /// ξ and the ZMP at `tau` of a segment of duration `dur` whose ZMP moves linearly from
    /// `pa` to `pb`, ξ = `xi_end` at its end: with slope s = (pb − pa)/dur,
    /// ξ(τ) = p(τ) + s/ω + e^{ω(τ − dur)}(ξ_end − pb − s/ω).
    fn segment(&self, xi_end: [R; 2], pa: [R; 2], pb: [R; 2], dur: R, tau: R) -> ([R; 2], [R; 2]) {
        let w = self.omega;
        let tiny = R::of(1e-9);
        let tau = tau.min(dur);
        let e = (w * (tau - dur)).exp();
        let f = |i: usize| {
            let at = |v: [R; 2]| if i == 0 { v[0] } else { v[1] };
            let slope = if dur > tiny {
                (at(pb) - at(pa)) / dur
            } else {
                R::zero()
            };
            let p = at(pa) + slope * tau;
            (p + slope / w + e * (at(xi_end) - at(pb) - slope / w), p)
        };
        let (x0, p0) = f(0);
        let (x1, p1) = f(1);
        ([x0, x1], [p0, p1])
    }

    fn replan(&mut self) {
        self.xi_eos = self.preview(&self.gen, 0);
    }

    /// The start phase's target: ξ_ini of the first step (its ξ_eos brought back one period).
    fn replan_start(&mut self) {
        let mut g = self.gen;
        let side = g.next_swing();
        let [l, r] = self.feet;
        let (support, from) = match side {
            Side::Left => (r, l),
            Side::Right => (l, r),
        };
        let (fs, _, _, _, used) =
            self.next_of(&mut g, self.queue.front(), R::zero(), [R::zero(); 2]);
        let first = Step {
            t: R::zero(),
            support,
            side,
            from,
            to: fs.place,
        };
        let eos = self.preview(&g, usize::from(used));
        self.xi_eos = self.step_back(&first, eos, R::zero()).0;
        // The constant ZMP that brings ξ from now to the target in the remaining time.
        let t = match self.mode {
            WalkMode::Starting(s) => s.t,
            _ => R::zero(),
        };
        let xi0 = self.dcm();
        let e = (self.omega * (R::of(self.p.period) - t)).exp();
        let vrp = [
            (self.xi_eos[0] - e * xi0[0]) / (R::one() - e),
            (self.xi_eos[1] - e * xi0[1]) / (R::one() - e),
        ];
        if let WalkMode::Starting(s) = &mut self.mode {
            s.vrp = vrp;
        }
    }

    fn dcm(&self) -> [R; 2] {
        [
            self.x[0] + self.v[0] / self.omega,
            self.x[1] + self.v[1] / self.omega,
        ]
    }

    /// Begins the next step from the generator (committing its landing place).
    fn begin_step(&mut self) -> Step<R> {
        let side = self.gen.next_swing();
        let [l, r] = self.feet;
        let (support, from) = match side {
            Side::Left => (r, l),
            Side::Right => (l, r),
        };
        let listed = self.queue.front().copied();
        let support_side = side.other();
        let (turn, shift) = match listed {
            Some(_) => (R::zero(), [R::zero(); 2]),
            None => (
                self.heading_turn(),
                self.position_shift(support_side, &support),
            ),
        };
        let mut g = self.gen;
        let (fs, stepped, moved, given, used) = self.next_of(&mut g, listed.as_ref(), turn, shift);
        self.gen = g;
        if used {
            self.queue.pop_front();
        }
        self.given = given;
        self.requested_turn = turn;
        self.stepped_turn = stepped;
        self.turned += stepped;
        self.requested_shift = shift;
        // Σc += R(θ_S)·λc (P1, world frame); the swing foot has not been surveyed where it lands.
        let (s, k) = support.yaw.sin_cos();
        self.shifted[0] += k * moved[0] - s * moved[1];
        self.shifted[1] += s * moved[0] + k * moved[1];
        *side.of_mut(&mut self.landed) = None;
        self.committed = Some(fs);
        let step = Step {
            t: R::zero(),
            support,
            side,
            from,
            to: fs.place,
        };
        self.xi_eos = self.preview(&self.gen, 0);
        step
    }

    /// One tick: the mode's reference, the DCM feedback (D3), the CoM (D4), transitions.
    pub fn tick(&mut self) -> GaitSample<R> {
        let dt = R::of(self.p.dt);
        let w = self.omega;
        let period = R::of(self.p.period);
        // The ZMP reference, the DCM reference and the box the commanded ZMP stays in: the
        // support foot ± ZMP_MARGIN in a step, the feet's bounding box ± ZMP_MARGIN on both.
        let m = R::of(ZMP_MARGIN);
        let [fl, fr] = self.feet;
        let both = (
            [fl.x.min(fr.x) - m, fl.y.min(fr.y) - m],
            [fl.x.max(fr.x) + m, fl.y.max(fr.y) + m],
        );
        let (p_ref, xi_ref, (lo, hi)) = match &self.mode {
            WalkMode::Standing(_) => {
                let c = mid(&fl, &fr);
                (c, c, both)
            }
            WalkMode::Starting(s) => {
                // ξ_ref(t) = vrp + e^{ω(t−T)}(ξ_target − vrp).
                let e = (w * (s.t - period)).exp();
                let xi = [
                    s.vrp[0] + e * (self.xi_eos[0] - s.vrp[0]),
                    s.vrp[1] + e * (self.xi_eos[1] - s.vrp[1]),
                ];
                (s.vrp, xi, both)
            }
            WalkMode::Walking(Walking { step }) | WalkMode::Stopping(Stopping { step }) => {
                let (xi, p0) = self.step_back(step, self.xi_eos, step.t);
                let (t1, t2) = (R::of(self.p.t1), R::of(self.p.t2));
                let sup = step.support;
                let [zx, zy] = self.support_zmp(step);
                let sup = Place {
                    x: zx,
                    y: zy,
                    yaw: sup.yaw,
                };
                let other = if step.t < t1 { step.from } else { step.to };
                let bx = if step.t > t1 && step.t < t2 {
                    ([sup.x - m, sup.y - m], [sup.x + m, sup.y + m])
                } else {
                    (
                        [sup.x.min(other.x) - m, sup.y.min(other.y) - m],
                        [sup.x.max(other.x) + m, sup.y.max(other.y) + m],
                    )
                };
                (p0, xi, bx)
            }
        };
        let xi = self.dcm();
        let gain = R::of(2.0);
        let zmp_of = |i: usize| {
            let at = |a: [R; 2]| if i == 0 { a[0] } else { a[1] };
            let c = at(p_ref) + gain * (at(xi) - at(xi_ref));
            if c.is_finite() {
                c.clamp_to(at(lo), at(hi))
            } else {
                at(p_ref)
            }
        };
        let p = [zmp_of(0), zmp_of(1)];
        // (D4).
        let (ch, sh) = {
            let e = (w * dt).exp();
            let ei = R::one() / e;
            ((e + ei) * R::of(0.5), (e - ei) * R::of(0.5))
        };
        for ((x, v), p) in self.x.iter_mut().zip(self.v.iter_mut()).zip(p) {
            let d = *x - p;
            let x1 = p + d * ch + *v / w * sh;
            *v = w * d * sh + *v * ch;
            *x = x1;
        }
        self.zmp = p;
        self.time_ns = self.time_ns.saturating_add((self.p.dt * 1e9) as u64);

        // The feet of this tick and the mode's clock.
        let mut feet = [
            FootSample::on_ground(&self.feet[0]),
            FootSample::on_ground(&self.feet[1]),
        ];
        let mut phase = SupportPhase::Standing;
        let mut support_foot = None;
        match &mut self.mode {
            WalkMode::Standing(_) => {}
            WalkMode::Starting(s) => {
                s.t += dt;
                phase = SupportPhase::Double;
            }
            WalkMode::Walking(Walking { step }) | WalkMode::Stopping(Stopping { step }) => {
                step.t += dt;
                let (t1, t2) = (R::of(self.p.t1), R::of(self.p.t2));
                support_foot = Some(step.side.other());
                if step.t > t1 && step.t < t2 {
                    let u = (step.t - t1) / (t2 - t1);
                    let shape = match self.p.swing {
                        SwingShape::Cycloid { height, width } => SwingShape::Cycloid {
                            height: R::of(height),
                            width: R::of(width),
                        },
                        SwingShape::Sinusoid { height } => SwingShape::Sinusoid {
                            height: R::of(height),
                        },
                    };
                    if let Some(f) = feet.get_mut(step.side.index()) {
                        *f = swing_foot(&shape, &step.from, &step.to, u, R::of(step.side.sign()));
                    }
                    phase = SupportPhase::Single(step.side.other());
                } else {
                    if step.t >= t2 {
                        if let Some(f) = feet.get_mut(step.side.index()) {
                            *f = FootSample::on_ground(&step.to);
                        }
                    }
                    phase = SupportPhase::Double;
                }
            }
        }
        let sample = GaitSample {
            time_ns: self.time_ns,
            zmp: p,
            com: [self.x[0], self.x[1], R::of(self.p.z_c)],
            com_vel: self.v,
            feet,
            phase,
            support_foot,
            steps_done: self.steps_done,
        };
        self.transition(period, dt);
        sample
    }

    /// The transitions at the end of a tick.
    fn transition(&mut self, period: R, dt: R) {
        let half = dt * R::of(0.5);
        match self.mode {
            WalkMode::Starting(s) if s.t + half >= period => {
                let step = self.begin_step();
                self.mode = WalkMode::Walking(Walking { step });
            }
            WalkMode::Walking(Walking { step }) | WalkMode::Stopping(Stopping { step })
                if step.t + half >= period =>
            {
                if let Some(f) = self.feet.get_mut(step.side.index()) {
                    *f = step.to;
                }
                self.steps_done = self.steps_done.saturating_add(1);
                if !self.wants_walk() && self.gen.is_standing() {
                    self.mode = WalkMode::Standing(Standing);
                    return;
                }
                let next = self.begin_step();
                self.mode = if !self.wants_walk() {
                    WalkMode::Stopping(Stopping { step: next })
                } else {
                    WalkMode::Walking(Walking { step: next })
                };
            }
            _ => {}
        }
    }
}
