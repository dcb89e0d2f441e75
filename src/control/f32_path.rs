//! The f32 path: every feedback (the first implementation of [`TickPath`]).

use dxl::table::foot::FootForces;
use dxl::table::imu::ImuSample;
use gait_core::feedback::catch::StepAdapter;
use gait_core::feedback::compliance::{LoadModel, SagFeedForward};
use gait_core::feedback::fdc::FootForceCorrection;
use gait_core::feedback::gyro::GyroFeedback;
use gait_core::feedback::stabilizer::StabilizerCorrection;
use gait_core::feedback::{IkOffsets, JointCorrection, JointInput, Measured, SampleCorrection};
use gait_core::gait::Targets;
use gait_core::measure::zmp::{ForceReading, SolePose, ZmpMeter};
use gait_core::robot::LEG_JOINTS;
use gait_core::trajectory::fixed_sampler::FixedFoot;
use gait_core::{GaitSample, Robot, Side};

use crate::board::Board;
use crate::bus::BoardMaster;
use crate::imu::{AttitudeFilter, Heading, PitchAccel};
use crate::record::{FaultKind, LogWriter};
use crate::supervisor::JointMap;
use crate::Config;

use super::act::fault;
use super::modes::{Tau, Walk};
use super::path::{
    finite_rates, ik_f32, pitch_config, raw_rates, stabilizer, Goal, IkRequest, MeasuredZmp,
    TickPath, Trunk,
};
use super::servo_sense::ServoSense;

/// The force reading of a foot sample (N; NaN when missing).
fn reading(f: &Option<FootForces>) -> ForceReading<f32> {
    ForceReading::new(f.map_or([f32::NAN; 4], |f| f.forces_mn.map(|v| v as f32 * 1e-3)))
}

/// The catching step (gait-core `feedback::catch` A1–A7) and the landing hold (A8–A9) as the
/// first sample correction, with its log: the largest landing move asked during one single
/// support and the landing hold's move, written as `CatchStep` records (components 0, 1 and 2)
/// when that single support ends. Its state also keeps the swing sole level (A10: a joint
/// correction) and holds the walk's clock (A11).
pub(super) struct Catching {
    adapter: StepAdapter,
    /// The swing foot of the single support being noted.
    swing: Option<Side>,
    /// Its largest move asked (forward, leftward; trunk frame) and the landing hold's move
    /// (along the stance foot's heading), m.
    largest: [f32; 3],
}

impl Catching {
    fn new(adapter: StepAdapter) -> Self {
        Catching {
            adapter,
            swing: None,
            largest: [0.0; 3],
        }
    }

    /// Notes this tick's catch `asked` and the landing hold's move in `phase`; logs the swing's
    /// when it ends (the catch's two components when it caught, the hold's when it moved).
    fn note<B: Board>(
        &mut self,
        board: &mut B,
        log: &mut LogWriter,
        phase: gait_core::SupportPhase,
        asked: [f32; 2],
    ) {
        let swing = phase.swing();
        if swing != self.swing {
            if let Some(side) = self.swing {
                let now = board.now_us();
                let side_code: u8 = if side == Side::Left { 1 } else { 2 };
                let [x, y, landing] = self.largest;
                let caught = (x != 0.0 || y != 0.0).then_some([(0u8, x), (1, y)]);
                let held = (landing != 0.0).then_some([(2u8, landing)]);
                for (component, v) in caught
                    .into_iter()
                    .flatten()
                    .chain(held.into_iter().flatten())
                {
                    // |v| ≤ the limits (< 0.1 m): the µm fit an i32.
                    let um = gait_core::maths::fastmath::round_i32(v * 1e6);
                    let rec = fault(now, FaultKind::CatchStep, side_code * 16 + component, um);
                    log.write(board, rec);
                }
            }
            self.swing = swing;
            self.largest = [0.0; 3];
        }
        for (l, a) in self.largest.iter_mut().zip(asked) {
            if a.abs() > l.abs() {
                *l = a;
            }
        }
        if let Some((_, forward)) = self.adapter.landing_move_forward() {
            self.largest[2] = forward;
        }
    }

    /// (A1)–(A7) from the `present` sample; the move asked is noted for the log.
    fn update<B: Board>(
        &mut self,
        board: &mut B,
        log: &mut LogWriter,
        m: &Measured<'_>,
        present: &GaitSample<f32>,
    ) {
        if !self.adapter.is_on() {
            return;
        }
        let asked = self.adapter.update(present, m.attitude, m.gyro, m.loads);
        self.note(board, log, present.phase, asked);
    }
}

/// The swing sole's levelling (A10) as a joint correction.
impl JointCorrection for Catching {
    fn correct_joints(&mut self, _: &Measured<'_>, _: &JointInput<'_>, q: &mut [f32; LEG_JOINTS]) {
        self.adapter.apply_level(q);
    }
}

/// The servo survey's records (`ServoSurvey`): component 0 the stiffness measured (mN·m/rad;
/// 0: none), component 1 the deflection feedback's gain it set (1/1000 s⁻¹), component 2 the
/// supply it was measured at (mV; 0: none read yet).
fn survey_records<B: Board>(
    board: &mut B,
    log: &mut LogWriter,
    note: &super::servo_sense::SurveyNote,
) {
    let now = board.now_us();
    let k = note.stiffness.map_or(0.0, |s| s.k);
    let volts = if note.volts.is_finite() {
        note.volts
    } else {
        0.0
    };
    for (component, v) in [(0u8, k), (1, note.ki), (2, volts)] {
        // k ≤ 1000 N·m/rad, k_i ≤ 150/s, the supply's 0.1 V in a u16: the thousandths fit an
        // i32.
        let milli = gait_core::maths::fastmath::round_i32(v * 1e3);
        log.write(board, fault(now, FaultKind::ServoSurvey, component, milli));
    }
}

/// Whether one of the servo survey's uses is on: the deflection integral from the softness
/// (`deflection_soft` > 0) or the gyro damping's gains following the stiffness.
fn survey_wanted(cfg: &Config) -> bool {
    let g = &cfg.gyro_feedback;
    cfg.deflection.soft_ki > 0.0
        || (g.follow_stiffness && (g.ankle != 0.0 || g.hip != 0.0))
        || (cfg.compliance_follow && (cfg.compliance.roll != 0.0 || cfg.compliance.pitch != 0.0))
}

impl F32Path<'_> {
    /// The gyro damping's gains for the servo survey's stiffness at the present supply (G3),
    /// and with `compliance_follow` the sag feed-forward's stiffness (at most
    /// 1 + `MAX_SOFTNESS` times softer than configured); the configured ones before the survey.
    fn follow_survey(&mut self) {
        let Some(k) = self.servo_sense.stiffness() else {
            return;
        };
        let k_n = self.compliance_configured;
        self.gyro = self.gyro_configured.for_stiffness(k_n, k);
        if self.compliance_follow {
            let softest = k_n / (1.0 + gait_core::measure::stiffness::MAX_SOFTNESS);
            self.sag.compliance.stiffness = libm::fmaxf(k, softest);
        }
    }
}

/// The f32 path: every feedback.
pub(super) struct F32Path<'r> {
    dt_s: f32,
    pitch: PitchAccel,
    attitude: AttitudeFilter,
    heading: Heading,
    zmp_meter: ZmpMeter<f32>,
    catching: Catching,
    stabilizer: StabilizerCorrection<'r>,
    foot_force: FootForceCorrection,
    sag: SagFeedForward,
    /// The sag feed-forward's configured stiffness K_n (N·m/rad), and whether it follows the
    /// servo survey's.
    compliance_configured: f32,
    compliance_follow: bool,
    /// The gyro damping as configured, and as it acts (its gains follow the servo survey's
    /// stiffness, gait-core gyro G3).
    gyro_configured: GyroFeedback,
    gyro: GyroFeedback,
    /// The servos' Present Position: the deflection feedback, the leg odometry, the swing's
    /// lags and the servo survey (no reads while none of them wants one).
    servo_sense: ServoSense,
    map: &'r JointMap,
}

impl<'r> F32Path<'r> {
    /// The path of `cfg` for `robot` walking at the CoM height `z_c` (m).
    pub(super) fn new(cfg: &Config, robot: &'r Robot, map: &'r JointMap, z_c: f32) -> Self {
        let dt_s = cfg.dt_s() as f32;
        F32Path {
            dt_s,
            pitch: PitchAccel::new(pitch_config(cfg, robot)),
            attitude: AttitudeFilter::new(),
            heading: Heading::new(),
            zmp_meter: ZmpMeter::new(robot, cfg.min_load_n),
            catching: Catching::new(StepAdapter::new(&cfg.step_adaptation, robot, z_c, dt_s)),
            stabilizer: stabilizer(cfg, robot),
            foot_force: FootForceCorrection::new(cfg.foot_force, dt_s),
            sag: SagFeedForward {
                load: LoadModel::new(robot),
                compliance: cfg.compliance,
            },
            compliance_configured: cfg.compliance.stiffness,
            compliance_follow: cfg.compliance_follow,
            gyro_configured: cfg.gyro_feedback,
            gyro: cfg.gyro_feedback,
            servo_sense: ServoSense::new(
                &cfg.deflection,
                cfg.compliance.stiffness,
                survey_wanted(cfg),
                cfg.sole_poses_measured,
                cfg.step_adaptation.level_joints > 0.0,
                cfg.step_adaptation.hold_lag_m > 0.0,
                robot,
                dt_s,
            ),
            map,
        }
    }
}

impl TickPath for F32Path<'_> {
    fn read_servos<B: Board>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        previous: &GaitSample<f32>,
        walk: &mut Walk,
    ) {
        let d = &mut self.servo_sense;
        let [l, r] = &previous.feet;
        let landed = d.read(
            bus,
            self.map,
            &[l.sole_place(), r.sole_place()],
            previous.phase,
        );
        self.catching.adapter.set_joint_lag(d.swing_lag());
        self.catching.adapter.set_swing_lag_m(d.sole_lag_m());
        // Where the new foot landed off its targets: the online walk's position hold (P1), a
        // plan's landing hold (A8).
        if let Some((side, offset)) = landed {
            match walk.gait.online_mut() {
                Some(o) => o.set_landing_offset(side, offset),
                None => self.catching.adapter.set_landing(side, offset),
            }
        }
    }

    fn ramp_end(&mut self, q: &mut [f32; LEG_JOINTS], loaded: &GaitSample<f32>) {
        self.sag
            .load
            .apply(&self.sag.compliance, q, loaded, [0.0; 2]);
    }

    fn trunk(&mut self, imu: Option<&ImuSample>, walk: &mut Walk) -> Trunk {
        let Some(s) = imu else {
            self.pitch.update(f32::NAN);
            return Trunk {
                gyro: None,
                gyro_raw: None,
                attitude: None,
                tilt: self.attitude.tilt().tilt,
            };
        };
        let g = s.gyro_rad_s();
        self.pitch.update(g[1]);
        let att = self.attitude.update(g, s.accel_m_s2(), self.dt_s);
        // The online walk's heading hold: the gyro's yaw, the bias learnt while it stands.
        if let Some(o) = walk.gait.online_mut() {
            let still = matches!(
                o.mode(),
                gait_core::trajectory::online::WalkMode::Standing(_)
            );
            o.set_heading(self.heading.update(g, &att, self.dt_s, still));
        }
        let gyro = finite_rates(g);
        Trunk {
            gyro,
            gyro_raw: raw_rates(imu, gyro),
            attitude: Some([att.roll, att.pitch]),
            tilt: att.tilt,
        }
    }

    fn tau(&self) -> Tau {
        Tau::Nm(self.pitch.torque())
    }

    fn loads(&self, feet: &[Option<FootForces>; 2]) -> [f32; 2] {
        feet.each_ref().map(|f| {
            reading(f)
                .compression()
                .map_or(f32::NAN, |c| c.iter().sum::<f32>())
        })
    }

    fn zmp(
        &self,
        feet: &[Option<FootForces>; 2],
        previous: &GaitSample<f32>,
        _: Option<[FixedFoot; 2]>,
    ) -> MeasuredZmp {
        let [fl, fr] = feet;
        let [pl, pr] = &previous.feet;
        let [l, r] = self.servo_sense.feet([pl.sole_place(), pr.sole_place()]);
        let m = self
            .zmp_meter
            .zmp((&l, &reading(fl)), (&r, &reading(fr)))
            .zmp;
        MeasuredZmp { m, fx: None }
    }

    fn follow(&mut self, phase: gait_core::SupportPhase, loads: [f32; 2]) {
        self.servo_sense.follow(phase, loads);
    }

    fn wants_hold(&self) -> bool {
        self.catching.adapter.wants_hold()
    }

    fn update_samples<B: Board>(
        &mut self,
        board: &mut B,
        log: &mut LogWriter,
        m: &Measured<'_>,
        present: &GaitSample<f32>,
        offsets: &mut IkOffsets,
    ) -> bool {
        if let Some(note) = self.servo_sense.take_survey_note() {
            survey_records(board, log, &note);
            self.follow_survey();
        }
        self.catching.update(board, log, m, present);
        self.stabilizer.update(m, present, offsets);
        self.foot_force.update(m, present, offsets);
        self.catching.adapter.is_shifting()
    }

    fn apply_samples(&self, sample: &mut GaitSample<f32>) {
        // (A6): the feet by their offsets, the CoM and the ZMP reference by the body's.
        self.catching.adapter.apply(sample);
    }

    fn reference_shift(&self) -> [f32; 2] {
        self.catching.adapter.landing_body_shift()
    }

    fn joints(&mut self, targets: &Targets, m: &Measured<'_>, ik: &IkRequest<'_>, goal: &mut Goal) {
        let (mut q, loaded) = ik_f32(targets, ik);
        let input = JointInput {
            phase: ik.present.phase,
            loaded,
            com_shift: ik.com_shift,
            walk_tick: ik.walk_tick,
        };
        self.servo_sense.note_ik(&q);
        self.sag.correct_joints(m, &input, &mut q);
        self.gyro.correct_joints(m, &input, &mut q);
        self.catching.correct_joints(m, &input, &mut q);
        self.servo_sense.correct_joints(m, &input, &mut q);
        *goal = Goal::Rad(q);
    }

    fn surveys(&self) -> Option<(u16, u16)> {
        self.servo_sense.surveys()
    }

    fn supply(&mut self, dv: u16) {
        if self.servo_sense.supply(f32::from(dv) * 0.1) {
            self.follow_survey();
        }
    }

    fn servo_stiffness_cnm(&self) -> u16 {
        // Saturating float-to-int conversion (K ≤ 1000 N·m/rad: at most 100,000 → 65,535).
        self.servo_sense
            .stiffness()
            .map_or(0, |k| (k * 100.0 + 0.5) as u16)
    }
}
