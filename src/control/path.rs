//! The tick's arithmetic, chosen once per run: `F32Path` (every feedback, f32 maths) or
//! `FixedPath` (`math=fixed`, FPU-less cores: the estimate and the joint path in integers).
//! Each is one implementation of [`TickPath`]; the [`Controller`](super::controller::Controller)
//! is generic over it, so a build that never runs a path leaves it out (the OpenCM 9.04 has
//! only the fixed one).
//!
//! The corrections around the IK (gait-core [`gait_core::feedback`]) in their order:
//!
//! | path | sample corrections (before the IK) | joint corrections (after it) |
//! | --- | --- | --- |
//! | f32 | catching step, stabilizer, foot force difference | compliance feed-forward, gyro damping, swing sole levelling, deflection feedback |
//! | fixed | stabilizer | gyro damping (integer) |

use dxl::table::foot::FootForces;
use dxl::table::imu::ImuSample;
use gait_core::feedback::stabilizer::{Stabilizer, StabilizerCorrection};
use gait_core::feedback::{IkOffsets, Measured};
use gait_core::gait::{Sample, Targets};
use gait_core::maths::fixed_point::Fx;
use gait_core::robot::LEG_JOINTS;
use gait_core::trajectory::fixed_sampler::FixedFoot;
use gait_core::{GaitSample, Robot};

use crate::board::Board;
use crate::bus::BoardMaster;
use crate::imu::PitchAccelConfig;
use crate::record::LogWriter;
use crate::Config;

use super::modes::{Plan, Tau, Walk};

/// What the IMU's sample tells this tick.
#[derive(Clone, Copy, Debug)]
pub(super) struct Trunk {
    /// Roll and pitch rates, rad/s (`None`: missing or non-finite).
    pub gyro: Option<[f32; 2]>,
    /// The same rates as the IMU gave them, µrad/s (for the integer gyro damping).
    pub gyro_raw: Option<[i32; 2]>,
    /// Roll and pitch of the attitude filter, rad (f32 path, fresh sample only).
    pub attitude: Option<[f32; 2]>,
    /// Tilt from vertical, rad (the supervisor's fall check).
    pub tilt: f32,
}

/// The measured ZMP: f32, and the integer one when the fixed-point path measured it.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct MeasuredZmp {
    /// m (`None`: not available).
    pub m: Option<[f32; 2]>,
    /// I16F16 m, logged as it is.
    pub fx: Option<[Fx; 2]>,
}

/// A tick's joint targets: f32 rad, or I16F16 rad straight from the integer IK.
#[cfg_attr(not(feature = "fixed-gait"), allow(dead_code))]
pub(super) enum Goal {
    /// f32 rad (may be non-finite: [`crate::supervisor::safe_targets`] catches it).
    Rad([f32; LEG_JOINTS]),
    /// I16F16 rad ([`crate::supervisor::safe_targets_fx`]).
    Fx([Fx; LEG_JOINTS]),
}

/// What the IK takes this tick: the plan (its engine's IK paths), the sample the IK takes when
/// it is the plan's (`ahead`), the present one, and the sample corrections' output.
#[cfg_attr(not(feature = "fixed-gait"), allow(dead_code))]
pub(super) struct IkRequest<'a> {
    /// The plan, when the gait is one.
    pub plan: Option<&'a Plan>,
    /// The plan's sample the IK takes, corrected.
    pub ahead: Option<&'a Sample>,
    /// The present sample, corrected (the IK's when there is no `ahead`).
    pub present: &'a GaitSample<f32>,
    /// The commanded CoM's shift, m.
    pub com_shift: [f32; 2],
    /// The soles' height offsets, m.
    pub sole_dz: [f32; 2],
    /// Walk tick.
    pub walk_tick: u32,
    /// The gyro's rates as the IMU gave them, µrad/s (the integer gyro damping).
    pub gyro_raw: Option<[i32; 2]>,
    /// The integer IK is not to be used (fault injection on the f32 targets).
    pub f32_only: bool,
}

/// One arithmetic of the tick: the estimate of the trunk, τ and the ZMP, the corrections and the
/// IK.
pub(super) trait TickPath {
    /// Reads the servos' Present Position this tick needs (one BULK READ, f32 path only).
    fn read_servos<B: Board>(
        &mut self,
        _bus: &mut BoardMaster<'_, B>,
        _previous: &GaitSample<f32>,
        _walk: &mut Walk,
    ) {
    }

    /// The path's feed-forwards on the ramp's end pose `q` (the IK's targets of `loaded`).
    fn ramp_end(&mut self, _q: &mut [f32; LEG_JOINTS], _loaded: &GaitSample<f32>) {}

    /// The IMU's fresh sample (or none) into the trunk's estimate; the online walk's heading.
    fn trunk(&mut self, imu: Option<&ImuSample>, walk: &mut Walk) -> Trunk;

    /// τ = J·φ̈ for the sampler.
    fn tau(&self) -> Tau;

    /// The soles' loads, N (left, right; NaN: not measured or not needed by this path).
    fn loads(&self, _feet: &[Option<FootForces>; 2]) -> [f32; 2] {
        [f32::NAN; 2]
    }

    /// The measured ZMP of the forces `feet` under the soles of the `previous` sample (its
    /// integer feet `previous_fx` when the fixed-point sampler made it).
    fn zmp(
        &self,
        feet: &[Option<FootForces>; 2],
        previous: &GaitSample<f32>,
        previous_fx: Option<[FixedFoot; 2]>,
    ) -> MeasuredZmp;

    /// Follows the executed support phase and the loads (the leg odometry's survey).
    fn follow(&mut self, _phase: gait_core::SupportPhase, _loads: [f32; 2]) {}

    /// Whether the walk's clock stands still this tick (the catching step's hold).
    fn wants_hold(&self) -> bool {
        false
    }

    /// The sample corrections' updates, in this path's order, from the `present` sample as the
    /// walk gave it: their offsets into `offsets`; whether they move the samples this tick
    /// ([`TickPath::apply_samples`]).
    fn update_samples<B: Board>(
        &mut self,
        board: &mut B,
        log: &mut LogWriter,
        measured: &Measured<'_>,
        present: &GaitSample<f32>,
        offsets: &mut IkOffsets,
    ) -> bool;

    /// The sample corrections' moves on a copy of a sample, in this path's order.
    fn apply_samples(&self, _sample: &mut GaitSample<f32>) {}

    /// How far the frame the moved samples command the joints in stands from the world the
    /// robot's references are logged in (the landing hold's share of the body's offset), m.
    fn reference_shift(&self) -> [f32; 2] {
        [0.0; 2]
    }

    /// The IK and the joint corrections, in this path's order.
    fn joints(
        &mut self,
        targets: &Targets,
        measured: &Measured<'_>,
        ik: &IkRequest<'_>,
        goal: &mut Goal,
    );

    /// Leg odometry surveys taken and refused, when it runs.
    fn surveys(&self) -> Option<(u16, u16)> {
        None
    }

    /// The leg servos' supply voltage last read (0.1 V, > 0): the servo survey's stiffness
    /// follows it.
    fn supply(&mut self, _dv: u16) {}

    /// The leg servos' stiffness the servo survey measured, at the present supply, in
    /// 0.01 N·m/rad (0: no survey, or not yet).
    fn servo_stiffness_cnm(&self) -> u16 {
        0
    }
}

/// The f32 IK of `ik` (soles lifted by `sole_dz` when it is not 0): the targets and the sample
/// whose loads the compliance feed-forward takes.
pub(super) fn ik_f32<'a>(
    targets: &Targets,
    ik: &IkRequest<'a>,
) -> ([f32; LEG_JOINTS], &'a GaitSample<f32>) {
    let lift = |g: &mut GaitSample<f32>| {
        for (f, dz) in g.feet.iter_mut().zip(ik.sole_dz) {
            f.z += dz;
        }
    };
    let lifted = ik.sole_dz != [0.0; 2];
    match (ik.ahead, ik.plan) {
        (Some(a), Some(p)) if lifted => {
            let mut l = *a;
            lift(&mut l.f32);
            (p.engine().joints(targets, &l, ik.com_shift), &a.f32)
        }
        (Some(a), Some(p)) => (p.engine().joints(targets, a, ik.com_shift), &a.f32),
        _ if lifted => {
            let mut l = *ik.present;
            lift(&mut l);
            (targets.joints(&l, ik.com_shift).0, ik.present)
        }
        _ => (targets.joints(ik.present, ik.com_shift).0, ik.present),
    }
}

/// The pitch filter's configuration of `cfg` for `robot`.
pub(super) fn pitch_config(cfg: &Config, robot: &Robot) -> PitchAccelConfig {
    PitchAccelConfig {
        dt_s: cfg.dt_s() as f32,
        cutoff_hz: cfg.imu_cutoff_hz,
        inertia: robot.masses.upper_body_inertia as f32,
    }
}

/// The stabilizer of `cfg` (`stab=on`) for `robot`.
pub(super) fn stabilizer<'r>(cfg: &Config, robot: &'r Robot) -> StabilizerCorrection<'r> {
    let s = Stabilizer::<f32>::new(&cfg.stabilizer, cfg.dt_s(), robot.masses.upper_body_height);
    StabilizerCorrection::new(s, cfg.stabilizer_on, robot)
}

/// The gyro's roll and pitch rates when both are finite.
pub(super) fn finite_rates(g: [f32; 3]) -> Option<[f32; 2]> {
    let [roll_rate, rate, _] = g;
    Some([roll_rate, rate]).filter(|g| g.iter().all(|v| v.is_finite()))
}

/// The raw rates of `imu` when the f32 ones passed.
pub(super) fn raw_rates(imu: Option<&ImuSample>, gyro: Option<[f32; 2]>) -> Option<[i32; 2]> {
    imu.filter(|_| gyro.is_some())
        .map(|s| [s.gyro_urad_s[0], s.gyro_urad_s[1]])
}
