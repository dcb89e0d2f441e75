//! The numbers of gait-core: the scalar type [`real::Real`] (`f32` on the robot, `f64` for
//! reference evaluations), the fast `f32` functions of the servo loop and the fixed-point
//! arithmetic of FPU-less cores.

pub mod fastmath;
pub mod fixed_point;
pub mod real;
