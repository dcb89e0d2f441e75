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
//! * [`supervisor`]: last-good hold, fall/overrun/device-loss stop sequence, target filter.
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
pub mod imu;
pub mod log;
pub mod supervisor;

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

/// Run-time configuration shared by the boards and the control loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// Control tick period, µs.
    pub tick_period_us: u32,
    /// Servo bus baud rate, bit/s.
    pub bus_baud: u32,
    /// Servo Return Delay Time, µs (modelled by the QEMU board's clock).
    pub return_delay_us: u32,
    /// Watchdog timeout once walking, ms.
    pub watchdog_ms: u32,
    /// Supervisor limits.
    pub supervisor: supervisor::SupervisorConfig,
    /// Low-pass cutoff of the φ̈ filter, Hz.
    pub imu_cutoff_hz: f32,
}

impl Config {
    /// Defaults: 1 kHz tick, 1 Mbps bus, Return Delay Time 0, 50 ms watchdog.
    pub const fn default_config() -> Self {
        Config {
            tick_period_us: 1_000,
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
        }
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
