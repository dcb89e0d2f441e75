//! Gait decisions shared by the firmware and the host tools: which sampler a walk configuration
//! builds, which joint-target pipeline turns a sample into 12 joint angles (and with which CoM
//! shift), the support polygon of a sample and its cache, and the servo-speed feasibility check
//! with its timing stretch.
//!
//! # Joint targets ([`Targets`])
//! * [`Compensation::None`], the paper's pipeline: the pelvis point on the model's CoM c + δ
//!   (δ = the stabilizer's shift, 0 without feedback), two-leg IK ([`crate::kinematics::pipeline`]);
//! * [`Compensation::WholeBody`]: the pelvis placed so that the multi-body CoM (swing leg
//!   included) is on c + δ ([`crate::kinematics::wholebody`], [`WHOLEBODY_ITERATIONS`] fixed-point steps).
//!
//! # Support polygon ([`support_of`], [`SupportCache`])
//! The support sole in single support, the hull of both soles otherwise. The cache rebuilds it
//! only when the phase or a supporting foot changes (a few times per step).
//!
//! # CoM method ([`ComMethod`])
//! Seed 000's exact bounded solution ([`crate::trajectory::com`]), or seed 001's Fourier series through the
//! steady steps, blended C¹ with the exact one at the start and the stop
//! ([`crate::trajectory::fourier_walk`]: the series is periodic, a walk is not). f32 only.
//!
//! # Arithmetic ([`Engine`])
//! The per-sample work runs in f32 ([`Arithmetic::F32`]) or in fixed point
//! ([`Arithmetic::Fixed`]: the I16F16 sampler of `fixed_sampler.rs` and the integer-only IK of
//! `fixed_ik.rs`, same plan and timeline; BENCHMARKS.md gives its accuracy against f64, CoM
//! ≤ 5.4e-5 m over the Table 2 walk). The log, the stabilizer and the support polygon take
//! the sample in f32 either way.
//!
//! # Servo-speed check ([`servo_timing`])
//! The whole plan runs through the sampler and [`Targets`] at dt (a dry run, O(1) memory) with
//! [`JointSpeedMonitor`]. When the peak joint speed v exceeds the servo limit v_max
//! (`robot.servo.max_speed`), with [`Feasibility::Stretch`] t1, t2 and T are multiplied by
//! f = ⌈1000·(v/v_max)·1.05⌉/1000 (joint speeds scale as 1/f for the same path,
//! [`stretched`]), with [`Feasibility::Lower`] the swing height becomes ⌊h_z·v_max/(1.05·v)⌋
//! (µm), and the plan is checked again, at most [`MAX_TIMING_ROUNDS`] adjustments. All rounds
//! together spend at most [`MAX_DRY_RUN_WORK`] (a bound of a few seconds on the M7); a longer plan is
//! refused.

#[cfg(feature = "fixed-engine")]
use crate::kinematics::fixed_ik::FixedLegKinematics;
use crate::kinematics::leg::{JointSpeedMonitor, JointSpeedReport, LegKinematics, LegsIkReport};
use crate::kinematics::pipeline::joint_targets;
use crate::kinematics::wholebody::WholeBody;
use crate::measure::support::SupportPolygon;
use crate::robot::LEG_JOINTS;
use crate::trajectory::fixed_sampler::FixedSample;
#[cfg(feature = "fixed-engine")]
use crate::trajectory::fixed_sampler::FixedSampler;
pub use crate::trajectory::fourier_walk::ComMethod;
use crate::trajectory::fourier_walk::WalkSampler;
use crate::trajectory::plan::SwingShape;
use crate::trajectory::zmp::ZmpShape;
use crate::{ForwardWalk, GaitError, GaitSample, Model, ModelKind, Place, Robot};

/// Fixed-point steps of the whole-body compensation per sample (cost: that + 1 two-leg IK and
/// FK evaluations).
pub const WHOLEBODY_ITERATIONS: u8 = 2;
/// Most adjustments of the servo-speed check.
pub const MAX_TIMING_ROUNDS: u8 = 4;
/// Safety factor on the needed slow-down.
pub const TIMING_MARGIN: f64 = 1.05;
/// Work budget of the whole servo-speed check (every round together), in units of one plain
/// dry-run sample (sampler + two-leg IK + speed monitor); a whole-body sample costs
/// [`WHOLEBODY_SAMPLE_COST`] units (the stages' costs per call are in BENCHMARKS.md). 200,000
/// units keep the start-up check within a few seconds on the 216 MHz M7 whatever the
/// parameters (the parameter table's longest plan would need some thirty times more). A plan
/// beyond it is refused ([`GaitError::DryRunTooLong`]) rather than checked in part.
pub const MAX_DRY_RUN_WORK: u32 = 200_000;
/// Cost of one whole-body dry-run sample in [`MAX_DRY_RUN_WORK`] units.
pub const WHOLEBODY_SAMPLE_COST: u32 = 5;
/// The dry run calls its `feed` callback (the firmware's watchdog) every this many samples.
pub const DRY_RUN_FEED_EVERY: u32 = 256;

/// How the pelvis is placed (firmware token `comp=`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compensation {
    /// The paper's pipeline: the pelvis point on the model's CoM.
    None,
    /// Whole-body compensation: the multi-body CoM (swing leg included) on the model's CoM.
    WholeBody,
}

/// What the servo-speed check does when the plan needs a joint faster than the servo
/// (firmware token `feasibility=`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feasibility {
    /// Stretch t1, t2 and T by the needed factor × 1.05 (re-checked).
    Stretch,
    /// Lower the swing height by the needed factor × 1.05 (re-checked).
    Lower,
    /// Only report it.
    Off,
}

/// What a walk is made of: the model, the forward walk, the ZMP and swing shapes and dt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WalkConfig {
    /// Pendulum model.
    pub model: ModelKind,
    /// The forward walk (Table 2 names).
    pub walk: ForwardWalk,
    /// Seed 001's continuous ZMP instead of the natural ZMP.
    pub zmp_continuous: bool,
    /// Half travel b of the continuous ZMP, m (`None`: the walk's `a`).
    pub zmp_b: Option<f64>,
    /// Seed 001's sinusoid swing instead of the cycloid.
    pub swing_sinusoid: bool,
    /// The CoM solver: seed 000's exact solution or seed 001's Fourier series.
    pub com: ComMethod,
    /// Sample time, s.
    pub dt_s: f64,
}

/// The f32 sampler of `w` (model, walk, ZMP and swing shape, CoM method, dt) with room for
/// `N` steps.
pub fn build_sampler<const N: usize>(
    w: &WalkConfig,
    robot: &Robot,
) -> Result<WalkSampler<f32, N>, GaitError> {
    let mut s = WalkSampler::idle();
    rebuild_sampler(w, robot, &mut s)?;
    Ok(s)
}

/// [`build_sampler`] in place: `s` becomes the sampler of `w` (done after an error). The
/// firmware builds its samplers this way, where they live: a sampler is ≈ 4.4 KB and its
/// constructors' `Result`s would each put a copy on the stack.
pub fn rebuild_sampler<const N: usize>(
    w: &WalkConfig,
    robot: &Robot,
    s: &mut WalkSampler<f32, N>,
) -> Result<(), GaitError> {
    s.rebuild(|p| build_plan_into(w, robot, p), &w.walk, w.com, w.dt_s)
}

/// The f32 footstep plan of `w` with room for `N` steps.
pub fn build_plan<const N: usize>(
    w: &WalkConfig,
    robot: &Robot,
) -> Result<crate::Plan<f32, N>, GaitError> {
    w.walk.plan::<f32, N>(robot, walk_params(w, robot)?)
}

/// [`build_plan`] written into `plan` in place.
pub fn build_plan_into<const N: usize>(
    w: &WalkConfig,
    robot: &Robot,
    plan: &mut crate::Plan<f32, N>,
) -> Result<(), GaitError> {
    w.walk.plan_into(robot, walk_params(w, robot)?, plan)
}

/// The gait parameters of `w`'s plan: its model, ZMP shape and swing profile.
fn walk_params(w: &WalkConfig, robot: &Robot) -> Result<crate::GaitParams<f32>, GaitError> {
    let fw = &w.walk;
    let model = Model::<f32>::new(w.model, robot, fw.z_c)?;
    let mut params = fw.params(model);
    if w.zmp_continuous {
        let b = w.zmp_b.unwrap_or(fw.a);
        params.zmp = ZmpShape::Continuous { b: b as f32 };
    }
    if w.swing_sinusoid {
        params.swing = SwingShape::Sinusoid {
            height: fw.h_z as f32,
        };
    }
    Ok(params)
}

/// The number type of the per-sample gait work (firmware token `math=`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arithmetic {
    /// The f32 sampler and the f32 IK (or whole-body compensation).
    F32,
    /// The fixed-point sampler ([`crate::trajectory::fixed_sampler`]) and, with [`Compensation::None`], the
    /// integer-only two-leg IK ([`crate::kinematics::fixed_ik`]); whole-body compensation stays f32 on the
    /// fixed-point sample.
    Fixed,
}

/// One gait sample: in f32 always (log, stabilizer, support polygon) and in fixed point too
/// when the fixed-point sampler made it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// The sample in f32.
    pub f32: GaitSample<f32>,
    /// The fixed-point sample it came from.
    pub fixed: Option<FixedSample>,
}

impl Sample {
    /// A zero f32 sample without a fixed-point one (storage, written by the engine).
    #[inline(always)]
    pub fn zero() -> Self {
        Sample {
            f32: GaitSample::zero(),
            fixed: None,
        }
    }
}

/// The gait's per-sample engine: the f32 sampler, or the fixed-point sampler with the
/// integer-only IK ([`Arithmetic`]; built with the feature `fixed-engine` only, so that a
/// firmware without it keeps its flash: ≈ 17 KB for the fixed-point sampler and IK).
// One engine lives for the whole walk and no_std has no Box: the size of the larger variant is
// the cost of choosing at run time.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Engine<const N: usize> {
    /// f32 sampler (either CoM method).
    F32(WalkSampler<f32, N>),
    /// Fixed-point sampler and IK (feature `fixed-engine`).
    #[cfg(feature = "fixed-engine")]
    Fixed(FixedSampler<N>, FixedLegKinematics),
}

impl<const N: usize> Engine<N> {
    /// The engine of `w` in `arithmetic`.
    pub fn new(w: &WalkConfig, arithmetic: Arithmetic, robot: &Robot) -> Result<Self, GaitError> {
        let mut e = Engine::idle();
        e.rebuild(w, arithmetic, robot)?;
        Ok(e)
    }

    /// Storage for an engine: an idle f32 sampler ([`WalkSampler::idle`], done).
    /// [`Engine::rebuild`] makes it an engine in place.
    // Inline: the storage is then written where it lives, not built on the stack and copied.
    #[inline(always)]
    pub fn idle() -> Self {
        Engine::F32(WalkSampler::idle())
    }

    /// Makes this engine, in place, the one [`Engine::new`] would return (the same checks in
    /// the same order); done after an error. The firmware's way: the engine is ≈ 4.4 KB, and
    /// `Engine::new`'s `Result`s would put copies of it on the stack.
    pub fn rebuild(
        &mut self,
        w: &WalkConfig,
        arithmetic: Arithmetic,
        robot: &Robot,
    ) -> Result<(), GaitError> {
        match arithmetic {
            Arithmetic::F32 => match self.f32_storage() {
                Some(s) => rebuild_sampler(w, robot, s),
                None => Err(GaitError::NotBuiltIn),
            },
            #[cfg(feature = "fixed-engine")]
            Arithmetic::Fixed => {
                let ik = FixedLegKinematics::new(robot);
                match self {
                    Engine::Fixed(_, k) => *k = ik,
                    _ => *self = Engine::Fixed(FixedSampler::idle(), ik),
                }
                let Engine::Fixed(s, _) = self else {
                    return Err(GaitError::NotBuiltIn);
                };
                // The plan's own errors first, then the CoM method, then the sampler's.
                s.rebuild(
                    |p| {
                        build_plan_into(w, robot, p)?;
                        match w.com {
                            ComMethod::Exact => Ok(()),
                            _ => Err(GaitError::NotPeriodicWalk),
                        }
                    },
                    w.dt_s,
                )
            }
            #[cfg(not(feature = "fixed-engine"))]
            Arithmetic::Fixed => {
                let _ = robot;
                Err(GaitError::NotBuiltIn)
            }
        }
    }

    /// The engine's storage as an f32 walk sampler (made an idle one if it held the
    /// fixed-point engine): the dry run's scratch ([`servo_timing_in`]) before
    /// [`Engine::rebuild`]. Always `Some`.
    pub fn f32_storage(&mut self) -> Option<&mut WalkSampler<f32, N>> {
        #[cfg(feature = "fixed-engine")]
        if matches!(self, Engine::Fixed(..)) {
            *self = Engine::idle();
        }
        match self {
            Engine::F32(s) => Some(s),
            #[cfg(feature = "fixed-engine")]
            Engine::Fixed(..) => None,
        }
    }

    /// True once the lead-out is over.
    pub fn is_done(&self) -> bool {
        match self {
            Engine::F32(s) => s.is_done(),
            #[cfg(feature = "fixed-engine")]
            Engine::Fixed(s, _) => s.is_done(),
        }
    }

    /// The next sample with the measured torque `tau` (N·m; the fixed-point sampler takes it
    /// in whole mN·m, as read from the bus).
    pub fn next(&mut self, tau: f32) -> Sample {
        let mut out = Sample::zero();
        self.next_into(tau, &mut out);
        out
    }

    /// [`Engine::next`] with τ in whole mN·m (the fixed-point sampler's unit: no float on the
    /// way there).
    pub fn next_mnm(&mut self, tau_mnm: i32) -> Sample {
        let mut out = Sample::zero();
        self.next_mnm_into(tau_mnm, &mut out);
        out
    }

    /// [`Engine::next`] written into `out`, where the sample lives (the control tick: the
    /// ≈ 160 B of a returned sample are not copied).
    pub fn next_into(&mut self, tau: f32, out: &mut Sample) {
        match self {
            Engine::F32(s) => {
                out.f32 = s.next(tau);
                out.fixed = None;
            }
            #[cfg(feature = "fixed-engine")]
            Engine::Fixed(..) => {
                let mnm = if tau.is_finite() {
                    libm::roundf(tau * 1000.0).clamp(-1.0e9, 1.0e9) as i32
                } else {
                    0
                };
                self.next_mnm_into(mnm, out)
            }
        }
    }

    /// [`Engine::next_mnm`] written into `out` (as [`Engine::next_into`]).
    pub fn next_mnm_into(&mut self, tau_mnm: i32, out: &mut Sample) {
        match self {
            Engine::F32(s) => {
                out.f32 = s.next(tau_mnm as f32 * 1e-3);
                out.fixed = None;
            }
            #[cfg(feature = "fixed-engine")]
            Engine::Fixed(s, _) => {
                let f = out.fixed.insert(s.next(tau_mnm));
                out.f32 = f.to_f32();
            }
        }
    }

    /// The joint targets (rad) of `s` with its CoM shifted by `shift` (m): the integer IK for
    /// a fixed-point sample with [`Targets::Plain`], `targets` otherwise.
    pub fn joints(&self, targets: &Targets, s: &Sample, shift: [f32; 2]) -> [f32; LEG_JOINTS] {
        if let Some(q) = self.joints_fx(targets, s, shift) {
            return q.map(crate::maths::fixed_point::fx_to_f32);
        }
        targets.joints(&s.f32, shift).0
    }

    /// The joint targets of `s` in I16F16 rad straight from the integer IK (no f32 round
    /// trip), when [`Engine::joints`] would take that path (a fixed-point sample with
    /// [`Targets::Plain`]); `None` otherwise.
    pub fn joints_fx(
        &self,
        targets: &Targets,
        s: &Sample,
        shift: [f32; 2],
    ) -> Option<[crate::maths::fixed_point::Fx; LEG_JOINTS]> {
        #[cfg(feature = "fixed-engine")]
        if let (Engine::Fixed(_, ik), Some(f), Targets::Plain(_)) = (self, &s.fixed, targets) {
            // No shift (the stabilizer off): the sample as it is, without the two f32 → fixed
            // conversions (library calls on FPU-less cores) and the copy.
            let q = if shift.iter().all(|d| d.to_bits() << 1 == 0) {
                crate::kinematics::fixed_ik::joint_targets(ik, f)
            } else {
                crate::kinematics::fixed_ik::joint_targets(ik, &f.shifted(shift))
            };
            return Some(q.0);
        }
        let _ = (targets, s, shift);
        None
    }
}

/// Sample → 12 joint targets, built once: the paper's pipeline or whole-body compensation.
#[derive(Clone, Debug)]
pub enum Targets {
    /// Pelvis point on the (shifted) model CoM, two-leg IK.
    Plain(LegKinematics<f32>),
    /// Multi-body CoM on the (shifted) model CoM.
    WholeBody(WholeBody<f32>),
}

impl Targets {
    /// The pipeline of `comp` for `robot`.
    pub fn new(robot: &Robot, comp: Compensation) -> Self {
        match comp {
            Compensation::None => Targets::Plain(LegKinematics::new(robot)),
            Compensation::WholeBody => {
                Targets::WholeBody(WholeBody::new(robot, WHOLEBODY_ITERATIONS))
            }
        }
    }

    /// The joint targets of `s` with its CoM shifted by `shift` (m), and what the IK clamped.
    pub fn joints(
        &self,
        s: &GaitSample<f32>,
        shift: [f32; 2],
    ) -> ([f32; LEG_JOINTS], LegsIkReport<f32>) {
        match self {
            Targets::Plain(kin) => {
                let mut shifted = *s;
                shifted.com[0] += shift[0];
                shifted.com[1] += shift[1];
                joint_targets(kin, &shifted)
            }
            Targets::WholeBody(wb) => {
                let c = wb.pelvis_for_com(s, [s.com[0] + shift[0], s.com[1] + shift[1]]);
                (c.joints, c.report)
            }
        }
    }
}

/// The support polygon of a sample: the support sole in single support, both soles otherwise.
pub fn support_of(robot: &Robot, s: &GaitSample<f32>) -> Option<SupportPolygon<f32>> {
    let place = |i: usize| {
        s.feet.get(i).map(|f| Place {
            x: f.x,
            y: f.y,
            yaw: f.yaw,
        })
    };
    match s.phase {
        crate::SupportPhase::Single(side) => {
            SupportPolygon::single(&place(side.index())?, robot).ok()
        }
        _ => SupportPolygon::double(&place(0)?, &place(1)?, robot).ok(),
    }
}

/// The support polygon of the gait samples, rebuilt only when the support phase or a
/// supporting foot changes (a few times per step) instead of every tick: building the hull costs
/// thousands of instructions and the supporting feet stand still while they support.
#[derive(Clone, Debug, Default)]
pub struct SupportCache {
    key: Option<(crate::SupportPhase, [[f32; 3]; 2])>,
    poly: Option<SupportPolygon<f32>>,
}

impl SupportCache {
    /// The support polygon of `s` (as [`support_of`]).
    pub fn get(&mut self, robot: &Robot, s: &GaitSample<f32>) -> Option<&SupportPolygon<f32>> {
        let foot = |i: usize| s.feet.get(i).map_or([0.0; 3], |f| [f.x, f.y, f.yaw]);
        // Only the feet that support enter the key: a swinging foot does not change the polygon.
        let feet = match s.phase {
            crate::SupportPhase::Single(side) => {
                let mut k = [[0.0; 3]; 2];
                if let Some(slot) = k.get_mut(side.index()) {
                    *slot = foot(side.index());
                }
                k
            }
            _ => [foot(0), foot(1)],
        };
        let key = (s.phase, feet);
        if self.key != Some(key) {
            self.poly = support_of(robot, s);
            self.key = Some(key);
        }
        self.poly.as_ref()
    }
}

/// One adjustment or warning of the servo-speed check (the firmware logs each as a fault
/// record).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimingNote {
    /// t1, t2 and T were stretched by `milli`/1000 for joint `joint`.
    Stretched {
        /// The worst joint that triggered it.
        joint: u8,
        /// Total factor, 1/1000.
        milli: u32,
    },
    /// The swing height was lowered to `um` µm for joint `joint`.
    Lowered {
        /// The worst joint that triggered it.
        joint: u8,
        /// New swing height, µm.
        um: u32,
    },
    /// Joint `joint` still needs `mrad_s` mrad/s, above the servo limit.
    TooFast {
        /// The worst joint.
        joint: u8,
        /// Its peak speed, mrad/s.
        mrad_s: i32,
    },
}

/// The outcome of [`servo_timing`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimingCheck {
    /// The walk to use (the configured one, possibly adjusted).
    pub walk: ForwardWalk,
    /// Total factor applied to t1, t2 and T, in 1/1000 (1000 = unchanged).
    pub factor_milli: u32,
    /// Swing height after lowering, µm (`None` = unchanged).
    pub lowered_um: Option<u32>,
    /// The worst joint that triggered the (last) adjustment.
    pub trigger_joint: u8,
    /// Peak speeds of the walk that will run.
    pub report: JointSpeedReport,
    /// Number of adjustments made.
    pub rounds: u8,
    /// Work spent by the dry runs, [`MAX_DRY_RUN_WORK`] units.
    pub work: u32,
}

impl TimingCheck {
    /// True when the walk that will run stays within the servo limit.
    pub fn feasible(&self) -> bool {
        self.report.worst_speed <= self.report.limit
    }

    /// What to report: stretched / lowered, then the warning.
    pub fn notes(&self) -> heapless::Vec<TimingNote, 2> {
        let mut v = heapless::Vec::new();
        if self.factor_milli != 1000 {
            let _ = v.push(TimingNote::Stretched {
                joint: self.trigger_joint,
                milli: self.factor_milli,
            });
        }
        if let Some(um) = self.lowered_um {
            let _ = v.push(TimingNote::Lowered {
                joint: self.trigger_joint,
                um,
            });
        }
        if !self.feasible() {
            let mrad = self.report.worst_speed * 1000.0;
            let mrad_s = if mrad.is_finite() {
                mrad.clamp(0.0, i32::MAX as f64) as i32
            } else {
                i32::MAX
            };
            let joint = u8::try_from(self.report.worst_joint).unwrap_or(u8::MAX);
            let _ = v.push(TimingNote::TooFast { joint, mrad_s });
        }
        v
    }
}

/// `walk` with t1, t2 and T multiplied by `milli`/1000 (the host reproduces it from the log).
pub fn stretched(walk: &ForwardWalk, milli: u32) -> ForwardWalk {
    let f = f64::from(milli) / 1000.0;
    ForwardWalk {
        t1: walk.t1 * f,
        t2: walk.t2 * f,
        period: walk.period * f,
        ..*walk
    }
}

/// Peak joint speeds of `w`'s walk through `targets` at dt (dry run, no τ, no feedback);
/// `N` is the plan capacity. Refused when it would take more than [`MAX_DRY_RUN_WORK`].
pub fn dry_run<const N: usize>(
    w: &WalkConfig,
    robot: &Robot,
    targets: &Targets,
) -> Result<JointSpeedReport, GaitError> {
    let mut budget = MAX_DRY_RUN_WORK;
    let mut scratch = WalkSampler::idle();
    dry_run_within::<N>(w, robot, targets, &mut budget, &mut || {}, &mut scratch)
}

/// [`dry_run`] drawing on `budget` (units of [`MAX_DRY_RUN_WORK`]), calling `feed` every
/// [`DRY_RUN_FEED_EVERY`] samples, its sampler rebuilt in `s`.
fn dry_run_within<const N: usize>(
    w: &WalkConfig,
    robot: &Robot,
    targets: &Targets,
    budget: &mut u32,
    feed: &mut dyn FnMut(),
    s: &mut WalkSampler<f32, N>,
) -> Result<JointSpeedReport, GaitError> {
    let cost = match targets {
        Targets::Plain(_) => 1,
        Targets::WholeBody(_) => WHOLEBODY_SAMPLE_COST,
    };
    rebuild_sampler(w, robot, s)?;
    let mut mon = JointSpeedMonitor::new(robot, w.dt_s)?;
    let mut n = 0u32;
    while !s.is_done() {
        *budget = budget.checked_sub(cost).ok_or(GaitError::DryRunTooLong)?;
        let g = s.next(0.0);
        let (q, _) = targets.joints(&g, [0.0; 2]);
        mon.push(g.time_ns as f64 * 1e-9, &q);
        n = n.wrapping_add(1);
        if n.is_multiple_of(DRY_RUN_FEED_EVERY) {
            feed();
        }
    }
    Ok(mon.report())
}

/// The servo-speed check of `w`'s walk (see the module docs): the walk to run and what was
/// done. Errors are gait-core's rejections of the (adjusted) plan.
pub fn servo_timing<const N: usize>(
    w: &WalkConfig,
    feasibility: Feasibility,
    robot: &Robot,
    targets: &Targets,
) -> Result<TimingCheck, GaitError> {
    servo_timing_fed::<N>(w, feasibility, robot, targets, &mut || {})
}

/// [`servo_timing`] calling `feed` every [`DRY_RUN_FEED_EVERY`] samples (the firmware feeds
/// its watchdog); all rounds together spend at most [`MAX_DRY_RUN_WORK`]
/// ([`GaitError::DryRunTooLong`] beyond).
pub fn servo_timing_fed<const N: usize>(
    w: &WalkConfig,
    feasibility: Feasibility,
    robot: &Robot,
    targets: &Targets,
    feed: &mut dyn FnMut(),
) -> Result<TimingCheck, GaitError> {
    let mut scratch = WalkSampler::idle();
    servo_timing_in::<N>(w, feasibility, robot, targets, feed, &mut scratch)
}

/// [`servo_timing_fed`] with the dry runs' sampler in `scratch`, rebuilt in place for each run
/// (a firmware lends its engine's storage: [`Engine::f32_storage`]); `scratch` is left done.
pub fn servo_timing_in<const N: usize>(
    w: &WalkConfig,
    feasibility: Feasibility,
    robot: &Robot,
    targets: &Targets,
    feed: &mut dyn FnMut(),
    scratch: &mut WalkSampler<f32, N>,
) -> Result<TimingCheck, GaitError> {
    let base = w.walk;
    let mut run = *w;
    let mut budget = MAX_DRY_RUN_WORK;
    let report = dry_run_within::<N>(&run, robot, targets, &mut budget, feed, scratch)?;
    let mut out = TimingCheck {
        walk: base,
        factor_milli: 1000,
        lowered_um: None,
        trigger_joint: 0,
        report,
        rounds: 0,
        work: MAX_DRY_RUN_WORK - budget,
    };
    while !out.feasible() && out.rounds < MAX_TIMING_ROUNDS && feasibility != Feasibility::Off {
        let r = &out.report;
        let need = r.worst_speed / r.limit * TIMING_MARGIN;
        if !(need.is_finite() && need > 1.0) {
            break;
        }
        out.trigger_joint = u8::try_from(r.worst_joint).unwrap_or(u8::MAX);
        match feasibility {
            Feasibility::Stretch => {
                let f = libm::ceil(f64::from(out.factor_milli) * need);
                out.factor_milli = if f < 100_000.0 { f as u32 } else { 100_000 };
                out.walk = stretched(&base, out.factor_milli);
            }
            Feasibility::Lower | Feasibility::Off => {
                let h = libm::floor(out.walk.h_z / need * 1e6);
                let um = if h > 0.0 { h as u32 } else { 0 };
                out.lowered_um = Some(um);
                out.walk.h_z = f64::from(um) * 1e-6;
            }
        }
        out.rounds += 1;
        run.walk = out.walk;
        out.report = dry_run_within::<N>(&run, robot, targets, &mut budget, feed, scratch)?;
        out.work = MAX_DRY_RUN_WORK - budget;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const N: usize = 64;

    fn table2(dt_s: f64) -> WalkConfig {
        WalkConfig {
            model: ModelKind::Tlipfm,
            walk: ForwardWalk::table2(),
            zmp_continuous: false,
            zmp_b: None,
            swing_sinusoid: false,
            com: ComMethod::Exact,
            dt_s,
        }
    }

    fn samples(w: &WalkConfig, robot: &Robot) -> u32 {
        let mut s = build_sampler::<N>(w, robot).unwrap();
        let mut n = 0;
        while !s.is_done() {
            s.next(0.0);
            n += 1;
        }
        n
    }

    #[test]
    fn the_servo_check_spends_one_unit_per_plain_sample() {
        // Table 2 at 5 ms: the first dry run and the stretched one, one unit per sample.
        let robot = Robot::reference();
        let w = table2(0.005);
        let targets = Targets::new(&robot, Compensation::None);
        let mut feeds = 0u32;
        let t = servo_timing_fed::<N>(&w, Feasibility::Stretch, &robot, &targets, &mut || {
            feeds += 1
        })
        .unwrap();
        assert_eq!(t.rounds, 1, "{t:?}");
        let stretched_w = WalkConfig { walk: t.walk, ..w };
        let expected = samples(&w, &robot) + samples(&stretched_w, &robot);
        assert_eq!(t.work, expected);
        assert!(t.work > 4_000 && t.work < MAX_DRY_RUN_WORK, "{}", t.work);
        // Fed every 256 samples of each run.
        let per_run = samples(&w, &robot) / DRY_RUN_FEED_EVERY
            + samples(&stretched_w, &robot) / DRY_RUN_FEED_EVERY;
        assert_eq!(feeds, per_run);
    }

    #[test]
    fn the_longest_plan_is_refused_within_the_work_budget() {
        // The parameter table's worst case: 64 steps of 4 s, 4 s lead-in and lead-out, dt = 1 ms,
        // whole-body compensation: 264,000 samples per run (5 runs with stretching). Refused
        // after at most MAX_DRY_RUN_WORK units (40,000 whole-body samples).
        let robot = Robot::reference();
        let mut w = table2(0.001);
        w.walk.steps = 64;
        w.walk.step_length = 0.01;
        w.walk.period = 4.0;
        w.walk.t1 = 0.4;
        w.walk.t2 = 3.6;
        w.walk.lead_in = 4.0;
        w.walk.lead_out = 4.0;
        assert!(samples(&w, &robot) > 260_000);
        for comp in [Compensation::WholeBody, Compensation::None] {
            let targets = Targets::new(&robot, comp);
            let mut fed = 0u32;
            let r =
                servo_timing_fed::<N>(&w, Feasibility::Stretch, &robot, &targets, &mut || fed += 1);
            assert_eq!(r.unwrap_err(), GaitError::DryRunTooLong, "{comp:?}");
            let cost = match comp {
                Compensation::WholeBody => WHOLEBODY_SAMPLE_COST,
                Compensation::None => 1,
            };
            // Exactly the budget's worth of samples were run (fed every 256 of them).
            assert_eq!(
                fed,
                MAX_DRY_RUN_WORK / cost / DRY_RUN_FEED_EVERY,
                "{comp:?}"
            );
        }
        // A plan that fits is checked whole: Table 2 at 1 ms with whole-body compensation.
        let targets = Targets::new(&robot, Compensation::WholeBody);
        let t = servo_timing::<N>(&table2(0.001), Feasibility::Stretch, &robot, &targets).unwrap();
        assert!(t.work <= MAX_DRY_RUN_WORK, "{t:?}");
    }

    /// A shorter, faster LIPM walk at 10 ms (another plan, model and dt than Table 2).
    fn other_walk() -> WalkConfig {
        let mut w = table2(0.01);
        w.model = ModelKind::Lipm;
        w.walk.steps = 6;
        w.walk.step_length = 0.03;
        w
    }

    /// Samples `e` and `fresh` to the end and asserts they are the same, sample for sample.
    fn assert_same_walk(e: &mut Engine<N>, fresh: &mut Engine<N>) {
        let mut n = 0u32;
        while !fresh.is_done() {
            assert!(!e.is_done(), "rebuilt engine done early at sample {n}");
            assert_eq!(e.next(0.0), fresh.next(0.0), "sample {n}");
            n += 1;
        }
        assert!(e.is_done());
        assert!(n > 500, "{n}");
    }

    #[test]
    fn engines_rebuilt_in_place_walk_as_new_ones() {
        // One engine's storage reused across plans, models, sample times and number types
        // walks exactly as a new engine: nothing of the previous walk (stage, segment, clock,
        // τ response, queued steps) survives a rebuild.
        let robot = Robot::reference();
        let runs = [
            (table2(0.005), Arithmetic::F32),
            (other_walk(), Arithmetic::F32),
            #[cfg(feature = "fixed-engine")]
            (table2(0.005), Arithmetic::Fixed),
            #[cfg(feature = "fixed-engine")]
            (other_walk(), Arithmetic::Fixed),
            (table2(0.005), Arithmetic::F32),
        ];
        let mut e = Engine::<N>::idle();
        assert!(e.is_done(), "idle storage is never sampled");
        for (i, (w, arithmetic)) in runs.iter().enumerate() {
            e.rebuild(w, *arithmetic, &robot).unwrap();
            let mut fresh = Engine::<N>::new(w, *arithmetic, &robot).unwrap();
            if i % 2 == 0 {
                assert_same_walk(&mut e, &mut fresh);
            } else {
                // Rebuilt mid-walk next time round.
                for _ in 0..377 {
                    assert_eq!(e.next(0.0), fresh.next(0.0));
                }
            }
        }
        // A rejected walk leaves the engine done; the next rebuild walks again.
        let mut bad = table2(0.005);
        bad.dt_s = 0.5;
        assert_eq!(
            e.rebuild(&bad, Arithmetic::F32, &robot),
            Err(GaitError::BadSampleTime)
        );
        assert!(e.is_done());
        bad = table2(0.005);
        bad.walk.steps = N + 1;
        assert_eq!(
            e.rebuild(&bad, Arithmetic::F32, &robot),
            Err(GaitError::CapacityExceeded)
        );
        assert!(e.is_done());
        e.rebuild(&other_walk(), Arithmetic::F32, &robot).unwrap();
        let mut fresh = Engine::<N>::new(&other_walk(), Arithmetic::F32, &robot).unwrap();
        assert_same_walk(&mut e, &mut fresh);
    }

    /// The order of Engine::rebuild's checks with the Fourier CoM under `arithmetic`: the
    /// plan's errors first, then `refusal` of the CoM method; the engine is left done.
    #[cfg(any(feature = "fixed-engine", not(feature = "fourier-com")))]
    fn refuses_the_fourier_com_after_the_plan_checks(
        arithmetic: Arithmetic,
        refusal: GaitError,
    ) -> Engine<N> {
        let robot = Robot::reference();
        let mut w = table2(0.005);
        w.com = ComMethod::Fourier { terms: 8 };
        let mut e = Engine::<N>::idle();
        assert_eq!(e.rebuild(&w, arithmetic, &robot), Err(refusal));
        assert!(e.is_done());
        w.walk.steps = 0;
        assert_eq!(e.rebuild(&w, arithmetic, &robot), Err(GaitError::EmptyPlan));
        e
    }

    #[cfg(feature = "fixed-engine")]
    #[test]
    fn the_fixed_engine_refuses_the_fourier_com_after_the_plan_checks() {
        refuses_the_fourier_com_after_the_plan_checks(
            Arithmetic::Fixed,
            GaitError::NotPeriodicWalk,
        );
    }

    #[cfg(not(feature = "fourier-com"))]
    #[test]
    fn without_fourier_com_the_fourier_com_is_refused() {
        // The OpenCM 9.04's gait-core: the Fourier CoM is refused after the plan's checks,
        // the engine is left done; the exact CoM builds in the same storage.
        let mut e =
            refuses_the_fourier_com_after_the_plan_checks(Arithmetic::F32, GaitError::NotBuiltIn);
        let robot = Robot::reference();
        let w = table2(0.005);
        e.rebuild(&w, Arithmetic::F32, &robot).unwrap();
        let mut fresh = Engine::<N>::new(&w, Arithmetic::F32, &robot).unwrap();
        assert_same_walk(&mut e, &mut fresh);
    }

    #[test]
    fn the_servo_check_in_lent_storage_is_the_servo_check() {
        // servo_timing_in with an engine's storage as scratch: the same check as
        // servo_timing_fed, and the storage is left done.
        let robot = Robot::reference();
        let targets = Targets::new(&robot, Compensation::None);
        let w = table2(0.005);
        let own =
            servo_timing_fed::<N>(&w, Feasibility::Stretch, &robot, &targets, &mut || {}).unwrap();
        let mut e = Engine::<N>::new(&other_walk(), Arithmetic::F32, &robot).unwrap();
        let lent = match e.f32_storage() {
            Some(s) => {
                servo_timing_in::<N>(&w, Feasibility::Stretch, &robot, &targets, &mut || {}, s)
                    .unwrap()
            }
            None => panic!("f32 storage"),
        };
        assert_eq!(own, lent);
        assert!(own.rounds >= 1, "{own:?}");
        assert!(e.is_done());
    }
}
