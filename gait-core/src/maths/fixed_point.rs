//! Fixed-point numbers for cores without an FPU (Cortex-M0/M3): the formats, conversions to and
//! from `f32`, products, and the integer exponential and sine/cosine of the fixed-point sampler
//! ([`crate::trajectory::fixed_sampler`]) and IK ([`crate::kinematics::fixed_ik`]).
//!
//! Format: every length, velocity and time is `I16F16` (the `fixed` crate): range ±32,768 m,
//! resolution 2⁻¹⁶ m ≈ 0.015 mm — thirty times finer than the 0.5 mm budget, and a kid-size
//! robot's walk never leaves the range. Factors in [0, 1] (the exponentials e^{−ω(D−s)}, e^{−ωs},
//! sin, cos) are `I2F30` (resolution 9.3e-10). Products are formed in `i64` and shifted back, so
//! nothing overflows; every operation saturates instead of panicking.

use crate::error::GaitError;
use fixed::types::{I16F16, I2F30};

/// A length (m), velocity (m/s) or time (s) in the sampler's fixed-point format.
pub type Fx = I16F16;
/// A factor in [−2, 2) (exponentials, sines).
pub type Fac = I2F30;

pub(crate) const ONE_FAC: i64 = 1 << 30;

/// f32 → `Fx`, saturating; non-finite becomes an error.
pub fn fx(v: f32) -> Result<Fx, GaitError> {
    if !v.is_finite() {
        return Err(GaitError::NonFinite);
    }
    if v.abs() >= 32_767.0 {
        return Err(GaitError::FixedPointOverflow);
    }
    Ok(Fx::saturating_from_num(v))
}

/// `v` saturated to the `i32` range.
pub(crate) fn sat32(v: i64) -> i32 {
    v.clamp(i32::MIN as i64, i32::MAX as i64) as i32
}

/// `a` (Fx) times `f` (Fac).
pub(crate) fn mul_fac(a: Fx, f: i64) -> Fx {
    Fx::from_bits(sat32((a.to_bits() as i64 * f) >> 30))
}

/// `a` times `b`, both Fx.
pub(crate) fn mul_fx(a: Fx, b: Fx) -> Fx {
    Fx::from_bits(sat32((a.to_bits() as i64 * b.to_bits() as i64) >> 16))
}

/// 2³⁰/k for k = 1..=10: Horner steps multiply instead of divide (no 64-bit division, which
/// is a library call on Cortex-M).
const INV: [i32; 11] = [
    0,
    1_073_741_824,
    536_870_912,
    357_913_941,
    268_435_456,
    214_748_365,
    178_956_971,
    153_391_689,
    134_217_728,
    119_304_647,
    107_374_182,
];
/// 2³⁰/((2k)(2k+1)) and 2³⁰/((2k−1)(2k)) for k = 1..=4 (sine and cosine Taylor steps).
const INV_SIN: [i32; 5] = [0, 178_956_971, 53_687_091, 25_565_282, 14_913_081];
const INV_COS: [i32; 5] = [0, 536_870_912, 89_478_485, 35_791_394, 19_173_962];

/// (a·b) >> 30 for Fac-scaled values (|a|, |b| < 2³²: the product fits i64).
pub(crate) fn mul30(a: i64, b: i64) -> i64 {
    (a * b) >> 30
}

/// (a·b) >> 30 of two `i32`: one 32×32 → 64-bit multiply (`smull`), where the `i64` form
/// costs three multiplies on a 32-bit core; the same value as in `i64` whenever the result
/// fits `i32` (|a·b| < 2⁶¹: every use below keeps both factors within 2³⁰ or so).
#[inline(always)]
pub(crate) fn mul30_32(a: i32, b: i32) -> i32 {
    ((i64::from(a) * i64::from(b)) >> 30) as i32
}

/// e^{−x} for x ≥ 0 in Fx, as a Fac (bits, 2³⁰ = 1). Negative x counts as 0.
pub fn exp_neg(x: Fx) -> i64 {
    let x16 = x.to_bits().max(0);
    const LN2_16: i32 = 45_426; // ln 2 · 2^16 (only picks n; r is reduced exactly below)
    const LN2: i64 = 744_261_118; // ln 2 · 2^30
    let n = x16 / LN2_16;
    if n >= 31 {
        return 0;
    }
    // r in 2^30 units, r ∈ [0, ln 2) up to the rounding of LN2_16 (harmless for the series).
    let r = ((x16 as i64) << 14) - n as i64 * LN2;
    // e^{−r} by its Taylor polynomial to r¹⁰ (Horner): truncation < ln2¹¹/11! ≈ 4e-10.
    // In i32, the same values as in i64: |r| < 2³⁰, every Horner value in [0, 2³⁰], the
    // factors 2³⁰/k ≤ 2³⁰; written out (no loop).
    let r = r as i32;
    const ONE: i32 = ONE_FAC as i32;
    let [_, i1, i2, i3, i4, i5, i6, i7, i8, i9, i10] = INV;
    let step = |acc: i32, inv: i32| ONE.wrapping_sub(mul30_32(mul30_32(acc, r), inv));
    let acc = step(step(step(step(step(ONE, i10), i9), i8), i7), i6);
    let acc = step(step(step(step(step(acc, i5), i4), i3), i2), i1);
    i64::from(acc) >> n
}

/// sin and cos of `x` (rad, Fx) as Fac bits.
pub fn sin_cos(x: Fx) -> (i64, i64) {
    // Reduce to [−π/4, π/4] by quadrant q (32-bit division picks q; r is exact in 2^30 units).
    const HALF_PI_16: i32 = 102_944; // π/2 · 2^16
    const HALF_PI: i64 = 1_686_629_713; // π/2 · 2^30
    let x16 = x.to_bits();
    let q = x16.saturating_add(HALF_PI_16 / 2).div_euclid(HALF_PI_16);
    let r = ((x16 as i64) << 14) - q as i64 * HALF_PI;
    // Taylor to r⁹ / r⁸: |r| ≤ π/4 → error < (π/4)^10/10! ≈ 2e-8. In i32, the same values as
    // in i64: |r| < π/4·2³⁰ + 10⁸ (q's 16-bit rounding of π/2 over the whole Fx range) < 2³⁰,
    // r² and every Horner value in [0, 2³⁰], the factors below 2³⁰; written out (no loop).
    let r = r as i32;
    let r2 = mul30_32(r, r);
    const ONE: i32 = ONE_FAC as i32;
    let [_, s1, s2, s3, s4] = INV_SIN;
    let [_, c1, c2, c3, c4] = INV_COS;
    let step = |acc: i32, inv: i32| ONE.wrapping_sub(mul30_32(mul30_32(acc, r2), inv));
    let s = step(step(step(step(ONE, s4), s3), s2), s1);
    let c = step(step(step(step(ONE, c4), c3), c2), c1);
    let (s, c) = (i64::from(mul30_32(s, r)), i64::from(c));
    match q.rem_euclid(4) {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// `v` (f32) as the nearest `Fx` (ties to even), saturating at the ends, NaN → 0: the value
/// of `Fx::saturating_from_num(v)` but total (that one panics on NaN) and in 32-bit integer
/// steps (the `fixed` crate's conversion is several times longer on cores without an FPU).
///
/// v = ±m·2^(e − 150) with m the 24-bit significand (e the biased exponent), so the `Fx` bits
/// are m·2^(e − 134): a left shift below 2³¹ for e − 134 ∈ [0, 7], a rounding right shift for
/// e < 134 (0 when the shift passes 24: below half an Fx step), saturation above.
pub fn fx_sat(v: f32) -> Fx {
    let bits = v.to_bits();
    let negative = bits >> 31 != 0;
    let e = (bits >> 23) & 0xFF;
    let frac = bits & 0x7F_FFFF;
    if e == 0xFF && frac != 0 {
        return Fx::ZERO; // NaN
    }
    // |v|·2¹⁶ rounded, or None above the range (∞ included).
    let magnitude: Option<u32> = if e >= 134 + 8 {
        None
    } else if e >= 134 {
        Some((frac | 0x80_0000) << (e - 134))
    } else if e + 25 <= 134 {
        Some(0) // |v| < 2⁻¹⁷: zero and subnormals too
    } else {
        let m = frac | 0x80_0000;
        let r = 134 - e; // 1..=24
        let (q, rem, half) = (m >> r, m & ((1 << r) - 1), 1 << (r - 1));
        Some(q + u32::from(rem > half || (rem == half && q & 1 == 1)))
    };
    Fx::from_bits(match (magnitude, negative) {
        (Some(m), false) => i32::try_from(m).unwrap_or(i32::MAX),
        (Some(m), true) => 0i32.checked_sub_unsigned(m).unwrap_or(i32::MIN),
        (None, false) => i32::MAX,
        (None, true) => i32::MIN,
    })
}

/// `x` as the nearest f32 (ties to even): the value of `x.to_num::<f32>()`, in 32-bit integer
/// steps. On cores without an FPU `to_num` goes through the `fixed` crate's generic helper with
/// 64-bit shifts (library calls, 21 values a sample); this uses 32-bit steps only.
///
/// |x|·2¹⁶ = m ∈ [2^t, 2^(t+1)): the 24-bit significand is m shifted to [2²³, 2²⁴), rounded
/// to nearest even when t > 23 (it may round up to 2²⁴); the biased exponent is t − 16 + 127,
/// and adding the significand with its hidden bit to (t + 110)·2²³ gives the exponent field
/// and carries a round-up into it.
pub fn fx_to_f32(x: Fx) -> f32 {
    let b = x.to_bits();
    if b == 0 {
        return 0.0;
    }
    let sign = (b as u32) & 0x8000_0000;
    let m = b.unsigned_abs(); // 1..=2³¹
    let t = 31 - m.leading_zeros();
    let significand = if t <= 23 {
        m << (23 - t)
    } else {
        let s = t - 23; // 1..=8
        let (q, rem, half) = (m >> s, m & ((1 << s) - 1), 1 << (s - 1));
        q + u32::from(rem > half || (rem == half && q & 1 == 1))
    };
    f32::from_bits(sign | (((t + 110) << 23) + significand))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `sin_cos` as it was, in `i64` throughout.
    fn sin_cos_i64(x: Fx) -> (i64, i64) {
        const HALF_PI_16: i32 = 102_944;
        const HALF_PI: i64 = 1_686_629_713;
        let x16 = x.to_bits();
        let q = x16.saturating_add(HALF_PI_16 / 2).div_euclid(HALF_PI_16);
        let r = ((x16 as i64) << 14) - q as i64 * HALF_PI;
        let r2 = mul30(r, r);
        let mut s = ONE_FAC;
        let mut c = ONE_FAC;
        for k in (1..=4).rev() {
            s = ONE_FAC - mul30(mul30(s, r2), i64::from(INV_SIN[k]));
            c = ONE_FAC - mul30(mul30(c, r2), i64::from(INV_COS[k]));
        }
        let s = mul30(s, r);
        match q.rem_euclid(4) {
            0 => (s, c),
            1 => (c, -s),
            2 => (-s, -c),
            _ => (-c, s),
        }
    }

    /// `exp_neg` as it was, in `i64` throughout.
    fn exp_neg_i64(x: Fx) -> i64 {
        let x16 = x.to_bits().max(0);
        let n = x16 / 45_426;
        if n >= 31 {
            return 0;
        }
        let r = ((x16 as i64) << 14) - n as i64 * 744_261_118;
        let mut acc = ONE_FAC;
        for inv in INV.iter().skip(1).rev() {
            acc = ONE_FAC - mul30(mul30(acc, r), i64::from(*inv));
        }
        acc >> n
    }

    #[test]
    fn exp_neg_in_i32_is_the_i64_evaluation() {
        // Every 2⁻¹⁶ up to 24 (where it underflows), a sweep of the rest, both ends.
        let ends = [i32::MIN, -1, 0, i32::MAX];
        for b in (0..24 << 16)
            .chain((0..=i32::MAX).step_by(65_537))
            .chain(ends)
        {
            let x = Fx::from_bits(b);
            assert_eq!(exp_neg(x), exp_neg_i64(x), "x bits {b}");
        }
    }

    #[test]
    fn sin_cos_in_i32_is_the_i64_evaluation() {
        // The whole Fx range in steps of 2⁻¹⁶·65,537 (odd: every residue class of the quadrant
        // reduction), every 2⁻¹⁶ around 0 and the two ends, bit for bit.
        let ends = (-70_000..70_000).chain([i32::MIN, i32::MIN + 1, i32::MAX - 1, i32::MAX]);
        for b in (i32::MIN..=i32::MAX).step_by(65_537).chain(ends) {
            let x = Fx::from_bits(b);
            assert_eq!(sin_cos(x), sin_cos_i64(x), "x bits {b}");
        }
    }

    /// `fx_to_f32` is `to_num::<f32>` (the correctly rounded conversion): every value near
    /// each power of two (where the rounding changes), every 2¹⁶-th bit pattern, the ends.
    #[test]
    fn fx_to_f32_is_to_num() {
        let check = |b: i32| {
            let x = Fx::from_bits(b);
            let (got, want) = (fx_to_f32(x), x.to_num::<f32>());
            assert_eq!(got.to_bits(), want.to_bits(), "bits {b}: {got} vs {want}");
        };
        for t in 0..31 {
            for d in -600..=600 {
                let b = (1i64 << t) + d;
                for b in [b, -b] {
                    if let Ok(b) = i32::try_from(b) {
                        check(b);
                    }
                }
            }
        }
        for b in (i32::MIN..=i32::MAX).step_by(65_521) {
            check(b);
        }
        for b in [
            0,
            1,
            -1,
            i32::MAX,
            i32::MIN,
            i32::MAX - 1,
            i32::MIN + 1,
            0x0180_0000,
        ] {
            check(b);
        }
        // Ties to even: 2²⁴ + 1 and 2²⁴ + 3 (in units of 2⁻¹⁶) sit halfway between f32s.
        assert_eq!(fx_to_f32(Fx::from_bits((1 << 24) + 1)), 256.0);
        assert_eq!(
            fx_to_f32(Fx::from_bits((1 << 24) + 3)),
            256.0 + 4.0 / 65536.0
        );
    }

    /// `fx_sat` is `Fx::saturating_from_num` wherever that is defined (not NaN): every
    /// 4093rd f32 bit pattern, every value around each rounding tie and each power of two of
    /// the Fx range, the range's ends and beyond; NaN → 0.
    #[test]
    fn fx_sat_is_saturating_from_num() {
        let check = |v: f32| {
            if !v.is_nan() {
                let (got, want) = (fx_sat(v), Fx::saturating_from_num(v));
                assert_eq!(got, want, "{v:e} ({:#010x})", v.to_bits());
            }
        };
        for b in (0..=u32::MAX).step_by(4093) {
            check(f32::from_bits(b));
        }
        for e in -20i32..=16 {
            let p = libm::exp2f(e as f32);
            for k in -300i32..=300 {
                // Around 2^e and around ties k + ½ Fx steps.
                let steps = (k as f32 + 0.5) / 65536.0;
                for v in [p * (1.0 + k as f32 * f32::EPSILON), p + steps, steps] {
                    check(v);
                    check(-v);
                }
            }
        }
        for v in [
            0.0, -0.0, 32767.99, 32768.0, -32768.0, -32768.01, 1e30, -1e30, 1e-40,
        ] {
            check(v);
        }
        check(f32::INFINITY);
        check(f32::NEG_INFINITY);
        assert_eq!(fx_sat(f32::NAN), Fx::ZERO);
        assert_eq!(fx_sat(-f32::NAN), Fx::ZERO);
    }
}
