//! The MuJoCo model (MJCF) of the simulated robot, generated from [`gait_core::Robot`] so that
//! masses, lengths, joint axes, limits and sensor positions have one source.
//!
//! # Bodies (world x forward, y left, z up; `σ` = +1 left, −1 right)
//!
//! * `torso`, on a free joint, origin at the pelvis point P: the upper body's mass M_u at
//!   (f_u, 0, l_u) (its forward offset and height) with the pitch inertia J of the description
//!   and its roll and yaw inertias where the description has them
//!   ([`gait_core::robot::LinkInertias`]), else roll J and yaw J/2 (the seed gives only J). Site `imu` at
//!   P (gyro and accelerometer). Collision boxes for the pelvis and the trunk and a sphere for
//!   the head, from the description's [`gait_core::robot::BodyShape`] (a fall is a torso
//!   contact).
//! * `{l,r}_thigh` at the hip (0, σ·d, 0) with the joints `hip_yaw` (z), `hip_roll` (x),
//!   `hip_pitch` (y) in that order (MuJoCo composes a body's joints in order, giving
//!   `Rz(q0)·Rx(q1)·Ry(q2)` of [`gait_core::kinematics::leg`]); mass m_t at (0, 0, −c_t·L1)
//!   (c_t = `masses.thigh_com`).
//! * `{l,r}_calf` at (0, 0, −L1), joint `knee` (y); mass of the calf at (0, 0, −c_c·L2).
//! * `{l,r}_foot` at the ankle (0, 0, −L2), joints `ankle_pitch` (y), `ankle_roll` (x); the sole
//!   mass `masses.sole_height` above the sole point and `masses.sole_com` from it (the same
//!   mass points as gait-core's forward kinematics); the sole box `{l,r}_sole` (the
//!   description's length × width, 10 mm thick, centred on the sole point
//!   S = (o_x, σ·o_y, −h) from the ankle, its bottom at S) with rubber-like
//!   contact (`solref` 4 ms, critically damped, as MuJoCo Menagerie's ROBOTIS OP3 feet; friction
//!   from [`EnvConfig::floor_friction`]); site `{l,r}_sole` at the sole point.
//!
//! Link inertias are the description's ([`gait_core::robot::Masses::inertias`]) or, where it
//! has none, those of uniform rods and of the sole box. Joint ranges are the robot's
//! limits (mechanical stops; the right leg's mirrored ones from [`Robot::joint_limit`]);
//! armature, damping and friction loss come from the servo model ([`super::dynamixel`]). Every
//! joint has a `motor` actuator (gear 1, the servo model's output torque as its control).
//! Robot geoms collide with the floor, not with each other.
//!
//! # Environment
//!
//! A floor plane named `floor` (checker texture for the video), optionally tilted
//! ([`EnvConfig::slope_deg`], uphill forward) or covered (x from −0.15 to 0.6 m, y within ±0.2 m) with square tiles of random heights in
//! ±[`EnvConfig::step_height_m`] (deterministic from the seed; the tiles under the start pose are
//! level), a payload on the torso, and a weld `hold` of the torso to the world (a person holding
//! the robot until its servos are powered; released by [`super::mujoco`]).

use std::fmt::Write as _;

use gait_core::kinematics::leg::{leg_fk, Pose};
use gait_core::robot::{LinkInertias, JOINT_NAMES};
use gait_core::{Robot, Side};

use super::dynamixel::XServoParams;
use super::rng::Rng;

/// Thickness of the sole box, m.
pub const SOLE_THICKNESS: f64 = 0.010;
/// Radius of a leg link's capsule, m.
pub const LINK_RADIUS: f64 = 0.018;
/// A leg link's capsule starts and ends this far inside its joints, m.
pub const LINK_INSET: f64 = 0.012;
/// The torso's collision boxes of `robot` (name, half sizes, centre from P), m.
pub fn torso_boxes(robot: &Robot) -> [(&'static str, [f64; 3], [f64; 3]); 2] {
    let s = robot.shape;
    [
        ("pelvis", s.pelvis[0], s.pelvis[1]),
        ("trunk", s.trunk[0], s.trunk[1]),
    ]
}

/// The sole point S of leg `sigma` (+1 left, −1 right) from its ankle, foot frame, m.
pub fn sole_point(robot: &Robot, sigma: f64) -> [f64; 3] {
    let g = robot.geometry;
    // `+ 0.0`: a zero offset prints as 0, not −0, on the right leg.
    [
        g.sole_offset[0],
        sigma * g.sole_offset[1] + 0.0,
        -g.ankle_height,
    ]
}

/// The environment the robot walks in.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvConfig {
    /// Coulomb friction coefficient between soles and floor.
    pub floor_friction: f64,
    /// Floor slope about the y axis, degrees (positive: uphill walking forward).
    pub slope_deg: f64,
    /// Largest tile height above or below the mean floor, m (0 = flat floor).
    pub step_height_m: f64,
    /// Edge length of a floor tile, m.
    pub tile_size_m: f64,
    /// Extra mass fixed to the torso, kg.
    pub payload_kg: f64,
    /// Where the payload sits in the torso frame (from P), m.
    pub payload_pos_m: [f64; 3],
    /// Scale of every link mass (robustness sweeps; 1 = the robot description).
    pub mass_scale: f64,
    /// Forward offset of the upper body's centre of mass from the robot description's, m
    /// (MuJoCo model; robustness sweeps; 0 = the description).
    pub trunk_com_dx_m: f64,
    /// The robot starts this high above the floor (0: standing on it), m.
    pub start_lift_m: f64,
}

impl Default for EnvConfig {
    fn default() -> Self {
        EnvConfig {
            floor_friction: 1.0,
            slope_deg: 0.0,
            step_height_m: 0.0,
            tile_size_m: 0.05,
            payload_kg: 0.0,
            payload_pos_m: [0.0, 0.0, 0.15],
            mass_scale: 1.0,
            trunk_com_dx_m: 0.0,
            start_lift_m: 0.0,
        }
    }
}

impl EnvConfig {
    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), String> {
        let fin = |v: f64| v.is_finite();
        if !(fin(self.floor_friction) && self.floor_friction > 0.0 && self.floor_friction <= 5.0) {
            return Err("floor friction must be in (0, 5]".into());
        }
        if !(fin(self.slope_deg) && self.slope_deg.abs() <= 20.0) {
            return Err("floor slope must be within ±20°".into());
        }
        if !(fin(self.step_height_m) && (0.0..=0.05).contains(&self.step_height_m)) {
            return Err("floor step height must be in [0, 0.05] m".into());
        }
        if !(fin(self.tile_size_m) && (0.01..=1.0).contains(&self.tile_size_m)) {
            return Err("floor tile size must be in [0.01, 1] m".into());
        }
        if !(fin(self.payload_kg) && (0.0..=10.0).contains(&self.payload_kg)) {
            return Err("payload must be in [0, 10] kg".into());
        }
        if self.payload_pos_m.iter().any(|v| !fin(*v) || v.abs() > 1.0) {
            return Err("payload position must be within 1 m of P".into());
        }
        if !(fin(self.start_lift_m) && (0.0..=2.0).contains(&self.start_lift_m)) {
            return Err("start lift must be in [0, 2] m".into());
        }
        if !(fin(self.mass_scale) && (0.5..=2.0).contains(&self.mass_scale)) {
            return Err("mass scale must be in [0.5, 2]".into());
        }
        if !(fin(self.trunk_com_dx_m) && self.trunk_com_dx_m.abs() <= 0.05) {
            return Err("trunk CoM offset must be within ±0.05 m".into());
        }
        Ok(())
    }
}

/// Height of the pelvis point P above the floor when both soles rest flat at joint angles `q`
/// with the pelvis upright at (0, 0, ·).
pub fn standing_height(robot: &Robot, q: &[f64; 12]) -> f64 {
    let pelvis = Pose::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let low = [Side::Left, Side::Right]
        .into_iter()
        .enumerate()
        .map(|(k, side)| {
            let qs: [f64; 6] = std::array::from_fn(|j| q[6 * k + j]);
            leg_fk(robot, side, &pelvis, &qs).z
        })
        .fold(f64::INFINITY, f64::min);
    -low
}

fn rod_inertia(m: f64, len: f64, r: f64) -> [f64; 3] {
    let t = m * (3.0 * r * r + len * len) / 12.0;
    [t, t, 0.5 * m * r * r]
}

fn box_inertia(m: f64, x: f64, y: f64, z: f64) -> [f64; 3] {
    [
        m * (y * y + z * z) / 12.0,
        m * (x * x + z * z) / 12.0,
        m * (x * x + y * y) / 12.0,
    ]
}

/// A leg link hanging from its joint: `mass` at `com` of the way down its `len`, with the
/// description's `inertia` (else a uniform rod's, radius 2 cm), and its capsule geom.
fn rod_link(out: &mut String, pad: &str, len: f64, mass: f64, com: f64, inertia: Option<[f64; 3]>) {
    inertial(
        out,
        pad,
        [0.0, 0.0, -com * len],
        mass,
        inertia.unwrap_or_else(|| rod_inertia(mass, len, 0.02)),
    );
    let _ = writeln!(
        out,
        "{pad}<geom type=\"capsule\" fromto=\"0 0 {} 0 0 {}\" size=\"{LINK_RADIUS}\"/>",
        -LINK_INSET,
        -len + LINK_INSET
    );
}

/// Writes `<inertial>`; MuJoCo needs a positive mass and inertia on moving bodies.
fn inertial(out: &mut String, pad: &str, pos: [f64; 3], mass: f64, diag: [f64; 3]) {
    let m = mass.max(1e-4);
    let d = diag.map(|v| v.max(1e-7));
    let _ = writeln!(
        out,
        "{pad}<inertial pos=\"{} {} {}\" mass=\"{m}\" diaginertia=\"{} {} {}\"/>",
        pos[0], pos[1], pos[2], d[0], d[1], d[2]
    );
}

/// The MJCF text of `robot` with servos `servo` in `env`, standing at joint angles `q0`
/// (radians; the torso placed so both soles rest on the floor). `timestep_s` is the physics
/// step; `seed` draws the floor tiles.
pub fn model_xml(
    robot: &Robot,
    servo: &XServoParams,
    env: &EnvConfig,
    q0: &[f64; 12],
    timestep_s: f64,
    seed: u64,
) -> String {
    let m = robot.masses;
    let g = robot.geometry;
    let ms = env.mass_scale;
    let z0 = standing_height(robot, q0) + env.start_lift_m;
    let mut x = String::new();
    let _ = writeln!(x, "<mujoco model=\"walker-{}\">", robot.name);
    let _ = writeln!(x, "  <compiler angle=\"radian\" autolimits=\"true\"/>");
    let _ = writeln!(
        x,
        "  <option timestep=\"{timestep_s}\" gravity=\"0 0 {}\" integrator=\"implicitfast\" cone=\"elliptic\"/>",
        -robot.gravity
    );
    x.push_str(
        "  <visual><global offwidth=\"1280\" offheight=\"720\"/><quality shadowsize=\"2048\"/></visual>\n",
    );
    x.push_str(
        "  <asset>\n    <texture name=\"grid\" type=\"2d\" builtin=\"checker\" rgb1=\".82 .84 .86\" rgb2=\".62 .66 .70\" width=\"256\" height=\"256\"/>\n    <material name=\"grid\" texture=\"grid\" texrepeat=\"8 8\" texuniform=\"true\" reflectance=\".1\"/>\n    <texture name=\"sky\" type=\"skybox\" builtin=\"gradient\" rgb1=\".9 .93 .97\" rgb2=\".5 .6 .75\" width=\"256\" height=\"256\"/>\n    <material name=\"body\" rgba=\".25 .3 .38 1\"/>\n    <material name=\"link\" rgba=\".85 .55 .2 1\"/>\n    <material name=\"sole\" rgba=\".1 .1 .1 1\"/>\n    <material name=\"tile\" rgba=\".7 .72 .75 1\"/>\n  </asset>\n",
    );
    x.push_str("  <default>\n");
    let _ = writeln!(
        x,
        "    <joint armature=\"{}\" damping=\"{}\" frictionloss=\"{}\" limited=\"true\"/>",
        servo.armature, servo.gear_damping, servo.friction_loss
    );
    x.push_str("    <geom contype=\"2\" conaffinity=\"0\" mass=\"0\" material=\"link\"/>\n");
    x.push_str("    <motor gear=\"1\" ctrllimited=\"false\"/>\n");
    x.push_str("  </default>\n");
    x.push_str("  <worldbody>\n");
    x.push_str("    <light name=\"sun\" pos=\"0.3 -1 2.5\" dir=\"-0.1 0.4 -1\" directional=\"true\" diffuse=\".8 .8 .8\" castshadow=\"true\"/>\n");
    let mu = env.floor_friction;
    let floor_z = if env.step_height_m > 0.0 {
        -env.step_height_m
    } else {
        0.0
    };
    let _ = writeln!(
        x,
        "    <geom name=\"floor\" type=\"plane\" size=\"4 4 0.1\" pos=\"0 0 {floor_z}\" euler=\"0 {} 0\" material=\"grid\" contype=\"1\" conaffinity=\"2\" friction=\"{mu} 0.005 0.0001\"/>",
        -env.slope_deg.to_radians()
    );
    if env.step_height_m > 0.0 {
        let h = env.step_height_m;
        let s = env.tile_size_m;
        let mut rng = Rng::new(seed, 7);
        let (nx0, nx1) = ((-0.15 / s).floor() as i64, (0.6 / s).ceil() as i64);
        let (ny0, ny1) = ((-0.2 / s).floor() as i64, (0.2 / s).ceil() as i64);
        for ix in nx0..nx1 {
            for iy in ny0..ny1 {
                let (cx, cy) = ((ix as f64 + 0.5) * s, (iy as f64 + 0.5) * s);
                // Draw for every tile (so the pattern does not depend on the start area).
                let r = rng.uniform() * 2.0 - 1.0;
                let level = cx.abs() < 0.09 + s / 2.0 && cy.abs() < 0.09 + s / 2.0;
                let top = if level { 0.0 } else { r * h };
                let half = (top + h) / 2.0;
                if half <= 1e-6 {
                    continue;
                }
                let _ = writeln!(
                    x,
                    "    <geom name=\"tile_{ix}_{iy}\" type=\"box\" size=\"{} {} {half}\" pos=\"{cx} {cy} {}\" material=\"tile\" contype=\"1\" conaffinity=\"2\" friction=\"{mu} 0.005 0.0001\"/>",
                    s / 2.0,
                    s / 2.0,
                    -h + half
                );
            }
        }
    }
    let _ = writeln!(x, "    <body name=\"torso\" pos=\"0 0 {z0}\">");
    x.push_str("      <freejoint name=\"root\"/>\n");
    let j = m.upper_body_inertia * ms;
    let inertias = m.inertias.map(|i| LinkInertias {
        upper_body_roll_yaw: i.upper_body_roll_yaw.map(|v| v * ms),
        thigh: i.thigh.map(|v| v * ms),
        calf: i.calf.map(|v| v * ms),
        sole: i.sole.map(|v| v * ms),
    });
    let ub_diag = inertias.map_or([j, j, 0.5 * j], |i| {
        let [roll, yaw] = i.upper_body_roll_yaw;
        [roll, j, yaw]
    });
    inertial(
        &mut x,
        "      ",
        [
            m.upper_body_forward + env.trunk_com_dx_m,
            0.0,
            m.upper_body_height,
        ],
        m.upper_body * ms,
        ub_diag,
    );
    x.push_str("      <site name=\"imu\" pos=\"0 0 0\" size=\"0.01\"/>\n");
    for (name, h, p) in torso_boxes(robot) {
        let _ = writeln!(
            x,
            "      <geom name=\"{name}\" type=\"box\" size=\"{} {} {}\" pos=\"{} {} {}\" material=\"body\"/>",
            h[0], h[1], h[2], p[0], p[1], p[2]
        );
    }
    let _ = writeln!(
        x,
        "      <geom name=\"head\" type=\"sphere\" size=\"{}\" pos=\"0 0 {}\" material=\"body\"/>",
        robot.shape.head[0], robot.shape.head[1]
    );
    x.push_str("      <camera name=\"track\" mode=\"trackcom\" pos=\"0.55 -0.75 0.25\" xyaxes=\"0.81 0.59 0 -0.2 0.28 0.94\"/>\n");
    if env.payload_kg > 0.0 {
        let p = env.payload_pos_m;
        let _ = writeln!(
            x,
            "      <body name=\"payload\" pos=\"{} {} {}\">",
            p[0], p[1], p[2]
        );
        inertial(
            &mut x,
            "        ",
            [0.0; 3],
            env.payload_kg,
            box_inertia(env.payload_kg, 0.05, 0.05, 0.05),
        );
        x.push_str("        <geom type=\"box\" size=\"0.025 0.025 0.025\" rgba=\".8 .2 .2 1\"/>\n");
        x.push_str("      </body>\n");
    }
    for side in [Side::Left, Side::Right] {
        let (k, pfx, sigma) = match side {
            Side::Left => (0usize, "l", 1.0),
            Side::Right => (1usize, "r", -1.0),
        };
        let joint = |x: &mut String, pad: &str, jj: usize, axis: &str| {
            let lim = robot.joint_limit(side, jj);
            let name = JOINT_NAMES.get(6 * k + jj).copied().unwrap_or("joint");
            let _ = writeln!(
                x,
                "{pad}<joint name=\"{name}\" type=\"hinge\" axis=\"{axis}\" range=\"{} {}\"/>",
                lim.min, lim.max
            );
        };
        let _ = writeln!(
            x,
            "      <body name=\"{pfx}_thigh\" pos=\"0 {} 0\">",
            sigma * g.hip_offset_y
        );
        joint(&mut x, "        ", 0, "0 0 1");
        joint(&mut x, "        ", 1, "1 0 0");
        joint(&mut x, "        ", 2, "0 1 0");
        rod_link(
            &mut x,
            "        ",
            g.thigh,
            m.thigh * ms,
            m.thigh_com,
            inertias.map(|i| i.thigh),
        );
        let _ = writeln!(
            x,
            "        <body name=\"{pfx}_calf\" pos=\"0 0 {}\">",
            -g.thigh
        );
        joint(&mut x, "          ", 3, "0 1 0");
        rod_link(
            &mut x,
            "          ",
            g.calf,
            m.calf * ms,
            m.calf_com,
            inertias.map(|i| i.calf),
        );
        let _ = writeln!(
            x,
            "          <body name=\"{pfx}_foot\" pos=\"0 0 {}\">",
            -g.calf
        );
        joint(&mut x, "            ", 4, "0 1 0");
        joint(&mut x, "            ", 5, "1 0 0");
        let sp = sole_point(robot, sigma);
        inertial(
            &mut x,
            "            ",
            [
                sp[0] + m.sole_com[0],
                sp[1] + sigma * m.sole_com[1],
                -(g.ankle_height - m.sole_height),
            ],
            m.sole * ms,
            inertias.map_or_else(
                || box_inertia(m.sole * ms, g.sole_length, g.sole_width, 0.02),
                |i| i.sole,
            ),
        );
        let _ = writeln!(
            x,
            "            <geom name=\"{pfx}_sole\" type=\"box\" size=\"{} {} {}\" pos=\"{} {} {}\" material=\"sole\" solref=\"0.004 1\" friction=\"{mu} 0.005 0.0001\" condim=\"4\"/>",
            g.sole_length / 2.0,
            g.sole_width / 2.0,
            SOLE_THICKNESS / 2.0,
            sp[0],
            sp[1],
            -g.ankle_height + SOLE_THICKNESS / 2.0
        );
        let _ = writeln!(
            x,
            "            <site name=\"{pfx}_sole\" pos=\"{} {} {}\" size=\"0.005\"/>",
            sp[0], sp[1], sp[2]
        );
        x.push_str("          </body>\n        </body>\n      </body>\n");
    }
    x.push_str("    </body>\n  </worldbody>\n");
    x.push_str("  <equality>\n    <weld name=\"hold\" body1=\"torso\"/>\n  </equality>\n");
    x.push_str("  <actuator>\n");
    for name in JOINT_NAMES {
        let _ = writeln!(x, "    <motor name=\"{name}\" joint=\"{name}\"/>");
    }
    x.push_str("  </actuator>\n  <sensor>\n");
    x.push_str("    <gyro name=\"imu_gyro\" site=\"imu\"/>\n");
    x.push_str("    <accelerometer name=\"imu_accel\" site=\"imu\"/>\n");
    x.push_str("  </sensor>\n</mujoco>\n");
    x
}
