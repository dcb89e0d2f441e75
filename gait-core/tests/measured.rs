//! Support polygons, the measured ZMP from the foot force sensors, and ZMP error statistics.
//!
//! Reference robot: sole 0.100 × 0.060 m centred under the ankle (half sizes 0.05 × 0.03),
//! force sensors at (±0.040, ±0.025) m, order front-left, front-right, rear-left, rear-right.

use gait_core::measure::support::{sole_corners, SupportPolygon, FAR_OUTSIDE, MAX_VERTICES};
use gait_core::measure::zmp::{
    measured_zmp, sensor_positions, Contact, ForceReading, MeasuredZmp, SolePose, ZmpErrorStats,
};
use gait_core::trajectory::swing::FootSample;
use gait_core::{GaitError, Place, Real, Robot};
use proptest::prelude::*;

const ROBOT: Robot = Robot::reference();
const EPS: f64 = 1e-12;

fn place(x: f64, y: f64, yaw: f64) -> Place<f64> {
    Place::new(x, y, yaw)
}

fn reading(f: [f64; 4]) -> ForceReading<f64> {
    ForceReading::new(f)
}

/// The reference robot's measured ZMP from each foot's place and four sensor forces, N.
fn zmp_of<L: SolePose<f64>, Q: SolePose<f64>>(
    (left, lf): (&L, [f64; 4]),
    (right, rf): (&Q, [f64; 4]),
    min_load: f64,
) -> MeasuredZmp<f64> {
    measured_zmp(
        &ROBOT,
        (left, &reading(lf)),
        (right, &reading(rf)),
        min_load,
    )
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

fn assert_xy(got: Option<[f64; 2]>, want: [f64; 2], tol: f64) {
    let g = got.expect("a ZMP");
    assert!(
        close(g[0], want[0], tol) && close(g[1], want[1], tol),
        "got {g:?}, want {want:?}"
    );
}

// ---------------------------------------------------------------------------------------------
// Support polygons
// ---------------------------------------------------------------------------------------------

#[test]
fn sole_corners_are_counter_clockwise_from_front_left() {
    // Foot at the origin, yaw 0: (±0.05, ±0.03).
    let c = sole_corners(&place(0.0, 0.0, 0.0), &ROBOT).unwrap();
    let want = [[0.05, 0.03], [-0.05, 0.03], [-0.05, -0.03], [0.05, -0.03]];
    for (g, w) in c.iter().zip(want.iter()) {
        assert!(close(g[0], w[0], EPS) && close(g[1], w[1], EPS), "{c:?}");
    }
    // Yaw π/2 at (1, 2): local (a, b) → (−b, a), so front-left = (1 − 0.03, 2 + 0.05).
    let c = sole_corners(&place(1.0, 2.0, core::f64::consts::FRAC_PI_2), &ROBOT).unwrap();
    assert!(
        close(c[0][0], 0.97, EPS) && close(c[0][1], 2.05, EPS),
        "{c:?}"
    );
    // Non-finite pose → error, never NaN corners.
    assert_eq!(
        sole_corners(&place(f64::NAN, 0.0, 0.0), &ROBOT),
        Err(GaitError::NonFinite)
    );
    assert_eq!(
        sole_corners(&place(0.0, 0.0, f64::INFINITY), &ROBOT),
        Err(GaitError::NonFinite)
    );
    let mut bad = ROBOT;
    bad.geometry.sole_width = 0.0;
    assert_eq!(
        sole_corners(&place(0.0, 0.0, 0.0), &bad),
        Err(GaitError::NonPositiveLength)
    );
}

#[test]
fn single_sole_margins() {
    let poly = SupportPolygon::single(&place(0.0, 0.0, 0.0), &ROBOT).unwrap();
    assert_eq!(poly.len(), 4);
    // Centre: nearest edges are the sides at y = ±0.03 → half the sole width.
    assert!(close(poly.margin([0.0, 0.0]), 0.03, EPS));
    // 1 cm outside the left side (y = 0.03) and outside the front edge (x = 0.05).
    assert!(close(poly.margin([0.0, 0.04]), -0.01, EPS));
    assert!(close(poly.margin([0.06, 0.0]), -0.01, EPS));
    // Outside the front-left corner by (0.03, 0.04): distance 0.05 (3-4-5).
    assert!(close(poly.margin([0.08, 0.07]), -0.05, EPS));
    // Inside, 5 mm behind the front edge (sides are 0.03 away).
    assert!(close(poly.margin([0.045, 0.0]), 0.005, EPS));
    // On the boundary.
    assert!(close(poly.margin([0.05, 0.01]), 0.0, EPS));
    assert!(poly.contains_with_margin([0.0, 0.0], 0.029));
    assert!(!poly.contains_with_margin([0.0, 0.0], 0.031));
    assert!(!poly.contains_with_margin([0.0, 0.04], 0.0));
    assert!(poly.contains_with_margin([0.0, 0.04], -0.011));
}

#[test]
fn single_sole_margin_is_rotated_with_the_foot() {
    // Yaw π/2 at (1, 2): the sole spans x ∈ 1 ± 0.03, y ∈ 2 ± 0.05.
    let poly =
        SupportPolygon::single(&place(1.0, 2.0, core::f64::consts::FRAC_PI_2), &ROBOT).unwrap();
    assert!(close(poly.margin([1.0, 2.0]), 0.03, EPS));
    // (1, 2.04) is 1 cm inside the (now lateral-in-world) front edge; an unrotated sole would
    // have it outside.
    assert!(close(poly.margin([1.0, 2.04]), 0.01, EPS));
    assert!(close(poly.margin([1.04, 2.0]), -0.01, EPS));

    // Yaw 0.3 at (0.2, −0.1): 1 cm beyond the left side along the foot's own lateral axis
    // (0, 0.04) in the foot frame → −0.01; 0.045 ahead along the heading → +0.005.
    let p = place(0.2, -0.1, 0.3);
    let poly = SupportPolygon::single(&p, &ROBOT).unwrap();
    let (s, c) = (0.3f64.sin(), 0.3f64.cos());
    let side = [0.2 - 0.04 * s, -0.1 + 0.04 * c];
    assert!(
        close(poly.margin(side), -0.01, 1e-12),
        "{}",
        poly.margin(side)
    );
    let ahead = p.ahead(0.045);
    assert!(close(poly.margin(ahead), 0.005, 1e-12));
    assert!(close(poly.margin([0.2, -0.1]), 0.03, 1e-12));
}

#[test]
fn double_support_of_parallel_feet() {
    // Feet side by side 0.09 m apart: the hull is x ∈ [−0.05, 0.05], y ∈ [−0.075, 0.075]
    // (0.075 = 0.045 + 0.03). The midpoint is 0.075 from the sides but only 0.05 from the
    // front and rear edges → margin 0.05.
    let l = place(0.0, 0.045, 0.0);
    let r = place(0.0, -0.045, 0.0);
    let poly = SupportPolygon::double(&l, &r, &ROBOT).unwrap();
    assert_eq!(poly.len(), 4);
    assert!(close(poly.margin([0.0, 0.0]), 0.05, EPS));
    // 1 cm outside the left foot's outer side.
    assert!(close(poly.margin([0.0, 0.085]), -0.01, EPS));
    assert!(poly.contains_with_margin([0.0, 0.0], 0.049));
    assert!(!poly.contains_with_margin([0.0, 0.0], 0.051));
}

#[test]
fn double_support_of_staggered_feet() {
    // Left at (0.02, 0.045), right at (−0.02, −0.045), yaw 0.
    // Left corners: (0.07, 0.075) (−0.03, 0.075) (−0.03, 0.015) (0.07, 0.015);
    // right corners: (0.03, −0.015) (−0.07, −0.015) (−0.07, −0.075) (0.03, −0.075).
    // Hull (6 vertices): (0.07, 0.075) (−0.03, 0.075) (−0.07, −0.015) (−0.07, −0.075)
    // (0.03, −0.075) (0.07, 0.015). From the midpoint (0, 0): top/bottom 0.075, left/right
    // 0.07, and the diagonals, e.g. (0.03, −0.075) → (0.07, 0.015) with d = (0.04, 0.09):
    // |d × (o − a)| / |d| = |0.04·0.075 − 0.09·(−0.03)| / √0.0097 = 0.0057 / √0.0097.
    let poly = SupportPolygon::double(&place(0.02, 0.045, 0.0), &place(-0.02, -0.045, 0.0), &ROBOT)
        .unwrap();
    assert_eq!(poly.len(), 6);
    let want = 0.0057 / 0.0097f64.sqrt(); // ≈ 0.057875
    assert!(
        close(poly.margin([0.0, 0.0]), want, EPS),
        "{}",
        poly.margin([0.0, 0.0])
    );
    // The inner corners (−0.03, 0.015) and (0.03, −0.015) are not hull vertices.
    for v in poly.vertices() {
        assert!(!(close(v[0], -0.03, EPS) && close(v[1], 0.015, EPS)));
    }
}

#[test]
fn hull_is_counter_clockwise_and_convex() {
    let poly = SupportPolygon::double(&place(0.03, 0.05, 0.4), &place(-0.01, -0.04, -0.2), &ROBOT)
        .unwrap();
    let v = poly.vertices();
    assert!(v.len() >= 4 && v.len() <= MAX_VERTICES);
    for i in 0..v.len() {
        let (a, b, c) = (v[i], v[(i + 1) % v.len()], v[(i + 2) % v.len()]);
        let cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        assert!(cross > 0.0, "not a strictly convex CCW turn at {i}: {v:?}");
    }
    // Every sole corner is inside or on the hull.
    for p in [place(0.03, 0.05, 0.4), place(-0.01, -0.04, -0.2)] {
        for c in sole_corners(&p, &ROBOT).unwrap() {
            assert!(poly.margin(c) >= -1e-12);
        }
    }
}

#[test]
fn degenerate_and_invalid_polygons() {
    // One point (repeated): margin = −distance.
    let p = SupportPolygon::from_points(&[[0.0, 0.0], [0.0, 0.0]]).unwrap();
    assert_eq!(p.len(), 1);
    assert!(close(p.margin([0.03, 0.04]), -0.05, EPS));
    // A segment from (0, 0) to (1, 0): (0.5, 0.2) → −0.2, (2, 0) → −1, on it → 0.
    let s = SupportPolygon::from_points(&[[1.0, 0.0], [0.0, 0.0], [0.5, 0.0]]).unwrap();
    assert_eq!(s.len(), 2);
    assert!(close(s.margin([0.5, 0.2]), -0.2, EPS));
    assert!(close(s.margin([2.0, 0.0]), -1.0, EPS));
    assert!(close(s.margin([0.25, 0.0]), 0.0, EPS));
    // No points, too many points, non-finite points → None.
    assert!(SupportPolygon::<f64>::from_points(&[]).is_none());
    assert!(SupportPolygon::from_points(&[[0.0, 0.0]; 9]).is_none());
    assert!(SupportPolygon::from_points(&[[0.0, f64::NAN], [1.0, 0.0]]).is_none());
    // A non-finite query point: FAR_OUTSIDE, never NaN; never contained.
    let sole = SupportPolygon::single(&place(0.0, 0.0, 0.0), &ROBOT).unwrap();
    assert_eq!(sole.margin([f64::NAN, 0.0]), FAR_OUTSIDE);
    assert_eq!(sole.margin([0.0, f64::INFINITY]), FAR_OUTSIDE);
    assert!(!sole.contains_with_margin([f64::NAN, 0.0], -1.0));
    assert!(!sole.contains_with_margin([0.0, 0.0], f64::NAN));
    // Very far points stay finite.
    assert!(sole.margin([1e300, -1e300]).is_finite());
    let sole32 = SupportPolygon::<f32>::single(&Place::new(0.0, 0.0, 0.0), &ROBOT).unwrap();
    assert!(sole32.margin([3e38, -3e38]).is_finite());
    assert!(close(sole32.margin([0.0, 0.0]) as f64, 0.03, 1e-7));
    // Non-finite foot → error.
    assert!(
        SupportPolygon::double(&place(0.0, 0.0, 0.0), &place(0.0, f64::NAN, 0.0), &ROBOT).is_err()
    );
}

// ---------------------------------------------------------------------------------------------
// Measured ZMP
// ---------------------------------------------------------------------------------------------

#[test]
fn equal_forces_put_the_zmp_at_the_ankle() {
    // Σ fᵢ sᵢ = 10·Σ sᵢ = 0 (the sensors are symmetric about the ankle) → ZMP = foot point,
    // whatever the yaw.
    let l = place(0.1, 0.2, 0.7);
    let r = place(0.1, 0.11, 0.0);
    let m = zmp_of((&l, [10.0; 4]), (&r, [0.0; 4]), 1.0);
    assert_xy(m.zmp, [0.1, 0.2], EPS);
    assert_eq!(m.contact, Contact::Left);
    assert!(
        close(m.total_force, 40.0, EPS) && close(m.left_load, 40.0, EPS) && m.right_load == 0.0
    );
    assert!(m.left_valid && m.right_valid);
}

#[test]
fn single_sensor_load_is_at_that_sensor_rotated_with_the_foot() {
    // Right foot at (0.05, −0.045), yaw 0.3; all 25 N on the front-left sensor s = (0.04, 0.025).
    // cos 0.3 = 0.955336489, sin 0.3 = 0.295520207:
    //   x = 0.05 + 0.04·0.955336489 − 0.025·0.295520207 = 0.05 + 0.038213460 − 0.007388005
    //     = 0.080825454
    //   y = −0.045 + 0.04·0.295520207 + 0.025·0.955336489 = −0.045 + 0.011820808 + 0.023883412
    //     = −0.009295780
    let r = place(0.05, -0.045, 0.3);
    let l = place(0.0, 0.045, 0.0);
    let m = zmp_of((&l, [0.0; 4]), (&r, [25.0, 0.0, 0.0, 0.0]), 1.0);
    assert_xy(m.zmp, [0.080825454, -0.009295780], 1e-9);
    assert_eq!(m.contact, Contact::Right);
    // And it is exactly the world position of that sensor.
    let s = sensor_positions(&ROBOT, &r).unwrap();
    assert_xy(m.zmp, s[0], EPS);
    // The same in f32.
    let r32: Place<f32> = Place::new(0.05, -0.045, 0.3);
    let l32: Place<f32> = Place::new(0.0, 0.045, 0.0);
    let m32 = measured_zmp(
        &ROBOT,
        (&l32, &ForceReading::new([0.0f32; 4])),
        (&r32, &ForceReading::new([25.0f32, 0.0, 0.0, 0.0])),
        1.0f32,
    );
    let z = m32.zmp.unwrap();
    assert!(close(z[0] as f64, 0.080825454, 1e-6) && close(z[1] as f64, -0.009295780, 1e-6));
}

#[test]
fn sensor_positions_follow_the_robot_description() {
    // A robot with other sensor positions: all force on "front-right" at (0.03, −0.02).
    let mut robot = ROBOT;
    robot.geometry.force_sensors = [[0.03, 0.02], [0.03, -0.02], [-0.03, 0.02], [-0.03, -0.02]];
    let f = place(0.0, 0.0, 0.0);
    let m = measured_zmp(
        &robot,
        (&f, &reading([0.0, 5.0, 0.0, 0.0])),
        (&f, &reading([0.0; 4])),
        1.0,
    );
    assert_xy(m.zmp, [0.03, -0.02], EPS);
}

#[test]
fn both_feet_loaded_equally_give_the_midpoint() {
    // Each foot's CoP is its ankle (equal forces), equal loads → midpoint of the ankles:
    // ((0.02 − 0.02)/2, (0.045 − 0.045)/2) = (0, 0).
    let l = place(0.02, 0.045, 0.2);
    let r = place(-0.02, -0.045, -0.1);
    let m = zmp_of((&l, [7.0; 4]), (&r, [7.0; 4]), 1.0);
    assert_xy(m.zmp, [0.0, 0.0], EPS);
    assert_eq!(m.contact, Contact::Both);
    assert!(close(m.total_force, 56.0, EPS));
    // Unequal loads 30 N : 10 N → 0.75·(0.02, 0.045) + 0.25·(−0.02, −0.045) = (0.01, 0.0225).
    let m = zmp_of((&l, [7.5; 4]), (&r, [2.5; 4]), 1.0);
    assert_xy(m.zmp, [0.01, 0.0225], EPS);
    // Σ fᵢ rᵢ / Σ fᵢ over all 8 sensors gives the same point.
    let (sl, sr) = (
        sensor_positions(&ROBOT, &l).unwrap(),
        sensor_positions(&ROBOT, &r).unwrap(),
    );
    let (mut num, mut den) = ([0.0; 2], 0.0);
    for (s, f) in sl
        .iter()
        .map(|s| (s, 7.5))
        .chain(sr.iter().map(|s| (s, 2.5)))
    {
        num[0] += f * s[0];
        num[1] += f * s[1];
        den += f;
    }
    assert_xy(m.zmp, [num[0] / den, num[1] / den], EPS);
}

#[test]
fn foot_sample_poses_are_accepted() {
    // A FootSample's height does not matter, only its ground projection and heading.
    let l = FootSample {
        x: 0.0,
        y: 0.045,
        z: 0.02,
        yaw: 0.0,
    };
    let r = place(0.0, -0.045, 0.0);
    let m = zmp_of((&l, [5.0; 4]), (&r, [5.0; 4]), 1.0);
    assert_xy(m.zmp, [0.0, 0.0], EPS);
}

#[test]
fn a_foot_below_min_load_is_ignored() {
    // Right foot: 2 N on one sensor < min_load 5 N → only the left ankle counts.
    let l = place(0.0, 0.045, 0.0);
    let r = place(0.0, -0.045, 0.0);
    let m = zmp_of((&l, [10.0; 4]), (&r, [2.0, 0.0, 0.0, 0.0]), 5.0);
    assert_xy(m.zmp, [0.0, 0.045], EPS);
    assert_eq!(m.contact, Contact::Left);
    // The load is still reported.
    assert!(close(m.right_load, 2.0, EPS) && close(m.total_force, 42.0, EPS));
    // Exactly at min_load counts.
    let m = zmp_of((&l, [0.0; 4]), (&r, [5.0, 0.0, 0.0, 0.0]), 5.0);
    assert_eq!(m.contact, Contact::Right);
}

#[test]
fn airborne_gives_no_zmp() {
    let l = place(0.0, 0.045, 0.0);
    let r = place(0.0, -0.045, 0.0);
    let m = zmp_of((&l, [0.0; 4]), (&r, [0.0; 4]), 1.0);
    assert_eq!(m.zmp, None);
    assert_eq!(m.contact, Contact::None);
    assert_eq!(m.total_force, 0.0);
    // Both below the threshold.
    let m = zmp_of((&l, [0.1; 4]), (&r, [0.2; 4]), 1.0);
    assert_eq!((m.zmp, m.contact), (None, Contact::None));
    // A zero load with a negative (or zero) threshold is still no contact, never 0/0.
    let m = zmp_of((&l, [0.0; 4]), (&r, [-3.0; 4]), -1.0);
    assert_eq!((m.zmp, m.contact), (None, Contact::None));
    // A NaN threshold loads no foot.
    let m = zmp_of((&l, [9.0; 4]), (&r, [9.0; 4]), f64::NAN);
    assert_eq!((m.zmp, m.contact), (None, Contact::None));
}

#[test]
fn negative_readings_are_clamped_to_zero() {
    // FL −5 → 0: CoP = 10·[(0.04, −0.025) + (−0.04, 0.025) + (−0.04, −0.025)] / 30
    //              = (−0.04/3, −0.025/3).
    let f = place(0.0, 0.0, 0.0);
    let m = zmp_of((&f, [-5.0, 10.0, 10.0, 10.0]), (&f, [0.0; 4]), 1.0);
    assert_xy(m.zmp, [-0.04 / 3.0, -0.025 / 3.0], EPS);
    assert!(close(m.left_load, 30.0, EPS));
}

#[test]
fn non_finite_readings_invalidate_that_foot_only() {
    let l = place(0.0, 0.045, 0.0);
    let r = place(0.0, -0.045, 0.0);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let m = zmp_of((&l, [10.0, bad, 10.0, 10.0]), (&r, [10.0; 4]), 1.0);
        assert_xy(m.zmp, [0.0, -0.045], EPS);
        assert!(!m.left_valid && m.right_valid);
        assert_eq!(m.left_load, 0.0);
        assert_eq!(m.contact, Contact::Right);
        assert!(close(m.total_force, 40.0, EPS));
        // Both bad → no ZMP, never NaN.
        let m = zmp_of((&l, [bad; 4]), (&r, [1.0, 1.0, bad, 1.0]), 1.0);
        assert_eq!((m.zmp, m.contact), (None, Contact::None));
        assert!(!m.left_valid && !m.right_valid && m.total_force == 0.0);
    }
    // A non-finite pose invalidates the foot too.
    let m = measured_zmp(
        &ROBOT,
        (&place(f64::NAN, 0.0, 0.0), &reading([10.0; 4])),
        (&r, &reading([10.0; 4])),
        1.0,
    );
    assert_xy(m.zmp, [0.0, -0.045], EPS);
    assert!(!m.left_valid);
    // Loads that overflow f32 → invalid, never an infinite force.
    let p: Place<f32> = Place::new(0.0, 0.0, 0.0);
    let huge = ForceReading::new([3e38f32; 4]);
    let m = measured_zmp(
        &ROBOT,
        (&p, &huge),
        (&p, &ForceReading::new([1.0f32; 4])),
        0.5f32,
    );
    assert!(!m.left_valid && m.right_valid && m.total_force.is_finite());
    assert_eq!(m.contact, Contact::Right);
    // Each foot finite but the sum overflows → nothing trustworthy.
    let big = ForceReading::new([6e37f32; 4]);
    let m = measured_zmp(&ROBOT, (&p, &big), (&p, &big), 0.5f32);
    assert!(m.total_force.is_finite() && m.zmp.is_none());
}

fn pose_strategy() -> impl Strategy<Value = Place<f64>> {
    (-1.0..1.0f64, -1.0..1.0f64, -3.2..3.2f64).prop_map(|(x, y, yaw)| Place::new(x, y, yaw))
}

fn forces_strategy() -> impl Strategy<Value = [f64; 4]> {
    // Some sensors often unloaded (exactly 0), the rest up to 60 N.
    proptest::array::uniform4(prop_oneof![Just(0.0), 0.0..60.0f64])
}

proptest! {
    #[test]
    fn measured_zmp_lies_in_the_loaded_feet_hulls(
        lp in pose_strategy(),
        rp in pose_strategy(),
        lf in forces_strategy(),
        rf in forces_strategy(),
        min_load in 0.0..30.0f64,
    ) {
        let m = zmp_of((&lp, lf), (&rp, rf), min_load);
        let (ll, rl): (f64, f64) = (lf.iter().sum(), rf.iter().sum());
        let l_on = ll > 0.0 && ll >= min_load;
        let r_on = rl > 0.0 && rl >= min_load;
        prop_assert_eq!(m.contact, Contact::from_loaded(l_on, r_on));
        prop_assert!(close(m.total_force, ll + rl, 1e-9));
        match (l_on, r_on) {
            (false, false) => prop_assert!(m.zmp.is_none()),
            _ => {
                let z = m.zmp.unwrap();
                prop_assert!(z[0].is_finite() && z[1].is_finite());
                // Convex hull of the loaded feet's sensor points.
                let mut pts = [[0.0; 2]; 8];
                let mut n = 0;
                for (on, p) in [(l_on, &lp), (r_on, &rp)] {
                    if on {
                        for s in sensor_positions(&ROBOT, p).unwrap() {
                            pts[n] = s;
                            n += 1;
                        }
                    }
                }
                let sensors = SupportPolygon::from_points(&pts[..n]).unwrap();
                prop_assert!(sensors.margin(z) >= -1e-6, "sensor hull margin {}", sensors.margin(z));
                // Support polygon of the loaded feet.
                let support = match (l_on, r_on) {
                    (true, true) => SupportPolygon::double(&lp, &rp, &ROBOT).unwrap(),
                    (true, false) => SupportPolygon::single(&lp, &ROBOT).unwrap(),
                    _ => SupportPolygon::single(&rp, &ROBOT).unwrap(),
                };
                prop_assert!(support.margin(z) >= -1e-6, "support margin {}", support.margin(z));
            }
        }
    }

    #[test]
    fn margin_never_panics_or_goes_non_finite(
        lp in pose_strategy(),
        rp in pose_strategy(),
        qx in prop::num::f64::ANY,
        qy in prop::num::f64::ANY,
    ) {
        let poly = SupportPolygon::double(&lp, &rp, &ROBOT).unwrap();
        let m = poly.margin([qx, qy]);
        prop_assert!(m.is_finite() && m >= FAR_OUTSIDE);
        // Points inside a sole are inside the hull.
        let inside = lp.ahead(0.03);
        prop_assert!(poly.margin(inside) >= 0.02 - 1e-9);
    }

    #[test]
    fn measured_zmp_never_non_finite(
        lf in proptest::array::uniform4(prop::num::f64::ANY),
        rf in proptest::array::uniform4(prop::num::f64::ANY),
        min_load in prop::num::f64::ANY,
    ) {
        let l = place(0.0, 0.045, 0.1);
        let r = place(0.0, -0.045, -0.1);
        let m = zmp_of((&l, lf), (&r, rf), min_load);
        prop_assert!(m.total_force.is_finite() && m.left_load.is_finite() && m.right_load.is_finite());
        if let Some(z) = m.zmp {
            prop_assert!(z[0].is_finite() && z[1].is_finite());
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Error statistics
// ---------------------------------------------------------------------------------------------

#[test]
fn error_statistics_of_a_hand_made_sequence() {
    // e = measured − reference:
    //   1: (0.01, −0.02)   2: no measured ZMP (skipped)   3: (−0.03, 0)   4: (0.04, 0.02)
    // x: |e| = 0.01, 0.03, 0.04 → sum 0.08, mean 0.08/3, RMS √((1 + 9 + 16)e-4 / 3) = √(26e-4/3),
    //    max 0.04.
    // y: |e| = 0.02, 0, 0.02 → sum 0.04, mean 0.04/3, RMS √(8e-4/3), max 0.02.
    let mut st = ZmpErrorStats::<f64>::new();
    st.push([0.0, 0.0], Some([0.01, -0.02]));
    st.push([0.1, 0.05], None);
    st.push([0.1, 0.05], Some([0.07, 0.05]));
    st.push([0.2, -0.1], Some([0.24, -0.08]));
    assert_eq!((st.samples(), st.skipped(), st.invalid()), (4, 1, 0));
    let (x, y) = (st.x(), st.y());
    assert_eq!((x.count, y.count), (3, 3));
    let tol = 1e-12;
    assert!(close(x.sum_abs, 0.08, tol) && close(x.mean_abs, 0.08 / 3.0, tol));
    assert!(close(x.rms, (26e-4f64 / 3.0).sqrt(), tol) && close(x.max_abs, 0.04, tol));
    assert!(close(y.sum_abs, 0.04, tol) && close(y.mean_abs, 0.04 / 3.0, tol));
    assert!(close(y.rms, (8e-4f64 / 3.0).sqrt(), tol) && close(y.max_abs, 0.02, tol));

    // Non-finite samples are counted as invalid and change nothing else.
    st.push([f64::NAN, 0.0], Some([0.0, 0.0]));
    st.push([0.0, 0.0], Some([0.0, f64::INFINITY]));
    assert_eq!((st.samples(), st.skipped(), st.invalid()), (6, 1, 2));
    assert_eq!(st.x(), x);

    st.reset();
    assert_eq!(st.samples(), 0);
    let e = st.x();
    assert_eq!(
        (e.count, e.sum_abs, e.mean_abs, e.rms, e.max_abs),
        (0, 0.0, 0.0, 0.0, 0.0)
    );
}

#[test]
fn error_statistics_in_f32_accumulate_in_f64() {
    // 100 000 samples of e = (0.001, −0.002) in f32: f64 sums stay exact to ~1e-9 relative of
    // the f32 value of 0.001 (an f32 running sum would drift by ~1e-3 relative).
    let mut st = ZmpErrorStats::<f32>::new();
    for _ in 0..100_000 {
        st.push([0.0f32, 0.0], Some([0.001f32, -0.002]));
    }
    let e = 0.001f32.to_f64();
    let x = st.x();
    assert_eq!(x.count, 100_000);
    assert!(close(x.sum_abs, 1e5 * e, 1e-9), "{}", x.sum_abs);
    assert!(close(x.mean_abs, e, 1e-15) && close(x.rms, e, 1e-15) && x.max_abs == e);
    assert!(close(st.y().rms, 0.002f32.to_f64(), 1e-15));
}

#[test]
fn error_statistics_huge_errors_stay_finite() {
    let mut st = ZmpErrorStats::<f64>::new();
    st.push([-1e300, 0.0], Some([1e300, 0.0]));
    st.push([0.0, 0.0], Some([1e300, 0.0]));
    let x = st.x();
    assert!(x.sum_abs.is_finite() && x.rms.is_finite() && x.mean_abs.is_finite());
    assert!(close(x.max_abs, 2e300, 1e286));
    // RMS = √((4 + 1)/2)·1e300.
    assert!(close(x.rms / 1e300, 2.5f64.sqrt(), 1e-12));
}

#[test]
fn inside_fraction_against_the_support_polygon() {
    // Sole at the origin, margin 0.01:
    //   (0, 0): margin 0.03 → inside;  (0.045, 0): margin 0.005 < 0.01 → not inside;
    //   None: not inside (skipped);    (0.2, 0): outside.        → 1 of 4 = 0.25.
    let poly = SupportPolygon::single(&place(0.0, 0.0, 0.0), &ROBOT).unwrap();
    let mut st = ZmpErrorStats::<f64>::new();
    st.push_with_polygon([0.0, 0.0], Some([0.0, 0.0]), &poly, 0.01);
    st.push_with_polygon([0.0, 0.0], Some([0.045, 0.0]), &poly, 0.01);
    st.push_with_polygon([0.0, 0.0], None, &poly, 0.01);
    st.push_with_polygon([0.0, 0.0], Some([0.2, 0.0]), &poly, 0.01);
    assert_eq!((st.inside_count(), st.polygon_samples()), (1, 4));
    assert!(close(st.inside_fraction(), 0.25, EPS));
    assert_eq!((st.samples(), st.skipped()), (4, 1));
    // x errors 0, 0.045, 0.2 → sum 0.245, max 0.2.
    assert!(close(st.x().sum_abs, 0.245, EPS) && st.x().max_abs == 0.2);
    // Plain pushes do not count towards the polygon check.
    st.push([0.0, 0.0], Some([0.0, 0.0]));
    assert_eq!(
        (st.inside_count(), st.polygon_samples(), st.samples()),
        (1, 4, 5)
    );
    assert_eq!(ZmpErrorStats::<f32>::new().inside_fraction(), 0.0);
}

// ---------------------------------------------------------------------------------------------
// The fixed-point measured ZMP
// ---------------------------------------------------------------------------------------------

fn fixed_foot(x: f64, y: f64, yaw: f64) -> gait_core::trajectory::fixed_sampler::FixedFoot {
    use gait_core::maths::fixed_point::Fx;
    gait_core::trajectory::fixed_sampler::FixedFoot {
        x: Fx::from_num(x),
        y: Fx::from_num(y),
        z: Fx::ZERO,
        yaw: Fx::from_num(yaw),
    }
}

proptest! {
    /// The fixed-point meter against the f64 formula on the same (fixed-point-representable)
    /// poses and whole-mN forces: within 2 I16F16 steps (≈ 31 µm) of the f64 ZMP, and `None`
    /// exactly when the f64 ZMP is `None`.
    #[test]
    fn fixed_zmp_matches_f64(
        lx in -0.3f64..0.3, ly in 0.0f64..0.2, lyaw in -0.8f64..0.8,
        rx in -0.3f64..0.3, ry in -0.2f64..0.0, ryaw in -0.8f64..0.8,
        lf in prop::array::uniform4(-2_000i32..40_000),
        rf in prop::array::uniform4(-2_000i32..40_000),
        min_load in 0.0f32..30.0,
    ) {
        use gait_core::measure::zmp::FixedZmpMeter;
        let (l, r) = (fixed_foot(lx, ly, lyaw), fixed_foot(rx, ry, ryaw));
        let meter = FixedZmpMeter::new(&ROBOT, min_load);
        let got = meter.zmp((&l, Some(lf)), (&r, Some(rf)));
        let pl = place(l.x.to_num(), l.y.to_num(), l.yaw.to_num());
        let pr = place(r.x.to_num(), r.y.to_num(), r.yaw.to_num());
        let n = |f: [i32; 4]| reading(f.map(|v| f64::from(v) * 1e-3));
        // The meter rounds min_load to whole mN.
        let min = f64::from((min_load * 1000.0).round()) * 1e-3;
        let want = measured_zmp(&ROBOT, (&pl, &n(lf)), (&pr, &n(rf)), min).zmp;
        match (got, want) {
            (None, None) => {}
            (Some(g), Some(w)) => {
                let tol = 2.0 / 65536.0;
                prop_assert!(
                    close(g[0].to_num(), w[0], tol) && close(g[1].to_num(), w[1], tol),
                    "fixed {:?} vs f64 {:?}", g, w
                );
            }
            (g, w) => prop_assert!(false, "fixed {:?} vs f64 {:?}", g, w),
        }
    }
}

#[test]
fn fixed_zmp_without_readings_or_load_is_none() {
    use gait_core::measure::zmp::FixedZmpMeter;
    let meter = FixedZmpMeter::new(&ROBOT, 5.0);
    let f = fixed_foot(0.0, 0.05, 0.0);
    assert_eq!(meter.zmp((&f, None), (&f, None)), None);
    // 4 × 1 N = 4 N < 5 N on both feet.
    assert_eq!(
        meter.zmp((&f, Some([1000; 4])), (&f, Some([1000; 4]))),
        None
    );
    // Equal forces: the ankle of the one loaded foot.
    let z = meter.zmp((&f, Some([2000; 4])), (&f, None)).expect("a ZMP");
    assert_eq!(z, [f.x, f.y]);
}
