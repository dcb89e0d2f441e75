//! gait-core: the walking trajectory generator of seed 000 (Wong et al. 2020, TLIPFM) and
//! seed 001 (Erbatur et al. 2009), `no_std`, allocation-free, for the servo loop.
//!
//! The modules follow the data of a walking tick:
//!
//! - [`maths`]: the scalar type, fast `f32` functions and the fixed-point numbers.
//! - [`robot`], [`model`], [`error`]: the robot description, the pendulum models, the errors.
//! - [`trajectory`]: plan → ZMP reference → CoM → swing feet → one sample per tick.
//! - [`kinematics`]: a sample → 12 joint targets (leg IK, whole-body compensation).
//! - [`measure`]: the measured ZMP, support polygons and leg odometry.
//! - [`feedback`]: the corrections of the sample (catching step, stabilizer, foot force
//!   difference control) and of the joints (gyro damping, sole levelling, compliance,
//!   deflection), and the clock hold.
//! - [`gait`]: the firmware's and the host tools' choices of sampler and joint pipeline.
#![no_std]
// One audited exception: the FPU's square root (`maths::fastmath::vfp`, inline `VSQRT.F32`).
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod error;
pub mod feedback;
pub mod gait;
pub mod kinematics;
pub mod maths;
pub mod measure;
pub mod model;
pub mod robot;
pub mod trajectory;

pub use error::GaitError;
pub use maths::real::Real;
pub use model::{Model, ModelKind};
pub use robot::{Robot, Side};
pub use trajectory::plan::{Footstep, ForwardWalk, GaitParams, Place, Plan};
pub use trajectory::sampler::{CurrentStep, GaitSample, Sampler, StepPhase, SupportPhase};
