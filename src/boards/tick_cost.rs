//! Instructions per control tick measured by `scripts/bench.sh` (generated: the script
//! rewrites this file after each run; do not edit by hand).
//!
//! The firmware's control loop (`control::run`, default configuration: TLIPFM, f32 — or the
//! fixed-point path where named —, paper pipeline, stabilizer off) on the bench's emulated
//! bus, QEMU `-icount shift=0`, per walking tick: worst case and average over the Table 2
//! walk. The QEMU board charges the worst case
//! as its compute time per tick (see [`super::qemu_mps2::compute_ns`]).

/// Worst-case instructions per control tick, hard-float build (Cortex-M7/M4F, mps2-an500).
pub const TICK_INSTRUCTIONS_MAX_FPU: u32 = 29160;
/// Average instructions per control tick, hard-float build (for reference).
pub const TICK_INSTRUCTIONS_AVG_FPU: u32 = 20805;
/// Worst-case instructions per control tick, soft-float build (Cortex-M3, mps2-an385).
pub const TICK_INSTRUCTIONS_MAX_SOFT: u32 = 243640;
/// Average instructions per control tick, soft-float build (for reference).
pub const TICK_INSTRUCTIONS_AVG_SOFT: u32 = 179092;
/// Worst-case instructions per control tick, Cortex-M3 build with the fixed-point path
/// (`fixed-gait`, `math=fixed`; mps2-an385).
pub const TICK_INSTRUCTIONS_MAX_FIXED_SOFT: u32 = 34880;
/// Average instructions per control tick, Cortex-M3 fixed-point path (for reference).
pub const TICK_INSTRUCTIONS_AVG_FIXED_SOFT: u32 = 24893;
