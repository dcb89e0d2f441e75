//! Accuracy of the fast f32 sine / cosine of `gait_core::maths::fastmath` against f64 `libm`.

use gait_core::maths::fastmath::{cos, sin, sin_cos, sin_cos_real, FAST_RANGE};

/// Largest |fast − exact| over `n + 1` evenly spaced f32 points of [lo, hi]; exact values are
/// computed in f64 at the very f32 argument the fast functions receive.
fn max_error(lo: f64, hi: f64, n: u32) -> (f64, f64) {
    let mut worst = 0.0f64;
    let mut at = 0.0f64;
    for i in 0..=n {
        let x = (lo + (hi - lo) * f64::from(i) / f64::from(n)) as f32;
        let xd = f64::from(x);
        let (s, c) = sin_cos(x);
        let es = (f64::from(s) - libm::sin(xd)).abs();
        let ec = (f64::from(c) - libm::cos(xd)).abs();
        // sin / cos alone must agree exactly with sin_cos.
        assert_eq!(s.to_bits(), sin(x).to_bits(), "sin({x})");
        assert_eq!(c.to_bits(), cos(x).to_bits(), "cos({x})");
        let e = es.max(ec);
        if e > worst {
            worst = e;
            at = xd;
        }
    }
    (worst, at)
}

/// The brief's bound: max abs error ≤ 5e-7 over |x| ≤ 100 (2 million points, step 1e-4).
#[test]
fn fast_sin_cos_within_5e7_up_to_100() {
    let (e, at) = max_error(-100.0, 100.0, 2_000_000);
    eprintln!("max |error| over |x| <= 100: {e:e} at x = {at}");
    assert!(e <= 5e-7, "max error {e:e} at x = {at}");
}

/// Denser grid on the range the kinematics uses most (|x| ≤ 2π, step ≈ 6e-6).
#[test]
fn fast_sin_cos_dense_near_zero() {
    let (e, at) = max_error(-core::f64::consts::TAU, core::f64::consts::TAU, 2_000_000);
    assert!(e <= 2e-7, "max error {e:e} at x = {at}");
}

/// Every f32 in [0, 1] near the quadrant boundaries π/4, π/2 (exhaustive around them).
#[test]
fn fast_sin_cos_exhaustive_near_quadrant_edges() {
    for centre in [
        core::f32::consts::FRAC_PI_4,
        core::f32::consts::FRAC_PI_2,
        core::f32::consts::PI,
    ] {
        let mut x = centre;
        for _ in 0..20_000 {
            x = f32::from_bits(x.to_bits() - 1);
        }
        for _ in 0..40_000 {
            let (s, c) = sin_cos(x);
            let xd = f64::from(x);
            assert!((f64::from(s) - libm::sin(xd)).abs() <= 2e-7, "sin {x}");
            assert!((f64::from(c) - libm::cos(xd)).abs() <= 2e-7, "cos {x}");
            x = f32::from_bits(x.to_bits() + 1);
        }
    }
}

/// The fast path stays accurate (a few ulp of the argument reduction) up to FAST_RANGE; beyond
/// it the fmodf reduction keeps the result finite with an error ≤ |x|·1.8e-7; NaN and
/// infinities give NaN.
#[test]
fn fast_sin_cos_large_and_special_arguments() {
    let (e, at) = max_error(-f64::from(FAST_RANGE), f64::from(FAST_RANGE), 1_000_000);
    assert!(e <= 1e-6, "max error {e:e} at x = {at}");
    for x in [1.0e4f32, -3.3e5, 1.0e20, f32::MAX] {
        let (s, c) = sin_cos(x);
        assert!(
            s.abs() <= 1.0 && c.abs() <= 1.0 && (s * s + c * c - 1.0).abs() < 1e-5,
            "{x}"
        );
        if x.abs() < 1e6 {
            let tol = f64::from(x.abs()) * 1.8e-7 + 1e-6;
            assert!(
                (f64::from(s) - libm::sin(f64::from(x))).abs() < tol,
                "sin {x}"
            );
            assert!(
                (f64::from(c) - libm::cos(f64::from(x))).abs() < tol,
                "cos {x}"
            );
        }
    }
    for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let (s, c) = sin_cos(x);
        assert!(s.is_nan() && c.is_nan());
    }
    assert_eq!(sin_cos(0.0f32), (0.0, 1.0));
}

/// The generic dispatcher uses the polynomial for f32 and libm for f64.
#[test]
fn sin_cos_real_dispatches_by_precision() {
    let x = 0.7f32;
    assert_eq!(sin_cos_real(x), sin_cos(x));
    let xd = 0.7f64;
    assert_eq!(sin_cos_real(xd), (libm::sin(xd), libm::cos(xd)));
}
