//! The scalar type of the generator: `f32` on the robot, `f64` for reference evaluations.
//!
//! Every formula of gait-core is written once over [`Real`], so the host tests can evaluate the
//! very same code in `f64` and compare it with the `f32` path that runs on the servo loop.

use core::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

/// A floating-point scalar (`f32` or `f64`) with the maths gait-core needs.
///
/// For `f32`, `sin`/`cos`/`atan2` are the short polynomials of [`crate::maths::fastmath`] (|error|
/// < 1e-7 for sin/cos, ≤ [`crate::maths::fastmath::ATAN2_MAX_ERR`] for atan2; libm's `sinf` computes
/// in software doubles, far slower on a single-precision FPU) and `sqrt` is the FPU's
/// `VSQRT.F32` on hard-float ARM ([`crate::maths::fastmath::sqrt`]).
pub trait Real:
    Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + core::fmt::Debug
    + Default
{
    /// Converts from `f64` (rounding to nearest).
    fn of(v: f64) -> Self;
    /// Converts to `f64` exactly.
    fn to_f64(self) -> f64;
    /// Converts an unsigned integer (cheap on the target: no `f64` on the way).
    fn from_u32(v: u32) -> Self;
    /// e^self.
    fn exp(self) -> Self;
    /// Square root (NaN for negative input; callers clamp first).
    fn sqrt(self) -> Self;
    /// Sine.
    fn sin(self) -> Self;
    /// Cosine.
    fn cos(self) -> Self;
    /// Sine and cosine, the values of [`Real::sin`] and [`Real::cos`] (one evaluation where
    /// the implementation shares it).
    fn sin_cos(self) -> (Self, Self) {
        (self.sin(), self.cos())
    }
    /// Arc tangent of `self / x` in (−π, π].
    fn atan2(self, x: Self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// True when neither NaN nor infinite.
    fn is_finite(self) -> bool;
    /// Zero.
    fn zero() -> Self {
        Self::of(0.0)
    }
    /// One.
    fn one() -> Self {
        Self::of(1.0)
    }
    /// The smaller of two values.
    fn min(self, o: Self) -> Self {
        if o < self {
            o
        } else {
            self
        }
    }
    /// The larger of two values.
    fn max(self, o: Self) -> Self {
        if o > self {
            o
        } else {
            self
        }
    }
    /// `self` limited to `[lo, hi]` (NaN becomes `lo`).
    fn clamp_to(self, lo: Self, hi: Self) -> Self {
        if self >= lo {
            if self <= hi {
                self
            } else {
                hi
            }
        } else {
            lo
        }
    }
}

/// Implements [`Real`] for a float type from its conversion from `f64` and its maths
/// functions (each one-argument one, `name: function`, delegates alike): the one place that
/// says which implementation each type uses.
macro_rules! impl_real {
    ($t:ident, of: |$v:ident| $of:expr, sin_cos: $sin_cos:path, atan2: $atan2:path,
     $($unary:ident: $f:path),+ $(,)?) => {
        impl Real for $t {
            #[inline]
            fn of($v: f64) -> Self {
                $of
            }
            #[inline]
            fn to_f64(self) -> f64 {
                f64::from(self)
            }
            #[inline]
            fn from_u32(v: u32) -> Self {
                v as $t
            }
            $(
                #[inline]
                fn $unary(self) -> Self {
                    $f(self)
                }
            )+
            #[inline]
            fn sin_cos(self) -> (Self, Self) {
                $sin_cos(self)
            }
            #[inline]
            fn atan2(self, x: Self) -> Self {
                $atan2(self, x)
            }
            #[inline]
            fn is_finite(self) -> bool {
                $t::is_finite(self)
            }
        }
    };
}

impl_real!(
    f32,
    of: |v| v as f32,
    sin_cos: crate::maths::fastmath::sin_cos,
    atan2: crate::maths::fastmath::atan2,
    exp: libm::expf,
    sqrt: crate::maths::fastmath::sqrt,
    sin: crate::maths::fastmath::sin,
    cos: crate::maths::fastmath::cos,
    abs: libm::fabsf
);
impl_real!(
    f64,
    of: |v| v,
    sin_cos: sin_cos_f64,
    atan2: libm::atan2,
    exp: libm::exp,
    sqrt: libm::sqrt,
    sin: libm::sin,
    cos: libm::cos,
    abs: libm::fabs
);

/// libm's sine and cosine of an `f64` (its `sincos` may round differently from the two).
fn sin_cos_f64(x: f64) -> (f64, f64) {
    (libm::sin(x), libm::cos(x))
}
