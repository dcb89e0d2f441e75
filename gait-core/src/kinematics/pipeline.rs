//! From a gait sample to the 12 joint targets: pelvis = the CoM point at height z_c (upright,
//! heading = mean of the feet's headings), both feet from the sample, then the analytic leg IK
//! of [`crate::kinematics::leg`]. The data flows one way: plan → ZMP → CoM → feet → IK → targets.

use crate::kinematics::leg::{LegKinematics, LegsIkReport, Pose};
use crate::maths::real::Real;
use crate::trajectory::sampler::GaitSample;
use crate::trajectory::swing::{wrap_pi, FootSample};

/// The pelvis pose of a sample: (com_x, com_y, z_c), level, heading between the feet.
pub fn pelvis_pose<R: Real>(sample: &GaitSample<R>) -> Pose<R> {
    let [l, r] = sample.feet;
    let yaw = l.yaw + wrap_pi(r.yaw - l.yaw) * R::of(0.5);
    Pose::level(sample.com[0], sample.com[1], sample.com[2], yaw)
}

/// A foot's pose for the IK: sole flat, at the sample's position and heading.
pub fn foot_pose<R: Real>(f: &FootSample<R>) -> Pose<R> {
    Pose::level(f.x, f.y, f.z, f.yaw)
}

/// The 12 joint targets (left leg then right leg, joint order of the robot description) of a
/// sample, and what the IK had to clamp.
pub fn joint_targets<R: Real>(
    kin: &LegKinematics<R>,
    sample: &GaitSample<R>,
) -> ([R; 12], LegsIkReport<R>) {
    let pelvis = pelvis_pose(sample);
    kin.legs_ik(
        &pelvis,
        &foot_pose(&sample.feet[0]),
        &foot_pose(&sample.feet[1]),
    )
}
