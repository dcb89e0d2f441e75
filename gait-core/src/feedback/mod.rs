//! The walking feedback, one feature per module.
//!
//! Corrections of the gait sample before the IK:
//! - [`catch`]: the catching step (the swing foot's landing place and the body moved by the
//!   capture-point error); [`catch::StepAdapter`] composes it with [`level`] and [`hold`].
//! - [`stabilizer`]: the ZMP/DCM stabilizer's bounded CoM shift.
//! - [`fdc`]: foot force difference control (the soles' heights in double support).
//!
//! Corrections of the joint targets after the IK:
//! - [`compliance`]: the servos' predicted sag under the gait's loads.
//! - [`gyro`]: gyro damping of the trunk's rotation.
//! - [`level`]: the swing sole kept level.
//! - [`deflection`]: the stance leg driven to its targets from the servos' positions.
//!
//! And of the plan's clock: [`hold`], the landing that waits for the caught foot.

pub mod catch;
pub mod compliance;
pub mod deflection;
pub mod fdc;
pub mod gyro;
pub mod hold;
pub mod level;
pub mod stabilizer;
