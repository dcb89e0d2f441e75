//! The typed errors of gait-core: every bad parameter has its own variant.

/// Why a model, plan, sampler or kinematics request was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GaitError {
    /// A parameter was NaN or infinite.
    NonFinite,
    /// A mass was negative, or the upper-body mass not positive.
    NonPositiveMass,
    /// A length or height was not positive (e.g. z_c ≤ 0).
    NonPositiveLength,
    /// A period or duration was not positive.
    NonPositivePeriod,
    /// Another parameter that must be positive was not (g, servo speed, dt, …).
    NonPositiveParameter,
    /// The support-phase switch times are out of order: need 0 < t1 < t2 < T.
    BadPhaseTimes,
    /// A joint limit with min ≥ max.
    BadJointLimit,
    /// The ZMP offsets do not fit on the sole (a ≥ half the sole length, or negative).
    ZmpOffsetOffSole,
    /// A footstep is beyond the leg's reach (too long, too wide, crossing, or turned too far).
    StepOutOfReach,
    /// More footsteps than the plan's capacity.
    CapacityExceeded,
    /// The plan has no steps where one is needed.
    EmptyPlan,
    /// The servo rate is outside 1/1000 s ≤ dt ≤ 1/50 s.
    BadSampleTime,
    /// The Fourier solver needs at least one and at most its capacity of terms.
    BadTermCount,
    /// A value does not fit the fixed-point format.
    FixedPointOverflow,
    /// A period or standing time is longer than the sampler's 4 s segment limit.
    PeriodTooLong,
    /// S_first must be −1 (left foot first) or +1 (right foot first).
    BadStartFoot,
    /// The walk has reached its lead-out: no more steps can be appended.
    WalkEnded,
    /// The requested method is not built in (a cargo feature is off).
    NotBuiltIn,
    /// The Fourier CoM needs a straight forward walk of at least 5 steps, in f32 or f64.
    NotPeriodicWalk,
    /// The servo-speed check's dry run would exceed its work budget (the plan is too long to
    /// be checked at start-up: fewer steps, shorter phases or a longer dt).
    DryRunTooLong,
    /// The robot description's bus or mounting is inconsistent (an ID used twice or out of
    /// range, a mounting sign other than ±1, a zero baud rate).
    BadRobotDescription,
}

impl GaitError {
    /// Every error, in the order of its code.
    pub const ALL: [GaitError; 21] = [
        GaitError::NonFinite,
        GaitError::NonPositiveMass,
        GaitError::NonPositiveLength,
        GaitError::NonPositivePeriod,
        GaitError::NonPositiveParameter,
        GaitError::BadPhaseTimes,
        GaitError::BadJointLimit,
        GaitError::ZmpOffsetOffSole,
        GaitError::StepOutOfReach,
        GaitError::CapacityExceeded,
        GaitError::EmptyPlan,
        GaitError::BadSampleTime,
        GaitError::BadTermCount,
        GaitError::FixedPointOverflow,
        GaitError::PeriodTooLong,
        GaitError::BadStartFoot,
        GaitError::WalkEnded,
        GaitError::NotBuiltIn,
        GaitError::NotPeriodicWalk,
        GaitError::DryRunTooLong,
        GaitError::BadRobotDescription,
    ];

    /// The wire code (the firmware's `ConfigRejected` fault record carries it), one explicit
    /// value per variant: reordering the variants changes nothing on the wire.
    pub const fn code(self) -> u8 {
        match self {
            GaitError::NonFinite => 0,
            GaitError::NonPositiveMass => 1,
            GaitError::NonPositiveLength => 2,
            GaitError::NonPositivePeriod => 3,
            GaitError::NonPositiveParameter => 4,
            GaitError::BadPhaseTimes => 5,
            GaitError::BadJointLimit => 6,
            GaitError::ZmpOffsetOffSole => 7,
            GaitError::StepOutOfReach => 8,
            GaitError::CapacityExceeded => 9,
            GaitError::EmptyPlan => 10,
            GaitError::BadSampleTime => 11,
            GaitError::BadTermCount => 12,
            GaitError::FixedPointOverflow => 13,
            GaitError::PeriodTooLong => 14,
            GaitError::BadStartFoot => 15,
            GaitError::WalkEnded => 16,
            GaitError::NotBuiltIn => 17,
            GaitError::NotPeriodicWalk => 18,
            GaitError::DryRunTooLong => 19,
            GaitError::BadRobotDescription => 20,
        }
    }
}

impl TryFrom<u8> for GaitError {
    type Error = u8;
    /// The error of a wire code; the unknown code itself otherwise.
    fn try_from(c: u8) -> Result<Self, u8> {
        Ok(match c {
            0 => GaitError::NonFinite,
            1 => GaitError::NonPositiveMass,
            2 => GaitError::NonPositiveLength,
            3 => GaitError::NonPositivePeriod,
            4 => GaitError::NonPositiveParameter,
            5 => GaitError::BadPhaseTimes,
            6 => GaitError::BadJointLimit,
            7 => GaitError::ZmpOffsetOffSole,
            8 => GaitError::StepOutOfReach,
            9 => GaitError::CapacityExceeded,
            10 => GaitError::EmptyPlan,
            11 => GaitError::BadSampleTime,
            12 => GaitError::BadTermCount,
            13 => GaitError::FixedPointOverflow,
            14 => GaitError::PeriodTooLong,
            15 => GaitError::BadStartFoot,
            16 => GaitError::WalkEnded,
            17 => GaitError::NotBuiltIn,
            18 => GaitError::NotPeriodicWalk,
            19 => GaitError::DryRunTooLong,
            20 => GaitError::BadRobotDescription,
            other => return Err(other),
        })
    }
}

impl core::fmt::Display for GaitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let s = match self {
            GaitError::NonFinite => "a parameter is not finite",
            GaitError::NonPositiveMass => "a mass is not positive",
            GaitError::NonPositiveLength => "a length or height is not positive",
            GaitError::NonPositivePeriod => "a period is not positive",
            GaitError::NonPositiveParameter => "a parameter that must be positive is not",
            GaitError::BadPhaseTimes => "phase times must satisfy 0 < t1 < t2 < T",
            GaitError::BadJointLimit => "a joint limit has min >= max",
            GaitError::ZmpOffsetOffSole => "the ZMP offset leaves the sole",
            GaitError::StepOutOfReach => "a footstep is beyond the leg's reach",
            GaitError::CapacityExceeded => "more footsteps than the plan's capacity",
            GaitError::EmptyPlan => "the plan has no steps",
            GaitError::BadSampleTime => "dt must be within 1/1000 s ..= 1/50 s",
            GaitError::BadTermCount => "bad number of Fourier terms",
            GaitError::FixedPointOverflow => "value out of the fixed-point range",
            GaitError::PeriodTooLong => "a period or standing time is longer than 4 s",
            GaitError::BadStartFoot => "S_first must be -1 or +1",
            GaitError::WalkEnded => "the walk has ended; no more steps can be appended",
            GaitError::NotBuiltIn => "the requested method is not built in (cargo feature off)",
            GaitError::NotPeriodicWalk => {
                "the Fourier CoM needs a straight forward walk of at least 5 steps (f32, not fixed point)"
            }
            GaitError::DryRunTooLong => {
                "the plan is too long for the start-up servo-speed check's work budget"
            }
            GaitError::BadRobotDescription => {
                "the robot description's bus IDs, mounting signs or baud rate are inconsistent"
            }
        };
        f.write_str(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_round_trips() {
        for (i, e) in GaitError::ALL.iter().enumerate() {
            assert_eq!(usize::from(e.code()), i);
            assert_eq!(GaitError::try_from(e.code()), Ok(*e));
        }
        assert_eq!(GaitError::try_from(200), Err(200));
    }
}
