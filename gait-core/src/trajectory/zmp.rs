//! ZMP references: seed 000's natural ZMP (eqs 10-11) and seed 001's continuous forward-moving
//! ZMP (eqs 3-7), both as piecewise-linear curves through four knots per step.
//!
//! For step n with support foot S (heading unit vector `e`), in the step's local time t ∈ [0, T]:
//!
//! ```text
//!   p(0)  = B_n             (boundary point shared with the previous step, double support)
//!   p(t1) = S − a·e         (heel side: lift-off of the swing foot)
//!   p(t2) = S + a·e         (toe side: touch-down)                          heel-to-toe
//!   p(T)  = B_{n+1}
//! ```
//!
//! and p is linear in between. Along x for a straight walk this is seed 000 eq 10 with the
//! erratum (the last slope divides by T − t₂): p(0) = p^c − d₁, p(t₁) = p^c − a, p(t₂) = p^c + a,
//! p(T) = p^c + d₂; along y it is eq 11: 0 → p^c_y over [0, t₁], constant, → 0 over [t₂, T].
//! Each runs along its own foot's heading, so turning plans keep the ZMP on the sole.
//!
//! Boundary points (the ZMP between two support feet P, S in double support):
//! * seed 000 ([`ZmpShape::Natural`]): B = ½·[(P + d₂·e_P) + (S − d₁·e_S)]. For Table 2
//!   (S_L = d₁ + d₂) both halves coincide, so the ZMP is continuous step to step.
//! * seed 001 ([`ZmpShape::Continuous`]): B lies on the straight line from P + b·e_P to
//!   S − b·e_S at the time fraction λ = (T − t₂)/((T − t₂) + t₁), so the double-support motion
//!   is one straight line at constant speed, as in seed 001 Fig. 5 (with τ = t₁ = T − t₂ it is
//!   the midpoint). Our reading of eq 6 (erratum): the ZMP moves exactly ±b under the sole in
//!   single support (δ chosen so), not ±b(T − 2τ)/T. Eq 7 includes its k = 0 term: p_y is the
//!   continuous trapezoid of Fig. 5.
//!
//! The first boundary is the midpoint of the start feet, the last one the midpoint of the final
//! feet (standing, both feet on the ground).

use crate::error::GaitError;
use crate::maths::real::Real;
use crate::robot::Robot;
use crate::trajectory::plan::{Place, Timing};

/// The shape of the ZMP reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ZmpShape<R> {
    /// Seed 000 eqs 10-11: natural ZMP with double support and heel-to-toe motion.
    Natural {
        /// d₁: ZMP behind the support foot at the step start, m.
        d1: R,
        /// d₂: ZMP ahead of the support foot at the step end, m.
        d2: R,
        /// a: half the ZMP travel under the sole in single support, m.
        a: R,
    },
    /// Seed 001 eqs 3-7: continuous forward-moving ZMP with pre-assigned double support.
    Continuous {
        /// b: half the ZMP travel under the sole in single support, m.
        b: R,
    },
}

impl<R: Real> ZmpShape<R> {
    /// Checks the offsets: finite, not negative, and the single-support ZMP on the sole.
    pub fn validate(&self, robot: &Robot) -> Result<(), GaitError> {
        let half = R::of(robot.geometry.sole_length * 0.5);
        let (vals, a) = match *self {
            ZmpShape::Natural { d1, d2, a } => ([d1, d2, a], a),
            ZmpShape::Continuous { b } => ([b, b, b], b),
        };
        if vals.iter().any(|v| !v.is_finite()) {
            return Err(GaitError::NonFinite);
        }
        if vals.iter().any(|v| *v < R::zero()) || a >= half {
            return Err(GaitError::ZmpOffsetOffSole);
        }
        Ok(())
    }

    /// The ZMP offsets along the support foot at t1 (behind) and t2 (ahead), m.
    pub fn single_support_offsets(&self) -> (R, R) {
        match *self {
            ZmpShape::Natural { a, .. } => (a, a),
            ZmpShape::Continuous { b } => (b, b),
        }
    }

    /// The boundary point between a step on `prev` and the next on `next` (module doc).
    pub fn boundary(&self, timing: &Timing<R>, prev: &Place<R>, next: &Place<R>) -> [R; 2] {
        match *self {
            ZmpShape::Natural { d1, d2, .. } => {
                let p = prev.ahead(d2);
                let s = next.ahead(-d1);
                let h = R::of(0.5);
                [(p[0] + s[0]) * h, (p[1] + s[1]) * h]
            }
            ZmpShape::Continuous { b } => {
                let p = prev.ahead(b);
                let s = next.ahead(-b);
                let after = timing.period - timing.t2;
                let lambda = after / (after + timing.t1);
                [p[0] + (s[0] - p[0]) * lambda, p[1] + (s[1] - p[1]) * lambda]
            }
        }
    }
}

/// Linear interpolation between two knots: p(s) = p0 + (p1 − p0)·s/d, clamped to [0, d].
pub fn lerp2<R: Real>(p0: [R; 2], p1: [R; 2], s: R, d: R) -> [R; 2] {
    let f = if d > R::zero() {
        (s / d).clamp_to(R::zero(), R::one())
    } else {
        R::one()
    };
    [p0[0] + (p1[0] - p0[0]) * f, p0[1] + (p1[1] - p0[1]) * f]
}
