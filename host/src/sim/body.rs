//! The simulated body: servo dynamics, stance-leg kinematics, support switching, whole-body
//! ZMP, foot forces, IMU signals, the upper-body disturbance and falls.
//!
//! # Model (documented simplifications)
//!
//! * **Servos**: position-controlled; each joint follows its goal `g` (clamped to the robot's
//!   joint limits, the mechanical stops) as the closed position loop of a motor driving an inertia,
//!   a second-order system `q̈ = ω²·(g − q) − 2ζω·q̇` (ω = 2π·`servo_frequency_hz`, ζ =
//!   `servo_damping`) with `|q̇| ≤ v_max` (`v_max` = the configured speed limit, lowered by a
//!   non-zero Profile Velocity), integrated in sub-steps of at most 1/(100 ω). The joint velocity
//!   is continuous and the acceleration finite, so a goal staircase (the firmware's 1-tick =
//!   1.5 mrad rounding) does not kick the body: a first-order lag `q̇ = (g − q)/τ` would jump the
//!   velocity by Δ/τ at every goal change, an impulsive acceleration that the ZMP turns into
//!   ±0.2 m spikes at the tick rate. Torque off = limp, modelled as holding the present position.
//! * **Servo torque** (`SimConfig::servo_torque`, XM430-class by default; see [`super::servo`]):
//!   once per physics step the torques the motors must deliver are computed by virtual work
//!   with the stance sole fixed (the joint angles are then the generalised coordinates):
//!   `τ_k = Σᵢ mᵢ·(r̈ᵢ + g·ẑ)·∂rᵢ/∂q_k + (J·θ̈_u − τ_d)·∂θ_u/∂q_k − F_o·∂c_o/∂q_k + I_a·q̈_k`
//!   over the seven mass points `rᵢ` (both legs and the upper body), the upper body's pitch θ_u
//!   (inertia J, disturbance torque τ_d), the other foot's ground reaction `F_o` at its centre
//!   of pressure `c_o` in double support (its vertical share from the last step's force split,
//!   its horizontal share in the same proportion of `Σ mᵢ·r̈ᵢ`), and the reflected rotor inertia
//!   `I_a`. With `r̈ᵢ = Σ_l ∂rᵢ/∂q_l·q̈_l + (q̇ᵀ·H·q̇)ᵢ` this is `τ = M·q̈ + b`; the Jacobians
//!   are central differences (δ = 1 µrad) of the positions, the bias `b` the Taylor stencil
//!   below with `q̈ = 0`. Each motor's torque is limited to its torque–speed range; the joints
//!   get the accelerations those torques allow ([`super::servo::limit_accelerations`]; within a
//!   step, sub-step accelerations are clamped with the other joints' torque share frozen). A
//!   servo that cannot carry its load sags. Not modelled while the robot falls.
//! * **Body**: the stance sole stays where it is (no slip). The pelvis pose is the inverse of
//!   the stance leg's forward kinematics from that fixed sole pose, so pelvis roll and pitch
//!   follow from the joints. The other foot is placed by its own forward kinematics from the
//!   pelvis. Its sole height above the stance sole decides contact (≤ `contact_threshold` →
//!   double support, the pelvis still comes from the stance foot). When it is lower than the
//!   stance sole by more than `switch_threshold`, it becomes the stance foot, at its current
//!   pose (so nothing jumps: positions stay continuous, accelerations finite; the ground level
//!   can drift by at most the switch threshold per step, and a tilted landing foot stays tilted).
//!   Contact is judged from the sole point (the ankle's projection) only: sole corners of a
//!   tilted foot are ignored (no rolling onto a heel or toe edge).
//! * **Masses**: upper body M_u at l_u above the pelvis point P (rotated with the pelvis and the
//!   disturbance pitch φ_d), each leg's thigh, calf and sole masses from `gait-core`'s
//!   `LegPoints` — both legs, the swing leg included.
//! * **Accelerations** are those of the present motion state, not finite differences of the
//!   trajectory: the positions are evaluated along the second-order Taylor path
//!   `q(t ± ε) = q ± q̇·ε + ½·q̈·ε²` of every state variable (joint angles, waist deflection φ_d,
//!   fall angle) and differenced, `r̈ = (r₊ − 2r + r₋)/ε² = J·q̈ + q̇ᵀ·H·q̇ + O(ε²)` (ε = 0.1 ms):
//!   the exact acceleration of the point masses at `t`, with no lag and no smoothing (the sensors
//!   sample the truth of the present physics step). Angular rates likewise `(R₊ − R₋)/2ε`.
//! * **ZMP**: see [`super::zmp`], with `L̇_y = J·φ̈ − τ` (upper-body pitch inertia J, external
//!   disturbance torque τ); other link rotational inertia is neglected.
//! * **Disturbance**: an external pitch torque τ on the upper body, which is joined to the
//!   pelvis by a stiff, damped waist compliance: `J·φ̈_d = τ − k·φ_d − c·φ̇_d`.
//! * **Falls**: once triggered (forced at a time, ZMP outside the support polygon by more than a
//!   margin for a while, or a pelvis tilt above a limit), the whole robot rotates about the
//!   support edge in the fall direction (towards the CoM projection when it is outside the
//!   polygon, else towards the ZMP; the pelvis tilt direction; or the configured heading) as an inverted pendulum
//!   `θ̈ = (g/L)·(sin θ + 0.05)`, until it lies on the ground (θ = π/2 − 0.05). While it falls the
//!   whole load sits on the edge; once it lies, the feet carry nothing.

use gait_core::kinematics::leg::{LegKinematics, Pose};
use gait_core::measure::support::SupportPolygon;
use gait_core::trajectory::plan::Place;
use gait_core::{Robot, Side};

use super::forces::{center_of_pressure, distribute, FootContact};
use super::rng::Rng;
use super::servo::limit_accelerations;
use super::zmp::{center_of_mass, whole_body_zmp, MassPoint};
use super::SimConfig;

type V3 = [f64; 3];
/// Row-major rotation matrix.
type M3 = [[f64; 3]; 3];

const I3: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
/// Fall angle at which the robot lies on the ground, rad.
const LYING: f64 = core::f64::consts::FRAC_PI_2 - 0.05;
/// Half-width of the Taylor stencil for the accelerations, s.
const STENCIL_S: f64 = 1e-4;
/// Joint-angle step of the Jacobians' central differences, rad.
const JACOBIAN_STEP: f64 = 1e-6;

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn mv(m: &M3, v: V3) -> V3 {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}
fn mul(a: &M3, b: &M3) -> M3 {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j]))
}
fn tr(a: &M3) -> M3 {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[j][i]))
}
fn ry(a: f64) -> M3 {
    let (s, c) = a.sin_cos();
    [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
}
/// Rotation by `angle` about the unit `axis`.
fn rodrigues(axis: V3, angle: f64) -> M3 {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = axis;
    let t = 1.0 - c;
    [
        [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
        [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
        [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
    ]
}
/// ZYX angles (roll, pitch, yaw) of a rotation matrix.
pub(crate) fn rpy(m: &M3) -> V3 {
    [
        m[2][1].atan2(m[2][2]),
        (-m[2][0]).atan2((m[0][0] * m[0][0] + m[1][0] * m[1][0]).sqrt()),
        m[1][0].atan2(m[0][0]),
    ]
}
fn to_pose(p: V3, m: &M3) -> Pose<f64> {
    let [roll, pitch, yaw] = rpy(m);
    Pose::new(p[0], p[1], p[2], roll, pitch, yaw)
}

/// One servo's command for a physics step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ServoCmd {
    /// Goal angle (rad) when the torque is on; `None` = limp.
    pub goal: Option<f64>,
    /// Speed limit, rad/s.
    pub speed_limit: f64,
}

/// Support state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Support {
    /// Only the left foot touches the ground.
    #[default]
    Left,
    /// Only the right foot.
    Right,
    /// Both feet.
    Double,
}

impl Support {
    /// One-letter code for logs: `L`, `R`, `D`.
    pub fn code(self) -> char {
        match self {
            Support::Left => 'L',
            Support::Right => 'R',
            Support::Double => 'D',
        }
    }
}

/// Ground truth at one physics time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TruthSample {
    /// Time, µs.
    pub t_us: u64,
    /// Whole-body ZMP, m (the last valid one if `fz ≤ 0`).
    pub zmp: [f64; 2],
    /// Σ mᵢ(z̈ᵢ + g), N.
    pub fz: f64,
    /// Whole-body centre of mass, m.
    pub com: V3,
    /// Pelvis point P, m.
    pub pelvis: V3,
    /// Pelvis roll, pitch, yaw, rad.
    pub pelvis_rpy: V3,
    /// Which feet touch the ground.
    pub support: Support,
    /// Stance (pelvis reference) foot is the left one.
    pub stance_left: bool,
    /// Signed distance of the ZMP to the support polygon boundary (positive inside), m.
    pub margin: f64,
    /// Sensor forces (N, noiseless): left foot then right foot, sensor order of `dxl::table::foot`.
    pub forces: [[f64; 4]; 2],
    /// Upper-body angular rate in the body frame, rad/s (noiseless).
    pub gyro: V3,
    /// Specific force at P in the upper-body frame, m/s² (noiseless, +g on z when upright).
    pub accel: V3,
    /// Disturbance torque, N·m.
    pub tau: f64,
    /// The robot is falling (or lies on the ground).
    pub falling: bool,
    /// Fall angle, rad (0 upright).
    pub fall_angle: f64,
    /// Joint speeds, rad/s (left leg then right leg).
    pub joint_speed: [f64; 12],
    /// Motor torques, N·m (NaN without the torque model or while falling).
    pub joint_torque: [f64; 12],
    /// Bit `j` set: servo `j`'s motor is at its torque bound.
    pub torque_limited: u16,
    /// Each sole (left, right) touches the ground.
    pub sole_contact: [bool; 2],
    /// Each sole's contact wrench in the world frame about its sole point: force (N) then
    /// moment (N·m); zero in the kinematic model.
    pub sole_wrench: [[f64; 6]; 2],
    /// A robot part other than a sole touches the ground.
    pub other_contact: bool,
    /// Each sole's point on the ground and heading in the world (left, right): x, y (m), yaw
    /// (rad) — where the feet really are, in the air or on the ground.
    pub soles: [[f64; 3]; 2],
    /// Each sole's roll and pitch in the world (left, right; rad, ZYX angles): a sole flat on
    /// the ground reads 0, one rocking on its heel or toe its pitch. 0 in the kinematic model.
    pub sole_tilt: [[f64; 2]; 2],
    /// Each sole point's height above the floor (left, right; m): 0 on the ground, the swing
    /// foot's lift in the air. 0 in the kinematic model.
    pub sole_z: [f64; 2],
    /// Joint positions, rad (left leg then right leg, the simulator's joint coordinates).
    pub joint_position: [f64; 12],
}

/// One joint's torque line for a physics step: `τ = rest + m_kk·q̈` with the other joints'
/// share `rest` frozen.
#[derive(Clone, Copy, Debug, Default)]
struct TorqueLine {
    rest: f64,
    m_kk: f64,
}

#[derive(Clone, Copy, Debug)]
struct Snapshot {
    /// Time, µs.
    t_us: u64,
    /// The mass points, world frame, m.
    points: [V3; 7],
    /// Pelvis point, m.
    pelvis: V3,
    /// Pelvis rotation.
    r_pelvis: M3,
    /// Upper-body rotation.
    r_ub: M3,
    /// Floor height under the stance foot, m.
    ground_z: f64,
    /// Each sole on the ground (left, right).
    contact: [bool; 2],
    /// Each sole's contact (forces, centre of pressure).
    feet: [FootContact; 2],
    /// Sole point and rotation of each foot (before a fall's rotation), m.
    soles: [(V3, M3); 2],
    stance: Side,
    tau: f64,
    fall_angle: f64,
    fall_pivot: Option<[f64; 2]>,
}

impl Default for Snapshot {
    fn default() -> Self {
        Snapshot {
            t_us: 0,
            points: [[0.0; 3]; 7],
            pelvis: [0.0; 3],
            r_pelvis: I3,
            r_ub: I3,
            ground_z: 0.0,
            contact: [true; 2],
            feet: [FootContact::default(); 2],
            soles: [([0.0; 3], I3); 2],
            stance: Side::Left,
            tau: 0.0,
            fall_angle: 0.0,
            fall_pivot: None,
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Fall {
    pivot: V3,
    axis: V3,
    angle: f64,
    rate: f64,
    length: f64,
}

/// The simulated body.
#[derive(Clone, Debug)]
pub struct Physics {
    robot: Robot,
    kin: LegKinematics<f64>,
    masses: [f64; 7],
    /// Joint angles, rad (left leg then right leg).
    pub q: [f64; 12],
    /// Joint velocities, rad/s.
    pub qd: [f64; 12],
    /// Joint accelerations, rad/s² (at the present state with the last goals).
    pub qdd: [f64; 12],
    stance: Side,
    stance_place: (V3, M3),
    contact: [bool; 2],
    phi_d: f64,
    phi_d_rate: f64,
    tau: f64,
    fall: Option<Fall>,
    fallen_at_us: Option<u64>,
    fall_started_us: Option<u64>,
    outside_us: u64,
    /// Goals of the last step (rad, clamped to the joint limits; `None` = limp).
    goals: [Option<f64>; 12],
    speed_limits: [f64; 12],
    /// Torque lines of this step (`None`: no torque model, or falling).
    torque_lines: Option<[TorqueLine; 12]>,
    joint_torque: [f64; 12],
    torque_limited: u16,
    current: Snapshot,
    /// Physics time, µs.
    pub time_us: u64,
    dt_us: u64,
    truth: TruthSample,
    dist_rng: Rng,
    cfg: SimConfig,
    /// Largest distance of the ZMP outside the support polygon seen, m.
    pub max_outside: f64,
}

impl Physics {
    /// The body at rest at `cfg.initial_q` on flat ground, pelvis upright.
    pub fn new(cfg: &SimConfig) -> Self {
        let robot = cfg.robot;
        let m = robot.masses;
        let kin = LegKinematics::new(&robot);
        let mut q = cfg.initial_q;
        for (j, qj) in q.iter_mut().enumerate() {
            let side = if j < 6 { Side::Left } else { Side::Right };
            let l = robot.joint_limit(side, j % 6);
            *qj = qj.clamp(l.min, l.max);
        }
        let mut p = Physics {
            robot,
            kin,
            masses: [
                m.upper_body,
                m.thigh,
                m.calf,
                m.sole,
                m.thigh,
                m.calf,
                m.sole,
            ],
            q,
            qd: [0.0; 12],
            qdd: [0.0; 12],
            stance: Side::Left,
            stance_place: ([0.0; 3], I3),
            contact: [true; 2],
            phi_d: 0.0,
            phi_d_rate: 0.0,
            tau: 0.0,
            fall: None,
            fallen_at_us: None,
            fall_started_us: None,
            outside_us: 0,
            goals: [None; 12],
            speed_limits: [cfg.servo_speed_limit; 12],
            torque_lines: None,
            joint_torque: [f64::NAN; 12],
            torque_limited: 0,
            current: Snapshot::default(),
            time_us: 0,
            dt_us: cfg.physics_dt_us.max(1),
            truth: TruthSample::default(),
            dist_rng: Rng::new(cfg.seed, 3),
            cfg: cfg.clone(),
            max_outside: 0.0,
        };
        // Upright pelvis, lower sole on the ground at z = 0.
        let rel = [Side::Left, Side::Right].map(|s| p.foot_rel(s, &p.q));
        let stance = if rel[1].0[2] < rel[0].0[2] - 1e-12 {
            Side::Right
        } else {
            Side::Left
        };
        let (s0, r0) = rel[stance.index()];
        p.stance = stance;
        p.stance_place = ([s0[0], s0[1], 0.0], r0);
        p.update_contacts();
        p.current = p.snapshot_at(&p.q, p.phi_d, 0.0);
        p.truth = p.compute_truth();
        p
    }

    /// Sole pose relative to a pelvis at the origin, upright, for joint angles `q`.
    fn foot_rel(&self, side: Side, q: &[f64; 12]) -> (V3, M3) {
        let f = self.kin.fk(side, &Pose::default(), &leg_q(q, side));
        (f.position(), f.rotation())
    }

    /// Pelvis position and rotation with the sole of `side` at `place`, for joint angles `q`.
    fn pelvis_from(&self, side: Side, place: &(V3, M3), q: &[f64; 12]) -> (V3, M3) {
        let (s0, r0) = self.foot_rel(side, q);
        let rp = mul(&place.1, &tr(&r0));
        (sub(place.0, mv(&rp, s0)), rp)
    }

    fn update_contacts(&mut self) {
        let st = self.stance;
        let ot = st.other();
        let (p, rp) = self.pelvis_from(st, &self.stance_place, &self.q);
        let fo = self.kin.fk(ot, &to_pose(p, &rp), &leg_q(&self.q, ot));
        let dz = fo.z - self.stance_place.0[2];
        if dz < -self.cfg.switch_threshold {
            self.stance = ot;
            self.stance_place = (fo.position(), fo.rotation());
            self.contact[ot.index()] = true;
            self.contact[st.index()] = -dz <= self.cfg.contact_threshold;
        } else {
            self.contact[st.index()] = true;
            self.contact[ot.index()] = dz <= self.cfg.contact_threshold;
        }
    }

    /// Positions of the body for joint angles `q`, waist deflection `phi_d` and fall angle
    /// `fall_angle`, with the stance foot, contacts and fall pivot as they are now.
    fn snapshot_at(&self, q: &[f64; 12], phi_d: f64, fall_angle: f64) -> Snapshot {
        let (mut p, rp) = self.pelvis_from(self.stance, &self.stance_place, q);
        let pose = to_pose(p, &rp);
        let legs = [Side::Left, Side::Right].map(|s| self.kin.points(s, &pose, &leg_q(q, s)));
        let feet_pose = [Side::Left, Side::Right].map(|s| self.kin.fk(s, &pose, &leg_q(q, s)));
        let mut r_ub = mul(&rp, &ry(phi_d));
        let ub = add(
            p,
            mv(&r_ub, [0.0, 0.0, self.robot.masses.upper_body_height]),
        );
        let mut points = [
            ub,
            legs[0].thigh_mass,
            legs[0].calf_mass,
            legs[0].sole_mass,
            legs[1].thigh_mass,
            legs[1].calf_mass,
            legs[1].sole_mass,
        ];
        let mut r_pelvis = rp;
        let mut angle = 0.0;
        let mut fall_pivot = None;
        if let Some(f) = &self.fall {
            let rf = rodrigues(f.axis, fall_angle);
            let tf = |x: V3| add(f.pivot, mv(&rf, sub(x, f.pivot)));
            for pt in points.iter_mut() {
                *pt = tf(*pt);
            }
            p = tf(p);
            r_pelvis = mul(&rf, &r_pelvis);
            r_ub = mul(&rf, &r_ub);
            angle = fall_angle;
            fall_pivot = Some([f.pivot[0], f.pivot[1]]);
        }
        Snapshot {
            t_us: self.time_us,
            points,
            pelvis: p,
            r_pelvis,
            r_ub,
            ground_z: self.stance_place.0[2],
            contact: self.contact,
            feet: [0, 1].map(|i| FootContact {
                xy: [feet_pose[i].x, feet_pose[i].y],
                yaw: feet_pose[i].yaw,
            }),
            soles: [0, 1].map(|i| (feet_pose[i].position(), feet_pose[i].rotation())),
            stance: self.stance,
            tau: self.tau,
            fall_angle: angle,
            fall_pivot,
        }
    }

    /// Fall angle, rate and acceleration now (zeros when not falling).
    fn fall_state(&self) -> [f64; 3] {
        match &self.fall {
            Some(f) if f.angle < LYING => [
                f.angle,
                f.rate,
                self.robot.gravity / f.length * (f.angle.sin() + 0.05),
            ],
            Some(f) => [f.angle, 0.0, 0.0],
            None => [0.0; 3],
        }
    }

    /// Waist deflection acceleration now, rad/s².
    fn phi_d_acc(&self) -> f64 {
        let d = &self.cfg.disturbance;
        let j = self.robot.masses.upper_body_inertia.max(1e-6);
        let wn = core::f64::consts::TAU * d.waist_frequency_hz;
        (self.tau - j * wn * wn * self.phi_d - 2.0 * d.waist_damping * j * wn * self.phi_d_rate) / j
    }

    /// The support polygon of the feet in contact.
    fn polygon(&self, feet: &[FootContact; 2], contact: [bool; 2]) -> Option<SupportPolygon<f64>> {
        let place = |f: &FootContact| Place::<f64>::new(f.xy[0], f.xy[1], f.yaw);
        match contact {
            [true, true] => {
                SupportPolygon::double(&place(&feet[0]), &place(&feet[1]), &self.robot).ok()
            }
            [true, false] => SupportPolygon::single(&place(&feet[0]), &self.robot).ok(),
            [false, true] => SupportPolygon::single(&place(&feet[1]), &self.robot).ok(),
            [false, false] => None,
        }
    }

    fn compute_truth(&self) -> TruthSample {
        // The present positions and those along the Taylor path at ∓ε (see the module docs).
        let h = STENCIL_S;
        let [th, th_d, th_dd] = self.fall_state();
        let path = |sign: f64| {
            let at = |x: f64, v: f64, a: f64| x + sign * v * h + 0.5 * a * h * h;
            let q: [f64; 12] = std::array::from_fn(|j| at(self.q[j], self.qd[j], self.qdd[j]));
            let phi = at(self.phi_d, self.phi_d_rate, self.phi_d_acc());
            self.snapshot_at(&q, phi, at(th, th_d, th_dd))
        };
        let (a, c, b) = (&path(-1.0), &self.current, &path(1.0));
        let g = self.robot.gravity;
        let dd =
            |pa: V3, pc: V3, pb: V3| [0, 1, 2].map(|k| (pb[k] - 2.0 * pc[k] + pa[k]) / (h * h));
        let pts: Vec<MassPoint> = (0..7)
            .map(|i| {
                let mut pos = c.points[i];
                pos[2] -= c.ground_z;
                MassPoint {
                    mass: self.masses[i],
                    pos,
                    acc: dd(a.points[i], c.points[i], b.points[i]),
                }
            })
            .collect();
        let pitch = |s: &Snapshot| rpy(&s.r_ub)[1];
        let phi_dd = (pitch(b) - 2.0 * pitch(c) + pitch(a)) / (h * h);
        let j_term = if self.cfg.upper_body_inertia_term {
            self.robot.masses.upper_body_inertia * phi_dd
        } else {
            0.0
        };
        let zmp = whole_body_zmp(&pts, g, [0.0, j_term - c.tau]);
        let mut com = center_of_mass(&pts);
        com[2] += c.ground_z;
        let rt = tr(&c.r_ub);
        let dr = [0, 1, 2].map(|i| [0, 1, 2].map(|j| (b.r_ub[i][j] - a.r_ub[i][j]) / (2.0 * h)));
        let w = mul(&rt, &dr);
        let gyro = [
            0.5 * (w[2][1] - w[1][2]),
            0.5 * (w[0][2] - w[2][0]),
            0.5 * (w[1][0] - w[0][1]),
        ];
        let acc_p = dd(a.pelvis, c.pelvis, b.pelvis);
        let accel = mv(&rt, add(acc_p, [0.0, 0.0, g]));
        let poly = self.polygon(&c.feet, c.contact);
        let (zmp_xy, fz) = match zmp {
            Some(z) => (z.xy, z.fz),
            None => (self.truth.zmp, 0.0),
        };
        let margin = poly
            .as_ref()
            .map_or(f64::NEG_INFINITY, |p| p.margin(zmp_xy));
        let sensors = self.robot.geometry.force_sensors;
        let feet = [0, 1].map(|i| c.contact[i].then_some(c.feet[i]));
        let forces = if c.fall_angle >= LYING {
            [[0.0; 4]; 2]
        } else if let Some(pivot) = c.fall_pivot {
            let weight = self.robot.masses.total() * g;
            distribute(weight, pivot, feet[0], feet[1], &sensors)
        } else if fz > 0.0 {
            let target = poly
                .as_ref()
                .map_or(zmp_xy, |p| clamp_to_polygon(p, zmp_xy));
            distribute(fz, target, feet[0], feet[1], &sensors)
        } else {
            [[0.0; 4]; 2]
        };
        TruthSample {
            t_us: c.t_us,
            zmp: zmp_xy,
            fz,
            com,
            pelvis: c.pelvis,
            pelvis_rpy: rpy(&c.r_pelvis),
            support: match c.contact {
                [true, true] => Support::Double,
                [false, true] => Support::Right,
                _ => Support::Left,
            },
            stance_left: c.stance == Side::Left,
            margin,
            forces,
            gyro,
            accel,
            tau: c.tau,
            falling: c.fall_pivot.is_some(),
            fall_angle: c.fall_angle,
            joint_speed: self.qd,
            joint_torque: self.joint_torque,
            torque_limited: self.torque_limited,
            sole_contact: c.contact,
            sole_wrench: [[0.0; 6]; 2],
            other_contact: false,
            soles: c.feet.map(|f| [f.xy[0], f.xy[1], f.yaw]),
            sole_tilt: [[0.0; 2]; 2],
            sole_z: [0.0; 2],
            joint_position: self.q,
        }
    }

    /// The ground truth at `time_us`.
    pub fn truth(&self) -> &TruthSample {
        &self.truth
    }

    /// When the robot came to lie on the ground, µs.
    pub fn fallen_at_us(&self) -> Option<u64> {
        self.fallen_at_us
    }

    /// When the fall started, µs.
    pub fn fall_started_us(&self) -> Option<u64> {
        self.fall_started_us
    }

    fn update_disturbance(&mut self, dt: f64) {
        self.tau =
            self.cfg
                .disturbance
                .torque_at(self.time_us, self.dt_us, &mut self.dist_rng, self.tau);
        let acc = self.phi_d_acc();
        self.phi_d_rate += acc * dt;
        self.phi_d += self.phi_d_rate * dt;
    }

    fn start_fall(&mut self, dir: [f64; 2]) {
        let n = (dir[0] * dir[0] + dir[1] * dir[1]).sqrt();
        let d = if n > 1e-9 {
            [dir[0] / n, dir[1] / n]
        } else {
            [1.0, 0.0]
        };
        let com = self.truth.com;
        let cur = self.current;
        let poly = self.polygon(&cur.feet, cur.contact);
        let far = [com[0] + d[0], com[1] + d[1]];
        let piv = poly
            .as_ref()
            .map_or([com[0], com[1]], |p| clamp_to_polygon(p, far));
        let pivot = [piv[0], piv[1], self.stance_place.0[2]];
        let r = sub(com, pivot);
        self.fall = Some(Fall {
            pivot,
            axis: [-d[1], d[0], 0.0],
            angle: 0.0,
            rate: 0.2,
            length: (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt().max(0.05),
        });
        self.fall_started_us = Some(self.time_us);
    }

    fn update_fall(&mut self, dt: f64) {
        let g = self.robot.gravity;
        let f = self.cfg.fall.clone();
        if self.fall.is_none() {
            if let Some(t) = f.forced_at_s {
                if self.time_us as f64 * 1e-6 >= t {
                    self.start_fall([f.forced_direction.cos(), f.forced_direction.sin()]);
                }
            }
        }
        if self.fall.is_none() && f.enabled {
            let tr = self.truth;
            if tr.margin < -f.zmp_margin {
                self.outside_us += self.dt_us;
            } else {
                self.outside_us = 0;
            }
            let tilt_axis = self.current.r_pelvis;
            let tilt = tilt_axis[2][2].clamp(-1.0, 1.0).acos();
            if self.outside_us as f64 * 1e-6 >= f.zmp_time_s {
                let poly = self.polygon(&self.current.feet, self.current.contact);
                // Towards the CoM if it is outside (a static tip-over), else towards the ZMP.
                let com = [tr.com[0], tr.com[1]];
                let com_in = poly.as_ref().map_or(com, |p| clamp_to_polygon(p, com));
                let zmp_in = poly
                    .as_ref()
                    .map_or(tr.zmp, |p| clamp_to_polygon(p, tr.zmp));
                let dc = [com[0] - com_in[0], com[1] - com_in[1]];
                if dc[0].hypot(dc[1]) > 1e-6 {
                    self.start_fall(dc);
                } else {
                    self.start_fall([tr.zmp[0] - zmp_in[0], tr.zmp[1] - zmp_in[1]]);
                }
            } else if tilt > f.max_tilt_rad {
                self.start_fall([tilt_axis[0][2], tilt_axis[1][2]]);
            }
        }
        if let Some(fl) = &mut self.fall {
            if fl.angle < LYING {
                fl.rate += g / fl.length * (fl.angle.sin() + 0.05) * dt;
                fl.angle += fl.rate * dt;
                if fl.angle >= LYING {
                    fl.angle = LYING;
                    fl.rate = 0.0;
                    self.fallen_at_us = Some(self.time_us);
                }
            }
        }
    }

    /// Advances one physics step with these servo commands.
    pub fn step(&mut self, cmds: &[ServoCmd; 12]) {
        let dt = self.dt_us as f64 * 1e-6;
        self.time_us += self.dt_us;
        for (j, cmd) in cmds.iter().enumerate() {
            let side = if j < 6 { Side::Left } else { Side::Right };
            let l = self.robot.joint_limit(side, j % 6);
            self.goals[j] = cmd.goal.map(|g| g.clamp(l.min, l.max));
            self.speed_limits[j] = cmd.speed_limit.max(0.0);
        }
        self.update_torque_lines();
        for j in 0..12 {
            self.servo_step(j, dt);
        }
        self.finish_torques();
        self.update_disturbance(dt);
        self.update_contacts();
        self.update_fall(dt);
        self.current = self.snapshot_at(&self.q, self.phi_d, self.fall_state()[0]);
        self.truth = self.compute_truth();
        if self.truth.margin.is_finite() && !self.truth.falling {
            self.max_outside = self.max_outside.max(-self.truth.margin);
        }
    }

    /// Servo `j`'s acceleration at angle `q` and velocity `v` toward its goal (its position
    /// loop and speed limit, then its torque limit).
    fn servo_acc(&self, j: usize, q: f64, v: f64) -> f64 {
        let a = self.servo_loop_acc(j, q, v);
        self.torque_limited_acc(j, v, a).0
    }

    /// The acceleration servo `j`'s position loop asks for at angle `q` and velocity `v`
    /// (0 at the speed limit in the direction of motion).
    fn servo_loop_acc(&self, j: usize, q: f64, v: f64) -> f64 {
        let Some(g) = self.goals[j] else {
            return 0.0;
        };
        let wn = core::f64::consts::TAU * self.cfg.servo_frequency_hz;
        let a = wn * wn * (g - q) - 2.0 * self.cfg.servo_damping * wn * v;
        // At the speed limit the motor cannot accelerate further.
        let vmax = self.speed_limits[j];
        if (v >= vmax && a > 0.0) || (v <= -vmax && a < 0.0) {
            0.0
        } else {
            a
        }
    }

    /// The acceleration servo `j` reaches at speed `v` when its loop asks for `a`, and whether
    /// its motor is at a torque bound (this step's torque line, see the module docs).
    fn torque_limited_acc(&self, j: usize, v: f64, a: f64) -> (f64, bool) {
        let (Some(lines), Some(model)) = (&self.torque_lines, &self.cfg.servo_torque) else {
            return (a, false);
        };
        let TorqueLine { rest, m_kk } = lines[j];
        if m_kk <= 0.0 {
            return (a, false);
        }
        let (lo, hi) = model.range(v);
        let tau = rest + m_kk * a;
        if tau > hi {
            ((hi - rest) / m_kk, true)
        } else if tau < lo {
            ((lo - rest) / m_kk, true)
        } else {
            (a, false)
        }
    }

    /// The mass points, the upper body's pitch and the other foot's centre-of-pressure point
    /// (`cop`: foot frame, m) for joint angles `q` and waist deflection `phi_d` (no fall).
    fn loaded_points(&self, q: &[f64; 12], phi_d: f64, cop: [f64; 2]) -> ([V3; 7], f64, V3) {
        let s = self.snapshot_at(q, phi_d, 0.0);
        let (sole, r) = s.soles[self.stance.other().index()];
        let c = add(sole, mv(&r, [cop[0], cop[1], 0.0]));
        (s.points, rpy(&s.r_ub)[1], c)
    }

    /// Sets this step's torque lines from the joint-space dynamics `τ = M·q̈ + b` at the present
    /// state (see the module docs); none without the torque model or while falling.
    fn update_torque_lines(&mut self) {
        self.torque_lines = None;
        let Some(model) = self.cfg.servo_torque else {
            return;
        };
        if self.fall.is_some() {
            return;
        }
        // The other foot's load in double support (last step's split).
        let ot = self.stance.other();
        // Its centre of pressure in its own frame: the foot placed at the origin, heading 0.
        let (cop, fz_other) = if self.contact[ot.index()] {
            center_of_pressure(
                &[self.truth.forces[ot.index()], [0.0; 4]],
                [Some(FootContact::default()), None],
                &self.robot.geometry.force_sensors,
            )
            .unwrap_or(([0.0; 2], 0.0))
        } else {
            ([0.0; 2], 0.0)
        };
        // Jacobians by central differences.
        let mut jr = [[[0.0; 3]; 12]; 7];
        let mut jt = [0.0; 12];
        let mut jc = [[0.0; 3]; 12];
        for k in 0..12 {
            let (mut qp, mut qm) = (self.q, self.q);
            qp[k] += JACOBIAN_STEP;
            qm[k] -= JACOBIAN_STEP;
            let (pp, tp, cp) = self.loaded_points(&qp, self.phi_d, cop);
            let (pm, tm, cm) = self.loaded_points(&qm, self.phi_d, cop);
            let d = 2.0 * JACOBIAN_STEP;
            for i in 0..7 {
                jr[i][k] = [0, 1, 2].map(|a| (pp[i][a] - pm[i][a]) / d);
            }
            jt[k] = (tp - tm) / d;
            jc[k] = [0, 1, 2].map(|a| (cp[a] - cm[a]) / d);
        }
        // Bias accelerations: the Taylor stencil with q̈ = 0 (the waist keeps its motion).
        let h = STENCIL_S;
        let phi_acc = self.phi_d_acc();
        let path = |sign: f64| {
            let q: [f64; 12] = std::array::from_fn(|j| self.q[j] + sign * self.qd[j] * h);
            let phi = self.phi_d + sign * self.phi_d_rate * h + 0.5 * phi_acc * h * h;
            self.loaded_points(&q, phi, cop)
        };
        let (a, c, b) = (
            path(-1.0),
            self.loaded_points(&self.q, self.phi_d, cop),
            path(1.0),
        );
        let bias_r: [V3; 7] = std::array::from_fn(|i| {
            [0, 1, 2].map(|x| (b.0[i][x] - 2.0 * c.0[i][x] + a.0[i][x]) / (h * h))
        });
        let bias_t = (b.1 - 2.0 * c.1 + a.1) / (h * h);
        // The position loops' wishes.
        let desired: [f64; 12] =
            std::array::from_fn(|j| self.servo_loop_acc(j, self.q[j], self.qd[j]));
        let g = self.robot.gravity;
        let jub = self.robot.masses.upper_body_inertia;
        // The other foot's ground reaction: its vertical share, the same share of Σ m·r̈ (h).
        let fz_total = self.truth.fz;
        let share = if fz_total > 0.0 && fz_other > 0.0 {
            (fz_other / fz_total).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let mut f_h = [0.0; 2];
        for i in 0..7 {
            for (x, fx) in f_h.iter_mut().enumerate() {
                let acc = bias_r[i][x] + (0..12).map(|l| jr[i][l][x] * desired[l]).sum::<f64>();
                *fx += self.masses[i] * acc;
            }
        }
        let f_o = [share * f_h[0], share * f_h[1], fz_other];
        let dot = |u: V3, v: V3| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
        let mut m = [[0.0; 12]; 12];
        let mut bv = [0.0; 12];
        for k in 0..12 {
            for l in 0..12 {
                m[k][l] = (0..7)
                    .map(|i| self.masses[i] * dot(jr[i][k], jr[i][l]))
                    .sum::<f64>()
                    + jub * jt[k] * jt[l];
            }
            m[k][k] += model.armature;
            bv[k] = (0..7)
                .map(|i| self.masses[i] * dot(add(bias_r[i], [0.0, 0.0, g]), jr[i][k]))
                .sum::<f64>()
                + (jub * bias_t - self.tau) * jt[k]
                - dot(f_o, jc[k]);
        }
        let range: [(f64, f64); 12] = std::array::from_fn(|j| model.range(self.qd[j]));
        let free: [bool; 12] = std::array::from_fn(|j| self.goals[j].is_some());
        let (x, tau, _) = limit_accelerations(&m, &bv, &desired, &range, &free);
        // τ_k = rest_k + M_kk·q̈_k with the other joints' share at the solved accelerations.
        let lines: [TorqueLine; 12] = std::array::from_fn(|k| TorqueLine {
            rest: tau[k] - m[k][k] * x[k],
            m_kk: if free[k] { m[k][k] } else { 0.0 },
        });
        self.torque_lines = Some(lines);
    }

    /// The motor torques and torque-limit flags at the end of the step.
    fn finish_torques(&mut self) {
        self.torque_limited = 0;
        let Some(lines) = self.torque_lines else {
            self.joint_torque = [f64::NAN; 12];
            return;
        };
        for (j, line) in lines.iter().enumerate() {
            let a = self.servo_loop_acc(j, self.q[j], self.qd[j]);
            let (acc, limited) = self.torque_limited_acc(j, self.qd[j], a);
            self.joint_torque[j] = line.rest + line.m_kk * acc;
            if limited {
                self.torque_limited |= 1 << j;
            }
        }
    }

    /// Moves servo `j` over `dt` (semi-implicit Euler sub-steps of at most 1/(100 ω)).
    fn servo_step(&mut self, j: usize, dt: f64) {
        if self.goals[j].is_none() {
            self.qd[j] = 0.0;
            self.qdd[j] = 0.0;
            return;
        }
        let wn = core::f64::consts::TAU * self.cfg.servo_frequency_hz;
        let n = (dt * wn * 100.0).ceil().clamp(1.0, 10_000.0) as usize;
        let h = dt / n as f64;
        let vmax = self.speed_limits[j];
        let side = if j < 6 { Side::Left } else { Side::Right };
        let l = self.robot.joint_limit(side, j % 6);
        let (mut q, mut v) = (self.q[j], self.qd[j].clamp(-vmax, vmax));
        for _ in 0..n {
            let a = self.servo_acc(j, q, v);
            v = (v + a * h).clamp(-vmax, vmax);
            q += v * h;
            // The mechanical stops.
            if q < l.min || q > l.max {
                q = q.clamp(l.min, l.max);
                v = 0.0;
            }
        }
        self.q[j] = q;
        self.qd[j] = v;
        self.qdd[j] = self.servo_acc(j, q, v);
    }
}

fn leg_q(q: &[f64; 12], side: Side) -> [f64; 6] {
    let o = 6 * side.index();
    [0, 1, 2, 3, 4, 5].map(|j| q[o + j])
}

/// The point of the polygon nearest to `q` (`q` itself when inside).
pub fn clamp_to_polygon(poly: &SupportPolygon<f64>, q: [f64; 2]) -> [f64; 2] {
    if poly.margin(q) >= 0.0 {
        return q;
    }
    let v = poly.vertices();
    let mut best = v.first().copied().unwrap_or(q);
    let mut best_d = f64::INFINITY;
    for k in 0..v.len() {
        let a = v[k];
        let b = v[(k + 1) % v.len()];
        let e = [b[0] - a[0], b[1] - a[1]];
        let l2 = e[0] * e[0] + e[1] * e[1];
        let t = if l2 > 0.0 {
            (((q[0] - a[0]) * e[0] + (q[1] - a[1]) * e[1]) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let p = [a[0] + t * e[0], a[1] + t * e[1]];
        let d = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
        if d < best_d {
            best_d = d;
            best = p;
        }
    }
    best
}
