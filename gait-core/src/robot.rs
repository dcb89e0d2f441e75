//! The robot description: masses, geometry, joint limits and signs, servo limits and the bus
//! (servo IDs, sensors, held servos) in one value.
//!
//! Two robots are described, each in its own module and nowhere else: [`Robot::reference`]
//! ([`tku_x`]) is the TKU-X class robot of `shared/reference-robot.md` (masses from seed 000
//! Table 1; geometry assumed there), [`Robot::op3`] ([`op3`]) the ROBOTIS OP3 (MuJoCo
//! Menagerie's `robotis_op3/op3.xml`, ROBOTIS-OP3's `op3_manager/config/OP3.robot`).
//! [`Robot::by_name`] selects one by name. Every other module takes its numbers from a
//! `Robot`, never from literals.
//!
//! Frames: world x forward, y left, z up. Joint order per leg: `hip_yaw` (z), `hip_roll` (x),
//! `hip_pitch` (y), `knee` (y), `ankle_pitch` (y), `ankle_roll` (x); zero = straight leg with the
//! sole flat and parallel to the pelvis; positive = right-hand rule about the axis in the pelvis
//! frame at the zero pose (knee flexion > 0).

use crate::error::GaitError;

pub mod op3;
pub mod tku_x;

/// Number of joints of one leg.
pub const JOINTS_PER_LEG: usize = 6;
/// Number of leg joints of the robot (left leg then right leg).
pub const LEG_JOINTS: usize = 2 * JOINTS_PER_LEG;
/// Index of `hip_pitch` within a leg's joints.
pub const HIP_PITCH: usize = 2;
/// Index of `knee` within a leg's joints.
pub const KNEE: usize = 3;
/// Index of `ankle_pitch` within a leg's joints.
pub const ANKLE_PITCH: usize = 4;
/// Index of `ankle_roll` within a leg's joints.
pub const ANKLE_ROLL: usize = 5;

/// Joint names as used in logs and CSV files (left leg, then right leg).
pub const JOINT_NAMES: [&str; LEG_JOINTS] = [
    "l_hip_yaw",
    "l_hip_roll",
    "l_hip_pitch",
    "l_knee",
    "l_ankle_pitch",
    "l_ankle_roll",
    "r_hip_yaw",
    "r_hip_roll",
    "r_hip_pitch",
    "r_knee",
    "r_ankle_pitch",
    "r_ankle_roll",
];

/// The joint limits of the walking workspace, left leg, joint order (both described robots;
/// the mechanical ranges are wider): positive roll moves the left foot outward (+y).
pub const WALKING_LIMITS: [JointLimit; JOINTS_PER_LEG] = [
    JointLimit {
        min: -0.9,
        max: 0.9,
    }, // hip_yaw
    JointLimit {
        min: -0.5,
        max: 0.7,
    }, // hip_roll
    JointLimit {
        min: -1.9,
        max: 0.9,
    }, // hip_pitch
    JointLimit { min: 0.0, max: 2.5 }, // knee
    JointLimit {
        min: -1.3,
        max: 1.1,
    }, // ankle_pitch
    JointLimit {
        min: -0.7,
        max: 0.5,
    }, // ankle_roll
];

/// Every described robot (one copy in flash: a configuration refers to one of them).
pub static ROBOTS: [Robot; 2] = [tku_x::TKU_X, op3::OP3];
/// The names [`Robot::by_name`] takes.
pub const ROBOT_NAMES: [&str; 2] = [tku_x::TKU_X.name, op3::OP3.name];

/// Which leg / foot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Side {
    /// The left leg (+y side).
    Left,
    /// The right leg (−y side).
    Right,
}

impl Side {
    /// The other leg.
    pub fn other(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
    /// +1 for the left leg, −1 for the right leg (the sign of its lateral offset).
    pub fn sign(self) -> f64 {
        match self {
            Side::Left => 1.0,
            Side::Right => -1.0,
        }
    }
    /// This leg's element of a (left, right) pair (no indexing).
    pub fn of<T>(self, pair: &[T; 2]) -> &T {
        let [l, r] = pair;
        match self {
            Side::Left => l,
            Side::Right => r,
        }
    }
    /// [`Side::of`], mutable.
    pub fn of_mut<T>(self, pair: &mut [T; 2]) -> &mut T {
        let [l, r] = pair;
        match self {
            Side::Left => l,
            Side::Right => r,
        }
    }
    /// Index of the leg in left-then-right arrays (0 left, 1 right).
    pub fn index(self) -> usize {
        match self {
            Side::Left => 0,
            Side::Right => 1,
        }
    }
}

/// True for the joints whose right-leg limits are the left's mirrored, [−max, −min]: hip yaw,
/// hip roll, ankle roll ([`Robot::joint_limit`]).
pub const fn mirrored_limit(j: usize) -> bool {
    matches!(j, 0 | 1 | 5)
}

/// Lower and upper limit of one joint, rad.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimit {
    /// Lowest allowed angle, rad.
    pub min: f64,
    /// Highest allowed angle, rad.
    pub max: f64,
}

/// Masses of the robot (seed 000 Table 1), kg, and where the multi-body model puts them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Masses {
    /// Upper body M_u (head, trunk, arms), kg.
    pub upper_body: f64,
    /// Height l_u of the upper-body mass above the pelvis point P, m.
    pub upper_body_height: f64,
    /// Thigh m_t, each leg, kg (on the hip–knee line, [`Masses::thigh_com`]).
    pub thigh: f64,
    /// Calf, each leg, kg (on the knee–ankle line, [`Masses::calf_com`]).
    pub calf: f64,
    /// Sole, each leg, kg ([`Masses::sole_height`] above the ground, [`Masses::sole_com`]
    /// from the sole point).
    pub sole: f64,
    /// Height of the sole mass above the ground, m.
    pub sole_height: f64,
    /// Where the thigh's mass sits: its share of the way from the hip to the knee (0.5: the
    /// middle; the pendulum models' constants keep the seed's fractions).
    pub thigh_com: f64,
    /// Where the calf's mass sits: its share of the way from the knee to the ankle.
    pub calf_com: f64,
    /// The sole mass's offset from the sole point, foot frame: (forward, outward), m; the
    /// outward offset is +y on the left foot and −y on the right.
    pub sole_com: [f64; 2],
    /// The links' rotational inertias where a source gives them (`None`: the simulator
    /// assumes rods, a box and the upper body's roll and yaw from J).
    pub inertias: Option<&'static LinkInertias>,
    /// Upper-body rotational inertia J about the pitch axis, kg·m² (τ = J·φ̈, seed 000 eq 1).
    pub upper_body_inertia: f64,
    /// Forward offset of the upper-body mass from the pelvis point P, pelvis frame, m (the
    /// whole-body compensation puts it there; the pendulum models keep it over P).
    pub upper_body_forward: f64,
}

/// Moments of inertia of the lumped links about their own centres of mass and the link frame's
/// axes at the zero pose (x forward, y left, z up; the left leg's, the right mirrored; products
/// of inertia left out), kg·m².
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkInertias {
    /// The upper body's about x (roll) and z (yaw); its pitch moment is
    /// [`Masses::upper_body_inertia`].
    pub upper_body_roll_yaw: [f64; 2],
    /// A thigh's (x, y, z).
    pub thigh: [f64; 3],
    /// A calf's (x, y, z).
    pub calf: [f64; 3],
    /// A sole lump's (x, y, z).
    pub sole: [f64; 3],
}

impl LinkInertias {
    /// Every moment, in one list (for the checks).
    fn all(&self) -> [f64; 11] {
        let [r, y] = self.upper_body_roll_yaw;
        let [a, b, c] = self.thigh;
        let [d, e, f] = self.calf;
        let [g, h, i] = self.sole;
        [r, y, a, b, c, d, e, f, g, h, i]
    }
}

impl Masses {
    /// TLIPFM's m_c: calf plus sole of one leg, kg.
    pub fn calf_and_sole(&self) -> f64 {
        self.calf + self.sole
    }
    /// Mass of one whole leg, kg.
    pub fn leg(&self) -> f64 {
        self.thigh + self.calf + self.sole
    }
    /// Mass of the whole robot, kg.
    pub fn total(&self) -> f64 {
        self.upper_body + 2.0 * self.leg()
    }
}

/// Leg and foot geometry, m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geometry {
    /// Lateral offset of each hip joint from the pelvis point P (left +, right −), m.
    pub hip_offset_y: f64,
    /// Thigh length, hip to knee, m.
    pub thigh: f64,
    /// Calf length, knee to ankle, m.
    pub calf: f64,
    /// Height of the ankle joint above the sole, m.
    pub ankle_height: f64,
    /// The sole point S (the foot's reference point: the centre of the sole rectangle, on the
    /// ground) from the ankle's ground projection, foot frame: (forward, outward), m; the
    /// outward offset is +y on the left foot and −y on the right.
    pub sole_offset: [f64; 2],
    /// Height of the hip yaw joint above the hip point (where the roll and pitch axes meet),
    /// m: the yaw axis is vertical through the hip point, so only the body's shape needs it.
    pub hip_yaw_height: f64,
    /// Sole length (x), centred on the sole point, m.
    pub sole_length: f64,
    /// Sole width (y), centred on the sole point, m.
    pub sole_width: f64,
    /// Force sensor positions (x, y) relative to the sole point, foot frame, m.
    /// Order: front-left, front-right, rear-left, rear-right.
    pub force_sensors: [[f64; 2]; 4],
}

impl Geometry {
    /// Height of the pelvis point above the ground with straight legs, m.
    pub fn straight_leg_height(&self) -> f64 {
        self.thigh + self.calf + self.ankle_height
    }
}

/// Servo characteristics shared by the 12 leg servos.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServoLimits {
    /// Highest joint speed the servo can follow, rad/s (no-load speed of an XM430 ≈ 4.8).
    pub max_speed: f64,
    /// Encoder ticks per turn.
    pub ticks_per_turn: u32,
    /// Tick that stands for 0 rad.
    pub zero_tick: i32,
}

/// Where the robot's IMU (gyro and accelerometer) is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImuPlace {
    /// A Dynamixel 2.0 device on the servo bus with this ID (a waist sensor board), reporting
    /// in the trunk's axes.
    Bus(u8),
    /// On the controller board itself (the OpenCR's IMU), the chip turned in the trunk as
    /// these axes say.
    Board(ImuAxes),
}

/// How an IMU chip's axes lie in the trunk frame (x forward, y left, z up): trunk axis `i`
/// is `sign[i]` times chip axis `axis[i]`, a signed permutation
///
/// ```text
///   v_trunk[i] = sign[i] · v_chip[axis[i]]                     (I1)
///   v_chip[axis[i]] = sign[i] · v_trunk[i]                     (I2, its inverse)
/// ```
///
/// ([`ImuAxes::is_rotation`]: a proper rotation, no mirror). For the gyroscope and the
/// accelerometer alike.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImuAxes {
    /// The chip axis (0 x, 1 y, 2 z) each trunk axis reads.
    pub axis: [u8; 3],
    /// Its sign, ±1.
    pub sign: [i8; 3],
}

impl ImuAxes {
    /// The chip's axes are the trunk's.
    pub const ALIGNED: ImuAxes = ImuAxes {
        axis: [0, 1, 2],
        sign: [1, 1, 1],
    };

    /// True when the axes are a permutation with signs ±1 and a determinant of +1 (a turn of
    /// the chip, not a mirror image).
    pub fn is_rotation(&self) -> bool {
        let [a, b, c] = self.axis;
        let perm_ok = a < 3 && b < 3 && c < 3 && a != b && b != c && a != c;
        let signs_ok = self.sign.iter().all(|&s| s == 1 || s == -1);
        if !(perm_ok && signs_ok) {
            return false;
        }
        // The permutation's parity: even for the cyclic orders of (0, 1, 2).
        let even = matches!((a, b, c), (0, 1, 2) | (1, 2, 0) | (2, 0, 1));
        let sign_product: i32 = self.sign.iter().map(|&s| i32::from(s)).product();
        (if even { 1 } else { -1 }) * sign_product == 1
    }

    /// A chip vector in trunk axes (I1); integer units, saturating (−i32::MIN is i32::MAX).
    pub fn to_trunk_i32(&self, chip: [i32; 3]) -> [i32; 3] {
        core::array::from_fn(|i| {
            let a = self.axis.get(i).map_or(0, |&a| usize::from(a));
            let v = chip.get(a).copied().unwrap_or(0);
            if self.sign.get(i).is_some_and(|&s| s < 0) {
                v.saturating_neg()
            } else {
                v
            }
        })
    }

    /// A trunk vector in chip axes (I2).
    pub fn to_chip_f64(&self, trunk: [f64; 3]) -> [f64; 3] {
        let mut chip = [0.0; 3];
        for ((&a, &s), &v) in self.axis.iter().zip(&self.sign).zip(&trunk) {
            if let Some(c) = chip.get_mut(usize::from(a)) {
                *c = f64::from(s) * v;
            }
        }
        chip
    }
}

/// A servo that is not a leg joint and is held at one angle while the robot walks (arms,
/// head): torque on, that pose, monitored like the legs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeldServo {
    /// Joint name in logs.
    pub name: &'static str,
    /// Dynamixel ID.
    pub id: u8,
    /// The held angle in the servo's own direction, rad (tick = zero tick + angle · ticks/rad).
    pub angle: f64,
}

/// The upper body's collision shape (the simulator's fall detection and video): two boxes
/// and a head sphere, in the pelvis frame from P, m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyShape {
    /// The pelvis box: half sizes, centre.
    pub pelvis: [[f64; 3]; 2],
    /// The trunk box: half sizes, centre.
    pub trunk: [[f64; 3]; 2],
    /// The head sphere: radius, centre height above P.
    pub head: [f64; 2],
}

/// The robot's servo bus: speed, who is on it and what each ID is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BusDescription {
    /// Baud rate, bit/s.
    pub baud: u32,
    /// Leg servo IDs in joint order, left leg then right leg ([`JOINT_NAMES`]).
    pub legs: [u8; LEG_JOINTS],
    /// The foot sensor boards (left, right), each reporting four forces; `None` when the robot
    /// has no foot sensors.
    pub foot_boards: Option<[u8; 2]>,
    /// Where the IMU is.
    pub imu: ImuPlace,
    /// The other servos, held at a pose.
    pub held: &'static [HeldServo],
}

/// The robot description: everything the gait, the kinematics and the simulator need.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Robot {
    /// The robot's name as [`Robot::by_name`] takes it.
    pub name: &'static str,
    /// Masses and their positions.
    pub masses: Masses,
    /// Leg and foot geometry.
    pub geometry: Geometry,
    /// Joint limits of one leg in joint order; the right leg mirrors roll and yaw (see
    /// [`Robot::joint_limit`]).
    pub joint_limits: [JointLimit; JOINTS_PER_LEG],
    /// Servo limits.
    pub servo: ServoLimits,
    /// Mounting of each leg joint's servo, left leg then right leg: +1 when the joint's
    /// positive direction (right-hand rule about +x, +y or +z of the pelvis frame at the zero
    /// pose) is the servo's positive direction, −1 when it is the opposite.
    pub mounting: [i8; LEG_JOINTS],
    /// Each leg servo's zero offset, left leg then right leg, ticks: the servo reads
    /// `zero_tick + zero_offsets[j]` when joint j is at 0 rad (a calibration, within ±127
    /// ticks: ±11° on a 4096-tick servo; 0 on a robot assembled to its drawings).
    pub zero_offsets: [i8; LEG_JOINTS],
    /// The servo bus.
    pub bus: BusDescription,
    /// The upper body's collision shape.
    pub shape: &'static BodyShape,
    /// Gravity g, m/s².
    pub gravity: f64,
}

impl Default for Robot {
    fn default() -> Self {
        Self::reference()
    }
}

impl Robot {
    /// The reference robot of `shared/reference-robot.md` (TKU-X class).
    pub const fn reference() -> Robot {
        tku_x::TKU_X
    }

    /// The ROBOTIS OP3.
    pub const fn op3() -> Robot {
        op3::OP3
    }

    /// The described robot called `name` ([`ROBOT_NAMES`]), `None` for another name.
    pub fn by_name(name: &str) -> Option<&'static Robot> {
        ROBOTS.iter().find(|r| r.name == name)
    }

    /// Limits of joint `j` (0..6, joint order) of leg `side`. The right leg mirrors the left
    /// leg's yaw and roll limits (a motion outward is positive roll on the left, negative on the
    /// right).
    pub fn joint_limit(&self, side: Side, j: usize) -> JointLimit {
        let l = match self.joint_limits.get(j) {
            Some(l) => *l,
            None => return JointLimit { min: 0.0, max: 0.0 },
        };
        if side == Side::Right && mirrored_limit(j) {
            JointLimit {
                min: -l.max,
                max: -l.min,
            }
        } else {
            l
        }
    }

    /// Checks that every number is finite and every mass, length and limit makes sense.
    pub fn validate(&self) -> Result<(), GaitError> {
        let m = &self.masses;
        let g = &self.geometry;
        let all = [
            m.upper_body,
            m.upper_body_height,
            m.thigh,
            m.calf,
            m.sole,
            m.sole_height,
            m.upper_body_inertia,
            m.upper_body_forward,
            m.thigh_com,
            m.calf_com,
            m.sole_com[0],
            m.sole_com[1],
            g.hip_offset_y,
            g.thigh,
            g.calf,
            g.ankle_height,
            g.sole_offset[0],
            g.sole_offset[1],
            g.hip_yaw_height,
            g.sole_length,
            g.sole_width,
            self.servo.max_speed,
            self.gravity,
        ];
        if all.iter().any(|v| !v.is_finite()) {
            return Err(GaitError::NonFinite);
        }
        if g.force_sensors.iter().flatten().any(|v| !v.is_finite()) {
            return Err(GaitError::NonFinite);
        }
        if m.upper_body <= 0.0 || m.thigh < 0.0 || m.calf < 0.0 || m.sole < 0.0 {
            return Err(GaitError::NonPositiveMass);
        }
        if m.upper_body_inertia < 0.0 {
            return Err(GaitError::NonPositiveMass);
        }
        if let Some(i) = &m.inertias {
            if i.all().iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(GaitError::NonPositiveMass);
            }
        }
        if !((0.0..=1.0).contains(&m.thigh_com) && (0.0..=1.0).contains(&m.calf_com)) {
            return Err(GaitError::NonPositiveLength);
        }
        if g.thigh <= 0.0 || g.calf <= 0.0 || g.ankle_height < 0.0 || g.sole_length <= 0.0 {
            return Err(GaitError::NonPositiveLength);
        }
        if g.sole_width <= 0.0 || g.hip_offset_y < 0.0 || m.upper_body_height < 0.0 {
            return Err(GaitError::NonPositiveLength);
        }
        if self.gravity <= 0.0 || self.servo.max_speed <= 0.0 || self.servo.ticks_per_turn == 0 {
            return Err(GaitError::NonPositiveParameter);
        }
        if self
            .joint_limits
            .iter()
            .any(|l| !(l.min.is_finite() && l.max.is_finite() && l.min < l.max))
        {
            return Err(GaitError::BadJointLimit);
        }
        Ok(())
    }

    /// Checks the bus and the mounting: every ID used once and a valid Dynamixel ID
    /// (0..=252), every mounting sign ±1, a baud rate above 0, a board IMU's axes a turn
    /// ([`ImuAxes::is_rotation`]). ([`Robot::validate`] checks what the gait and the kinematics
    /// read; this, what the bus, the tick map and the sensors read.)
    pub fn validate_bus(&self) -> Result<(), GaitError> {
        let imu_ok = match self.bus.imu {
            ImuPlace::Bus(_) => true,
            ImuPlace::Board(axes) => axes.is_rotation(),
        };
        if self.mounting.iter().any(|&s| s != 1 && s != -1)
            || self.bus.baud == 0
            || !self.bus_ids_unique()
            || !imu_ok
        {
            return Err(GaitError::BadRobotDescription);
        }
        Ok(())
    }

    /// Every device ID on the bus: legs, foot boards, a bus IMU, held servos (in that order);
    /// calls `f` with each.
    pub fn for_each_bus_id(&self, mut f: impl FnMut(u8)) {
        let b = &self.bus;
        b.legs.iter().for_each(|&id| f(id));
        if let Some(feet) = b.foot_boards {
            feet.iter().for_each(|&id| f(id));
        }
        if let ImuPlace::Bus(id) = b.imu {
            f(id);
        }
        b.held.iter().for_each(|h| f(h.id));
    }

    /// True when no two devices share an ID and none is the broadcast ID 254 or above 252.
    pub fn bus_ids_unique(&self) -> bool {
        let mut seen = [false; 256];
        let mut ok = true;
        self.for_each_bus_id(|id| {
            let slot = seen.get_mut(usize::from(id));
            match slot {
                Some(s) if !*s && id <= 252 => *s = true,
                _ => ok = false,
            }
        });
        ok
    }
}
