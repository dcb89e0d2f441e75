//! The two kinds of correction a controller chains around the IK, and the gait-core features
//! that are one:
//!
//! ```text
//!   gait sample ──▶ SampleCorrection… ──▶ IK ──▶ JointCorrection… ──▶ joint targets
//!                   (catching step,              (compliance feed-forward, gyro damping,
//!                    stabilizer, foot force        swing sole levelling, deflection
//!                    difference control)           feedback)
//! ```
//!
//! A [`SampleCorrection`] changes what the IK is asked for ([`IkCommand`]: the samples, the
//! commanded CoM's shift δ, the soles' heights); a [`JointCorrection`] adds to the 12 joint
//! targets the IK gave. Both read this tick's [`Measured`] values; each chain's order is the
//! controller's, stated once where it runs them. Static dispatch: a chain is a fixed list of
//! concrete types, so a correction that is off costs its `is_on` test.

use crate::balance::{FootForceControl, FootForceState, GyroFeedback};
use crate::compliance::{Compliance, LoadModel};
use crate::gait::SupportCache;
use crate::robot::{Robot, LEG_JOINTS};
use crate::sampler::{GaitSample, SupportPhase};
use crate::stabilizer::{Stabilizer, StabilizerInput};

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

/// What the IK is asked for this tick.
#[derive(Debug)]
pub struct IkCommand<'a> {
    /// The present sample (the reference of the log and of the next tick's measurements).
    pub present: &'a mut GaitSample<f32>,
    /// The sample the IK takes when it is not the present one (a servo lead), else `None`.
    pub ahead: Option<&'a mut GaitSample<f32>>,
    /// Shift δ of the commanded CoM (x, y), m.
    pub com_shift: [f32; 2],
    /// Heights added to the left and right sole of the IK's sample, m.
    pub sole_dz: [f32; 2],
}

/// A correction of the gait sample before the IK.
pub trait SampleCorrection {
    /// Updates from `measured` and corrects `cmd`.
    fn correct_sample(&mut self, measured: &Measured<'_>, cmd: &mut IkCommand<'_>);
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

/// The feedback stabilizer as a sample correction: δ from the measured ZMP's error against
/// the previous sample's reference, inside that sample's support polygon (cached).
#[derive(Clone, Debug)]
pub struct StabilizerCorrection<'r> {
    /// The stabilizer (gait-core [`crate::stabilizer`]).
    pub stabilizer: Stabilizer<f32>,
    on: bool,
    support: SupportCache,
    robot: &'r Robot,
}

impl<'r> StabilizerCorrection<'r> {
    /// `stabilizer` for `robot`; `on` = false leaves δ at 0 and the state untouched.
    pub fn new(stabilizer: Stabilizer<f32>, on: bool, robot: &'r Robot) -> Self {
        StabilizerCorrection {
            stabilizer,
            on,
            support: SupportCache::default(),
            robot,
        }
    }
}

impl SampleCorrection for StabilizerCorrection<'_> {
    fn correct_sample(&mut self, m: &Measured<'_>, cmd: &mut IkCommand<'_>) {
        if !self.on {
            return;
        }
        cmd.com_shift = self.stabilizer.update(&StabilizerInput {
            zmp_ref: m.previous.zmp,
            zmp_meas: m.zmp,
            gyro: m.gyro,
            support: self.support.get(self.robot, m.previous),
        });
    }
}

/// The foot force difference control (gait-core [`crate::balance`] F1–F4) as a sample
/// correction: the soles' heights from the loads answering the previous sample.
#[derive(Clone, Copy, Debug)]
pub struct FootForceCorrection {
    /// Gains and limits.
    pub control: FootForceControl,
    /// Its state Δz.
    pub state: FootForceState,
    dt_s: f32,
}

impl FootForceCorrection {
    /// `control` at ticks of `dt_s` seconds, Δz = 0.
    pub fn new(control: FootForceControl, dt_s: f32) -> Self {
        FootForceCorrection {
            control,
            state: FootForceState::default(),
            dt_s,
        }
    }
}

impl SampleCorrection for FootForceCorrection {
    fn correct_sample(&mut self, m: &Measured<'_>, cmd: &mut IkCommand<'_>) {
        let [pl, pr] = &m.previous.feet;
        let dz = self.state.update(
            &self.control,
            m.previous.zmp,
            [[pl.x, pl.y], [pr.x, pr.y]],
            m.loads,
            m.previous.phase,
            self.dt_s,
        );
        if self.state.dz != 0.0 {
            cmd.sole_dz = dz;
        }
    }
}

/// The servos' predicted sag under the gait's loads, fed forward (gait-core
/// [`crate::compliance`] C3) as a joint correction.
#[derive(Clone, Debug)]
pub struct SagFeedForward {
    /// The loads' model.
    pub load: LoadModel,
    /// Gains (off: nothing added).
    pub compliance: Compliance,
}

impl JointCorrection for SagFeedForward {
    fn correct_joints(
        &mut self,
        _: &Measured<'_>,
        input: &JointInput<'_>,
        q: &mut [f32; LEG_JOINTS],
    ) {
        self.load
            .apply(&self.compliance, q, input.loaded, input.com_shift);
    }
}

impl JointCorrection for GyroFeedback {
    fn correct_joints(
        &mut self,
        m: &Measured<'_>,
        input: &JointInput<'_>,
        q: &mut [f32; LEG_JOINTS],
    ) {
        self.apply(q, input.phase, m.gyro);
    }
}
