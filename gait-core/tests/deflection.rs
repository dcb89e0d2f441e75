//! Servo deflection feedback (`gait_core::feedback::deflection`, D1–D5): the stance leg's sag removed at
//! the integral's rate, the swing leg's decay, the hold in double support, the joint mask, the
//! saturation and any configuration and input being total.

use gait_core::feedback::deflection::{
    DeflectionConfig, DeflectionFeedback, JointSet, MAX_CORRECTION_RAD,
};
use gait_core::{Side, SupportPhase};
use proptest::prelude::*;

const DT: f32 = 0.005;
const LEFT: SupportPhase = SupportPhase::Single(Side::Left);
const RIGHT: SupportPhase = SupportPhase::Single(Side::Right);

fn on(ki: f32) -> DeflectionConfig {
    DeflectionConfig {
        ki,
        ..DeflectionConfig::OFF
    }
}

/// A servo plant with a constant deflection: Present Position = the target sent − `sag`.
/// Runs `n` ticks of `phase` with the targets `q_star` and returns the last Present Position.
fn run(
    fb: &mut DeflectionFeedback,
    phase: SupportPhase,
    q_star: &[f32; 12],
    sag: &[f32; 12],
    n: usize,
) -> [f32; 12] {
    let mut present = [0.0f32; 12];
    for _ in 0..n {
        let mut sent = *q_star;
        fb.apply(&mut sent);
        present = core::array::from_fn(|j| sent[j] - sag[j]);
        fb.update(phase, q_star, &present);
    }
    present
}

#[test]
fn a_constant_sag_of_the_stance_leg_is_removed_at_the_integral_rate() {
    let ki = 8.0;
    let mut fb = DeflectionFeedback::new(&on(ki), DT);
    assert!(fb.is_on());
    let q_star: [f32; 12] = core::array::from_fn(|j| 0.1 * j as f32);
    let mut sag = [0.0f32; 12];
    sag[2] = -0.02; // left hip pitch
    sag[3] = 0.05; // left knee
    sag[4] = -0.03; // left ankle pitch
    for n in [1usize, 10, 100] {
        let mut f = fb;
        run(&mut f, LEFT, &q_star, &sag, n);
        // c_{k+1} = c_k + k_i·Δt·(sag − c_k): c_n = sag·(1 − (1 − k_i·Δt)ⁿ).
        let share = 1.0 - (1.0 - f64::from(ki * DT)).powi(n as i32);
        for j in [2, 3, 4] {
            let want = f64::from(sag[j]) * share;
            let got = f64::from(f.correction()[j]);
            assert!(
                (got - want).abs() < 1e-5,
                "n {n} joint {j}: {got} vs {want}"
            );
        }
    }
    // Long enough: the stance leg stands at its targets.
    let present = run(&mut fb, LEFT, &q_star, &sag, 2000);
    for j in 0..6 {
        assert!((present[j] - q_star[j]).abs() < 1e-4, "joint {j}");
    }
}

#[test]
fn the_swing_leg_decays_and_double_support_holds() {
    let cfg = DeflectionConfig {
        leak_s: 0.05,
        ..on(10.0)
    };
    let mut fb = DeflectionFeedback::new(&cfg, DT);
    let q_star = [0.2f32; 12];
    let mut sag = [0.0f32; 12];
    sag[3] = 0.04;
    sag[9] = 0.04; // right knee
    run(&mut fb, LEFT, &q_star, &sag, 300);
    let c_left = fb.correction()[3];
    assert!((c_left - 0.04).abs() < 1e-3, "{c_left}");
    assert_eq!(
        fb.correction()[9],
        0.0,
        "the swinging right leg integrates nothing"
    );
    // Double support and standing: every correction holds, whatever the error.
    let held = *fb.correction();
    run(&mut fb, SupportPhase::Double, &q_star, &[0.3; 12], 50);
    run(&mut fb, SupportPhase::Standing, &q_star, &[0.3; 12], 50);
    assert_eq!(*fb.correction(), held);
    // The left leg swings: its correction decays by (1 − Δt/T_l) a tick; the right integrates.
    run(&mut fb, RIGHT, &q_star, &sag, 20);
    let want = f64::from(c_left) * (1.0 - f64::from(DT) / 0.05).powi(20);
    assert!((f64::from(fb.correction()[3]) - want).abs() < 1e-6);
    assert!(fb.correction()[9] > 0.01);
}

#[test]
fn only_the_masked_joints_act_and_the_correction_saturates() {
    let mut fb = DeflectionFeedback::new(&on(20.0), DT);
    let q_star = [0.0f32; 12];
    // A sag on every joint, larger than c_max on the knee.
    let mut sag = [0.01f32; 12];
    sag[3] = 0.5;
    run(&mut fb, LEFT, &q_star, &sag, 1000);
    let c = fb.correction();
    for (j, c) in c.iter().enumerate() {
        let acts = j < 6 && JointSet::PITCH.contains(j);
        if !acts {
            assert_eq!(*c, 0.0, "joint {j} is not in the mask or swings");
        }
    }
    assert_eq!(
        c[3],
        DeflectionConfig::OFF.max_rad,
        "the knee stops at c_max"
    );
    assert!((c[2] - 0.01).abs() < 1e-4 && (c[4] - 0.01).abs() < 1e-4);
    // c_max above the ceiling is capped.
    let big = DeflectionConfig {
        max_rad: 5.0,
        ..on(20.0)
    };
    let mut fb = DeflectionFeedback::new(&big, DT);
    run(&mut fb, LEFT, &q_star, &sag, 1000);
    assert_eq!(fb.correction()[3], MAX_CORRECTION_RAD as f32);
}

#[test]
fn a_missing_reading_leaves_that_joint_alone() {
    let mut fb = DeflectionFeedback::new(&on(10.0), DT);
    let sent = [0.1f32; 12];
    let mut present = [0.08f32; 12];
    present[3] = f32::NAN;
    fb.update(LEFT, &sent, &present);
    let c = fb.correction();
    assert_eq!(c[3], 0.0);
    assert!((c[2] - 10.0 * DT * 0.02).abs() < 1e-7);
    let mut bad_sent = sent;
    bad_sent[4] = f32::INFINITY;
    let before = fb.correction()[4];
    fb.update(LEFT, &bad_sent, &present);
    assert_eq!(fb.correction()[4], before);
}

#[test]
fn off_or_nonsense_configurations_do_nothing() {
    let q_star = [0.1f32; 12];
    let sag = [0.05f32; 12];
    for (cfg, dt) in [
        (DeflectionConfig::OFF, DT),
        (on(f32::NAN), DT),
        (on(-3.0), DT),
        (on(10.0), f32::NAN),
        (on(10.0), 0.0),
        (
            DeflectionConfig {
                max_rad: f32::NAN,
                ..on(10.0)
            },
            DT,
        ),
    ] {
        let mut fb = DeflectionFeedback::new(&cfg, dt);
        assert!(!fb.is_on(), "{cfg:?} dt {dt}");
        run(&mut fb, LEFT, &q_star, &sag, 100);
        assert_eq!(*fb.correction(), [0.0; 12]);
    }
}

fn phase() -> impl Strategy<Value = SupportPhase> {
    prop_oneof![
        Just(SupportPhase::Standing),
        Just(SupportPhase::Double),
        Just(LEFT),
        Just(RIGHT),
    ]
}

fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        -1.0f32..1.0,
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(f32::NEG_INFINITY),
        any::<f32>(),
    ]
}

proptest! {
    #[test]
    fn any_configuration_and_input_keep_the_corrections_finite_and_bounded(
        ki in any_f32(),
        max_rad in any_f32(),
        leak_s in any_f32(),
        dt in any_f32(),
        ticks in proptest::collection::vec(
            (phase(), proptest::array::uniform12(any_f32()), proptest::array::uniform12(any_f32())),
            1..40,
        ),
    ) {
        let cfg = DeflectionConfig { ki, max_rad, leak_s, joints: JointSet([true; 6]), soft_ki: 0.0 };
        let mut fb = DeflectionFeedback::new(&cfg, dt);
        let bound = if max_rad.is_finite() && max_rad > 0.0 {
            max_rad.min(MAX_CORRECTION_RAD as f32)
        } else {
            0.0
        };
        for (ph, sent, present) in &ticks {
            fb.update(*ph, sent, present);
            for c in fb.correction() {
                prop_assert!(c.is_finite() && c.abs() <= bound, "{c} > {bound}");
            }
            let mut q = [0.25f32; 12];
            fb.apply(&mut q);
            for (v, c) in q.iter().zip(fb.correction()) {
                prop_assert_eq!(*v, 0.25 + c);
            }
        }
    }
}
