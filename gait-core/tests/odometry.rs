//! Leg odometry (`gait_core::measure::odometry`, O1–O6): a landing placed off its plan by a known amount
//! is recovered from the joint angles the IK gives for it, whatever the pelvis pose; the
//! corrections chain from step to step; the survey's timing, limits and refusals.

use gait_core::kinematics::leg::{LegKinematics, Pose};
use gait_core::measure::odometry::{
    compose, inverse, legs_at_first_read, relative_place, LegOdometry, OdometryLimits, SurveyError,
};
use gait_core::{Place, Robot, Side, SupportPhase};
use proptest::prelude::*;

const RIGHT: SupportPhase = SupportPhase::Single(Side::Right);
const Z_PELVIS: f64 = 0.217;

fn place(x: f64, y: f64, yaw: f64) -> Place<f64> {
    Place { x, y, yaw }
}

/// The joint angles (left leg then right leg) that put the soles at `feet` (world places, on
/// the floor) under a pelvis at `pelvis`.
fn angles(kin: &LegKinematics<f64>, pelvis: &Pose<f64>, feet: [Place<f64>; 2]) -> [f64; 12] {
    let foot = |p: Place<f64>| Pose::level(p.x, p.y, 0.0, p.yaw);
    let (q, report) = kin.legs_ik(pelvis, &foot(feet[0]), &foot(feet[1]));
    assert_eq!(
        report.limited, 0,
        "a reachable pose: {feet:?} under {pelvis:?}"
    );
    q
}

fn close(a: &Place<f64>, b: &Place<f64>, tol: f64) -> bool {
    (a.x - b.x).abs() <= tol && (a.y - b.y).abs() <= tol && (a.yaw - b.yaw).abs() <= tol
}

#[test]
fn compose_and_inverse_are_rigid_motions() {
    let a = place(0.3, -0.1, 0.7);
    let b = place(-0.05, 0.02, -0.2);
    // a ⊕ a⁻¹ = identity, (a ⊕ b) ⊕ b⁻¹ = a, by hand for one point.
    assert!(close(
        &compose(&a, &inverse(&a)),
        &place(0.0, 0.0, 0.0),
        1e-12
    ));
    assert!(close(&compose(&compose(&a, &b), &inverse(&b)), &a, 1e-12));
    let (s, c) = 0.7f64.sin_cos();
    let ab = compose(&a, &b);
    assert!((ab.x - (0.3 + c * -0.05 - s * 0.02)).abs() < 1e-12);
    assert!((ab.y - (-0.1 + s * -0.05 + c * 0.02)).abs() < 1e-12);
    assert!((ab.yaw - 0.5).abs() < 1e-12);
}

#[test]
fn the_survey_recovers_a_landing_off_its_plan() {
    let kin = LegKinematics::<f64>::new(&Robot::reference());
    // Right foot stands at its plan; the left one was planned 4 cm ahead and lands 12 mm
    // further, 3 mm outward and turned 3°.
    let right = place(0.0, -0.045, 0.0);
    let left_plan = place(0.04, 0.045, 0.0);
    let left_real = place(0.052, 0.048, 3f64.to_radians());
    let pelvis = Pose::new(0.02, 0.0, Z_PELVIS, 0.03, -0.05, 0.02);
    let q = angles(&kin, &pelvis, [left_real, right]);
    // The relative place from the stance sole, against the one computed from the places.
    let r = relative_place(&kin, &q, Side::Right, Side::Left);
    let r_true = compose(&inverse(&right), &left_real);
    assert!(close(&r, &r_true, 1e-9), "{r:?} against {r_true:?}");

    let mut odo = LegOdometry::<f64>::new(&OdometryLimits::DEFAULT);
    odo.phase(RIGHT);
    assert_eq!(
        odo.survey_due([0.0, 40.0]),
        None,
        "single support: none due"
    );
    odo.phase(SupportPhase::Double);
    assert_eq!(odo.survey_due([5.0, 40.0]), None, "the new foot under 20 %");
    assert_eq!(
        odo.survey_due([11.0, 40.0]),
        Some((Side::Right, Side::Left))
    );
    assert_eq!(
        odo.survey_due([40.0, 0.0]),
        Some((Side::Right, Side::Left)),
        "the old foot lifted in the landing's bounce"
    );
    // Before the survey the left foot is where the plan says (O6: the right foot's correction).
    assert!(close(&odo.place(Side::Left, &left_plan), &left_plan, 1e-12));
    let measured = odo.survey(&kin, &q, &[left_plan, right]).expect("taken");
    assert!(close(&measured, &left_real, 1e-9), "{measured:?}");
    assert!(close(&odo.place(Side::Left, &left_plan), &left_real, 1e-9));
    assert!(close(&odo.place(Side::Right, &right), &right, 1e-12));
    // Once a double support.
    assert_eq!(odo.survey_due([20.0, 20.0]), None);
    assert_eq!(
        odo.survey(&kin, &q, &[left_plan, right]),
        Err(SurveyError::NotDue)
    );
    assert_eq!(odo.counts(), (1, 0));
}

#[test]
fn the_corrections_chain_from_landing_to_landing() {
    // Three steps, each landing 10 mm long and 1° turned to the left of its plan (measured
    // from the stance sole): the true places follow from the chain of relative placements.
    let kin = LegKinematics::<f64>::new(&Robot::reference());
    let plan = [
        place(0.0, 0.045, 0.0),   // left stands
        place(0.04, -0.045, 0.0), // right lands
        place(0.08, 0.045, 0.0),  // left lands
        place(0.12, -0.045, 0.0), // right lands
    ];
    let err = place(0.010, 0.0, 1f64.to_radians());
    let mut real = [plan[0]; 4];
    for k in 1..4 {
        // The landing's relative place is the plan's, then off by `err` in the stance frame.
        let r_plan = compose(&inverse(&plan[k - 1]), &plan[k]);
        real[k] = compose(&real[k - 1], &compose(&r_plan, &err));
    }
    let mut odo = LegOdometry::<f64>::new(&OdometryLimits::DEFAULT);
    odo.phase(SupportPhase::Standing);
    odo.phase(SupportPhase::Double);
    assert_eq!(odo.survey_due([20.0, 20.0]), None, "no step yet");
    for k in 1..4 {
        let stance = if k % 2 == 1 { Side::Left } else { Side::Right };
        odo.phase(SupportPhase::Single(stance));
        odo.phase(SupportPhase::Double);
        let (s, n) = odo.survey_due([20.0, 20.0]).expect("due");
        assert_eq!((s, n), (stance, stance.other()));
        let mut feet = [real[k - 1], real[k]];
        let mut planned = [plan[k - 1], plan[k]];
        if stance == Side::Right {
            feet.swap(0, 1);
            planned.swap(0, 1);
        }
        let mid = compose(&feet[0], &place(0.0, -0.045, 0.0));
        let pelvis = Pose::new(mid.x, mid.y, Z_PELVIS, 0.0, 0.0, mid.yaw);
        let q = angles(&kin, &pelvis, feet);
        let got = odo.survey(&kin, &q, &planned).expect("taken");
        assert!(
            close(&got, &real[k], 1e-9),
            "step {k}: {got:?} {:?}",
            real[k]
        );
        assert!(close(&odo.place(n, &plan[k]), &real[k], 1e-9));
    }
    // The next swing foot takes the stance foot's correction (O6) when its support begins.
    let c_right = odo.correction(Side::Right);
    odo.phase(RIGHT);
    assert_eq!(odo.correction(Side::Left), c_right);
}

#[test]
fn two_reads_a_tick_apart_give_the_landing_at_the_first() {
    // The pelvis moves 1.5 mm forward, 1 mm sideways and turns between the reads; the servos
    // stand a constant 0.03 rad short of their goals (the sag cancels in the goals' change).
    let kin = LegKinematics::<f64>::new(&Robot::reference());
    let right = place(0.0, -0.045, 0.0);
    let left_real = place(0.052, 0.048, 0.04);
    let left_plan = place(0.04, 0.045, 0.0);
    let p1 = Pose::new(0.020, -0.010, Z_PELVIS, 0.02, -0.03, 0.01);
    let p2 = Pose::new(0.0215, -0.009, Z_PELVIS - 0.0005, 0.021, -0.028, 0.012);
    let q1 = angles(&kin, &p1, [left_real, right]);
    let q2 = angles(&kin, &p2, [left_real, right]);
    let goals = |q: &[f64; 12]| q.map(|v| v + 0.03);
    let mut first = q1;
    first[..6].fill(f64::NAN); // only the right (stance) leg was read first
    let mut second = q2;
    second[6..].fill(f64::NAN); // only the left (new) leg second
    let q = legs_at_first_read(Side::Right, &first, &second, &goals(&q1), &goals(&q2));
    for (j, (a, b)) in q.iter().zip(&q1).enumerate() {
        assert!((a - b).abs() < 1e-12, "joint {j}: {a} against {b}");
    }
    let mut odo = LegOdometry::<f64>::new(&OdometryLimits::DEFAULT);
    odo.phase(RIGHT);
    odo.phase(SupportPhase::Double);
    let got = odo.survey(&kin, &q, &[left_plan, right]).expect("taken");
    assert!(close(&got, &left_real, 1e-9), "{got:?}");
    // Without the goals' change (the second read as it is) the pelvis's motion is the error.
    let mut stale = q1;
    stale[..6].copy_from_slice(&q2[..6]);
    let r = relative_place(&kin, &stale, Side::Right, Side::Left);
    let r_true = compose(&inverse(&right), &left_real);
    assert!(
        (r.x - r_true.x).abs() > 5e-4,
        "the test moves the pelvis: {r:?}"
    );
}

#[test]
fn implausible_and_non_finite_readings_are_refused() {
    let kin = LegKinematics::<f64>::new(&Robot::reference());
    let right = place(0.0, -0.045, 0.0);
    let left_plan = place(0.04, 0.045, 0.0);
    let pelvis = Pose::new(0.02, 0.0, Z_PELVIS, 0.0, 0.0, 0.0);
    let due = || {
        let mut odo = LegOdometry::<f64>::new(&OdometryLimits::DEFAULT);
        odo.phase(RIGHT);
        odo.phase(SupportPhase::Double);
        odo
    };
    // 6 cm long: beyond d_max = 5 cm.
    let q = angles(&kin, &pelvis, [place(0.10, 0.045, 0.0), right]);
    let mut odo = due();
    assert_eq!(
        odo.survey(&kin, &q, &[left_plan, right]),
        Err(SurveyError::Implausible)
    );
    assert!(close(&odo.place(Side::Left, &left_plan), &left_plan, 0.0));
    // 4.9 cm long: taken.
    let q = angles(&kin, &pelvis, [place(0.089, 0.045, 0.0), right]);
    assert!(due().survey(&kin, &q, &[left_plan, right]).is_ok());
    // A NaN angle.
    let mut q = angles(&kin, &pelvis, [left_plan, right]);
    q[3] = f64::NAN;
    let mut odo = due();
    assert_eq!(
        odo.survey(&kin, &q, &[left_plan, right]),
        Err(SurveyError::NonFinite)
    );
    assert_eq!(odo.counts(), (0, 1));
    assert_eq!(odo.correction(Side::Left), place(0.0, 0.0, 0.0));
    // Limits that are not numbers refuse every survey.
    let bad = OdometryLimits {
        max_offset_m: f32::NAN,
        ..OdometryLimits::DEFAULT
    };
    let mut odo = LegOdometry::<f64>::new(&bad);
    odo.phase(RIGHT);
    odo.phase(SupportPhase::Double);
    let q = angles(&kin, &pelvis, [place(0.041, 0.045, 0.0), right]);
    assert_eq!(
        odo.survey(&kin, &q, &[left_plan, right]),
        Err(SurveyError::Implausible)
    );
    // Loads that are not numbers count as unloaded.
    assert_eq!(due().survey_due([f64::NAN, 40.0]), None);
    assert_eq!(due().survey_due([0.0, 0.0]), None);
}

#[test]
fn f32_survey_agrees_with_f64() {
    let robot = Robot::reference();
    let (k64, k32) = (
        LegKinematics::<f64>::new(&robot),
        LegKinematics::<f32>::new(&robot),
    );
    let pelvis = Pose::new(0.01, -0.01, Z_PELVIS, 0.02, 0.04, -0.03);
    let feet = [place(0.05, 0.05, 0.05), place(-0.02, -0.04, -0.02)];
    let q = angles(&k64, &pelvis, feet);
    let r64 = relative_place(&k64, &q, Side::Right, Side::Left);
    let r32 = relative_place(&k32, &q.map(|v| v as f32), Side::Right, Side::Left);
    // fastmath's sin/cos/atan2 (≈ 1e-6) over a 0.2 m chain: well under 0.1 mm.
    assert!((f64::from(r32.x) - r64.x).abs() < 5e-5, "{r32:?} {r64:?}");
    assert!((f64::from(r32.y) - r64.y).abs() < 5e-5);
    assert!((f64::from(r32.yaw) - r64.yaw).abs() < 5e-5);
}

proptest! {
    /// Any reachable landing within the limits is recovered to 1e-8 m / rad, under any pelvis
    /// attitude, from either stance foot.
    #[test]
    fn any_reachable_landing_is_recovered(
        dx in -0.04f64..0.04, dy in -0.02f64..0.02, dyaw in -0.2f64..0.2,
        roll in -0.1f64..0.1, pitch in -0.1f64..0.1, yaw in -0.3f64..0.3,
        px in -0.02f64..0.02, right_stance in any::<bool>(),
    ) {
        let kin = LegKinematics::<f64>::new(&Robot::reference());
        let (stance, new) = if right_stance { (Side::Right, Side::Left) } else { (Side::Left, Side::Right) };
        let sy = if right_stance { -0.045 } else { 0.045 };
        let stance_place = place(0.0, sy, yaw);
        let new_plan = compose(&stance_place, &place(0.03, -2.0 * sy, 0.0));
        let new_real = compose(&new_plan, &place(dx, dy, dyaw));
        let mid = compose(&stance_place, &place(px, -sy, 0.0));
        let pelvis = Pose::new(mid.x, mid.y, Z_PELVIS, roll, pitch, yaw + 0.5 * dyaw);
        let mut feet = [stance_place, new_real];
        let mut planned = [stance_place, new_plan];
        if right_stance {
            feet.swap(0, 1);
            planned.swap(0, 1);
        }
        let foot = |p: Place<f64>| Pose::level(p.x, p.y, 0.0, p.yaw);
        let (q, report) = kin.legs_ik(&pelvis, &foot(feet[0]), &foot(feet[1]));
        prop_assume!(report.limited == 0);
        // Reachable: the FK of the IK's angles puts both soles where asked (no reach clamp).
        let reached = [Side::Left, Side::Right].iter().zip(feet).all(|(&side, f)| {
            let at = if side == Side::Left { 0 } else { 6 };
            let leg: [f64; 6] = core::array::from_fn(|j| q[at + j]);
            let p = kin.fk(side, &pelvis, &leg);
            (p.x - f.x).abs() < 1e-9 && (p.y - f.y).abs() < 1e-9 && p.z.abs() < 1e-9
        });
        prop_assume!(reached);
        let mut odo = LegOdometry::<f64>::new(&OdometryLimits::DEFAULT);
        odo.phase(SupportPhase::Single(stance));
        odo.phase(SupportPhase::Double);
        prop_assert_eq!(odo.survey_due([10.0, 10.0]), Some((stance, new)));
        let limits_ok = (new_real.x - new_plan.x).abs() < 0.05;
        let got = odo.survey(&kin, &q, &planned);
        if limits_ok {
            let got = got.expect("taken");
            prop_assert!(close(&got, &new_real, 1e-8), "{:?} against {:?}", got, new_real);
        }
        let c = odo.correction(new);
        prop_assert!(c.x.is_finite() && c.y.is_finite() && c.yaw.is_finite());
    }
}

/// A sample standing on soles `l`, `r` (x, y) with its ZMP reference at `zmp`.
fn sample_at(l: [f32; 2], r: [f32; 2], zmp: [f32; 2]) -> gait_core::GaitSample<f32> {
    let mut s = gait_core::GaitSample::<f32>::zero();
    s.feet[0].x = l[0];
    s.feet[0].y = l[1];
    s.feet[1].x = r[0];
    s.feet[1].y = r[1];
    s.zmp = zmp;
    s
}

proptest! {
    /// The planned split of the loads (a robot without foot sensors times its surveys by it):
    /// the ZMP reference at the fraction t of the way from the right sole to the left one gives
    /// the left foot the share t (1 − t the right), clamped to [0, 1] beyond the soles; shares
    /// always finite and summing to 1.
    #[test]
    fn the_planned_split_is_the_zmp_reference_place_between_the_soles(
        rx in -0.3f32..0.3, ry in -0.3f32..0.3,
        dx in -0.1f32..0.1, dy in 0.03f32..0.12,
        t in -0.5f32..1.5, off in -0.02f32..0.02,
    ) {
        let (l, r) = ([rx + dx, ry + dy], [rx, ry]);
        // A point off the segment, across it, by `off`: the same share.
        let n = (dx * dx + dy * dy).sqrt();
        let zmp = [rx + t * dx - off * dy / n, ry + t * dy + off * dx / n];
        let [sl, sr] = sample_at(l, r, zmp).planned_load_shares();
        let want = t.clamp(0.0, 1.0);
        prop_assert!((sl - want).abs() < 1e-4, "{sl} for t = {t}");
        prop_assert!((sl + sr - 1.0).abs() < 1e-6);
    }
}

#[test]
fn the_planned_split_is_even_on_one_point_and_for_a_non_finite_reference() {
    let same = sample_at([0.1, 0.0], [0.1, 0.0], [0.3, 0.2]);
    assert_eq!(same.planned_load_shares(), [0.5, 0.5]);
    let nan = sample_at([0.0, 0.045], [0.0, -0.045], [f32::NAN, 0.0]);
    assert_eq!(nan.planned_load_shares(), [0.5, 0.5]);
    let on_right = sample_at([0.0, 0.045], [0.0, -0.045], [0.0, -0.045]);
    assert_eq!(on_right.planned_load_shares(), [0.0, 1.0]);
}
