//! The walking trajectory, from footsteps to one sample per tick: the footstep plan, the ZMP
//! reference, the CoM (exact piecewise solution or Fourier series), the swing feet, the
//! streaming sampler, and the online walk on velocity commands.

pub mod com;
pub mod command;
pub mod fixed_sampler;
pub mod fourier;
pub mod fourier_walk;
pub mod online;
pub mod plan;
pub mod sampler;
pub mod swing;
pub mod zmp;
