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
        };
        f.write_str(s)
    }
}
