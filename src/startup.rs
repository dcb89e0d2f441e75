//! Start-up on the bus: probe every device, Return Delay Time 0, present pose, torque on, and
//! the smooth move from the present pose to the gait's initial pose.
//!
//! Sequence (run by [`crate::control::run`]):
//! 1. [`probe`]: PING every id of [`walker_contract::bus_map::DEVICE_IDS`] (each up to
//!    [`Config::startup_attempts`] times, default 8); the ids that never answer are reported in the
//!    start-up log record. A missing servo or IMU stops (exit code 11, stop record
//!    `DeviceMissing`); a missing foot board too unless [`Config::feet_required`] is false
//!    (then the walk runs without it, see [`crate::control`]).
//! 2. [`set_return_delay`]: READ Return Delay Time (address 9) of every present device; when it
//!    is not 0, WRITE 0 and READ it back (the register is in EEPROM: writing only when needed
//!    spares it). A device whose value does not read back as 0 fails start-up.
//! 3. [`read_positions`]: one SYNC READ of Present Position (132, 4 bytes) of the 12 servos.
//! 4. [`enable_torque`]: WRITE Torque Enable (64) = 1 to each servo, status checked.
//! 5. [`Ramp`]: the joints move from the present pose to the initial pose (the first gait
//!    sample through the IK) along a minimum-jerk profile over [`Config::ramp_us`], one SYNC
//!    WRITE of Goal Position per tick (done by the control loop).
//!
//! Before all of this (before anything moves), [`servo_timing`] runs the whole plan through the
//! sampler and the joint-target pipeline at dt (a dry run, O(1) memory) with gait-core's
//! `JointSpeedMonitor`. When the peak joint speed v exceeds the servo limit v_max
//! (`robot.servo.max_speed`, 4.8 rad/s for an XM430; the Table 2 swing needs ≈ 5.8 rad/s at the
//! swing knee), with `feasibility=stretch` t1, t2 and T are multiplied by
//! f = ⌈1000·(v/v_max)·1.05⌉/1000 (joint speeds scale as 1/f for the same path), with
//! `feasibility=lower` the swing height becomes ⌊h_z·v_max/(1.05·v)⌋ (µm), and the plan is
//! checked again, at most [`MAX_TIMING_ROUNDS`] adjustments. All rounds together spend at most
//! [`MAX_DRY_RUN_WORK`] (a few seconds on the M7; a longer plan is refused with
//! `GaitError::DryRunTooLong`, exit 2), feeding the watchdog every 256 samples
//! ([`servo_timing_fed`]). Fault records (log kinds 7, 8, 9)
//! carry the factor / new height and a remaining excess.
//!
//! Steps 2–4 report the first failing device as a [`StartupError`] (log fault record
//! `StartupFailed`, exit code 20).

use dxl::table::x_series;
use gait_core::robot::ImuPlace;
use walker_contract::bus_map::{TickMap, MAX_HELD};

use crate::board::{Board, Clock, ServoBus};
use crate::bus::BoardMaster;
use crate::record::MAX_MISSING;
use crate::Config;
use gait_core::gait::Targets;
use gait_core::kinematics::leg::JointSpeedReport;
use gait_core::robot::{HeldServo, LEG_JOINTS};
use gait_core::trajectory::fourier_walk::WalkSampler;
use gait_core::{GaitError, Robot};
use walker_contract::config::MAX_STEPS;

pub use gait_core::gait::{
    stretched, TimingCheck, TimingNote, MAX_DRY_RUN_WORK, MAX_TIMING_ROUNDS, TIMING_MARGIN,
};

pub use walker_contract::record::timing_fault as note_record;

/// Peak joint speeds of `cfg`'s walk through `targets` at dt (gait-core's dry run).
pub fn dry_run(
    cfg: &Config,
    robot: &Robot,
    targets: &Targets,
) -> Result<JointSpeedReport, GaitError> {
    gait_core::gait::dry_run::<MAX_STEPS>(&cfg.walk_config(), robot, targets)
}

/// The servo-speed check of `cfg`'s walk (gait-core's [`gait_core::gait::servo_timing`]).
pub fn servo_timing(
    cfg: &Config,
    robot: &Robot,
    targets: &Targets,
) -> Result<TimingCheck, GaitError> {
    servo_timing_fed(cfg, robot, targets, &mut || {})
}

/// [`servo_timing`] calling `feed` (the watchdog) every few hundred samples.
pub fn servo_timing_fed(
    cfg: &Config,
    robot: &Robot,
    targets: &Targets,
    feed: &mut dyn FnMut(),
) -> Result<TimingCheck, GaitError> {
    servo_timing_in(cfg, robot, targets, feed, &mut WalkSampler::idle())
}

/// [`servo_timing_fed`] with the dry runs' sampler in `scratch` (the walk's engine storage,
/// `control::modes::Walk::scratch`: no sampler of its own on the stack).
// Out of line: its temporaries get a frame of their own, not the caller's (start-up
// stack: scripts/stack-depth.py, BENCHMARKS.md "RAM").
#[inline(never)]
pub fn servo_timing_in(
    cfg: &Config,
    robot: &Robot,
    targets: &Targets,
    feed: &mut dyn FnMut(),
    scratch: &mut WalkSampler<f32, MAX_STEPS>,
) -> Result<TimingCheck, GaitError> {
    gait_core::gait::servo_timing_in::<MAX_STEPS>(
        &cfg.walk_config(),
        cfg.feasibility,
        robot,
        targets,
        feed,
        scratch,
    )
}

pub use walker_contract::codes::StartupStep;

/// A start-up step failed for device `id`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StartupError {
    /// The step.
    pub step: StartupStep,
    /// The device.
    pub id: u8,
    /// The driver's error (`None` for a verification mismatch).
    pub error: Option<dxl::Error>,
}

/// Retries `f` up to `attempts` times (at least once); returns the last result.
fn retry<T>(attempts: u8, mut f: impl FnMut() -> Result<T, dxl::Error>) -> Result<T, dxl::Error> {
    let mut last = Err(dxl::Error::Timeout);
    for _ in 0..attempts.max(1) {
        last = f();
        if last.is_ok() {
            break;
        }
    }
    last
}

/// PINGs every id of `devices`; returns the ids that never answered (at most
/// [`MAX_MISSING`], in bus order).
pub fn probe<B: ServoBus + Clock>(
    bus: &mut BoardMaster<'_, B>,
    devices: &[u8],
    cfg: &Config,
) -> heapless::Vec<u8, MAX_MISSING> {
    let mut missing = heapless::Vec::new();
    for &id in devices {
        if retry(cfg.startup_attempts, || bus.master().ping(id).map(|_| ())).is_err() {
            // More than MAX_MISSING missing devices: the list is full, the count is enough.
            let _ = missing.push(id);
        }
    }
    missing
}

/// Starts the board's IMU when the robot's IMU is on the board ([`Board::imu_start`]);
/// false when it is and did not start (no IMU on this board, another chip, a dead bus), true
/// otherwise.
pub fn board_imu_started<B: Board>(bus: &mut BoardMaster<'_, B>) -> bool {
    if !matches!(bus.devices().imu, ImuPlace::Board(_)) {
        return true;
    }
    match bus.board().imu_start() {
        Some(Ok(())) => true,
        Some(Err(e)) => {
            let (code, byte) = e.code();
            crate::fw_log!(
                error,
                "the board's IMU did not start: error {} ({})",
                code,
                byte
            );
            false
        }
        None => {
            crate::fw_log!(error, "the robot's IMU is the board's: this board has none");
            false
        }
    }
}

/// Sets Return Delay Time to 0 on every device of `devices` (write only when needed) and
/// verifies it by reading it back; returns how many devices were written.
pub fn set_return_delay<B: ServoBus + Clock>(
    bus: &mut BoardMaster<'_, B>,
    devices: &[u8],
    cfg: &Config,
) -> Result<u8, StartupError> {
    let addr = x_series::RETURN_DELAY_TIME.addr;
    let n = cfg.startup_attempts;
    let fail = |step, id, error| StartupError { step, id, error };
    let mut written = 0u8;
    for &id in devices {
        let mut v = [0xFFu8; 1];
        retry(n, || bus.master().read(id, addr, &mut v))
            .map_err(|e| fail(StartupStep::ReturnDelayRead, id, Some(e)))?;
        if v[0] == 0 {
            continue;
        }
        let steps = [
            StartupStep::ReturnDelayWrite,
            StartupStep::ReturnDelayRead,
            StartupStep::ReturnDelayVerify,
        ];
        write_verified(bus, n, id, addr, [0], steps)?;
        written = written.saturating_add(1);
    }
    Ok(written)
}

/// Writes `value` at `addr` of device `id` and reads it back, each retried `attempts` times;
/// `steps` name the failures: [write, read-back, verify (the read-back differs)].
fn write_verified<B: ServoBus + Clock, const L: usize>(
    bus: &mut BoardMaster<'_, B>,
    attempts: u8,
    id: u8,
    addr: u16,
    value: [u8; L],
    steps: [StartupStep; 3],
) -> Result<(), StartupError> {
    let [write, read, verify] = steps;
    let fail = |step, error| StartupError { step, id, error };
    retry(attempts, || bus.master().write(id, addr, &value)).map_err(|e| fail(write, Some(e)))?;
    let mut back = [0u8; L];
    retry(attempts, || bus.master().read(id, addr, &mut back)).map_err(|e| fail(read, Some(e)))?;
    if back != value {
        return Err(fail(verify, None));
    }
    Ok(())
}

/// The Position I Gain of leg joint `j` from `cfg`: [`Config::servo_i_hip_roll`] for the
/// hip-roll joints (1 of each leg), [`Config::servo_i_roll`] for the ankle-roll joints (5),
/// [`Config::servo_i_pitch`] for hip pitch, knee and ankle pitch (2, 3, 4), none for the hip
/// yaw (0).
pub fn position_i_gain(cfg: &Config, j: usize) -> Option<u16> {
    match j % 6 {
        1 => Some(cfg.servo_i_hip_roll),
        5 => Some(cfg.servo_i_roll),
        2..=4 => Some(cfg.servo_i_pitch),
        _ => None,
    }
}

/// Writes the configured Position I Gains (register 82) to the leg servos whose gain is not 0,
/// each write read back (retried `startup_attempts` times); returns how many were written.
/// Position-mode servos follow their goal only to a load-dependent error (P gain 800: ≈ 19
/// N·m/rad on an XM430-W350); the integral removes that sag of the stance leg.
pub fn set_position_gains<B: ServoBus + Clock>(
    bus: &mut BoardMaster<'_, B>,
    cfg: &Config,
) -> Result<u8, StartupError> {
    let addr = x_series::POSITION_I_GAIN.addr;
    let n = cfg.startup_attempts;
    let mut written = 0u8;
    for (j, &id) in bus.devices().legs.iter().enumerate() {
        let Some(gain) = position_i_gain(cfg, j).filter(|g| *g > 0) else {
            continue;
        };
        let steps = [
            StartupStep::GainWrite,
            StartupStep::GainWrite,
            StartupStep::GainVerify,
        ];
        write_verified(bus, n, id, addr, gain.to_le_bytes(), steps)?;
        written = written.saturating_add(1);
    }
    Ok(written)
}

/// Present positions (ticks) of the 12 leg servos by SYNC READ, retried per device: each
/// attempt asks only the servos that have not answered yet, so a lost reply costs that servo
/// one more attempt, not the whole transaction (with `attempts` = 8 and 20 % reply loss, a
/// servo misses all attempts with probability 0.2⁸ ≈ 2.6·10⁻⁶).
pub fn read_positions<B: ServoBus + Clock>(
    bus: &mut BoardMaster<'_, B>,
    cfg: &Config,
) -> Result<[i32; LEG_JOINTS], StartupError> {
    let f = x_series::PRESENT_POSITION;
    let legs = bus.devices().legs;
    let mut ticks = [0i32; LEG_JOINTS];
    let mut done = [false; LEG_JOINTS];
    let mut last_error = dxl::Error::Timeout;
    for _ in 0..cfg.startup_attempts.max(1) {
        // The servos still to read, in bus order.
        let mut ids: heapless::Vec<u8, LEG_JOINTS> = heapless::Vec::new();
        let mut slots: heapless::Vec<usize, LEG_JOINTS> = heapless::Vec::new();
        for (j, (&id, &ok)) in legs.iter().zip(done.iter()).enumerate() {
            if !ok {
                let _ = ids.push(id);
                let _ = slots.push(j);
            }
        }
        if ids.is_empty() {
            break;
        }
        let mut out = [0u8; 4 * LEG_JOINTS];
        let mut results = [Ok(()); LEG_JOINTS];
        let n = ids.len();
        let (Some(out), Some(results)) = (out.get_mut(..4 * n), results.get_mut(..n)) else {
            break;
        };
        if let Err(e) = bus.master().sync_read(f.addr, f.len, &ids, out, results) {
            last_error = e;
            continue;
        }
        for ((r, c), &j) in results.iter().zip(out.chunks_exact(4)).zip(slots.iter()) {
            match r {
                Ok(()) => {
                    if let (Some(t), Some(d)) = (ticks.get_mut(j), done.get_mut(j)) {
                        *t = <[u8; 4]>::try_from(c).map_or(0, i32::from_le_bytes);
                        *d = true;
                    }
                }
                Err(e) => last_error = *e,
            }
        }
    }
    match done.iter().position(|d| !d) {
        None => Ok(ticks),
        Some(j) => Err(StartupError {
            step: StartupStep::ReadPositions,
            id: legs.get(j).copied().unwrap_or(0),
            error: Some(last_error),
        }),
    }
}

/// WRITE Torque Enable = 1 to each leg servo, then each held servo (arms, head) gets its
/// pose: Profile Velocity [`HELD_PROFILE_VELOCITY`] (a slow move there), Goal Position its
/// held angle, Torque Enable = 1 (every write's status checked).
pub fn enable_torque<B: ServoBus + Clock>(
    bus: &mut BoardMaster<'_, B>,
    cfg: &Config,
) -> Result<(), StartupError> {
    let addr = x_series::TORQUE_ENABLE.addr;
    let devices = bus.devices();
    let write = |bus: &mut BoardMaster<'_, B>, id: u8, addr: u16, data: &[u8]| {
        retry(cfg.startup_attempts, || bus.master().write(id, addr, data)).map_err(|e| {
            StartupError {
                step: StartupStep::TorqueEnable,
                id,
                error: Some(e),
            }
        })
    };
    for &id in devices.legs.iter() {
        write(bus, id, addr, &[1])?;
    }
    let ticks = TickMap::from_robot(cfg.robot);
    for h in devices.held.iter().take(MAX_HELD) {
        let profile = HELD_PROFILE_VELOCITY.to_le_bytes();
        write(bus, h.id, x_series::PROFILE_VELOCITY.addr, &profile)?;
        let goal = held_goal(&ticks, h).to_le_bytes();
        write(bus, h.id, x_series::GOAL_POSITION.addr, &goal)?;
        write(bus, h.id, addr, &[1])?;
    }
    Ok(())
}

/// A held servo's Goal Position (ticks): its angle in its own direction.
pub fn held_goal(ticks: &TickMap, h: &HeldServo) -> i32 {
    ticks.servo_tick_f32(h.angle as f32)
}

/// Profile Velocity of the held servos (0.229 rpm units: 20 ≈ 0.48 rad/s), so that an arm
/// far from its pose at start-up moves there slowly.
pub const HELD_PROFILE_VELOCITY: u32 = 20;

/// Minimum-jerk blend `s(u) = 10u³ − 15u⁴ + 6u⁵` for `u` clamped to [0, 1]: s(0) = 0,
/// s(1) = 1, zero velocity and acceleration at both ends (NaN counts as 0).
pub fn min_jerk(u: f32) -> f32 {
    let u = if u.is_nan() { 0.0 } else { u.clamp(0.0, 1.0) };
    u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
}

/// The smooth move from the present pose to the initial pose, in joint space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ramp {
    from: [f32; LEG_JOINTS],
    to: [f32; LEG_JOINTS],
    ticks: u32,
}

impl Ramp {
    /// From `from` to `to` (rad) in `ticks` ticks (at least 1).
    pub fn new(from: [f32; LEG_JOINTS], to: [f32; LEG_JOINTS], ticks: u32) -> Self {
        Ramp {
            from,
            to,
            ticks: ticks.max(1),
        }
    }

    /// Number of ticks of the move; tick `ticks()` − 1 commands `to` exactly.
    pub fn ticks(&self) -> u32 {
        self.ticks
    }

    /// The joint targets of tick `k` (0-based): `from + (to − from)·s((k+1)/ticks)`.
    pub fn at(&self, k: u32) -> [f32; LEG_JOINTS] {
        let s = min_jerk(k.saturating_add(1) as f32 / self.ticks as f32);
        let mut q = [0.0f32; LEG_JOINTS];
        for ((o, &a), &b) in q.iter_mut().zip(self.from.iter()).zip(self.to.iter()) {
            *o = a + (b - a) * s;
        }
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fake_robot::trace::FakeBoard;
    use core::cell::Cell;
    use dxl::opcode;
    use walker_contract::bus_map as ids;

    #[test]
    fn min_jerk_profile() {
        assert_eq!(min_jerk(0.0), 0.0);
        assert!((min_jerk(1.0) - 1.0).abs() < 1e-6);
        assert!((min_jerk(0.5) - 0.5).abs() < 1e-6);
        assert_eq!(min_jerk(-3.0), 0.0);
        assert!((min_jerk(7.0) - 1.0).abs() < 1e-6);
        assert_eq!(min_jerk(f32::NAN), 0.0);
        let mut prev = 0.0;
        for i in 1..=100 {
            let s = min_jerk(i as f32 / 100.0);
            assert!(s >= prev);
            prev = s;
        }
        // Zero slope at the ends: the first step of 1/100 moves by ~1e-5.
        assert!(min_jerk(0.01) < 2e-5);
        assert!(1.0 - min_jerk(0.99) < 2e-5);
    }

    #[test]
    fn ramp_ends_at_target() {
        let from = [0.5f32; 12];
        let mut to = [0.0f32; 12];
        to[3] = 1.0;
        let r = Ramp::new(from, to, 300);
        assert_eq!(r.at(299), to);
        let q0 = r.at(0);
        assert!((q0[0] - 0.5).abs() < 1e-4);
        assert_eq!(Ramp::new(from, to, 0).ticks(), 1);
    }

    #[test]
    fn positions_are_retried_per_device() {
        // Servos 3 and 9 never answer: every attempt after the first asks only those two (a
        // SYNC READ 10 id bytes shorter), and the error names the first of them.
        let mut board = FakeBoard::robot();
        for id in [3u8, 9] {
            if let Some(d) = board.device_mut(id) {
                d.dead = true;
            }
        }
        let time = Cell::new(0);
        let cfg = Config::default();
        let mut bus = BoardMaster::new(&mut board, &time, &cfg);
        let err = read_positions(&mut bus, &cfg).unwrap_err();
        assert_eq!(err.step, StartupStep::ReadPositions);
        assert_eq!(err.id, 3);
        let sizes: Vec<usize> = board
            .packets
            .iter()
            .filter(|p| p.op == dxl::opcode::SYNC_READ)
            .map(|p| p.tx_bytes)
            .collect();
        assert_eq!(sizes.len(), usize::from(cfg.startup_attempts));
        assert!(sizes[1..].iter().all(|&n| n + 10 == sizes[0]), "{sizes:?}");
        // With all servos answering, one attempt reads all twelve.
        let mut board = FakeBoard::robot();
        let mut bus = BoardMaster::new(&mut board, &time, &cfg);
        assert_eq!(
            read_positions(&mut bus, &cfg),
            Ok(FakeBoard::initial_ticks())
        );
        assert_eq!(board.count(dxl::opcode::SYNC_READ), 1);
    }

    #[test]
    fn startup_pings_all_sets_and_verifies_return_delay() {
        let mut board = FakeBoard::robot();
        let time = Cell::new(0);
        let cfg = Config::default();
        let mut bus = BoardMaster::new(&mut board, &time, &cfg);
        let missing = probe(&mut bus, &ids::DEVICE_IDS, &cfg);
        assert!(missing.is_empty());
        let written = set_return_delay(&mut bus, &ids::DEVICE_IDS, &cfg);
        assert_eq!(written, Ok(15));
        // Second time: already 0, nothing written.
        assert_eq!(set_return_delay(&mut bus, &ids::DEVICE_IDS, &cfg), Ok(0));
        let ticks = read_positions(&mut bus, &cfg).unwrap();
        assert_eq!(ticks, FakeBoard::initial_ticks());
        enable_torque(&mut bus, &cfg).unwrap();
        // Every device pinged, written (addr 9 = 0) and read back.
        for id in ids::DEVICE_IDS {
            let pk = |op: u8| {
                board
                    .packets
                    .iter()
                    .filter(move |p| p.id == id && p.op == op)
            };
            assert_eq!(pk(opcode::PING).count(), 1, "ping {id}");
            let writes: Vec<_> = pk(opcode::WRITE).filter(|p| p.addr == 9).collect();
            assert_eq!(writes.len(), 1, "write {id}");
            assert_eq!(writes[0].data, vec![0]);
            assert_eq!(
                pk(opcode::READ).filter(|p| p.addr == 9).count(),
                3,
                "reads {id}"
            );
            assert_eq!(board.device(id).unwrap().rdt, 0);
        }
        assert!(board.servos().all(|d| d.torque));
        assert_eq!(
            board
                .packets
                .iter()
                .filter(|p| p.op == opcode::SYNC_READ)
                .count(),
            1
        );
    }

    #[test]
    fn probe_reports_missing_and_verify_catches_a_stuck_register() {
        let mut board = FakeBoard::robot();
        board.remove(7);
        board.remove(200);
        board.device_mut(3).unwrap().rdt_stuck = true;
        let time = Cell::new(0);
        let cfg = Config::default();
        let mut bus = BoardMaster::new(&mut board, &time, &cfg);
        let missing = probe(&mut bus, &ids::DEVICE_IDS, &cfg);
        assert_eq!(&missing[..], &[7, 200]);
        let e = set_return_delay(&mut bus, &[1, 2, 3], &cfg).unwrap_err();
        assert_eq!(e.step, StartupStep::ReturnDelayVerify);
        assert_eq!(e.id, 3);
        let e = read_positions(&mut bus, &cfg).unwrap_err();
        assert_eq!((e.step, e.id), (StartupStep::ReadPositions, 7));
        let e = enable_torque(&mut bus, &cfg).unwrap_err();
        assert_eq!((e.step, e.id), (StartupStep::TorqueEnable, 7));
        // Each missing device was pinged `startup_attempts` times.
        let pings = board
            .packets
            .iter()
            .filter(|p| p.id == 7 && p.op == opcode::PING)
            .count();
        assert_eq!(pings, usize::from(cfg.startup_attempts));
    }
}
