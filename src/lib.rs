//! walker-firmware: the board-agnostic logic of the walking controller.
//!
//! `no_std` on the robot, `std` only for the host unit tests
//! (`cargo test --target host-tuple -p walker-firmware --lib`). What the host must agree on (bus
//! map, parameters, log records, codes) is in `walker-contract`, re-exported here. The boards ([`boards`]) exist only for the bare-metal
//! ARM target with their feature; the binaries in `src/bin/` wire one board to this library.
//!
//! Modules:
//! * [`board`]: the traits a board provides (servo bus, clock, tick, log sink, watchdog, exit);
//! * [`record`] (`walker-contract`): the ZMP-response log's wire format and its writer;
//! * [`imu`]: φ̈ and τ = J·φ̈ from the gyro, tilt from the accelerometer;
//! * [`supervisor`]: last-good hold, fall/overrun/device-loss stop sequence, target filter;
//! * [`bus`]: the Dynamixel master (`dxl`) over a board's servo bus and clock;
//! * [`startup`]: bus probe, Return Delay Time, present pose, torque on, smooth move to the
//!   initial pose;
//! * [`control`]: the walking loop (sensors → supervisor → gait → IK → servos → log) and the
//!   exit codes;
//! * `fake_robot` (feature `fake-robot`, and in the host tests): the one fake robot of the
//!   host tests, the bench and the on-target tests;
//! * [`params`] (`walker-contract`): `key=value` overrides of [`Config`] (the QEMU command
//!   line), one table for the firmware, the host and the docs.
#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]

#[cfg(any(
    all(feature = "board-qemu", feature = "board-opencr"),
    all(feature = "board-qemu", feature = "board-opencm"),
    all(feature = "board-opencr", feature = "board-opencm")
))]
compile_error!(
    "features `board-qemu`, `board-opencr` and `board-opencm` are exclusive: build with \
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

/// A firmware binary's `main` on the host (workspace-wide `cargo test`/`clippy --all-targets`):
/// a stub that prints `msg` (where the firmware runs). Nothing on the robot's target.
#[macro_export]
macro_rules! host_stub {
    ($msg:literal) => {
        /// On the host (workspace-wide `cargo test`/`clippy --all-targets`) this binary is a stub.
        #[cfg(not(all(target_arch = "arm", target_os = "none")))]
        fn main() {
            eprintln!($msg);
        }
    };
}

pub mod board;
pub mod bus;
pub mod control;
pub mod flash_store;
pub mod imu;
pub mod monitor;
pub mod mpu9250;
pub mod plausible;
pub mod rx_ring;
pub mod startup;
pub mod supervisor;

pub use walker_contract::bus_map;
pub use walker_contract::config::{self, Config};
pub use walker_contract::params;
pub use walker_contract::record;
pub use walker_contract::ExitCode;

#[cfg(any(test, feature = "fake-robot"))]
pub mod fake_robot;

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

/// The walk of a firmware binary once its board is up: logs the build and the configuration,
/// runs [`control::run`] (start-up, walk, stop) — with [`Config::wait_enable`]
/// [`control::run_on_enable`] (each run on the operator's enable) — and logs how it ended;
/// the (last) run's end.
pub fn run_walk<B: board::Board>(board: &mut B, cfg: &mut Config) -> control::RunEnd {
    fw_log!(
        info,
        "walker-firmware {=str} on {=str}: tick {=u32} us, bus {=u32} baud, model {=str}, {=usize} steps",
        env!("CARGO_PKG_VERSION"),
        B::NAME,
        cfg.tick_period_us,
        cfg.bus_baud,
        cfg.model.name(),
        cfg.walk.steps
    );
    let end = if cfg.wait_enable {
        control::run_on_enable(board, cfg)
    } else {
        control::run(board, cfg)
    };
    fw_log!(
        info,
        "run ended at t = {=u64} us: exit code {=i32}",
        board.now_us(),
        end.exit_code()
    );
    end
}

/// The start-up record for `board` (the bus is not probed in this phase: `probed = false`).
pub fn startup_record<B: board::Board>(
    board: &B,
    cfg: &Config,
    missing: Option<&[u8]>,
) -> record::Record {
    let mut list = heapless::Vec::new();
    if let Some(m) = missing {
        for &id in m.iter().take(record::MAX_MISSING) {
            // Cannot fail: at most MAX_MISSING ids are taken.
            let _ = list.push(id);
        }
    }
    record::Record::Startup(record::StartupRecord {
        seq: 0,
        time_us: board.now_us() as u32,
        board: B::ID,
        fw: FW_VERSION,
        tick_period_us: cfg.tick_period_us,
        bus_baud: board.baud(),
        device_count: bus_map::device_ids(&cfg.robot.bus).len() as u8,
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
}
