//! Fast single-precision sine, cosine, square root, arc tangent and rounding for the servo loop.
//!
//! **Rounding to an integer** ([`round_i32`]): `libm::roundf` is a software function
//! (with its `truncf` and `copysignf` on the M7, whose FPv4/FPv5-SP subset as targeted has no
//! `VRINTA`); the FPU's truncating conversion `VCVT` and one comparison of
//! the remainder give the same integer for every f32.
//!
//! On the Cortex-M7F `libm::sinf` / `libm::cosf` compute in software doubles; the
//! functions here use only f32 arithmetic (a short polynomial each).
//!
//! **Square root** ([`sqrt`]): on hard-float ARM targets (`target_abi = "eabihf"`: the
//! Cortex-M4F's FPv4-SP and the M7's FPv5 both have it) the FPU's `VSQRT.F32`, through the
//! one `unsafe` block of gait-core (module `vfp`); it is IEEE 754 correctly rounded, as
//! `libm::sqrtf` is, so the results are bit-identical — `libm::sqrtf` is a software square
//! root, `VSQRT` one instruction plus two register moves.
//! Elsewhere (the FPU-less Cortex-M3, the host) `libm::sqrtf`.
//!
//! **Arc tangent** ([`atan2`], Cephes `atanf`): with `t = min(|y|, |x|) / max(|y|, |x|)` in
//! [0, 1], `t > tan(π/8)` is reduced by `atan t = π/4 + atan((t − 1)/(t + 1))`, then for
//! `|u| ≤ tan(π/8)`, `z = u²`,
//!
//! ```text
//! atan u ≈ u + u·z·(A1 + z·(A2 + z·(A3 + z·A4)))
//! ```
//!
//! and the octant is restored: `π/2 − a` when |y| > |x|, `π − a` for x < 0 (or −0), the sign
//! of y. One division, no `f64`, no table; |error| ≤ [`ATAN2_MAX_ERR`] rad (checked against
//! `f64` on a dense grid), NaN in → NaN out, signed zeros and infinities as `libm::atan2f`.
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

use crate::maths::real::Real;

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

/// atan polynomial coefficients (Cephes `atanf`, |u| ≤ tan(π/8)).
const A1: f32 = -3.333_295e-1; // f32 of -3.333_294_927e-1
const A2: f32 = 1.997_771_1e-1; // f32 of 1.997_771_106e-1
const A3: f32 = -1.387_768_5e-1; // f32 of -1.387_768_56e-1
const A4: f32 = 8.053_744_6e-2; // f32 of 8.053_744_495e-2
/// tan(π/8) = √2 − 1.
const TAN_PI_8: f32 = 0.414_213_57; // f32 of √2 − 1

/// Bound on |`atan2` − the exact value| over all finite arguments, rad (the test
/// `atan2_agrees_with_f64` measures it on a dense grid of angles and magnitudes).
pub const ATAN2_MAX_ERR: f32 = 3.6e-7;

/// The FPU's square root (`VSQRT.F32`), on hard-float ARM targets only.
#[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
#[allow(unsafe_code)]
mod vfp {
    /// `VSQRT.F32` of `x`: IEEE 754 correctly rounded (NaN for x < 0).
    #[inline(always)]
    pub fn sqrt(x: f32) -> f32 {
        let out: u32;
        // SAFETY: the instructions read and write only `s0` (declared clobbered) and the two
        // core registers given as operands; no memory, no stack, no flags. Every `eabihf`
        // ARM target has a single-precision FPU with VSQRT (FPv4-SP, FPv5), and cortex-m-rt
        // enables the FPU before `main`. (rustc 1.95 refuses `sreg` operands on these
        // targets, hence the moves through core registers.)
        unsafe {
            core::arch::asm!(
                "vmov s0, {x}",
                "vsqrt.f32 s0, s0",
                "vmov {out}, s0",
                x = in(reg) x.to_bits(),
                out = lateout(reg) out,
                out("s0") _,
                options(pure, nomem, nostack, preserves_flags),
            );
        }
        f32::from_bits(out)
    }
}

/// Square root of `x`, f32: `VSQRT.F32` on hard-float ARM, `libm::sqrtf` elsewhere (the
/// same correctly rounded result; NaN for x < 0).
#[inline(always)]
pub fn sqrt(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        vfp::sqrt(x)
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

/// `libm::roundf(x) as i32` — nearest, half away from zero, saturating at the `i32` range,
/// NaN → 0. On hard-float ARM without the library call: `t = x as i32` (truncation) and the
/// remainder `x − t`, exact in f32 wherever x has a fraction (|x| < 2²³), decides ±1 — the
/// same integer for every f32 (test `round_i32_is_roundf_as_i32`); elsewhere `libm::roundf`.
#[inline]
pub fn round_i32(x: f32) -> i32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        round_i32_by_truncation(x)
    }
    // In soft float (the FPU-less Cortex-M3) the conversions and the subtraction are library
    // calls too: `libm::roundf` is the cheaper one there.
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::roundf(x) as i32
    }
}

/// [`round_i32`] on an FPU: truncation, then the remainder decides (tested on every target).
#[inline]
#[cfg_attr(
    not(any(test, all(target_arch = "arm", target_abi = "eabihf"))),
    allow(dead_code)
)]
fn round_i32_by_truncation(x: f32) -> i32 {
    let t = x as i32;
    let frac = x - t as f32;
    if frac >= 0.5 {
        t.saturating_add(1)
    } else if frac <= -0.5 {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// Arc tangent of `y / x` in [−π, π], f32 (see the module docs; |error| ≤ [`ATAN2_MAX_ERR`]).
#[inline]
pub fn atan2(y: f32, x: f32) -> f32 {
    use core::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    if x.is_nan() || y.is_nan() {
        return x + y;
    }
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = if ay > ax { (ax, ay) } else { (ay, ax) };
    // t = num / den in [0, 1]; 0/0 is 0 (signs below), ∞/∞ is 1 (the diagonals).
    let t = if den == 0.0 {
        0.0
    } else if num == f32::INFINITY {
        1.0
    } else {
        num / den
    };
    let (base, u) = if t > TAN_PI_8 {
        (FRAC_PI_4, (t - 1.0) / (t + 1.0))
    } else {
        (0.0, t)
    };
    let z = u * u;
    let mut a = base + (u + u * z * (A1 + z * (A2 + z * (A3 + z * A4))));
    if ay > ax {
        a = FRAC_PI_2 - a;
    }
    if x.is_sign_negative() {
        a = PI - a;
    }
    if y.is_sign_negative() {
        -a
    } else {
        a
    }
}

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

/// Cosine of `x`, f32.
#[inline]
pub fn cos(x: f32) -> f32 {
    let (_, c) = sin_cos(x);
    c
}

/// Retained for reference: sin of `x` plus `quarters` quarter turns by its own quadrant table
/// (independent of [`sin_cos`]'s): `quarters` 0 is sin x, 1 is cos x = sin(x + π/2).
#[cfg(test)]
fn sin_direct(x: f32, quarters: u32) -> f32 {
    let (r, q) = reduce(x);
    match (q + quarters) % 4 {
        0 => sin_poly(r),
        1 => cos_poly(r),
        2 => -sin_poly(r),
        _ => -cos_poly(r),
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
    extern crate std;

    #[test]
    fn round_i32_is_roundf_as_i32() {
        let check = |x: f32| {
            let want = libm::roundf(x) as i32;
            assert_eq!(
                round_i32_by_truncation(x),
                want,
                "{x:e} ({:#010x})",
                x.to_bits()
            );
            assert_eq!(round_i32(x), want);
        };
        // Every 997th bit pattern (both signs, NaNs and infinities included) …
        let mut b = 0u32;
        loop {
            check(f32::from_bits(b));
            match b.checked_add(997) {
                Some(n) => b = n,
                None => break,
            }
        }
        // … and every f32 within 64 ulps of each half-integer and integer up to ±2²⁴ in steps
        // of 1/4 near 0 and the servo range, plus the i32 limits.
        for k in -40_000i32..=40_000 {
            for base in [k as f32 * 0.25, k as f32 * 0.25 + 4096.0, k as f32 * 409.6] {
                let mut x = base;
                for _ in 0..64 {
                    check(x);
                    check(-x);
                    x = f32::from_bits(x.to_bits().wrapping_add(1));
                }
                let mut x = base;
                for _ in 0..64 {
                    check(x);
                    x = f32::from_bits(x.to_bits().wrapping_sub(1));
                }
            }
        }
        for x in [
            0.5,
            -0.5,
            0.499_999_97,
            -0.499_999_97,
            8_388_607.5,
            -8_388_607.5,
            2_147_483_520.0,
            2_147_483_648.0,
            -2_147_483_648.0,
            -2_147_483_904.0,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -0.0,
            f32::MIN_POSITIVE,
        ] {
            check(x);
        }
    }

    #[test]
    fn sqrt_is_correctly_rounded() {
        for k in 0..20_000u32 {
            let x = f32::from_bits(0x0080_0000 + k.wrapping_mul(104_729) % 0x7F00_0000);
            let r = sqrt(x);
            // Correct rounding: r is the f32 nearest to the exact root (checked in f64).
            let e = (x as f64).sqrt();
            let below = f32::from_bits(r.to_bits() - 1) as f64;
            let above = f32::from_bits(r.to_bits() + 1) as f64;
            assert!((r as f64 - e).abs() <= (below - e).abs().min((above - e).abs()));
        }
        assert_eq!(sqrt(0.0), 0.0);
        assert_eq!(sqrt(4.0), 2.0);
        assert!(sqrt(-1.0).is_nan() && sqrt(f32::NAN).is_nan());
        assert_eq!(sqrt(f32::INFINITY), f32::INFINITY);
    }

    #[test]
    fn atan2_agrees_with_f64() {
        let mut worst = 0.0f64;
        for i in 0..20_000 {
            let th = -3.2 + 6.4 * i as f64 / 20_000.0;
            for r in [1e-30f64, 1e-6, 0.031, 1.0, 7.3, 1e6, 1e30] {
                let (y, x) = ((r * th.sin()) as f32, (r * th.cos()) as f32);
                let err = (atan2(y, x) as f64 - (y as f64).atan2(x as f64)).abs();
                worst = worst.max(err);
            }
        }
        std::println!("fastmath::atan2 worst error {worst:e} rad");
        assert!(worst <= ATAN2_MAX_ERR as f64, "worst {worst:e}");
        // Bounds from the f32 rounding of π (8.7e-8) and the polynomial's ≈ 1e-7: the bound
        // is not loose by more than 2×.
        assert!(
            worst > ATAN2_MAX_ERR as f64 / 2.0,
            "worst {worst:e}: tighten the bound"
        );
    }

    #[test]
    fn atan2_specials_match_libm() {
        let v = [
            0.0f32,
            -0.0,
            1.0,
            -1.0,
            0.5,
            -2.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        for &y in &v {
            for &x in &v {
                let (a, b) = (atan2(y, x), libm::atan2f(y, x));
                assert!(
                    (a - b).abs() <= ATAN2_MAX_ERR,
                    "atan2({y}, {x}) = {a}, libm {b}"
                );
                assert_eq!(
                    a.is_sign_negative(),
                    b.is_sign_negative(),
                    "atan2({y}, {x})"
                );
            }
        }
        assert!(atan2(f32::NAN, 1.0).is_nan() && atan2(1.0, f32::NAN).is_nan());
    }

    #[test]
    fn quadrants_and_specials() {
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
        let (s, c) = sin_cos(core::f32::consts::FRAC_PI_2);
        assert!((s - 1.0).abs() < 1e-7 && c.abs() < 1e-7);
        assert!(sin(f32::NAN).is_nan() && cos(f32::INFINITY).is_nan());
        assert!((sin(1.0e6) as f64 - libm::sin(1.0e6)).abs() < 1e6 * 1.8e-7 + 1e-6);
        for x in [0.3f32, 2.0, -4.0, 100.0] {
            assert_eq!(sin(x), sin_direct(x, 0));
            assert_eq!(cos(x), sin_direct(x, 1));
        }
        assert!(is_single_precision::<f32>() && !is_single_precision::<f64>());
    }
}
