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
