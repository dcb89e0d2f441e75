//! What the robot measures of its walk: the ZMP from the foot force sensors and its tracking
//! error ([`zmp`]), the support polygons under the feet ([`support`]), and where the feet
//! really stand from the servos' positions ([`odometry`]), how stiff the leg servos are
//! ([`stiffness`]).

pub mod odometry;
pub mod stiffness;
pub mod support;
pub mod zmp;
