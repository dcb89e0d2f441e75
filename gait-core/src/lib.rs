//! gait-core: the walking trajectory generator of seed 000 (Wong et al. 2020, TLIPFM) and
//! seed 001 (Erbatur et al. 2009), `no_std`, allocation-free, for the servo loop.
#![no_std]
// One audited exception: the FPU's square root (`fastmath::vfp`, inline `VSQRT.F32`).
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod error;
pub mod fastmath;
pub mod kinematics;
pub mod real;
pub mod robot;

pub use error::GaitError;
pub use real::Real;
pub use robot::{Robot, Side};
pub mod com;
pub mod command;
pub mod fourier;
pub mod fourier_walk;
pub mod measured;
pub mod model;
pub mod online;
pub mod plan;
pub mod sampler;
pub mod support;
pub mod swing;
pub mod zmp;

pub use model::{Model, ModelKind};
pub use plan::{Footstep, ForwardWalk, GaitParams, Place, Plan};
pub use sampler::{CurrentStep, GaitSample, Sampler, StepPhase, SupportPhase};
pub mod balance;
pub mod catching;
pub mod compliance;
pub mod correction;
pub mod deflection;
pub mod fixed_ik;
pub mod fixed_point;
pub mod gait;
pub mod odometry;
pub mod pipeline;
pub mod stabilizer;
pub mod wholebody;
