//! The simulated robot on the servo bus.
//!
//! A kid-size humanoid ([`gait_core::Robot::reference`] by default) whose devices, as its
//! description's bus lists them ([`gait_core::robot::BusDescription`]: the 12 leg servos, the
//! foot force-sensor boards and the IMU board where it has them, the held arm and head servos),
//! answer Dynamixel Protocol 2.0 instructions over TCP, with the control tables of `dxl::table`
//! and the description's rad ↔ tick map (its mounting signs). A held servo is not in the
//! physics: with torque on it stands at its Goal Position. The body ([`Body`]) is, by default, MuJoCo in full dynamics ([`mujoco`]:
//! the MJCF of [`mjcf`] generated from the robot description, X-series servo models of
//! [`dynamixel`], load cells from the soles' contact wrenches, the IMU from MuJoCo sensors,
//! falls as the physics makes them); [`PhysicsModel::Kinematic`] selects the idealised
//! kinematic model ([`body`]: stance sole bolted down, whole-body ZMP from the link
//! accelerations [`zmp`], forces from that ZMP [`forces`], scripted falls), kept for its
//! exact, hand-checkable tests. See [`transport`] for the TCP endpoints and the lock-step
//! protocol used with the firmware in QEMU.
//!
//! ```no_run
//! use walker_host::sim::{spawn, SimConfig};
//! let cfg = SimConfig { port: 5760, lockstep_port: Some(5761), seed: 7, ..SimConfig::default() };
//! let handle = spawn(cfg).unwrap();          // listening now; start QEMU, then:
//! let summary = handle.join().unwrap();      // returns when the master disconnects
//! println!("{} instructions", summary.bus.instructions);
//! ```

pub mod body;
pub mod bus;
pub mod chip;
pub mod device;
pub mod dynamixel;
pub mod forces;
pub mod mjcf;
pub mod mujoco;
pub mod rng;
pub mod servo;
pub mod transport;
pub mod truth;
pub mod urdf;
pub mod zmp;

use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use dxl::table::{foot::FootForces, imu::ImuSample, x_series};
use dxl::{DecodeError, Decoder};
use gait_core::robot::ImuPlace;
use gait_core::Robot;
use walker_contract::bus_map::TickMap;

pub use body::{Physics, ServoCmd, Support, TruthSample};
pub use bus::{BusCounters, BusFaults, DeviceBus, Outage, OwnedPacket};
pub use device::{Device, DeviceKind};
pub use dynamixel::{XServoOutput, XServoParams, XServoRegisters};
pub use mjcf::EnvConfig;
pub use mujoco::{MjBody, Push};
pub use servo::ServoTorque;
pub use transport::{run, spawn, SimHandle, SimProgress};

/// Fault injection on the bus (drops, corruption, dead devices); forced falls are in
/// [`FallConfig`].
pub type FaultConfig = BusFaults;

/// Sensor noise and bias (all deterministic from the seed).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NoiseConfig {
    /// Standard deviation of each force sensor, N.
    pub force_std_n: f64,
    /// Standard deviation of each gyro axis, rad/s.
    pub gyro_std_rad_s: f64,
    /// Standard deviation of each accelerometer axis, m/s².
    pub accel_std_m_s2: f64,
    /// Constant gyro bias, rad/s.
    pub gyro_bias_rad_s: [f64; 3],
    /// Constant accelerometer bias, m/s².
    pub accel_bias_m_s2: [f64; 3],
    /// Latency of the foot boards' and the IMU's samples, µs (rounded to physics steps).
    pub latency_us: u64,
    /// Latency of the servos' Present Position and Present Velocity, µs (rounded to physics
    /// steps; the servos' own position loops see the joint without delay).
    pub position_latency_us: u64,
}

/// External pitch torque on the upper body (the angular-momentum disturbance).
#[derive(Clone, Debug, PartialEq)]
pub struct DisturbanceConfig {
    /// Constant torque while active, N·m (positive pitches the upper body forward).
    pub constant_nm: f64,
    /// Standard deviation of a random torque added while active, N·m.
    pub random_std_nm: f64,
    /// The random torque is piecewise constant over this period, s.
    pub hold_s: f64,
    /// Start of the disturbance, s.
    pub start_s: f64,
    /// End of the disturbance, s (`None`: never ends).
    pub end_s: Option<f64>,
    /// Natural frequency of the waist compliance joining the upper body to the pelvis, Hz
    /// (kinematic model only; the MuJoCo torso is one rigid body).
    pub waist_frequency_hz: f64,
    /// Damping ratio of the waist compliance (kinematic model only).
    pub waist_damping: f64,
}

impl Default for DisturbanceConfig {
    fn default() -> Self {
        DisturbanceConfig {
            constant_nm: 0.0,
            random_std_nm: 0.0,
            hold_s: 0.05,
            start_s: 0.0,
            end_s: None,
            waist_frequency_hz: 8.0,
            waist_damping: 0.7,
        }
    }
}

impl DisturbanceConfig {
    /// The disturbance torque at `time_us` (N·m), given the last one: constant while active,
    /// plus a random part resampled every `hold_s` on a fixed time grid (drawn whether active
    /// or not, so the random streams of runs stay aligned).
    pub fn torque_at(&self, time_us: u64, dt_us: u64, rng: &mut rng::Rng, last: f64) -> f64 {
        let t = time_us as f64 * 1e-6;
        let active = t >= self.start_s && self.end_s.is_none_or(|e| t < e);
        let hold_us = ((self.hold_s * 1e6) as u64).max(dt_us.max(1));
        if self.random_std_nm > 0.0 && time_us.is_multiple_of(hold_us) {
            let r = rng.gaussian() * self.random_std_nm;
            if active {
                self.constant_nm + r
            } else {
                0.0
            }
        } else if self.random_std_nm <= 0.0 {
            if active {
                self.constant_nm
            } else {
                0.0
            }
        } else if !active {
            0.0
        } else {
            last
        }
    }
}

/// Fall detection and forced falls.
#[derive(Clone, Debug, PartialEq)]
pub struct FallConfig {
    /// Detect falls from the ZMP and the pelvis tilt (kinematic model; the MuJoCo robot falls by
    /// itself and its truth marks the fall from the torso, see [`mujoco`]).
    pub enabled: bool,
    /// ZMP outside the support polygon by more than this, m … (kinematic model)
    pub zmp_margin: f64,
    /// … for at least this long, s, starts a fall.
    pub zmp_time_s: f64,
    /// A pelvis tilt beyond this starts a fall, rad.
    pub max_tilt_rad: f64,
    /// Force a fall at this time, s.
    pub forced_at_s: Option<f64>,
    /// Direction of a forced fall (heading in the ground plane; 0 = forward, π/2 = left), rad.
    pub forced_direction: f64,
}

impl Default for FallConfig {
    fn default() -> Self {
        FallConfig {
            enabled: true,
            zmp_margin: 0.005,
            zmp_time_s: 0.05,
            max_tilt_rad: 0.6,
            forced_at_s: None,
            forced_direction: 0.0,
        }
    }
}

/// Default [`SimConfig::servo_frequency_hz`], Hz: a stiff position loop for a hobby servo carrying
/// a leg or the whole body. The choice trades two real effects: a goal change Δ steps the joint
/// acceleration by ω²·Δ, so the ripple that the firmware's 1-tick (1.5 mrad) goal rounding puts
/// on the whole-body ZMP grows as f² (at most ±1.7 cm at 6 Hz during the start-up crouch, ±5 cm at
/// 10 Hz), while the servos' tracking delay 2ζ/ω (53 ms at 6 Hz, ζ = 1) grows as 1/f.
pub const SERVO_FREQUENCY_HZ: f64 = 6.0;

/// Which physics moves the simulated robot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PhysicsModel {
    /// MuJoCo full dynamics ([`mujoco`]): the robot can tip, slip, bounce and fall. The default,
    /// and the only source of walking-quality figures.
    #[default]
    MuJoCo,
    /// The idealised kinematic model ([`body`]): the stance sole bolted to the floor, scripted
    /// falls. Kept for its exact, hand-checkable servo and ZMP tests; its walking figures are
    /// several times better than physics gives.
    Kinematic,
}

/// Everything the simulator needs; `SimConfig::default()` is the reference robot with
/// XM430-class servos (4.8 rad/s, 3.5 N·m on the torque–speed line) on port 5760 without
/// lock-step, faults or noise.
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// Robot description.
    pub robot: Robot,
    /// Which physics moves the robot.
    pub physics: PhysicsModel,
    /// The X-series servo model of the MuJoCo robot ([`dynamixel`]).
    pub xservo: XServoParams,
    /// Floor, payload and mass scale of the MuJoCo robot ([`mjcf`]).
    pub env: EnvConfig,
    /// Pushes on the torso (MuJoCo robot).
    pub pushes: Vec<Push>,
    /// Hold the torso (a weld to the world) until all 12 servos have torque on (MuJoCo robot).
    pub hold_until_torque: bool,
    /// Write the generated MJCF model here (MuJoCo robot).
    pub model_out: Option<PathBuf>,
    /// Write the MuJoCo state (`t_s, qpos_0 …`) here at 100 Hz, for `scripts/render_walk.py`.
    pub qpos_out: Option<PathBuf>,
    /// Bus TCP port on 127.0.0.1 (0 = any free port; see [`SimHandle::bus_addr`]).
    pub port: u16,
    /// Lock-step channel TCP port (`None`: free-running on the wall clock, unless
    /// [`Self::lockstep_pipe`]).
    pub lockstep_port: Option<u16>,
    /// Lock-step over two named pipes at this path prefix instead of TCP, the bus inside them
    /// ([`transport`]; the firmware's word `lockstep=PREFIX`): created by [`spawn`], removed
    /// once the firmware has opened them. Overrides [`Self::port`] and [`Self::lockstep_port`].
    pub lockstep_pipe: Option<PathBuf>,
    /// `false` (default): listen and accept one connection per channel (QEMU with
    /// `-serial tcp:127.0.0.1:PORT,nodelay=on`); `true`: connect to a listening peer
    /// (QEMU with `-serial tcp:127.0.0.1:PORT,server=on,wait=off`), retrying.
    pub connect: bool,
    /// How long to wait for the peer (accept or connect retries).
    pub connect_timeout: Duration,
    /// Seed of every random stream.
    pub seed: u64,
    /// Servo speed limit, rad/s (kinematic model; the MuJoCo servos follow [`Self::xservo`]).
    pub servo_speed_limit: f64,
    /// Servo torque model of the kinematic model (`None`: unlimited torque; see [`servo`]).
    pub servo_torque: Option<ServoTorque>,
    /// Natural frequency of a servo's closed position loop with its load, Hz (kinematic model; see [`body`]: a
    /// second-order response, so the joint velocity never jumps when a goal changes).
    pub servo_frequency_hz: f64,
    /// Damping ratio of a servo's closed position loop (1 = critically damped; kinematic model).
    pub servo_damping: f64,
    /// Physics step, µs.
    pub physics_dt_us: u64,
    /// A sole at most this high above the stance sole is in contact, m (kinematic model).
    pub contact_threshold: f64,
    /// A sole this much lower than the stance sole becomes the stance foot, m (kinematic model).
    pub switch_threshold: f64,
    /// Joint angles at start, rad (left leg then right leg).
    pub initial_q: [f64; 12],
    /// Include the upper body's J·φ̈ pitch term in the ZMP (kinematic model).
    pub upper_body_inertia_term: bool,
    /// Sensor noise.
    pub noise: NoiseConfig,
    /// Disturbance torque.
    pub disturbance: DisturbanceConfig,
    /// Bus faults.
    pub faults: FaultConfig,
    /// Falls.
    pub fall: FallConfig,
    /// Write the ground truth to this CSV file.
    pub log_truth: Option<PathBuf>,
    /// Period of the truth CSV rows, µs (rounded up to whole physics steps).
    pub log_every_us: u64,
    /// Lock-step runs: simulated time run on after the firmware's end (its bus closed, the
    /// servos as it left them: torque off), µs; how the robot ended is in
    /// [`SimSummary::end`]. 0: none.
    pub after_end_us: u64,
    /// The truth CSV of the time after the firmware's end (same columns; `None`: not written).
    pub after_truth: Option<PathBuf>,
}

impl Default for SimConfig {
    fn default() -> Self {
        let robot = Robot::reference();
        SimConfig {
            robot,
            physics: PhysicsModel::MuJoCo,
            xservo: XServoParams::XM430_W350,
            env: EnvConfig::default(),
            pushes: Vec::new(),
            hold_until_torque: true,
            model_out: None,
            qpos_out: None,
            port: 5760,
            lockstep_port: None,
            lockstep_pipe: None,
            connect: false,
            connect_timeout: Duration::from_secs(30),
            seed: 0,
            servo_speed_limit: robot.servo.max_speed,
            servo_torque: Some(ServoTorque::XM430),
            servo_frequency_hz: SERVO_FREQUENCY_HZ,
            servo_damping: 1.0,
            physics_dt_us: 1000,
            contact_threshold: 0.002,
            switch_threshold: 0.0005,
            initial_q: [0.0; 12],
            upper_body_inertia_term: true,
            noise: NoiseConfig::default(),
            disturbance: DisturbanceConfig::default(),
            faults: FaultConfig::default(),
            fall: FallConfig::default(),
            log_truth: None,
            log_every_us: 1000,
            after_end_us: 0,
            after_truth: None,
        }
    }
}

impl SimConfig {
    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |m: &str| Err(SimError::Config(m.to_string()));
        if self.robot.validate().is_err() || self.robot.validate_bus().is_err() {
            return bad("invalid robot description");
        }
        let p = |v: f64| (0.0..=1.0).contains(&v);
        if !p(self.faults.p_drop)
            || !p(self.faults.p_corrupt)
            || !p(self.faults.p_drop + self.faults.p_corrupt)
        {
            return bad("fault probabilities must be in [0, 1] and sum to at most 1");
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        if !positive(self.servo_speed_limit)
            || !positive(self.servo_frequency_hz)
            || !positive(self.servo_damping)
        {
            return bad("servo speed limit, frequency and damping must be > 0");
        }
        if self.servo_torque.is_some_and(|t| !t.is_valid()) {
            return bad("servo stall torque and no-load speed must be > 0, armature >= 0");
        }
        if self.physics_dt_us == 0 {
            return bad("physics step must be > 0");
        }
        if !non_negative(self.contact_threshold) || !non_negative(self.switch_threshold) {
            return bad("contact thresholds must be >= 0");
        }
        if self.initial_q.iter().any(|q| !q.is_finite()) {
            return bad("initial joint angles must be finite");
        }
        if !self.xservo.is_valid() {
            return bad("servo model: torques, speeds, currents and voltages must be > 0");
        }
        if let Err(m) = self.env.validate() {
            return bad(&m);
        }
        if self.noise.latency_us > 1_000_000 {
            return bad("sensor latency must be at most 1 s");
        }
        if self.noise.position_latency_us > 1_000_000 {
            return bad("Present Position latency must be at most 1 s");
        }
        Ok(())
    }
}

/// Simulator failure.
#[derive(Debug)]
pub enum SimError {
    /// Socket or file error.
    Io(std::io::Error),
    /// The peer did not connect / accept in time.
    Timeout(String),
    /// Invalid configuration.
    Config(String),
    /// The simulator thread panicked.
    Panicked,
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimError::Io(e) => write!(f, "simulator I/O error: {e}"),
            SimError::Timeout(m) => write!(f, "simulator timeout: {m}"),
            SimError::Config(m) => write!(f, "invalid simulator configuration: {m}"),
            SimError::Panicked => write!(f, "simulator thread panicked"),
        }
    }
}

impl std::error::Error for SimError {}

impl From<std::io::Error> for SimError {
    fn from(e: std::io::Error) -> Self {
        SimError::Io(e)
    }
}

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SimSummary {
    /// Final simulated time, µs.
    pub sim_time_us: u64,
    /// Physics steps run.
    pub physics_steps: u64,
    /// Bus counters.
    pub bus: BusCounters,
    /// Bytes received on the bus.
    pub bytes_in: u64,
    /// Whether the run was in lock-step mode.
    pub lockstep: bool,
    /// Time messages received on the lock-step channel.
    pub lockstep_messages: u64,
    /// Unexpected bytes on the lock-step channel.
    pub lockstep_errors: u64,
    /// When a fall started, µs.
    pub fall_started_us: Option<u64>,
    /// When the robot came to lie on the ground, µs.
    pub fallen_at_us: Option<u64>,
    /// Largest distance of the true ZMP outside the support polygon (before any fall), m.
    pub max_zmp_outside_m: f64,
    /// Rows written to the truth CSV.
    pub truth_rows: u64,
    /// How the robot ended, [`SimConfig::after_end_us`] after the firmware's end.
    pub end: Option<EndPose>,
    /// When a leg servo first had its torque on (the physics step after the write), µs.
    pub torque_on_us: Option<u64>,
    /// When every servo's torque was last found off after it had been on (none while any is
    /// on), µs.
    pub torque_off_us: Option<u64>,
}

/// How the robot ended, from the truth after the firmware's end ([`EndPose::of`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EndState {
    /// Upright, the pelvis within 2 cm of the walking height z_c.
    Standing,
    /// Upright (trunk within [`FALLEN_TILT_RAD`] of vertical), the pelvis lower: crouched on
    /// its feet or sitting on its folded legs.
    Crouched,
    /// The trunk tilted beyond [`FALLEN_TILT_RAD`]: lying on the ground.
    Fallen,
}

/// Trunk tilt from which a robot at rest counts as fallen, rad (45°).
pub const FALLEN_TILT_RAD: f64 = std::f64::consts::FRAC_PI_4;

impl fmt::Display for EndState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            EndState::Standing => "standing",
            EndState::Crouched => "crouched",
            EndState::Fallen => "fallen",
        })
    }
}

/// The robot's pose at the end of the time after the firmware's end.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EndPose {
    /// Simulated time after the firmware's end, s.
    pub after_s: f64,
    /// Pelvis height, m.
    pub pelvis_z_m: f64,
    /// Trunk tilt from vertical, rad.
    pub tilt_rad: f64,
    /// The verdict.
    pub state: EndState,
}

impl EndPose {
    /// The verdict on a truth sample `after_s` after the firmware's end (walking height `z_c`, m).
    pub fn of(t: &TruthSample, z_c: f64, after_s: f64) -> Self {
        let [roll, pitch, _] = t.pelvis_rpy;
        // The angle between the trunk's z axis and the vertical.
        let tilt = (roll.cos() * pitch.cos()).clamp(-1.0, 1.0).acos();
        let pelvis_z_m = t.pelvis[2];
        let state = if tilt > FALLEN_TILT_RAD {
            EndState::Fallen
        } else if pelvis_z_m >= z_c - 0.02 {
            EndState::Standing
        } else {
            EndState::Crouched
        };
        EndPose {
            after_s,
            pelvis_z_m,
            tilt_rad: tilt,
            state,
        }
    }
}

impl fmt::Display for EndPose {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {:.1} s after the firmware's end (pelvis {:.3} m high, trunk {:.1}° from vertical)",
            self.state,
            self.after_s,
            self.pelvis_z_m,
            self.tilt_rad.to_degrees()
        )
    }
}

/// A complete packet from the bus decoder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Incoming {
    /// A well-formed packet.
    Packet(OwnedPacket),
    /// An instruction packet with a bad CRC and this ID field.
    CrcError(u8),
}

/// The simulated robot's body: full dynamics or the idealised kinematic model.
#[derive(Debug)]
pub enum Body {
    /// MuJoCo full dynamics.
    MuJoCo(Box<MjBody>),
    /// The idealised kinematic model.
    Kinematic(Box<Physics>),
}

impl Body {
    /// A body at rest at `cfg.initial_q`.
    pub fn new(cfg: &SimConfig) -> Result<Self, SimError> {
        Ok(match cfg.physics {
            PhysicsModel::MuJoCo => Body::MuJoCo(Box::new(MjBody::new(cfg)?)),
            PhysicsModel::Kinematic => Body::Kinematic(Box::new(Physics::new(cfg))),
        })
    }

    /// Physics time, µs.
    pub fn time_us(&self) -> u64 {
        match self {
            Body::MuJoCo(b) => b.time_us,
            Body::Kinematic(p) => p.time_us,
        }
    }

    /// Joint angles, rad (left leg then right leg).
    pub fn q(&self) -> &[f64; 12] {
        match self {
            Body::MuJoCo(b) => b.q(),
            Body::Kinematic(p) => &p.q,
        }
    }

    /// Joint speeds, rad/s.
    pub fn qd(&self) -> &[f64; 12] {
        match self {
            Body::MuJoCo(b) => b.qd(),
            Body::Kinematic(p) => &p.qd,
        }
    }

    /// The ground truth.
    pub fn truth(&self) -> &TruthSample {
        match self {
            Body::MuJoCo(b) => b.truth(),
            Body::Kinematic(p) => p.truth(),
        }
    }

    /// When a fall started, µs.
    pub fn fall_started_us(&self) -> Option<u64> {
        match self {
            Body::MuJoCo(b) => b.fall_started_us(),
            Body::Kinematic(p) => p.fall_started_us(),
        }
    }

    /// When the robot came to lie on the ground, µs.
    pub fn fallen_at_us(&self) -> Option<u64> {
        match self {
            Body::MuJoCo(b) => b.fallen_at_us(),
            Body::Kinematic(p) => p.fallen_at_us(),
        }
    }

    /// Largest distance of the true ZMP outside the support polygon before any fall, m.
    pub fn max_outside(&self) -> f64 {
        match self {
            Body::MuJoCo(b) => b.max_outside,
            Body::Kinematic(p) => p.max_outside,
        }
    }

    /// The kinematic model, if that is the body.
    pub fn kinematic(&self) -> Option<&Physics> {
        match self {
            Body::Kinematic(p) => Some(p),
            Body::MuJoCo(_) => None,
        }
    }

    /// The MuJoCo robot, if that is the body.
    pub fn mujoco(&mut self) -> Option<&mut MjBody> {
        match self {
            Body::MuJoCo(b) => Some(b),
            Body::Kinematic(_) => None,
        }
    }
}

/// Bus devices plus body, independent of the transport (used by [`transport`] and tests).
pub struct Simulator {
    /// The bus and its devices.
    pub bus: DeviceBus,
    /// The body.
    pub physics: Body,
    decoder: Box<Decoder<4096>>,
    noise_rng: rng::Rng,
    cfg: SimConfig,
    log: Option<truth::TruthLog>,
    next_log_us: u64,
    qpos_log: Option<csv::Writer<std::fs::File>>,
    next_qpos_us: u64,
    /// Sensor samples waiting out the configured latency: (time µs, foot samples, IMU sample).
    delayed: std::collections::VecDeque<(u64, [FootForces; 2], ImuSample)>,
    /// Joint angles and speeds waiting out the Present Position latency: (time µs, q, q̇).
    delayed_joints: std::collections::VecDeque<(u64, [f64; 12], [f64; 12])>,
    counter: u16,
    steps: u64,
    bytes_in: u64,
    /// When a leg servo first had its torque on, µs.
    torque_on_us: Option<u64>,
    /// When every servo's torque was last found off after it had been on, µs.
    torque_off_us: Option<u64>,
    /// The robot's rad ↔ tick map (the contract's one definition, the description's signs).
    ticks: TickMap,
    /// Where the foot boards and the bus IMU are in [`DeviceBus::devices`] (after the 12 leg
    /// servos), when the robot has them.
    foot_index: Option<[usize; 2]>,
    imu_index: Option<usize>,
    /// The controller board's IMU chip, turned in the trunk so, when the robot's IMU is the
    /// board's ([`transport`]'s SPI frames).
    board_chip: Option<(gait_core::robot::ImuAxes, chip::Mpu9250Chip)>,
}

impl fmt::Debug for Simulator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Simulator")
            .field("time_us", &self.physics.time_us())
            .field("counters", &self.bus.counters)
            .finish_non_exhaustive()
    }
}

/// The leg servos come first in [`DeviceBus::devices`], in joint order.
const LEG_SERVOS: usize = gait_core::robot::LEG_JOINTS;

impl Simulator {
    /// A simulator at time 0 (opens the truth CSV if asked).
    pub fn new(cfg: &SimConfig) -> Result<Self, SimError> {
        cfg.validate()?;
        let physics = Body::new(cfg)?;
        let bus = cfg.robot.bus;
        let ticks = TickMap::from_robot(&cfg.robot);
        let mut devices: Vec<Device> = bus
            .legs
            .iter()
            .enumerate()
            .map(|(j, &id)| Device::servo(id, j, ticks.tick_f64(j, physics.q()[j])))
            .collect();
        let foot_index = bus.foot_boards.map(|feet| {
            let first = devices.len();
            for (side, id) in feet.into_iter().enumerate() {
                devices.push(Device::foot(id, side));
            }
            [first, first + 1]
        });
        let imu_index = match bus.imu {
            ImuPlace::Bus(id) => {
                devices.push(Device::imu(id));
                Some(devices.len() - 1)
            }
            ImuPlace::Board(_) => None,
        };
        let board_chip = match bus.imu {
            ImuPlace::Board(axes) => Some((axes, chip::Mpu9250Chip::new())),
            ImuPlace::Bus(_) => None,
        };
        for (k, h) in bus.held.iter().enumerate() {
            // Joint index past the legs; the servo's own direction (no mounting sign).
            let tick = ticks.servo_tick_f64(h.angle);
            devices.push(Device::servo(h.id, LEG_SERVOS + k, tick));
        }
        let bus = DeviceBus::new(devices, cfg.faults.clone(), rng::Rng::new(cfg.seed, 1));
        let log = match &cfg.log_truth {
            Some(p) => Some(truth::TruthLog::create(p)?),
            None => None,
        };
        let qpos_log = match (&cfg.qpos_out, &physics) {
            (Some(p), Body::MuJoCo(b)) => {
                let mut w = csv::Writer::from_writer(std::fs::File::create(p)?);
                let cols = (0..b.qpos().len()).map(|i| format!("qpos_{i}"));
                w.write_record(std::iter::once("t_s".to_string()).chain(cols))
                    .map_err(std::io::Error::from)?;
                Some(w)
            }
            _ => None,
        };
        let mut sim = Simulator {
            bus,
            physics,
            decoder: Box::new(Decoder::new()),
            noise_rng: rng::Rng::new(cfg.seed, 2),
            cfg: cfg.clone(),
            log,
            next_log_us: 0,
            qpos_log,
            next_qpos_us: 0,
            delayed: std::collections::VecDeque::new(),
            delayed_joints: std::collections::VecDeque::new(),
            counter: 0,
            steps: 0,
            bytes_in: 0,
            torque_on_us: None,
            torque_off_us: None,
            ticks,
            foot_index,
            imu_index,
            board_chip,
        };
        sim.publish()?;
        Ok(sim)
    }

    /// Simulated time, µs.
    pub fn time_us(&self) -> u64 {
        self.physics.time_us()
    }

    /// The servo registers the MuJoCo servo model reads (`None`: dead device).
    fn servo_registers(&self) -> [Option<XServoRegisters>; 12] {
        std::array::from_fn(|j| {
            let d = &self.bus.devices[j];
            let u16f = |f: dxl::table::Field| d.get_u16(f);
            (!d.dead).then(|| XServoRegisters {
                torque_on: d.torque_on(),
                goal: d.get_i32(x_series::GOAL_POSITION),
                p_gain: u16f(x_series::POSITION_P_GAIN),
                i_gain: u16f(x_series::POSITION_I_GAIN),
                d_gain: u16f(x_series::POSITION_D_GAIN),
                pwm_limit: u16f(x_series::PWM_LIMIT),
                profile_velocity: d.get_i32(x_series::PROFILE_VELOCITY) as u32,
                profile_acceleration: d.get_i32(x_series::PROFILE_ACCELERATION) as u32,
            })
        })
    }

    /// Runs the physics up to `t_us` (whole steps; earlier times are ignored).
    pub fn advance_to(&mut self, t_us: u64) -> Result<(), SimError> {
        let dt = self.cfg.physics_dt_us;
        while self.physics.time_us() + dt <= t_us {
            if !self.cfg.faults.outages.is_empty() {
                self.bus.apply_outages(self.physics.time_us() + dt);
            }
            match &mut self.physics {
                Body::MuJoCo(_) => {
                    let regs = self.servo_registers();
                    if let Body::MuJoCo(b) = &mut self.physics {
                        b.step(&regs);
                    }
                }
                Body::Kinematic(_) => {
                    let cmds: [ServoCmd; 12] = std::array::from_fn(|j| {
                        let d = &self.bus.devices[j];
                        let profile = d.get_i32(x_series::PROFILE_VELOCITY);
                        let mut limit = self.cfg.servo_speed_limit;
                        if profile > 0 {
                            let rad_s = profile as f64
                                * f64::from(x_series::VELOCITY_UNIT_RPM)
                                * std::f64::consts::TAU
                                / 60.0;
                            limit = limit.min(rad_s);
                        }
                        ServoCmd {
                            goal: (d.torque_on() && !d.dead)
                                .then(|| self.ticks.rad_f64(j, d.get_i32(x_series::GOAL_POSITION))),
                            speed_limit: limit,
                        }
                    });
                    if let Body::Kinematic(p) = &mut self.physics {
                        p.step(&cmds);
                    }
                }
            }
            self.steps += 1;
            if self.bus.devices.iter().any(|d| d.torque_on()) {
                self.torque_on_us.get_or_insert(self.physics.time_us());
                self.torque_off_us = None;
            } else if self.torque_on_us.is_some() && self.torque_off_us.is_none() {
                self.torque_off_us = Some(self.physics.time_us());
            }
            self.publish()?;
        }
        Ok(())
    }

    /// Writes the present state into the device tables and the truth log.
    fn publish(&mut self) -> Result<(), SimError> {
        let volts = self.cfg.xservo.supply_voltage;
        // Present Position latency: the newest joint state at least `position_latency_us` old
        // (the oldest there is during the first steps).
        let now = self.physics.time_us();
        let (mut q_seen, mut qd_seen) = (*self.physics.q(), *self.physics.qd());
        let lat = self.cfg.noise.position_latency_us;
        if lat > 0 {
            self.delayed_joints.push_back((now, q_seen, qd_seen));
            while self
                .delayed_joints
                .get(1)
                .is_some_and(|&(ts, _, _)| ts + lat <= now)
            {
                self.delayed_joints.pop_front();
            }
            if let Some(&(_, q, qd)) = self.delayed_joints.front() {
                (q_seen, qd_seen) = (q, qd);
            }
        }
        for j in 0..12 {
            let (q, qd) = (q_seen[j], qd_seen[j]);
            let out = match &self.physics {
                Body::MuJoCo(b) => b.outputs()[j],
                Body::Kinematic(_) => XServoOutput::default(),
            };
            let d = &mut self.bus.devices[j];
            let ticks = self.ticks.tick_f64(j, q);
            d.set_i32(x_series::PRESENT_POSITION, ticks);
            // The servo's own direction: the mounting sign (±1, exact).
            let sign = f64::from(self.ticks.sign.get(j).copied().unwrap_or(1));
            let rpm = sign * qd * 60.0 / std::f64::consts::TAU;
            d.set_i32(
                x_series::PRESENT_VELOCITY,
                (rpm / f64::from(x_series::VELOCITY_UNIT_RPM)).round() as i32,
            );
            let ma = out.current * 1000.0 / f64::from(x_series::CURRENT_UNIT_MA);
            d.set(
                x_series::PRESENT_CURRENT,
                &(ma.round().clamp(-32768.0, 32767.0) as i16).to_le_bytes(),
            );
            d.set(x_series::PRESENT_PWM, &out.pwm.to_le_bytes());
            d.set(
                x_series::PRESENT_INPUT_VOLTAGE,
                &((volts * 10.0).round() as u16).to_le_bytes(),
            );
            let moving = d.torque_on() && (d.get_i32(x_series::GOAL_POSITION) - ticks).abs() > 1;
            d.set(x_series::MOVING, &[u8::from(moving)]);
        }
        let t = *self.physics.truth();
        self.counter = self.counter.wrapping_add(1);
        let nz = self.cfg.noise.clone();
        let mut feet = [FootForces {
            forces_mn: [0; 4],
            counter: self.counter,
        }; 2];
        for (foot, side_forces) in feet.iter_mut().zip(t.forces) {
            for (fi, v) in foot.forces_mn.iter_mut().zip(side_forces) {
                let noise = if nz.force_std_n > 0.0 {
                    self.noise_rng.gaussian() * nz.force_std_n
                } else {
                    0.0
                };
                *fi = ((v + noise) * 1000.0).round() as i32;
            }
        }
        let mut gyro = [0f32; 3];
        let mut accel = [0f32; 3];
        for k in 0..3 {
            let ng = if nz.gyro_std_rad_s > 0.0 {
                self.noise_rng.gaussian() * nz.gyro_std_rad_s
            } else {
                0.0
            };
            let na = if nz.accel_std_m_s2 > 0.0 {
                self.noise_rng.gaussian() * nz.accel_std_m_s2
            } else {
                0.0
            };
            gyro[k] = (t.gyro[k] + nz.gyro_bias_rad_s[k] + ng) as f32;
            accel[k] = (t.accel[k] + nz.accel_bias_m_s2[k] + na) as f32;
        }
        let imu = ImuSample::from_si(gyro, accel, self.counter);
        // Latency: publish the newest sample at least `latency_us` old.
        let now = self.physics.time_us();
        self.delayed.push_back((now, feet, imu));
        let mut out = None;
        while let Some(&(ts, _, _)) = self.delayed.front() {
            if ts + nz.latency_us <= now {
                out = self.delayed.pop_front();
            } else {
                break;
            }
        }
        if let Some((_, feet, imu)) = out {
            if let Some(index) = self.foot_index {
                for (i, s) in index.into_iter().zip(feet) {
                    self.bus.devices[i].set(dxl::table::foot::SAMPLE, &s.to_bytes());
                }
            }
            if let Some(i) = self.imu_index {
                self.bus.devices[i].set(dxl::table::imu::SAMPLE, &imu.to_bytes());
            }
            if let Some((axes, chip)) = &mut self.board_chip {
                let si = |v: [i32; 3]| axes.to_chip_f64(v.map(|x| f64::from(x) * 1e-6));
                chip.measure(walker_contract::mpu9250::Reading {
                    gyro_rad_s: si(imu.gyro_urad_s),
                    accel_m_s2: si(imu.accel_um_s2),
                });
            }
        }
        // Held servos: at their goal while torque is on.
        for d in self.bus.devices.iter_mut().skip(LEG_SERVOS) {
            if matches!(d.kind, DeviceKind::Servo { .. }) && d.torque_on() {
                let goal = d.get_i32(x_series::GOAL_POSITION);
                d.set_i32(x_series::PRESENT_POSITION, goal);
                d.set(
                    x_series::PRESENT_INPUT_VOLTAGE,
                    &((volts * 10.0).round() as u16).to_le_bytes(),
                );
            }
        }
        if let Some(log) = &mut self.log {
            if t.t_us >= self.next_log_us {
                log.row(&t)?;
                self.next_log_us = t.t_us + self.cfg.log_every_us.max(1);
            }
        }
        if let (Some(w), Body::MuJoCo(b)) = (&mut self.qpos_log, &self.physics) {
            if now >= self.next_qpos_us {
                w.write_field(format!("{:.4}", now as f64 * 1e-6))
                    .map_err(std::io::Error::from)?;
                for v in b.qpos() {
                    w.write_field(format!("{v:.5}"))
                        .map_err(std::io::Error::from)?;
                }
                w.write_record(None::<&[u8]>)
                    .map_err(std::io::Error::from)?;
                self.next_qpos_us = now + 10_000;
            }
        }
        Ok(())
    }

    /// One SPI transfer with the controller board's IMU chip: `mosi` in, a byte out for each
    /// (zeros where the robot has no such chip: nothing drives the line).
    pub fn spi(&mut self, mosi: &[u8]) -> Vec<u8> {
        match &mut self.board_chip {
            Some((_, chip)) => chip.transfer(mosi),
            None => vec![0; mosi.len()],
        }
    }

    /// Feeds one bus byte; returns a packet when one completes.
    pub fn push_byte(&mut self, b: u8) -> Option<Incoming> {
        self.bytes_in += 1;
        match self.decoder.push(b)? {
            Ok(p) => Some(Incoming::Packet(OwnedPacket::from_packet(&p))),
            Err(DecodeError::Crc { id }) => Some(Incoming::CrcError(id)),
            Err(_) => None,
        }
    }

    /// Executes a packet; returns the bytes to write on the bus, or `None` when the packet is
    /// not an instruction (a status packet: no lock-step acknowledgement either).
    pub fn respond(&mut self, inc: &Incoming) -> Option<Vec<u8>> {
        match inc {
            Incoming::Packet(p) => self.bus.handle(&p.packet()),
            Incoming::CrcError(id) => Some(self.bus.handle_crc_error(*id)),
        }
    }

    /// Feeds bytes and answers every instruction in them; returns the replies in order.
    pub fn feed(&mut self, bytes: &[u8]) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        for &b in bytes {
            if let Some(inc) = self.push_byte(b) {
                if let Some(r) = self.respond(&inc) {
                    out.push(r);
                }
            }
        }
        out
    }

    /// Runs [`SimConfig::after_end_us`] on after the firmware's end (the truth rows into
    /// [`SimConfig::after_truth`]) and says how the robot ended.
    pub fn after_end(&mut self) -> Result<Option<EndPose>, SimError> {
        if self.cfg.after_end_us == 0 {
            return Ok(None);
        }
        if let Some(l) = &mut self.log {
            l.flush()?;
        }
        self.log = match &self.cfg.after_truth {
            Some(p) => Some(truth::TruthLog::create(p)?),
            None => None,
        };
        let end = self.physics.time_us() + self.cfg.after_end_us;
        self.advance_to(end)?;
        if let Some(l) = &mut self.log {
            l.flush()?;
        }
        let z_c = gait_core::ForwardWalk::table2().z_c;
        Ok(Some(EndPose::of(
            self.physics.truth(),
            z_c,
            self.cfg.after_end_us as f64 * 1e-6,
        )))
    }

    /// The run's summary so far (flushes the truth log).
    pub fn summary(&mut self) -> SimSummary {
        let rows = self.log.as_mut().map_or(0, |l| {
            let _ = l.flush();
            l.rows()
        });
        if let Some(w) = &mut self.qpos_log {
            let _ = w.flush();
        }
        SimSummary {
            sim_time_us: self.physics.time_us(),
            physics_steps: self.steps,
            bus: self.bus.counters,
            bytes_in: self.bytes_in,
            lockstep: self.cfg.lockstep_port.is_some() || self.cfg.lockstep_pipe.is_some(),
            lockstep_messages: 0,
            lockstep_errors: 0,
            fall_started_us: self.physics.fall_started_us(),
            fallen_at_us: self.physics.fallen_at_us(),
            max_zmp_outside_m: self.physics.max_outside(),
            truth_rows: rows,
            end: None,
            torque_on_us: self.torque_on_us,
            torque_off_us: self.torque_off_us,
        }
    }
}
