//! The firmware's run-time configuration ([`Config`]) and the small enums it selects from.
//! Every field that a `key=value` token can set is declared once in [`crate::params::PARAMS`];
//! the host builds the same `Config` from a plan file through that table.

/// Most footsteps a firmware plan may have.
pub const MAX_STEPS: usize = 64;
/// Default Position I Gain of the ankle-roll servos (register units; the factory value is 0).
/// With [`DEFAULT_SERVO_I_HIP_ROLL`] and the compliance feed-forward at 0.75 roll / 0.15 pitch
/// ([`gait_core::feedback::compliance::Compliance::DEFAULT`]) it removes the stance leg's steady roll sag
/// the feed-forward's model misses (docs/beyond.md, "Servo compliance").
pub const DEFAULT_SERVO_I_ROLL: u16 = 1250;
/// Default Position I Gain of the hip-roll servos: less than the ankle rolls', because the hip's
/// integral, built up under the stance leg's load, unwinds through the swing and carries the
/// swing foot outward (docs/beyond.md, "The roll servos' integral beside less feed-forward").
pub const DEFAULT_SERVO_I_HIP_ROLL: u16 = 800;
/// Longest servo-lag feed-forward, s.
pub const MAX_SERVO_LEAD_S: f64 = 0.3;
/// Most ticks of servo-lag feed-forward (the firmware's delay line of gait samples: 0.3 s at
/// the 200 Hz default; at 1 kHz the lead is capped at 64 ms).
pub const MAX_LEAD_TICKS: usize = 64;
/// Default low-pass cutoff of the φ̈ filter, Hz (see the firmware's `imu` module).
pub const DEFAULT_IMU_CUTOFF_HZ: f32 = 15.0;
/// Default longest single wait for one reply byte, µs (see the firmware's `bus` module).
pub const DEFAULT_READ_POLL_US: u32 = 20;

pub use gait_core::gait::{Arithmetic, Compensation, Feasibility};

/// Supervisor limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupervisorConfig {
    /// Consecutive missed replies bridged with the last good value (then `DeviceLost`).
    pub hold_ticks: u16,
    /// Tilt from vertical that counts as a fall, rad.
    pub tilt_limit_rad: f32,
    /// Ticks the pose is held in `Stopping` before torque off.
    pub stopping_ticks: u16,
    /// Consecutive overruns that stop the robot.
    pub overrun_burst: u16,
}

impl SupervisorConfig {
    /// The defaults: 10 ticks of hold, 0.6 rad tilt, 200 ticks of stopping, 5 overruns.
    pub const fn default_limits() -> Self {
        SupervisorConfig {
            hold_ticks: 10,
            tilt_limit_rad: 0.6,
            stopping_ticks: 200,
            overrun_burst: 5,
        }
    }
}

impl Default for SupervisorConfig {
    fn default() -> Self {
        Self::default_limits()
    }
}

/// Limits of the servo monitor (one servo read per walking tick, round-robin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServoLimits {
    /// Highest Present Temperature, °C.
    pub temperature_max_c: u8,
    /// Lowest Present Input Voltage, V.
    pub voltage_min_v: f32,
    /// Highest Present Input Voltage, V.
    pub voltage_max_v: f32,
    /// Highest |Present Current|, A.
    pub current_max_a: f32,
    /// Monitor READs of one servo left unanswered in a row that make it lost (`ServoLost`).
    pub miss_limit: u8,
}

impl ServoLimits {
    /// XM430-W350 defaults: 70 °C (the servo shuts down at its 80 °C Temperature Limit),
    /// 10.0 ..= 14.8 V (its operating range), 2.5 A (above its 2.3 A stall current at 12 V:
    /// only a shorted or blocked motor draws it for long: the monitor stops at two readings
    /// over it in a row; the MuJoCo Table 2 walk peaks at 2.1 A).
    pub const fn xm430() -> Self {
        ServoLimits {
            temperature_max_c: 70,
            voltage_min_v: 10.0,
            voltage_max_v: 14.8,
            current_max_a: 2.5,
            miss_limit: 8,
        }
    }
}

/// The robot a configuration walks unless told otherwise.
const REFERENCE_ROBOT: gait_core::Robot = gait_core::Robot::reference();

/// Default heading-hold gain of the online walk (share of the heading error turned back per step).
pub const DEFAULT_HEADING_GAIN: f32 = 0.5;

/// Run-time configuration shared by the boards and the control loop. On QEMU every field
/// named in [`crate::params::PARAMS`] can be overridden from the semihosting command line; on the real
/// board the configuration is compiled in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// The robot walked: its description (geometry, masses, bus IDs, mounting signs).
    pub robot: &'static gait_core::Robot,
    /// Control tick period = gait sample time dt, µs (1000 ..= 20000).
    pub tick_period_us: u32,
    /// Servo bus baud rate, bit/s.
    pub bus_baud: u32,
    /// Servo Return Delay Time, µs (modelled by the QEMU board's clock).
    pub return_delay_us: u32,
    /// Watchdog timeout once the control loop runs, ms.
    pub watchdog_ms: u32,
    /// Supervisor limits.
    pub supervisor: SupervisorConfig,
    /// Low-pass cutoff of the φ̈ filter, Hz.
    pub imu_cutoff_hz: f32,
    /// Pendulum model of the gait.
    pub model: gait_core::ModelKind,
    /// The forward walk (seed 000 Table 2 by default).
    pub walk: gait_core::ForwardWalk,
    /// Use seed 001's continuous ZMP instead of the natural ZMP (d1, d2, a).
    pub zmp_continuous: bool,
    /// Half travel b of the continuous ZMP, m (`None`: the walk's `a`).
    pub zmp_b: Option<f64>,
    /// Use seed 001's sinusoid swing (height h_z) instead of the cycloid (h_z, w_y).
    pub swing_sinusoid: bool,
    /// The CoM from seed 001's Fourier series (`true`) or seed 000's exact solution.
    pub com_fourier: bool,
    /// Terms per axis of the Fourier CoM.
    pub fourier_terms: u8,
    /// Servo-lag feed-forward: the joint targets are the gait's this far ahead, s.
    pub servo_lead_s: f32,
    /// Position I Gain written at start-up to the ankle-roll servos (register units; the
    /// servo's integral action removes their load sag).
    pub servo_i_roll: u16,
    /// Position I Gain written at start-up to the hip-roll servos (register units).
    pub servo_i_hip_roll: u16,
    /// Position I Gain written at start-up to the hip-pitch, knee and ankle-pitch servos.
    pub servo_i_pitch: u16,
    /// Reply timeout of the Dynamixel master, µs (per expected status packet).
    pub reply_timeout_us: u32,
    /// Longest single wait for one reply byte, µs (the firmware's bus driver).
    pub read_poll_us: u32,
    /// Attempts per start-up transaction (ping, Return Delay Time, positions, torque).
    pub startup_attempts: u8,
    /// Duration of the smooth move from the present pose to the initial pose, µs.
    pub ramp_us: u32,
    /// Time the final pose is held after the plan before torque off, µs.
    pub final_hold_us: u32,
    /// A graded stop's longest walk to a standstill before the lowering begins anyway, µs.
    pub settle_us: u32,
    /// Duration of a graded stop's lowering to the crouch, µs (0: no lowering, the pose is
    /// held, then torque off).
    pub lower_us: u32,
    /// How far the crouch lowers the pelvis below the walking height z_c, m.
    pub crouch_m: f32,
    /// Smallest load of a foot that counts for the measured ZMP, N.
    pub min_load_n: f32,
    /// A foot board missing at start-up stops the robot (`true`) or is tolerated (`false`:
    /// the walk runs with the other foot's forces only; see the firmware's `control`).
    pub feet_required: bool,
    /// Modelled compute time per tick on the QEMU board, µs; 0 (the default): the bench's
    /// instructions per tick for the build at [`Config::core_mhz`] (ignored by real boards).
    pub compute_us: u32,
    /// Modelled core clock of the QEMU board, MHz (216: the OpenCR's STM32F746; 72 for an
    /// STM32F103 board): the compute time per tick is instructions ÷ MHz.
    pub core_mhz: u32,
    /// How the pelvis is placed: the paper's pipeline or whole-body compensation.
    pub compensation: Compensation,
    /// The ZMP/DCM feedback stabilizer is on.
    pub stabilizer_on: bool,
    /// The stabilizer's gains and limits.
    pub stabilizer: gait_core::feedback::stabilizer::StabilizerConfig,
    /// Gyro damping through the ankles and hips of the legs on the ground
    /// ([`gait_core::feedback::gyro`]).
    pub gyro_feedback: gait_core::feedback::gyro::GyroFeedback,
    /// Feed-forward of the position servos' static sag ([`gait_core::feedback::compliance`]).
    pub compliance: gait_core::feedback::compliance::Compliance,
    /// The sag feed-forward takes the servo survey's stiffness (at the present supply) in place
    /// of `compliance.stiffness` once the survey has it.
    pub compliance_follow: bool,
    /// Foot force difference control in double support ([`gait_core::feedback::fdc`]).
    pub foot_force: gait_core::feedback::fdc::FootForceControl,
    /// The catching step: the swing foot's landing place moved by the capture-point error
    /// beyond the ankles' reach ([`gait_core::feedback::catch`]).
    pub step_adaptation: gait_core::feedback::catch::StepAdaptation,
    /// The stance leg's joints driven to their targets from the servos' Present Position
    /// ([`gait_core::feedback::deflection`]).
    pub deflection: gait_core::feedback::deflection::DeflectionConfig,
    /// Where the measured ZMP places the feet: the plan's places, or each landing surveyed by
    /// forward kinematics of the servos' Present Position ([`gait_core::measure::odometry`]).
    pub sole_poses_measured: bool,
    /// The online walk's heading hold: share of the gyro-measured heading error each walking
    /// step turns back ([`gait_core::trajectory::online`] H1–H2; 0 = off).
    pub heading_gain: f32,
    /// The online walk's position hold: share of the surveyed feet's distance from the commanded
    /// track each walking step corrects ([`gait_core::trajectory::online`] P1–P2; 0 = off).
    pub position_gain: f32,
    /// What start-up does when the plan needs joints faster than the servos.
    pub feasibility: Feasibility,
    /// The number type of the per-sample gait work (f32, or the fixed-point sampler and IK).
    pub arithmetic: Arithmetic,
    /// Fault injection: replace joint 0's target by NaN at this walk tick.
    pub fault_nan_tick: Option<u32>,
    /// Fault injection: request a stop at this walk tick.
    pub stop_at_tick: Option<u32>,
    /// Fault injection (QEMU board): the next parameter save loses power after this many
    /// bytes of its slot (the firmware exits at once, as at a power cut).
    pub fault_cut_save: Option<u32>,
    /// Longest time a sensor board may go without a plausible reply before the robot stops
    /// (`SensorStale`), ms.
    pub sensor_stale_ms: u32,
    /// Foot forces above m·g·`force_factor` (one foot or both together) are implausible.
    pub force_factor: f32,
    /// Rounds of broadcast torque off + read-back of every servo's Torque Enable before the
    /// servo power is cut.
    pub torque_off_attempts: u8,
    /// Limits of the servo monitor.
    pub servo_limits: ServoLimits,
    /// Fault injection: make the gait sample's CoM NaN at this walk tick (the finite check
    /// before the IK must stop).
    pub fault_nan_com_tick: Option<u32>,
    /// Walk the configured forward plan at power-on (`true`: demos and the FIL tests), or
    /// stand up and wait for commands on the command port (`false`, the default).
    pub autostart: bool,
    /// The command deadman, ms: in Mode = walk, no valid command write for this long stops the
    /// online walk to standing.
    pub deadman_ms: u32,
    /// Torque stays off until the operator's enable (a Mode write of stand or walk on the
    /// command port) at power-on and after every stop, the command port answering meanwhile
    /// (`true`: the OpenCR and OpenCM 9.04 builds); `false`: the firmware starts at once and
    /// its run ends at the first stop (QEMU's firmware-in-the-loop runs).
    pub wait_enable: bool,
    /// An operator's stop (Mode = torque off, `stop_at`) ends with the robot resting in the
    /// crouch, torque on, and a second Mode = torque off turns torque off (`true`); `false`:
    /// torque off after the crouch's hold, as every other graded stop.
    pub rest: bool,
}

impl Config {
    /// Compute time the QEMU board charges per tick, ns: [`Config::compute_us`] when set
    /// (non-zero), else `tick_instructions` at [`Config::core_mhz`], one instruction per cycle
    /// (QEMU counts instructions, not cycles).
    pub const fn compute_ns(&self, tick_instructions: u32) -> u64 {
        if self.compute_us > 0 {
            self.compute_us as u64 * 1000
        } else {
            let mhz = if self.core_mhz == 0 { 1 } else { self.core_mhz };
            tick_instructions as u64 * 1000 / mhz as u64
        }
    }

    /// Defaults: the reference robot at its bus speed (1 Mbps), 200 Hz tick, Return Delay Time 0, 50 ms watchdog, TLIPFM,
    /// Table 2 walk, 1 ms reply timeout, 1.5 s ramp, 1 s final hold, 2 N minimum load, no
    /// compensation, stabilizer off, gyro balance feedback on (k_a 0.1 s, k_h 0.05 s), 8 start-up
    /// attempts, servo-speed feasibility by stretching the timing, factory servo gains.
    pub const fn default_config() -> Self {
        Config {
            robot: &REFERENCE_ROBOT,
            tick_period_us: 5_000,
            bus_baud: REFERENCE_ROBOT.bus.baud,
            return_delay_us: 0,
            watchdog_ms: 50,
            supervisor: SupervisorConfig::default_limits(),
            imu_cutoff_hz: DEFAULT_IMU_CUTOFF_HZ,
            model: gait_core::ModelKind::Tlipfm,
            walk: gait_core::ForwardWalk::table2(),
            zmp_continuous: false,
            zmp_b: None,
            swing_sinusoid: false,
            com_fourier: false,
            fourier_terms: gait_core::trajectory::fourier_walk::DEFAULT_FOURIER_TERMS,
            servo_lead_s: 0.0,
            servo_i_roll: DEFAULT_SERVO_I_ROLL,
            servo_i_hip_roll: DEFAULT_SERVO_I_HIP_ROLL,
            servo_i_pitch: 0,
            reply_timeout_us: 1_000,
            read_poll_us: DEFAULT_READ_POLL_US,
            startup_attempts: 8,
            ramp_us: 1_500_000,
            final_hold_us: 1_000_000,
            settle_us: 2_500_000,
            lower_us: 1_500_000,
            crouch_m: 0.05,
            min_load_n: 2.0,
            feet_required: true,
            compute_us: 0,
            core_mhz: 216,
            compensation: Compensation::None,
            stabilizer_on: false,
            stabilizer: gait_core::feedback::stabilizer::StabilizerConfig::default_gains(),
            gyro_feedback: gait_core::feedback::gyro::GyroFeedback::DEFAULT,
            compliance: gait_core::feedback::compliance::Compliance::DEFAULT,
            compliance_follow: false,
            foot_force: gait_core::feedback::fdc::FootForceControl::OFF,
            step_adaptation: gait_core::feedback::catch::StepAdaptation::DEFAULT,
            deflection: gait_core::feedback::deflection::DeflectionConfig::DEFAULT,
            sole_poses_measured: true,
            heading_gain: DEFAULT_HEADING_GAIN,
            position_gain: 0.5,
            feasibility: Feasibility::Stretch,
            arithmetic: Arithmetic::F32,
            fault_nan_tick: None,
            stop_at_tick: None,
            fault_cut_save: None,
            fault_nan_com_tick: None,
            sensor_stale_ms: 100,
            force_factor: 6.0,
            torque_off_attempts: 3,
            servo_limits: ServoLimits::xm430(),
            autostart: false,
            deadman_ms: 500,
            wait_enable: false,
            rest: true,
        }
    }

    /// The tick period in seconds (the gait's dt).
    pub fn dt_s(&self) -> f64 {
        f64::from(self.tick_period_us) * 1e-6
    }

    /// The gait part of the configuration (gait-core's [`gait_core::gait::WalkConfig`]).
    pub fn walk_config(&self) -> gait_core::gait::WalkConfig {
        gait_core::gait::WalkConfig {
            model: self.model,
            walk: self.walk,
            zmp_continuous: self.zmp_continuous,
            zmp_b: self.zmp_b,
            swing_sinusoid: self.swing_sinusoid,
            com: if self.com_fourier {
                gait_core::gait::ComMethod::Fourier {
                    terms: self.fourier_terms,
                }
            } else {
                gait_core::gait::ComMethod::Exact
            },
            dt_s: self.dt_s(),
        }
    }

    /// The servo lead in whole ticks (rounded, at most [`MAX_LEAD_TICKS`]).
    pub fn lead_ticks(&self) -> usize {
        let t = libm::roundf(self.servo_lead_s * 1e6 / self.tick_period_us.max(1) as f32);
        if t > 0.0 {
            (t as usize).min(MAX_LEAD_TICKS)
        } else {
            0
        }
    }

    /// Number of whole ticks covering `us` microseconds (at least 1).
    pub fn ticks_for_us(&self, us: u32) -> u32 {
        us.div_ceil(self.tick_period_us.max(1)).max(1)
    }
}

impl Default for Config {
    fn default() -> Self {
        Self::default_config()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compute_time_is_instructions_over_the_core_clock() {
        let mut c = Config::default_config();
        assert_eq!((c.compute_us, c.core_mhz), (0, 216));
        // 16,200 instructions at 216 MHz = 75 µs; at 72 MHz (an STM32F103) 225 µs.
        assert_eq!(c.compute_ns(16_200), 75_000);
        c.core_mhz = 72;
        assert_eq!(c.compute_ns(16_200), 225_000);
        // An explicit compute_us wins.
        c.compute_us = 300;
        assert_eq!(c.compute_ns(16_200), 300_000);
        c.compute_us = 0;
        c.core_mhz = 0;
        assert_eq!(
            c.compute_ns(7),
            7_000,
            "0 MHz is read as 1, never a division by zero"
        );
    }
}
