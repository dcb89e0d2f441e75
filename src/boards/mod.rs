//! Board support: one module per board, compiled only for the bare-metal ARM target with its
//! feature (`board-qemu` → [`qemu_mps2`], `board-opencr` → [`opencr`]).

#[cfg(feature = "board-opencr")]
pub mod opencr;
#[cfg(feature = "board-qemu")]
pub mod qemu_mps2;
#[cfg(feature = "board-qemu")]
pub mod tick_cost;
