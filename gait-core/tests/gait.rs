//! Scenario and property tests of the gait generator against independent numbers: eq 4 by hand,
//! the model ODE by finite differences, RK4 integration, f32 against f64.

use gait_core::model::{model_constants, Model, ModelKind};
use gait_core::trajectory::com::ComSegment;
use gait_core::trajectory::plan::{
    Footstep, ForwardWalk, GaitParams, Place, Plan, SwingShape, Timing,
};
use gait_core::trajectory::sampler::{GaitSample, Sampler, Stage, SupportPhase};
use gait_core::trajectory::zmp::ZmpShape;
use gait_core::{GaitError, Real, Robot, Side};
use proptest::prelude::*;

const CAP: usize = 64;

fn table2_sampler<R: Real>(kind: ModelKind, dt: f64) -> Sampler<R, CAP> {
    let plan = ForwardWalk::table2()
        .model_plan::<R, CAP>(&Robot::reference(), kind)
        .expect("plan");
    Sampler::new(plan, dt).expect("sampler")
}

fn run<R: Real>(mut s: Sampler<R, CAP>) -> Vec<GaitSample<R>> {
    let mut out = Vec::new();
    while !s.is_done() {
        out.push(s.next(R::zero()));
        assert!(out.len() < 1_000_000, "sampler never finished");
    }
    out.push(s.next(R::zero()));
    out
}

#[test]
fn tlipfm_constants_match_eq4_by_hand() {
    // Seed 000 Table 1 / reference robot: M_u 3.05, m_t 0.2, m_c = 0.5 + 0.25, l_u 0.09, z_c 0.217.
    let (mu, mt, mc, lu, zc, g) = (3.05, 0.2, 0.75, 0.09, 0.217, 9.80665);
    let c2 = mu * zc + mu * lu + 9.0 * mt * zc / 16.0 + mc * zc / 16.0;
    let t2 = c2 / ((mu + 3.0 * mt / 4.0 + mc / 4.0) * g);
    let m = Model::<f64>::new(ModelKind::Tlipfm, &Robot::reference(), zc).unwrap();
    assert!(
        (m.t_tf - t2.sqrt()).abs() / t2.sqrt() < 1e-6,
        "T_TF {} vs {}",
        m.t_tf,
        t2.sqrt()
    );
    assert!((m.c_tau() - c2.sqrt()).abs() / c2.sqrt() < 1e-6);
    assert!((m.inv_c_tau_sq - 1.0 / c2).abs() * c2 < 1e-6);
    // The numbers themselves (hand arithmetic): C_τ² = 0.970934375, T_TF = 0.170962 s.
    assert!((c2 - 0.970_934_375).abs() < 1e-12, "{c2}");
    assert!((m.t_tf - 0.170_962).abs() < 1e-5, "{}", m.t_tf);
    // The unstable mode grows e^{T/T_TF} ≈ 42 per Table 2 step (ERRATA).
    let growth = (0.64 / m.t_tf).exp();
    assert!((41.0..44.0).contains(&growth), "{growth}");
    // f32 model agrees.
    let m32 = Model::<f32>::new(ModelKind::Tlipfm, &Robot::reference(), zc).unwrap();
    assert!(((m32.t_tf as f64) - m.t_tf).abs() / m.t_tf < 1e-6);
}

#[test]
fn tlipfm_reduces_to_lipm() {
    let mut r = Robot::reference();
    r.masses.thigh = 0.0;
    r.masses.calf = 0.0;
    r.masses.sole = 0.0;
    r.masses.upper_body_height = 0.0;
    let (c_t, t_t) = model_constants(ModelKind::Tlipfm, &r, 0.217).unwrap();
    let (c_l, t_l) = model_constants(ModelKind::Lipm, &r, 0.217).unwrap();
    assert!((c_t - c_l).abs() / c_l < 1e-12);
    assert!((t_t - t_l).abs() / t_l < 1e-12);
    assert!((t_l - 0.217 / 9.80665).abs() < 1e-12, "LIPM T² = z_c/g");
}

#[test]
fn dlipm_constants_by_hand() {
    // Upper body 3.05 at (x, z_c), support leg 0.95 at (x/2, z_c/2).
    let (mu, ml, zc, g) = (3.05, 0.95, 0.217, 9.80665);
    let c2 = mu * zc + ml * zc / 4.0;
    let t2 = c2 / ((mu + ml / 2.0) * g);
    let (c, t) = model_constants(ModelKind::Dlipm, &Robot::reference(), zc).unwrap();
    assert!((c - c2).abs() < 1e-12 && (t - t2).abs() < 1e-12);
}

/// Finite-difference residual of the model ODE on every sample whose ±h neighbourhood lies in
/// the same segment. Returns the largest residual, m/s².
fn ode_residual(mut s: Sampler<f64, CAP>, h: f64) -> f64 {
    let mut worst: f64 = 0.0;
    let omega = s.plan().params().model.omega;
    while !s.is_done() {
        let seg: ComSegment<f64> = *s.segment();
        let local = (s.now_ns() - s.segment_start_ns()) as f64 * 1e-9;
        let _ = s.next(0.0);
        if local - h < 0.0 || local + h > seg.duration {
            continue;
        }
        let x = |t: f64| seg.eval(omega, t).0;
        let (xm, x0, xp) = (x(local - h), x(local), x(local + h));
        let p = seg.zmp(local);
        for i in 0..2 {
            let acc = (xp[i] - 2.0 * x0[i] + xm[i]) / (h * h);
            let rhs = omega * omega * (x0[i] - p[i]);
            worst = worst.max((acc - rhs).abs());
        }
    }
    worst
}

#[test]
fn table2_com_satisfies_the_model_ode() {
    for kind in ModelKind::ALL {
        let r = ode_residual(table2_sampler::<f64>(kind, 0.005), 1e-4);
        assert!(r <= 1e-6, "{kind:?}: ODE residual {r} m/s²");
    }
}

/// Checks position/velocity continuity at every segment change and returns the largest jump.
fn boundary_jumps(mut s: Sampler<f64, CAP>) -> (f64, f64) {
    let omega = s.plan().params().model.omega;
    let (mut dx, mut dv): (f64, f64) = (0.0, 0.0);
    let mut prev = (*s.segment(), s.stage());
    while !s.is_done() {
        let _ = s.next(0.0);
        let cur = (*s.segment(), s.stage());
        if cur.0 != prev.0 && cur.1 != Stage::Done {
            let (x1, v1) = prev.0.eval(omega, prev.0.duration);
            let (x2, v2) = cur.0.eval(omega, 0.0);
            for i in 0..2 {
                dx = dx.max((x1[i] - x2[i]).abs());
                dv = dv.max((v1[i] - v2[i]).abs());
            }
        }
        prev = cur;
    }
    (dx, dv)
}

#[test]
fn table2_com_is_continuous_and_starts_and_ends_at_rest() {
    for kind in ModelKind::ALL {
        let (dx, dv) = boundary_jumps(table2_sampler::<f64>(kind, 0.005));
        assert!(dx < 1e-12 && dv < 1e-10, "{kind:?}: jumps {dx} m, {dv} m/s");
        let samples = run(table2_sampler::<f64>(kind, 0.005));
        let first = samples.first().unwrap();
        let last = samples.last().unwrap();
        let speed = |s: &GaitSample<f64>| s.com_vel[0].hypot(s.com_vel[1]);
        assert!(speed(first) < 1e-4, "{kind:?} start speed {}", speed(first));
        assert!(speed(last) < 1e-4, "{kind:?} end speed {}", speed(last));
        // Over the start and end positions: between the feet, 13·S_L forward at the end.
        assert!(first.com[0].abs() < 1e-9 && first.com[1].abs() < 1e-9);
        assert!(
            (last.com[0] - 13.0 * 0.02).abs() < 1e-4 && last.com[1].abs() < 1e-4,
            "{:?}",
            last.com
        );
        assert_eq!(last.steps_done, 14);
        // The walk is bounded: the CoM never leaves a band around the footprints.
        for s in &samples {
            assert!(
                s.com[0] > -0.03 && s.com[0] < 0.29 && s.com[1].abs() < 0.05,
                "{:?}",
                s.com
            );
        }
    }
}

#[test]
fn table2_timeline_and_zmp_knots_match_eqs_10_11() {
    let samples = run(table2_sampler::<f64>(ModelKind::Tlipfm, 0.001));
    let walk = ForwardWalk::table2();
    let t0 = (walk.lead_in * 1e9) as u64;
    let at = |t: f64| {
        let ns = t0 + (t * 1e9).round() as u64;
        samples.iter().find(|s| s.time_ns == ns).copied().unwrap()
    };
    for n in 1..13usize {
        let (px, py) = walk.support_location(n);
        let base = n as f64 * walk.period;
        // eq 10 (with the erratum), eq 11.
        let checks = [
            (0.0, px - walk.d1, 0.0),
            (walk.t1, px - walk.a, py),
            (walk.t2, px + walk.a, py),
        ];
        for (t, ex, ey) in checks {
            let s = at(base + t);
            assert!(
                (s.zmp[0] - ex).abs() < 1e-9 && (s.zmp[1] - ey).abs() < 1e-9,
                "step {n} t {t}: {:?}",
                s.zmp
            );
        }
        let mid_ssp = at(base + 0.5 * (walk.t1 + walk.t2));
        let support = if py > 0.0 { Side::Left } else { Side::Right };
        assert_eq!(mid_ssp.phase, SupportPhase::Single(support));
        let swing = if py > 0.0 { Side::Right } else { Side::Left };
        assert_eq!(mid_ssp.phase.swing(), Some(swing));
        assert_eq!(at(base + 0.05).phase, SupportPhase::Double);
        assert_eq!(at(base + 0.05).phase.swing(), None);
    }
    assert_eq!(samples[0].phase, SupportPhase::Standing);
    assert_eq!(samples[0].phase.swing(), None);
    // 14 steps of 0.64 s = 8.96 s of walking (seed 000 Figs. 14-16).
    let walking = samples
        .iter()
        .filter(|s| s.phase != SupportPhase::Standing)
        .count();
    assert_eq!(walking, 8960);
}

/// RK4 over each segment from the closed form's state at the segment start.
#[test]
fn rk4_integration_agrees_with_the_closed_form() {
    let mut s = table2_sampler::<f64>(ModelKind::Tlipfm, 0.005);
    let omega = s.plan().params().model.omega;
    let mut segs: Vec<ComSegment<f64>> = vec![*s.segment()];
    while !s.is_done() {
        let _ = s.next(0.0);
        if *s.segment() != *segs.last().unwrap() && s.stage() != Stage::Done {
            segs.push(*s.segment());
        }
    }
    assert_eq!(segs.len(), 14 * 3 + 2);
    for seg in &segs {
        let (x0, v0) = seg.eval(omega, 0.0);
        for i in 0..2 {
            let acc = |t: f64, x: f64| omega * omega * (x - (seg.p0[i] + seg.slope[i] * t));
            let (mut x, mut v, mut t) = (x0[i], v0[i], 0.0);
            let n = 2000;
            let h = seg.duration / n as f64;
            for _ in 0..n {
                let (k1x, k1v) = (v, acc(t, x));
                let (k2x, k2v) = (v + 0.5 * h * k1v, acc(t + 0.5 * h, x + 0.5 * h * k1x));
                let (k3x, k3v) = (v + 0.5 * h * k2v, acc(t + 0.5 * h, x + 0.5 * h * k2x));
                let (k4x, k4v) = (v + h * k3v, acc(t + h, x + h * k3x));
                x += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
                v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
                t += h;
            }
            let (xe, ve) = seg.eval(omega, seg.duration);
            assert!((x - xe[i]).abs() < 1e-9, "rk4 x {x} vs {}", xe[i]);
            assert!((v - ve[i]).abs() < 1e-8, "rk4 v {v} vs {}", ve[i]);
        }
    }
}

#[test]
fn f32_agrees_with_f64_over_the_whole_walk() {
    for kind in ModelKind::ALL {
        let a = run(table2_sampler::<f32>(kind, 0.005));
        let b = run(table2_sampler::<f64>(kind, 0.005));
        assert_eq!(a.len(), b.len());
        let mut worst: f64 = 0.0;
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.time_ns, y.time_ns);
            assert_eq!(x.phase, y.phase);
            for i in 0..2 {
                worst = worst.max((x.com[i] as f64 - y.com[i]).abs());
                worst = worst.max((x.zmp[i] as f64 - y.zmp[i]).abs());
            }
            for f in 0..2 {
                worst = worst.max((x.feet[f].x as f64 - y.feet[f].x).abs());
                worst = worst.max((x.feet[f].z as f64 - y.feet[f].z).abs());
            }
        }
        println!("{kind:?}: f32 vs f64 max difference {:.3e} m", worst);
        assert!(worst < 1e-4, "{kind:?}: f32 off by {worst} m");
    }
}

#[test]
fn cycloid_stride_height_and_zero_end_velocity() {
    let dt = 0.001;
    let samples = run(table2_sampler::<f64>(ModelKind::Tlipfm, dt));
    let walk = ForwardWalk::table2();
    for n in 0..14usize {
        let swing = if n % 2 == 0 { 0 } else { 1 }; // left swings first (S_first = −1)
        let steps: Vec<_> = samples
            .iter()
            .filter(|s| s.steps_done == n as u32 && matches!(s.phase, SupportPhase::Single(_)))
            .collect();
        assert_eq!(steps.len(), 340, "single support lasts T_SSP = 0.34 s");
        let first = steps.first().unwrap().feet[swing];
        let last = steps.last().unwrap().feet[swing];
        let stride = last.x - first.x;
        let want = if n == 0 || n == 13 {
            walk.step_length
        } else {
            2.0 * walk.step_length
        };
        assert!((stride - want).abs() < 1e-3, "step {n}: stride {stride}");
        let peak = steps.iter().map(|s| s.feet[swing].z).fold(0.0, f64::max);
        assert!((peak - walk.h_z).abs() < 1e-5, "peak {peak}");
        // Velocity at lift-off and touch-down from the first/last two samples: O(dt²) only.
        let v0 = (steps[1].feet[swing].x - steps[0].feet[swing].x) / dt;
        let k = steps.len();
        let v1 = (steps[k - 1].feet[swing].z - steps[k - 2].feet[swing].z) / dt;
        assert!(v0.abs() < 1e-3 && v1.abs() < 0.02, "v0 {v0} vz1 {v1}");
        // The support foot never moves.
        let sup = 1 - swing;
        assert!(steps
            .iter()
            .all(|s| s.feet[sup].x == first_support(&steps, sup) && s.feet[sup].z == 0.0));
    }
}

fn first_support(steps: &[&GaitSample<f64>], sup: usize) -> f64 {
    steps[0].feet[sup].x
}

#[test]
fn constant_tau_shifts_the_com_forward_and_stays_bounded() {
    // ERRATA: constant τ > 0 shifts the bounded CoM forward by τ·T_TF²/C_τ².
    let tau = 0.3; // N·m
    let mut a = table2_sampler::<f64>(ModelKind::Tlipfm, 0.005);
    let mut b = table2_sampler::<f64>(ModelKind::Tlipfm, 0.005);
    let m = a.plan().params().model;
    let shift = tau * m.t_tf * m.t_tf * m.inv_c_tau_sq;
    let mut last = 0.0;
    while !a.is_done() {
        let sa = a.next(tau);
        let sb = b.next(0.0);
        let d = sa.com[0] - sb.com[0];
        assert!(
            d >= -1e-12 && d <= shift + 1e-12,
            "offset {d} outside [0, {shift}]"
        );
        assert_eq!(sa.com[1], sb.com[1], "τ does not act laterally (eq 4)");
        last = d;
    }
    assert!(
        (last - shift).abs() < 1e-9,
        "settled offset {last} vs {shift}"
    );
}

#[test]
fn random_forward_backward_tau_never_diverges() {
    // Seed 000 Fig. 8(b): random forward and backward angular momentum.
    let mut a = table2_sampler::<f32>(ModelKind::Tlipfm, 0.005);
    let mut b = table2_sampler::<f32>(ModelKind::Tlipfm, 0.005);
    let m = a.plan().params().model;
    let tau_max = 1.5f32;
    let bound = tau_max * m.tau_to_offset;
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let mut worst = 0.0f32;
    while !a.is_done() {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        let tau = ((rng >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * tau_max;
        let sa = a.next(tau);
        let sb = b.next(0.0);
        assert!(sa.is_finite());
        worst = worst.max((sa.com[0] - sb.com[0]).abs());
    }
    assert!(worst <= bound * 1.0001, "{worst} > {bound}");
    // Non-finite τ never reaches the CoM.
    let mut c = table2_sampler::<f32>(ModelKind::Tlipfm, 0.005);
    for t in [f32::NAN, f32::INFINITY, -f32::INFINITY, 1e30] {
        assert!(c.next(t).is_finite());
    }
}

#[test]
fn steering_step_by_step_matches_the_whole_plan() {
    // A host appends each step two steps ahead; the walk must equal the planned one closely.
    let robot = Robot::reference();
    let walk = ForwardWalk::table2();
    let model = Model::<f64>::new(ModelKind::Tlipfm, &robot, walk.z_c).unwrap();
    let full = walk.plan::<f64, CAP>(&robot, walk.params(model)).unwrap();
    let steps: Vec<Footstep<f64>> = (0..full.len())
        .map(|i| full.step(i).unwrap().step)
        .collect();
    let mut queued = Plan::<f64, 4>::new(
        &robot,
        walk.params(model),
        full.start_feet()[0],
        full.start_feet()[1],
    )
    .unwrap();
    for st in steps.iter().take(3) {
        queued.push(*st).unwrap();
    }
    let mut a = Sampler::new(full, 0.005).unwrap();
    let mut b = Sampler::new(queued, 0.005).unwrap();
    let mut next = 3;
    let mut worst: f64 = 0.0;
    let mut prev_v: Option<[f64; 2]> = None;
    while !a.is_done() {
        if next < steps.len() && b.plan().len() < 3 {
            b.push_step(steps[next]).unwrap();
            next += 1;
        }
        let sa = a.next(0.0);
        let sb = b.next(0.0);
        worst = worst
            .max((sa.com[0] - sb.com[0]).abs())
            .max((sa.com[1] - sb.com[1]).abs());
        if let Some(v) = prev_v {
            // No velocity jump beyond what the model's acceleration allows in one sample.
            assert!((sb.com_vel[1] - v[1]).abs() < 0.02, "velocity jump");
        }
        prev_v = Some(sb.com_vel);
    }
    assert!(worst < 2e-4, "step-by-step walk differs by {worst} m");
    assert_eq!(b.push_step(steps[0]), Err(GaitError::WalkEnded));
}

fn params(t1: f64, t2: f64, period: f64) -> GaitParams<f64> {
    let robot = Robot::reference();
    GaitParams {
        model: Model::new(ModelKind::Tlipfm, &robot, 0.217).unwrap(),
        timing: Timing { t1, t2, period },
        zmp: ZmpShape::Natural {
            d1: 0.01,
            d2: 0.01,
            a: 0.004,
        },
        swing: SwingShape::Cycloid {
            height: 0.03,
            width: 0.0,
        },
        lead_in: 1.6,
        lead_out: 1.6,
    }
}

#[test]
fn every_error_variant_is_reported() {
    let robot = Robot::reference();
    let l = Place::new(0.0, 0.045, 0.0);
    let r = Place::new(0.0, -0.045, 0.0);
    let p = |pp: GaitParams<f64>| Plan::<f64, 4>::new(&robot, pp, l, r).err();
    assert_eq!(p(params(0.3, 0.2, 0.64)), Some(GaitError::BadPhaseTimes));
    assert_eq!(p(params(0.15, 0.7, 0.64)), Some(GaitError::BadPhaseTimes));
    assert_eq!(
        p(params(0.15, 0.49, -1.0)),
        Some(GaitError::NonPositivePeriod)
    );
    assert_eq!(p(params(0.15, 0.49, 5.0)), Some(GaitError::PeriodTooLong));
    assert_eq!(p(params(f64::NAN, 0.49, 0.64)), Some(GaitError::NonFinite));
    let mut off = params(0.15, 0.49, 0.64);
    off.zmp = ZmpShape::Natural {
        d1: 0.01,
        d2: 0.01,
        a: 0.06,
    };
    assert_eq!(p(off), Some(GaitError::ZmpOffsetOffSole));
    let mut neg = params(0.15, 0.49, 0.64);
    neg.swing = SwingShape::Cycloid {
        height: -0.01,
        width: 0.0,
    };
    assert_eq!(p(neg), Some(GaitError::NonPositiveLength));
    // Robot description errors.
    let mut bad = robot;
    bad.masses.upper_body = 0.0;
    assert_eq!(
        Model::<f64>::new(ModelKind::Tlipfm, &bad, 0.217).err(),
        Some(GaitError::NonPositiveMass)
    );
    assert_eq!(
        Model::<f64>::new(ModelKind::Tlipfm, &robot, -0.2).err(),
        Some(GaitError::NonPositiveLength)
    );
    bad = robot;
    bad.gravity = 0.0;
    assert_eq!(bad.validate(), Err(GaitError::NonPositiveParameter));
    bad = robot;
    bad.joint_limits[3].min = 3.0;
    assert_eq!(bad.validate(), Err(GaitError::BadJointLimit));
    bad = robot;
    bad.geometry.thigh = f64::INFINITY;
    assert_eq!(bad.validate(), Err(GaitError::NonFinite));
    // Footsteps.
    let mut plan = Plan::<f64, 2>::new(&robot, params(0.15, 0.49, 0.64), l, r).unwrap();
    let far = Footstep {
        side: Side::Left,
        place: Place::new(0.5, 0.045, 0.0),
    };
    assert_eq!(plan.push(far), Err(GaitError::StepOutOfReach));
    let crossing = Footstep {
        side: Side::Left,
        place: Place::new(0.02, -0.08, 0.0),
    };
    assert_eq!(plan.push(crossing), Err(GaitError::StepOutOfReach));
    let nan = Footstep {
        side: Side::Left,
        place: Place::new(f64::NAN, 0.045, 0.0),
    };
    assert_eq!(plan.push(nan), Err(GaitError::NonFinite));
    plan.push(Footstep {
        side: Side::Left,
        place: Place::new(0.02, 0.045, 0.0),
    })
    .unwrap();
    plan.push(Footstep {
        side: Side::Right,
        place: Place::new(0.04, -0.045, 0.0),
    })
    .unwrap();
    let third = Footstep {
        side: Side::Left,
        place: Place::new(0.06, 0.045, 0.0),
    };
    assert_eq!(plan.push(third), Err(GaitError::CapacityExceeded));
    // Sampler.
    assert_eq!(
        Sampler::new(plan.clone(), 0.0001).err(),
        Some(GaitError::BadSampleTime)
    );
    assert_eq!(
        Sampler::new(plan.clone(), f64::NAN).err(),
        Some(GaitError::NonFinite)
    );
    let short = Plan::<f64, 2>::new(&robot, params(0.002, 0.49, 0.64), l, r).unwrap();
    assert_eq!(
        Sampler::new(short, 0.005).err(),
        Some(GaitError::BadSampleTime)
    );
    // Forward walks.
    let mut w = ForwardWalk::table2();
    w.steps = 0;
    let m = Model::new(ModelKind::Tlipfm, &robot, 0.217).unwrap();
    assert_eq!(
        w.plan::<f64, 16>(&robot, w.params(m)).err(),
        Some(GaitError::EmptyPlan)
    );
    w = ForwardWalk::table2();
    assert_eq!(
        w.plan::<f64, 8>(&robot, w.params(m)).err(),
        Some(GaitError::CapacityExceeded)
    );
    w.s_first = 0;
    assert_eq!(
        w.plan::<f64, 16>(&robot, w.params(m)).err(),
        Some(GaitError::BadStartFoot)
    );
}

/// A plan from random (forward, width, turn) steps relative to the support foot, alternating
/// feet; steps the plan refuses (out of reach) are skipped.
fn random_plan(robot: &Robot, pp: GaitParams<f64>, steps: &[(f64, f64, f64)]) -> Plan<f64, CAP> {
    let start = (Place::new(0.0, 0.045, 0.0), Place::new(0.0, -0.045, 0.0));
    let mut plan = Plan::<f64, CAP>::new(robot, pp, start.0, start.1).unwrap();
    let mut side = Side::Left;
    for &(fwd, width, turn) in steps {
        let sup = plan.end_feet()[side.other().index()];
        let yaw = sup.yaw + turn;
        let (s, c) = yaw.sin_cos();
        let lat = side.sign() * width;
        let to = Place::new(sup.x + c * fwd - s * lat, sup.y + s * fwd + c * lat, yaw);
        if plan.push(Footstep { side, place: to }).is_ok() {
            side = side.other();
        }
    }
    plan
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Random plans: forward/backward, sideways and turning steps with random timing.
    #[test]
    fn random_plans_are_bounded_continuous_and_solve_the_ode(
        steps in prop::collection::vec((-0.05f64..0.08, 0.075f64..0.11, -0.3f64..0.3), 1..10),
        t1 in 0.05f64..0.3, ssp in 0.15f64..0.5, t3 in 0.05f64..0.3,
        kind in prop::sample::select(ModelKind::ALL.to_vec()),
        continuous in any::<bool>(),
    ) {
        let robot = Robot::reference();
        let mut pp = params(t1, t1 + ssp, t1 + ssp + t3);
        pp.model = Model::new(kind, &robot, 0.217).unwrap();
        if continuous {
            pp.zmp = ZmpShape::Continuous { b: 0.01 };
            pp.swing = SwingShape::Sinusoid { height: 0.02 };
        }
        let plan = random_plan(&robot, pp, &steps);
        let s = Sampler::new(plan.clone(), 0.005).unwrap();
        let r = ode_residual(s.clone(), 1e-4);
        prop_assert!(r <= 1e-6, "residual {}", r);
        let (dx, dv) = boundary_jumps(s.clone());
        prop_assert!(dx < 1e-12 && dv < 1e-9, "jumps {} {}", dx, dv);
        let samples = run(s);
        let first = samples.first().unwrap();
        let last = samples.last().unwrap();
        prop_assert!(first.com_vel[0].hypot(first.com_vel[1]) < 1e-4);
        prop_assert!(last.com_vel[0].hypot(last.com_vel[1]) < 1e-4);
        let end = plan.end_zmp();
        prop_assert!((last.com[0] - end[0]).abs() < 1e-4 && (last.com[1] - end[1]).abs() < 1e-4);
        prop_assert!(samples.iter().all(|s| s.is_finite()));
    }
}

#[test]
fn fixed_point_agrees_with_f64_over_the_whole_walk() {
    use gait_core::trajectory::fixed_sampler::FixedSampler;
    for kind in ModelKind::ALL {
        let robot = Robot::reference();
        let walk = ForwardWalk::table2();
        let model = Model::<f32>::new(kind, &robot, walk.z_c).unwrap();
        let plan = walk.plan::<f32, CAP>(&robot, walk.params(model)).unwrap();
        let mut fxs = FixedSampler::new(plan, 0.005).unwrap();
        let mut reference = table2_sampler::<f64>(kind, 0.005);
        let (mut worst, mut worst_v): (f64, f64) = (0.0, 0.0);
        let mut n = 0;
        while !reference.is_done() {
            let a = fxs.next(0);
            let b = reference.next(0.0);
            assert_eq!(a.time_ns, b.time_ns);
            assert_eq!(a.phase, b.phase);
            for i in 0..2 {
                worst = worst.max((a.com[i].to_num::<f64>() - b.com[i]).abs());
                worst = worst.max((a.zmp[i].to_num::<f64>() - b.zmp[i]).abs());
                worst_v = worst_v.max((a.com_vel[i].to_num::<f64>() - b.com_vel[i]).abs());
                worst = worst.max((a.feet[i].x.to_num::<f64>() - b.feet[i].x).abs());
                worst = worst.max((a.feet[i].y.to_num::<f64>() - b.feet[i].y).abs());
                worst = worst.max((a.feet[i].z.to_num::<f64>() - b.feet[i].z).abs());
            }
            n += 1;
        }
        println!("{kind:?}: fixed point vs f64 over {n} samples: {worst:.3e} m, velocity {worst_v:.3e} m/s");
        assert!(worst < 5e-4, "{kind:?}: fixed point off by {worst} m");
        assert!(
            worst_v < 5e-3,
            "{kind:?}: fixed point velocity off by {worst_v} m/s"
        );
    }
}

#[test]
fn fixed_point_math_primitives() {
    use gait_core::maths::fixed_point::{exp_neg, sin_cos, Fx};
    for i in 0..2000 {
        let x = i as f64 * 0.01;
        let e = exp_neg(Fx::from_num(x)) as f64 / (1u64 << 30) as f64;
        let xr = Fx::from_num(x).to_num::<f64>();
        assert!((e - (-xr).exp()).abs() < 3e-8, "exp(-{x}) = {e}");
    }
    for i in -700..700 {
        let x = i as f64 * 0.01;
        let (s, c) = sin_cos(Fx::from_num(x));
        let xr = Fx::from_num(x).to_num::<f64>();
        let k = (1u64 << 30) as f64;
        assert!(
            (s as f64 / k - xr.sin()).abs() < 4e-7 && (c as f64 / k - xr.cos()).abs() < 4e-7,
            "sincos {x}"
        );
    }
}

/// The ZMP reference never leaves the support polygon: the support sole in single support, the
/// hull of both soles in double support and while standing.
fn zmp_margin_min(samples: &[GaitSample<f64>], robot: &Robot) -> f64 {
    use gait_core::measure::support::SupportPolygon;
    let mut worst = f64::INFINITY;
    for s in samples {
        let place = |i: usize| Place::new(s.feet[i].x, s.feet[i].y, s.feet[i].yaw);
        let poly = match s.phase {
            SupportPhase::Single(side) => {
                SupportPolygon::single(&place(side.index()), robot).unwrap()
            }
            _ => SupportPolygon::double(&place(0), &place(1), robot).unwrap(),
        };
        worst = worst.min(poly.margin([s.zmp[0], s.zmp[1]]));
    }
    worst
}

#[test]
fn table2_zmp_reference_stays_inside_the_support_polygon() {
    let robot = Robot::reference();
    for kind in ModelKind::ALL {
        let samples = run(table2_sampler::<f64>(kind, 0.005));
        let m = zmp_margin_min(&samples, &robot);
        // In single support the ZMP is at most a = 4 mm off the ankle along the 10 cm sole and
        // on the sole's centre line: margin = min(0.05 − 0.004, 0.03) = 0.03 m.
        assert!((m - 0.03).abs() < 1e-9, "{kind:?}: margin {m}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]
    #[test]
    fn random_walks_keep_the_zmp_on_the_support_polygon(
        steps in prop::collection::vec((-0.04f64..0.06, 0.08f64..0.11, -0.25f64..0.25), 1..8),
        continuous in any::<bool>(),
    ) {
        let robot = Robot::reference();
        let mut pp = params(0.15, 0.49, 0.64);
        if continuous {
            pp.zmp = ZmpShape::Continuous { b: 0.01 };
        }
        let plan = random_plan(&robot, pp, &steps);
        let samples = run(Sampler::new(plan, 0.005).unwrap());
        let m = zmp_margin_min(&samples, &robot);
        prop_assert!(m >= 0.0, "ZMP left the support polygon by {}", -m);
    }
}

#[test]
fn fixed_point_conversion_refuses_out_of_range_and_non_finite() {
    use gait_core::maths::fixed_point::fx;
    assert_eq!(fx(40_000.0), Err(GaitError::FixedPointOverflow));
    assert_eq!(fx(-1e30), Err(GaitError::FixedPointOverflow));
    assert_eq!(fx(f32::NAN), Err(GaitError::NonFinite));
    assert_eq!(fx(0.25).map(|v| v.to_num::<f32>()), Ok(0.25));
}
