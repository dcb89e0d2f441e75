//! The walking controller: start-up, the smooth move to the initial pose, the control loop at
//! the servo rate, and the stop sequence. Written once over `B: Board`; the QEMU and OpenCR
//! binaries call [`run`], host tests run it on a fake board.
//!
//! # One tick (period [`Config::tick_period_us`], default 5 ms = 200 Hz)
//! The tick is a pipeline, `controller::Controller::tick`; its arithmetic (f32, or fixed point
//! with `math=fixed`) is one implementation of `path::TickPath`, chosen once per run:
//!
//! ```text
//!  sense ─▶ estimate ─▶ command ─▶ walk mode ─▶ sample corrections ─▶ IK ─▶ joint corrections ─▶ act ─▶ report
//! ```
//!
//! 1. `wait_tick()`; overruns go to the supervisor (a burst of them stops).
//! 2. Sense (`sense`): ONE BULK READ: foot boards 111/112 (18 bytes at 128: 4 forces +
//!    counter) and the IMU 200 (26 bytes at 128: gyro, accelerometer, counter); with the
//!    deflection feedback or the leg odometry one more of the servos' Present Position
//!    (`servo_sense`). Every reply is checked for plausibility ([`crate::plausible`]: the
//!    board's sample counter advanced, values in the sensor's range, foot forces consistent with
//!    the robot's weight); a rejected reply counts as missing (fault record `SensorRejected` at
//!    the first of a run). Per device the supervisor decides fresh / held (last good value, at
//!    most [`crate::supervisor::SupervisorConfig::hold_ticks`] ticks in a row) / lost (stop); a
//!    board without an accepted sample for longer than [`Config::sensor_stale_ms`] stops
//!    (`SensorStale`, exit 19) whatever `hold_ticks`.
//! 3. Estimate: the attitude and the tilt (fall → stop), φ̈ from the gyro pitch rate and
//!    τ = J·φ̈ ([`PitchAccel`](crate::imu::PitchAccel)), the measured ZMP from the 8 forces
//!    (gait-core `measured_zmp`; the feet where the previous sample put them, moved by the leg
//!    odometry's surveys with `sole_poses=measured`; feet under [`Config::min_load_n`] ignored),
//!    the soles' loads.
//! 4. Command: the command port is answered; torque off on command; the online walk's command.
//! 5. Walk mode ([`modes`]): the ramp's targets, or the gait's samples (the one the IK takes is
//!    `servo_lead` ahead of the present one, the log's reference), checked finite before the IK
//!    (a non-finite one holds the last targets and stops: `NonFiniteSample`, exit 18).
//! 6. Sample corrections (gait-core [`gait_core::correction`]), in the path's order: the
//!    catching step (`catch_gain`: the capture-point error beyond the ankles' deadband moves
//!    the swing foot's landing place; logged as `CatchStep` records when its single support
//!    ends), the stabilizer (`stab=on`: a bounded shift δ of the commanded CoM from the measured
//!    ZMP error and the gyro), the foot force difference control (`fdc_gain`: the soles'
//!    heights in double support).
//! 7. IK: [`Targets`] (built once): the paper's pipeline (pelvis on the model's CoM + δ, two-leg
//!    IK) or, with `comp=wholebody`, whole-body compensation; it clamps to reach and joint
//!    limits. The fixed-point path takes the integer IK for the plan's integer samples.
//! 8. Joint corrections, in the path's order: the compliance feed-forward (`compliance_roll`,
//!    `compliance_pitch`), the gyro damping (`gyro_ankle`, `gyro_hip`), the swing sole kept
//!    level (`catch_level_pitch`, `catch_level_roll`), the deflection feedback
//!    (`deflection_ki`). With `catch_hold_max` > 0 the walk's clock stands still for a tick
//!    while a caught swing foot is still on its way to its landing place.
//! 9. Act: [`safe_targets`](crate::supervisor::safe_targets) to the servo ticks (a non-finite
//!    target holds the previous tick and stops); ONE SYNC WRITE of the 12 Goal Positions (116,
//!    4 bytes each);
//!    the servo monitor ([`crate::monitor`]) reads the leg servos round-robin (Torque Enable
//!    and Hardware Error Status, voltage and temperature, current); a servo silent or limp, or
//!    a limit exceeded, stops (`ServoLost`, `ServoFault`).
//! 10. Report: the tick log record (nominal time, ZMP reference, measured ZMP, CoM, τ, support
//!     phase, fault state, bus error counters, overruns); the watchdog is fed.
//!
//! With `math=fixed` (FPU-less cores, feature `fixed-gait`) the estimate, the IK and the log's
//! positions run in integers (`fixed_path::FixedPath`): the pitch filter with τ in whole mN·m,
//! the tilt, the measured ZMP, the fixed-point sample and IK, the gyro damping, the limits and
//! ticks (no f32 round trip); the sample is still copied to f32 for the support phase, the
//! stabilizer and the command port. The catching step, the levelling, the compliance
//! feed-forward, the force difference control, the deflection feedback and the leg odometry
//! are f32 only.
//!
//! Bus traffic per tick at 1 Mbps (no byte stuffing needed for typical data): BULK READ
//! instruction 25 bytes out; replies 29 + 29 + 37 = 95 bytes in; SYNC WRITE 74 bytes out — 99
//! bytes out and 95 in, ≈ 1.94 ms of line time (+ the Return Delay Times, 0 after start-up);
//! while walking the servo monitor adds two READs (14 + 14 bytes out, at most 18 + 18 in): 2.6 ms.
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
//! * Any supervisor stop, by its grade (docs/stops.md): a fall or a servo's hardware error
//!   turns torque off at once; the others lower the robot to the crouch
//!   ([`Config::lower_us`], [`Config::crouch_m`]) — operator stops and minor faults after the
//!   online walk has stopped to standing ([`Config::settle_us`]) — hold it for
//!   `stopping_ticks`, then torque off and the stop record with the reason. An operator's stop
//!   with [`Config::rest`] ends there instead, resting in the crouch with torque on
//!   ([`RunEnd::Resting`]); [`standby`] turns torque off on the next Mode = torque off.
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
//! again needs a power cycle.
//!
//! # Exit codes
//! [`RunEnd::exit_code`] maps an end to the contract's [`walker_contract::ExitCode`] table (the
//! one table of the codes and their meanings; QEMU passes them to the host through
//! semihosting).

use core::cell::Cell;

use gait_core::gait::TimingCheck;
use gait_core::robot::LEG_JOINTS;
use gait_core::{GaitError, Robot};
use walker_contract::bus_map;
#[cfg(not(feature = "board-opencm"))]
use walker_contract::command_port::ParamAccess;
#[cfg(feature = "board-opencm")]
use walker_contract::command_port::ParamStatus;
use walker_contract::command_port::{Mode, PortState};
use walker_contract::ExitCode;

use crate::board::{Board, CrashCode, CrashNote, ResetCause};
use crate::bus::BoardMaster;
use crate::monitor::ServoMonitor;
use crate::params::ArgError;
use crate::plausible::Plausibility;
use crate::record::{FaultKind, LogWriter};
use crate::startup::{self, Ramp, StartupError};
use crate::supervisor::{JointMap, StopReason, Supervisor};
use crate::{startup_record, Config};

use act::{fault, torque_off, write_goals, write_stop};
use controller::Controller;
use faults::FaultInjector;
use path::TickPath;
use sense::Sense;

mod act;
pub mod commanded;
mod controller;
#[cfg(not(feature = "board-opencm"))]
mod f32_path;
mod faults;
#[cfg(feature = "fixed-gait")]
mod fixed_path;
pub mod modes;
mod path;
mod sense;
#[cfg(not(feature = "board-opencm"))]
mod servo_sense;
#[cfg(not(feature = "board-opencm"))]
mod store;

use modes::Walk;

pub use walker_contract::config::{Compensation, Feasibility, MAX_LEAD_TICKS, MAX_STEPS};
/// The sampler type of the firmware.
pub type GaitSampler = gait_core::trajectory::fourier_walk::WalkSampler<f32, MAX_STEPS>;
/// Fault-record id of a plan rejected by gait-core.
pub const PLAN_REJECTED_ID: u8 = 0xFE;

pub use gait_core::gait::{support_of, SupportCache, Targets, WHOLEBODY_ITERATIONS};

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunEnd {
    /// The supervisor stopped (plan done or a fault); torque is off.
    Stopped(StopReason),
    /// The operator stopped the walk ([`Config::rest`]): the robot rests in the crouch with
    /// torque on.
    Resting(StopReason),
    /// A start-up step failed after the probe; torque is off.
    Startup(StartupError),
    /// gait-core rejected the configured walk; the bus was not touched.
    Config(GaitError),
}

impl RunEnd {
    /// The exit code of this end (the contract's table).
    pub fn exit(&self) -> ExitCode {
        match self {
            RunEnd::Stopped(r) | RunEnd::Resting(r) => r.kind().exit(),
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

/// Runs start-up and the walk on `board` with `cfg` until torque is off (see the module docs).
/// Never returns before torque is off once it was enabled.
pub fn run<B: Board>(board: &mut B, cfg: &Config) -> RunEnd {
    run_with(board, cfg, &mut commanded::CommandLink::new())
}

/// The board's whole life with the operator's enable ([`Config::wait_enable`]; module docs
/// "Enable"): torque off and the command port answered ([`standby`]) until a master writes
/// Mode = stand or walk, then a run ([`run_with`], the same port); after its stop, the same
/// again. Returns the last run's end (or `Requested` before any) when a master writes Mode =
/// torque off while the firmware waits with torque off (a run that ended resting is
/// [`RunEnd::Stopped`] then: its torque off was the first of the two writes). Parameter sets
/// on the command port while it waits change `cfg` for the next run (`command_port`
/// "Parameters").
pub fn run_on_enable<B: Board>(board: &mut B, cfg: &mut Config) -> RunEnd {
    let mut link = commanded::CommandLink::new();
    // The saved parameters, loaded once (not on the OpenCM 9.04: no flash for the parameter
    // table and a store).
    #[cfg(not(feature = "board-opencm"))]
    {
        let found = store::load(board, cfg);
        crate::fw_log!(info, "saved parameters: {}", found);
        link.store_note = Some(found);
        link.log_params = true;
    }
    let mut last = None;
    loop {
        let state = match last {
            None => PortState::Waiting,
            Some(RunEnd::Resting(_)) => PortState::Resting,
            Some(_) => PortState::Stopped,
        };
        if !standby(board, cfg, &mut link, state) {
            return match last {
                Some(RunEnd::Resting(r)) => RunEnd::Stopped(r),
                Some(end) => end,
                None => RunEnd::Stopped(StopReason::Requested),
            };
        }
        crate::fw_log!(info, "enabled: starting a run");
        last = Some(run_with(board, cfg, &mut link));
    }
}

/// How long the board's operator button must read other than its idle level to count as a
/// press (the enable), µs.
pub const BUTTON_HOLD_US: u64 = 50_000;

/// The operator's enable awaited, torque off (or, in `state` [`PortState::Resting`], the
/// robot resting in the crouch with torque on): every tick the command port is answered, its
/// State reads `state` (the rest of the status as the last run left it: Stop Code, Fault Kind,
/// step count) and the watchdog is fed. Mode reads torque off meanwhile: true on a master's
/// Mode write of stand or walk, or a press of the board's button ([`Board::enable_button`]:
/// its level other than the one found at the start for [`BUTTON_HOLD_US`]) — the enable;
/// on a Mode write of torque off: resting, torque off (confirmed, servo power cut; State
/// then 4) and the wait goes on; else false. A write of stop is taken and ignored. Parameter
/// ops are served against `cfg` (sets allowed: no run is going; the OpenCM 9.04 answers them
/// "not in this board's build", [`walker_contract::command_port::ParamStatus::Unsupported`]).
pub fn standby<B: Board>(
    board: &mut B,
    cfg: &mut Config,
    link: &mut commanded::CommandLink,
    state: PortState,
) -> bool {
    let mut log = LogWriter::new();
    let mut resting = state == PortState::Resting;
    link.set_mode(Mode::TorqueOff);
    link.port.table.set_state(state);
    let mut seen = link.port.table.mode_writes();
    let idle = board.enable_button();
    let mut pressed_since: Option<u64> = None;
    loop {
        board.wait_tick();
        board.feed();
        link.poll(board, &mut log);
        // Parameter ops: served, a save written to the board's store.
        #[cfg(not(feature = "board-opencm"))]
        {
            link.port.table.serve_param(ParamAccess::Settable(cfg));
            if link.port.table.take_save() {
                let saved = store::save(board, cfg);
                crate::fw_log!(info, "parameters saved: {}", saved);
                link.port.table.finish_save(saved);
            }
        }
        // The OpenCM 9.04's flash holds neither the parameter table nor a store (≈ 36 KB that
        // its 114 KiB do not have): an op is answered "not in this board's build", never left
        // pending.
        #[cfg(feature = "board-opencm")]
        link.port.table.answer_param(ParamStatus::Unsupported);
        let now = board.now_us();
        match (idle, board.enable_button()) {
            (Some(i), Some(level)) if level != i => {
                let since = *pressed_since.get_or_insert(now);
                if now.saturating_sub(since) >= BUTTON_HOLD_US {
                    link.set_mode(Mode::Stand);
                    return true;
                }
            }
            _ => pressed_since = None,
        }
        if link.port.table.mode_writes() == seen {
            continue;
        }
        seen = link.port.table.mode_writes();
        match link.mode() {
            Mode::Stand | Mode::Walk => return true,
            Mode::TorqueOff if resting => {
                crate::fw_log!(info, "torque off: the operator's second torque off");
                let time = Cell::new(0);
                torque_off(&mut BoardMaster::new(board, &time, cfg), &mut log, cfg);
                link.port.table.set_state(PortState::Stopped);
                resting = false;
            }
            Mode::TorqueOff => return false,
            Mode::Stop => link.set_mode(Mode::TorqueOff),
        }
    }
}

/// The robot of a real board's build: its flash holds the walk's set-up for this one robot,
/// folded by the compiler from its description (for all of them it would not fit the OpenCM
/// 9.04's 114 KiB nor the OpenCR bootloader's 256 KiB region): the ROBOTIS OP3 with the
/// feature `robot-op3`, else the reference robot. QEMU builds walk any described robot
/// (`robot=`).
#[cfg(all(
    any(feature = "board-opencm", feature = "board-opencr"),
    not(feature = "robot-op3")
))]
pub const BUILD_ROBOT: Robot = Robot::reference();
/// The robot of a real board's build (see above): the ROBOTIS OP3.
#[cfg(all(feature = "board-opencr", feature = "robot-op3"))]
pub const BUILD_ROBOT: Robot = Robot::op3();

/// The configuration a build for `robot` starts from: the defaults with `robot` and its bus
/// speed (what the parameter `robot=` sets).
pub fn defaults_for(robot: &'static Robot) -> Config {
    Config {
        robot,
        bus_baud: robot.bus.baud,
        ..Config::default()
    }
}

/// The configuration a real board's build starts from: [`defaults_for`] its robot
/// ([`BUILD_ROBOT`]).
#[cfg(any(feature = "board-opencm", feature = "board-opencr"))]
pub fn build_defaults() -> Config {
    defaults_for(&BUILD_ROBOT)
}

/// [`run`] with the command port `link` (kept by [`run_on_enable`] across runs).
pub fn run_with<B: Board>(
    board: &mut B,
    cfg: &Config,
    link: &mut commanded::CommandLink,
) -> RunEnd {
    // The configured robot: a reference to its description in flash (a copy here would sit in
    // this frame all run); a real board's build walks its own robot ([`BUILD_ROBOT`]).
    #[cfg(not(any(feature = "board-opencm", feature = "board-opencr")))]
    let robot: &Robot = cfg.robot;
    #[cfg(any(feature = "board-opencm", feature = "board-opencr"))]
    let robot: &Robot = &BUILD_ROBOT;
    let mut log = LogWriter::new();
    // The operator's configuration (before the servo-speed check adjusts the walk), logged
    // after the start-up record where the runs log their parameters.
    let given = cfg;
    let params = ParamNotes {
        cfg: link.log_params.then_some(given),
        store: link.store_note.take(),
    };
    // The watchdog runs from boot: the boards feed it in their wait loops, the dry run every
    // 256 samples, the loop every tick.
    board.start(cfg.watchdog_ms);
    // Why did we boot? Only a power-on walks by itself.
    let boot = Boot::read(board);
    if boot.cause != ResetCause::PowerOn {
        return not_power_on(board, cfg, &boot, &mut log);
    }
    // A real board's build refuses another robot before the bus is touched.
    if cfg.robot.name != robot.name {
        return rejected_walk(board, cfg, &boot, &mut log, GaitError::BadRobotDescription);
    }
    let targets = gait_core::gait::Targets::new(robot, cfg.compensation);
    // The walk (≈ 10 KB) is built where it lives, never moved: its storage lends its engine to
    // the servo-speed check (a dry run that adjusts the walk before anything moves), then
    // holds the gait (BENCHMARKS.md "RAM").
    let mut walk = Walk::idle();
    let timing = match walk.scratch() {
        Some(s) => startup::servo_timing_in(cfg, robot, &targets, &mut || board.feed(), s),
        None => Err(GaitError::NotBuiltIn),
    };
    let timing = match timing {
        Ok(t) => t,
        Err(e) => return rejected_walk(board, cfg, &boot, &mut log, e),
    };
    let cfg = &Config {
        walk: timing.walk,
        ..*cfg
    };
    // Without autostart the robot stands up and walks on command (the online walk).
    if let Err(e) = walk.build(cfg, robot) {
        return rejected_walk(board, cfg, &boot, &mut log, e);
    }
    let time = Cell::new(0);
    let mut bus = BoardMaster::new(board, &time, cfg);
    let started = match start_up(&mut bus, &mut log, cfg, &boot, &timing, &params) {
        Ok(s) => s,
        Err(end) => return end,
    };
    let map = JointMap::from_robot(robot);
    let parts = Parts {
        cfg,
        robot,
        targets: &targets,
        map: &map,
    };
    // The arithmetic, chosen once: the OpenCM 9.04 (no FPU) runs the fixed-point path only;
    // `math=fixed` selects it where the build has it (feature `fixed-gait`).
    #[cfg(feature = "board-opencm")]
    {
        walk_on(&mut bus, log, &parts, &mut walk, link, started, |_| {
            fixed_path::FixedPath::new(cfg, robot)
        })
    }
    #[cfg(not(feature = "board-opencm"))]
    {
        #[cfg(feature = "fixed-gait")]
        if cfg.arithmetic == gait_core::gait::Arithmetic::Fixed {
            return walk_on(&mut bus, log, &parts, &mut walk, link, started, |_| {
                fixed_path::FixedPath::new(cfg, robot)
            });
        }
        walk_on(&mut bus, log, &parts, &mut walk, link, started, |z_c| {
            f32_path::F32Path::new(cfg, robot, &map, z_c)
        })
    }
}

/// After any reset but a power-on: the start-up record, the boot's records, torque off
/// (confirmed, then the servo power cut: the servos kept their power through the reset) and
/// the stop `NotPowerOn`.
fn not_power_on<B: Board>(board: &mut B, cfg: &Config, boot: &Boot, log: &mut LogWriter) -> RunEnd {
    crate::fw_log!(error, "reset cause {}: not walking", boot.cause.code());
    let rec = startup_record(board, cfg, None);
    log.write(board, rec);
    boot.write(board, log);
    let time = Cell::new(0);
    let mut bus = BoardMaster::new(board, &time, cfg);
    torque_off(&mut bus, log, cfg);
    let reason = StopReason::NotPowerOn { cause: boot.cause };
    write_stop(&mut bus, log, reason);
    RunEnd::Stopped(reason)
}

/// A walk gait-core rejected: the start-up record, the boot's records and `ConfigRejected`; the
/// bus was not touched.
fn rejected_walk<B: Board>(
    board: &mut B,
    cfg: &Config,
    boot: &Boot,
    log: &mut LogWriter,
    e: GaitError,
) -> RunEnd {
    crate::fw_log!(error, "walk rejected by gait-core: error {}", e.code());
    let rec = startup_record(board, cfg, None);
    log.write(board, rec);
    boot.write(board, log);
    let rec = fault(
        board.now_us(),
        FaultKind::ConfigRejected,
        PLAN_REJECTED_ID,
        i32::from(e.code()),
    );
    log.write(board, rec);
    RunEnd::Config(e)
}

/// What start-up leaves for the walk: the devices missing, the supervisor, the servos' present
/// ticks.
struct Started {
    missing: heapless::Vec<u8, { crate::record::MAX_MISSING }>,
    sup: Supervisor<3>,
    present: [i32; LEG_JOINTS],
}

/// Start-up on the bus: 1. probe (start-up record, boot and timing notes; a missing device the
/// walk needs stops), 2–4. Return Delay Time, position gains, present pose, goal = present,
/// torque on. Any failure turns torque off and ends the run.
/// What a run logs about its parameters after its start-up record (not on the OpenCM 9.04:
/// no parameter table's text in its flash).
#[cfg_attr(feature = "board-opencm", allow(dead_code))]
struct ParamNotes<'a> {
    /// The configuration whose parameters that differ from the defaults are logged
    /// (`ParamValue`), if the run logs them.
    cfg: Option<&'a Config>,
    /// The boot's load of the saved parameters (`ParamStore`), once.
    store: Option<walker_contract::param_store::StoreOutcome>,
}

/// Logs `notes` ([`FaultKind::ParamStore`], then a [`FaultKind::ParamValue`] per parameter
/// that differs from the defaults).
#[cfg(not(feature = "board-opencm"))]
fn log_param_notes<B: Board>(board: &mut B, log: &mut LogWriter, notes: &ParamNotes<'_>) {
    const DEFAULTS: Config = Config::default_config();
    let now = board.now_us();
    if let Some(s) = notes.store {
        log.write(
            board,
            fault(now, FaultKind::ParamStore, s.code(), s.value()),
        );
    }
    let Some(cfg) = notes.cfg else {
        return;
    };
    for (i, p) in crate::params::PARAMS.iter().enumerate() {
        let v = p.value(cfg);
        if v == p.value(&DEFAULTS) {
            continue;
        }
        let (Some(v), Ok(i)) = (v, u8::try_from(i)) else {
            continue;
        };
        let bits = (v.as_f64() as f32).to_bits() as i32;
        log.write(board, fault(now, FaultKind::ParamValue, i, bits));
    }
}

fn start_up<B: Board>(
    bus: &mut BoardMaster<'_, B>,
    log: &mut LogWriter,
    cfg: &Config,
    boot: &Boot,
    timing: &TimingCheck,
    params: &ParamNotes<'_>,
) -> Result<Started, RunEnd> {
    let devices = bus_map::device_ids(bus.devices());
    let mut missing = startup::probe(bus, &devices, cfg);
    if !startup::board_imu_started(bus) {
        // At most MAX_MISSING: a full list already stops the run.
        let _ = missing.push(bus_map::BOARD_IMU);
    }
    {
        let b = bus.board();
        let rec = startup_record(&*b, cfg, Some(&missing));
        log.write(b, rec);
        boot.write(b, log);
        #[cfg(not(feature = "board-opencm"))]
        log_param_notes(b, log, params);
    }
    #[cfg(feature = "board-opencm")]
    let _ = params;
    // A robot without some sensors says so once (the log's ZMP response then has no measured
    // ZMP, and no record pretends otherwise).
    let slots = bus_map::sensor_ids(bus.devices());
    if slots.iter().any(Option::is_none) {
        let has = slots
            .iter()
            .enumerate()
            .fold(0u8, |m, (k, s)| if s.is_some() { m | (1 << k) } else { m });
        crate::fw_log!(
            info,
            "sensor slots (bits: left foot, right foot, IMU): {}",
            has
        );
        let now = bus.board().now_us();
        log.write(bus.board(), fault(now, FaultKind::SensorsAbsent, has, 0));
    }
    for (kind, id, value) in timing.notes().into_iter().map(startup::note_record) {
        let now = bus.board().now_us();
        log.write(bus.board(), fault(now, kind, id, value));
    }
    let mut critical: heapless::Vec<u8, { crate::record::MAX_MISSING }> = heapless::Vec::new();
    for &id in missing.iter() {
        if cfg.feet_required || !bus_map::is_foot(bus.devices(), id) {
            let _ = critical.push(id);
        }
    }
    let ticks = |us: u32| u16::try_from(cfg.ticks_for_us(us)).unwrap_or(u16::MAX);
    let sensors = bus_map::sensor_ids(bus.devices()).map(|s| s.unwrap_or(bus_map::NOT_ON_BUS));
    let mut sup = Supervisor::new(cfg.supervisor, sensors)
        .with_grades(ticks(cfg.settle_us), ticks(cfg.lower_us))
        .with_rest(cfg.rest);
    if let Err(reason) = sup.startup(&critical) {
        crate::fw_log!(
            error,
            "{} device(s) missing, first {}",
            missing.len(),
            critical.first()
        );
        torque_off(bus, log, cfg);
        write_stop(bus, log, reason);
        return Err(RunEnd::Stopped(reason));
    }
    let mut present_ids: heapless::Vec<u8, { bus_map::MAX_DEVICES }> = heapless::Vec::new();
    for &id in devices.iter() {
        if !missing.contains(&id) {
            let _ = present_ids.push(id);
        }
    }
    let present = startup::set_return_delay(bus, &present_ids, cfg)
        .and_then(|_| startup::set_position_gains(bus, cfg))
        .and_then(|_| startup::read_positions(bus, cfg))
        .and_then(|p| {
            write_goals(bus, &p);
            startup::enable_torque(bus, cfg).map(|()| p)
        });
    match present {
        Ok(present) => Ok(Started {
            missing,
            sup,
            present,
        }),
        Err(e) => {
            crate::fw_log!(error, "start-up failed at device {}", e.id);
            let t = bus.board().now_us();
            let rec = fault(t, FaultKind::StartupFailed, e.id, i32::from(e.step.code()));
            log.write(bus.board(), rec);
            torque_off(bus, log, cfg);
            write_stop(bus, log, StopReason::DeviceLost { id: e.id });
            Err(RunEnd::Startup(e))
        }
    }
}

/// What the controller is built from.
struct Parts<'a> {
    cfg: &'a Config,
    robot: &'a Robot,
    targets: &'a gait_core::gait::Targets,
    map: &'a JointMap,
}

/// The ramp from the present pose to the initial pose (the plan's first sample or the online
/// walk's standing pose, with the path's feed-forwards), then the [`Controller`] with the path
/// `make_path(z_c)` ticks until torque is off. The controller is built where it lives (its
/// fields in its literal: no copies on the stack).
// The arguments are the controller's parts, each borrowed where it lives.
#[allow(clippy::too_many_arguments)]
fn walk_on<B: Board, P: TickPath>(
    bus: &mut BoardMaster<'_, B>,
    log: LogWriter,
    parts: &Parts<'_>,
    walk: &mut Walk,
    link: &mut commanded::CommandLink,
    started: Started,
    make_path: impl FnOnce(f32) -> P,
) -> RunEnd {
    let Parts {
        cfg,
        robot,
        targets,
        map,
    } = *parts;
    let (first, mut q0, loaded) = walk.gait.initial_pose(targets);
    let weight_n = (robot.masses.total() * robot.gravity) as f32;
    let Started {
        missing,
        sup,
        present,
    } = started;
    let mut c = Controller {
        cfg,
        targets,
        map,
        walk,
        path: make_path(first.com[2]),
        sense: Sense::new(
            bus.devices(),
            &missing,
            Plausibility::<3>::new(cfg, weight_n, bus.board().now_us()),
        ),
        sup,
        monitor: ServoMonitor::new(),
        link,
        log,
        faults: FaultInjector::new(cfg),
        last_ticks: present.map(|t| t.max(map.tick_min).min(map.tick_max)),
        prev: first,
        prev_feet_fx: None,
        goal: path::Goal::Rad([0.0; LEG_JOINTS]),
        clamped_seen: 0,
        final_hold: u16::try_from(cfg.ticks_for_us(cfg.final_hold_us)).unwrap_or(u16::MAX),
        lowering: None,
        no_lead: cfg.lead_ticks() == 0,
    };
    c.path.ramp_end(&mut q0, &loaded);
    if c.walk.gait.online().is_some() {
        let now = bus.board().now_us();
        let period = commanded::period_us(cfg);
        let rec = fault(
            now,
            FaultKind::Footstep,
            walker_contract::footstep_log::PERIOD_ID,
            period,
        );
        c.log.write(bus.board(), rec);
    }
    let mut from = [0.0f32; LEG_JOINTS];
    for (j, (f, &t)) in from.iter_mut().zip(present.iter()).enumerate() {
        *f = map.rad_of_tick(j, t);
    }
    let ramp = Ramp::new(from, q0, cfg.ticks_for_us(cfg.ramp_us));
    let ramp_ticks = ramp.ticks();
    c.walk.start(ramp);
    if !first.is_finite() {
        // The initial pose would come from a non-finite sample: hold the present pose, stop.
        c.sup.stop(StopReason::NonFiniteSample { tick: 0 });
    }
    crate::fw_log!(info, "walking: ramp {} ticks", ramp_ticks);
    loop {
        if let Some(end) = c.tick(bus) {
            return end;
        }
    }
}

#[cfg(test)]
mod stage_tests;
#[cfg(test)]
mod tests;
