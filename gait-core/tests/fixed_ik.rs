//! The fixed-point two-leg IK: its primitives against f64, the IK against `LegKinematics<f64>`,
//! FK round trips, the Table 2 walk through `FixedSampler` + fixed IK against the f64 pipeline,
//! and unreachable / absurd targets.

use gait_core::kinematics::fixed_ik::{
    atan2, atan2_fac, isqrt, joint_targets, sqrt, FixedIkReport, FixedLegKinematics, FixedPose,
};
use gait_core::kinematics::leg::{LegKinematics, Pose};
use gait_core::kinematics::pipeline;
use gait_core::maths::fixed_point::Fx;
use gait_core::robot::{JOINT_NAMES, LEG_JOINTS};
use gait_core::trajectory::fixed_sampler::FixedSampler;
use gait_core::{ForwardWalk, Model, ModelKind, Robot, Sampler, Side};
use proptest::prelude::*;
use proptest::test_runner::{RngAlgorithm, TestRng};
use std::f64::consts::PI;

const ROBOT: Robot = Robot::reference();
const FAC: f64 = (1u64 << 30) as f64;

/// A deterministic generator for the dense random sweeps (proptest's ChaCha, seeded).
fn seeded(seed: u64) -> TestRng {
    let mut s = [0u8; 32];
    s[..8].copy_from_slice(&seed.to_le_bytes());
    TestRng::from_seed(RngAlgorithm::ChaCha, &s)
}

fn fx(v: f64) -> Fx {
    Fx::saturating_from_num(v)
}

fn f(v: Fx) -> f64 {
    v.to_num::<f64>()
}

fn fixed_pose(p: [f64; 6]) -> FixedPose {
    let [x, y, z, roll, pitch, yaw] = p.map(fx);
    FixedPose::new(x, y, z, roll, pitch, yaw)
}

fn to_pose(p: &FixedPose) -> Pose<f64> {
    Pose::new(f(p.x), f(p.y), f(p.z), f(p.roll), f(p.pitch), f(p.yaw))
}

fn side_of_joint(j: usize) -> Side {
    if j < 6 {
        Side::Left
    } else {
        Side::Right
    }
}

/// Every angle inside the robot's (f64) joint limits.
fn assert_within_limits(q: &[Fx; LEG_JOINTS]) {
    for (j, v) in q.iter().enumerate() {
        let l = ROBOT.joint_limit(side_of_joint(j), j % 6);
        let v = f(*v);
        assert!(
            v >= l.min && v <= l.max,
            "{} = {v} outside [{}, {}]",
            JOINT_NAMES[j],
            l.min,
            l.max
        );
    }
}

// ---------------------------------------------------------------------------------------------
// (a) Primitives.

#[test]
fn isqrt_is_exact() {
    let check = |n: u64| {
        let r = isqrt(n) as u128;
        let n = n as u128;
        assert!(r * r <= n && (r + 1) * (r + 1) > n, "isqrt({n}) = {r}");
    };
    for n in 0..100_000u64 {
        check(n);
    }
    for e in 0..64u32 {
        let p = 1u64 << e;
        for n in [p - 1, p, p + 1] {
            check(n);
        }
    }
    check(u64::MAX);
    check(u64::MAX - 1);
    let mut rng = seeded(0x1234_5678_9abc_def1);
    for _ in 0..200_000 {
        let shift = rng.next_u64() % 64;
        check(rng.next_u64() >> shift);
        // Perfect squares and their neighbours.
        let r = rng.next_u64() >> 32;
        check(r * r);
        check((r * r).saturating_sub(1));
    }
    // The wide path (n ≥ 2³²: estimate from the top bits, one Newton step, corrections):
    // squares and their neighbours where the estimate is worst (r₀ = 2¹⁵, the bottom of its
    // range) and at the ends of u64, every operand width 33..=64 bits.
    for r in (1u64 << 16..1 << 16 | 64).chain((1u64 << 32) - 64..1 << 32) {
        for n in [r * r - 2, r * r - 1, r * r, r * r + 1, r * r + 2 * r] {
            check(n);
        }
    }
    for bits in 33..=64u32 {
        let top = 1u64 << (bits - 1);
        for _ in 0..20_000 {
            let n = top | (rng.next_u64() & (top - 1));
            check(n);
            let r = isqrt(n);
            check(r * r);
            check(r * r - 1);
        }
    }
}

#[test]
fn sqrt_fx_matches_f64() {
    let mut worst: f64 = 0.0;
    for i in 0..400_000i64 {
        let x = Fx::from_bits((i * 5_368) as i32);
        let got = f(sqrt(x));
        let want = f(x).sqrt();
        assert!(got <= want + 1e-12, "sqrt rounds down");
        worst = worst.max(want - got);
    }
    println!(
        "sqrt(Fx): worst error {worst:.2e} (resolution {:.2e})",
        1.0 / 65536.0
    );
    assert!(worst < 1.0 / 65536.0);
    assert_eq!(sqrt(Fx::from_num(-3)), Fx::ZERO);
    assert_eq!(sqrt(Fx::from_num(4)), Fx::from_num(2));
    assert_eq!(sqrt(Fx::MAX).to_num::<f64>().floor(), 181.0);
}

#[test]
fn atan2_matches_f64_over_dense_grid() {
    let mut worst_fac: f64 = 0.0;
    let mut worst_fx: f64 = 0.0;
    let mut n = 0usize;
    // Radii from 2^5 to 2^62 in steps of 2^(1/2), angles over the whole circle.
    for e2 in 10..=124 {
        let radius = 2f64.powf(e2 as f64 / 2.0);
        for k in 0..20_000 {
            let th = -PI + 2.0 * PI * (k as f64 + 0.37) / 20_000.0;
            let (y, x) = ((radius * th.sin()) as i64, (radius * th.cos()) as i64);
            let want = (y as f64).atan2(x as f64);
            let got = atan2_fac(y, x) as f64 / FAC;
            worst_fac = worst_fac.max((got - want).abs());
            let got_fx = f(atan2(y, x));
            worst_fx = worst_fx.max((got_fx - want).abs());
            n += 1;
        }
    }
    // Extreme inputs.
    let mut rng = seeded(42);
    for _ in 0..200_000 {
        let (y, x) = (
            rng.next_u64() as i64,
            rng.next_u64() as i64 >> (rng.next_u64() % 64),
        );
        let want = (y as f64).atan2(x as f64);
        worst_fac = worst_fac.max((atan2_fac(y, x) as f64 / FAC - want).abs());
    }
    for (y, x) in [
        (i64::MIN, i64::MIN),
        (i64::MAX, i64::MIN),
        (i64::MIN, i64::MAX),
        (i64::MIN, 0),
        (0, i64::MIN),
        (1, i64::MAX),
    ] {
        let want = (y as f64).atan2(x as f64);
        worst_fac = worst_fac.max((atan2_fac(y, x) as f64 / FAC - want).abs());
    }
    println!(
        "atan2 over {n} grid points + 200000 random: worst {worst_fac:.2e} rad (2^-30 rad out), \
         {worst_fx:.2e} rad (Fx out)"
    );
    assert!(worst_fac < 2e-8, "atan2_fac error {worst_fac}");
    assert!(worst_fx < 2e-5, "atan2 (Fx) error {worst_fx}");
    // Special values.
    assert_eq!(atan2_fac(0, 0), 0);
    assert_eq!(atan2_fac(0, 5), 0);
    assert!((atan2_fac(0, -5) as f64 / FAC - PI).abs() < 1e-8);
    assert!((atan2_fac(5, 0) as f64 / FAC - PI / 2.0).abs() < 1e-8);
    assert!((atan2_fac(-5, 0) as f64 / FAC + PI / 2.0).abs() < 1e-8);
    assert!((atan2_fac(7, 7) as f64 / FAC - PI / 4.0).abs() < 1e-8);
}

// ---------------------------------------------------------------------------------------------
// (b), (c) IK against the f64 IK and FK round trips.

/// A random pelvis and two feet of the workspace of tests/kinematics.rs: pelvis height
/// 0.16–0.225 m, each foot ±0.06 m (x) and ±0.04 m (y) around the point under its nominal hip
/// (in the pelvis heading), up to 0.03 m off the ground, yaw ±0.4 (pelvis) and ±0.4 relative
/// (foot), roll and pitch ±0.15 for all three (or 0 when `level`).
fn workspace(robot: &Robot, rng: &mut TestRng, level: bool) -> ([f64; 6], [f64; 6], [f64; 6]) {
    let t = |rng: &mut TestRng| {
        if level {
            0.0
        } else {
            rng.random_range(-0.15..0.15)
        }
    };
    let p: [f64; 6] = [
        rng.random_range(-0.1..0.1),
        rng.random_range(-0.1..0.1),
        rng.random_range(0.16..0.225),
        t(rng),
        t(rng),
        rng.random_range(-0.4..0.4),
    ];
    let (s, c) = p[5].sin_cos();
    let foot = |sigma: f64, rng: &mut TestRng| {
        let (lx, ly) = (
            rng.random_range(-0.06..0.06),
            sigma * robot.geometry.hip_offset_y + rng.random_range(-0.04..0.04),
        );
        [
            p[0] + c * lx - s * ly,
            p[1] + s * lx + c * ly,
            rng.random_range(0.0..0.03),
            t(rng),
            t(rng),
            p[5] + rng.random_range(-0.4..0.4),
        ]
    };
    let l = foot(1.0, rng);
    let r = foot(-1.0, rng);
    (p, l, r)
}

/// (worst joint error vs f64 IK, worst FK position error, worst FK rotation error, cases used).
fn compare_with_f64(robot: &Robot, level: bool, cases: usize, seed: u64) -> (f64, f64, f64, usize) {
    let kin = FixedLegKinematics::new(robot);
    let k64 = LegKinematics::<f64>::new(robot);
    let mut rng = seeded(seed);
    let (mut worst_q, mut worst_p, mut worst_r, mut used) = (0.0f64, 0.0f64, 0.0f64, 0);
    for _ in 0..cases {
        let (p, l, r) = workspace(robot, &mut rng, level);
        let (fp, fl, fr) = (fixed_pose(p), fixed_pose(l), fixed_pose(r));
        // The f64 IK gets exactly the fixed-point targets.
        let (pp, lp, rp) = (to_pose(&fp), to_pose(&fl), to_pose(&fr));
        let (q, rep): ([Fx; 12], FixedIkReport) = kin.legs_ik(&fp, &fl, &fr);
        let (q64, rep64) = k64.legs_ik(&pp, &lp, &rp);
        assert_within_limits(&q);
        if rep64.clamped() || rep.clamped() {
            continue;
        }
        used += 1;
        for j in 0..12 {
            let e = (f(q[j]) - q64[j]).abs();
            worst_q = worst_q.max(e);
            assert!(e < 2e-4, "{}: {} vs {}", JOINT_NAMES[j], f(q[j]), q64[j]);
        }
        for (side, target) in [(Side::Left, &lp), (Side::Right, &rp)] {
            let i = side.index();
            let leg: [f64; 6] = core::array::from_fn(|j| f(q[6 * i + j]));
            let back = k64.fk(side, &pp, &leg);
            let ep = (back.x - target.x)
                .abs()
                .max((back.y - target.y).abs())
                .max((back.z - target.z).abs());
            let (ra, rb) = (back.rotation(), target.rotation());
            let er = (0..9)
                .map(|k| (ra[k / 3][k % 3] - rb[k / 3][k % 3]).abs())
                .fold(0.0, f64::max);
            worst_p = worst_p.max(ep);
            worst_r = worst_r.max(er);
            assert!(ep < 5e-4, "FK of the fixed IK off by {ep} m");
        }
    }
    (worst_q, worst_p, worst_r, used)
}

#[test]
fn fixed_ik_matches_f64_ik_on_random_reachable_targets() {
    for robot in gait_core::robot::ROBOTS {
        for (level, seed) in [(true, 7u64), (false, 11u64)] {
            let (q, p, r, used) = compare_with_f64(&robot, level, 30_000, seed);
            println!(
                "{}: {} targets, {used} reachable: joints within {q:.2e} rad of the f64 IK, \
                 FK(f64) of the fixed angles within {p:.2e} m / {r:.2e} (rotation entries)",
                robot.name,
                if level { "level" } else { "tilted" }
            );
            assert!(used > 20_000, "too few reachable cases: {used}");
            assert!(q < 2e-4 && p < 5e-4);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// (d) The Table 2 walk: FixedSampler + fixed IK against the f64 sampler + f64 IK.

#[test]
fn table2_walk_fixed_pipeline_matches_f64_pipeline() {
    let walk = ForwardWalk::table2();
    let kin = FixedLegKinematics::new(&ROBOT);
    let k64 = LegKinematics::<f64>::new(&ROBOT);
    for kind in ModelKind::ALL {
        let m32 = Model::<f32>::new(kind, &ROBOT, walk.z_c).unwrap();
        let plan32 = walk.plan::<f32, 32>(&ROBOT, walk.params(m32)).unwrap();
        let mut fxs = FixedSampler::new(plan32, 0.005).unwrap();
        let m64 = Model::<f64>::new(kind, &ROBOT, walk.z_c).unwrap();
        let plan64 = walk.plan::<f64, 32>(&ROBOT, walk.params(m64)).unwrap();
        let mut reference = Sampler::new(plan64, 0.005).unwrap();
        let (mut worst, mut worst_ik, mut n) = (0.0f64, 0.0f64, 0usize);
        while !reference.is_done() {
            let a = fxs.next(0);
            let b = reference.next(0.0);
            assert_eq!(a.time_ns, b.time_ns);
            let (q, rep) = joint_targets(&kin, &a);
            let (q64, rep64) = pipeline::joint_targets(&k64, &b);
            assert!(
                !rep.clamped(),
                "fixed IK clamped at {} ns: {rep:?}",
                a.time_ns
            );
            assert!(!rep64.clamped());
            assert_within_limits(&q);
            // The same fixed-point sample through the f64 IK: the IK's own share of the error.
            let pelvis = gait_core::kinematics::fixed_ik::pelvis_pose(&a);
            let feet = a
                .feet
                .map(|ft| gait_core::kinematics::fixed_ik::foot_pose(&ft));
            let (q_same, _) =
                k64.legs_ik(&to_pose(&pelvis), &to_pose(&feet[0]), &to_pose(&feet[1]));
            for j in 0..12 {
                let e = (f(q[j]) - q64[j]).abs();
                assert!(e < 1e-3, "{kind:?} {} off by {e} rad", JOINT_NAMES[j]);
                worst = worst.max(e);
                worst_ik = worst_ik.max((f(q[j]) - q_same[j]).abs());
            }
            n += 1;
        }
        println!(
            "{kind:?}: {n} samples, fixed sampler + fixed IK vs f64 pipeline: {worst:.2e} rad; \
             fixed IK vs f64 IK on the same samples: {worst_ik:.2e} rad"
        );
        assert!(worst_ik < 2e-4);
    }
}

// ---------------------------------------------------------------------------------------------
// (e) Unreachable and absurd targets.

#[test]
fn unreachable_and_absurd_targets_are_clamped_and_reported() {
    let kin = FixedLegKinematics::new(&ROBOT);
    let z = Fx::ZERO;
    let level = |x: f64, y: f64, zz: f64| FixedPose::level(fx(x), fx(y), fx(zz), z);
    let pelvis = level(0.0, 0.0, 0.2);

    // Foot 1 m below the hip: out of reach by ≈ 1.03 − 0.2 m, straight-ish leg, not invalid.
    let (q, rep) = kin.legs_ik(&pelvis, &level(0.0, 0.045, -0.8), &level(0.0, -0.045, 0.0));
    assert_within_limits(&q);
    let want = 1.0 - 0.03 - f(kin.max_reach());
    assert!((f(rep.reach_deficit[0]) - want).abs() < 1e-4, "{rep:?}");
    assert!(rep.reach_deficit[1] == z && !rep.invalid_input && rep.clamped());
    assert!(
        (f(q[3]) - 0.02).abs() < 1e-4,
        "knee stays bent 0.02 rad: {}",
        f(q[3])
    );

    // Foot at the hip (zero distance): the minimum reach, deficit = d_min.
    let (q, rep) = kin.legs_ik(&pelvis, &level(0.0, 0.045, 0.17), &level(0.0, -0.045, 0.17));
    assert_within_limits(&q);
    assert!((f(rep.reach_deficit[0]) - f(kin.min_reach())).abs() < 1e-4);
    assert!(rep.clamped());

    // Positions beyond ±1000 m: clamped and flagged; Fx extremes everywhere.
    let extremes = [
        Fx::MIN,
        Fx::MAX,
        Fx::ZERO,
        Fx::DELTA,
        -Fx::DELTA,
        fx(1000.5),
        fx(-999.0),
    ];
    let mut count = 0;
    for &a in &extremes {
        for &b in &extremes {
            for &c in &extremes {
                let p = FixedPose::new(a, b, c, b, c, a);
                let l = FixedPose::new(c, a, b, a, a, c);
                let r = FixedPose::new(b, c, a, c, b, b);
                let (q, rep) = kin.legs_ik(&p, &l, &r);
                assert_within_limits(&q);
                let big = |v: Fx| f(v).abs() > 1000.0;
                let any_big = [a, b, c].iter().any(|v| big(*v));
                assert_eq!(rep.invalid_input, any_big, "{a} {b} {c}");
                assert!(rep.reach_deficit.iter().all(|d| *d >= z));
                count += 1;
            }
        }
    }
    assert_eq!(count, 343);

    // Beside the body, above the pelvis, behind: within limits and flagged as limited or short.
    for foot in [
        level(0.0, 0.4, 0.1),
        level(0.0, 0.045, 0.4),
        level(-0.15, 0.045, 0.1),
        level(0.15, 0.1, 0.0),
        FixedPose::level(fx(0.0), fx(0.045), fx(0.05), fx(3.0)),
    ] {
        let (q, rep) = kin.legs_ik(&pelvis, &foot, &level(0.0, -0.045, 0.0));
        assert_within_limits(&q);
        assert!(rep.clamped(), "{foot:?}: {rep:?}");
        assert!(rep.limited & 0x3f != 0 || rep.reach_deficit[0] > z);
        assert_eq!(rep.limited >> 6, 0, "right leg untouched: {rep:?}");
    }
}

/// Outside the workspace (feet anywhere within 0.4 m of the pelvis, any angles): the fixed IK
/// agrees with the f64 IK on which joints it clamps and, where both clamp the same joints and
/// no hip-yaw/pitch angle is near ±π (where a branch cut sends a clamp to the other limit),
/// on the angles.
#[test]
fn clamped_targets_agree_with_f64() {
    let kin = FixedLegKinematics::new(&ROBOT);
    let k64 = LegKinematics::<f64>::new(&ROBOT);
    let mut rng = seeded(99);
    let (mut same, mut worst, mut total) = (0usize, 0.0f64, 0usize);
    for _ in 0..20_000 {
        let p = [0.0, 0.0, 0.2, 0.0, 0.0, rng.random_range(-1.0..1.0)];
        let foot = |rng: &mut TestRng| {
            [
                rng.random_range(-0.4..0.4),
                rng.random_range(-0.4..0.4),
                rng.random_range(-0.2..0.4),
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(-1.5..1.5),
            ]
        };
        let (l, r) = (foot(&mut rng), foot(&mut rng));
        let (fp, fl, fr) = (fixed_pose(p), fixed_pose(l), fixed_pose(r));
        let (q, rep) = kin.legs_ik(&fp, &fl, &fr);
        let (q64, rep64) = k64.legs_ik(&to_pose(&fp), &to_pose(&fl), &to_pose(&fr));
        assert_within_limits(&q);
        for i in 0..2 {
            let d = (f(rep.reach_deficit[i]) - rep64.reach_deficit[i]).abs();
            assert!(
                d < 8e-6,
                "reach deficit {} vs {}",
                f(rep.reach_deficit[i]),
                rep64.reach_deficit[i]
            );
        }
        total += 1;
        if rep.limited == rep64.limited {
            same += 1;
            let e = (0..12)
                .map(|j| (f(q[j]) - q64[j]).abs())
                .fold(0.0, f64::max);
            worst = worst.max(e);
        }
    }
    println!("clamped targets: same limited bits in {same}/{total}, angles within {worst:.2e} rad");
    assert!(same as f64 > 0.995 * total as f64);
    assert!(worst < 2e-4, "{worst}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 3000, ..ProptestConfig::default() })]

    /// Any bit patterns whatsoever: angles within the limits, deficits ≥ 0, invalid_input
    /// exactly when a position is beyond ±1000 m.
    #[test]
    fn any_input_stays_within_limits(
        p in proptest::array::uniform6(any::<i32>()),
        l in proptest::array::uniform6(any::<i32>()),
        r in proptest::array::uniform6(any::<i32>()),
    ) {
        let kin = FixedLegKinematics::new(&ROBOT);
        let pose = |b: [i32; 6]| {
            let [x, y, z, ro, pi, ya] = b.map(Fx::from_bits);
            FixedPose::new(x, y, z, ro, pi, ya)
        };
        let (q, rep) = kin.legs_ik(&pose(p), &pose(l), &pose(r));
        assert_within_limits(&q);
        prop_assert!(rep.reach_deficit.iter().all(|d| *d >= Fx::ZERO));
        let big = |b: &[i32; 6]| b[..3].iter().any(|v| (*v as i64).abs() > 1000 << 16);
        prop_assert_eq!(rep.invalid_input, big(&p) || big(&l) || big(&r));
    }
}
