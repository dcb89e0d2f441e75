//! walker-contract: what the firmware and the host tools must agree on, each fact once.
//!
//! * [`bus_map`]: device IDs, joint order and names, the ONE joint-angle ↔ servo-tick map;
//! * [`command_port`]: the command port (the firmware as a Dynamixel device: control table, packet handling);
//! * [`codes`]: stop reasons, fault kinds and exit codes with explicit numeric values;
//! * [`config`]: the firmware's run-time configuration;
//! * [`lockstep`]: the lock-step protocol of the QEMU board and the simulator;
//! * [`params`]: the run-time parameter table (one declaration per key), its parser and the
//!   docs' table;
//! * [`param_store`]: the saved parameters (two CRC-checked copies in a board's store);
//! * [`record`]: the ZMP-response log's wire format, its writer and its decoder.
//!
//! `no_std`, allocation-free and panic-free (no unwrap, expect or unchecked indexing outside
//! tests); `std` only for its own tests.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![cfg_attr(
    not(test),
    deny(
        clippy::indexing_slicing,
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic
    )
)]

pub mod bus_map;
pub mod codes;
pub mod command_port;
pub mod config;
pub mod footstep_log;
pub mod lockstep;
pub mod mpu9250;
pub mod param_store;
pub mod params;
pub mod record;

pub use codes::{ExitCode, FaultKind, StopCode, StopReason};
pub use config::Config;
