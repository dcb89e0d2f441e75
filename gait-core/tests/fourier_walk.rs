//! Seed 001's Fourier CoM walked from rest to rest (`fourier_walk.rs`): the Table 2 walk with
//! `ComMethod::Fourier` against the same walk with the exact solver, sample by sample.
//! Run with `--nocapture` to see the figures.

use gait_core::gait::{self, Arithmetic, Engine, WalkConfig};
use gait_core::trajectory::fourier_walk::{
    ComMethod, WalkSampler, MAX_FOURIER_TERMS, MIN_FOURIER_STEPS,
};
use gait_core::{ForwardWalk, GaitError, GaitSample, ModelKind, Robot};

const DT: f64 = 0.001;

fn config(kind: ModelKind, com: ComMethod) -> WalkConfig {
    WalkConfig {
        model: kind,
        walk: ForwardWalk::table2(),
        zmp_continuous: false,
        zmp_b: None,
        swing_sinusoid: false,
        com,
        dt_s: DT,
    }
}

fn walk64(w: &WalkConfig) -> Vec<GaitSample<f64>> {
    let plan = w
        .walk
        .model_plan::<f64, 64>(&Robot::reference(), w.model)
        .unwrap();
    let mut s = WalkSampler::new(plan, &w.walk, w.com, w.dt_s).unwrap();
    let mut out = Vec::new();
    while !s.is_done() {
        out.push(s.next(0.0));
    }
    out
}

struct Figures {
    /// Max |c_fourier − c_exact| where the series alone drives the CoM, per axis, m.
    steady: [f64; 2],
    /// The same over the whole walk, m.
    whole: [f64; 2],
    /// Max |(c[k+1] − c[k])/dt − (v[k] + v[k+1])/2|, m/s.
    vel_consistency: f64,
    /// Max |v[k+1] − v[k]| of the Fourier walk and of the exact walk, m/s.
    vel_step: [f64; 2],
    /// Max |c − c̈/ω² − p_ref| of the Fourier walk (finite differences), m.
    zmp_residual: f64,
    /// Max of the same for the exact walk (the discretisation's floor), m.
    zmp_residual_exact: f64,
    /// The series' CoM truncation bound, m.
    bound: [f64; 2],
    /// The series' ZMP truncation bound, m.
    zmp_bound: [f64; 2],
}

fn figures(kind: ModelKind, terms: u8) -> Figures {
    let exact = walk64(&config(kind, ComMethod::Exact));
    let fw = config(kind, ComMethod::Fourier { terms });
    let four = walk64(&fw);
    assert_eq!(exact.len(), four.len());
    let robot = Robot::reference();
    let model = gait_core::Model::<f64>::new(kind, &robot, fw.walk.z_c).unwrap();
    let omega = model.omega;
    let plan = fw.walk.model_plan::<f64, 64>(&robot, kind).unwrap();
    let s = WalkSampler::new(plan, &fw.walk, fw.com, DT).unwrap();
    let blend = s.fourier().unwrap();
    let start = s.walk_start_ns();
    let t_of = |g: &GaitSample<f64>| (g.time_ns as f64 - start as f64) * 1e-9;
    let mut f = Figures {
        steady: [0.0; 2],
        whole: [0.0; 2],
        vel_consistency: 0.0,
        vel_step: [0.0; 2],
        zmp_residual: 0.0,
        zmp_residual_exact: 0.0,
        bound: blend.series().truncation_bound(),
        zmp_bound: blend.series().zmp_truncation_bound(),
    };
    for (e, g) in exact.iter().zip(&four) {
        assert_eq!(e.time_ns, g.time_ns);
        assert_eq!(e.zmp, g.zmp, "the ZMP reference is the plan's");
        assert_eq!(e.feet, g.feet);
        let (w, _) = blend.weight(t_of(g));
        for ax in 0..2 {
            let d = (g.com[ax] - e.com[ax]).abs();
            f.whole[ax] = f.whole[ax].max(d);
            if w == 1.0 {
                f.steady[ax] = f.steady[ax].max(d);
            }
            if w == 0.0 {
                assert_eq!(g.com[ax], e.com[ax], "exact where w = 0 (t = {})", t_of(g));
            }
        }
    }
    for (walk, is_fourier) in [(&four, true), (&exact, false)] {
        for k in 1..walk.len() - 1 {
            let (a, b, c) = (&walk[k - 1], &walk[k], &walk[k + 1]);
            for ax in 0..2 {
                let fd = (c.com[ax] - b.com[ax]) / DT;
                let mid = 0.5 * (b.com_vel[ax] + c.com_vel[ax]);
                let dv = (c.com_vel[ax] - b.com_vel[ax]).abs();
                let acc = (c.com[ax] - 2.0 * b.com[ax] + a.com[ax]) / (DT * DT);
                let zmp = b.com[ax] - acc / (omega * omega);
                let r = (zmp - b.zmp[ax]).abs();
                if is_fourier {
                    f.vel_consistency = f.vel_consistency.max((fd - mid).abs());
                    f.vel_step[0] = f.vel_step[0].max(dv);
                    f.zmp_residual = f.zmp_residual.max(r);
                } else {
                    f.vel_step[1] = f.vel_step[1].max(dv);
                    f.zmp_residual_exact = f.zmp_residual_exact.max(r);
                }
            }
        }
    }
    f
}

/// Where the series alone drives the CoM it is the exact solution up to the truncation bound
/// plus the exact solver's start/stop transients two steps in (≈ e^{−2ωT}·1 cm ≤ 2e-6 m for
/// LIPM's ω = 6.7/s, T = 0.64 s); the blend keeps the velocity the derivative of the position,
/// never jumps more per tick than the exact walk, and the walk's ZMP (c − c̈/ω²) stays within
/// the series' ZMP truncation bound of the reference (the blend's own terms, w'·ḋ/ω² and
/// w''·d/ω², are < 1e-5 m).
#[test]
fn fourier_walk_follows_the_exact_walk_and_is_smooth() {
    for kind in ModelKind::ALL {
        for terms in [6u8, 12, 24] {
            let f = figures(kind, terms);
            println!(
                "{} N={terms:2}: steady |c_F − c_exact| x {:.2e} y {:.2e} m (bound {:.2e} {:.2e}), \
                 whole walk {:.2e} {:.2e} m; |Δc/dt − v̄| {:.2e} m/s; |Δv| per tick {:.2e} (exact {:.2e}) m/s; \
                 ZMP residual {:.2e} m (exact {:.2e}, series bound {:.2e} {:.2e})",
                kind.name(),
                f.steady[0],
                f.steady[1],
                f.bound[0],
                f.bound[1],
                f.whole[0],
                f.whole[1],
                f.vel_consistency,
                f.vel_step[0],
                f.vel_step[1],
                f.zmp_residual,
                f.zmp_residual_exact,
                f.zmp_bound[0],
                f.zmp_bound[1]
            );
            for ax in 0..2 {
                assert!(
                    f.steady[ax] <= f.bound[ax] + 1e-5,
                    "{} N={terms} axis {ax}: {} > bound {}",
                    kind.name(),
                    f.steady[ax],
                    f.bound[ax]
                );
                // The blend regions add at most the transients of the exact solver one step
                // from either end, ≈ e^{−ωT}·A ≈ 1 mm for the 4.5 cm half width.
                assert!(f.whole[ax] < 2e-3, "axis {ax}: {}", f.whole[ax]);
            }
            let zb = f.zmp_bound[0].max(f.zmp_bound[1]);
            assert!(
                f.zmp_residual <= zb + f.zmp_residual_exact + 1e-4,
                "ZMP residual {} > {zb}",
                f.zmp_residual
            );
            // Second-order accurate at dt = 1 ms: |c⃛|·dt²/12 ≈ 1e-5 m/s for these walks.
            assert!(f.vel_consistency < 1e-4, "{}", f.vel_consistency);
            assert!(
                f.vel_step[0] <= 1.2 * f.vel_step[1],
                "{} > {}",
                f.vel_step[0],
                f.vel_step[1]
            );
        }
    }
}

#[test]
fn fourier_walk_refuses_what_it_cannot_walk() {
    let robot = Robot::reference();
    let mut w = config(ModelKind::Tlipfm, ComMethod::Fourier { terms: 12 });
    w.walk.steps = MIN_FOURIER_STEPS - 1;
    assert_eq!(
        gait::build_sampler::<64>(&w, &robot).err(),
        Some(GaitError::NotPeriodicWalk)
    );
    w.walk.steps = MIN_FOURIER_STEPS;
    assert!(gait::build_sampler::<64>(&w, &robot).is_ok());
    for terms in [0u8, MAX_FOURIER_TERMS as u8 + 1] {
        let w = config(ModelKind::Tlipfm, ComMethod::Fourier { terms });
        assert_eq!(
            gait::build_sampler::<64>(&w, &robot).err(),
            Some(GaitError::BadTermCount)
        );
    }
    let w = config(ModelKind::Tlipfm, ComMethod::Fourier { terms: 12 });
    let fixed = Engine::<64>::new(&w, Arithmetic::Fixed, &robot).err();
    assert!(
        matches!(
            fixed,
            Some(GaitError::NotPeriodicWalk) | Some(GaitError::NotBuiltIn)
        ),
        "{fixed:?}"
    );
    assert!(Engine::<64>::new(&w, Arithmetic::F32, &robot).is_ok());
}

/// The f32 engine of the firmware walks the Fourier CoM within f32 rounding of the f64 walk.
#[test]
fn f32_fourier_walk_agrees_with_f64() {
    let robot = Robot::reference();
    let w = config(ModelKind::Tlipfm, ComMethod::Fourier { terms: 12 });
    let reference = walk64(&w);
    let mut s = gait::build_sampler::<64>(&w, &robot).unwrap();
    let mut worst = 0.0f64;
    for r in &reference {
        let g = s.next(0.0);
        assert_eq!(g.time_ns, r.time_ns);
        for ax in 0..2 {
            worst = worst.max((f64::from(g.com[ax]) - r.com[ax]).abs());
        }
    }
    assert!(s.is_done());
    println!("f32 vs f64 Fourier walk: max |Δc| {worst:.2e} m");
    assert!(worst < 5e-5, "{worst}");
}
