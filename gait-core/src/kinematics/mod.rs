//! From a gait sample to the 12 joint targets: the analytic leg kinematics in `f32`/`f64`
//! ([`leg`]) and in fixed point ([`fixed_ik`]), the sample → pelvis and feet → IK pipeline, and
//! the whole-body compensation of the CoM.

pub mod fixed_ik;
pub mod leg;
pub mod pipeline;
pub mod wholebody;
