//! Every numeric code that crosses the firmware–host boundary, each in ONE explicit table:
//! the stop reasons of the log's stop record ([`StopCode`]), the fault kinds of its fault record
//! ([`FaultKind`]) and the firmware's exit codes ([`ExitCode`]). Each variant states its code
//! once (`Variant = code` in a `wire_codes!` table; [`FaultKind`] by hand), from which `code()`
//! and `TryFrom<u8>` are generated value by value: reordering variants changes nothing on the
//! wire, and a round-trip test covers every value.
//!
//! # Exit codes (QEMU passes them to the host through semihosting)
//! | code | meaning |
//! | --- | --- |
//! | 0 | plan done |
//! | 2 | configuration rejected (bad `key=value` token, or gait-core rejected the plan) |
//! | 3 | virtual watchdog (QEMU board) |
//! | 11 | device missing at start-up (stop record `DeviceMissing`, first missing id) |
//! | 12 | device lost while running |
//! | 13 | fall (tilt beyond the limit) |
//! | 14 | overrun burst |
//! | 15 | non-finite joint target |
//! | 17 | stop requested |
//! | 18 | non-finite gait sample (CoM, ZMP, feet or the stabilizer's shift) before the IK |
//! | 19 | sensor data stale (no plausible reply from a sensor board for longer than `stale_ms`) |
//! | 21 | servo fault (Hardware Error Status, temperature, input voltage or current beyond its limit) |
//! | 22 | not walking after a reset other than power-on (brown-out, watchdog, software/panic, pin) |
//! | 24 | a leg servo lost while running (no reply to `servo_misses` monitor READs in a row) |
//! | 20 | start-up step failed after the probe (Return Delay Time, positions, torque) |
//! | 25 | the simulator is gone (QEMU board: its lock-step pipe closed) |
//! | 101 | panic |
//!
//! i.e. 10 + the stop record's reason code for supervisor stops (a finished plan is 0). Stop
//! code 10 is never used: its exit code would be start-up's 20. Stop code 13 (the command
//! deadman) is the online walk's stop to standing, not the supervisor's: no run exits with it.

/// Declares a code table once: an enum whose every variant carries its explicit wire code
/// (`Variant = code`), and from it the enum, `ALL` (every variant, in declaration order),
/// `code()` and `TryFrom<u8>` (unknown values: [`UnknownCode`]). The codes are written out value by value in the generated matches, so
/// reordering variants changes nothing on the wire.
macro_rules! wire_codes {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $($(#[$vmeta:meta])* $variant:ident = $code:literal,)+
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        #[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
        pub enum $name {
            $(
                $(#[$vmeta])*
                #[doc = ""]
                #[doc = concat!("Wire code ", stringify!($code), ".")]
                $variant,
            )+
        }

        impl $name {
            /// Every variant, in declaration order.
            pub const ALL: [$name; [$($name::$variant),+].len()] = [$($name::$variant),+];

            /// The wire code.
            pub const fn code(self) -> u8 {
                match self {
                    $($name::$variant => $code,)+
                }
            }
        }

        impl TryFrom<u8> for $name {
            type Error = $crate::codes::UnknownCode;
            fn try_from(c: u8) -> Result<Self, $crate::codes::UnknownCode> {
                Ok(match c {
                    $($code => $name::$variant,)+
                    other => return Err($crate::codes::UnknownCode(other)),
                })
            }
        }
    };
}
pub(crate) use wire_codes;

/// An unknown code (the value that could not be decoded).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub struct UnknownCode(pub u8);

wire_codes! {
    /// The reason code of a stop record.
    pub enum StopCode {
        /// A device did not answer the start-up probe (id).
        DeviceMissing = 1,
        /// A device missed more than `hold_ticks` replies in a row (id).
        DeviceLost = 2,
        /// The trunk tilted beyond the limit (value = tilt, mrad).
        Fall = 3,
        /// Too many consecutive tick overruns (value = count).
        OverrunBurst = 4,
        /// A joint target was NaN or infinite (id = joint).
        NonFiniteTarget = 5,
        /// The walking plan finished.
        PlanDone = 6,
        /// Stop requested from outside.
        Requested = 7,
        /// A gait sample (or the stabilizer's shift) was not finite before the IK (value =
        /// walk tick).
        NonFiniteSample = 8,
        /// A sensor board gave no plausible reply for longer than `stale_ms` (id = device,
        /// value = age of its last accepted sample, ms).
        SensorStale = 9,
        /// The servo monitor saw a servo beyond a limit (id = servo, value = [`ServoCheck`]
        /// code · 65536 + the reading in the check's unit). (10 is not used: see the module docs.)
        ServoFault = 11,
        /// The last reset was not a power-on: the firmware does not walk by itself (value =
        /// [`ResetCause`] code).
        NotPowerOn = 12,
        /// The command deadman: in Mode = walk, no valid command write on the command port for
        /// `deadman_ms`; the online walk stopped to standing. Not a supervisor stop: the robot
        /// stands with torque on, no stop record is written and no run ends with it; the
        /// command port's Stop Code reads it until the master writes Mode again.
        Deadman = 13,
        /// A leg servo missed `servo_misses` of the servo monitor's READs in a row (id = servo).
        ServoLost = 14,
    }
}

impl StopCode {
    /// The firmware's exit code for a run that stopped for this reason.
    pub const fn exit(self) -> ExitCode {
        match self {
            StopCode::DeviceMissing => ExitCode::DeviceMissing,
            StopCode::DeviceLost => ExitCode::DeviceLost,
            StopCode::Fall => ExitCode::Fall,
            StopCode::OverrunBurst => ExitCode::OverrunBurst,
            StopCode::NonFiniteTarget => ExitCode::NonFiniteTarget,
            StopCode::PlanDone => ExitCode::PlanDone,
            StopCode::Requested => ExitCode::Requested,
            StopCode::NonFiniteSample => ExitCode::NonFiniteSample,
            StopCode::SensorStale => ExitCode::SensorStale,
            StopCode::ServoFault => ExitCode::ServoFault,
            StopCode::NotPowerOn => ExitCode::NotPowerOn,
            StopCode::ServoLost => ExitCode::ServoLost,
            // Never a run's end (see the variant); a master that then writes Mode = torque off
            // ends the run as requested.
            StopCode::Deadman => ExitCode::Requested,
        }
    }
}

/// Why the supervisor stopped the robot (the stop record's reason with its data).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub enum StopReason {
    /// A device did not answer the start-up probe.
    DeviceMissing {
        /// Its bus id.
        id: u8,
    },
    /// A device missed more than `hold_ticks` replies in a row.
    DeviceLost {
        /// Its bus id.
        id: u8,
    },
    /// The trunk tilted beyond the limit.
    Fall {
        /// Tilt from vertical, mrad.
        tilt_mrad: u16,
    },
    /// Too many consecutive tick overruns.
    OverrunBurst {
        /// Consecutive overruns counted.
        count: u16,
    },
    /// A joint target was NaN or infinite.
    NonFiniteTarget {
        /// Joint index 0..12 (left leg then right leg).
        joint: u8,
    },
    /// The walking plan finished.
    PlanDone,
    /// Stop requested from outside (operator, host).
    Requested,
    /// A gait sample (CoM, ZMP, feet) or the stabilizer's CoM shift was NaN or infinite: it
    /// never reaches the IK (whose clamping would turn it into finite, meaningless angles).
    NonFiniteSample {
        /// Walk tick of the sample (0 = the first sample, before the ramp).
        tick: u32,
    },
    /// No plausible reply from a sensor board for longer than the staleness bound.
    SensorStale {
        /// Its bus id.
        id: u8,
        /// Age of its last accepted sample, ms (saturating).
        age_ms: u16,
    },
    /// A servo read while walking was beyond a limit.
    ServoFault {
        /// Its bus id.
        id: u8,
        /// Which check.
        check: ServoCheck,
        /// The reading, in the check's unit (see [`ServoCheck`]).
        reading: u16,
    },
    /// The last reset was not a power-on: no walk without a command.
    NotPowerOn {
        /// What reset the controller.
        cause: ResetCause,
    },
    /// A leg servo missed `servo_misses` of the servo monitor's READs in a row.
    ServoLost {
        /// Its bus id.
        id: u8,
    },
}

/// How the supervisor brings the robot down for a stop reason (docs/stops.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub enum StopGrade {
    /// Torque off at once: a fall (stiff legs would only lever it) or a servo's own hardware
    /// error (the servo has already cut its torque).
    Limp,
    /// Hold the pose, then torque off: the finished plan (it already stands; its runs are the
    /// paper's experiments, whose figures end with the final hold).
    Hold,
    /// Lower the robot to the crouch, hold, torque off: the walk cannot be trusted to reach a
    /// standstill (its samples or targets were not finite, a leg servo was lost or found limp).
    Lower,
    /// Walk to a standstill (the online walk's stop: finish the step, feet together), then
    /// lower, hold, torque off: operator stops and minor faults.
    Settle,
}

impl StopReason {
    /// The reason's code.
    pub const fn kind(&self) -> StopCode {
        match self {
            StopReason::DeviceMissing { .. } => StopCode::DeviceMissing,
            StopReason::DeviceLost { .. } => StopCode::DeviceLost,
            StopReason::Fall { .. } => StopCode::Fall,
            StopReason::OverrunBurst { .. } => StopCode::OverrunBurst,
            StopReason::NonFiniteTarget { .. } => StopCode::NonFiniteTarget,
            StopReason::PlanDone => StopCode::PlanDone,
            StopReason::Requested => StopCode::Requested,
            StopReason::NonFiniteSample { .. } => StopCode::NonFiniteSample,
            StopReason::SensorStale { .. } => StopCode::SensorStale,
            StopReason::ServoFault { .. } => StopCode::ServoFault,
            StopReason::NotPowerOn { .. } => StopCode::NotPowerOn,
            StopReason::ServoLost { .. } => StopCode::ServoLost,
        }
    }

    /// How the robot is brought down for this reason ([`StopGrade`]). Start-up's reasons
    /// (`DeviceMissing`, `NotPowerOn`) never had torque on.
    pub const fn grade(&self) -> StopGrade {
        match self {
            StopReason::Fall { .. }
            | StopReason::DeviceMissing { .. }
            | StopReason::NotPowerOn { .. }
            | StopReason::ServoFault {
                check: ServoCheck::HardwareError,
                ..
            } => StopGrade::Limp,
            StopReason::NonFiniteSample { .. }
            | StopReason::NonFiniteTarget { .. }
            | StopReason::ServoLost { .. }
            | StopReason::ServoFault {
                check: ServoCheck::TorqueOff,
                ..
            } => StopGrade::Lower,
            StopReason::PlanDone => StopGrade::Hold,
            StopReason::DeviceLost { .. }
            | StopReason::OverrunBurst { .. }
            | StopReason::Requested
            | StopReason::SensorStale { .. }
            | StopReason::ServoFault { .. } => StopGrade::Settle,
        }
    }

    /// An operator's stop (Mode = torque off): with [`crate::Config::rest`] it ends resting
    /// in the crouch with torque on instead of torque off (a limp robot does not keep a
    /// crouch); the second torque off is the operator's.
    pub const fn rests(&self) -> bool {
        matches!(self, StopReason::Requested)
    }

    /// The [`FaultKind::ServoProblem`] fault record's value for this reason: the stop code ·
    /// 2²⁴ + the low 24 bits of its value.
    pub fn servo_problem_value(&self) -> i32 {
        let (code, _, value) = self.code();
        (i32::from(code) << 24) | (value & 0x00FF_FFFF)
    }

    /// Wire form (code, id, value) used by the log's stop record ([`StopCode`] for the codes).
    pub fn code(&self) -> (u8, u8, i32) {
        let c = self.kind().code();
        match *self {
            StopReason::DeviceMissing { id }
            | StopReason::DeviceLost { id }
            | StopReason::ServoLost { id } => (c, id, 0),
            StopReason::Fall { tilt_mrad } => (c, 0, i32::from(tilt_mrad)),
            StopReason::OverrunBurst { count } => (c, 0, i32::from(count)),
            StopReason::NonFiniteTarget { joint } => (c, joint, 0),
            StopReason::PlanDone | StopReason::Requested => (c, 0, 0),
            StopReason::NonFiniteSample { tick } => (c, 0, i32::try_from(tick).unwrap_or(i32::MAX)),
            StopReason::SensorStale { id, age_ms } => (c, id, i32::from(age_ms)),
            StopReason::ServoFault { id, check, reading } => {
                (c, id, (i32::from(check.code()) << 16) | i32::from(reading))
            }
            StopReason::NotPowerOn { cause } => (c, 0, i32::from(cause.code())),
        }
    }

    /// Inverse of [`StopReason::code`]; None for an unknown code or impossible value.
    pub fn from_code(code: u8, id: u8, value: i32) -> Option<Self> {
        Some(match StopCode::try_from(code).ok()? {
            StopCode::DeviceMissing => StopReason::DeviceMissing { id },
            StopCode::DeviceLost => StopReason::DeviceLost { id },
            StopCode::Fall => StopReason::Fall {
                tilt_mrad: u16::try_from(value).ok()?,
            },
            StopCode::OverrunBurst => StopReason::OverrunBurst {
                count: u16::try_from(value).ok()?,
            },
            StopCode::NonFiniteTarget => StopReason::NonFiniteTarget { joint: id },
            StopCode::PlanDone => StopReason::PlanDone,
            StopCode::Requested => StopReason::Requested,
            StopCode::NonFiniteSample => StopReason::NonFiniteSample {
                tick: u32::try_from(value).ok()?,
            },
            StopCode::SensorStale => StopReason::SensorStale {
                id,
                age_ms: u16::try_from(value).ok()?,
            },
            StopCode::ServoFault => StopReason::ServoFault {
                id,
                check: ServoCheck::try_from(u8::try_from(value >> 16).ok()?).ok()?,
                reading: u16::try_from(value & 0xFFFF).ok()?,
            },
            StopCode::NotPowerOn => StopReason::NotPowerOn {
                cause: ResetCause::try_from(u8::try_from(value).ok()?).ok()?,
            },
            StopCode::ServoLost => StopReason::ServoLost { id },
            // No stop record carries it (the walk's stop, not the supervisor's).
            StopCode::Deadman => return None,
        })
    }
}

/// Kind of a fault event record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub enum FaultKind {
    /// 1: a device missed its reply; the firmware holds its last good value (`value` = ticks).
    DeviceHolding,
    /// 2: a held device answered again (`value` = ticks it was held).
    DeviceRecovered,
    /// 3: a target was clamped to its joint limit (`id` = joint index, `value` = mask).
    TargetClamped,
    /// 4: a non-finite IMU sample was replaced by the last good one (`value` = count).
    ImuNonFinite,
    /// 5: a run-time parameter was rejected before start-up (`id` = key index in
    /// [`crate::params::PARAMS`], 0xFF unknown key, 0xFE plan rejected by gait-core, 0xFD
    /// command line longer than the firmware's buffer; `value` = token position, or the
    /// `GaitError` code for 0xFE, or the buffer size for 0xFD).
    ConfigRejected,
    /// 6: a start-up step failed after the probe (`id` = device, `value` = step code).
    StartupFailed,
    /// 7: the step timing was stretched for the servo speed limit (`id` = worst joint index,
    /// `value` = total factor on t1, t2, T in 1/1000).
    TimingStretched,
    /// 8: the swing was lowered for the servo speed limit (`id` = worst joint index, `value` =
    /// new swing height, µm).
    SwingLowered,
    /// 9: a joint still needs more than the servo speed limit (`id` = worst joint index,
    /// `value` = its peak speed, mrad/s); the walk goes on, the servo will lag.
    SpeedLimit,
    /// 10: a sensor reply arrived but failed the plausibility check and counts as missing
    /// (`id` = device, `value` = [`SensorRejection`] code); logged at the first of a run.
    SensorRejected,
    /// 11: torque off was not confirmed by every servo after `off_attempts` rounds of
    /// broadcast Torque Enable = 0 and read-back (`id` = first unconfirmed servo, `value` =
    /// number unconfirmed); the servo power is cut anyway.
    TorqueOffUnconfirmed,
    /// 12: what reset the controller, logged at every boot (`id` = [`ResetCause`] code, `value`
    /// = the raw reset flags where the board has them: RCC_CSR bits 24..=31 on the OpenCR).
    ResetCause,
    /// 13: a panic or watchdog record found in no-init RAM at boot, from the previous run
    /// (`id` = [`CrashCode`], `value` = the last control tick index it noted).
    CrashRecord,
    /// 14: the command port accepted a command (`id` = [`CommandField`] code, `value` = the
    /// value in the register's unit: mode code, mm/s or mrad/s); logged when it changes.
    CommandReceived,
    /// 15: the online walk committed a footstep (three records per step: `id` = side (1 left,
    /// 2 right) · 16 + component (0 x, 1 y, 2 yaw), `value` = µm or µrad, world frame; before
    /// them, component 3: the heading hold's correction, µrad, if any, and components 4, 5, 6:
    /// an explicit step's travel, mm, mm, mrad); once at start `id` = 0: the online walk's step
    /// period, µs.
    Footstep,
    /// 16: the catching step or the landing hold moved the landing place of a swing foot
    /// (records at the end of that single support: `id` = side (1 left, 2 right) · 16 +
    /// component; components 0 forward and 1 leftward, trunk frame: the largest catch asked in
    /// that swing, gait-core `feedback::catch` A3–A4; component 2: the landing hold's move
    /// along the stance foot's heading, A9; `value` µm). An event of the walk, not a fault.
    CatchStep,
    /// 17: the command deadman fired: in Mode = walk no valid command write came for
    /// `deadman_ms`, the walk stops to standing (`id` 0, `value` = ms since the last valid
    /// write); the command port's Stop Code then reads [`StopCode::Deadman`].
    Deadman,
    /// 18: the servo monitor found a leg servo lost or beyond a limit (`id` = servo, `value` =
    /// the stop code (14 lost, 11 fault) · 2²⁴ + the stop record's value for it, the low 24
    /// bits); logged at the finding, whatever stop is already under way (the stop record
    /// keeps the first reason).
    ServoProblem,
    /// 19: the saved parameters at boot (`id` = [`crate::param_store::StoreOutcome`] code: 0
    /// loaded, 1 none saved, 2 corrupt, 3 refused by the parser, 4 no store on this board;
    /// `value` = the loaded slot · 2²⁴ + its sequence number); after the first start-up record
    /// of a boot with `wait_enable`.
    ParamStore,
    /// 20: a parameter of this run that differs from the firmware's default (`id` = its index
    /// in [`crate::params::PARAMS`], `value` = the f32 bits of the value as the setter takes
    /// it: the number, or the word's index); after the start-up record of every run with
    /// `wait_enable`.
    ParamValue,
    /// 21: the servo survey's result, once standing before the first step
    /// (`gait_core::measure::stiffness`): `id` 0 the leg servos' stiffness measured, `value`
    /// mN·m/rad (0: too little load to tell); `id` 1 the deflection feedback's gain it set
    /// (gait-core `feedback::deflection` D6), `value` 1/1000 s⁻¹. A notice, not a fault.
    ServoSurvey,
    /// 22: the robot lacks sensors the walk can use, logged once at start-up when it does
    /// (`id` = the sensor slots it has on the bus as bits: 0 left foot board, 1 right foot
    /// board, 2 IMU; `value` 0): without foot boards the log has no measured ZMP and no feedback
    /// from the loads, and the leg odometry times its surveys by the loads' split the ZMP
    /// reference plans; without a bus IMU no gyro feedback. A notice.
    SensorsAbsent,
    /// Other kind (code kept for forward compatibility).
    Other(u8),
}

impl FaultKind {
    /// A fault, not an event of the walk nor a notice: false for [`FaultKind::CommandReceived`],
    /// [`FaultKind::Footstep`], [`FaultKind::CatchStep`], [`FaultKind::ResetCause`] (logged at every boot),
    /// the saved parameters' notices [`FaultKind::ParamStore`] and [`FaultKind::ParamValue`], the
    /// servo survey's and the missing sensors' notices, and the
    /// start-up's plan adjustments [`FaultKind::TimingStretched`] and
    /// [`FaultKind::SwingLowered`] (the servo-speed check made the plan fit; the default plan
    /// is stretched on the reference robot, so the port's Fault Kind would read 7 from boot).
    /// [`FaultKind::SpeedLimit`] stays a fault: the walk then asks more than the servos give.
    pub const fn is_fault(self) -> bool {
        !matches!(
            self,
            Self::CommandReceived
                | Self::Footstep
                | Self::CatchStep
                | Self::ResetCause
                | Self::ParamStore
                | Self::ParamValue
                | Self::ServoSurvey
                | Self::SensorsAbsent
                | Self::TimingStretched
                | Self::SwingLowered
        )
    }

    /// Wire code.
    pub const fn code(self) -> u8 {
        match self {
            Self::DeviceHolding => 1,
            Self::DeviceRecovered => 2,
            Self::TargetClamped => 3,
            Self::ImuNonFinite => 4,
            Self::ConfigRejected => 5,
            Self::StartupFailed => 6,
            Self::TimingStretched => 7,
            Self::SwingLowered => 8,
            Self::SpeedLimit => 9,
            Self::SensorRejected => 10,
            Self::TorqueOffUnconfirmed => 11,
            Self::ResetCause => 12,
            Self::CrashRecord => 13,
            Self::CommandReceived => 14,
            Self::Footstep => 15,
            Self::CatchStep => 16,
            Self::Deadman => 17,
            Self::ServoProblem => 18,
            Self::ParamStore => 19,
            Self::ParamValue => 20,
            Self::ServoSurvey => 21,
            Self::SensorsAbsent => 22,
            Self::Other(c) => c,
        }
    }
    /// From a wire code (every code decodes: unknown ones as [`FaultKind::Other`]).
    pub const fn from_code(c: u8) -> Self {
        match c {
            1 => Self::DeviceHolding,
            2 => Self::DeviceRecovered,
            3 => Self::TargetClamped,
            4 => Self::ImuNonFinite,
            5 => Self::ConfigRejected,
            6 => Self::StartupFailed,
            7 => Self::TimingStretched,
            8 => Self::SwingLowered,
            9 => Self::SpeedLimit,
            10 => Self::SensorRejected,
            11 => Self::TorqueOffUnconfirmed,
            12 => Self::ResetCause,
            13 => Self::CrashRecord,
            14 => Self::CommandReceived,
            15 => Self::Footstep,
            16 => Self::CatchStep,
            17 => Self::Deadman,
            18 => Self::ServoProblem,
            19 => Self::ParamStore,
            20 => Self::ParamValue,
            21 => Self::ServoSurvey,
            22 => Self::SensorsAbsent,
            c => Self::Other(c),
        }
    }
}

impl From<u8> for FaultKind {
    fn from(c: u8) -> Self {
        Self::from_code(c)
    }
}

wire_codes! {
    /// Which command a `CommandReceived` fault record carries (its `id`; the code is also the
    /// field's index in the logged command).
    pub enum CommandField {
        /// The mode (value = the command port's mode code).
        Mode = 0,
        /// Forward velocity, mm/s.
        VelocityX = 1,
        /// Leftward velocity, mm/s.
        VelocityY = 2,
        /// Yaw rate, mrad/s.
        YawRate = 3,
    }
}

wire_codes! {
    /// Why a sensor reply was rejected (the `SensorRejected` fault record's `value`).
    pub enum SensorRejection {
        /// The board's sample counter did not advance since its last accepted sample.
        FrozenCounter = 1,
        /// A value is outside the sensor's range.
        OutOfRange = 2,
        /// The foot forces are not consistent with the robot's weight (total above
        /// m·g·`force_factor`, or below −0.1·m·g).
        Weight = 3,
        /// The reply data could not be read as a sample.
        Malformed = 4,
    }
}

wire_codes! {
    /// Which servo check failed (the `ServoFault` stop's reason; the reading's unit in brackets).
    pub enum ServoCheck {
        /// Hardware Error Status (70) is not 0 [its bits: 0 input voltage, 2 overheating, 3
        /// motor encoder, 4 electrical shock, 5 overload].
        HardwareError = 1,
        /// Present Temperature (146) above the limit [°C].
        Temperature = 2,
        /// Present Input Voltage (144) below the limit [0.1 V].
        VoltageLow = 3,
        /// Present Input Voltage above the limit [0.1 V].
        VoltageHigh = 4,
        /// |Present Current| (126) above the limit [mA].
        Current = 5,
        /// Torque Enable (64) read 0 while the robot walks: the servo browned out and came
        /// back limp [the value read, 0]. The monitor turns its torque on again at its last
        /// goal.
        TorqueOff = 6,
    }
}

wire_codes! {
    /// What reset the controller (the `ResetCause` fault record's `id`).
    pub enum ResetCause {
        /// Power-on (the only reset after which the firmware walks by itself).
        PowerOn = 1,
        /// Brown-out (the supply sagged below the threshold).
        BrownOut = 2,
        /// A watchdog (independent or window).
        Watchdog = 3,
        /// A software reset (the panic path, `SCB::sys_reset`).
        Software = 4,
        /// The reset pin (button, debugger).
        Pin = 5,
        /// Low-power management.
        LowPower = 6,
        /// No flag set (unknown).
        Unknown = 7,
    }
}

wire_codes! {
    /// What a crash record in no-init RAM says (the `CrashRecord` fault record's `id`).
    pub enum CrashCode {
        /// The firmware panicked.
        Panic = 1,
        /// The watchdog reset the controller (the record holds the last tick noted).
        Watchdog = 2,
    }
}

wire_codes! {
    /// Which start-up step failed (its code is the `StartupFailed` fault record's `value`).
    pub enum StartupStep {
        /// Reading Return Delay Time.
        ReturnDelayRead = 1,
        /// Writing Return Delay Time = 0.
        ReturnDelayWrite = 2,
        /// The read-back value was not 0.
        ReturnDelayVerify = 3,
        /// SYNC READ of the present positions.
        ReadPositions = 4,
        /// WRITE Torque Enable = 1.
        TorqueEnable = 5,
        /// Writing a servo's Position I Gain.
        GainWrite = 6,
        /// The read-back Position I Gain differed.
        GainVerify = 7,
    }
}

wire_codes! {
    /// The firmware's exit code (see the module docs' table).
    pub enum ExitCode {
        /// Plan done.
        PlanDone = 0,
        /// Configuration rejected.
        ConfigRejected = 2,
        /// Virtual watchdog (QEMU board).
        Watchdog = 3,
        /// Device missing at start-up.
        DeviceMissing = 11,
        /// Device lost while running.
        DeviceLost = 12,
        /// Fall.
        Fall = 13,
        /// Overrun burst.
        OverrunBurst = 14,
        /// Non-finite joint target.
        NonFiniteTarget = 15,
        /// Stop requested.
        Requested = 17,
        /// Non-finite gait sample.
        NonFiniteSample = 18,
        /// Sensor data stale.
        SensorStale = 19,
        /// A start-up step failed after the probe.
        StartupFailed = 20,
        /// Servo fault seen by the monitor.
        ServoFault = 21,
        /// Not walking after a reset other than power-on.
        NotPowerOn = 22,
        /// A leg servo lost while running.
        ServoLost = 24,
        /// The simulator is gone (QEMU board: its lock-step pipe closed).
        SimulatorGone = 25,
        /// Panic.
        Panic = 101,
    }
}

impl ExitCode {
    /// The numeric exit code as the process status (`i32`, semihosting `exit`).
    pub const fn status(self) -> i32 {
        self.code() as i32
    }

    /// What the code means, in a few words.
    pub const fn meaning(self) -> &'static str {
        match self {
            ExitCode::PlanDone => "plan done",
            ExitCode::ConfigRejected => "configuration rejected",
            ExitCode::Watchdog => "watchdog",
            ExitCode::DeviceMissing => "device missing at start-up",
            ExitCode::DeviceLost => "device lost",
            ExitCode::Fall => "fall",
            ExitCode::OverrunBurst => "overrun burst",
            ExitCode::NonFiniteTarget => "non-finite target",
            ExitCode::Requested => "stop requested",
            ExitCode::NonFiniteSample => "non-finite gait sample",
            ExitCode::SensorStale => "sensor data stale",
            ExitCode::ServoFault => "servo fault",
            ExitCode::NotPowerOn => "reset other than power-on: not walking",
            ExitCode::ServoLost => "leg servo lost",
            ExitCode::StartupFailed => "start-up step failed",
            ExitCode::SimulatorGone => "simulator gone",
            ExitCode::Panic => "panic",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every variant of a code table (`all`) decodes from its code, and no other code decodes.
    fn round_trips<T>(all: &[T], code: fn(T) -> u8)
    where
        T: Copy + PartialEq + core::fmt::Debug + TryFrom<u8, Error = UnknownCode>,
    {
        for &v in all {
            assert_eq!(T::try_from(code(v)), Ok(v));
        }
        let decoded = (0..=255u8).filter(|&c| T::try_from(c).is_ok()).count();
        assert_eq!(decoded, all.len(), "{all:?}");
    }

    #[test]
    fn every_code_round_trips_and_is_unique() {
        round_trips(&StopCode::ALL, StopCode::code);
        round_trips(&ExitCode::ALL, ExitCode::code);
        round_trips(&CommandField::ALL, CommandField::code);
        round_trips(&StartupStep::ALL, StartupStep::code);
        round_trips(&SensorRejection::ALL, SensorRejection::code);
        round_trips(&ServoCheck::ALL, ServoCheck::code);
        round_trips(&ResetCause::ALL, ResetCause::code);
        round_trips(&CrashCode::ALL, CrashCode::code);
        for c in 0..=255u8 {
            assert_eq!(FaultKind::from_code(c).code(), c);
        }
        assert_eq!(StopCode::try_from(0), Err(UnknownCode(0)));
    }

    #[test]
    fn supervisor_stops_exit_with_ten_plus_their_code() {
        for s in StopCode::ALL {
            let e = s.exit();
            if s == StopCode::PlanDone {
                assert_eq!(e, ExitCode::PlanDone);
            } else if s == StopCode::Deadman {
                // Not a supervisor stop: no run ends with it.
                assert_eq!(e, ExitCode::Requested);
                assert_eq!(StopReason::from_code(s.code(), 0, 0), None);
            } else {
                assert_eq!(e.code(), 10 + s.code(), "{s:?}");
            }
        }
    }

    #[test]
    fn stop_reasons_round_trip() {
        for r in [
            StopReason::DeviceMissing { id: 111 },
            StopReason::DeviceLost { id: 7 },
            StopReason::Fall { tilt_mrad: 650 },
            StopReason::OverrunBurst { count: 5 },
            StopReason::NonFiniteTarget { joint: 3 },
            StopReason::PlanDone,
            StopReason::Requested,
            StopReason::NonFiniteSample { tick: 1234 },
            StopReason::SensorStale {
                id: 200,
                age_ms: 105,
            },
            StopReason::ServoFault {
                id: 7,
                check: ServoCheck::Temperature,
                reading: 81,
            },
            StopReason::ServoFault {
                id: 12,
                check: ServoCheck::Current,
                reading: 65_535,
            },
            StopReason::NotPowerOn {
                cause: ResetCause::BrownOut,
            },
        ] {
            let (c, id, v) = r.code();
            assert_eq!(StopReason::from_code(c, id, v), Some(r));
        }
        assert_eq!(StopReason::from_code(3, 0, -1), None);
        assert_eq!(StopReason::from_code(99, 0, 0), None);
    }
}
