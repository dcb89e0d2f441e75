//! Leg kinematics: FK/IK round trips, sign conventions, unreachable and invalid targets, and
//! the joint-speed feasibility monitor.

use gait_core::kinematics::leg::{
    check, leg_fk, leg_ik, leg_points, legs_ik, IkSolution, JointSpeedMonitor, LegKinematics, Pose,
    KNEE_MIN_BEND,
};
use gait_core::robot::{JOINT_NAMES, LEG_JOINTS};
use gait_core::{GaitError, Real, Robot, Side};
use proptest::prelude::*;

const ROBOT: Robot = Robot::reference();

fn pose<R: Real>(p: [f64; 6]) -> Pose<R> {
    let [x, y, z, roll, pitch, yaw] = p.map(R::of);
    Pose::new(x, y, z, roll, pitch, yaw)
}

/// Largest position difference, m.
fn pos_err<R: Real>(a: &Pose<R>, b: &Pose<R>) -> f64 {
    let (pa, pb) = (a.position(), b.position());
    (0..3)
        .map(|i| (pa[i].to_f64() - pb[i].to_f64()).abs())
        .fold(0.0, f64::max)
}

/// Largest rotation-matrix entry difference (≈ the rotation angle between the poses), rad.
fn rot_err<R: Real>(a: &Pose<R>, b: &Pose<R>) -> f64 {
    let (ra, rb) = (a.rotation(), b.rotation());
    let mut e = 0.0f64;
    for i in 0..3 {
        for j in 0..3 {
            e = e.max((ra[i][j].to_f64() - rb[i][j].to_f64()).abs());
        }
    }
    e
}

/// Every angle is finite and inside the joint limits of `side`.
fn assert_within_limits<R: Real>(side: Side, q: &[R; 6]) {
    for (j, v) in q.iter().enumerate() {
        let l = ROBOT.joint_limit(side, j);
        let v = v.to_f64();
        assert!(v.is_finite(), "joint {j} not finite");
        assert!(
            v >= R::of(l.min).to_f64() && v <= R::of(l.max).to_f64(),
            "joint {j} = {v} outside [{}, {}]",
            l.min,
            l.max
        );
    }
}

fn side_of(left: bool) -> Side {
    if left {
        Side::Left
    } else {
        Side::Right
    }
}

/// A random pelvis pose and foot pose of the brief's workspace: pelvis height 0.16–0.225 m,
/// foot ±0.06 m (x) and ±0.04 m (y) around the point under the nominal hip (in the pelvis
/// heading), foot up to 0.03 m off the ground, yaw ±0.4 (pelvis) and ±0.4 relative (foot),
/// roll and pitch ±0.15 for both.
fn workspace() -> impl Strategy<Value = (bool, [f64; 6], [f64; 6])> {
    let pelvis = (
        -0.1..0.1f64,
        -0.1..0.1f64,
        0.16..0.225f64,
        -0.15..0.15f64,
        -0.15..0.15f64,
        -0.4..0.4f64,
    );
    let foot = (
        -0.06..0.06f64,
        -0.04..0.04f64,
        0.0..0.03f64,
        -0.15..0.15f64,
        -0.15..0.15f64,
        -0.4..0.4f64,
    );
    (any::<bool>(), pelvis, foot).prop_map(|(left, p, f)| {
        let sigma = if left { 1.0 } else { -1.0 };
        let (px, py, pz, pr, pp, pyaw) = p;
        let (dx, dy, fz, fr, fp, dyaw) = f;
        let (s, c) = pyaw.sin_cos();
        let (lx, ly) = (dx, sigma * ROBOT.geometry.hip_offset_y + dy);
        let foot = [
            px + c * lx - s * ly,
            py + s * lx + c * ly,
            fz,
            fr,
            fp,
            pyaw + dyaw,
        ];
        (left, [px, py, pz, pr, pp, pyaw], foot)
    })
}

/// FK(IK(target)) reproduces the target; returns false when the target was not reachable.
fn round_trip_target<R: Real>(
    left: bool,
    p: [f64; 6],
    f: [f64; 6],
    tol_pos: f64,
    tol_rot: f64,
) -> bool {
    let side = side_of(left);
    let (pelvis, foot) = (pose::<R>(p), pose::<R>(f));
    let sol: IkSolution<R> = leg_ik(&ROBOT, side, &pelvis, &foot);
    assert_within_limits(side, &sol.q);
    if sol.clamped() {
        return false;
    }
    let back = leg_fk(&ROBOT, side, &pelvis, &sol.q);
    let (ep, er) = (pos_err(&back, &foot), rot_err(&back, &foot));
    assert!(
        ep <= tol_pos,
        "position error {ep:e} m for {side:?} {p:?} {f:?}"
    );
    assert!(
        er <= tol_rot,
        "orientation error {er:e} rad for {side:?} {p:?} {f:?}"
    );
    true
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, max_global_rejects: 4000, ..ProptestConfig::default() })]

    /// FK(IK(target)) = target within 1e-5 m / 1e-4 rad in f32 for reachable random targets.
    #[test]
    fn fk_of_ik_is_target_f32((left, p, f) in workspace()) {
        prop_assume!(round_trip_target::<f32>(left, p, f, 1e-5, 1e-4));
    }

    /// FK(IK(target)) = target within 1e-9 in f64 for reachable random targets.
    #[test]
    fn fk_of_ik_is_target_f64((left, p, f) in workspace()) {
        prop_assume!(round_trip_target::<f64>(left, p, f, 1e-9, 1e-9));
    }

    /// IK(FK(q)) = q for q inside the limits, knee in [0.2, 2.4], |rolls| ≤ 0.35 and the ankle
    /// in the |q3/2 + q4| < 1.4 branch (hip above the ankle in the foot frame), under a random
    /// pelvis pose; 1e-9 rad in f64, 1e-4 rad in f32.
    #[test]
    fn ik_of_fk_is_q(
        left in any::<bool>(),
        q0 in -0.85..0.85f64, q1 in -0.35..0.35f64, q2 in -1.85..0.85f64,
        q3 in 0.2..2.4f64, q4 in -1.25..1.05f64, q5 in -0.35..0.35f64,
        p in (-0.1..0.1f64, -0.1..0.1f64, 0.1..0.3f64, -0.15..0.15f64, -0.15..0.15f64, -0.5..0.5f64),
    ) {
        prop_assume!((q3 / 2.0 + q4).abs() < 1.4);
        let side = side_of(left);
        let q = [q0, q1, q2, q3, q4, q5];
        let p = [p.0, p.1, p.2, p.3, p.4, p.5];
        let pelvis = pose::<f64>(p);
        let foot = leg_fk(&ROBOT, side, &pelvis, &q);
        let sol = leg_ik(&ROBOT, side, &pelvis, &foot);
        prop_assert!(!sol.clamped(), "{sol:?}");
        for (j, (got, want)) in sol.q.iter().zip(q.iter()).enumerate() {
            prop_assert!((got - want).abs() < 1e-9, "f64 joint {j}: {got} vs {want}");
        }
        let q32 = q.map(|v| v as f32);
        let pelvis32 = pose::<f32>(p);
        let foot32 = leg_fk(&ROBOT, side, &pelvis32, &q32);
        let sol32 = leg_ik(&ROBOT, side, &pelvis32, &foot32);
        for (j, (got, want)) in sol32.q.iter().zip(q32.iter()).enumerate() {
            prop_assert!((got - want).abs() < 1e-4, "f32 joint {j}: {got} vs {want}");
        }
    }

    /// Any input whatsoever (NaN, ±inf, huge, subnormal) gives finite angles within the limits,
    /// and non-finite input is flagged.
    #[test]
    fn ik_never_leaves_limits_on_any_input(
        left in any::<bool>(),
        p in proptest::array::uniform6(any::<f32>()),
        f in proptest::array::uniform6(any::<f32>()),
    ) {
        let side = side_of(left);
        let pelvis = Pose::new(p[0], p[1], p[2], p[3], p[4], p[5]);
        let foot = Pose::new(f[0], f[1], f[2], f[3], f[4], f[5]);
        let sol = leg_ik(&ROBOT, side, &pelvis, &foot);
        assert_within_limits(side, &sol.q);
        prop_assert!(sol.reach_deficit.is_finite() && sol.reach_deficit >= 0.0);
        if !(pelvis.is_finite() && foot.is_finite()) {
            prop_assert!(sol.invalid_input && sol.clamped());
        }
        let (q, rep) = legs_ik(&ROBOT, &pelvis, &foot, &foot);
        prop_assert!(q.iter().all(|v| v.is_finite()));
        prop_assert!(rep.reach_deficit.iter().all(|v| v.is_finite()));
    }

    /// The link lengths are preserved by FK and the mass points sit where documented.
    #[test]
    fn leg_points_geometry(
        left in any::<bool>(),
        q in proptest::array::uniform6(-1.0..1.0f64),
        p in proptest::array::uniform6(-0.3..0.3f64),
    ) {
        let side = side_of(left);
        let pelvis = pose::<f64>(p);
        let pts = leg_points(&ROBOT, side, &pelvis, &q);
        let g = ROBOT.geometry;
        let dist = |a: [f64; 3], b: [f64; 3]| ((a[0]-b[0]).powi(2) + (a[1]-b[1]).powi(2) + (a[2]-b[2]).powi(2)).sqrt();
        prop_assert!((dist(pts.hip, pelvis.position()) - g.hip_offset_y).abs() < 1e-12);
        prop_assert!((dist(pts.hip, pts.knee) - g.thigh).abs() < 1e-12);
        prop_assert!((dist(pts.knee, pts.ankle) - g.calf).abs() < 1e-12);
        prop_assert!((dist(pts.ankle, pts.sole) - g.ankle_height).abs() < 1e-12);
        prop_assert!((dist(pts.sole_mass, pts.sole) - ROBOT.masses.sole_height).abs() < 1e-12);
        prop_assert!((dist(pts.sole_mass, pts.ankle) - (g.ankle_height - ROBOT.masses.sole_height)).abs() < 1e-12);
        prop_assert!((dist(pts.thigh_mass, pts.hip) - g.thigh / 2.0).abs() < 1e-12);
        prop_assert!((dist(pts.calf_mass, pts.knee) - g.calf / 2.0).abs() < 1e-12);
        let foot = leg_fk(&ROBOT, side, &pelvis, &q);
        prop_assert!(dist(foot.position(), pts.sole) < 1e-15);
    }
}

// ---------------------------------------------------------------------------------------------
// Hand-checked signs. Pelvis at the origin, level; left leg unless stated. With all joints at
// zero the sole point is at (0, +0.045, −0.23) and the foot is flat (roll = pitch = yaw = 0).
// Ry(a)·(0,0,−L) = (−L·sin a, 0, −L·cos a); Rx(a)·(0,0,−L) = (0, L·sin a, −L·cos a);
// Ry(a) maps the foot's x axis to (cos a, 0, −sin a) (toe down for a > 0); Rx(a) maps its y axis
// to (0, cos a, sin a) (left edge up for a > 0).
// ---------------------------------------------------------------------------------------------

const LEG: f64 = 0.23;
const HIP_Y: f64 = 0.045;

fn fk(side: Side, q: [f64; 6]) -> Pose<f64> {
    leg_fk(&ROBOT, side, &Pose::default(), &q)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-12
}

#[test]
fn zero_pose_is_straight_leg_flat_foot() {
    for (side, y) in [(Side::Left, HIP_Y), (Side::Right, -HIP_Y)] {
        let f = fk(side, [0.0; 6]);
        assert!(
            close(f.x, 0.0) && close(f.y, y) && close(f.z, -LEG),
            "{f:?}"
        );
        assert!(close(f.roll, 0.0) && close(f.pitch, 0.0) && close(f.yaw, 0.0));
        assert!(close(ROBOT.geometry.straight_leg_height(), LEG));
    }
}

/// +hip_yaw turns the foot counter-clockwise seen from above (foot yaw = +a). With the leg
/// swung back by hip_pitch = +0.3 the sole point is at (−L·sin 0.3, 0) from the hip axis, and
/// yawing it by +0.4 rotates it toward −y: Δy = −L·sin 0.3·sin 0.4 < 0.
#[test]
fn sign_hip_yaw() {
    let f = fk(Side::Left, [0.4, 0.0, 0.0, 0.0, 0.0, 0.0]);
    assert!(close(f.yaw, 0.4) && close(f.x, 0.0) && close(f.y, HIP_Y));
    let f = fk(Side::Left, [0.4, 0.0, 0.3, 0.0, 0.0, 0.0]);
    let back = LEG * 0.3f64.sin();
    assert!(close(f.x, -back * 0.4f64.cos()), "{f:?}");
    assert!(close(f.y, HIP_Y - back * 0.4f64.sin()), "{f:?}");
    assert!(f.y < HIP_Y);
}

/// +hip_roll swings the foot to +y (outward for the left leg, inward for the right) and
/// tilts the sole with roll = +a: y = ±0.045 + L·sin a, z = −L·cos a.
#[test]
fn sign_hip_roll() {
    for (side, y0) in [(Side::Left, HIP_Y), (Side::Right, -HIP_Y)] {
        let f = fk(side, [0.0, 0.2, 0.0, 0.0, 0.0, 0.0]);
        assert!(close(f.y, y0 + LEG * 0.2f64.sin()) && f.y > y0, "{f:?}");
        assert!(close(f.z, -LEG * 0.2f64.cos()) && close(f.roll, 0.2) && close(f.x, 0.0));
    }
}

/// +hip_pitch swings the foot backward (−x) and pitches the sole toe-down (pitch = +a).
#[test]
fn sign_hip_pitch() {
    let f = fk(Side::Left, [0.0, 0.0, 0.3, 0.0, 0.0, 0.0]);
    assert!(close(f.x, -LEG * 0.3f64.sin()) && f.x < 0.0, "{f:?}");
    assert!(close(f.pitch, 0.3) && close(f.z, -LEG * 0.3f64.cos()));
}

/// +knee alone folds the calf backward: the sole point goes back (−x) and up; the foot pitches
/// toe-down by the knee angle. With hip_pitch = ankle_pitch = −knee/2 (a crouch) the foot stays
/// flat, directly under the hip, and rises by (L1 + L2)(1 − cos(knee/2)).
#[test]
fn sign_knee() {
    let g = ROBOT.geometry;
    let lower = g.calf + g.ankle_height;
    let f = fk(Side::Left, [0.0, 0.0, 0.0, 0.6, 0.0, 0.0]);
    assert!(close(f.x, -lower * 0.6f64.sin()) && f.x < 0.0, "{f:?}");
    assert!(close(f.z, -g.thigh - lower * 0.6f64.cos()) && f.z > -LEG);
    assert!(close(f.pitch, 0.6));
    let f = fk(Side::Left, [0.0, 0.0, -0.3, 0.6, -0.3, 0.0]);
    assert!(close(f.x, 0.0) && close(f.pitch, 0.0), "{f:?}");
    let rise = (g.thigh + g.calf) * (1.0 - 0.3f64.cos());
    assert!(close(f.z, -LEG + rise) && rise > 0.0);
    // The IK agrees: a lower pelvis needs a positive knee and a crouch.
    let sol = leg_ik(&ROBOT, Side::Left, &Pose::default(), &f);
    assert!(
        (sol.q[2] + 0.3).abs() < 1e-9
            && (sol.q[3] - 0.6).abs() < 1e-9
            && (sol.q[4] + 0.3).abs() < 1e-9
    );
}

/// +ankle_pitch swings the sole point backward about the ankle (Δx = −h·sin a) and pitches the
/// foot toe-down (pitch = +a).
#[test]
fn sign_ankle_pitch() {
    let h = ROBOT.geometry.ankle_height;
    let f = fk(Side::Left, [0.0, 0.0, 0.0, 0.0, 0.3, 0.0]);
    assert!(
        close(f.x, -h * 0.3f64.sin()) && f.x < 0.0 && close(f.pitch, 0.3),
        "{f:?}"
    );
}

/// +ankle_roll swings the sole point to +y about the ankle (Δy = h·sin a) and tilts the sole
/// so its +y (left) edge rises: roll = +a. The IK answers a foot moved to +y under a fixed
/// pelvis with +hip_roll and −ankle_roll (the sole stays flat).
#[test]
fn sign_ankle_roll() {
    let h = ROBOT.geometry.ankle_height;
    let f = fk(Side::Left, [0.0, 0.0, 0.0, 0.0, 0.0, 0.2]);
    assert!(
        close(f.y, HIP_Y + h * 0.2f64.sin()) && close(f.roll, 0.2),
        "{f:?}"
    );
    let rot = f.rotation();
    assert!(rot[2][1] > 0.0, "the foot's y axis points up");
    let pelvis = Pose::level(0.0, 0.0, 0.2, 0.0);
    for side in [Side::Left, Side::Right] {
        let y0 = side.sign() * HIP_Y;
        let sol = leg_ik(
            &ROBOT,
            side,
            &pelvis,
            &Pose::level(0.0, y0 + 0.02, 0.0, 0.0),
        );
        assert!(
            sol.q[1] > 0.0 && sol.q[5] < 0.0 && close(sol.q[1], -sol.q[5]),
            "{sol:?}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Unreachable and invalid targets.
// ---------------------------------------------------------------------------------------------

#[test]
fn unreachable_foot_one_metre_away() {
    let pelvis = Pose::level(0.0f32, 0.0, 0.2, 0.0);
    for side in [Side::Left, Side::Right] {
        for foot in [
            Pose::level(1.0f32, 0.0, 0.0, 0.0),
            Pose::level(0.0, -1.0, 0.0, 0.0),
            Pose::level(0.0, 0.0, -1.0, 0.0),
        ] {
            let sol = leg_ik(&ROBOT, side, &pelvis, &foot);
            assert!(sol.reach_deficit > 0.7 && sol.clamped(), "{sol:?}");
            assert_within_limits(side, &sol.q);
            assert!(
                sol.q[3] >= KNEE_MIN_BEND as f32 * 0.999,
                "knee stays bent: {}",
                sol.q[3]
            );
        }
    }
}

/// The straight-down target just beyond reach: knee held at the minimum bend, deficit reported.
#[test]
fn reach_is_clamped_to_slightly_bent_knee() {
    let k = LegKinematics::<f64>::new(&ROBOT);
    let pelvis = Pose::level(0.0, 0.0, LEG, 0.0);
    let sol = leg_ik(
        &ROBOT,
        Side::Left,
        &pelvis,
        &Pose::level(0.0, HIP_Y, 0.0, 0.0),
    );
    let expected = 0.2 - k.max_reach();
    assert!(
        close(sol.reach_deficit, expected) && expected > 0.0,
        "{sol:?}"
    );
    assert!(close(sol.q[3], KNEE_MIN_BEND) && sol.limited == 0);
    // Too close: knee at its upper limit.
    let sol = leg_ik(
        &ROBOT,
        Side::Left,
        &Pose::level(0.0, 0.0, 0.04, 0.0),
        &Pose::level(0.0, HIP_Y, 0.0, 0.0),
    );
    assert!(
        sol.reach_deficit > 0.0 && close(sol.q[3], ROBOT.joint_limits[3].max),
        "{sol:?}"
    );
}

#[test]
fn nan_and_inf_inputs_give_finite_flagged_result() {
    let good_p = [0.0, 0.0, 0.2, 0.0, 0.0, 0.0];
    let good_f = [0.0, HIP_Y, 0.0, 0.0, 0.0, 0.0];
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300] {
        for i in 0..12 {
            let (mut p, mut f) = (good_p, good_f);
            if i < 6 {
                p[i] = bad;
            } else {
                f[i - 6] = bad;
            }
            for side in [Side::Left, Side::Right] {
                let s32 = leg_ik(&ROBOT, side, &pose::<f32>(p), &pose::<f32>(f));
                assert_within_limits(side, &s32.q);
                assert!(
                    s32.clamped() && s32.reach_deficit.is_finite(),
                    "{bad} at {i}: {s32:?}"
                );
                let s64 = leg_ik(&ROBOT, side, &pose::<f64>(p), &pose::<f64>(f));
                assert_within_limits(side, &s64.q);
                assert!(s64.clamped() && s64.reach_deficit.is_finite());
                if !bad.is_finite() || i < 3 || (6..9).contains(&i) {
                    assert!(s64.invalid_input);
                }
            }
        }
    }
}

#[test]
fn pelvis_below_foot_is_flagged() {
    let pelvis = Pose::level(0.0, 0.0, -0.15, 0.0);
    for side in [Side::Left, Side::Right] {
        let sol = leg_ik(
            &ROBOT,
            side,
            &pelvis,
            &Pose::level(0.0, side.sign() * HIP_Y, 0.0, 0.0),
        );
        assert_within_limits(side, &sol.q);
        assert!(sol.clamped() && sol.limited != 0, "{sol:?}");
    }
}

#[test]
fn legs_ik_matches_single_leg_ik() {
    let pelvis = pose::<f32>([0.01, 0.0, 0.2, 0.05, -0.03, 0.1]);
    let lf = pose::<f32>([0.03, 0.05, 0.0, 0.0, 0.0, 0.1]);
    let rf = pose::<f32>([-0.02, -0.05, 0.02, 0.0, 0.05, 0.2]);
    let (q, rep) = legs_ik(&ROBOT, &pelvis, &lf, &rf);
    let l = leg_ik(&ROBOT, Side::Left, &pelvis, &lf);
    let r = leg_ik(&ROBOT, Side::Right, &pelvis, &rf);
    assert_eq!(q[..6], l.q);
    assert_eq!(q[6..], r.q);
    assert!(!rep.clamped() && !l.clamped() && !r.clamped());
    // Right leg out of reach, left fine: the bits and deficits land on the right leg.
    let far = Pose::level(0.0f32, -1.0, 0.0, 3.0);
    let (_, rep) = legs_ik(&ROBOT, &pelvis, &lf, &far);
    assert!(rep.reach_deficit[0] == 0.0 && rep.reach_deficit[1] > 0.0);
    assert_eq!(rep.limited & 0x3f, 0);
    assert_ne!(
        rep.limited & 0xfc0,
        0,
        "the 3 rad yaw clamps the right hip yaw: {rep:?}"
    );
}

#[test]
fn ik_respects_mirrored_limits() {
    // Hip yaw far beyond ±0.9: clamped to the mirrored limit with bit 0 set.
    let pelvis = Pose::level(0.0, 0.0, 0.2, 0.0);
    for side in [Side::Left, Side::Right] {
        let foot = Pose::level(0.0, side.sign() * HIP_Y, 0.0, 1.5);
        let sol = leg_ik(&ROBOT, side, &pelvis, &foot);
        assert!(
            sol.limited & 1 != 0 && close(sol.q[0], ROBOT.joint_limit(side, 0).max),
            "{sol:?}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Joint-speed feasibility.
// ---------------------------------------------------------------------------------------------

/// Runs `q_j(t) = offset + amp·sin(ω(t − t0))` on joint `j` (others still) from 0 to `t_end`.
fn sine_run(j: usize, amp: f64, omega: f64, t0: f64, t_end: f64, dt: f64) -> JointSpeedMonitor {
    let mut m = JointSpeedMonitor::new(&ROBOT, dt).unwrap();
    let n = (t_end / dt).round() as usize;
    for k in 0..=n {
        let t = k as f64 * dt;
        let mut q = [0.1f32; LEG_JOINTS];
        q[j] = (0.5 + amp * (omega * (t - t0)).sin()) as f32;
        m.push(t, &q);
    }
    m
}

/// A 2 Hz, 0.3 rad sine has peak speed 0.3·4π ≈ 3.77 rad/s < 4.8: reported within the
/// finite-difference error (ω·dt)²/6 relative and dt/2 in time, and accepted.
#[test]
fn sine_trajectory_peak_speed_is_reported() {
    let (amp, omega, dt) = (0.3, 4.0 * core::f64::consts::PI, 0.005);
    let m = sine_run(4, amp, omega, 0.0, 1.0, dt);
    let rep = m.report();
    let peak = amp * omega;
    assert_eq!(rep.worst_joint, 4);
    assert!(
        (rep.worst_speed - peak).abs() <= peak * (omega * dt).powi(2) / 6.0 + 1e-5,
        "{rep:?}"
    );
    // The peaks are at multiples of 0.25 s.
    let phase = rep.worst_time / 0.25;
    assert!(
        (phase - phase.round()).abs() * 0.25 <= dt / 2.0 + 1e-12,
        "{}",
        rep.worst_time
    );
    for (j, s) in rep.peak_speed.iter().enumerate() {
        if j != 4 {
            assert_eq!(*s, 0.0);
        }
    }
    assert_eq!(check(&rep), Ok(()));
    assert_eq!(rep.limit, ROBOT.servo.max_speed);
}

/// A 0.5 rad, 2 Hz sine on the right knee peaks at 2π ≈ 6.28 rad/s > 4.8 at t = 0.1 s: rejected,
/// naming r_knee, the time and the speed.
#[test]
fn too_fast_trajectory_is_rejected_naming_joint_and_time() {
    let (amp, omega, dt) = (0.5, 4.0 * core::f64::consts::PI, 0.004);
    let m = sine_run(9, amp, omega, 0.1, 0.2, dt);
    let err = check(&m.report()).unwrap_err();
    assert_eq!(err.joint, 9);
    assert_eq!(err.joint_name(), "r_knee");
    assert_eq!(JOINT_NAMES[err.joint], "r_knee");
    assert!((err.time - 0.1).abs() <= dt / 2.0 + 1e-12, "{err:?}");
    assert!((err.speed - amp * omega).abs() < amp * omega * (omega * dt).powi(2) / 6.0 + 1e-5);
    assert_eq!(err.limit, 4.8);
    let msg = format!("{err}");
    assert!(msg.contains("r_knee"), "{msg}");
}

#[test]
fn speed_monitor_edge_cases() {
    assert_eq!(
        JointSpeedMonitor::new(&ROBOT, 0.0).unwrap_err(),
        GaitError::NonPositiveParameter
    );
    assert!(JointSpeedMonitor::new(&ROBOT, f64::NAN).is_err());
    // No samples: nothing reported, feasible.
    let m = JointSpeedMonitor::new(&ROBOT, 0.01).unwrap();
    assert_eq!(check(&m.report()), Ok(()));
    // A NaN sample makes that joint infinitely fast, hence infeasible.
    let mut m = JointSpeedMonitor::new(&ROBOT, 0.01).unwrap();
    m.push(0.0, &[0.0f64; 12]);
    let mut q = [0.0f64; 12];
    q[2] = f64::NAN;
    m.push(0.01, &q);
    let err = check(&m.report()).unwrap_err();
    assert_eq!((err.joint, err.joint_name()), (2, "l_hip_pitch"));
    // Repeated timestamps fall back to dt.
    let mut m = JointSpeedMonitor::new(&ROBOT, 0.01).unwrap();
    m.push(1.0, &[0.0f64; 12]);
    let mut q = [0.0f64; 12];
    q[11] = 0.01;
    m.push(1.0, &q);
    let rep = m.report();
    assert!((rep.peak_speed[11] - 1.0).abs() < 1e-12 && rep.worst_joint == 11);
}

/// The random workspace of the FK(IK) round trips is mostly reachable, so those tests do
/// exercise the whole range (the unreachable rest is covered by the clamping tests).
#[test]
fn workspace_is_mostly_reachable() {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::TestRunner;
    let mut runner = TestRunner::deterministic();
    let strategy = workspace();
    let n = 2000;
    let mut reachable = 0;
    for _ in 0..n {
        let (left, p, f) = strategy.new_tree(&mut runner).unwrap().current();
        if !leg_ik(&ROBOT, side_of(left), &pose::<f64>(p), &pose::<f64>(f)).clamped() {
            reachable += 1;
        }
    }
    eprintln!("reachable: {reachable} / {n}");
    assert!(reachable * 2 > n, "only {reachable} of {n} reachable");
}

proptest! {
    /// Both legs' points and axes at once (the pelvis rotation shared) are each leg's own.
    #[test]
    fn legs_joint_axes_is_joint_axes_of_each_leg(
        p in proptest::array::uniform6(-0.5f64..0.5),
        q in proptest::array::uniform12(-1.0f32..1.0),
    ) {
        let kin = LegKinematics::<f32>::new(&Robot::reference());
        let pelvis = pose::<f32>(p);
        let both = kin.legs_joint_axes(&pelvis, &q);
        for (i, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let leg: [f32; 6] = core::array::from_fn(|j| q[6 * i + j]);
            let (pts, axes) = kin.joint_axes(side, &pelvis, &leg);
            prop_assert_eq!(both[i].1, axes);
            prop_assert_eq!(
                [both[i].0.hip, both[i].0.knee, both[i].0.ankle, both[i].0.sole],
                [pts.hip, pts.knee, pts.ankle, pts.sole]
            );
            prop_assert_eq!(
                [both[i].0.thigh_mass, both[i].0.calf_mass, both[i].0.sole_mass],
                [pts.thigh_mass, pts.calf_mass, pts.sole_mass]
            );
        }
    }
}
