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
//!
//! # The two kinds of correction
//! ```text
//!   gait sample ──▶ SampleCorrection… ──▶ IK ──▶ JointCorrection… ──▶ joint targets
//! ```
//! A [`SampleCorrection`] changes what the IK is asked for: its [`IkOffsets`] (the commanded
//! CoM's shift δ, the soles' heights) and, while it moves them, the samples themselves (on
//! copies: the walk's own samples stay the plan's); a [`JointCorrection`] adds to the 12 joint
//! targets the IK gave. Both read this tick's [`Measured`] values; each chain's order is the
//! controller's, stated once where it runs them. Static dispatch: a chain is a fixed list of
//! concrete types, so a correction that is off costs its `is_on` test.

pub mod catch;
pub mod compliance;
pub mod deflection;
pub mod fdc;
pub mod gyro;
pub mod hold;
pub mod level;
pub mod stabilizer;

use crate::robot::LEG_JOINTS;
use crate::trajectory::sampler::{GaitSample, SupportPhase};

/// What the feedback paths measured this tick (f32; missing values `None` or NaN).
#[derive(Clone, Copy, Debug)]
pub struct Measured<'a> {
    /// The trunk's roll and pitch from the attitude filter, rad (`None`: no fresh sample).
    pub attitude: Option<[f32; 2]>,
    /// The gyro's roll and pitch rates, rad/s (`None`: missing or non-finite).
    pub gyro: Option<[f32; 2]>,
    /// Vertical load on the left and right sole, N (NaN: not measured).
    pub loads: [f32; 2],
    /// The measured ZMP, m (`None`: not available).
    pub zmp: Option<[f32; 2]>,
    /// The previous tick's present sample: the command this tick's measurements answer.
    pub previous: &'a GaitSample<f32>,
}

/// What the sample corrections add to the IK's command this tick.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IkOffsets {
    /// Shift δ of the commanded CoM (x, y), m.
    pub com_shift: [f32; 2],
    /// Heights added to the left and right sole of the IK's sample, m (0: none).
    pub sole_dz: [f32; 2],
}

/// A correction of the gait sample before the IK.
pub trait SampleCorrection {
    /// Updates from `measured` and the `present` sample as the walk gave it; adds its part to
    /// `offsets`.
    fn update(
        &mut self,
        measured: &Measured<'_>,
        present: &GaitSample<f32>,
        offsets: &mut IkOffsets,
    );

    /// Whether it moves the samples themselves this tick ([`SampleCorrection::apply`] then runs
    /// on copies of the present sample and of the one the IK takes).
    fn moves_samples(&self) -> bool {
        false
    }

    /// Moves `sample` (a copy) by this correction.
    fn apply(&self, sample: &mut GaitSample<f32>) {
        let _ = sample;
    }
}

/// What a joint correction knows of the tick besides the measurements.
#[derive(Clone, Copy, Debug)]
pub struct JointInput<'a> {
    /// The support phase of the present sample.
    pub phase: SupportPhase,
    /// The sample the IK took (its loads), after the sample corrections.
    pub loaded: &'a GaitSample<f32>,
    /// The commanded CoM's shift δ the IK took, m.
    pub com_shift: [f32; 2],
    /// The walk tick (0 at the first gait tick).
    pub walk_tick: u32,
}

/// A correction of the 12 joint targets (rad, left leg then right leg) after the IK.
pub trait JointCorrection {
    /// Adds this correction to `q`.
    fn correct_joints(
        &mut self,
        measured: &Measured<'_>,
        input: &JointInput<'_>,
        q: &mut [f32; LEG_JOINTS],
    );
}
