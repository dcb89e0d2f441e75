//! The robot as a URDF (for Foxglove's 3D panel) and its link transforms, generated from
//! [`gait_core::Robot`] and the MJCF model's visual sizes ([`super::mjcf`]) so that the
//! geometry has one source.
//!
//! # Links and joints (world x forward, y left, z up; `σ` = +1 left, −1 right)
//!
//! The root link `pelvis` is the pelvis point P. Each leg is a chain of seven links:
//!
//! | joint | parent → child | origin in the parent | axis |
//! | --- | --- | --- | --- |
//! | `s_hip_yaw` | `pelvis` → `s_hip_yaw_link` | (0, σ·d, 0) | z |
//! | `s_hip_roll` | `s_hip_yaw_link` → `s_hip_roll_link` | 0 | x |
//! | `s_hip_pitch` | `s_hip_roll_link` → `s_thigh` | 0 | y |
//! | `s_knee` | `s_thigh` → `s_calf` | (0, 0, −L1) | y |
//! | `s_ankle_pitch` | `s_calf` → `s_ankle_link` | (0, 0, −L2) | y |
//! | `s_ankle_roll` | `s_ankle_link` → `s_foot` | 0 | x |
//! | `s_sole_fixed` (fixed) | `s_foot` → `s_sole` | (o_x, σ·o_y, −h) | — |
//!
//! (`s` = `l` or `r`; joint names and order are [`gait_core::robot::JOINT_NAMES`].) The joint
//! angles rotate the child about the axis by the right-hand rule, so the chain is the one of
//! [`gait_core::kinematics::leg`]: `R_F = R_P·Rz(q0)·Rx(q1)·Ry(q2)·Ry(q3)·Ry(q4)·Rx(q5)`, the
//! `s_sole` frame at the sole point S (tested against [`gait_core::kinematics::leg::leg_fk`]).

use std::fmt::Write as _;

use gait_core::robot::{JOINTS_PER_LEG, JOINT_NAMES, LEG_JOINTS};
use gait_core::{Robot, Side};

use super::mjcf::{sole_point, torso_boxes, LINK_INSET, LINK_RADIUS, SOLE_THICKNESS};

/// The root link (the pelvis point P).
pub const ROOT: &str = "pelvis";

/// One joint of the link tree.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeJoint {
    /// Joint name (a [`JOINT_NAMES`] entry, or `s_sole_fixed`).
    pub name: String,
    /// Parent link.
    pub parent: String,
    /// Child link.
    pub child: String,
    /// Child frame origin in the parent frame at zero angle, m.
    pub origin: [f64; 3],
    /// Rotation axis (unit, parent frame) and the joint's index in the 12 angles; `None`: fixed.
    pub axis: Option<([f64; 3], usize)>,
}

/// The link tree of `robot`: both legs' joints, left leg first, each leg's revolute joints in
/// joint order followed by its fixed sole joint.
pub fn tree(robot: &Robot) -> Vec<TreeJoint> {
    let g = robot.geometry;
    let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let mut out = Vec::with_capacity(2 * (JOINTS_PER_LEG + 1));
    for side in [Side::Left, Side::Right] {
        let k = side.index();
        let s = if k == 0 { "l" } else { "r" };
        let links = [
            ROOT.to_string(),
            format!("{s}_hip_yaw_link"),
            format!("{s}_hip_roll_link"),
            format!("{s}_thigh"),
            format!("{s}_calf"),
            format!("{s}_ankle_link"),
            format!("{s}_foot"),
            format!("{s}_sole"),
        ];
        let spec: [([f64; 3], [f64; 3]); JOINTS_PER_LEG] = [
            ([0.0, side.sign() * g.hip_offset_y, 0.0], z),
            ([0.0; 3], x),
            ([0.0; 3], y),
            ([0.0, 0.0, -g.thigh], y),
            ([0.0, 0.0, -g.calf], y),
            ([0.0; 3], x),
        ];
        for (j, (origin, axis)) in spec.into_iter().enumerate() {
            let i = JOINTS_PER_LEG * k + j;
            out.push(TreeJoint {
                name: JOINT_NAMES[i].to_string(),
                parent: links[j].clone(),
                child: links[j + 1].clone(),
                origin,
                axis: Some((axis, i)),
            });
        }
        out.push(TreeJoint {
            name: format!("{s}_sole_fixed"),
            parent: links[6].clone(),
            child: links[7].clone(),
            origin: sole_point(robot, side.sign()),
            axis: None,
        });
    }
    out
}

/// A rigid transform: the child frame's origin in the parent frame and its rotation as a
/// quaternion (x, y, z, w).
#[derive(Clone, Debug, PartialEq)]
pub struct LinkTransform {
    /// Parent frame.
    pub parent: String,
    /// Child frame.
    pub child: String,
    /// Translation, m.
    pub translation: [f64; 3],
    /// Rotation (x, y, z, w).
    pub rotation: [f64; 4],
}

/// The transforms of every joint of `tree` at joint angles `q` (rad, joint order).
pub fn transforms(tree: &[TreeJoint], q: &[f64; LEG_JOINTS]) -> Vec<LinkTransform> {
    tree.iter()
        .map(|j| {
            let rotation = match j.axis {
                Some((a, i)) => {
                    let (s, c) = (q[i] / 2.0).sin_cos();
                    [a[0] * s, a[1] * s, a[2] * s, c]
                }
                None => [0.0, 0.0, 0.0, 1.0],
            };
            LinkTransform {
                parent: j.parent.clone(),
                child: j.child.clone(),
                translation: j.origin,
                rotation,
            }
        })
        .collect()
}

fn v3(v: [f64; 3]) -> String {
    format!("{} {} {}", v[0], v[1], v[2])
}

/// The URDF text of `robot`: the link tree of [`tree`] with joint limits (the robot's; effort
/// `stall_torque_nm`, velocity the servo's speed limit) and visuals: the MJCF model's torso
/// boxes and head on `pelvis`, a cylinder along each thigh and calf, the sole box on each foot.
pub fn urdf(robot: &Robot, stall_torque_nm: f64) -> String {
    let g = robot.geometry;
    let mut x = String::new();
    let _ = writeln!(
        x,
        "<?xml version=\"1.0\"?>\n<robot name=\"walker-{}\">",
        robot.name
    );
    for (name, rgba) in [
        ("body", "0.25 0.3 0.38 1"),
        ("link", "0.85 0.55 0.2 1"),
        ("sole", "0.1 0.1 0.1 1"),
    ] {
        let _ = writeln!(
            x,
            "  <material name=\"{name}\"><color rgba=\"{rgba}\"/></material>"
        );
    }
    let visual = |x: &mut String, xyz: [f64; 3], geometry: String, material: &str| {
        let _ = writeln!(
            x,
            "    <visual><origin xyz=\"{}\" rpy=\"0 0 0\"/><geometry>{geometry}</geometry><material name=\"{material}\"/></visual>",
            v3(xyz)
        );
    };
    let _ = writeln!(x, "  <link name=\"{ROOT}\">");
    for (_, h, p) in torso_boxes(robot) {
        let size = v3([2.0 * h[0], 2.0 * h[1], 2.0 * h[2]]);
        visual(&mut x, p, format!("<box size=\"{size}\"/>"), "body");
    }
    visual(
        &mut x,
        [0.0, 0.0, robot.shape.head[1]],
        format!("<sphere radius=\"{}\"/>", robot.shape.head[0]),
        "body",
    );
    x.push_str("  </link>\n");
    let tree = tree(robot);
    for j in &tree {
        let _ = writeln!(x, "  <link name=\"{}\">", j.child);
        let rod = |x: &mut String, len: f64| {
            let l = len - 2.0 * LINK_INSET;
            visual(
                x,
                [0.0, 0.0, -len / 2.0],
                format!("<cylinder radius=\"{LINK_RADIUS}\" length=\"{l}\"/>"),
                "link",
            );
        };
        if j.child.ends_with("_thigh") {
            rod(&mut x, g.thigh);
        } else if j.child.ends_with("_calf") {
            rod(&mut x, g.calf);
        } else if j.child.ends_with("_foot") {
            let sigma = if j.child.starts_with('l') { 1.0 } else { -1.0 };
            let sp = sole_point(robot, sigma);
            visual(
                &mut x,
                [sp[0], sp[1], -g.ankle_height + SOLE_THICKNESS / 2.0],
                format!(
                    "<box size=\"{}\"/>",
                    v3([g.sole_length, g.sole_width, SOLE_THICKNESS])
                ),
                "sole",
            );
        }
        x.push_str("  </link>\n");
    }
    for j in &tree {
        let kind = if j.axis.is_some() {
            "revolute"
        } else {
            "fixed"
        };
        let _ = writeln!(x, "  <joint name=\"{}\" type=\"{kind}\">", j.name);
        let _ = writeln!(
            x,
            "    <parent link=\"{}\"/><child link=\"{}\"/><origin xyz=\"{}\" rpy=\"0 0 0\"/>",
            j.parent,
            j.child,
            v3(j.origin)
        );
        if let Some((axis, i)) = j.axis {
            let side = if i < JOINTS_PER_LEG {
                Side::Left
            } else {
                Side::Right
            };
            let lim = robot.joint_limit(side, i % JOINTS_PER_LEG);
            let _ = writeln!(
                x,
                "    <axis xyz=\"{}\"/><limit lower=\"{}\" upper=\"{}\" effort=\"{stall_torque_nm}\" velocity=\"{}\"/>",
                v3(axis),
                lim.min,
                lim.max,
                robot.servo.max_speed
            );
        }
        x.push_str("  </joint>\n");
    }
    x.push_str("</robot>\n");
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use gait_core::kinematics::leg::{leg_fk, Pose};
    use std::collections::BTreeMap;

    type Frame = ([f64; 3], [[f64; 3]; 3]);

    fn rot(q: [f64; 4]) -> [[f64; 3]; 3] {
        let [x, y, z, w] = q;
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - z * w),
                2.0 * (x * z + y * w),
            ],
            [
                2.0 * (x * y + z * w),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - x * w),
            ],
            [
                2.0 * (x * z - y * w),
                2.0 * (y * z + x * w),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    fn mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
        std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
    }

    fn apply(a: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
    }

    /// The transforms composed from the pelvis put each `s_sole` frame where gait-core's FK puts
    /// the foot (position and rotation), for a bent, twisted pose of both legs.
    #[test]
    fn transforms_compose_to_the_feet_of_gait_core_fk() {
        for robot in gait_core::robot::ROBOTS {
            transforms_are_fk(robot);
        }
    }

    fn transforms_are_fk(robot: Robot) {
        let q: [f64; LEG_JOINTS] = [
            0.1, 0.05, -0.4, 0.8, -0.35, -0.04, -0.12, -0.06, -0.3, 0.7, -0.42, 0.08,
        ];
        let pelvis = Pose::new(0.03, -0.01, 0.21, 0.02, -0.05, 0.3);
        let mut frames: BTreeMap<String, Frame> = BTreeMap::new();
        frames.insert(ROOT.into(), (pelvis.position(), pelvis.rotation()));
        for t in transforms(&tree(&robot), &q) {
            let (p, r) = frames[&t.parent];
            let d = apply(&r, t.translation);
            let child = (
                [p[0] + d[0], p[1] + d[1], p[2] + d[2]],
                mul(&r, &rot(t.rotation)),
            );
            frames.insert(t.child.clone(), child);
        }
        for (side, s) in [(Side::Left, "l"), (Side::Right, "r")] {
            let qs: [f64; 6] = std::array::from_fn(|j| q[6 * side.index() + j]);
            let foot = leg_fk(&robot, side, &pelvis, &qs);
            let (p, r) = frames[&format!("{s}_sole")];
            let want = foot.rotation();
            for i in 0..3 {
                assert!(
                    (p[i] - foot.position()[i]).abs() < 1e-12,
                    "{} {s}: {p:?}",
                    robot.name
                );
                for j in 0..3 {
                    assert!(
                        (r[i][j] - want[i][j]).abs() < 1e-12,
                        "{s}: {r:?} vs {want:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn urdf_names_every_joint_with_its_limits() {
        let robot = Robot::reference();
        let text = urdf(&robot, 4.1);
        for name in JOINT_NAMES {
            assert!(
                text.contains(&format!("<joint name=\"{name}\" type=\"revolute\">")),
                "{name}"
            );
        }
        assert_eq!(text.matches("<link name=").count(), 1 + 2 * 7);
        assert_eq!(text.matches("type=\"fixed\"").count(), 2);
        let lim = robot.joint_limit(Side::Left, 3);
        assert!(text.contains(&format!("lower=\"{}\" upper=\"{}\"", lim.min, lim.max)));
    }
}
