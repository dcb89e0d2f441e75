//! The robot descriptions: each validates, is found by name, and the OP3's kinematics is the
//! chain of MuJoCo Menagerie's `robotis_op3/op3.xml` (its body positions and joint axes,
//! written out below as the test's independent data), through the description's mounting
//! signs.

use gait_core::kinematics::leg::{LegKinematics, Pose};
use gait_core::robot::{ImuPlace, ROBOTS, ROBOT_NAMES};
use gait_core::{GaitError, Robot, Side};
use proptest::prelude::*;

type V3 = [f64; 3];
type M3 = [[f64; 3]; 3];

fn mul(a: &M3, b: &M3) -> M3 {
    core::array::from_fn(|i| core::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn apply(a: &M3, v: &V3) -> V3 {
    core::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

fn add(a: &V3, b: &V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Rotation by `angle` about the unit `axis` (Rodrigues).
fn axis_angle(axis: V3, angle: f64) -> M3 {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = axis;
    let t = 1.0 - c;
    [
        [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
        [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
        [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
    ]
}

/// op3.xml's leg chain, side sign `s` (+1 left): each body's position in its parent and its
/// joint's axis, hip yaw to ankle roll.
fn menagerie_leg(s: f64) -> [(V3, V3); 6] {
    [
        ([0.0, s * 0.035, 0.0], [0.0, 0.0, -1.0]),
        ([-0.024, 0.0, -0.0285], [-1.0, 0.0, 0.0]),
        ([0.0241, s * 0.019, 0.0], [0.0, s, 0.0]),
        ([0.0, 0.0, -0.11015], [0.0, s, 0.0]),
        ([0.0, 0.0, -0.11], [0.0, -s, 0.0]),
        ([-0.0241, -s * 0.019, 0.0], [1.0, 0.0, 0.0]),
    ]
}

/// The sole's centre in op3.xml's ankle roll link (the wider foot box's centre, on the
/// ground: its half height 0.004 below the box centre 0.0265 down).
fn menagerie_sole(s: f64) -> V3 {
    [0.024, s * 0.0125, -0.0305]
}

/// Menagerie forward kinematics in `body_link`'s frame: (sole centre, ankle roll link
/// rotation) for servo angles `theta`.
fn menagerie_fk(side: Side, theta: &[f64; 6]) -> (V3, M3) {
    let s = side.sign();
    let mut p = [0.0; 3];
    let mut r: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for ((pos, axis), &t) in menagerie_leg(s).iter().zip(theta) {
        p = add(&p, &apply(&r, pos));
        r = mul(&r, &axis_angle(*axis, t));
    }
    (add(&p, &apply(&r, &menagerie_sole(s))), r)
}

#[test]
fn every_description_validates_and_is_found_by_name() {
    for (robot, name) in ROBOTS.iter().zip(ROBOT_NAMES) {
        assert_eq!(robot.validate(), Ok(()), "{name}");
        assert_eq!(robot.validate_bus(), Ok(()), "{name}");
        assert_eq!(Robot::by_name(name), Some(robot));
    }
    assert_eq!(Robot::by_name("tku-x"), Some(&Robot::reference()));
    assert_eq!(Robot::by_name("op3"), Some(&Robot::op3()));
    assert_eq!(Robot::by_name("OP3"), None);
    assert_eq!(Robot::by_name(""), None);
}

#[test]
fn the_two_robots_differ_where_the_sources_say() {
    let (t, o) = (Robot::reference(), Robot::op3());
    assert_eq!(t.bus.legs, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
    assert_eq!(t.bus.foot_boards, Some([111, 112]));
    assert_eq!(t.bus.imu, ImuPlace::Bus(200));
    assert_eq!(t.bus.baud, 1_000_000);
    assert!(t.bus.held.is_empty());
    // OP3.robot: legs 7–18, the right leg's joint first, 2 Mbps; arms 1–6, head 19–20.
    assert_eq!(o.bus.legs, [8, 10, 12, 14, 16, 18, 7, 9, 11, 13, 15, 17]);
    assert_eq!(o.bus.baud, 2_000_000);
    assert_eq!(o.bus.foot_boards, None);
    // open_cr_module.cpp: the robot's x and y are the chip's negated, z is z.
    let ImuPlace::Board(axes) = o.bus.imu else {
        panic!("the OP3's IMU is the OpenCR's");
    };
    assert!(axes.is_rotation());
    assert_eq!(
        axes.to_trunk_i32([10, 20, 30]),
        [-10, -20, 30],
        "the chip's x and y point backward and right in the torso"
    );
    let mut held: Vec<u8> = o.bus.held.iter().map(|h| h.id).collect();
    held.sort_unstable();
    assert_eq!(held, [1, 2, 3, 4, 5, 6, 19, 20]);
    // Menagerie's masses: trunk, head, arms and legs sum to 3.14747 kg.
    assert!(
        (o.masses.total() - 3.14747).abs() < 1e-9,
        "{}",
        o.masses.total()
    );
}

#[test]
fn validate_refuses_a_shared_id_a_bad_sign_and_no_baud() {
    let mut r = Robot::op3();
    r.bus.legs[3] = 19; // the head pan servo's ID
    assert_eq!(r.validate_bus(), Err(GaitError::BadRobotDescription));
    let mut r = Robot::reference();
    r.bus.legs[0] = 111; // a foot board's ID
    assert_eq!(r.validate_bus(), Err(GaitError::BadRobotDescription));
    let mut r = Robot::reference();
    r.bus.legs[0] = 254; // broadcast
    assert_eq!(r.validate_bus(), Err(GaitError::BadRobotDescription));
    let mut r = Robot::op3();
    r.mounting[2] = 0;
    assert_eq!(r.validate_bus(), Err(GaitError::BadRobotDescription));
    let mut r = Robot::op3();
    r.bus.baud = 0;
    assert_eq!(r.validate_bus(), Err(GaitError::BadRobotDescription));
}

/// At the zero pose the OP3's sole point is 0.25065 m below the hip point and 0.0125 m outward
/// of it, 0.0001 m behind.
#[test]
fn op3_zero_pose_from_the_description() {
    let kin = LegKinematics::<f64>::new(&Robot::op3());
    let pelvis = Pose::level(0.0, 0.0, 0.0, 0.0);
    for side in [Side::Left, Side::Right] {
        let s = side.sign();
        let f = kin.fk(side, &pelvis, &[0.0; 6]);
        assert!((f.x + 0.0001).abs() < 1e-12, "{f:?}");
        assert!((f.y - s * (0.035 + 0.0125)).abs() < 1e-12, "{f:?}");
        assert!((f.z + 0.11015 + 0.11 + 0.0305).abs() < 1e-12, "{f:?}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    /// The description's FK (pelvis point P = the hips' midpoint, at (0.0001, 0, −0.0285) in
    /// `body_link`) gives op3.xml's sole centre and foot rotation for any joint angles, the servo
    /// angles being the mounting sign times the joint angles: within 0.1 mm·|q0| + 1e-12 m (the
    /// yaw axis passes 0.1 mm behind the hip point in op3.xml) and 1e-12 in rotation.
    #[test]
    fn op3_fk_is_the_menagerie_chain(
        left in any::<bool>(),
        q in proptest::array::uniform6(-1.2..1.2f64),
    ) {
        let robot = Robot::op3();
        let side = if left { Side::Left } else { Side::Right };
        let kin = LegKinematics::<f64>::new(&robot);
        let p = [0.0001, 0.0, -0.0285];
        let foot = kin.fk(side, &Pose::level(p[0], p[1], p[2], 0.0), &q);
        let i = side.index();
        let theta: [f64; 6] =
            core::array::from_fn(|j| f64::from(robot.mounting[6 * i + j]) * q[j]);
        let (sole, r) = menagerie_fk(side, &theta);
        let tol = 1e-4 * q[0].abs() + 1e-12;
        let got = foot.position();
        for k in 0..3 {
            prop_assert!((got[k] - sole[k]).abs() <= tol, "{side:?} {q:?}: {got:?} vs {sole:?}");
        }
        let rot = foot.rotation();
        for a in 0..3 {
            for b in 0..3 {
                prop_assert!((rot[a][b] - r[a][b]).abs() < 1e-12, "{side:?} {q:?}");
            }
        }
    }

    /// IK(FK(q)) = q on the OP3 (sole point off the ankle) as on the reference robot.
    #[test]
    fn op3_ik_of_fk_is_q(
        left in any::<bool>(),
        q0 in -0.85..0.85f64, q1 in -0.35..0.35f64, q2 in -1.85..0.85f64,
        q3 in 0.2..2.4f64, q4 in -1.25..1.05f64, q5 in -0.35..0.35f64,
        p in (-0.1..0.1f64, -0.1..0.1f64, 0.1..0.3f64, -0.15..0.15f64, -0.15..0.15f64, -0.5..0.5f64),
    ) {
        prop_assume!((q3 / 2.0 + q4).abs() < 1.4);
        let side = if left { Side::Left } else { Side::Right };
        let kin = LegKinematics::<f64>::new(&Robot::op3());
        let q = [q0, q1, q2, q3, q4, q5];
        let pelvis = Pose::new(p.0, p.1, p.2, p.3, p.4, p.5);
        let foot = kin.fk(side, &pelvis, &q);
        let sol = kin.ik(side, &pelvis, &foot);
        prop_assert!(!sol.clamped(), "{sol:?}");
        for (j, (got, want)) in sol.q.iter().zip(q.iter()).enumerate() {
            prop_assert!((got - want).abs() < 1e-9, "joint {j}: {got} vs {want}");
        }
    }
}

/// The plan's reach check from each robot's legs (`StepLimits::for_robot`): L = 0.95 × (thigh +
/// calf), the hip's pitch axis at z_c minus the hip yaw joint's height, the ankle above the
/// sole; the widest stance adds the soles' outward offsets. Figures worked by hand from the
/// descriptions' numbers.
#[test]
fn the_reach_check_reads_each_robots_legs() {
    use gait_core::trajectory::plan::StepLimits;
    // TKU-X at Table 2's z_c 0.217: L = 0.19, h = 0.187, reach = √(0.19² − 0.187²) = 0.033630.
    let t = StepLimits::for_robot(&Robot::reference(), 0.217);
    assert!((t.max_length - 2.0 * 0.033630).abs() < 1e-5, "{t:?}");
    assert!(
        (t.max_width - (0.09 + 2.0 * 0.033630)).abs() < 1e-5,
        "{t:?}"
    );
    assert!((t.min_width - 0.07).abs() < 1e-12, "{t:?}");
    // OP3 at z_c 0.235: L = 0.95 × 0.22015 = 0.2091425, h = 0.235 − 0.0285 − 0.0305 = 0.176,
    // reach = √(0.2091425² − 0.176²) = 0.112981; widest = 2 × (0.035 + 0.0125) + 2 × reach.
    let o = StepLimits::for_robot(&Robot::op3(), 0.235);
    assert!((o.max_length - 2.0 * 0.112981).abs() < 1e-5, "{o:?}");
    assert!(
        (o.max_width - (0.095 + 2.0 * 0.112981)).abs() < 1e-5,
        "{o:?}"
    );
    assert!((o.min_width - 0.088).abs() < 1e-12, "{o:?}");
    // At the OP3's straight-leg height nothing is in reach.
    let straight = StepLimits::for_robot(&Robot::op3(), 0.279);
    assert_eq!(straight.max_length, 0.0);
}

/// (I1) and (I2) of [`ImuAxes`], against a quarter turn worked by hand and over every signed
/// permutation: the inverse undoes the turn, the rotation check keeps the 24 turns of a cube
/// and refuses its 24 mirror images and any bad axis or sign.
#[test]
fn imu_axes_turn_a_vector_and_back() {
    use gait_core::robot::ImuAxes;
    // The chip turned a quarter turn left about z: its x points along the trunk's y, its y
    // along the trunk's −x. A trunk x reads the chip's −y, the trunk's y the chip's x.
    let quarter = ImuAxes {
        axis: [1, 0, 2],
        sign: [-1, 1, 1],
    };
    assert!(quarter.is_rotation());
    // A chip rate of 1 about its x is a rate of 1 about the trunk's y.
    assert_eq!(quarter.to_trunk_i32([1, 0, 0]), [0, 1, 0]);
    assert_eq!(quarter.to_trunk_i32([0, 1, 0]), [-1, 0, 0]);
    assert_eq!(quarter.to_chip_f64([0.0, 1.0, 0.0]), [1.0, 0.0, 0.0]);
    assert_eq!(quarter.to_trunk_i32([i32::MIN, 0, 0]), [0, i32::MIN, 0]);
    assert_eq!(quarter.to_trunk_i32([0, i32::MIN, 0]), [i32::MAX, 0, 0]);
    assert_eq!(ImuAxes::ALIGNED.to_trunk_i32([4, 5, 6]), [4, 5, 6]);
    let mut turns = 0;
    for axis in [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ] {
        for bits in 0..8u8 {
            let sign = [0, 1, 2].map(|k| if bits & (1 << k) != 0 { -1 } else { 1 });
            let a = ImuAxes { axis, sign };
            // The determinant of the signed permutation matrix, by cofactors.
            let mut m = [[0i32; 3]; 3];
            for i in 0..3 {
                m[i][usize::from(axis[i])] = i32::from(sign[i]);
            }
            let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
            assert_eq!(a.is_rotation(), det == 1, "{a:?}");
            turns += usize::from(det == 1);
            let v = [3.0, -5.0, 7.0];
            let chip = a.to_chip_f64(v);
            let back = a.to_trunk_i32(chip.map(|x| x as i32));
            assert_eq!(back, v.map(|x| x as i32), "{a:?}");
        }
    }
    assert_eq!(turns, 24);
    assert!(!ImuAxes {
        axis: [0, 0, 2],
        sign: [1, 1, 1]
    }
    .is_rotation());
    assert!(!ImuAxes {
        axis: [0, 1, 3],
        sign: [1, 1, 1]
    }
    .is_rotation());
    assert!(!ImuAxes {
        axis: [0, 1, 2],
        sign: [1, 0, 1]
    }
    .is_rotation());
}

/// One body of op3.xml: parent, position in it, joint axis (None: the free base), and its
/// `<inertial>`: position, quaternion (w, x, y, z), mass, diagonal inertia.
struct Link {
    name: &'static str,
    parent: &'static str,
    pos: V3,
    axis: Option<V3>,
    com: V3,
    quat: [f64; 4],
    mass: f64,
    diag: V3,
}

/// op3.xml's bodies (left side and the upper body; the right side mirrors them).
#[rustfmt::skip]
const MENAGERIE_LINKS: [Link; 15] = [
    Link { name: "body_link", parent: "", pos: [0.0; 3], axis: None, com: [-0.01501, 0.00013, 0.06582], quat: [0.704708, 0.704003, 0.0667707, -0.0575246], mass: 1.34928, diag: [0.00341264, 0.00316574, 0.00296931] },
    Link { name: "head_pan_link", parent: "body_link", pos: [-0.001, 0.0, 0.1365], axis: Some([0.0, 0.0, 1.0]), com: [0.00233, 0.0, 0.00823], quat: [0.663575, 0.663575, 0.244272, -0.244272], mass: 0.01176, diag: [4.23401e-06, 3.60599e-06, 1.65e-06] },
    Link { name: "head_tilt_link", parent: "head_pan_link", pos: [0.01, 0.019, 0.0285], axis: Some([0.0, -1.0, 0.0]), com: [0.0023, -0.01863, 0.0277], quat: [0.997312, 0.00973825, 0.0726131, -0.00102702], mass: 0.13631, diag: [0.000107452, 8.72266e-05, 4.39413e-05] },
    Link { name: "l_sho_pitch_link", parent: "body_link", pos: [-0.001, 0.06, 0.111], axis: Some([0.0, 1.0, 0.0]), com: [0.0, 0.00823, -0.00233], quat: [0.244272, 0.663575, 0.244272, 0.663575], mass: 0.01176, diag: [4.23401e-06, 3.60599e-06, 1.65e-06] },
    Link { name: "l_sho_roll_link", parent: "l_sho_pitch_link", pos: [0.019, 0.0285, -0.01], axis: Some([-1.0, 0.0, 0.0]), com: [-0.01844, 0.04514, 0.00028], quat: [0.501853, 0.50038, -0.498173, 0.499588], mass: 0.17758, diag: [0.000234742, 0.00022804, 3.04183e-05] },
    Link { name: "l_el_link", parent: "l_sho_roll_link", pos: [0.0, 0.0904, -0.0001], axis: Some([1.0, 0.0, 0.0]), com: [-0.019, 0.07033, 0.0038], quat: [0.483289, 0.51617, -0.51617, 0.483289], mass: 0.04127, diag: [6.8785e-05, 6.196e-05, 1.2065e-05] },
    Link { name: "r_sho_pitch_link", parent: "body_link", pos: [-0.001, -0.06, 0.111], axis: Some([0.0, -1.0, 0.0]), com: [0.0, -0.00823, -0.00233], quat: [-0.244272, 0.663575, -0.244272, 0.663575], mass: 0.01176, diag: [4.23401e-06, 3.60599e-06, 1.65e-06] },
    Link { name: "r_sho_roll_link", parent: "r_sho_pitch_link", pos: [0.019, -0.0285, -0.01], axis: Some([-1.0, 0.0, 0.0]), com: [-0.01844, -0.04514, 0.00028], quat: [0.50038, 0.501853, -0.499588, 0.498173], mass: 0.17758, diag: [0.000234742, 0.00022804, 3.04183e-05] },
    Link { name: "r_el_link", parent: "r_sho_roll_link", pos: [0.0, -0.0904, -0.0001], axis: Some([1.0, 0.0, 0.0]), com: [-0.019, -0.07033, 0.0038], quat: [0.51617, 0.483289, -0.483289, 0.51617], mass: 0.04127, diag: [6.8785e-05, 6.196e-05, 1.2065e-05] },
    Link { name: "l_hip_yaw_link", parent: "body_link", pos: [0.0, 0.035, 0.0], axis: Some([0.0, 0.0, -1.0]), com: [-0.00157, 0.0, -0.00774], quat: [0.499041, 0.500957, 0.500957, 0.499041], mass: 0.01181, diag: [4.3e-06, 4.12004e-06, 1.50996e-06] },
    Link { name: "l_hip_roll_link", parent: "l_hip_yaw_link", pos: [-0.024, 0.0, -0.0285], axis: Some([-1.0, 0.0, 0.0]), com: [0.00388, 0.00028, -0.01214], quat: [0.502657, 0.490852, 0.498494, 0.507842], mass: 0.17886, diag: [0.000125243, 0.000108598, 4.65693e-05] },
    Link { name: "l_hip_pitch_link", parent: "l_hip_roll_link", pos: [0.0241, 0.019, 0.0], axis: Some([0.0, 1.0, 0.0]), com: [0.00059, -0.01901, -0.08408], quat: [0.999682, 0.0246915, 0.00447825, -0.002482], mass: 0.11543, diag: [0.000104996, 9.63044e-05, 2.47492e-05] },
    Link { name: "l_knee_link", parent: "l_hip_pitch_link", pos: [0.0, 0.0, -0.11015], axis: Some([0.0, 1.0, 0.0]), com: [0.0, -0.02151, -0.055], quat: [1.0, 0.0, 0.0, 0.0], mass: 0.04015, diag: [3.715e-05, 2.751e-05, 1.511e-05] },
    Link { name: "l_ank_pitch_link", parent: "l_knee_link", pos: [0.0, 0.0, -0.11], axis: Some([0.0, -1.0, 0.0]), com: [-0.02022, -0.01872, 0.01214], quat: [0.490852, 0.502657, 0.507842, 0.498494], mass: 0.17886, diag: [0.000125243, 0.000108598, 4.65693e-05] },
    Link { name: "l_ank_roll_link", parent: "l_ank_pitch_link", pos: [-0.0241, -0.019, 0.0], axis: Some([1.0, 0.0, 0.0]), com: [0.02373, 0.01037, -0.0276], quat: [0.0078515, 0.707601, 0.0113965, 0.706477], mass: 0.06934, diag: [0.000115818, 7.87135e-05, 4.03389e-05] },
];

/// The rotation of a unit quaternion (w, x, y, z).
fn quat_matrix([w, x, y, z]: [f64; 4]) -> M3 {
    let n = (w * w + x * x + y * y + z * z).sqrt();
    let (w, x, y, z) = (w / n, x / n, y / n, z / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// A link's frame in `body_link`'s at joint angles `angle(name)`: (rotation, origin).
fn link_frame(name: &str, angle: &dyn Fn(&str) -> f64) -> (M3, V3) {
    let l = MENAGERIE_LINKS.iter().find(|l| l.name == name).unwrap();
    let Some(axis) = l.axis else {
        return (
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [0.0; 3],
        );
    };
    let (rp, op) = link_frame(l.parent, angle);
    (
        mul(&rp, &axis_angle(axis, angle(name))),
        add(&op, &apply(&rp, &l.pos)),
    )
}

/// One link at `angle`: mass, centre of mass and inertia about it (body_link's axes); with
/// `mirror`, its mirror image in the sagittal plane (op3.xml's right links are the left ones'
/// mirror images).
fn part(name: &str, mirror: bool, angle: &dyn Fn(&str) -> f64) -> (f64, V3, M3) {
    let l = MENAGERIE_LINKS.iter().find(|l| l.name == name).unwrap();
    let (r, o) = link_frame(name, angle);
    let ri = mul(&r, &quat_matrix(l.quat));
    let d = [
        [l.diag[0], 0.0, 0.0],
        [0.0, l.diag[1], 0.0],
        [0.0, 0.0, l.diag[2]],
    ];
    let rt: M3 = core::array::from_fn(|i| core::array::from_fn(|j| ri[j][i]));
    let (c, i) = (add(&o, &apply(&r, &l.com)), mul(&mul(&ri, &d), &rt));
    if !mirror {
        return (l.mass, c, i);
    }
    // S·I·S with S = diag(1, −1, 1): the products with y change sign.
    let s = [1.0, -1.0, 1.0];
    let i: M3 = core::array::from_fn(|a| core::array::from_fn(|b| s[a] * s[b] * i[a][b]));
    (l.mass, [c[0], -c[1], c[2]], i)
}

/// The lump of `parts`: mass, centre of mass and inertia about it, by the parallel-axis
/// theorem.
fn lump(parts: &[(f64, V3, M3)]) -> (f64, V3, M3) {
    let m: f64 = parts.iter().map(|p| p.0).sum();
    let c: V3 = core::array::from_fn(|k| parts.iter().map(|p| p.0 * p.1[k]).sum::<f64>() / m);
    let mut inertia = [[0.0; 3]; 3];
    for (mi, ci, ii) in parts {
        let r: V3 = core::array::from_fn(|k| ci[k] - c[k]);
        let r2: f64 = r.iter().map(|v| v * v).sum();
        for i in 0..3 {
            for j in 0..3 {
                let delta = if i == j { r2 } else { 0.0 };
                inertia[i][j] += ii[i][j] + mi * (delta - r[i] * r[j]);
            }
        }
    }
    (m, c, inertia)
}

#[test]
fn the_op3_masses_are_menageries_links_lumped() {
    let o = Robot::op3();
    let (m, g) = (&o.masses, &o.geometry);
    let i = m.inertias.expect("the OP3's inertias are known");
    // The arms hang as held (shoulder roll ±1.3 rad), every other joint at 0.
    let held = |n: &str| match n {
        "l_sho_roll_link" => 1.3,
        "r_sho_roll_link" => -1.3,
        _ => 0.0,
    };
    let at = |n: &str| part(n, false, &held);
    let leg =
        |n: &str| n.starts_with("l_hip_pitch") || n.starts_with("l_knee") || n.starts_with("l_ank");
    // The upper body: the trunk, head, arms and both legs' hip yaw and roll links.
    let mut upper: Vec<_> = MENAGERIE_LINKS
        .iter()
        .map(|l| l.name)
        .filter(|n| !leg(n))
        .map(at)
        .collect();
    upper.push(part("l_hip_yaw_link", true, &held));
    upper.push(part("l_hip_roll_link", true, &held));
    let (mu, cu, iu) = lump(&upper);
    // The hip point H (the roll and pitch axes' meeting point), P between the hips.
    let (_, pitch_origin) = link_frame("l_hip_pitch_link", &held);
    let hip = [pitch_origin[0], pitch_origin[1] - 0.019, pitch_origin[2]];
    let p = [hip[0], 0.0, hip[2]];
    let close = |a: f64, b: f64, tol: f64, what: &str| {
        assert!((a - b).abs() <= tol, "{what}: description {a}, op3.xml {b}");
    };
    close(m.upper_body, mu, 1e-9, "upper body mass");
    close(m.upper_body_height, cu[2] - p[2], 1e-4, "upper body height");
    close(
        m.upper_body_forward,
        cu[0] - p[0],
        1e-4,
        "upper body forward",
    );
    assert!(
        cu[1].abs() < 1e-3,
        "the upper body's centre in the middle: {}",
        cu[1]
    );
    close(m.upper_body_inertia, iu[1][1], 1e-4, "upper body J_yy");
    close(i.upper_body_roll_yaw[0], iu[0][0], 1e-5, "upper body J_xx");
    close(i.upper_body_roll_yaw[1], iu[2][2], 1e-5, "upper body J_zz");
    assert!(
        iu[0][2].abs() < 0.07 * iu[2][2],
        "the products left out are small"
    );
    // Thigh: the hip pitch link, on the hip–knee line thigh_com of the way down.
    let (mt, ct, it) = lump(&[at("l_hip_pitch_link")]);
    close(m.thigh, mt, 1e-9, "thigh mass");
    close(
        m.thigh_com * g.thigh,
        hip[2] - ct[2],
        1e-5,
        "thigh centre below the hip",
    );
    assert!(
        (ct[0] - hip[0]).abs() < 1e-3 && (ct[1] - hip[1]).abs() < 1e-3,
        "on the line"
    );
    // Calf: the knee link, from the knee.
    let knee = [hip[0], hip[1], hip[2] - g.thigh];
    let (mc, cc, ic) = lump(&[at("l_knee_link")]);
    close(m.calf, mc, 1e-9, "calf mass");
    close(
        m.calf_com * g.calf,
        knee[2] - cc[2],
        1e-5,
        "calf centre below the knee",
    );
    assert!((cc[1] - knee[1]).abs() < 3e-3, "within 3 mm of the line");
    // Sole lump: the ankle pitch and roll links, from the ankle.
    let (ms, cs, is) = lump(&[at("l_ank_pitch_link"), at("l_ank_roll_link")]);
    let ankle = [hip[0], hip[1], knee[2] - g.calf];
    close(m.sole, ms, 1e-9, "sole mass");
    close(
        m.sole_height,
        cs[2] - (ankle[2] - g.ankle_height),
        1e-4,
        "sole height",
    );
    close(
        g.sole_offset[0] + m.sole_com[0],
        cs[0] - ankle[0],
        1e-4,
        "sole mass forward of the ankle",
    );
    close(
        g.sole_offset[1] + m.sole_com[1],
        cs[1] - ankle[1],
        1e-4,
        "sole mass outward of the ankle",
    );
    for (what, desc, lumped) in [
        ("thigh", i.thigh, it),
        ("calf", i.calf, ic),
        ("sole", i.sole, is),
    ] {
        for k in 0..3 {
            close(desc[k], lumped[k][k], 2e-3 * lumped[k][k] + 1e-8, what);
        }
    }
}

#[test]
fn the_mass_points_sit_where_the_description_puts_them() {
    // A bent leg: the thigh's mass point thigh_com of the way from hip to knee, the calf's
    // calf_com from knee to ankle, the sole's sole_com from the sole point along the foot's
    // forward and outward axes, sole_height up its z.
    for robot in ROBOTS {
        let kin = LegKinematics::<f64>::new(&robot);
        let m = &robot.masses;
        let pelvis = Pose {
            x: 0.01,
            y: -0.02,
            z: 0.2,
            roll: 0.05,
            pitch: -0.1,
            yaw: 0.3,
        };
        for side in [Side::Left, Side::Right] {
            let q = [0.1, -0.05, -0.6, 1.1, -0.45, 0.07];
            let p = kin.points(side, &pelvis, &q);
            let foot = kin.fk(side, &pelvis, &q);
            let lerp =
                |a: V3, b: V3, f: f64| -> V3 { core::array::from_fn(|k| a[k] + f * (b[k] - a[k])) };
            let near = |a: V3, b: V3, what: &str| {
                let d = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
                assert!(d < 1e-12, "{} {side:?} {what}: {a:?} vs {b:?}", robot.name);
            };
            near(p.thigh_mass, lerp(p.hip, p.knee, m.thigh_com), "thigh");
            near(p.calf_mass, lerp(p.knee, p.ankle, m.calf_com), "calf");
            let r = foot.rotation();
            let out = side.sign() * m.sole_com[1];
            let local = [m.sole_com[0], out, m.sole_height];
            let want: V3 = core::array::from_fn(|k| {
                p.sole[k] + r[k][0] * local[0] + r[k][1] * local[1] + r[k][2] * local[2]
            });
            near(p.sole_mass, want, "sole");
        }
    }
}
