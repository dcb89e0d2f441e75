//! The two-leg inverse kinematics in fixed point, for cores without an FPU (Cortex-M0/M3):
//! with [`crate::trajectory::fixed_sampler::FixedSampler`] the whole path sampler → IK → joint targets needs
//! no floating point per sample.
//!
//! # Method
//!
//! The chain, conventions, clamping and report are those of [`crate::kinematics::leg`] (see its
//! module documentation for the equations); only the arithmetic differs:
//!
//! - Inputs and outputs are [`Fx`] (`I16F16`): positions in m, angles in rad (resolution
//!   2⁻¹⁶ ≈ 1.5e-5 rad, so an output angle is within 7.6e-6 rad of the exact one plus the
//!   method error below).
//! - Internally every length is an `i64` in 2⁻³⁰ m units ("P30", resolution 9.3e-10 m) and every
//!   rotation-matrix entry, sine and cosine an `i64` in 2⁻³⁰ units (`Fac` bits); products are
//!   formed in `i64` (at most 2⁶² in magnitude, bounds noted at each step) and shifted back.
//! - Square roots: [`isqrt`], exact integer square root: Newton's iteration with 32-bit `udiv`
//!   for 32-bit operands; for wider ones a 16-bit estimate from the top bits and one Newton step
//!   whose division is two 32-bit `udiv`s (no 64-bit division).
//! - Angles: [`atan2_fac`], octant reduction, one 32-bit division seeding a Newton reciprocal
//!   step (`i64` multiplications only) for the ratio in [0, 1], then a degree-17 odd polynomial
//!   (Chebyshev fit in t², measured |error| < 1.6e-8 rad). No 64-bit division anywhere: the
//!   Cortex-M3 build of the per-sample path has one `udiv` and no division or float calls.
//! - Sines and cosines: [`crate::maths::fixed_point::sin_cos`] (|error| < 4e-7).
//! - The knee and the ankle pitch come without any division:
//!   `a = √((L1+L2)² − D²)`, `b = √(D² − (L1−L2)²)` (exact integer differences, so there is no
//!   cancellation near the straight leg), `q3 = 2·atan2(a, b)` and, since
//!   `L1·sin q3 = 2ab/(4L2)` and `L2 + L1·cos q3 = (4L2² + b² − a²)/(4L2)`,
//!   `q4 = −atan2(2ab, 4L2² + b² − a²) − atan2(r_x, w_z)` (atan2 ignores the common factor).
//! - The reach clamp does not rescale `r`: every later use of `r` is a ratio (atan2), so only the
//!   clamped distance D enters the knee.
//! - The hip of level poses (the walk's: pelvis and soles without roll and pitch) in closed
//!   form: R_P = Rz(ψ_P), R_F = Rz(ψ_F), so M = Rz(ψ_F − ψ_P)·Rx(−q5)·Ry(−(q3 + q4)) is already
//!   the hip's Rz(q0)·Rx(q1)·Ry(q2): q0 = ψ_F − ψ_P, q1 = −q5, q2 = −(q3 + q4), inside
//!   (−π, π) with |q5| < π/2 (`level_hip`; the general path's three atan2 give the same bits).
//!
//! Full poses are supported: pelvis and feet roll, pitch and yaw (the walk uses level poses).
//!
//! # Totality
//!
//! Every input is a valid number in fixed point. Positions beyond ±[`MAX_POSITION`] m are
//! clamped and flagged (`invalid_input`), like the float IK; the hip–ankle vector is scaled down
//! by a power of two when it exceeds 1 m so that every product stays inside `i64`; the leg
//! lengths, hip offset and ankle height are limited to 0.5 m at construction (a kid-size leg is
//! 0.1 m). The result is always within the joint limits (converted inward, so the `Fx` limits
//! are inside the `f64` ones), and nothing panics.
//!
//! # Accuracy (tests/fixed_ik.rs)
//!
//! Against `LegKinematics::<f64>` on the same (fixed-point) targets: within 1.6e-5 rad per joint
//! for level poses and 2.3e-5 rad with ±0.15 rad pelvis/foot roll and pitch (the 2e-4 rad budget;
//! half of it is the 2⁻¹⁶ rad output resolution); the `f64` forward kinematics of the fixed-point
//! angles lands within 4 µm of the target. The Table 2 walk through
//! [`crate::trajectory::fixed_sampler::FixedSampler`] and this IK stays within 4.5e-4 rad of the `f64`
//! sampler and IK (mostly the sampler's share).

use crate::kinematics::leg::{KNEE_MIN_BEND, MAX_POSITION};
use crate::maths::fixed_point::{mul30_32, sin_cos, Fx};
use crate::robot::{Robot, Side, JOINTS_PER_LEG, LEG_JOINTS};
use crate::trajectory::fixed_sampler::{FixedFoot, FixedSample};

const ONE: i64 = 1 << 30;
/// π in 2⁻³⁰ rad units.
const PI_30: i64 = 3_373_259_426;
/// π/2 in 2⁻³⁰ rad units.
const HALF_PI_30: i64 = 1_686_629_713;
/// 2π in 2⁻¹⁶ rad units (Fx bits).
const TWO_PI_16: i64 = 411_775;
/// π in 2⁻¹⁶ rad units (Fx bits), rounded down: |a| ≤ PI_16 means |a| < π.
const PI_16: i64 = 205_887;
/// π/2 in 2⁻¹⁶ rad units (Fx bits), rounded down (π/2·2¹⁶ = 102,943.7): |a| ≤ HALF_PI_16 means
/// |a| < π/2.
const HALF_PI_16: i64 = 102_943;

/// A pose in fixed point: position (m) and ZYX angles (rad), `R = Rz(yaw)·Ry(pitch)·Rx(roll)`
/// (the convention of [`crate::kinematics::leg::Pose`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FixedPose {
    /// Position x (forward), m.
    pub x: Fx,
    /// Position y (left), m.
    pub y: Fx,
    /// Position z (up), m.
    pub z: Fx,
    /// Roll about x, rad (applied first).
    pub roll: Fx,
    /// Pitch about y, rad.
    pub pitch: Fx,
    /// Yaw about z, rad (applied last).
    pub yaw: Fx,
}

impl FixedPose {
    /// A pose from position and ZYX angles.
    pub fn new(x: Fx, y: Fx, z: Fx, roll: Fx, pitch: Fx, yaw: Fx) -> Self {
        FixedPose {
            x,
            y,
            z,
            roll,
            pitch,
            yaw,
        }
    }

    /// A level pose (roll = pitch = 0) with the given heading.
    pub fn level(x: Fx, y: Fx, z: Fx, yaw: Fx) -> Self {
        FixedPose {
            x,
            y,
            z,
            roll: Fx::ZERO,
            pitch: Fx::ZERO,
            yaw,
        }
    }
}

/// Report of a fixed-point two-leg IK (the meaning of [`crate::kinematics::leg::LegsIkReport`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FixedIkReport {
    /// Reach deficit of the left and right leg, m (0 when reachable).
    pub reach_deficit: [Fx; 2],
    /// Bit i set when joint i of the 12 (left leg 0..6, right leg 6..12) was clamped.
    pub limited: u16,
    /// True when a position was beyond ±[`MAX_POSITION`] m and was clamped.
    pub invalid_input: bool,
}

impl FixedIkReport {
    /// True when either leg's target was not met exactly.
    pub fn clamped(&self) -> bool {
        self.limited != 0
            || self.reach_deficit[0] > Fx::ZERO
            || self.reach_deficit[1] > Fx::ZERO
            || self.invalid_input
    }
}

// ---------------------------------------------------------------------------------------------
// Primitives.

/// Floor of the square root of `n`, exact: `isqrt32` for 32-bit operands, `isqrt_wide`
/// above (no 64-bit division, no float).
pub fn isqrt(n: u64) -> u64 {
    let Ok(small) = u32::try_from(n) else {
        return isqrt_wide(n);
    };
    u64::from(isqrt32(small))
}

/// ⌊√m⌋ for a 32-bit m: Newton's iteration `x ← ⌊(x + ⌊m/x⌋)/2⌋` from above (one 32-bit
/// `udiv` a step), started at 2^⌈b/2⌉ ≥ √m (b the bit length of m, so the start is within a
/// factor 2). The relative error e goes to e²/(2(1+e)): 1, 0.25, 0.025, 3e-4, 5e-8 — after four
/// steps the iterate is ⌊√m⌋ or ⌊√m⌋ + 1 (√m < 2¹⁶), and the iteration stops at the first step
/// that does not decrease, ⌊√m⌋ (integer Newton from above never passes below ⌊√m⌋, by AM–GM).
fn isqrt32(m: u32) -> u32 {
    if m == 0 {
        return 0;
    }
    let bits = 32 - m.leading_zeros();
    // ≤ 2¹⁶: m / x and x + m / x stay below 2¹⁷.
    let mut x = 1u32 << bits.div_ceil(2);
    // Six steps suffice (see above); the bound only makes the loop visibly finite.
    for _ in 0..8 {
        let y = (x + m / x) >> 1;
        if y >= x {
            break;
        }
        x = y;
    }
    x
}

/// ⌊√n⌋ for n ≥ 2³², without a 64-bit division (the Cortex-M3 has only a 32-bit `udiv`):
///
/// 1. n = m·2^s + low with s even and m ∈ [2³⁰, 2³²): r₀ = ⌊√m⌋ ∈ [2¹⁵, 2¹⁶) ([`isqrt32`]), so
///    r = (r₀+1)·2^(s/2) ≥ √n with relative error δ ≤ 1/r₀ ≤ 2⁻¹⁵.
/// 2. One Newton step r' = ⌊(r + ⌊n/r⌋)/2⌋; ⌊n/r⌋ = ⌊⌊n/2^(s/2)⌋/(r₀+1)⌋, a number below 2⁴⁸
///    by one of 17 bits, in two 32-bit divisions (16-bit long division). r' ≥ ⌊√n⌋ (AM–GM) and
///    r' − √n ≤ √n·δ²/2 < 2³²·2⁻³¹ = 2.
/// 3. r' decreases while r'² > n: at most two steps.
fn isqrt_wide(n: u64) -> u64 {
    let bits = 64 - n.leading_zeros(); // 33..=64
    let s = (bits - 31) & !1; // even; n >> s has 31 or 32 bits
    let half = s / 2;
    let m = (n >> s) as u32;
    let d = isqrt32(m) + 1; // ≤ 2¹⁶
    let r = u64::from(d) << half;
    // ⌊(n >> half) / d⌋ with the numerator below 2⁴⁸ (64 − bits + … : bits − half ≤ 48).
    let num = n >> half;
    let hi = (num >> 16) as u32;
    let (q1, r1) = (hi / d, hi % d);
    let lo = (r1 << 16) | (num as u32 & 0xFFFF);
    let q = (u64::from(q1) << 16) + u64::from(lo / d);
    let mut x = (r + q) >> 1;
    // At most two corrections (step 3); the bound only makes the loop visibly finite. x² by
    // one 32×32 → 64-bit multiply: x ≥ 2³² is above √n (n < 2⁶⁴) and is decreased anyway.
    for _ in 0..4 {
        let low = x as u32;
        if u64::from(low) == x && u64::from(low) * u64::from(low) <= n {
            break;
        }
        x -= 1;
    }
    x
}

/// √x for x in Fx (negative counts as 0), rounded down to the Fx resolution.
pub fn sqrt(x: Fx) -> Fx {
    let b = x.to_bits().max(0) as u64;
    // √(b·2⁻¹⁶) = √(b·2¹⁶)·2⁻¹⁶; √(2⁴⁷) < 2³¹ fits.
    Fx::from_bits(isqrt(b << 16) as i32)
}

/// Degree-8 Chebyshev fit of atan(√u)/√u on u ∈ [0, 1], monomial coefficients × 2³⁰
/// (atan(t) = t·P(t²), |error| < 1e-8 rad before rounding).
const ATAN_COEF: [i32; 9] = [
    1_073_741_804,
    -357_910_756,
    214_661_091,
    -152_447_693,
    114_013_887,
    -80_067_369,
    45_244_929,
    -16_891_300,
    2_970_274,
];

/// num/den in 2⁻³⁰ units for 0 ≤ num ≤ den, den > 0 (result in [0, 2³⁰]). One 32-bit division
/// seeds 2⁶¹/den to 2⁻¹⁴; a Newton step (i64 multiplications) takes it to 2⁻²⁸.
///
/// After the normalisation every operand but the Newton step's error term fits 32 bits, so
/// the shifts and the last product are 32-bit work (`umull`), not 64-bit library shifts.
fn ratio30(num: u64, den: u64) -> i64 {
    // Normalise den to [2³⁰, 2³¹) (num ≤ den shifts along and stays < 2³¹).
    let sh = den.leading_zeros() as i32 - 33;
    let (n, d) = if sh >= 0 {
        // den < 2³¹ (and so num): 32-bit left shifts.
        ((num as u32) << sh, (den as u32) << sh)
    } else {
        let right = sh.unsigned_abs();
        (shr_to_u32(num, right), shr_to_u32(den, right))
    };
    // Seed: 2³¹ / (d >> 15), d >> 15 ∈ [2¹⁵, 2¹⁶): a u32 division, quotient ≈ 2⁴⁶/d.
    let d16 = d >> 15;
    let r0 = (1u32 << 31) / d16.max(1);
    // ≈ 2⁶¹/d ∈ (2³⁰, 2³¹].
    let r = i64::from(r0) << 15;
    // Newton: r ← r + r·(2⁶¹ − d·r)/2⁶¹; d·r < 2⁶², |e| ≲ 2⁴⁸, r·(e >> 16) < 2⁶³.
    let e = (1i64 << 61) - i64::from(d) * r;
    let r = r + ((r * (e >> 16)) >> 45);
    // r ∈ (2³⁰, 2³¹·(1 + 2⁻¹⁴)) after the step: a u32; n < 2³¹, so n·r < 2⁶³ by one `umull`.
    let q = (u64::from(n) * u64::from(r as u32)) >> 31;
    (q as i64).clamp(0, ONE)
}

/// `x >> s` for a shift s in 1..=33 whose result fits 32 bits, from the two 32-bit halves
/// (a variable 64-bit shift is a library call on the Cortex-M3).
#[inline(always)]
fn shr_to_u32(x: u64, s: u32) -> u32 {
    let (hi, lo) = ((x >> 32) as u32, x as u32);
    if s >= 32 {
        hi.wrapping_shr(s - 32)
    } else {
        // 1 ≤ s ≤ 31: the low bits of hi move into the top of the result.
        hi.wrapping_shl(32 - s) | (lo >> s)
    }
}

/// atan(t) for t ∈ [0, 1] in 2⁻³⁰ units, result in [0, π/4] (2⁻³⁰ rad).
///
/// In `i32` (the same values as in `i64`, so the same result): t and u = t² lie in [0, 2³⁰],
/// every coefficient below 2³⁰ in magnitude, and every Horner partial sum too (the largest,
/// 1,073,741,804, is P's constant term: measured over t ∈ [0, 1] in 200,000 steps).
fn atan_unit(t: i64) -> i64 {
    let t = t.clamp(0, ONE) as i32;
    let u = mul30_32(t, t);
    // Horner written out (no loop: on the M3 the loop's bookkeeping costs as much as a step);
    // `wrapping_add` never wraps (the bound above).
    let [c0, c1, c2, c3, c4, c5, c6, c7, c8] = ATAN_COEF;
    let step = |acc: i32, c: i32| c.wrapping_add(mul30_32(acc, u));
    let acc = step(
        step(
            step(step(step(step(step(step(c8, c7), c6), c5), c4), c3), c2),
            c1,
        ),
        c0,
    );
    i64::from(mul30_32(acc, t))
}

/// atan2(y, x) in 2⁻³⁰ rad, in [−π, π] (y and x in any common scale; atan2(0, 0) = 0,
/// atan2(0, x < 0) = π). |error| < 2e-8 rad; no 64-bit division.
pub fn atan2_fac(y: i64, x: i64) -> i64 {
    let (ay, ax) = (y.unsigned_abs(), x.unsigned_abs());
    let (num, den, swapped) = if ay > ax {
        (ax, ay, true)
    } else {
        (ay, ax, false)
    };
    if den == 0 {
        return 0;
    }
    let mut a = atan_unit(ratio30(num, den));
    if swapped {
        a = HALF_PI_30 - a;
    }
    if x < 0 {
        a = PI_30 - a;
    }
    if y < 0 {
        -a
    } else {
        a
    }
}

/// atan2(y, x) rounded to Fx rad (y and x in any common scale).
pub fn atan2(y: i64, x: i64) -> Fx {
    round_angle(atan2_fac(y, x))
}

/// 2⁻³⁰ rad → Fx, rounded to nearest (|a| ≤ π + small, so it fits).
#[inline(always)]
fn round_angle(a: i64) -> Fx {
    Fx::from_bits(((a + (1 << 13)) >> 14) as i32)
}

/// `a` wrapped into [−π, π] in Fx bits (0 for |a| ≥ 64 rad, like [`crate::trajectory::swing::wrap_pi`]).
fn wrap_pi(a: i64) -> i64 {
    if a.abs() >= 64 << 16 {
        return 0;
    }
    let mut x = a;
    for _ in 0..16 {
        if x > PI_16 {
            x -= TWO_PI_16;
        } else if x < -PI_16 {
            x += TWO_PI_16;
        } else {
            break;
        }
    }
    x
}

// ---------------------------------------------------------------------------------------------
// Rotations: columns of 3×3 matrices with entries in 2⁻³⁰ units.

type V3 = [i64; 3];
type Cols = [V3; 3];

/// sin, cos (Fac bits) with the exact (0, 1) for a zero angle.
#[inline(always)]
fn sc(a: Fx) -> (i64, i64) {
    if a == Fx::ZERO {
        (0, ONE)
    } else {
        sin_cos(a)
    }
}

/// `cu·u + cv·v` for unit-scale factors and columns (each product < 2⁶¹).
#[inline(always)]
fn comb(cu: i64, u: &V3, cv: i64, v: &V3) -> V3 {
    [
        (cu * u[0] + cv * v[0]) >> 30,
        (cu * u[1] + cv * v[1]) >> 30,
        (cu * u[2] + cv * v[2]) >> 30,
    ]
}

/// `a·b` >> 30 for |a_i|, |b_i| ≤ 2³¹ with one side ≤ ~2³⁰ (the sum stays < 2⁶³).
#[inline(always)]
fn dot(a: &V3, b: &V3) -> i64 {
    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) >> 30
}

/// Columns of `M·Ry(a)` given (sin a, cos a).
fn post_ry(m: &Cols, (s, c): (i64, i64)) -> Cols {
    [comb(c, &m[0], -s, &m[2]), m[1], comb(s, &m[0], c, &m[2])]
}

/// Columns of `M·Rx(a)` given (sin a, cos a).
fn post_rx(m: &Cols, (s, c): (i64, i64)) -> Cols {
    [m[0], comb(c, &m[1], s, &m[2]), comb(-s, &m[1], c, &m[2])]
}

/// Columns of `Rz(yaw)·Ry(pitch)·Rx(roll)`.
fn rot_cols(p: &FixedPose) -> Cols {
    if p.roll == Fx::ZERO && p.pitch == Fx::ZERO {
        // Rz(yaw) alone: the products below with sin = 0, cos = 2³⁰ (the same values).
        let (sy, cy) = sc(p.yaw);
        return [[cy, sy, 0], [-sy, cy, 0], [0, 0, ONE]];
    }
    let (sr, cr) = sc(p.roll);
    let (sp, cp) = sc(p.pitch);
    let (sy, cy) = sc(p.yaw);
    // Sines, cosines and their products lie within ±2³⁰ (Fac bits): each product is one
    // 32-bit multiply, the same value as `mul30` in i64; the sums stay in i64.
    let m = |a: i64, b: i64| i64::from(mul30_32(a as i32, b as i32));
    let (cysp, sysp) = (m(cy, sp), m(sy, sp));
    [
        [m(cy, cp), m(sy, cp), -sp],
        [m(cysp, sr) - m(sy, cr), m(sysp, sr) + m(cy, cr), m(cp, sr)],
        [m(cysp, cr) + m(sy, sr), m(sysp, cr) - m(cy, sr), m(cp, cr)],
    ]
}

/// The hip angles (q0, q1, q2) of level poses in closed form, or `None` outside its domain.
///
/// With level pelvis and foot, R_P = Rz(ψ_P) and R_F = Rz(ψ_F), so the hip's matrix
/// M = R_Pᵀ·R_F·Rx(−q5)·Ry(−(q3 + q4)) = Rz(ψ_F − ψ_P)·Rx(−q5)·Ry(−(q3 + q4)) is already in
/// the hip's Rz(q0)·Rx(q1)·Ry(q2) form: q0 = ψ_F − ψ_P, q1 = −q5, q2 = −(q3 + q4) — what the
/// general path's three atan2 return as long as every angle is inside (−π, π) and |q5| < π/2
/// (cos q1 > 0: atan2(m21, √(m01² + m11²)) = −q5 needs it); otherwise `None` and the general
/// path. The same bits: the general path recovers these Fx angles to ≈ 2e-8 rad, far from a
/// rounding boundary of the 2⁻¹⁶ rad grid (test `level_hip_is_the_general_hip`). It saves
/// per leg three atan2, a square root, two sines and cosines and the matrix products.
#[inline(always)]
fn level_hip(pelvis: &FixedPose, foot: &FixedPose, q5: Fx, q34: Fx) -> Option<(Fx, Fx, Fx)> {
    let level = |p: &FixedPose| p.roll == Fx::ZERO && p.pitch == Fx::ZERO;
    let yaw = i64::from(foot.yaw.to_bits()) - i64::from(pelvis.yaw.to_bits());
    let inside = |a: i64, lim: i64| -lim <= a && a <= lim;
    let ok = level(pelvis)
        && level(foot)
        && inside(yaw, PI_16)
        && inside(i64::from(q5.to_bits()), HALF_PI_16)
        && inside(i64::from(q34.to_bits()), PI_16);
    // Inside those bounds every negation and the difference fit i32.
    ok.then(|| {
        (
            Fx::from_bits(yaw as i32),
            Fx::from_bits(-q5.to_bits()),
            Fx::from_bits(-q34.to_bits()),
        )
    })
}

/// Positions clamped to ±[`MAX_POSITION`] (flagged); angles are used as they are.
fn sanitize(p: &FixedPose) -> (FixedPose, bool) {
    let lim = Fx::from_bits((MAX_POSITION as i32) << 16);
    let mut bad = false;
    let mut pos = |v: Fx| {
        if v > lim {
            bad = true;
            lim
        } else if v < -lim {
            bad = true;
            -lim
        } else {
            v
        }
    };
    let (x, y, z) = (pos(p.x), pos(p.y), pos(p.z));
    (FixedPose { x, y, z, ..*p }, bad)
}

/// f64 → i64 bits at scale 2^`frac`, rounded; non-finite → 0, clamped to ±`max`.
fn bits(v: f64, frac: i32, max: i64) -> i64 {
    if !v.is_finite() {
        return 0;
    }
    let s = libm::round(v * libm::exp2(frac as f64));
    if s >= max as f64 {
        max
    } else if s <= -max as f64 {
        -max
    } else {
        s as i64
    }
}

/// `v` clamped to `lim` (Fx bits), setting `bit` in `flags` when changed.
#[inline(always)]
fn limit(v: Fx, lim: &[Fx; 2], bit: u8, flags: &mut u8) -> Fx {
    if v < lim[0] {
        *flags |= bit;
        lim[0]
    } else if v > lim[1] {
        *flags |= bit;
        lim[1]
    } else {
        v
    }
}

// ---------------------------------------------------------------------------------------------
// The IK.

/// An angle limit (rad) as I16F16 bits rounded inward (`up`: toward +∞, for a lower limit),
/// saturating; 0 for a non-finite limit. One out-of-line copy: it takes f64 rounding, a library
/// call on FPU-less cores.
#[inline(never)]
fn rad_bits_inward(v: f64, up: bool) -> i32 {
    if !v.is_finite() {
        return 0;
    }
    let m = i32::MAX as f64;
    let s = v * 65536.0;
    let r = if up { libm::ceil(s) } else { libm::floor(s) };
    r.clamp(-m, m) as i32
}

/// cos x for x in [0, π] (a knee limit; x clamped to it, NaN taken as 0), f64, within 1e-15 of
/// libm's:
/// cos x = −cos(π − x) beyond π/2, then the Taylor series to x²⁰/20! (< 1e-18 on [0, π/2]).
/// Not `libm::cos`: its full argument reduction (never needed here) is ≈ 2.5 KB of flash on the
/// FPU-less M3, where this runs once.
fn cos_half_turn(x: f64) -> f64 {
    use core::f64::consts::{FRAC_PI_2, PI};
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, PI) };
    let (x, sign) = if x > FRAC_PI_2 {
        (PI - x, -1.0)
    } else {
        (x, 1.0)
    };
    let x2 = x * x;
    // Horner from the x²⁰ term down: 1 − x²/2!·(1 − x²/(3·4)·(1 − …)).
    let mut sum = 1.0;
    let mut k = 20.0;
    while k > 0.0 {
        sum = 1.0 - x2 / (k * (k - 1.0)) * sum;
        k -= 2.0;
    }
    sign * sum
}

/// Longest link length accepted (m): keeps every product of the knee step inside `i64`.
const MAX_LINK: f64 = 0.5;

/// The robot's leg description in fixed point, converted once, for the per-sample IK.
#[derive(Clone, Copy, Debug)]
pub struct FixedLegKinematics {
    /// Hip offset and ankle height, 2⁻³⁰ m.
    hip_offset_y: i64,
    ankle_height: i64,
    /// The sole point's (forward, outward) offset from the ankle's ground projection, 2⁻³⁰ m.
    sole_offset: [i64; 2],
    /// (L1 + L2)², (L1 − L2)², 4·L2², 2⁻⁶⁰ m².
    sum2: i64,
    diff2: i64,
    four_calf2: i64,
    /// Shortest and longest hip–ankle distance, 2⁻³⁰ m.
    d_min: i64,
    d_max: i64,
    /// [min, max] per joint, left leg then right leg, rounded inward.
    limits: [[[Fx; 2]; JOINTS_PER_LEG]; 2],
}

/// Output of one leg.
struct LegOut {
    q: [Fx; JOINTS_PER_LEG],
    deficit: Fx,
    limited: u8,
}

impl FixedLegKinematics {
    /// Converts the robot's geometry (lengths limited to 0.5 m) and joint limits (mirrored for
    /// the right leg as in [`Robot::joint_limit`]) to fixed point; the reach bounds are those of
    /// [`crate::kinematics::leg::LegKinematics`].
    pub fn new(robot: &Robot) -> Self {
        let g = &robot.geometry;
        let len = |v: f64| -> f64 {
            if v.is_finite() {
                v.abs().min(MAX_LINK)
            } else {
                0.0
            }
        };
        // A signed offset, limited to ±0.5 m as the lengths are.
        let offset = |v: f64| -> f64 {
            if v.is_finite() {
                v.clamp(-MAX_LINK, MAX_LINK)
            } else {
                0.0
            }
        };
        let (l1, l2) = (len(g.thigh), len(g.calf));
        let p30 = |v: f64| bits(v, 30, 1 << 62);
        let (t, c) = (p30(l1), p30(l2));
        let knee = robot.joint_limit(Side::Left, 3);
        let reach = |q: f64| -> f64 {
            let d2 = l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * cos_half_turn(q);
            if d2 > 0.0 {
                libm::sqrt(d2)
            } else {
                0.0
            }
        };
        let kmin = if knee.min.is_finite() { knee.min } else { 0.0 };
        let kmax = if knee.max.is_finite() {
            knee.max
        } else {
            core::f64::consts::PI
        };
        let d_max = reach(kmin.max(KNEE_MIN_BEND));
        let d_min = reach(kmax.min(core::f64::consts::PI)).max((l1 - l2).abs());
        let lim = |side: Side| -> [[Fx; 2]; JOINTS_PER_LEG] {
            let mut out = [[Fx::ZERO; 2]; JOINTS_PER_LEG];
            for (j, o) in out.iter_mut().enumerate() {
                let l = robot.joint_limit(side, j);
                let lo = rad_bits_inward(l.min, true);
                let hi = rad_bits_inward(l.max, false);
                *o = [Fx::from_bits(lo), Fx::from_bits(hi.max(lo))];
            }
            out
        };
        FixedLegKinematics {
            hip_offset_y: p30(len(g.hip_offset_y)),
            ankle_height: p30(len(g.ankle_height)),
            sole_offset: [p30(offset(g.sole_offset[0])), p30(offset(g.sole_offset[1]))],
            sum2: (t + c) * (t + c),
            diff2: (t - c) * (t - c),
            four_calf2: 4 * c * c,
            d_min: p30(d_min),
            d_max: p30(d_max),
            limits: [lim(Side::Left), lim(Side::Right)],
        }
    }

    /// The [min, max] limits (Fx, rounded inward) of the leg's six joints.
    pub fn limits(&self, side: Side) -> &[[Fx; 2]; JOINTS_PER_LEG] {
        match side {
            Side::Left => &self.limits[0],
            Side::Right => &self.limits[1],
        }
    }

    /// Longest hip–ankle distance the IK reaches (knee bent [`KNEE_MIN_BEND`]), m.
    pub fn max_reach(&self) -> Fx {
        Fx::from_bits((self.d_max >> 14) as i32)
    }

    /// Shortest hip–ankle distance the IK reaches, m.
    pub fn min_reach(&self) -> Fx {
        Fx::from_bits((self.d_min >> 14) as i32)
    }

    /// Inverse kinematics of both legs: 12 angles (left leg then right leg, rad) and the report.
    /// Integer arithmetic only; total for every input.
    pub fn legs_ik(
        &self,
        pelvis: &FixedPose,
        left: &FixedPose,
        right: &FixedPose,
    ) -> ([Fx; LEG_JOINTS], FixedIkReport) {
        let (pelvis, bad_p) = sanitize(pelvis);
        let (left, bad_l) = sanitize(left);
        let (right, bad_r) = sanitize(right);
        let rp = rot_cols(&pelvis);
        let l = self.leg(Side::Left, &pelvis, &rp, &left, true);
        let r = self.leg(Side::Right, &pelvis, &rp, &right, true);
        let [a0, a1, a2, a3, a4, a5] = l.q;
        let [b0, b1, b2, b3, b4, b5] = r.q;
        let report = FixedIkReport {
            reach_deficit: [l.deficit, r.deficit],
            limited: u16::from(l.limited) | (u16::from(r.limited) << JOINTS_PER_LEG),
            invalid_input: bad_p || bad_l || bad_r,
        };
        ([a0, a1, a2, a3, a4, a5, b0, b1, b2, b3, b4, b5], report)
    }

    /// One leg on sanitized inputs (|positions| ≤ 1000 m); `allow_level`: the hip of level
    /// poses in closed form ([`level_hip`]; off only to test it against the general path).
    fn leg(
        &self,
        side: Side,
        pelvis: &FixedPose,
        rp: &Cols,
        foot: &FixedPose,
        allow_level: bool,
    ) -> LegOut {
        let lims = self.limits(side);
        let rf = rot_cols(foot);
        let (hip, outward) = match side {
            Side::Left => (self.hip_offset_y, self.sole_offset[1]),
            Side::Right => (-self.hip_offset_y, -self.sole_offset[1]),
        };
        let forward = self.sole_offset[0];

        // d = H − A = (P − S) + σd·R_P·e_y − h·R_F·e_z + o_x·R_F·e_x + σo_y·R_F·e_y in 2⁻³⁰ m:
        // |P − S| ≤ 2000 m → < 2⁴², the offsets < 2²⁹.
        let ps = [
            pelvis.x.to_bits() as i64 - foot.x.to_bits() as i64,
            pelvis.y.to_bits() as i64 - foot.y.to_bits() as i64,
            pelvis.z.to_bits() as i64 - foot.z.to_bits() as i64,
        ];
        // The sole point's offset only where there is one (six 64-bit products saved a leg on
        // FPU-less cores for a sole under the ankle; the sum is the same either way).
        let offset = forward != 0 || outward != 0;
        let d: V3 = core::array::from_fn(|i| {
            let d =
                (ps[i] << 14) + ((hip * rp[1][i]) >> 30) - ((self.ankle_height * rf[2][i]) >> 30);
            if offset {
                d + ((forward * rf[0][i]) >> 30) + ((outward * rf[1][i]) >> 30)
            } else {
                d
            }
        });
        // Scale down by 2^k so that every component is ≤ 2³⁰ (1 m): then r = R_Fᵀ·d and |r|²
        // stay below 3·2⁶⁰.
        let m = d[0]
            .unsigned_abs()
            .max(d[1].unsigned_abs())
            .max(d[2].unsigned_abs());
        let k = (64 - m.leading_zeros()).saturating_sub(30);
        let d = d.map(|v| v >> k);
        let r = [dot(&rf[0], &d), dot(&rf[1], &d), dot(&rf[2], &d)];
        let n2 = r.iter().fold(0u64, |acc, v| {
            acc.saturating_add(v.unsigned_abs() * v.unsigned_abs())
        });
        let dist = isqrt(n2) as i64;
        // Back to 2⁻³⁰ m: dist < 2³², k ≤ 13.
        let dist_full = dist << k;

        // 1. Reach (r is not rescaled: only its direction is used below).
        let (dd, deficit, r) = if dist_full > self.d_max {
            (self.d_max, dist_full - self.d_max, r)
        } else if dist_full < self.d_min {
            let r = if dist > 1 { r } else { [0, 0, 1] };
            (self.d_min, self.d_min - dist_full, r)
        } else {
            (dist_full, 0, r)
        };
        // To Fx, rounded, but never to 0 when the reach was clamped (so `clamped()` sees it).
        let deficit_fx = if deficit > 0 {
            ((deficit + (1 << 13)) >> 14).clamp(1, i32::MAX as i64)
        } else {
            0
        };
        let deficit = Fx::from_bits(deficit_fx as i32);

        // 2. Knee: exact integer differences (2⁻⁶⁰ m², all < 2⁶⁰ since the links ≤ 0.5 m).
        let dd2 = dd * dd;
        let a = isqrt((self.sum2 - dd2).max(0) as u64) as i64;
        let b = isqrt((dd2 - self.diff2).max(0) as u64) as i64;
        let q3 = round_angle(2 * atan2_fac(a, b));

        // 3. Ankle roll, 4. ankle pitch.
        let wz = isqrt((r[1] * r[1] + r[2] * r[2]) as u64) as i64;
        let q5 = if wz > 0 { atan2_fac(r[1], r[2]) } else { 0 };
        let q4 = -atan2_fac(2 * a * b, self.four_calf2 + b * b - a * a) - atan2_fac(r[0], wz);
        let (q4, q5) = (round_angle(q4), round_angle(q5));

        let mut flags = 0u8;
        let [lim0, lim1, lim2, lim3, lim4, lim5] = lims;
        let q3 = limit(q3, lim3, 1 << 3, &mut flags);
        let q4 = limit(q4, lim4, 1 << 4, &mut flags);
        let q5 = limit(q5, lim5, 1 << 5, &mut flags);

        // 5. Hip: M = R_Pᵀ·R_F·Rx(−q5)·Ry(−(q3 + q4)).
        let q34 = q3.saturating_add(q4);
        let (q0, q1, q2) = match level_hip(pelvis, foot, q5, q34) {
            Some(q) if allow_level => q,
            _ => {
                let (s5, c5) = sc(q5);
                let (s34, c34) = sc(q34);
                let n = post_ry(&post_rx(&rf, (-s5, c5)), (-s34, c34));
                let m01 = dot(&rp[0], &n[1]);
                let m11 = dot(&rp[1], &n[1]);
                let m21 = dot(&rp[2], &n[1]);
                let m20 = dot(&rp[2], &n[0]);
                let m22 = dot(&rp[2], &n[2]);
                (
                    atan2(-m01, m11),
                    atan2(m21, isqrt((m01 * m01 + m11 * m11) as u64) as i64),
                    atan2(-m20, m22),
                )
            }
        };
        let q0 = limit(q0, lim0, 1, &mut flags);
        let q1 = limit(q1, lim1, 1 << 1, &mut flags);
        let q2 = limit(q2, lim2, 1 << 2, &mut flags);

        LegOut {
            q: [q0, q1, q2, q3, q4, q5],
            deficit,
            limited: flags,
        }
    }
}

/// The pelvis pose of a fixed-point sample: (com_x, com_y, z_c), level, heading between the
/// feet (the [`crate::kinematics::pipeline::pelvis_pose`] rule).
pub fn pelvis_pose(sample: &FixedSample) -> FixedPose {
    let [l, r] = sample.feet;
    let half = wrap_pi(r.yaw.to_bits() as i64 - l.yaw.to_bits() as i64) >> 1;
    let yaw = Fx::from_bits(
        (l.yaw.to_bits() as i64 + half).clamp(i32::MIN as i64, i32::MAX as i64) as i32,
    );
    FixedPose::level(sample.com[0], sample.com[1], sample.com[2], yaw)
}

/// A foot's pose for the IK: sole flat, at the sample's position and heading.
pub fn foot_pose(f: &FixedFoot) -> FixedPose {
    FixedPose::level(f.x, f.y, f.z, f.yaw)
}

/// The 12 joint targets (left leg then right leg, rad) of a fixed-point sample and what the IK
/// had to clamp, like [`crate::kinematics::pipeline::joint_targets`], with integer arithmetic only.
pub fn joint_targets(
    kin: &FixedLegKinematics,
    sample: &FixedSample,
) -> ([Fx; LEG_JOINTS], FixedIkReport) {
    kin.legs_ik(
        &pelvis_pose(sample),
        &foot_pose(&sample.feet[0]),
        &foot_pose(&sample.feet[1]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maths::fixed_point::mul30;
    extern crate std;

    /// The `i64` Horner evaluation `atan_unit` was before it moved to `i32`.
    fn atan_unit_i64(t: i64) -> i64 {
        let u = mul30(t, t);
        let mut acc = 0i64;
        for &c in ATAN_COEF.iter().rev() {
            acc = i64::from(c) + mul30(acc, u);
        }
        mul30(acc, t)
    }

    /// `ratio30` as it was in `i64` throughout.
    fn ratio30_i64(num: u64, den: u64) -> i64 {
        let sh = den.leading_zeros() as i32 - 33;
        let (n, d) = if sh >= 0 {
            (num << sh, den << sh)
        } else {
            (num >> -sh, den >> -sh)
        };
        let (n, d) = (n as i64, d as i64);
        let d16 = (d >> 15) as u32;
        let r0 = ((1u32 << 31) / d16.max(1)) as i64;
        let r = r0 << 15;
        let e = (1i64 << 61) - d * r;
        let r = r + ((r * (e >> 16)) >> 45);
        ((n * r) >> 31).clamp(0, ONE)
    }

    #[test]
    fn ratio30_in_32_bit_steps_is_the_i64_evaluation() {
        // Denominators of every width 1..=63 bits, numerators 0..=den (ends and random).
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for bits in 1..=63u32 {
            let top = 1u64 << (bits - 1);
            for _ in 0..4_000 {
                let den = top | (next() & (top - 1));
                for num in [0, 1, den / 3, den - 1, den, next() % (den + 1)] {
                    assert_eq!(ratio30(num, den), ratio30_i64(num, den), "{num}/{den}");
                }
            }
        }
        // Within 2⁻³⁰ of the exact ratio (the Newton step's 2⁻²⁸ bound is loose here).
        assert!((ONE - ratio30(5, 5)).abs() <= 1);
        assert!((ratio30(1, 3) - ONE / 3).abs() <= 1);
    }

    /// `rot_cols` as it was, with `i64` products.
    fn rot_cols_i64(p: &FixedPose) -> Cols {
        let (sr, cr) = sc(p.roll);
        let (sp, cp) = sc(p.pitch);
        let (sy, cy) = sc(p.yaw);
        let (cysp, sysp) = (mul30(cy, sp), mul30(sy, sp));
        [
            [mul30(cy, cp), mul30(sy, cp), -sp],
            [
                mul30(cysp, sr) - mul30(sy, cr),
                mul30(sysp, sr) + mul30(cy, cr),
                mul30(cp, sr),
            ],
            [
                mul30(cysp, cr) + mul30(sy, sr),
                mul30(sysp, cr) - mul30(cy, sr),
                mul30(cp, cr),
            ],
        ]
    }

    #[test]
    fn cos_half_turn_is_libm_cos_on_zero_to_pi() {
        for i in 0..=10_000 {
            let x = core::f64::consts::PI * f64::from(i) / 10_000.0;
            let (got, want) = (cos_half_turn(x), libm::cos(x));
            assert!((got - want).abs() < 1e-15, "{x}: {got} vs {want}");
        }
        assert_eq!(cos_half_turn(0.0), 1.0);
        assert_eq!(cos_half_turn(-1.0), 1.0);
        assert_eq!(cos_half_turn(f64::NAN), 1.0);
        assert_eq!(cos_half_turn(9.0), -1.0);
        // The described robots' reach bounds come out to the same 2⁻³⁰ m bits either way.
        for robot in crate::robot::ROBOTS {
            let g = &robot.geometry;
            let knee = robot.joint_limit(Side::Left, 3);
            for q in [knee.min.max(KNEE_MIN_BEND), knee.max] {
                let d = |c: f64| {
                    libm::sqrt(g.thigh * g.thigh + g.calf * g.calf + 2.0 * g.thigh * g.calf * c)
                };
                assert_eq!(
                    bits(d(cos_half_turn(q)), 30, 1 << 62),
                    bits(d(libm::cos(q)), 30, 1 << 62),
                    "{}: knee {q}",
                    robot.name
                );
            }
        }
    }

    #[test]
    fn rot_cols_with_32_bit_products_is_the_i64_evaluation() {
        // Angles over the whole Fx range (coarse) and ±π (fine), every combination.
        let coarse = (i32::MIN..=i32::MAX).step_by(1 << 27);
        let fine = (-205_887..=205_887).step_by(9_973);
        let angles: std::vec::Vec<Fx> = coarse.chain(fine).map(Fx::from_bits).collect();
        for &roll in &angles {
            for &pitch in angles.iter().step_by(3) {
                for &yaw in angles.iter().step_by(5) {
                    let p = FixedPose {
                        x: Fx::ZERO,
                        y: Fx::ZERO,
                        z: Fx::ZERO,
                        roll,
                        pitch,
                        yaw,
                    };
                    assert_eq!(rot_cols(&p), rot_cols_i64(&p), "{p:?}");
                }
            }
        }
    }

    #[test]
    fn atan_unit_in_i32_is_the_i64_evaluation() {
        // Every 2⁻¹⁶ step of [0, 1] and a dense run at both ends, bit for bit.
        let ends = (0..4096).chain(ONE - 4096..=ONE);
        for t in (0..=ONE).step_by(1 << 14).chain(ends) {
            assert_eq!(atan_unit(t), atan_unit_i64(t), "t = {t}");
        }
    }

    /// The level poses' closed-form hip against the general path's three atan2, over level
    /// targets: headings across ±π, heading differences up to ±3.6 rad (beyond π: the general
    /// path), feet near, far (reach clamped)
    /// and beside the hip, so joints are clamped too. The same angles and reports; and the
    /// closed form is taken (not the general path) on most of them.
    #[test]
    fn level_hip_is_the_general_hip() {
        let kin = FixedLegKinematics::new(&Robot::reference());
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = |lo: f64, hi: f64| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            lo + (hi - lo) * ((seed >> 11) as f64 / (1u64 << 53) as f64)
        };
        let fx = |v: f64| Fx::from_num(v);
        let mut closed = 0usize;
        let cases = 40_000;
        for _ in 0..cases {
            let pelvis_yaw = next(-3.3, 3.3);
            let pelvis = FixedPose::level(
                fx(next(-0.1, 0.1)),
                fx(next(-0.1, 0.1)),
                fx(next(0.1, 0.3)),
                fx(pelvis_yaw),
            );
            let foot = FixedPose::level(
                fx(next(-0.15, 0.15)),
                fx(next(-0.15, 0.15)),
                fx(next(-0.02, 0.05)),
                fx(pelvis_yaw + next(-3.6, 3.6)),
            );
            let (pelvis, _) = sanitize(&pelvis);
            let (foot, _) = sanitize(&foot);
            let rp = rot_cols(&pelvis);
            for side in [Side::Left, Side::Right] {
                let a = kin.leg(side, &pelvis, &rp, &foot, true);
                let b = kin.leg(side, &pelvis, &rp, &foot, false);
                assert_eq!(a.q, b.q, "{side:?}");
                assert_eq!(a.deficit, b.deficit);
                assert_eq!(a.limited, b.limited, "{:?} vs {:?}", a.q, b.q);
                let q34 = a.q[3].saturating_add(a.q[4]);
                closed += usize::from(level_hip(&pelvis, &foot, a.q[5], q34).is_some());
            }
        }
        std::println!("level hip: closed form on {closed} of {} legs", 2 * cases);
        assert!(closed > cases, "closed form taken on {closed} legs only");
        // Outside its domain (a tilted pose, a heading difference beyond π) it is not used.
        let tilted = FixedPose::new(Fx::ZERO, Fx::ZERO, fx(0.2), fx(0.1), Fx::ZERO, Fx::ZERO);
        let flat = FixedPose::level(Fx::ZERO, Fx::ZERO, Fx::ZERO, Fx::ZERO);
        assert!(level_hip(&tilted, &flat, Fx::ZERO, Fx::ZERO).is_none());
        let turned = FixedPose::level(Fx::ZERO, Fx::ZERO, Fx::ZERO, fx(3.2));
        assert!(level_hip(&flat, &turned, Fx::ZERO, Fx::ZERO).is_none());
        assert!(level_hip(&flat, &flat, fx(1.6), Fx::ZERO).is_none());
        assert!(level_hip(&flat, &flat, Fx::ZERO, fx(-3.2)).is_none());
        assert!(level_hip(&flat, &flat, fx(0.2), fx(-0.5)).is_some());
    }
}
