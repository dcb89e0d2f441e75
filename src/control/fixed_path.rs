//! The fixed-point path (`math=fixed`, feature `fixed-gait`; the OpenCM 9.04's only one): the
//! second implementation of [`TickPath`].

use dxl::table::foot::FootForces;
use dxl::table::imu::ImuSample;
use gait_core::feedback::gyro::{FixedGyroFeedback, GyroFeedback};
use gait_core::feedback::stabilizer::StabilizerCorrection;
use gait_core::feedback::{IkOffsets, JointCorrection, JointInput, Measured, SampleCorrection};
use gait_core::gait::Targets;
use gait_core::maths::fixed_point::{fx_sat, fx_to_f32, Fx};
use gait_core::measure::zmp::FixedZmpMeter;
use gait_core::trajectory::fixed_sampler::FixedFoot;
use gait_core::{GaitSample, Robot};

use crate::board::Board;
use crate::imu::{FixedAttitudeFilter, FixedPitchAccel};
use crate::record::LogWriter;
use crate::Config;

use super::modes::{Tau, Walk};
use super::path::{
    finite_rates, ik_f32, pitch_config, raw_rates, stabilizer, Goal, IkRequest, MeasuredZmp,
    TickPath, Trunk,
};

/// The fixed-point path (`math=fixed`, FPU-less cores): the pitch filter with τ in whole mN·m,
/// the tilt, the measured ZMP, the integer IK and the integer gyro damping; the catching step,
/// the levelling, the compliance feed-forward, the force difference control, the deflection
/// feedback and the leg odometry are f32 only and not here. A sample without its integer copy
/// (the online walk) takes the f32 IK and gyro damping.
pub(super) struct FixedPath<'r> {
    pitch: FixedPitchAccel,
    attitude: FixedAttitudeFilter,
    zmp_meter: FixedZmpMeter,
    stabilizer: StabilizerCorrection<'r>,
    gyro: GyroFeedback,
    gyro_fx: FixedGyroFeedback,
}

impl<'r> FixedPath<'r> {
    /// The path of `cfg` for `robot`.
    pub(super) fn new(cfg: &Config, robot: &'r Robot) -> Self {
        FixedPath {
            pitch: FixedPitchAccel::new(pitch_config(cfg, robot)),
            attitude: FixedAttitudeFilter::new(cfg.dt_s() as f32),
            zmp_meter: FixedZmpMeter::new(robot, cfg.min_load_n),
            stabilizer: stabilizer(cfg, robot),
            gyro: cfg.gyro_feedback,
            gyro_fx: FixedGyroFeedback::new(&cfg.gyro_feedback),
        }
    }
}

/// A foot sample in fixed point (exact for a sample the fixed-point sampler made).
fn fixed_foot(f: &gait_core::trajectory::swing::FootSample<f32>) -> FixedFoot {
    FixedFoot {
        x: fx_sat(f.x),
        y: fx_sat(f.y),
        z: fx_sat(f.z),
        yaw: fx_sat(f.yaw),
    }
}

impl TickPath for FixedPath<'_> {
    fn trunk(&mut self, imu: Option<&ImuSample>, _: &mut Walk) -> Trunk {
        let Some(s) = imu else {
            self.pitch.update(None);
            return Trunk {
                gyro: None,
                gyro_raw: None,
                attitude: None,
                tilt: self.attitude.tilt(),
            };
        };
        self.pitch.update(Some(s.gyro_urad_s[1]));
        let tilt = self.attitude.update(s.gyro_urad_s, s.accel_um_s2);
        let gyro = finite_rates(s.gyro_rad_s());
        Trunk {
            gyro,
            gyro_raw: raw_rates(imu, gyro),
            attitude: None,
            tilt,
        }
    }

    fn tau(&self) -> Tau {
        Tau::MilliNm(self.pitch.torque_mnm())
    }

    fn zmp(
        &self,
        feet: &[Option<FootForces>; 2],
        previous: &GaitSample<f32>,
        previous_fx: Option<[FixedFoot; 2]>,
    ) -> MeasuredZmp {
        let [fl, fr] = feet;
        let [pl, pr] = &previous.feet;
        let forces = |f: &Option<FootForces>| f.map(|f| f.forces_mn);
        let [fpl, fpr] = previous_fx.unwrap_or_else(|| [fixed_foot(pl), fixed_foot(pr)]);
        let fx = self.zmp_meter.zmp((&fpl, forces(fl)), (&fpr, forces(fr)));
        MeasuredZmp {
            m: fx.map(|z| z.map(fx_to_f32)),
            fx,
        }
    }

    fn update_samples<B: Board>(
        &mut self,
        _: &mut B,
        _: &mut LogWriter,
        m: &Measured<'_>,
        present: &GaitSample<f32>,
        offsets: &mut IkOffsets,
    ) -> bool {
        self.stabilizer.update(m, present, offsets);
        false
    }

    fn joints(&mut self, targets: &Targets, m: &Measured<'_>, ik: &IkRequest<'_>, goal: &mut Goal) {
        let fx_q = match (ik.ahead, ik.plan) {
            (Some(a), Some(p)) if !ik.f32_only => p.engine().joints_fx(targets, a, ik.com_shift),
            _ => None,
        };
        match fx_q {
            Some(mut q) => {
                self.gyro_fx
                    .for_each(ik.present.phase, ik.gyro_raw, |j, d| {
                        if let Some(v) = q.get_mut(j) {
                            *v = v.saturating_add(Fx::from_bits(d));
                        }
                    });
                *goal = Goal::Fx(q);
            }
            None => {
                let (mut q, loaded) = ik_f32(targets, ik);
                let input = JointInput {
                    phase: ik.present.phase,
                    loaded,
                    com_shift: ik.com_shift,
                    walk_tick: ik.walk_tick,
                };
                self.gyro.correct_joints(m, &input, &mut q);
                *goal = Goal::Rad(q);
            }
        }
    }
}
