//! Fast single-precision sine and cosine for the servo loop.
//!
//! On the Cortex-M7F `libm::sinf` / `libm::cosf` compute in software doubles (≈1,260
//! instructions each); the functions here use only f32 arithmetic (≈34 instructions).
//!
//! Method (Cody–Waite reduction plus the Cephes minimax polynomials):
//!
//! ```text
//! n = round(x · 2/π)                      (an integer, |n| ≤ 2^13 on the fast path)
//! r = ((x − n·P1) − n·P2) − n·P3          P1 + P2 + P3 = π/2, P1 and P2 with short
//!                                         mantissas so n·P1 and n·P2 are exact in f32
//! |r| ≤ π/4,  z = r²
//! sin r ≈ r + r·z·(S1 + z·(S2 + z·S3))
//! cos r ≈ 1 − z/2 + z²·(C1 + z·(C2 + z·C3))
//! (sin x, cos x) = ( sin r,  cos r)  n ≡ 0 (mod 4)
//!                  ( cos r, −sin r)  n ≡ 1
//!                  (−sin r, −cos r)  n ≡ 2
//!                  (−cos r,  sin r)  n ≡ 3
//! ```
//!
//! The absolute error is below 2e-7 for |x| ≤ 100 (tested against f64 on dense grids) and
//! stays at a few ulp up to |x| = [`FAST_RANGE`]. Beyond that (never a physical joint angle or
//! heading) the argument is first reduced with `fmodf` by the f32 value of 2π: the result stays
//! finite and in [−1, 1], with an error growing like |x|·1.8e-7 (libm's exact reduction would
//! cost 3 KiB of flash for angles nobody walks). NaN and ±∞ give NaN, as for `libm`.

use crate::real::Real;

/// Largest |x| handled by the fast path directly; larger finite arguments are reduced first.
pub const FAST_RANGE: f32 = 8192.0;

/// 2/π in f32.
const FRAC_2_PI: f32 = core::f32::consts::FRAC_2_PI;
/// First part of π/2 (8 significant bits, so n·P1 is exact for |n| < 2^16).
const P1: f32 = 1.570_312_5;
/// Second part of π/2 (short mantissa).
const P2: f32 = 4.837513e-04; // f32 of 4.837_512_969_970_703_125e-4
/// Third part of π/2: P1 + P2 + P3 = π/2 to well beyond f32 precision.
const P3: f32 = 7.54979e-08; // f32 of 7.549_789_954_891_882e-8

/// sin polynomial coefficients (Cephes `sinf`, |r| ≤ π/4).
const S1: f32 = -1.6666655e-01; // f32 of -1.666_665_461_1e-1
const S2: f32 = 8.332161e-03; // f32 of 8.332_160_873_6e-3
const S3: f32 = -1.9515296e-04; // f32 of -1.951_529_589_1e-4
/// cos polynomial coefficients (Cephes `cosf`, |r| ≤ π/4).
const C1: f32 = 4.1666646e-02; // f32 of 4.166_664_568_298_827e-2
const C2: f32 = -1.3887316e-03; // f32 of -1.388_731_625_493_765e-3
const C3: f32 = 2.4433157e-05; // f32 of 2.443_315_711_809_948e-5

/// Brings a large finite `x` into [−2π, 2π] (see the module doc); NaN and ±∞ stay NaN.
#[inline(never)]
fn wrap_large(x: f32) -> f32 {
    libm::fmodf(x, 2.0 * core::f32::consts::PI)
}

/// Reduces `x` (|x| ≤ [`FAST_RANGE`]) to `r` in [−π/4, π/4] and the quadrant `n mod 4`.
#[inline(always)]
fn reduce(x: f32) -> (f32, u32) {
    let y = x * FRAC_2_PI;
    let half = if y < 0.0 { -0.5 } else { 0.5 };
    // In range because |x| ≤ FAST_RANGE; `as` saturates anyway, so this can never misbehave.
    let n = (y + half) as i32;
    let nf = n as f32;
    let r = ((x - nf * P1) - nf * P2) - nf * P3;
    (r, (n & 3) as u32)
}

/// sin r for |r| ≤ π/4.
#[inline(always)]
fn sin_poly(r: f32) -> f32 {
    let z = r * r;
    r + r * z * (S1 + z * (S2 + z * S3))
}

/// cos r for |r| ≤ π/4.
#[inline(always)]
fn cos_poly(r: f32) -> f32 {
    let z = r * r;
    1.0 - 0.5 * z + z * z * (C1 + z * (C2 + z * C3))
}

/// Sine and cosine of `x` together (one range reduction), f32.
#[inline]
pub fn sin_cos(x: f32) -> (f32, f32) {
    let x = if x.abs() > FAST_RANGE || x.is_nan() {
        wrap_large(x)
    } else {
        x
    };
    if x.is_nan() {
        return (x, x);
    }
    let (r, q) = reduce(x);
    let s = sin_poly(r);
    let c = cos_poly(r);
    match q {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// Sine of `x`, f32.
#[inline]
pub fn sin(x: f32) -> f32 {
    let (s, _) = sin_cos(x);
    s
}

/// Retained for reference: sin by its own quadrant table.
#[cfg(test)]
fn sin_direct(x: f32) -> f32 {
    let (r, q) = reduce(x);
    match q {
        0 => sin_poly(r),
        1 => cos_poly(r),
        2 => -sin_poly(r),
        _ => -cos_poly(r),
    }
}

/// Cosine of `x`, f32.
#[inline]
pub fn cos(x: f32) -> f32 {
    let (_, c) = sin_cos(x);
    c
}

/// Retained for reference: cos by its own quadrant table.
#[cfg(test)]
fn cos_direct(x: f32) -> f32 {
    let (r, q) = reduce(x);
    match q {
        0 => cos_poly(r),
        1 => -sin_poly(r),
        2 => -cos_poly(r),
        _ => sin_poly(r),
    }
}

/// True when `R` has single precision (f32-like); a compile-time constant after inlining.
#[inline(always)]
pub fn is_single_precision<R: Real>() -> bool {
    R::of(1.0 + 1.0e-10).to_f64() == 1.0
}

/// Sine and cosine over any [`Real`]: the fast f32 polynomial for single precision, the
/// type's own (`libm`) `sin`/`cos` otherwise.
///
/// For `R = f32` the `f32 → f64 → f32` round trip folds away after inlining.
#[inline(always)]
pub fn sin_cos_real<R: Real>(x: R) -> (R, R) {
    if is_single_precision::<R>() {
        let (s, c) = sin_cos(x.to_f64() as f32);
        (R::of(s as f64), R::of(c as f64))
    } else {
        (x.sin(), x.cos())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadrants_and_specials() {
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
        let (s, c) = sin_cos(core::f32::consts::FRAC_PI_2);
        assert!((s - 1.0).abs() < 1e-7 && c.abs() < 1e-7);
        assert!(sin(f32::NAN).is_nan() && cos(f32::INFINITY).is_nan());
        assert!((sin(1.0e6) as f64 - libm::sin(1.0e6)).abs() < 1e6 * 1.8e-7 + 1e-6);
        for x in [0.3f32, 2.0, -4.0, 100.0] {
            assert_eq!(sin(x), sin_direct(x));
            assert_eq!(cos(x), cos_direct(x));
        }
        assert!(is_single_precision::<f32>() && !is_single_precision::<f64>());
    }
}
