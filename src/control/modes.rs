//! The control loop's motion as walk modes: one type per mode, explicit transitions (the style
//! of HULKs' walking engine). The `Controller` keeps the
//! tick's plumbing — sensors, command port, supervisor, the IK and the servo writes, the log —
//! and asks a [`Walk`] what moves the legs this tick ([`Walk::tick`]):
//!
//! ```text
//!  Starting ──ramp done──▶ Gait::Online  (without autostart: gait-core's OnlineWalk, whose own
//!  (the minimum-jerk         mode types are standing → starting → walking → stopping →
//!   ramp from the present    standing, driven by the command port)
//!   pose to the initial  ──▶ Gait::Plan    (autostart: the configured plan's samples, then the
//!   pose)                    supervisor's final hold when the plan is done)
//!  any mode ── supervisor stop ──▶ hold the pose, torque off (the supervisor's own states)
//! ```
//!
//! The command port's State register is the mode's ([`Walk::port_state`]): starting,
//! standing / walking / stopping (the online walk's mode), walking (the plan), stopped (the
//! supervisor stopped).

use gait_core::gait::{Engine, Sample, Targets};
use gait_core::robot::LEG_JOINTS;
use gait_core::trajectory::fourier_walk::WalkSampler;
use gait_core::trajectory::online::OnlineWalk;
use gait_core::trajectory::plan::Footstep;
use gait_core::{GaitError, GaitSample, Robot};
use walker_contract::command_port::PortState;

use super::{commanded, MAX_LEAD_TICKS, MAX_STEPS};
use crate::startup::Ramp;
use crate::Config;

/// The measured flywheel torque τ = J·φ̈ fed to the sampler: N·m on the f32 path, whole mN·m
/// on the fixed-point path (no float).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tau {
    /// N·m.
    Nm(f32),
    /// Whole mN·m.
    MilliNm(i32),
}

/// Starting: the ramp from the servos' present pose to the gait's initial pose
/// (State = starting).
#[derive(Clone, Debug)]
pub struct Starting {
    ramp: Ramp,
    k: u32,
}

impl Starting {
    /// At the ramp's first tick.
    pub fn new(ramp: Ramp) -> Self {
        Starting { ramp, k: 0 }
    }

    /// This tick's joint targets (rad) and whether the ramp is over after them.
    pub fn step(&mut self) -> ([f32; LEG_JOINTS], bool) {
        let q = self.ramp.at(self.k);
        let done = self.k.saturating_add(1) >= self.ramp.ticks();
        self.k = self.k.saturating_add(1);
        (q, done)
    }
}

/// Most ticks of servo lead the plan's delay line holds: [`MAX_LEAD_TICKS`], and 16 (80 ms at
/// the 200 Hz default) on the OpenCM 9.04, whose 20 KiB of RAM do not hold 65 samples of 80 B
/// beside the rest of the walk (BENCHMARKS.md "RAM"; that board runs its default
/// configuration, no lead). A longer `servo_lead` is walked with this many ticks.
pub const DELAY_TICKS: usize = if cfg!(feature = "board-opencm") {
    16
} else {
    MAX_LEAD_TICKS
};

/// The plan walked at power-on (autostart; State = walking): the sampler and the delay line
/// of the servo-lag feed-forward (`servo_lead`: the joint targets come from the sample
/// `lead` ticks ahead, the reference and the log from the present one).
#[derive(Clone, Debug)]
pub struct Plan {
    engine: Engine<MAX_STEPS>,
    delay: heapless::Deque<GaitSample<f32>, { DELAY_TICKS + 1 }>,
    /// The sample `lead` ticks ahead of the delay line's front, not yet handed out.
    pending: Option<Sample>,
    /// The sample the IK takes this tick (`lead` ticks ahead of the present one).
    ahead: Sample,
    /// The first sample (the initial pose's reference).
    first: GaitSample<f32>,
}

impl Plan {
    /// The plan with its delay line primed: the first sample and `lead_ticks` more (the
    /// sampler's first `lead_ticks + 1` samples, τ = 0).
    pub fn new(engine: Engine<MAX_STEPS>, lead_ticks: usize) -> Self {
        let mut plan = Plan {
            engine,
            ..Plan::idle()
        };
        plan.prime(lead_ticks);
        plan
    }

    /// Storage for the plan (an idle engine, never sampled): [`Walk::build`] builds the engine
    /// in place and primes it ([`Plan::prime`]).
    // Inline: the storage is then written where it lives, not built on the stack and copied.
    #[inline(always)]
    pub fn idle() -> Self {
        Plan {
            engine: Engine::idle(),
            delay: heapless::Deque::new(),
            pending: None,
            ahead: Sample::zero(),
            first: GaitSample::zero(),
        }
    }

    /// Primes the delay line from the (built) engine: the first sample and `lead_ticks` more
    /// (at most [`DELAY_TICKS`]; τ = 0), the last of them pending as the first sample the IK
    /// takes.
    pub fn prime(&mut self, lead_ticks: usize) {
        self.delay.clear();
        let first = self.engine.next(0.0);
        let _ = self.delay.push_back(first.f32);
        let mut lead = first;
        for _ in 0..lead_ticks.min(DELAY_TICKS) {
            lead = self.engine.next(0.0);
            let _ = self.delay.push_back(lead.f32);
        }
        self.pending = Some(lead);
        self.ahead = lead;
        self.first = first.f32;
    }

    /// One tick: the present sample into `present`, the one `lead` ticks ahead (which the IK
    /// takes: [`Plan::ahead`]) kept here, the sampler fed the measured τ. In place: the samples (≈ 100 B f32, ≈ 220 B with the
    /// fixed-point copy) are not passed around by value (a `memcpy` each).
    pub fn advance(&mut self, tau: Tau, present: &mut GaitSample<f32>) {
        match self.pending.take() {
            Some(p) => self.ahead = p,
            None => {
                match tau {
                    Tau::MilliNm(t) => self.engine.next_mnm_into(t, &mut self.ahead),
                    Tau::Nm(t) => self.engine.next_into(t, &mut self.ahead),
                }
                if self.delay.is_empty() {
                    // No lead: the sample ahead is the present one (pushed and popped at once).
                    *present = self.ahead.f32;
                    return;
                }
                let _ = self.delay.push_back(self.ahead.f32);
            }
        }
        *present = self.delay.pop_front().unwrap_or(self.ahead.f32);
    }

    /// The sample the IK takes this tick (set by [`Plan::advance`]).
    pub fn ahead(&self) -> &Sample {
        &self.ahead
    }

    /// The sampler (its IK paths: [`Engine::joints`], [`Engine::joints_fx`]).
    pub fn engine(&self) -> &Engine<MAX_STEPS> {
        &self.engine
    }
}

/// What the legs follow once the ramp is over.
// One gait lives for the whole run and no_std has no Box: the larger variant's size is the cost.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Gait {
    /// On command (no autostart): the online walk.
    Online(OnlineWalk<f32>),
    /// At power-on (autostart): the plan.
    Plan(Plan),
}

impl Gait {
    /// The initial pose: its reference sample, the 12 joint targets (before the compliance
    /// feed-forward) and the sample that feed-forward loads (the one the IK took).
    // Out of line: its temporaries (online walks of ≈ 900 B) get a frame of their own, not
    // the control loop's (stack: scripts/stack-depth.py, BENCHMARKS.md "RAM").
    #[inline(never)]
    pub fn initial_pose(
        &self,
        targets: &Targets,
    ) -> (GaitSample<f32>, [f32; LEG_JOINTS], GaitSample<f32>) {
        match self {
            Gait::Online(o) => {
                let s = o.clone().tick();
                (s, targets.joints(&s, [0.0; 2]).0, s)
            }
            Gait::Plan(p) => match &p.pending {
                Some(lead) => (p.first, p.engine.joints(targets, lead, [0.0; 2]), lead.f32),
                // Not reached in the firmware: `initial_pose` is asked before the first
                // `Plan::next`, while the lead sample is still pending. Kept total: the first
                // sample's own pose.
                None => (p.first, targets.joints(&p.first, [0.0; 2]).0, p.first),
            },
        }
    }

    /// The online walk, if this is one.
    pub fn online(&self) -> Option<&OnlineWalk<f32>> {
        match self {
            Gait::Online(o) => Some(o),
            Gait::Plan(_) => None,
        }
    }

    /// The online walk, mutable, if this is one.
    pub fn online_mut(&mut self) -> Option<&mut OnlineWalk<f32>> {
        match self {
            Gait::Online(o) => Some(o),
            Gait::Plan(_) => None,
        }
    }

    /// The plan, if this is one.
    pub fn plan(&self) -> Option<&Plan> {
        match self {
            Gait::Plan(p) => Some(p),
            Gait::Online(_) => None,
        }
    }

    /// True when the plan's samples are over (never for the online walk).
    pub fn plan_done(&self) -> bool {
        self.plan().is_some_and(|p| p.engine.is_done())
    }
}

/// A footstep the online walk committed this tick, with what the log records of it.
#[derive(Clone, Copy, Debug)]
pub struct TakenStep {
    /// The footstep.
    pub step: Footstep<f32>,
    /// The heading hold's correction (rad).
    pub turn: f32,
    /// The position hold's correction (m, support-foot frame).
    pub shift: [f32; 2],
    /// An explicit step's travel (m, m, rad), if the step came from the step list.
    pub given: Option<[f32; 3]>,
}

/// What moves the legs this tick.
#[derive(Clone, Copy, Debug)]
pub enum Motion {
    /// The ramp's joint targets (rad).
    Ramp([f32; LEG_JOINTS]),
    /// The gait at walk tick `k`: its samples are [`Walk::present`] and [`Walk::ahead`]
    /// (borrowed, not copied).
    Gait {
        /// Walk tick (0 at the first tick after the ramp).
        k: u32,
        /// A footstep the online walk committed.
        footstep: Option<TakenStep>,
    },
}

/// The loop's walk mode: starting (the ramp), then the gait.
#[derive(Clone, Debug)]
enum Mode {
    /// The ramp to the initial pose.
    Starting(Starting),
    /// The gait (walk tick count).
    Gait(u32),
}

/// The walk: its mode and its gait.
#[derive(Clone, Debug)]
pub struct Walk {
    mode: Mode,
    /// The gait the ramp hands over to.
    pub gait: Gait,
    /// The gait's present sample (the last gait tick's; the gait's first before that).
    present: GaitSample<f32>,
}

impl Walk {
    /// Starting on `ramp`, then `gait`.
    pub fn new(ramp: Ramp, gait: Gait) -> Self {
        let mut walk = Walk {
            mode: Mode::Gait(0),
            gait,
            present: GaitSample::zero(),
        };
        walk.present = walk.first_present();
        walk.start(ramp);
        walk
    }

    /// Storage for the walk: an idle plan ([`Plan::idle`]), never sampled. The firmware's way
    /// to its ≈ 10 KB walk without copies on the stack: this storage lends its engine to the
    /// servo-speed check ([`Walk::scratch`]), [`Walk::build`] builds the gait in it and
    /// [`Walk::start`] sets the ramp.
    // Inline: the storage is then written where it lives, not built on the stack and copied.
    #[inline(always)]
    pub fn idle() -> Self {
        Walk {
            mode: Mode::Gait(0),
            gait: Gait::Plan(Plan::idle()),
            present: GaitSample::zero(),
        }
    }

    /// The plan's engine storage as an f32 walk sampler: the dry runs' scratch
    /// ([`gait_core::gait::servo_timing_in`]). Always `Some`.
    pub fn scratch(&mut self) -> Option<&mut WalkSampler<f32, MAX_STEPS>> {
        self.plan_storage()?.engine.f32_storage()
    }

    /// Builds the gait of `cfg` in place: the plan's engine where it lives
    /// ([`Engine::rebuild`]); with autostart its delay line primed, otherwise (after the
    /// engine's checks: `math=fixed` needs its build feature, the fixed-point engine refuses
    /// the Fourier CoM) the online walk in its place. The walk is not started
    /// ([`Walk::start`]).
    // Out of line: its temporaries (online walks of ≈ 900 B) get a frame of their own, not
    // the control loop's (stack: scripts/stack-depth.py, BENCHMARKS.md "RAM").
    #[inline(never)]
    pub fn build(&mut self, cfg: &Config, robot: &Robot) -> Result<(), GaitError> {
        let p = self.plan_storage().ok_or(GaitError::NotBuiltIn)?;
        p.engine
            .rebuild(&cfg.walk_config(), cfg.arithmetic, robot)?;
        if cfg.autostart {
            p.prime(cfg.lead_ticks());
        } else {
            self.gait = Gait::Online(commanded::online_walk(cfg, robot)?);
        }
        self.present = self.first_present();
        Ok(())
    }

    /// The plan the gait holds, made an idle one ([`Plan::idle`]) if it held the online walk.
    /// Always `Some`.
    fn plan_storage(&mut self) -> Option<&mut Plan> {
        if let Gait::Online(_) = self.gait {
            self.gait = Gait::Plan(Plan::idle());
        }
        match &mut self.gait {
            Gait::Plan(p) => Some(p),
            Gait::Online(_) => None,
        }
    }

    /// Starting on `ramp`, then the gait (State = starting).
    pub fn start(&mut self, ramp: Ramp) {
        self.mode = Mode::Starting(Starting::new(ramp));
    }

    /// The gait's first present sample: the plan's first, the online walk's standing one.
    fn first_present(&self) -> GaitSample<f32> {
        match &self.gait {
            Gait::Plan(p) => p.first,
            Gait::Online(o) => o.clone().tick(),
        }
    }

    /// The present sample (reference, log, stabilizer, support phase) of the last gait tick.
    pub fn present(&self) -> &GaitSample<f32> {
        &self.present
    }

    /// The sample the IK takes (`servo_lead` ahead): the plan's only; the online walk's IK
    /// takes the present one.
    pub fn ahead(&self) -> Option<&Sample> {
        self.gait.plan().map(Plan::ahead)
    }

    /// True while the ramp runs.
    pub fn is_starting(&self) -> bool {
        matches!(self.mode, Mode::Starting(_))
    }

    /// True when a graded stop may lower the robot now: the online walk stands, or the walk
    /// cannot stop by itself (the ramp; a plan, which is walked to its end or not at all).
    pub fn at_standstill(&self) -> bool {
        match (&self.mode, &self.gait) {
            (Mode::Gait(_), Gait::Online(o)) => {
                matches!(
                    o.mode(),
                    gait_core::trajectory::online::WalkMode::Standing(_)
                )
            }
            (Mode::Starting(_), _) | (Mode::Gait(_), Gait::Plan(_)) => true,
        }
    }

    /// The command port's State while the supervisor runs the walk.
    pub fn port_state(&self) -> PortState {
        match (&self.mode, &self.gait) {
            (Mode::Starting(_), _) => PortState::Starting,
            (Mode::Gait(_), Gait::Online(o)) => commanded::state_of(o.mode()),
            (Mode::Gait(_), Gait::Plan(_)) => PortState::Walking,
        }
    }

    /// This tick's motion; the ramp's last tick hands over to the gait (Starting → Gait). With
    /// `hold` a gait tick hands out the same samples again (gait-core `feedback::hold` A11).
    pub fn tick(&mut self, tau: Tau, hold: bool) -> Motion {
        match &mut self.mode {
            Mode::Starting(s) => {
                let (q, done) = s.step();
                if done {
                    self.mode = Mode::Gait(0);
                }
                Motion::Ramp(q)
            }
            Mode::Gait(walk_tick) => {
                let k = *walk_tick;
                *walk_tick = walk_tick.saturating_add(1);
                if hold {
                    // The plan's clock stands still: the same samples again.
                    return Motion::Gait { k, footstep: None };
                }
                match &mut self.gait {
                    Gait::Online(o) => {
                        self.present = o.tick();
                        let footstep = o.take_footstep().map(|step| TakenStep {
                            step,
                            turn: o.last_turn(),
                            shift: o.last_shift(),
                            given: o.last_given(),
                        });
                        Motion::Gait { k, footstep }
                    }
                    Gait::Plan(p) => {
                        p.advance(tau, &mut self.present);
                        Motion::Gait { k, footstep: None }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Config;
    use gait_core::Robot;

    fn plan(lead: usize) -> (Plan, Engine<MAX_STEPS>) {
        let cfg = Config {
            autostart: true,
            ..Config::default()
        };
        let robot = Robot::reference();
        let e = Engine::<MAX_STEPS>::new(&cfg.walk_config(), cfg.arithmetic, &robot).unwrap();
        (Plan::new(e.clone(), lead), e)
    }

    #[test]
    fn the_plan_hands_out_the_present_sample_and_the_one_lead_ticks_ahead() {
        let lead = 3;
        let (mut p, mut reference) = plan(lead);
        let all: Vec<_> = (0..40).map(|_| reference.next(0.0)).collect();
        let mut present = all[0].f32;
        present.com[0] = f32::NAN;
        for k in 0..(all.len() - lead) {
            p.advance(Tau::Nm(0.0), &mut present);
            assert_eq!(present, all[k].f32, "tick {k}");
            assert_eq!(*p.ahead(), all[k + lead], "tick {k}");
        }
    }

    #[test]
    fn starting_ramps_then_hands_over_to_the_gait_with_walk_tick_zero() {
        let (p, _) = plan(0);
        let first = p.first;
        let ramp = Ramp::new([0.1; LEG_JOINTS], [0.0; LEG_JOINTS], 5);
        let mut w = Walk::new(ramp, Gait::Plan(p));
        assert_eq!(w.port_state(), PortState::Starting);
        for k in 0..ramp.ticks() {
            assert!(w.is_starting());
            match w.tick(Tau::Nm(0.0), false) {
                Motion::Ramp(q) => assert_eq!(q, ramp.at(k)),
                m => panic!("tick {k}: {m:?}"),
            }
        }
        assert!(!w.is_starting());
        assert_eq!(w.port_state(), PortState::Walking);
        for k in 0..3 {
            match w.tick(Tau::Nm(0.0), false) {
                Motion::Gait {
                    k: wk,
                    footstep: None,
                } => {
                    assert_eq!(wk, k);
                    assert!(w.ahead().is_some());
                    if k == 0 {
                        assert_eq!(*w.present(), first);
                    }
                }
                m => panic!("walk tick {k}: {m:?}"),
            }
        }
        assert!(!w.gait.plan_done());
        assert!(w.gait.online().is_none());
        // A held tick (the catching step's clock hold) counts as a walk tick but hands out the
        // same samples again; the next one goes on from there.
        let (present, ahead) = (*w.present(), w.ahead().map(|a| a.f32));
        match w.tick(Tau::Nm(0.0), true) {
            Motion::Gait {
                k: 3,
                footstep: None,
            } => {}
            m => panic!("held tick: {m:?}"),
        }
        assert_eq!(*w.present(), present);
        assert_eq!(w.ahead().map(|a| a.f32), ahead);
        assert!(matches!(
            w.tick(Tau::Nm(0.0), false),
            Motion::Gait { k: 4, .. }
        ));
        assert_ne!(*w.present(), present);
    }

    #[test]
    fn the_online_walk_stands_after_the_ramp() {
        let cfg = Config::default();
        let o = commanded::online_walk(&cfg, &Robot::reference()).unwrap();
        let mut w = Walk::new(
            Ramp::new([0.0; LEG_JOINTS], [0.0; LEG_JOINTS], 1),
            Gait::Online(o),
        );
        assert!(matches!(w.tick(Tau::Nm(0.0), false), Motion::Ramp(_)));
        assert_eq!(w.port_state(), PortState::Standing);
        match w.tick(Tau::Nm(0.0), false) {
            Motion::Gait {
                k: 0,
                footstep: None,
            } => assert!(w.ahead().is_none()),
            m => panic!("{m:?}"),
        }
        assert!(!w.gait.plan_done());
    }
}
