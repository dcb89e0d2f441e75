//! The servo survey (`gait_core::measure::stiffness`, K1–K3) and the deflection gain it sets
//! (`feedback::deflection` D6): a spring plant's K recovered, the window (settling, span, an
//! early end of standing), reads that failed, no load and no sag, the softness and the supply
//! scaling, and any input being total.

use gait_core::feedback::deflection::DeflectionConfig;
use gait_core::measure::stiffness::{
    Stiffness, StiffnessSurvey, MAX_SOFTNESS, MAX_STIFFNESS, MIN_SAG_RAD, MIN_TORQUE_NM,
};
use gait_core::{Side, SupportPhase};
use proptest::prelude::*;

const DT: f32 = 0.01;
const STAND: SupportPhase = SupportPhase::Standing;
/// The pitch joints of both legs (hip pitch, knee, ankle pitch).
const PITCH: [usize; 6] = [2, 3, 4, 8, 9, 10];

/// The goals, the Present Positions of a spring servo of stiffness `k` under `tau` (sag τ/K on
/// every joint), and the torques.
fn spring(k: f32, tau: [f32; 12]) -> ([f32; 12], [f32; 12], [f32; 12]) {
    let goal = [0.3f32; 12];
    let mut present = goal;
    for (p, t) in present.iter_mut().zip(tau) {
        *p -= t / k;
    }
    (goal, present, tau)
}

/// Feeds `n` standing ticks of the spring `k` under `tau`; returns what closed the window.
fn stand(s: &mut StiffnessSurvey, k: f32, tau: [f32; 12], n: usize) -> Option<Option<Stiffness>> {
    let (goal, present, tau) = spring(k, tau);
    let mut closed = None;
    for _ in 0..n {
        if let Some(r) = s.add(STAND, &goal, &present, &tau) {
            closed = Some(r);
        }
    }
    closed
}

/// Standing torques of a bent-knee stance: the knee carries most, the ankle pitch a little.
const TAU: [f32; 12] = [
    0.0, 0.4, -0.15, 0.6, 0.1, 0.4, 0.0, -0.4, -0.15, 0.6, 0.1, -0.4,
];

#[test]
fn a_spring_servos_stiffness_is_recovered_from_the_pitch_joints_alone() {
    // The roll joints (1, 5, 7, 11) get a sag of another stiffness: they are not surveyed.
    let (goal, mut present, tau) = spring(11.3, TAU);
    for j in [1, 5, 7, 11] {
        present[j] = goal[j] - TAU[j] / 40.0;
    }
    let mut s = StiffnessSurvey::new(0.3, 0.6, DT);
    let mut closed = None;
    for n in 0..200 {
        assert_eq!(s.wants(STAND), (30..90).contains(&n), "tick {n}");
        if let Some(r) = s.add(STAND, &goal, &present, &tau) {
            assert!(closed.is_none(), "closed twice");
            assert_eq!(n, 30 + 60 - 1, "window: 30 settling ticks, then 60");
            closed = Some(r);
        }
    }
    let k = closed.flatten().expect("a result");
    assert!((k.k - 11.3).abs() < 1e-3, "{k:?}");
    assert_eq!(k.samples, 60 * 6);
    assert_eq!(s.result(), Some(k));
    assert!(s.is_done() && !s.wants(STAND));
}

#[test]
fn the_settling_ticks_are_not_in_the_fit() {
    // A servo still moving from the ramp (its error ten times the sag) for the first 0.3 s.
    let mut s = StiffnessSurvey::new(0.3, 0.5, DT);
    assert_eq!(stand(&mut s, 1.9, TAU, 30), None);
    let k = stand(&mut s, 19.0, TAU, 50).flatten().expect("closed");
    assert!((k.k - 19.0).abs() < 1e-3, "{k:?}");
}

#[test]
fn leaving_standing_closes_the_window_with_what_it_has_but_not_before_the_settling() {
    let (goal, present, tau) = spring(15.0, TAU);
    let single = SupportPhase::Single(Side::Left);
    // Before the settling is over: the window stays open for a later standing.
    let mut s = StiffnessSurvey::new(0.3, 0.6, DT);
    assert_eq!(stand(&mut s, 15.0, TAU, 10), None);
    assert_eq!(s.add(single, &goal, &present, &tau), None);
    assert!(!s.is_done() && !s.wants(single) && !s.wants(STAND));
    // Ten ticks into the window, then a step: closed with those ten.
    assert_eq!(stand(&mut s, 15.0, TAU, 30), None);
    let r = s
        .add(single, &goal, &present, &tau)
        .flatten()
        .expect("closed");
    assert!((r.k - 15.0).abs() < 1e-3, "{r:?}");
    assert_eq!(r.samples, 10 * 6);
    assert_eq!(s.add(STAND, &goal, &present, &tau), None, "closed for good");
}

#[test]
fn failed_reads_are_left_out_and_no_load_or_no_sag_are_told_apart() {
    // Every other tick's knee read failed: the fit is the same.
    let (goal, present, tau) = spring(12.0, TAU);
    let mut lost = present;
    lost[3] = f32::NAN;
    lost[9] = f32::NAN;
    let mut s = StiffnessSurvey::new(0.0, 0.2, DT);
    for n in 0..20 {
        let p = if n % 2 == 0 { &present } else { &lost };
        s.add(STAND, &goal, p, &tau);
    }
    let r = s.result().expect("result");
    assert!((r.k - 12.0).abs() < 1e-3, "{r:?}");
    assert_eq!(r.samples, 10 * 6 + 10 * 4);
    // Below MIN_TORQUE_NM on every joint: too little load to tell.
    let mut s = StiffnessSurvey::new(0.0, 0.2, DT);
    let small = TAU.map(|t| t.signum() * MIN_TORQUE_NM * 0.5);
    assert_eq!(stand(&mut s, 12.0, small, 20), Some(None));
    // Loaded, but no sag at all (a servo with integral action): unknown, not infinite.
    let mut s = StiffnessSurvey::new(0.0, 0.2, DT);
    assert_eq!(stand(&mut s, f32::INFINITY, TAU, 20), Some(None));
    // A sag below two encoder steps (RMS): the encoder's rounding, no result; just above: one.
    let rms = (PITCH.iter().map(|&j| TAU[j] * TAU[j]).sum::<f32>() / 6.0).sqrt();
    let mut s = StiffnessSurvey::new(0.0, 0.2, DT);
    assert_eq!(
        stand(&mut s, rms / (0.9 * MIN_SAG_RAD), TAU, 20),
        Some(None)
    );
    let mut s = StiffnessSurvey::new(0.0, 0.2, DT);
    let k = rms / (1.1 * MIN_SAG_RAD);
    let r = stand(&mut s, k, TAU, 20).flatten().expect("result");
    assert!((r.k - k).abs() < 1e-3 * k, "{r:?}");
    // Goals rounded to whole encoder steps with no sag: no result.
    let mut s = StiffnessSurvey::new(0.0, 0.2, DT);
    let step = core::f32::consts::TAU / 4096.0;
    let goal: [f32; 12] = core::array::from_fn(|j| 0.3 + 0.37 * j as f32 * step);
    let present = goal.map(|q| (q / step).round() * step);
    for _ in 0..20 {
        s.add(STAND, &goal, &present, &TAU);
    }
    assert!(s.is_done() && s.result().is_none(), "{:?}", s.result());
    // Every read failed: no result.
    let mut s = StiffnessSurvey::new(0.0, 0.2, DT);
    for _ in 0..20 {
        s.add(STAND, &goal, &[f32::NAN; 12], &tau);
    }
    assert!(s.is_done() && s.result().is_none());
}

#[test]
fn softness_is_the_datasheets_stiffness_over_the_measured_one_less_one() {
    let k = |k| Stiffness { k, samples: 1 };
    assert_eq!(k(18.875).softness(18.875), 0.0);
    assert!((k(11.325).softness(18.875) - (18.875 / 11.325 - 1.0)).abs() < 1e-6);
    assert_eq!(k(30.0).softness(18.875), 0.0, "stiffer: no softness");
    assert_eq!(k(1.0).softness(18.875), MAX_SOFTNESS, "bounded");
    assert_eq!(k(10.0).softness(f32::NAN), 0.0);
    assert_eq!(k(10.0).softness(-1.0), 0.0);
    // K follows the supply: 12 V → 10.5 V is 7/8 of it.
    assert!((k(16.0).at_supply(10.5, 12.0).k - 14.0).abs() < 1e-5);
    assert_eq!(k(16.0).at_supply(0.0, 12.0), k(16.0));
    assert_eq!(k(16.0).at_supply(10.5, f32::NAN), k(16.0));
}

#[test]
fn the_deflection_gain_grows_with_the_softness_from_the_configured_one() {
    let d = DeflectionConfig::DEFAULT;
    assert_eq!(
        d.ki, 0.0,
        "no integral on a servo as stiff as its datasheet"
    );
    assert_eq!(d.ki_for(0.0), 0.0);
    assert!((d.ki_for(0.5) - 0.5 * d.soft_ki).abs() < 1e-6);
    let c = DeflectionConfig {
        ki: 2.0,
        soft_ki: 4.0,
        ..DeflectionConfig::OFF
    };
    assert!((c.ki_for(0.25) - 3.0).abs() < 1e-6);
    assert_eq!(c.ki_for(f32::NAN), 2.0);
    assert_eq!(c.ki_for(-1.0), 2.0);
    assert_eq!(DeflectionConfig::OFF.ki_for(1.0), 0.0, "off stays off");
}

proptest! {
    #[test]
    fn any_spring_in_the_range_is_recovered(
        k in 2.0f32..200.0,
        scale in 0.2f32..3.0,
        mask in prop::array::uniform12(any::<bool>()),
    ) {
        // Any scale of the torques, any joints' reads lost, as long as one pitch joint is read
        // and the RMS sag is more than the encoder's rounding (else: no result).
        prop_assume!(PITCH.iter().any(|&j| mask[j]));
        let read: Vec<f32> = PITCH.iter().filter(|&&j| mask[j]).map(|&j| TAU[j] * scale).collect();
        let rms = (read.iter().map(|t| t * t).sum::<f32>() / read.len() as f32).sqrt();
        let sags = rms / k >= MIN_SAG_RAD * 1.001;
        prop_assume!(sags || rms / k <= MIN_SAG_RAD * 0.999);
        let tau = TAU.map(|t| t * scale);
        let (goal, mut present, tau) = spring(k, tau);
        for (p, m) in present.iter_mut().zip(mask) {
            if !m {
                *p = f32::NAN;
            }
        }
        let mut s = StiffnessSurvey::new(0.0, 0.1, DT);
        for _ in 0..10 {
            s.add(STAND, &goal, &present, &tau);
        }
        if sags {
            let r = s.result().expect("result");
            prop_assert!((r.k - k).abs() <= 1e-3 * k, "{:?} vs {}", r, k);
        } else {
            prop_assert!(s.is_done() && s.result().is_none());
        }
    }

    #[test]
    fn any_input_gives_a_bounded_result_or_none(
        goal in prop::array::uniform12(prop::num::f32::ANY),
        present in prop::array::uniform12(prop::num::f32::ANY),
        tau in prop::array::uniform12(prop::num::f32::ANY),
        dt in prop::num::f32::ANY,
        ticks in 0usize..40,
    ) {
        let mut s = StiffnessSurvey::new(0.05, 0.1, dt);
        for _ in 0..ticks {
            s.add(STAND, &goal, &present, &tau);
        }
        s.add(SupportPhase::Double, &goal, &present, &tau);
        if let Some(r) = s.result() {
            prop_assert!(r.k > 0.0 && r.k <= MAX_STIFFNESS, "{:?}", r);
            let soft = r.softness(18.875);
            prop_assert!((0.0..=MAX_SOFTNESS).contains(&soft));
        }
    }
}
