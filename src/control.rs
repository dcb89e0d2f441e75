//! The walking controller: start-up, the smooth move to the initial pose, the control loop at
//! the servo rate, and the stop sequence. Written once over `B: Board`; the QEMU and OpenCR
//! binaries call [`run`], host tests run it on a fake board.
//!
//! # One tick (period [`Config::tick_period_us`], default 5 ms = 200 Hz)
//! 1. `wait_tick()`; overruns go to the supervisor (a burst of them stops).
//! 2. ONE BULK READ: foot boards 111/112 (18 bytes at 128: 4 forces + counter) and the IMU 200
//!    (26 bytes at 128: gyro, accelerometer, counter).
//! 3. Every reply is checked for plausibility ([`crate::plausible`]: the board's sample counter
//!    advanced, values in the sensor's range, foot forces consistent with the robot's weight);
//!    a rejected reply counts as missing (fault record `SensorRejected` at the first of a run).
//!    Per device the supervisor decides fresh / held (last good value, at most
//!    [`crate::supervisor::SupervisorConfig::hold_ticks`] ticks in a row) / lost (stop); a
//!    board without an accepted sample for longer than [`Config::sensor_stale_ms`] stops
//!    (`SensorStale`, exit 19) whatever `hold_ticks`.
//! 4. Measured ZMP from the 8 forces (gait-core `measured_zmp` by a `ZmpMeter`, feet placed
//!    where the previous gait sample put them moved by the leg odometry's corrections
//!    (`sole_poses=measured`, the default, f32 path: gait-core [`gait_core::measure::odometry`]; each
//!    landing surveyed once in its double support from the Present Position of the stance leg's
//!    six servos, then the new leg's on the next tick, in one more BULK READ each), feet under
//!    [`Config::min_load_n`] ignored); φ̈
//!    from the gyro pitch rate through [`PitchAccel`], τ = J·φ̈; tilt from the accelerometer
//!    (fall → stop).
//! 5. One gait sample with τ, checked finite (CoM, ZMP, feet; then the stabilizer's shift) before
//!    the IK: a non-finite one holds the last targets and stops (`NonFiniteSample`, exit 18); with `stab=on` the feedback stabilizer (gait-core
//!    [`gait_core::feedback::stabilizer`]) turns the measured ZMP error and the gyro into a bounded shift
//!    δ of the commanded CoM (‖δ‖ ≤ `stab_max` ≤ 2 cm, rate-limited, ZMP command inside the
//!    support polygon with margin; a missing or non-finite measurement never reaches it);
//!    then [`Targets`] (built once): the paper's pipeline (pelvis on the model's CoM + δ, two-leg
//!    IK) or, with `comp=wholebody`, whole-body compensation (pelvis placed so the multi-body
//!    CoM is on the model's CoM + δ, gait-core [`gait_core::kinematics::wholebody`]); the IK clamps to
//!    reach and joint limits; with `compliance_roll`/`compliance_pitch` = k the servos' predicted static sag under
//!    the gait's loads is added (k·τ/K per joint, gait-core [`gait_core::feedback::compliance`], also on
//!    the start-up ramp's end pose; f32 only: off with `math=fixed`); the gyro damping; with
//!    `deflection_ki` > 0 the servo deflection feedback (gait-core [`gait_core::feedback::deflection`],
//!    f32 only: the pitch servos' Present Position, read in one more BULK READ right after the
//!    sensors', drives the stance leg's joints to their targets); [`safe_targets`] to the servo ticks (a non-finite target holds
//!    the previous tick and stops); ONE SYNC WRITE of the 12 Goal Positions (116, 4 bytes
//!    each).
//!    The catching step (`catch_gain`, default on; gait-core [`gait_core::feedback::catch`], f32
//!    only) runs before the stabilizer: the attitude and the gyro give the capture-point
//!    error; beyond the ankles' deadband it moves the swing foot's landing place, and the
//!    feet's and the body's offsets from the plan are added to copies of the samples (the IK's,
//!    the log's reference and the next tick's measured-ZMP feet); each catch is logged as two
//!    `CatchStep` records when its single support ends. The same state keeps the swing sole
//!    level (`catch_level_pitch`, `catch_level_roll`, default on; `catching` A10): the swing
//!    leg's ankle pitch and roll targets turn back by the trunk's deviation from its baseline,
//!    added after the compliance feed-forward and the gyro damping. With `catch_hold_max` > 0
//!    (default 0.15 s, `catching` A11) the walk's clock stands still for a tick (the same samples
//!    again) while a caught swing foot is still on its way to its landing place.
//!    With `servo_lead = Δ` (default 0) the targets come from the gait sample Δ ahead
//!    (a delay line of [`MAX_LEAD_TICKS`] samples) while the reference, the log, the stabilizer
//!    and the gyro feedback's support phase stay at the present sample: a feed-forward of the
//!    position servos' lag. Measured on the MuJoCo robot (Table 2, paper timing, default gyro
//!    feedback; true CoP − reference, mean |e| x / y): Δ = 0 13.0 / 34.5 mm, 50 ms
//!    15.0 / 31.0, 100 ms 16.9 / 30.4, 150 ms 17.0 / 30.8, 200 ms 18.7 / 33.3 — laterally a
//!    little better, sagittally worse, so it stays off by default.
//! 6. The servo monitor ([`crate::monitor`]) reads one leg servo's Hardware Error Status,
//!    current, voltage and temperature (round-robin); a limit exceeded stops (`ServoFault`).
//! 7. The tick log record (nominal time, ZMP reference, measured ZMP, CoM, τ, support phase,
//!    fault state, bus error counters, overruns); the watchdog is fed.
//!
//! With `math=fixed` (FPU-less cores, feature `fixed-gait`) steps 4-5 and 7 run in integers:
//! the pitch filter with τ in whole mN·m ([`FixedPitchAccel`]), the tilt
//! ([`FixedAttitudeFilter`]), the measured ZMP ([`FixedZmpMeter`]), the fixed-point sample and
//! IK, the gyro feedback ([`FixedGyroFeedback`]), the limits and ticks ([`safe_targets_fx`], no
//! f32 round trip) and the log's positions (`pos_of_fx`); the sample is still copied to f32
//! for the support phase, the stabilizer and the command port.
//!
//! Bus traffic per tick at 1 Mbps (no byte stuffing needed for typical data): BULK READ
//! instruction 25 bytes out; replies 29 + 29 + 37 = 95 bytes in; SYNC WRITE 74 bytes out — 99
//! bytes out and 95 in, ≈ 1.94 ms of line time (+ the Return Delay Times, 0 after start-up);
//! while walking the servo monitor adds two READs (14 + 14 bytes out, 12 + 32 in): 2.66 ms.
//!
//! # Phases
//! What moves the legs is a walk mode ([`modes`]: one type per mode, explicit transitions):
//! [`modes::Starting`] (the ramp) hands over to the gait — the online walk (its modes standing,
//! starting, walking, stopping are gait-core's types) or the autostart plan ([`modes::Plan`]);
//! the supervisor's stop ends every mode.
//! * Servo-speed check (before the bus is touched for motion): the plan is run through the
//!   sampler and [`Targets`] at dt ([`startup::servo_timing`]); when a joint would need more
//!   than the servo's speed limit, the step timing is stretched or the swing lowered
//!   ([`Config::feasibility`]), logged as a fault record after the start-up record.
//! * Ramp: [`Config::ramp_us`] of minimum-jerk motion from the present pose to the first gait
//!   sample's joint targets (same tick structure: sensors are read and supervised).
//! * Walk: one gait sample per tick until the sampler is done.
//! * Final hold: the final pose for [`Config::final_hold_us`], then torque off (broadcast WRITE
//!   Torque Enable = 0) and the stop record `PlanDone`.
//! * Any supervisor stop: the pose is held for `stopping_ticks`, torque off, stop record with
//!   the reason.
//! * Torque off (every stop, start-up failures included) is confirmed: up to
//!   [`Config::torque_off_attempts`] rounds of broadcast Torque Enable = 0 and a READ of Torque
//!   Enable (64) from each servo not yet confirmed at 0; then the servo power is cut
//!   ([`Board::servo_power`], PF15 on the OpenCR). Unconfirmed servos: fault record
//!   `TorqueOffUnconfirmed` before the stop record.
//!
//! # Foot boards missing at start-up
//! With [`Config::feet_required`] (the default) a missing foot board stops like any other
//! device. With `feet=optional` the walk runs without it: it is not read, its forces count as
//! invalid, the measured ZMP comes from the other foot only (and is "not available" while
//! only the missing foot carries load). The gait itself never depends on the feet: they are
//! measurement instruments for the ZMP-response log. A foot board that stops answering
//! *during* the walk is a device loss (stop), whatever this setting.
//!
//! # Reset cause and crash records
//! At every boot [`run`] logs the reset cause ([`Board::reset_cause`]: RCC_CSR on the OpenCR,
//! power-on under QEMU) as a `ResetCause` fault record after the start-up record, and a panic
//! or watchdog record left by the previous run in no-init RAM ([`Board::crash_cell`]; the loop
//! notes its tick there every tick) as a `CrashRecord`. After any reset but a power-on the
//! firmware does not walk by itself: torque off (confirmed, then servo power cut: the servos
//! kept their power through the controller's reset) and stop `NotPowerOn` (exit 22). Walking
//! again needs a power cycle until the command port of the online-walking issue exists.
//!
//! # Exit codes
//! [`RunEnd::exit_code`] maps an end to the contract's [`walker_contract::ExitCode`] table (the
//! one table of the codes and their meanings; QEMU passes them to the host through
//! semihosting).

use core::cell::Cell;

use dxl::table::foot::FootForces;
use dxl::table::imu::ImuSample;
use dxl::table::{foot, imu as imu_table, x_series};
use dxl::{BulkReadRequest, DeviceResult};
use gait_core::feedback::catch::{StepAdaptation, StepAdapter};
use gait_core::feedback::compliance::{Compliance, LoadModel};
use gait_core::feedback::fdc::{FootForceControl, FootForceState};
use gait_core::feedback::gyro::FixedGyroFeedback;
use gait_core::feedback::stabilizer::{Stabilizer, StabilizerInput};
use gait_core::gait::{Arithmetic, Sample};
use gait_core::maths::fixed_point::{fx_sat, Fx};
use gait_core::measure::odometry::SurveyedSole;
use gait_core::measure::zmp::{FixedZmpMeter, ForceReading, SolePose, ZmpMeter};
use gait_core::robot::LEG_JOINTS;
use gait_core::trajectory::fixed_sampler::FixedFoot;
use gait_core::{GaitError, GaitSample, Robot, Side};
use walker_contract::bus_map::{self as ids, DEVICE_IDS};
use walker_contract::ExitCode;

use crate::board::{Board, CrashCode, CrashNote, ResetCause, BROADCAST_ID, TORQUE_ENABLE_ADDR};
use crate::bus::BoardMaster;
use crate::imu::{
    AttitudeFilter, FixedAttitudeFilter, FixedPitchAccel, Heading, PitchAccel, PitchAccelConfig,
};
use crate::monitor::ServoMonitor;
use crate::params::ArgError;
use crate::plausible::Plausibility;
use crate::record::{
    FaultKind, FaultRecord, FaultState, LogWriter, LoggedPhase, Record, StopRecord, TickRecord,
};
use crate::startup::{self, Ramp, StartupError};
use crate::supervisor::{
    safe_targets, safe_targets_fx, Action, Freshness, JointMap, StopReason, Supervisor,
};
use crate::{startup_record, Config};
use walker_contract::codes::SensorRejection;
use walker_contract::command_port::{Mode, PortState, PortStatus};

pub mod commanded;
pub mod modes;

use modes::{Motion, Walk};

pub use walker_contract::config::{Compensation, Feasibility, MAX_LEAD_TICKS, MAX_STEPS};
/// The sampler type of the firmware.
pub type GaitSampler = gait_core::trajectory::fourier_walk::WalkSampler<f32, MAX_STEPS>;
pub use walker_contract::bus_map::SENSOR_IDS;
/// Fault-record id of a plan rejected by gait-core.
pub const PLAN_REJECTED_ID: u8 = 0xFE;

pub use gait_core::gait::{support_of, SupportCache, Targets, WHOLEBODY_ITERATIONS};

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunEnd {
    /// The supervisor stopped (plan done or a fault); torque is off.
    Stopped(StopReason),
    /// A start-up step failed after the probe; torque is off.
    Startup(StartupError),
    /// gait-core rejected the configured walk; the bus was not touched.
    Config(GaitError),
}

impl RunEnd {
    /// The exit code of this end (the contract's table).
    pub fn exit(&self) -> ExitCode {
        match self {
            RunEnd::Stopped(r) => r.kind().exit(),
            RunEnd::Startup(_) => ExitCode::StartupFailed,
            RunEnd::Config(_) => ExitCode::ConfigRejected,
        }
    }

    /// The process exit status of this end (QEMU semihosting).
    pub fn exit_code(&self) -> i32 {
        self.exit().status()
    }
}

/// What the boot found: the reset cause (with the board's raw flags) and the crash record of
/// the previous run, if any.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Boot {
    /// What reset the controller.
    pub cause: ResetCause,
    /// The board's raw reset flags.
    pub flags: u32,
    /// A panic or watchdog of the previous run and the last tick it noted.
    pub crash: Option<(CrashCode, u32)>,
}

impl Boot {
    /// Reads the reset cause and takes the crash record from `board` (after a power-on the
    /// no-init RAM is random: cleared, not read; a watchdog reset without a record still
    /// reports the watchdog, with the last tick the loop noted if any).
    pub fn read<B: Board>(board: &mut B) -> Self {
        let (cause, flags) = board.reset_cause();
        let note = board.crash_cell().take();
        let crash = match (cause, note) {
            (ResetCause::PowerOn, _) => None,
            (
                _,
                Some(CrashNote {
                    code: Some(c),
                    tick,
                }),
            ) => Some((c, tick)),
            (ResetCause::Watchdog, n) => Some((CrashCode::Watchdog, n.map_or(0, |n| n.tick))),
            _ => None,
        };
        Boot {
            cause,
            flags,
            crash,
        }
    }

    /// Writes the boot's records: `ResetCause` (id = cause, value = raw flags), then
    /// `CrashRecord` (id = crash code, value = tick) if there was one.
    pub fn write<B: Board>(&self, board: &mut B, log: &mut LogWriter) {
        let now = board.now_us();
        let flags = i32::try_from(self.flags).unwrap_or(i32::MAX);
        let rec = fault(now, FaultKind::ResetCause, self.cause.code(), flags);
        log.write(board, rec);
        if let Some((code, tick)) = self.crash {
            let tick = i32::try_from(tick).unwrap_or(i32::MAX);
            log.write(board, fault(now, FaultKind::CrashRecord, code.code(), tick));
        }
    }
}

/// The gait sampler of `cfg` (model, walk, ZMP and swing shape, dt; gait-core decides).
pub fn build_sampler(cfg: &Config, robot: &Robot) -> Result<GaitSampler, GaitError> {
    gait_core::gait::build_sampler::<MAX_STEPS>(&cfg.walk_config(), robot)
}

/// Logs a rejected command line: the start-up record (bus not probed) and a
/// `ConfigRejected` fault record (id = key index, value = token position).
pub fn report_arg_error<B: Board>(board: &mut B, cfg: &Config, e: &ArgError) {
    let mut log = LogWriter::new();
    let rec = startup_record(board, cfg, None);
    log.write(board, rec);
    let rec = fault(
        board.now_us(),
        FaultKind::ConfigRejected,
        e.key_index,
        i32::from(e.position),
    );
    log.write(board, rec);
}

/// Logs a command line the firmware could not read (longer than its buffer): the start-up
/// record and a `ConfigRejected` fault record (id = `CMDLINE_TOO_LONG`, value = the buffer).
pub fn report_cmdline_too_long<B: Board>(board: &mut B, cfg: &Config) {
    let mut log = LogWriter::new();
    let rec = startup_record(board, cfg, None);
    log.write(board, rec);
    let max = i32::try_from(crate::params::CMDLINE_MAX).unwrap_or(i32::MAX);
    let rec = fault(
        board.now_us(),
        FaultKind::ConfigRejected,
        crate::params::CMDLINE_TOO_LONG,
        max,
    );
    log.write(board, rec);
}

fn fault(time_us: u64, kind: FaultKind, id: u8, value: i32) -> Record {
    Record::Fault(FaultRecord {
        seq: 0,
        time_us: time_us as u32,
        kind,
        id,
        value,
    })
}

/// The catching step's log: the largest landing move asked during one single support, written
/// as two `CatchStep` records when that single support ends.
#[derive(Default)]
struct CatchLog {
    /// The swing foot of the single support being noted.
    swing: Option<Side>,
    /// Its largest move asked (forward, leftward; trunk frame), m.
    largest: [f32; 2],
}

impl CatchLog {
    /// Notes this tick's move `asked` in `phase`; logs the swing's largest when it ends.
    fn note<B: Board>(
        &mut self,
        board: &mut B,
        log: &mut LogWriter,
        phase: gait_core::SupportPhase,
        asked: [f32; 2],
    ) {
        let swing = match phase {
            gait_core::SupportPhase::Single(stance) => Some(stance.other()),
            _ => None,
        };
        if swing != self.swing {
            if let Some(side) = self.swing.filter(|_| self.largest != [0.0; 2]) {
                let now = board.now_us();
                let side_code: u8 = if side == Side::Left { 1 } else { 2 };
                for (component, v) in (0u8..).zip(self.largest) {
                    // |v| ≤ the limits (< 0.1 m): the µm fit an i32.
                    let um = gait_core::maths::fastmath::round_i32(v * 1e6);
                    let rec = fault(now, FaultKind::CatchStep, side_code * 16 + component, um);
                    log.write(board, rec);
                }
            }
            self.swing = swing;
            self.largest = [0.0; 2];
        }
        for (l, a) in self.largest.iter_mut().zip(asked) {
            if a.abs() > l.abs() {
                *l = a;
            }
        }
    }
}

fn is_foot(id: u8) -> bool {
    id == ids::FOOT_LEFT || id == ids::FOOT_RIGHT
}

fn phase_of(s: &GaitSample<f32>) -> LoggedPhase {
    match s.phase {
        gait_core::SupportPhase::Standing => LoggedPhase::Standing,
        gait_core::SupportPhase::Double => LoggedPhase::Double,
        gait_core::SupportPhase::Single(Side::Left) => LoggedPhase::SingleLeft,
        gait_core::SupportPhase::Single(Side::Right) => LoggedPhase::SingleRight,
    }
}

/// The stop that stops: up to [`Config::torque_off_attempts`] rounds of broadcast Torque
/// Enable = 0 (the board's best-effort raw packet if the master cannot send it) followed by a
/// READ of Torque Enable from every leg servo not yet confirmed at 0; then the servo power is
/// cut ([`Board::servo_power`]) whatever the outcome. Servos never confirmed are logged
/// (`TorqueOffUnconfirmed`). The watchdog is fed after each round (a dead bus costs
/// `attempts` × 12 reply timeouts, 36 ms by default).
fn torque_off<B: Board>(bus: &mut BoardMaster<'_, B>, log: &mut LogWriter, cfg: &Config) {
    let mut off = [false; LEG_JOINTS];
    for _ in 0..cfg.torque_off_attempts.max(1) {
        if bus
            .master()
            .write(BROADCAST_ID, TORQUE_ENABLE_ADDR, &[0])
            .is_err()
        {
            bus.board().torque_off_best_effort();
        }
        for (done, &id) in off.iter_mut().zip(ids::LEGS.iter()) {
            if !*done {
                let mut v = [0xFFu8; 1];
                *done = bus.master().read(id, TORQUE_ENABLE_ADDR, &mut v).is_ok() && v == [0];
            }
        }
        bus.board().feed();
        if off.iter().all(|&d| d) {
            break;
        }
    }
    let unconfirmed = off.iter().filter(|&&d| !d).count();
    if let Some(&id) = off.iter().position(|&d| !d).and_then(|j| ids::LEGS.get(j)) {
        crate::fw_log!(
            error,
            "torque off not confirmed by {} servo(s), first {}",
            unconfirmed,
            id
        );
        let now = bus.board().now_us();
        let rec = fault(now, FaultKind::TorqueOffUnconfirmed, id, unconfirmed as i32);
        log.write(bus.board(), rec);
    }
    bus.board().servo_power(false);
}

fn write_stop<B: Board>(bus: &mut BoardMaster<'_, B>, log: &mut LogWriter, reason: StopReason) {
    let b = bus.board();
    let rec = Record::Stop(StopRecord {
        seq: 0,
        time_us: b.now_us() as u32,
        reason,
    });
    log.write(b, rec);
}

/// ONE SYNC WRITE of the 12 Goal Positions.
fn write_goals<B: Board>(bus: &mut BoardMaster<'_, B>, ticks: &[i32; LEG_JOINTS]) {
    let mut data = [[0u8; 4]; LEG_JOINTS];
    for (d, t) in data.iter_mut().zip(ticks.iter()) {
        *d = t.to_le_bytes();
    }
    let mut entries: [(u8, &[u8]); LEG_JOINTS] = [(0, &[]); LEG_JOINTS];
    for ((e, &id), d) in entries.iter_mut().zip(ids::LEGS.iter()).zip(data.iter()) {
        *e = (id, d.as_slice());
    }
    let f = x_series::GOAL_POSITION;
    // A failed broadcast is counted in the master's stats; nothing else to do this tick.
    let _ = bus.master().sync_write(f.addr, f.len, &entries);
}

/// The servos' Present Position and what the firmware makes of it (f32 path only): the servo
/// deflection feedback ([`gait_core::feedback::deflection`], `deflection_ki`: its joints read in one BULK
/// READ every tick, the targets of the last walking tick before the correction (D1)) and the leg
/// odometry ([`gait_core::measure::odometry`], `sole_poses=measured`: once a step, the stance leg's six
/// on the tick after a survey falls due, the new leg's six on the next, O3′). Built only while one of them acts; the OpenCM build has a
/// zero-sized stand-in (`NoServoSense`: its RAM is short).
#[cfg(not(feature = "board-opencm"))]
struct ServoSense {
    deflection: Option<gait_core::feedback::deflection::DeflectionFeedback>,
    /// The deflection feedback's joints.
    mask: gait_core::feedback::deflection::JointSet,
    odometry: Option<Odometry>,
    reqs: heapless::Vec<BulkReadRequest, LEG_JOINTS>,
    /// Per request: the joint index.
    joints: heapless::Vec<usize, LEG_JOINTS>,
    buf: [u8; 4 * LEG_JOINTS],
    results: [DeviceResult; LEG_JOINTS],
    /// This tick's Present Positions, rad (NaN where not read).
    present: [f32; LEG_JOINTS],
    /// The targets q* of the last walking tick before the correction, and that tick.
    sent: Option<(u32, [f32; LEG_JOINTS])>,
}

/// The leg odometry's firmware side: its state, the legs' FK and the survey's two reads.
#[cfg(not(feature = "board-opencm"))]
struct Odometry {
    legs: gait_core::measure::odometry::LegOdometry<f32>,
    kin: gait_core::kinematics::leg::LegKinematics<f32>,
    stage: Survey,
    /// The IK's joint targets of the last walking tick (before the feed-forwards and the
    /// feedback: the gait's planned motion, which the loaded leg follows), rad.
    ik: [f32; LEG_JOINTS],
}

/// Where the survey's reads stand (odometry O3′: the stance leg on one tick, the new leg on the
/// next).
#[cfg(not(feature = "board-opencm"))]
#[derive(Clone, Copy)]
enum Survey {
    /// None due.
    Idle,
    /// Due since last tick: this tick reads the stance leg.
    Stance(Side),
    /// This tick reads the new leg and takes the survey, with the stance leg's read and the
    /// IK's targets sent before it.
    New {
        stance: Side,
        first: [f32; LEG_JOINTS],
        ik: [f32; LEG_JOINTS],
    },
}

#[cfg(not(feature = "board-opencm"))]
impl ServoSense {
    /// The deflection feedback of `cfg` at tick period `dt_s` and the odometry when `odometry`;
    /// `None` while neither acts.
    fn new(
        cfg: &gait_core::feedback::deflection::DeflectionConfig,
        odometry: bool,
        robot: &Robot,
        dt_s: f32,
    ) -> Option<Self> {
        let feedback = gait_core::feedback::deflection::DeflectionFeedback::new(cfg, dt_s);
        let deflection = feedback.is_on().then_some(feedback);
        let odometry = odometry.then(|| Odometry {
            legs: gait_core::measure::odometry::LegOdometry::new(
                &gait_core::measure::odometry::OdometryLimits::DEFAULT,
            ),
            kin: gait_core::kinematics::leg::LegKinematics::new(robot),
            stage: Survey::Idle,
            ik: [f32::NAN; LEG_JOINTS],
        });
        if deflection.is_none() && odometry.is_none() {
            return None;
        }
        Some(ServoSense {
            deflection,
            mask: cfg.joints,
            odometry,
            reqs: heapless::Vec::new(),
            joints: heapless::Vec::new(),
            buf: [0; 4 * LEG_JOINTS],
            results: [Ok(()); LEG_JOINTS],
            present: [f32::NAN; LEG_JOINTS],
            sent: None,
        })
    }

    /// ONE BULK READ of the Present Positions this tick needs (rad; NaN for a reply that
    /// failed) — the deflection feedback's joints, and a survey's leg (odometry O3′: the stance
    /// leg, then the new one on the next tick, which takes the survey against the plan's places
    /// of the feet `planned`). Returns a survey taken: the new foot and its surveyed place minus
    /// the planned one (m, x and y; for the online walk's position hold).
    fn read<B: Board>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        map: &JointMap,
        planned: &[gait_core::Place<f32>; 2],
    ) -> Option<(Side, [f32; 2])> {
        self.present = [f32::NAN; LEG_JOINTS];
        let leg = match self.odometry.as_ref().map(|o| o.stage) {
            Some(Survey::Stance(s)) => Some(s),
            Some(Survey::New { stance, .. }) => Some(stance.other()),
            _ => None,
        };
        let deflection = self.deflection.is_some();
        if leg.is_none() && !deflection {
            return None;
        }
        let in_leg = |j: usize| leg.is_some_and(|s| (j < LEG_JOINTS / 2) == (s == Side::Left));
        self.reqs.clear();
        self.joints.clear();
        let f = x_series::PRESENT_POSITION;
        for j in (0..LEG_JOINTS).filter(|&j| in_leg(j) || (deflection && self.mask.contains(j))) {
            if let Some(id) = ids::servo_id(j) {
                // At most LEG_JOINTS entries: cannot fail.
                let _ = self.reqs.push(BulkReadRequest {
                    id,
                    addr: f.addr,
                    len: f.len,
                });
                let _ = self.joints.push(j);
            }
        }
        let n = self.reqs.len();
        if let (Some(results), Some(buf)) = (self.results.get_mut(..n), self.buf.get_mut(..4 * n)) {
            if n > 0 && bus.master().bulk_read(&self.reqs, buf, results).is_ok() {
                for ((&j, r), b) in self
                    .joints
                    .iter()
                    .zip(results.iter())
                    .zip(buf.chunks_exact(4))
                {
                    if let (Ok(()), Some(v), [b0, b1, b2, b3]) = (r, self.present.get_mut(j), b) {
                        *v = map
                            .ticks
                            .rad_f32(j, i32::from_le_bytes([*b0, *b1, *b2, *b3]));
                    }
                }
            }
        }
        let o = self.odometry.as_mut()?;
        let mut taken = None;
        o.stage = match o.stage {
            Survey::Idle => Survey::Idle,
            Survey::Stance(stance) => Survey::New {
                stance,
                first: self.present,
                ik: o.ik,
            },
            Survey::New { stance, first, ik } => {
                let q = gait_core::measure::odometry::legs_at_first_read(
                    stance,
                    &first,
                    &self.present,
                    &ik,
                    &o.ik,
                );
                // A refused survey (a failed read: NaN) keeps the landing where the plan puts it.
                let new = stance.other();
                if let Ok(p) = o.legs.survey(&o.kin, &q, planned) {
                    let [l, r] = planned;
                    let plan = if new == Side::Left { l } else { r };
                    taken = Some((new, [p.x - plan.x, p.y - plan.y]));
                }
                Survey::Idle
            }
        };
        taken
    }

    /// The IK's joint targets of this walking tick (rad), for the survey's reads (O3′): kept
    /// only while a survey is under way (the next tick reads a leg).
    fn note_ik(&mut self, q: &[f32; LEG_JOINTS]) {
        if let Some(o) = self
            .odometry
            .as_mut()
            .filter(|o| !matches!(o.stage, Survey::Idle))
        {
            o.ik = *q;
        }
    }

    /// Walking tick `k` of phase `phase` with the targets `q` (rad, before the correction):
    /// (D1)-(D4) against the last tick's targets if that was tick k − 1, then (D5) on `q`.
    fn apply(&mut self, k: u32, phase: gait_core::SupportPhase, q: &mut [f32; LEG_JOINTS]) {
        let Some(feedback) = self.deflection.as_mut() else {
            return;
        };
        if let Some((_, sent)) = self.sent.filter(|(at, _)| at.wrapping_add(1) == k) {
            feedback.update(phase, &sent, &self.present);
        }
        self.sent = Some((k, *q));
        feedback.apply(q);
    }

    /// The soles' places for the measured ZMP when the plan puts the feet at `planned`
    /// (odometry O2; the plan's own with `sole_poses=planned`).
    fn feet(&self, planned: [gait_core::Place<f32>; 2]) -> [SurveyedSole<f32>; 2] {
        let [l, r] = planned;
        match &self.odometry {
            Some(o) => [o.legs.sole(Side::Left, &l), o.legs.sole(Side::Right, &r)],
            None => [SurveyedSole::planned(l), SurveyedSole::planned(r)],
        }
    }

    /// Follows the support phase of the sample the servos execute and the feet's loads (N,
    /// left and right): a survey due reads the stance leg next tick, the new leg the tick after
    /// (odometry O6, the due rule and O3′).
    fn follow(&mut self, phase: gait_core::SupportPhase, loads: [f32; 2]) {
        if let Some(o) = self.odometry.as_mut() {
            o.legs.phase(phase);
            if let (Survey::Idle, Some((stance, _))) = (o.stage, o.legs.survey_due(loads)) {
                o.stage = Survey::Stance(stance);
            }
        }
    }

    /// Odometry surveys taken and refused.
    fn surveys(&self) -> (u16, u16) {
        self.odometry.as_ref().map_or((0, 0), |o| o.legs.counts())
    }
}

/// The OpenCM's stand-in for [`ServoSense`]: never built (f32 only), no RAM.
#[cfg(feature = "board-opencm")]
struct NoServoSense;

#[cfg(feature = "board-opencm")]
impl NoServoSense {
    fn new(
        _: &gait_core::feedback::deflection::DeflectionConfig,
        _: bool,
        _: &Robot,
        _: f32,
    ) -> Option<Self> {
        None
    }

    fn read<B: Board>(
        &mut self,
        _: &mut BoardMaster<'_, B>,
        _: &JointMap,
        _: &[gait_core::Place<f32>; 2],
    ) -> Option<(Side, [f32; 2])> {
        None
    }

    fn note_ik(&mut self, _: &[f32; LEG_JOINTS]) {}

    fn apply(&mut self, _: u32, _: gait_core::SupportPhase, _: &mut [f32; LEG_JOINTS]) {}

    fn feet(&self, planned: [gait_core::Place<f32>; 2]) -> [SurveyedSole<f32>; 2] {
        planned.map(SurveyedSole::planned)
    }

    fn follow(&mut self, _: gait_core::SupportPhase, _: [f32; 2]) {}

    fn surveys(&self) -> (u16, u16) {
        (0, 0)
    }
}

/// The Present Position feedback of this build.
#[cfg(not(feature = "board-opencm"))]
type ServoSenseLoop = ServoSense;
/// The Present Position feedback of this build.
#[cfg(feature = "board-opencm")]
type ServoSenseLoop = NoServoSense;

/// The sensor devices read each tick and where their data lands in the bulk-read buffer.
struct Sensors {
    reqs: heapless::Vec<BulkReadRequest, 3>,
    /// Per request: index into [`SENSOR_IDS`] and offset into the buffer.
    slots: heapless::Vec<(usize, usize), 3>,
    buf: [u8; 18 + 18 + 26],
    results: [DeviceResult; 3],
}

impl Sensors {
    fn new(missing: &[u8]) -> Self {
        let mut s = Sensors {
            reqs: heapless::Vec::new(),
            slots: heapless::Vec::new(),
            buf: [0; 62],
            results: [Ok(()); 3],
        };
        let mut off = 0usize;
        for (k, &id) in SENSOR_IDS.iter().enumerate() {
            if missing.contains(&id) {
                continue;
            }
            let f = if id == ids::IMU {
                imu_table::SAMPLE
            } else {
                foot::SAMPLE
            };
            // At most 3 entries: cannot fail.
            let _ = s.reqs.push(BulkReadRequest {
                id,
                addr: f.addr,
                len: f.len,
            });
            let _ = s.slots.push((k, off));
            off += usize::from(f.len);
        }
        s
    }

    /// ONE BULK READ; afterwards `results[i]` is request i's outcome.
    fn read<B: Board>(&mut self, bus: &mut BoardMaster<'_, B>) {
        let n = self.reqs.len();
        let Some(results) = self.results.get_mut(..n) else {
            return;
        };
        if n == 0 {
            return;
        }
        if let Err(e) = bus.master().bulk_read(&self.reqs, &mut self.buf, results) {
            results.iter_mut().for_each(|r| *r = Err(e));
        }
    }

    fn data(&self, req: usize, len: usize) -> Option<&[u8]> {
        let &(_, off) = self.slots.get(req)?;
        self.buf.get(off..off + len)
    }

    /// Parses and checks every reply of the last [`Sensors::read`] ([`crate::plausible`]);
    /// accepted samples are recorded in `checks` at `now_us`.
    fn check(&self, checks: &mut Plausibility<3>, now_us: u64) -> Checked {
        let mut out = Checked {
            feet: [None; 2],
            imu: None,
            rejected: [None; 3],
        };
        for (i, &(k, _)) in self.slots.iter().enumerate() {
            if !self.results.get(i).is_some_and(|r| r.is_ok()) {
                continue;
            }
            let verdict = if SENSOR_IDS.get(k) == Some(&ids::IMU) {
                let s = self
                    .data(i, usize::from(imu_table::SAMPLE.len))
                    .and_then(ImuSample::from_bytes);
                match s {
                    Some(s) => checks.imu(k, &s).map(|()| out.imu = Some(s)),
                    None => Err(SensorRejection::Malformed),
                }
            } else {
                let f = self
                    .data(i, usize::from(foot::SAMPLE.len))
                    .and_then(FootForces::from_bytes);
                match (f, out.feet.get_mut(k)) {
                    (Some(f), Some(slot)) => checks.foot(k, &f).map(|()| *slot = Some(f)),
                    _ => Err(SensorRejection::Malformed),
                }
            };
            if let (Err(r), Some(slot)) = (verdict, out.rejected.get_mut(k)) {
                *slot = Some(r);
            }
        }
        if let [Some(a), Some(b)] = &out.feet {
            if let Err(r) = checks.feet_together(a, b) {
                out.feet = [None; 2];
                for slot in out.rejected.iter_mut().take(2) {
                    *slot = Some(r);
                }
            }
        }
        for (k, f) in out.feet.iter().enumerate() {
            if let Some(f) = f {
                checks.accept(k, f.counter, now_us);
            }
        }
        if let (Some(s), Some(k)) = (out.imu, SENSOR_IDS.iter().position(|&d| d == ids::IMU)) {
            checks.accept(k, s.counter, now_us);
        }
        out
    }
}

/// The replies of one tick that passed the plausibility checks, and why the others failed.
struct Checked {
    /// Accepted foot samples (index = side).
    feet: [Option<FootForces>; 2],
    /// Accepted IMU sample.
    imu: Option<ImuSample>,
    /// Per [`SENSOR_IDS`] index: why its reply was rejected (a reply that never came is `None`).
    rejected: [Option<SensorRejection>; 3],
}

impl Checked {
    /// True when sensor `k`'s (index into [`SENSOR_IDS`]) reply was accepted.
    fn accepted(&self, k: usize) -> bool {
        match SENSOR_IDS.get(k) {
            Some(&ids::IMU) => self.imu.is_some(),
            Some(_) => self.feet.get(k).is_some_and(|f| f.is_some()),
            None => false,
        }
    }
}

/// A tick's joint targets: f32 rad, or I16F16 rad straight from the integer IK (`math=fixed`).
enum Goal {
    /// f32 rad (may be non-finite: [`safe_targets`] catches it).
    Rad([f32; LEG_JOINTS]),
    /// I16F16 rad ([`safe_targets_fx`]).
    Fx([Fx; LEG_JOINTS]),
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

/// An I16F16 position (m) in the log's unit ([`crate::record::POS_UNIT_M`] = 10 µm), rounded
/// half up: bits · 10⁵ / 2¹⁶ (integer only), saturating at the record's ±8,388,607 like
/// `pos_from_m`.
fn pos_of_fx(v: Fx) -> i32 {
    let p = (i64::from(v.to_bits()) * 100_000 + (1 << 15)) >> 16;
    p.clamp(-8_388_607, 8_388_607) as i32
}

/// Last good sensor values.
struct SensorState {
    feet: [Option<FootForces>; 2],
    held: [u16; 3],
    /// Per sensor: its last reply was rejected (the fault record is written once per run).
    rejecting: [bool; 3],
}

/// Runs start-up and the walk on `board` with `cfg` until torque is off (see the module docs).
/// Never returns before torque is off once it was enabled.
pub fn run<B: Board>(board: &mut B, cfg: &Config) -> RunEnd {
    let robot = Robot::reference();
    let mut log = LogWriter::new();
    // The watchdog runs from boot: the boards feed it in their wait loops, the dry run every
    // 256 samples, the loop every tick.
    board.start(cfg.watchdog_ms);
    // Why did we boot? Only a power-on walks by itself.
    let boot = Boot::read(board);
    if boot.cause != ResetCause::PowerOn {
        crate::fw_log!(error, "reset cause {}: not walking", boot.cause.code());
        let rec = startup_record(board, cfg, None);
        log.write(board, rec);
        boot.write(board, &mut log);
        let time = Cell::new(0);
        let mut bus = BoardMaster::new(board, &time, cfg);
        // The servos kept their power through the controller's reset: let go, cut it.
        torque_off(&mut bus, &mut log, cfg);
        let reason = StopReason::NotPowerOn { cause: boot.cause };
        write_stop(&mut bus, &mut log, reason);
        return RunEnd::Stopped(reason);
    }
    let targets = Targets::new(&robot, cfg.compensation);
    // The walk (≈ 10 KB) is built where it lives, never moved: its storage lends its engine to
    // the servo-speed check (a dry run that adjusts the walk before anything moves), then
    // holds the gait (BENCHMARKS.md "RAM").
    let mut walk = Walk::idle();
    let timing = match walk.scratch() {
        Some(s) => startup::servo_timing_in(cfg, &robot, &targets, &mut || board.feed(), s),
        None => Err(GaitError::NotBuiltIn),
    };
    let walk_cfg = match &timing {
        Ok(t) => Config {
            walk: t.walk,
            ..*cfg
        },
        Err(_) => *cfg,
    };
    let cfg = &walk_cfg;
    // Without autostart the robot stands up and walks on command (the online walk).
    let built = match &timing {
        Ok(_) => walk.build(cfg, &robot),
        Err(e) => Err(*e),
    };
    if let Err(e) = built {
        crate::fw_log!(error, "walk rejected by gait-core: error {}", e.code());
        let rec = startup_record(board, cfg, None);
        log.write(board, rec);
        boot.write(board, &mut log);
        let rec = fault(
            board.now_us(),
            FaultKind::ConfigRejected,
            PLAN_REJECTED_ID,
            i32::from(e.code()),
        );
        log.write(board, rec);
        return RunEnd::Config(e);
    }

    let time = Cell::new(0);
    let mut bus = BoardMaster::new(board, &time, cfg);

    // 1. Probe.
    let missing = startup::probe(&mut bus, &DEVICE_IDS, cfg);
    {
        let b = bus.board();
        let rec = startup_record(&*b, cfg, Some(&missing));
        log.write(b, rec);
        boot.write(b, &mut log);
    }
    if let Ok(t) = &timing {
        for (kind, id, value) in t.notes().into_iter().map(startup::note_record) {
            let now = bus.board().now_us();
            log.write(bus.board(), fault(now, kind, id, value));
        }
    }
    let mut critical: heapless::Vec<u8, { crate::record::MAX_MISSING }> = heapless::Vec::new();
    for &id in missing.iter() {
        if cfg.feet_required || !is_foot(id) {
            let _ = critical.push(id);
        }
    }
    let mut sup = Supervisor::new(cfg.supervisor, SENSOR_IDS);
    if let Err(reason) = sup.startup(&critical) {
        crate::fw_log!(
            error,
            "{} device(s) missing, first {}",
            missing.len(),
            critical.first()
        );
        torque_off(&mut bus, &mut log, cfg);
        write_stop(&mut bus, &mut log, reason);
        return RunEnd::Stopped(reason);
    }

    // 2–4. Return Delay Time, present pose, goal = present, torque on.
    let mut present_ids: heapless::Vec<u8, 15> = heapless::Vec::new();
    for &id in DEVICE_IDS.iter() {
        if !missing.contains(&id) {
            let _ = present_ids.push(id);
        }
    }
    let present = match startup::set_return_delay(&mut bus, &present_ids, cfg)
        .and_then(|_| startup::set_position_gains(&mut bus, cfg))
        .and_then(|_| startup::read_positions(&mut bus, cfg))
        .and_then(|p| {
            write_goals(&mut bus, &p);
            startup::enable_torque(&mut bus, cfg).map(|()| p)
        }) {
        Ok(p) => p,
        Err(e) => {
            crate::fw_log!(error, "start-up failed at device {}", e.id);
            let t = bus.board().now_us();
            let b = bus.board();
            log.write(
                b,
                fault(t, FaultKind::StartupFailed, e.id, i32::from(e.step.code())),
            );
            torque_off(&mut bus, &mut log, cfg);
            write_stop(&mut bus, &mut log, StopReason::DeviceLost { id: e.id });
            return RunEnd::Startup(e);
        }
    };

    // 5. The initial pose and the ramp to it (the plan's delay line of the servo-lag
    // feed-forward was primed with it: [`modes::Plan::prime`]).
    let map = JointMap::from_robot(&robot);
    // The servos' sag under the gait's loads, fed forward (`compliance_roll`/`_pitch`); f32
    // maths, so not with the fixed-point path (`math=fixed`: FPU-less cores).
    let load = LoadModel::new(&robot);
    let compliance = match cfg.arithmetic {
        Arithmetic::F32 => cfg.compliance,
        _ => Compliance::OFF,
    };
    // Foot force difference control (`fdc_gain`): f32 only, like the compliance feed-forward.
    let foot_force = match cfg.arithmetic {
        Arithmetic::F32 => cfg.foot_force,
        _ => FootForceControl::OFF,
    };
    let mut foot_force_state = FootForceState::default();
    // The initial pose: the plan's first sample, or the online walk's standing pose.
    let (first, mut q0, loaded) = walk.gait.initial_pose(&targets);
    load.apply(&compliance, &mut q0, &loaded, [0.0; 2]);
    let mut link = commanded::CommandLink::new();
    if walk.gait.online().is_some() {
        let now = bus.board().now_us();
        let rec = fault(
            now,
            FaultKind::Footstep,
            walker_contract::footstep_log::PERIOD_ID,
            commanded::period_us(cfg),
        );
        log.write(bus.board(), rec);
    }
    let mut from = [0.0f32; LEG_JOINTS];
    for (j, (f, &t)) in from.iter_mut().zip(present.iter()).enumerate() {
        *f = map.rad_of_tick(j, t);
    }
    let ramp = Ramp::new(from, q0, cfg.ticks_for_us(cfg.ramp_us));
    let ramp_ticks = ramp.ticks();
    walk.start(ramp);
    let final_hold = u16::try_from(cfg.ticks_for_us(cfg.final_hold_us)).unwrap_or(u16::MAX);
    // Whether the IK takes the present sample (no servo lead; float maths, so once).
    let no_lead = cfg.lead_ticks() == 0;

    let mut sensors = Sensors::new(&missing);
    let mut state = SensorState {
        feet: [None; 2],
        held: [0; 3],
        rejecting: [false; 3],
    };
    let pitch_cfg = PitchAccelConfig {
        dt_s: cfg.dt_s() as f32,
        cutoff_hz: cfg.imu_cutoff_hz,
        inertia: robot.masses.upper_body_inertia as f32,
    };
    let mut pitch = PitchAccel::new(pitch_cfg);
    let mut attitude = AttitudeFilter::new();
    let mut heading = Heading::new();
    // `math=fixed` (FPU-less cores): the pitch filter and τ, the tilt estimate, the measured
    // ZMP, the gyro feedback and the joint path (integer IK → ticks) in integers; the f32
    // ones otherwise.
    // The OpenCM 9.04 (no FPU) always runs the fixed path: a constant, so its build leaves
    // the f32 branches out (flash).
    let fixed_math = cfg!(feature = "board-opencm")
        || (cfg!(feature = "fixed-gait") && cfg.arithmetic == Arithmetic::Fixed);
    let dt_f32 = cfg.dt_s() as f32;
    // The catching step (`catch_gain`, gait-core `catching`): f32 only, like the compliance
    // feed-forward; its largest move asked in the present swing, for the log.
    let mut catching = StepAdapter::new(
        &match fixed_math {
            false => cfg.step_adaptation,
            true => StepAdaptation::OFF,
        },
        &robot,
        first.com[2],
        dt_f32,
    );
    let mut catch_asked = CatchLog::default();
    // The servo deflection feedback (`deflection_ki`, gait-core `deflection`) and the leg
    // odometry (`sole_poses=measured`, gait-core `odometry`): f32 only; Present Positions are
    // read only while one of them acts.
    let mut servo_sense = match fixed_math {
        false => ServoSenseLoop::new(&cfg.deflection, cfg.sole_poses_measured, &robot, dt_f32),
        true => None,
    };
    let mut pitch_fx = FixedPitchAccel::new(pitch_cfg);
    let mut attitude_fx = FixedAttitudeFilter::new(dt_f32);
    let zmp_meter = FixedZmpMeter::new(&robot, cfg.min_load_n);
    let zmp_meter_f32 = ZmpMeter::new(&robot, cfg.min_load_n);
    let feedback_fx = FixedGyroFeedback::new(&cfg.gyro_feedback);
    let mut stab =
        Stabilizer::<f32>::new(&cfg.stabilizer, cfg.dt_s(), robot.masses.upper_body_height);
    let mut last_ticks = present.map(|t| t.clamp(map.tick_min, map.tick_max));
    let mut prev = first;
    // The fixed-point feet of `prev` when the fixed-point sampler made it (`math=fixed`, no
    // lead, no shift): the measured ZMP takes them as they are (no f32 → fixed conversions).
    let mut prev_feet_fx: Option<[FixedFoot; 2]> = None;
    let mut support_cache = SupportCache::default();
    let mut clamped_seen = 0u16;

    if !first.is_finite() {
        // The initial pose would come from a non-finite sample: hold the present pose, stop.
        sup.stop(StopReason::NonFiniteSample { tick: 0 });
    }
    crate::fw_log!(info, "walking: ramp {} ticks", ramp_ticks);
    let weight_n = (robot.masses.total() * robot.gravity) as f32;
    let mut plausible = Plausibility::<3>::new(cfg, weight_n, bus.board().now_us());
    let mut monitor = ServoMonitor::new();
    loop {
        let tick = bus.board().wait_tick();
        bus.board().crash_cell().note_tick(tick.index);
        sup.tick_timing(tick.overrun);

        // Sensors.
        sensors.read(&mut bus);
        if let Some(d) = servo_sense.as_mut() {
            let [l, r] = &prev.feet;
            let landed = d.read(&mut bus, &map, &[l.sole_place(), r.sole_place()]);
            // The online walk's position hold (P1): where the new foot landed off its plan.
            if let (Some((side, offset)), Some(o)) = (landed, walk.gait.online_mut()) {
                o.set_landing_offset(side, offset);
            }
        }
        let now = bus.board().now_us();
        let checked = sensors.check(&mut plausible, now);
        let mut imu_fresh = None;
        for &(k, _) in sensors.slots.iter() {
            let Some(&id) = SENSOR_IDS.get(k) else {
                continue;
            };
            let t = bus.board().now_us();
            let rejected = checked.rejected.get(k).copied().flatten();
            if let (Some(r), Some(seen)) = (rejected, state.rejecting.get_mut(k)) {
                if !*seen {
                    crate::fw_log!(warn, "sensor {} reply rejected: {}", id, r.code());
                    let rec = fault(t, FaultKind::SensorRejected, id, i32::from(r.code()));
                    log.write(bus.board(), rec);
                }
                *seen = true;
            }
            let ok = checked.accepted(k);
            if ok {
                if let Some(seen) = state.rejecting.get_mut(k) {
                    *seen = false;
                }
            }
            let fresh = sup.report(id, ok);
            if let Some(age_ms) = plausible.stale(k, now) {
                crate::fw_log!(error, "sensor {} stale for {} ms", id, age_ms);
                sup.stop(StopReason::SensorStale { id, age_ms });
            }
            let held = state.held.get_mut(k);
            match (fresh, held) {
                (Freshness::Fresh, Some(h)) => {
                    if *h > 0 {
                        let rec = fault(t, FaultKind::DeviceRecovered, id, i32::from(*h));
                        log.write(bus.board(), rec);
                    }
                    *h = 0;
                    if id == ids::IMU {
                        imu_fresh = checked.imu;
                    } else if let (Some(slot), Some(f)) =
                        (state.feet.get_mut(k), checked.feet.get(k))
                    {
                        *slot = *f;
                    }
                }
                (Freshness::Held(n), Some(h)) => {
                    *h = n;
                    if n == 1 {
                        log.write(bus.board(), fault(t, FaultKind::DeviceHolding, id, 1));
                    }
                }
                _ => {}
            }
        }
        // A non-finite or missing gyro sample never reaches the stabilizer.
        let mut roll_pitch = None;
        let (gyro, tilt) = match imu_fresh {
            Some(s) => {
                let g = s.gyro_rad_s();
                let [roll_rate, rate, _] = g;
                let tilt = if fixed_math {
                    pitch_fx.update(Some(s.gyro_urad_s[1]));
                    attitude_fx.update(s.gyro_urad_s, s.accel_um_s2)
                } else {
                    pitch.update(rate);
                    let att = attitude.update(g, s.accel_m_s2(), dt_f32);
                    // The online walk's heading hold (f32 path): the gyro's yaw, the bias
                    // learnt while it stands.
                    if let Some(o) = walk.gait.online_mut() {
                        let still = matches!(
                            o.mode(),
                            gait_core::trajectory::online::WalkMode::Standing(_)
                        );
                        o.set_heading(heading.update(g, &att, dt_f32, still));
                    }
                    roll_pitch = Some([att.roll, att.pitch]);
                    att.tilt
                };
                let g = Some([roll_rate, rate]).filter(|g| g.iter().all(|v| v.is_finite()));
                (g, tilt)
            }
            None => {
                if fixed_math {
                    pitch_fx.update(None);
                    (None, attitude_fx.tilt())
                } else {
                    pitch.update(f32::NAN);
                    (None, attitude.tilt().tilt)
                }
            }
        };
        // The integer rates for the fixed-point gyro feedback (when the f32 ones pass).
        let gyro_raw = imu_fresh
            .filter(|_| gyro.is_some())
            .map(|s| [s.gyro_urad_s[0], s.gyro_urad_s[1]]);
        sup.tilt(tilt);
        // τ: N·m (f32 path) or whole mN·m (`math=fixed`, no float).
        let (tau, tau_mnm) = if fixed_math {
            (0.0, pitch_fx.torque_mnm())
        } else {
            (pitch.torque(), 0)
        };
        let reading = |f: &Option<FootForces>| {
            ForceReading::new(f.map_or([f32::NAN; 4], |f| f.forces_mn.map(|v| v as f32 * 1e-3)))
        };
        let [fl, fr] = &state.feet;
        let [pl, pr] = &prev.feet;
        // The fixed-point ZMP also goes to the log as is (no float).
        let mut meas_fx = None;
        let meas_zmp = if fixed_math {
            let forces = |f: &Option<FootForces>| f.map(|f| f.forces_mn);
            let [fpl, fpr] = prev_feet_fx.unwrap_or_else(|| [fixed_foot(pl), fixed_foot(pr)]);
            meas_fx = zmp_meter.zmp((&fpl, forces(fl)), (&fpr, forces(fr)));
            meas_fx.map(|z| z.map(gait_core::maths::fixed_point::fx_to_f32))
        } else {
            match servo_sense.as_mut() {
                Some(d) => {
                    let [l, r] = d.feet([pl.sole_place(), pr.sole_place()]);
                    zmp_meter_f32
                        .zmp((&l, &reading(fl)), (&r, &reading(fr)))
                        .zmp
                }
                None => {
                    zmp_meter_f32
                        .zmp((pl, &reading(fl)), (pr, &reading(fr)))
                        .zmp
                }
            }
        };
        let foot_load = |f: &Option<FootForces>| {
            reading(f)
                .compression()
                .map_or(f32::NAN, |c| c.iter().sum::<f32>())
        };
        if let Some(d) = servo_sense.as_mut() {
            d.follow(prev.phase, [foot_load(fl), foot_load(fr)]);
        }
        // Not on the start-up ramp (its targets do not take the offsets: no jump at its end);
        // off with `math=fixed` (f32 only: its state stays 0, so it is not run there).
        let sole_dz = match walk.is_starting() {
            true => [0.0; 2],
            false if fixed_math => [0.0; 2],
            false => foot_force_state.update(
                &foot_force,
                prev.zmp,
                [[pl.x, pl.y], [pr.x, pr.y]],
                [foot_load(fl), foot_load(fr)],
                prev.phase,
                dt_f32,
            ),
        };

        // The command port: answered every tick; torque off on command; the online walk's
        // command.
        link.poll(bus.board(), &mut log);
        if link.mode() == Mode::TorqueOff {
            sup.stop(StopReason::Requested);
        }
        if !walk.is_starting() {
            if let Some(o) = walk.gait.online_mut() {
                o.set_command(link.velocity());
                link.feed_steps(o);
            }
        }

        // Supervisor, targets, servos.
        let action = sup.step();
        let mut rec = TickRecord {
            time_us: tick.nominal_us as u32,
            overrun: tick.overrun,
            ..TickRecord::default()
        };
        match action {
            Action::Run => {
                // The walk's mode says what moves the legs ([`modes`]).
                let hold = !fixed_math && catching.wants_hold();
                let q = match walk.tick(fixed_math, tau, tau_mnm, hold) {
                    Motion::Ramp(q) => Some(Goal::Rad(q)),
                    Motion::Gait { k, footstep } => 'sample: {
                        // The online walk's sample (no lead) or the plan's (`servo_lead` ahead).
                        if let Some(f) = footstep {
                            commanded::log_footstep(
                                bus.board(),
                                &mut log,
                                f.step.side,
                                &f.step.place,
                                f.turn,
                                f.shift,
                                f.given,
                            );
                        }
                        // The present sample and the one the IK takes, borrowed from the walk.
                        let s = walk.present();
                        // The fault injection spoils the sample the IK takes (a copy of
                        // `ahead`, or the present one: then only its check sees it).
                        let nan_com = cfg.fault_nan_com_tick == Some(k);
                        let poisoned: Sample;
                        let ahead = match walk.ahead() {
                            Some(a) if nan_com => {
                                let mut p = *a;
                                p.f32.com[0] = f32::NAN;
                                poisoned = p;
                                Some(&poisoned)
                            }
                            a => a,
                        };
                        let ahead_finite = match ahead {
                            Some(a) => a.f32.is_finite(),
                            None => !nan_com,
                        };
                        // The finite check before the IK (which would clamp a NaN pelvis to
                        // finite, meaningless angles): the sample the IK takes (`servo_lead`
                        // ahead) and the present one; hold the last targets and stop.
                        if !(s.is_finite() && ahead_finite) {
                            crate::fw_log!(error, "non-finite gait sample at walk tick {}", k);
                            sup.stop(StopReason::NonFiniteSample { tick: k });
                            break 'sample None;
                        }
                        // The catching step (gait-core `catching` A1-A7): the feet's and
                        // the body's offsets from the plan, on copies of the samples.
                        // (`fixed_math` first: a constant on the OpenCM, whose build then
                        // leaves this f32 path out.)
                        if !fixed_math && catching.is_on() {
                            // The loads only matter for a swing foot.
                            let loads = match s.phase {
                                gait_core::SupportPhase::Single(_) => {
                                    [foot_load(fl), foot_load(fr)]
                                }
                                _ => [f32::NAN; 2],
                            };
                            let asked = catching.update(s, roll_pitch, gyro, loads);
                            catch_asked.note(bus.board(), &mut log, s.phase, asked);
                        }
                        let caught: GaitSample<f32>;
                        let caught_ahead: Sample;
                        let (s, ahead) = match !fixed_math && catching.is_shifting() {
                            false => (s, ahead),
                            true => {
                                let mut c = *s;
                                catching.apply(&mut c);
                                caught = c;
                                let a = ahead.map(|a| {
                                    let mut c = *a;
                                    catching.apply(&mut c.f32);
                                    // The fixed-point IK would not see the offsets.
                                    c.fixed = None;
                                    c
                                });
                                match a {
                                    Some(a) => {
                                        caught_ahead = a;
                                        (&caught, Some(&caught_ahead))
                                    }
                                    None => (&caught, None),
                                }
                            }
                        };
                        let shift = if cfg.stabilizer_on {
                            // The measurement answers the previous command: compare with it.
                            stab.update(&StabilizerInput {
                                zmp_ref: prev.zmp,
                                zmp_meas: meas_zmp,
                                gyro,
                                support: support_cache.get(&robot, &prev),
                            })
                        } else {
                            [0.0; 2]
                        };
                        if !shift.iter().all(|v| v.is_finite()) {
                            sup.stop(StopReason::NonFiniteSample { tick: k });
                            break 'sample None;
                        }
                        // The soles' heights of the force difference control (F4).
                        let lift = |mut g: GaitSample<f32>| {
                            for (f, dz) in g.feet.iter_mut().zip(sole_dz) {
                                f.z += dz;
                            }
                            g
                        };
                        // The integer IK's angles go to the ticks without an f32 round trip
                        // (`math=fixed`; compliance and the force difference control are off
                        // there); the f32 path otherwise (and for the NaN fault injection).
                        let plan = walk.gait.plan();
                        let fx_q = match (ahead, plan) {
                            (Some(a), Some(p)) if cfg.fault_nan_tick != Some(k) => {
                                p.engine().joints_fx(&targets, a, shift)
                            }
                            _ => None,
                        };
                        let mut goal = match fx_q {
                            Some(mut q) => {
                                feedback_fx.for_each(s.phase, gyro_raw, |j, d| {
                                    if let Some(v) = q.get_mut(j) {
                                        *v = v.saturating_add(Fx::from_bits(d));
                                    }
                                });
                                Goal::Fx(q)
                            }
                            None => {
                                let (mut q, loaded) = match (ahead, plan) {
                                    (Some(a), Some(p)) if foot_force_state.dz != 0.0 => {
                                        let mut lifted = *a;
                                        lifted.f32 = lift(a.f32);
                                        (p.engine().joints(&targets, &lifted, shift), &a.f32)
                                    }
                                    (Some(a), Some(p)) => {
                                        (p.engine().joints(&targets, a, shift), &a.f32)
                                    }
                                    _ => (targets.joints(&lift(*s), shift).0, s),
                                };
                                if let Some(d) = servo_sense.as_mut() {
                                    d.note_ik(&q);
                                }
                                load.apply(&compliance, &mut q, loaded, shift);
                                cfg.gyro_feedback.apply(&mut q, s.phase, gyro);
                                // The swing sole kept level (gait-core `catching` A10).
                                catching.apply_level(&mut q);
                                if let Some(d) = servo_sense.as_mut() {
                                    d.apply(k, s.phase, &mut q);
                                }
                                Goal::Rad(q)
                            }
                        };
                        if walk.gait.plan_done() {
                            sup.stop_with_hold(StopReason::PlanDone, final_hold);
                        }
                        if cfg.stop_at_tick == Some(k) {
                            sup.stop(StopReason::Requested);
                        }
                        if cfg.fault_nan_tick == Some(k) {
                            if let Goal::Rad(q) = &mut goal {
                                if let Some(v) = q.first_mut() {
                                    *v = f32::NAN;
                                }
                            }
                        }
                        // The present sample in fixed point (`math=fixed` without lead or
                        // shift: it is the one the IK took) goes to the log without float.
                        let present_fx = ahead
                            .and_then(|a| a.fixed.as_ref())
                            .filter(|_| no_lead && !cfg.stabilizer_on);
                        match present_fx {
                            Some(f) => {
                                rec.zmp_ref = f.zmp.map(pos_of_fx);
                                rec.com = [pos_of_fx(f.com[0]), pos_of_fx(f.com[1])];
                            }
                            None => {
                                let ([zx, zy], [cx, cy, _]) = (s.zmp, s.com);
                                rec.set_zmp_ref_m(zx, zy);
                                rec.set_com_m(cx + shift[0], cy + shift[1]);
                            }
                        }
                        rec.phase = phase_of(s);
                        prev = *s;
                        prev_feet_fx = present_fx.map(|f| f.feet);
                        Some(goal)
                    }
                };
                let ticks = match q.map(|g| match g {
                    Goal::Rad(q) => safe_targets(&q, &map, &last_ticks),
                    Goal::Fx(q) => Ok(safe_targets_fx(&q, &map)),
                }) {
                    // A non-finite sample: the last targets again (the stop has begun); the
                    // log shows the last finite sample.
                    None => {
                        let ([zx, zy], [cx, cy, _]) = (prev.zmp, prev.com);
                        rec.set_zmp_ref_m(zx, zy);
                        rec.set_com_m(cx, cy);
                        rec.phase = LoggedPhase::Stopped;
                        last_ticks
                    }
                    Some(Ok(t)) => {
                        if t.clamped & !clamped_seen != 0 {
                            let first = t.clamped.trailing_zeros() as u8;
                            let now = bus.board().now_us();
                            let rec =
                                fault(now, FaultKind::TargetClamped, first, i32::from(t.clamped));
                            log.write(bus.board(), rec);
                        }
                        clamped_seen |= t.clamped;
                        t.ticks
                    }
                    Some(Err(e)) => {
                        sup.stop(StopReason::NonFiniteTarget {
                            joint: e.first_joint(),
                        });
                        e.ticks
                    }
                };
                write_goals(&mut bus, &ticks);
                last_ticks = ticks;
                if let Some(reason) = monitor.poll(&mut bus, &cfg.servo_limits, cfg.tick_period_us)
                {
                    crate::fw_log!(error, "servo fault: {}", reason);
                    sup.stop(reason);
                }
            }
            Action::HoldPose => write_goals(&mut bus, &last_ticks),
            Action::SendTorqueOff => torque_off(&mut bus, &mut log, cfg),
            Action::Idle => {}
        }
        if action != Action::Run {
            let ([zx, zy], [cx, cy, _]) = (prev.zmp, prev.com);
            rec.set_zmp_ref_m(zx, zy);
            rec.set_com_m(cx, cy);
            rec.phase = match sup.stop_reason() {
                Some(StopReason::PlanDone) => LoggedPhase::Standing,
                _ => LoggedPhase::Stopped,
            };
        }
        if let Some(z) = meas_fx {
            rec.zmp_meas = z.map(pos_of_fx);
            rec.zmp_valid = true;
        } else if let Some([zx, zy]) = meas_zmp {
            rec.set_zmp_meas_m(zx, zy);
            rec.zmp_valid = true;
        }
        if fixed_math {
            rec.tau_mnm = tau_mnm.clamp(-32_767, 32_767) as i16;
        } else {
            rec.set_tau_nm(tau);
        }
        // The state that produced this tick's action.
        rec.fault = match action {
            Action::Run if sup.any_holding() => FaultState::Holding,
            Action::Run => FaultState::Ok,
            Action::HoldPose => FaultState::Stopping,
            Action::SendTorqueOff | Action::Idle => FaultState::TorqueOff,
        };
        let state = match action {
            Action::Run => walk.port_state(),
            _ => PortState::Stopped,
        };
        let online = walk.gait.online();
        link.publish(&PortStatus {
            state,
            support: commanded::support_code(prev.phase),
            step_count: u16::try_from(online.map_or(prev.steps_done, |o| o.steps_done()))
                .unwrap_or(u16::MAX),
            zmp_m: meas_zmp,
            stop_code: sup.stop_reason().map_or(0, |r| r.kind().code()),
            fault_kind: log.last_fault(),
            walk_velocity: online.map_or([0.0; 3], |o| o.velocity()),
            queued: online.map_or(0, |o| o.queued()),
        });
        rec.bus = bus.counters();
        rec.overruns = u16::try_from(bus.board().overruns()).unwrap_or(u16::MAX);
        log.write(bus.board(), Record::Tick(rec));
        bus.board().feed();

        if matches!(action, Action::SendTorqueOff | Action::Idle) {
            let reason = sup.stop_reason().unwrap_or(StopReason::Requested);
            write_stop(&mut bus, &mut log, reason);
            crate::fw_log!(info, "stopped: {}", reason);
            if let Some(d) = servo_sense.as_ref() {
                let (taken, refused) = d.surveys();
                crate::fw_log!(info, "odometry: {} surveys, {} refused", taken, refused);
            }
            return RunEnd::Stopped(reason);
        }
    }
}

#[cfg(test)]
mod tests;
