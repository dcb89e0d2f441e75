//! walker-firmware: the board-agnostic logic of the walking controller.
//!
//! `no_std` on the robot, `std` only for the host unit tests
//! (`cargo test --target host-tuple -p walker-firmware --lib`). Host tools depend on this crate
//! to decode the log ([`log::Decoder`]). The boards ([`boards`]) exist only for the bare-metal
//! ARM target with their feature; the binaries in `src/bin/` wire one board to this library.
//!
//! Modules:
//! * [`board`]: the traits a board provides (servo bus, clock, tick, log sink, watchdog, exit);
//! * [`log`]: the ZMP-response log records, their framing and the streaming decoder;
//! * [`imu`]: φ̈ and τ = J·φ̈ from the gyro, tilt from the accelerometer;
//! * [`supervisor`]: last-good hold, fall/overrun/device-loss stop sequence, target filter;
//! * [`bus`]: the Dynamixel master (`dxl`) over a board's servo bus and clock;
//! * [`startup`]: bus probe, Return Delay Time, present pose, torque on, smooth move to the
//!   initial pose;
//! * [`control`]: the walking loop (sensors → supervisor → gait → IK → servos → log) and the
//!   exit codes;
//! * [`params`]: `key=value` overrides of [`Config`] (the QEMU command line).
#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]

#[cfg(all(feature = "board-qemu", feature = "board-opencr"))]
compile_error!(
    "features `board-qemu` and `board-opencr` are exclusive: build with \
     `--no-default-features --features board-qemu` for QEMU"
);

/// Debug logging that is defmt on the robot and nothing on the host (where there is no defmt
/// global logger). Usage: `fw_log!(info, "x = {}", x)`; levels trace, debug, info, warn, error.
/// On the host the arguments are still evaluated by reference (no unused-variable warnings).
#[macro_export]
macro_rules! fw_log {
    ($level:ident, $fmt:literal $(, $arg:expr)* $(,)?) => {{
        #[cfg(all(target_arch = "arm", target_os = "none"))]
        {
            defmt::$level!($fmt $(, $arg)*);
        }
        #[cfg(not(all(target_arch = "arm", target_os = "none")))]
        {
            $( let _ = &$arg; )*
        }
    }};
}

pub mod board;
pub mod bus;
pub mod control;
pub mod imu;
pub mod log;
pub mod params;
pub mod startup;
pub mod supervisor;

#[cfg(test)]
mod testkit;

#[cfg(all(target_arch = "arm", target_os = "none"))]
pub mod boards;

/// Firmware version reported in the start-up record (from Cargo.toml).
pub const FW_VERSION: [u8; 3] = [
    parse_u8(env!("CARGO_PKG_VERSION_MAJOR")),
    parse_u8(env!("CARGO_PKG_VERSION_MINOR")),
    parse_u8(env!("CARGO_PKG_VERSION_PATCH")),
];

const fn parse_u8(s: &str) -> u8 {
    let b = s.as_bytes();
    let mut v: u32 = 0;
    let mut i = 0;
    while i < b.len() {
        let d = b[i];
        if d >= b'0' && d <= b'9' {
            v = v * 10 + (d - b'0') as u32;
        }
        i += 1;
    }
    if v > 255 {
        255
    } else {
        v as u8
    }
}

/// Run-time configuration shared by the boards and the control loop. On QEMU every field
/// named in [`params::KEYS`] can be overridden from the semihosting command line; on the real
/// board the configuration is compiled in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// Control tick period = gait sample time dt, µs (1000 ..= 20000).
    pub tick_period_us: u32,
    /// Servo bus baud rate, bit/s.
    pub bus_baud: u32,
    /// Servo Return Delay Time, µs (modelled by the QEMU board's clock).
    pub return_delay_us: u32,
    /// Watchdog timeout once the control loop runs, ms.
    pub watchdog_ms: u32,
    /// Supervisor limits.
    pub supervisor: supervisor::SupervisorConfig,
    /// Low-pass cutoff of the φ̈ filter, Hz.
    pub imu_cutoff_hz: f32,
    /// Pendulum model of the gait.
    pub model: gait_core::ModelKind,
    /// The forward walk (seed 000 Table 2 by default).
    pub walk: gait_core::ForwardWalk,
    /// Use seed 001's continuous ZMP instead of the natural ZMP (d1, d2, a).
    pub zmp_continuous: bool,
    /// Half travel b of the continuous ZMP, m (`None`: the walk's `a`).
    pub zmp_b: Option<f64>,
    /// Use seed 001's sinusoid swing (height h_z) instead of the cycloid (h_z, w_y).
    pub swing_sinusoid: bool,
    /// Reply timeout of the Dynamixel master, µs (per expected status packet).
    pub reply_timeout_us: u32,
    /// Longest single wait for one reply byte, µs (see [`bus`]).
    pub read_poll_us: u32,
    /// Attempts per start-up transaction (ping, Return Delay Time, positions, torque).
    pub startup_attempts: u8,
    /// Duration of the smooth move from the present pose to the initial pose, µs.
    pub ramp_us: u32,
    /// Time the final pose is held after the plan before torque off, µs.
    pub final_hold_us: u32,
    /// Smallest load of a foot that counts for the measured ZMP, N.
    pub min_load_n: f32,
    /// A foot board missing at start-up stops the robot (`true`) or is tolerated (`false`:
    /// the walk runs with the other foot's forces only; see [`control`]).
    pub feet_required: bool,
    /// Modelled compute time per tick on the QEMU board, µs (ignored by real boards).
    pub compute_us: u32,
    /// How the pelvis is placed: the paper's pipeline or whole-body compensation.
    pub compensation: control::Compensation,
    /// The ZMP/DCM feedback stabilizer is on.
    pub stabilizer_on: bool,
    /// The stabilizer's gains and limits.
    pub stabilizer: gait_core::stabilizer::StabilizerConfig,
    /// Gyro damping through the ankles and hips of the legs on the ground
    /// ([`gait_core::balance`]).
    pub gyro_feedback: gait_core::balance::GyroFeedback,
    /// What start-up does when the plan needs joints faster than the servos.
    pub feasibility: control::Feasibility,
    /// Fault injection: replace joint 0's target by NaN at this walk tick.
    pub fault_nan_tick: Option<u32>,
    /// Fault injection: request a stop at this walk tick.
    pub stop_at_tick: Option<u32>,
}

impl Config {
    /// Defaults: 200 Hz tick, 1 Mbps bus, Return Delay Time 0, 50 ms watchdog, TLIPFM,
    /// Table 2 walk, 1 ms reply timeout, 1.5 s ramp, 1 s final hold, 2 N minimum load, no
    /// compensation, stabilizer off, servo-speed feasibility by stretching the timing.
    pub const fn default_config() -> Self {
        Config {
            tick_period_us: 5_000,
            bus_baud: 1_000_000,
            return_delay_us: 0,
            watchdog_ms: 50,
            supervisor: supervisor::SupervisorConfig {
                hold_ticks: 10,
                tilt_limit_rad: 0.6,
                stopping_ticks: 200,
                overrun_burst: 5,
            },
            imu_cutoff_hz: imu::DEFAULT_CUTOFF_HZ,
            model: gait_core::ModelKind::Tlipfm,
            walk: gait_core::ForwardWalk::table2(),
            zmp_continuous: false,
            zmp_b: None,
            swing_sinusoid: false,
            reply_timeout_us: 1_000,
            read_poll_us: bus::DEFAULT_READ_POLL_US,
            startup_attempts: 8,
            ramp_us: 1_500_000,
            final_hold_us: 1_000_000,
            min_load_n: 2.0,
            feet_required: true,
            compute_us: 150,
            compensation: control::Compensation::None,
            stabilizer_on: false,
            stabilizer: gait_core::stabilizer::StabilizerConfig::default_gains(),
            gyro_feedback: gait_core::balance::GyroFeedback::DEFAULT,
            feasibility: control::Feasibility::Stretch,
            fault_nan_tick: None,
            stop_at_tick: None,
        }
    }

    /// The tick period in seconds (the gait's dt).
    pub fn dt_s(&self) -> f64 {
        f64::from(self.tick_period_us) * 1e-6
    }

    /// Number of whole ticks covering `us` microseconds (at least 1).
    pub fn ticks_for_us(&self, us: u32) -> u32 {
        us.div_ceil(self.tick_period_us.max(1)).max(1)
    }
}

impl Default for Config {
    fn default() -> Self {
        Self::default_config()
    }
}

/// Dynamixel ids on the reference robot's bus: legs 1–12, foot sensor boards 111/112, IMU 200.
pub const DEVICE_IDS: [u8; 15] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 111, 112, 200];

/// The start-up record for `board` (the bus is not probed in this phase: `probed = false`).
pub fn startup_record<B: board::Board>(
    board: &B,
    cfg: &Config,
    missing: Option<&[u8]>,
) -> log::Record {
    let mut list = heapless::Vec::new();
    if let Some(m) = missing {
        for &id in m.iter().take(log::MAX_MISSING) {
            // Cannot fail: at most MAX_MISSING ids are taken.
            let _ = list.push(id);
        }
    }
    log::Record::Startup(log::StartupRecord {
        seq: 0,
        time_us: board.now_us() as u32,
        board: B::ID,
        fw: FW_VERSION,
        tick_period_us: cfg.tick_period_us,
        bus_baud: board.baud(),
        device_count: DEVICE_IDS.len() as u8,
        probed: missing.is_some(),
        missing: list,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_parses() {
        assert_eq!(FW_VERSION, [0, 1, 0]);
        assert_eq!(parse_u8("300"), 255);
    }

    #[test]
    fn log_macro_compiles_on_host() {
        let x = 3;
        fw_log!(info, "x = {}", x);
        fw_log!(warn, "plain");
    }

    #[test]
    fn config_matches_supervisor_default() {
        assert_eq!(
            Config::default().supervisor,
            supervisor::SupervisorConfig::default()
        );
    }
}
