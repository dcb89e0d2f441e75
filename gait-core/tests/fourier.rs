//! The Fourier-series CoM of seed 001: exact coefficients against the errata's closed forms and
//! quadrature, the series ZMP against the piecewise-linear reference, the ODE by finite
//! differences, and the steady state of the exact solver (the sampler) against the series.
//! Run with `--nocapture` to see the measured errors and the truncation bounds.

use core::f64::consts::PI;
use gait_core::trajectory::fourier::{fourier_coefficients, FourierCom, PeriodicWalk, TAIL_TERMS};
use gait_core::trajectory::plan::{GaitParams, SwingShape, Timing};
use gait_core::trajectory::zmp::ZmpShape;
use gait_core::{ForwardWalk, GaitError, Model, ModelKind, Plan, Robot, Sampler};

const G: f64 = 9.80665;

/// Seed 001 Fig. 8: A = 0.1, B = 0.1, b = 0.04, T = 1, τ = 0.2.
fn fig8() -> (f64, f64, f64, f64, f64) {
    (0.1, 0.1, 0.04, 1.0, 0.2)
}

/// Seed 001 Table II: 2T = 3, T_s = 0.6, T_d = 0.9 (τ = 0.45), 2A = 0.24, B = 0.1, 2b = 0.08.
fn table2() -> (f64, f64, f64, f64, f64) {
    (0.12, 0.1, 0.04, 1.5, 0.45)
}

/// Errata, eq 13 simplified: the CoM's y sine coefficient.
fn b_closed(a: f64, t: f64, tau: f64, w: f64, k: usize) -> f64 {
    if k.is_multiple_of(2) {
        return 0.0;
    }
    let k = k as f64;
    let wt2 = w * w * t * t;
    wt2 / (wt2 + PI * PI * k * k) * 4.0 * a * t * (PI * k * tau / t).sin() / (PI * PI * k * k * tau)
}

/// Errata, eq 17 simplified: the CoM's x sine coefficient for the peak δ.
fn beta_closed(delta: f64, t: f64, tau: f64, w: f64, k: usize) -> f64 {
    let k = k as f64;
    let wt2 = w * w * t * t;
    wt2 / (wt2 + 4.0 * PI * PI * k * k) * delta * t * t * (2.0 * PI * k * tau / t).sin()
        / (PI * PI * k * k * tau * (t - 2.0 * tau))
}

#[test]
fn coefficients_match_errata_closed_forms() {
    for (name, (a, b_step, b, t, tau)) in [("fig8", fig8()), ("table2", table2())] {
        // Our reading of eq 6: the ZMP moves exactly ±b under the sole.
        let delta = b_step * (t - 2.0 * tau) / (2.0 * t) - b;
        // The printed eq 6 is our walk with b replaced by b(T − 2τ)/T.
        let delta_printed = (t - 2.0 * tau) / t * (b_step / 2.0 - b);
        let b_printed = b * (t - 2.0 * tau) / t;
        println!(
            "{name}: delta (ours) = {delta:.6} m, delta (printed eq 6) = {delta_printed:.6} m"
        );
        for z_c in [0.217, 0.5, 0.8, 1.2] {
            let w = (G / z_c).sqrt();
            let ours =
                FourierCom::<f64, 24>::new(&PeriodicWalk::seed001(a, b_step, b, t, tau), w, 24)
                    .unwrap();
            let printed = FourierCom::<f64, 24>::new(
                &PeriodicWalk::seed001(a, b_step, b_printed, t, tau),
                w,
                24,
            )
            .unwrap();
            let m = ours.mean();
            assert!(
                m[0].abs() < 1e-14 && m[1].abs() < 1e-14,
                "{name}: means {m:?}"
            );
            for k in 1..=24 {
                let [al, be, ay, by] = ours.com_coefficients(k).unwrap();
                let tol = 1e-13;
                assert!(al.abs() < tol, "{name} k={k}: alpha_k = {al}");
                assert!(ay.abs() < tol, "{name} k={k}: a_k = {ay}");
                let bk = b_closed(a, t, tau, w, k);
                assert!(
                    (by - bk).abs() < tol,
                    "{name} k={k}: b_k {by} vs closed form {bk}"
                );
                let bek = beta_closed(delta, t, tau, w, k);
                assert!(
                    (be - bek).abs() < tol,
                    "{name} k={k}: beta_k {be} vs closed form {bek}"
                );
                let bep = printed.com_coefficients(k).unwrap()[1];
                let bepk = beta_closed(delta_printed, t, tau, w, k);
                assert!(
                    (bep - bepk).abs() < tol,
                    "{name} k={k}: printed-delta beta_k {bep} vs {bepk}"
                );
                // The ZMP coefficients are the CoM ones times the factors (eqs 11, 15, erratum).
                let z = ours.zmp_coefficients(k).unwrap();
                let kf = k as f64;
                let fx = 1.0 + 4.0 * PI * PI * kf * kf / (w * w * t * t);
                assert!((z[1] - be * fx).abs() < 1e-13);
            }
        }
    }
}

/// Composite Simpson on every piece of a piecewise-linear curve times cos / sin.
fn quad(times: &[f64], values: &[f64], period: f64, k: u32) -> (f64, f64) {
    let w = 2.0 * PI * k as f64 / period;
    let (mut ca, mut sa) = (0.0, 0.0);
    for j in 0..times.len() - 1 {
        let (u, v) = (times[j], times[j + 1]);
        if v <= u {
            continue;
        }
        let n = 4000;
        let h = (v - u) / n as f64;
        for i in 0..=n {
            let x = u + h * i as f64;
            let p = values[j] + (values[j + 1] - values[j]) * (x - u) / (v - u);
            let wt = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            ca += wt * h / 3.0 * p * (w * x).cos();
            sa += wt * h / 3.0 * p * (w * x).sin();
        }
    }
    (2.0 / period * ca, 2.0 / period * sa)
}

#[test]
fn exact_coefficients_match_quadrature_for_general_knots() {
    // Asymmetric knots, and a curve with a jump (two knots at the same time).
    let curves: [(&[f64], &[f64], f64); 3] = [
        (&[0.0, 0.13, 0.52, 0.7], &[0.01, -0.03, 0.025, 0.01], 0.7),
        (&[0.0, 0.3, 0.3, 1.1, 2.0], &[0.0, 0.5, -0.2, 0.4, 0.1], 2.0),
        (&[0.5, 0.9, 1.7, 2.5], &[1.0, 2.0, -1.0, 1.0], 2.0),
    ];
    for (times, values, period) in curves {
        for k in 0..30u32 {
            let (a, b) = fourier_coefficients(times, values, period, k).unwrap();
            let (qa, qb) = quad(times, values, period, k);
            assert!(
                (a - qa).abs() < 1e-9 && (b - qb).abs() < 1e-9,
                "k={k}: ({a}, {b}) vs ({qa}, {qb})"
            );
        }
    }
    assert_eq!(fourier_coefficients(&[0.0, 1.0], &[1.0], 1.0, 1), None);
    assert_eq!(fourier_coefficients(&[0.0, 1.0], &[1.0, 1.0], 0.0, 1), None);
}

#[test]
fn general_timing_and_natural_shape_coefficients_match_quadrature() {
    // t1 ≠ T − t2: the boundary point is no longer the middle of the double support.
    let w = (G / 0.217).sqrt();
    let walks = [
        PeriodicWalk {
            step_length: 0.05,
            half_width: 0.045,
            timing: Timing {
                t1: 0.1,
                t2: 0.45,
                period: 0.64,
            },
            zmp: ZmpShape::Continuous { b: 0.02 },
        },
        PeriodicWalk {
            step_length: 0.02,
            half_width: -0.045,
            timing: Timing {
                t1: 0.15,
                t2: 0.49,
                period: 0.64,
            },
            zmp: ZmpShape::Natural {
                d1: 0.01,
                d2: 0.012,
                a: 0.004,
            },
        },
    ];
    for walk in walks {
        let f = FourierCom::<f64, 12>::new(&walk, w, 12).unwrap();
        let t = walk.timing.period;
        // Sample the exact reference as knots of one period of each axis.
        let (t1, t2) = (walk.timing.t1, walk.timing.t2);
        let tx = [0.0, t1, t2, t];
        let px: Vec<f64> = tx
            .iter()
            .map(|&s| f.zmp_reference(s)[0] - walk.step_length / t * (s - t / 2.0))
            .collect();
        let ty = [0.0, t1, t2, t, t + t1, t + t2, 2.0 * t];
        let py: Vec<f64> = ty.iter().map(|&s| f.zmp_reference(s)[1]).collect();
        let (qx0, _) = quad(&tx, &px, t, 0);
        let (qy0, _) = quad(&ty, &py, 2.0 * t, 0);
        assert!((f.mean()[0] - qx0 / 2.0).abs() < 1e-10 && (f.mean()[1] - qy0 / 2.0).abs() < 1e-10);
        for k in 1..=12 {
            let z = f.zmp_coefficients(k).unwrap();
            let (qa, qb) = quad(&tx, &px, t, k as u32);
            let (ya, yb) = quad(&ty, &py, 2.0 * t, k as u32);
            for (got, want) in z.iter().zip([qa, qb, ya, yb]) {
                assert!((got - want).abs() < 1e-9, "k={k}: {got} vs {want}");
            }
        }
    }
}

#[test]
fn series_zmp_reproduces_reference_within_tail_and_bounds_hold() {
    for (name, (a, b_step, b, t, tau)) in [("fig8", fig8()), ("table2", table2())] {
        let w = (G / 0.8).sqrt();
        let walk = PeriodicWalk::seed001(a, b_step, b, t, tau);
        let truth = FourierCom::<f64, 400>::new(&walk, w, 400).unwrap();
        for n in [6, 12, 24] {
            let f = FourierCom::<f64, 24>::new(&walk, w, n).unwrap();
            let (zb, cb) = (f.zmp_truncation_bound(), f.truncation_bound());
            let tb = truth.truncation_bound();
            let (mut ez, mut ec) = ([0.0f64; 2], [0.0f64; 2]);
            for i in 0..=6000 {
                let tt = -2.0 * t + 6.0 * t * i as f64 / 6000.0;
                let (c, _, z) = f.sample(tt);
                let (ct, _, _) = truth.sample(tt);
                let r = f.zmp_reference(tt);
                for ax in 0..2 {
                    ez[ax] = ez[ax].max((z[ax] - r[ax]).abs());
                    ec[ax] = ec[ax].max((c[ax] - ct[ax]).abs());
                }
            }
            println!(
                "{name} N={n:2}: series-ZMP err x {:.3e} y {:.3e} (bound {:.3e} {:.3e}); \
                 CoM vs N=400 x {:.3e} y {:.3e} (bound {:.3e} {:.3e})",
                ez[0], ez[1], zb[0], zb[1], ec[0], ec[1], cb[0], cb[1]
            );
            for ax in 0..2 {
                assert!(
                    ez[ax] <= zb[ax] + 1e-12,
                    "{name} N={n} axis {ax}: zmp {} > {}",
                    ez[ax],
                    zb[ax]
                );
                assert!(
                    ec[ax] <= cb[ax] + tb[ax] + 1e-12,
                    "{name} N={n} axis {ax}: com {} > {}",
                    ec[ax],
                    cb[ax]
                );
            }
        }
    }
}

#[test]
fn truncated_series_satisfies_the_ode_exactly() {
    let (a, b_step, b, t, tau) = fig8();
    let w = (G / 0.5).sqrt();
    let f =
        FourierCom::<f64, 24>::new(&PeriodicWalk::seed001(a, b_step, b, t, tau), w, 24).unwrap();
    let h = 2.5e-4;
    let d1 = |g: &dyn Fn(f64) -> [f64; 2], tt: f64, ax: usize| {
        (-g(tt + 2.0 * h)[ax] + 8.0 * g(tt + h)[ax] - 8.0 * g(tt - h)[ax] + g(tt - 2.0 * h)[ax])
            / (12.0 * h)
    };
    let pos = |tt: f64| f.sample(tt).0;
    let vel = |tt: f64| f.sample(tt).1;
    let (mut rv, mut ra) = (0.0f64, 0.0f64);
    for i in 0..500 {
        let tt = -1.0 + 4.0 * i as f64 / 500.0;
        let (c, v, z) = f.sample(tt);
        for ax in 0..2 {
            rv = rv.max((d1(&pos, tt, ax) - v[ax]).abs());
            let acc = d1(&vel, tt, ax);
            ra = ra.max((acc - w * w * (c[ax] - z[ax])).abs());
        }
    }
    println!("ODE residual: velocity {rv:.2e} m/s, acceleration {ra:.2e} m/s^2");
    assert!(rv < 1e-9, "velocity residual {rv}");
    assert!(ra < 1e-9, "acceleration residual {ra}");
}

/// The sampler's steady state (middle steps of a 40-step walk) against the series.
fn compare_with_sampler(
    kind: ModelKind,
    n: usize,
) -> ([f64; 2], [f64; 2], [f64; 2], [f64; 2], f64) {
    let robot = Robot::reference();
    let model = Model::<f64>::new(kind, &robot, 0.217).unwrap();
    let (t, tau, b, s_l, s_w) = (0.64, 0.15, 0.02, 0.05, 0.045);
    let params = GaitParams {
        model,
        timing: Timing {
            t1: tau,
            t2: t - tau,
            period: t,
        },
        zmp: ZmpShape::Continuous { b },
        swing: SwingShape::Sinusoid { height: 0.03 },
        lead_in: 1.6,
        lead_out: 1.6,
    };
    let walk = ForwardWalk {
        step_length: s_l,
        step_width: s_w,
        steps: 40,
        ..ForwardWalk::table2()
    };
    let plan: Plan<f64, 64> = walk.plan(&robot, params).unwrap();
    let mut s = Sampler::new(plan, 0.001).unwrap();
    // S_first = −1: step 0 stands on the right foot, y = −S_W, so A = −S_W.
    let f = FourierCom::<f64, 24>::from_params(&params, s_l, -s_w, n).unwrap();
    let start = s.walk_start_ns();
    let (mut ec, mut ev, mut ez) = ([0.0f64; 2], [0.0f64; 2], 0.0f64);
    while !s.is_done() {
        let g = s.next(0.0);
        let tt = (g.time_ns as f64 - start as f64) * 1e-9;
        if !(10.0 * t..=30.0 * t).contains(&tt) {
            continue;
        }
        let (c, v, _) = f.sample(tt);
        let r = f.zmp_reference(tt);
        for ax in 0..2 {
            ec[ax] = ec[ax].max((g.com[ax] - c[ax]).abs());
            ev[ax] = ev[ax].max((g.com_vel[ax] - v[ax]).abs());
            ez = ez.max((g.zmp[ax] - r[ax]).abs());
        }
    }
    (
        ec,
        f.truncation_bound(),
        ev,
        f.velocity_truncation_bound(),
        ez,
    )
}

#[test]
fn steady_state_of_exact_solver_matches_series_within_bound() {
    for kind in ModelKind::ALL {
        for n in [6, 12, 24] {
            let (ec, bc, ev, bv, ez) = compare_with_sampler(kind, n);
            println!(
                "{} N={n:2}: |c_exact - c_fourier| x {:.3e} y {:.3e} m (bound {:.3e} {:.3e}); \
                 velocity x {:.3e} y {:.3e} m/s (bound {:.3e} {:.3e}); ZMP knots {:.1e}",
                kind.name(),
                ec[0],
                ec[1],
                bc[0],
                bc[1],
                ev[0],
                ev[1],
                bv[0],
                bv[1],
                ez
            );
            assert!(
                ez < 1e-12,
                "the sampler's ZMP and the series' reference differ by {ez}"
            );
            // Transients of the start and the stop decay like e^{−ω·10T} < 1e-18 here.
            for (what, e, bound, slack) in [("pos", ec, bc, 1e-11), ("vel", ev, bv, 1e-10)] {
                for ax in 0..2 {
                    assert!(
                        e[ax] <= bound[ax] + slack,
                        "{} N={n} axis {ax}: {what} {} > {}",
                        kind.name(),
                        e[ax],
                        bound[ax]
                    );
                }
            }
        }
    }
}

#[test]
fn f32_path_is_small_and_close_to_f64() {
    let size = core::mem::size_of::<FourierCom<f32, 24>>();
    println!("size_of::<FourierCom<f32, 24>>() = {size} bytes (TAIL_TERMS = {TAIL_TERMS})");
    assert!(size <= 500, "{size} bytes");
    let (a, b_step, b, t, tau) = fig8();
    let w = (G / 0.217).sqrt();
    let f64s =
        FourierCom::<f64, 24>::new(&PeriodicWalk::seed001(a, b_step, b, t, tau), w, 24).unwrap();
    let walk32 =
        PeriodicWalk::<f32>::seed001(a as f32, b_step as f32, b as f32, t as f32, tau as f32);
    let f32s = FourierCom::<f32, 24>::new(&walk32, w as f32, 24).unwrap();
    let mut e = 0.0f64;
    for i in 0..2000 {
        let tt = -3.0 + 23.0 * i as f64 / 2000.0;
        let (c, v, z) = f64s.sample(tt);
        let (c32, v32, z32) = f32s.sample(tt as f32);
        for ax in 0..2 {
            e = e.max((c[ax] - c32[ax] as f64).abs());
            e = e.max((z[ax] - z32[ax] as f64).abs() / 10.0);
            e = e.max((v[ax] - v32[ax] as f64).abs() / 10.0);
        }
    }
    println!("f32 vs f64 (CoM, ZMP/10, velocity/10): {e:.2e}");
    assert!(e < 2e-5, "{e}");
}

#[test]
fn bounds_shrink_like_n_cubed() {
    let (a, b_step, b, t, tau) = table2();
    let w = (G / 0.8).sqrt();
    let walk = PeriodicWalk::seed001(a, b_step, b, t, tau);
    let mut prev = [f64::INFINITY; 2];
    for n in [3, 6, 12, 24, 48] {
        let f = FourierCom::<f64, 48>::new(&walk, w, n).unwrap();
        let bc = f.truncation_bound();
        println!("table2 N={n:2}: CoM bound x {:.3e} y {:.3e}", bc[0], bc[1]);
        for ax in 0..2 {
            assert!(bc[ax] > 0.0 && bc[ax] < prev[ax]);
        }
        prev = bc;
    }
}

#[test]
fn zmp_reference_is_seed001_fig5() {
    let (a, b_step, b, t, tau) = fig8();
    let f =
        FourierCom::<f64, 6>::new(&PeriodicWalk::seed001(a, b_step, b, t, tau), 7.0, 6).unwrap();
    let close =
        |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).abs() < 1e-12 && (p[1] - q[1]).abs() < 1e-12;
    // t = 0: middle of the double support, between the feet; step 0 stands on (0, A).
    assert!(close(f.zmp_reference(0.0), [-b_step / 2.0, 0.0]));
    assert!(close(f.zmp_reference(tau), [-b, a]));
    assert!(close(f.zmp_reference(t - tau), [b, a]));
    assert!(close(f.zmp_reference(t), [b_step / 2.0, 0.0]));
    assert!(close(f.zmp_reference(t + tau), [b_step - b, -a]));
    assert!(close(f.zmp_reference(-t + tau), [-b_step - b, -a]));
    assert!(close(
        f.zmp_reference(5.0 * t + 0.5 * t),
        [5.0 * b_step, -a]
    ));
    // Non-finite time: no panic.
    let (c, _, _) = f.sample(f64::NAN);
    assert!(c[0].is_nan());
    let _ = f.zmp_reference(f64::INFINITY);
}

#[test]
fn bad_inputs_are_refused() {
    let good = PeriodicWalk::seed001(0.1, 0.1, 0.04, 1.0, 0.2);
    let w = 5.0;
    assert!(FourierCom::<f64, 24>::new(&good, w, 24).is_ok());
    assert_eq!(
        FourierCom::<f64, 24>::new(&good, w, 0).err(),
        Some(GaitError::BadTermCount)
    );
    assert_eq!(
        FourierCom::<f64, 24>::new(&good, w, 25).err(),
        Some(GaitError::BadTermCount)
    );
    assert_eq!(
        FourierCom::<f64, 0>::new(&good, w, 0).err(),
        Some(GaitError::BadTermCount)
    );
    assert_eq!(
        FourierCom::<f64, 24>::new(&good, f64::NAN, 24).err(),
        Some(GaitError::NonFinite)
    );
    assert_eq!(
        FourierCom::<f64, 24>::new(&good, 0.0, 24).err(),
        Some(GaitError::NonPositiveParameter)
    );
    let with = |f: &dyn Fn(&mut PeriodicWalk<f64>)| {
        let mut w2 = good;
        f(&mut w2);
        FourierCom::<f64, 24>::new(&w2, w, 24).err()
    };
    assert_eq!(
        with(&|x| x.step_length = f64::INFINITY),
        Some(GaitError::NonFinite)
    );
    assert_eq!(
        with(&|x| x.half_width = f64::NAN),
        Some(GaitError::NonFinite)
    );
    assert_eq!(
        with(&|x| x.zmp = ZmpShape::Continuous { b: f64::NAN }),
        Some(GaitError::NonFinite)
    );
    assert_eq!(
        with(&|x| x.timing.period = 0.0),
        Some(GaitError::NonPositivePeriod)
    );
    assert_eq!(with(&|x| x.timing.t1 = 0.0), Some(GaitError::BadPhaseTimes));
    assert_eq!(with(&|x| x.timing.t2 = 0.1), Some(GaitError::BadPhaseTimes));
    assert_eq!(with(&|x| x.timing.t2 = 1.0), Some(GaitError::BadPhaseTimes));
    assert_eq!(
        with(&|x| x.zmp = ZmpShape::Continuous { b: -0.01 }),
        Some(GaitError::ZmpOffsetOffSole)
    );
    let f = FourierCom::<f64, 24>::new(&good, w, 12).unwrap();
    assert!(f.com_coefficients(0).is_none() && f.com_coefficients(13).is_none());
    assert!(f.com_coefficients(12).is_some());
}
