//! Swing-foot trajectories: seed 000's cycloid (eq 27) and seed 001's sinusoid-and-constant
//! profile. The stance foot stays fixed; the swing foot moves only in single support.
//!
//! Seed 000 eq 27 (erratum: θ runs over the single support only, F_x is a displacement from
//! lift-off), with θ = 2π(t − t₁)/(t₂ − t₁) ∈ [0, 2π] and the stride vector Δ = to − from:
//!
//! ```text
//!   F_xy(θ) = from + Δ·(θ − sin θ)/2π          (Amp_x = stride/2π)
//!   F_y    += W_y·(1 − cos θ)/2 outward        (our reading of Amp_y = W_y: a bulge)
//!   F_z(θ)  = (H_z/2)·(1 − cos θ)              (Amp_z = H_z/2, peak H_z at θ = π)
//! ```
//!
//! Velocities: dF/dθ ∝ (1 − cos θ) and sin θ vanish at θ = 0 and 2π, so the foot lifts off and
//! touches down at zero velocity (the vertical acceleration is not continuous there).
//!
//! Seed 001 (Fig. 9), with u = (t − t₁)/(t₂ − t₁) ∈ [0, 1]: F_xy = from + Δ·(1 − cos πu)/2,
//! F_z = h_s·(1 − cos 2πu)/2; constant outside the single support. Zero velocity at both ends.
//! The heading turns with the same fraction as the horizontal motion.

use crate::maths::real::Real;
use crate::trajectory::plan::{Place, SwingShape};
use core::f64::consts::PI;

/// A foot pose sample: sole point position (m) and heading (rad), world frame.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct FootSample<R> {
    /// x, m.
    pub x: R,
    /// y, m.
    pub y: R,
    /// Height of the sole above the ground, m.
    pub z: R,
    /// Heading, rad.
    pub yaw: R,
}

impl<R: Real> FootSample<R> {
    /// The foot standing on `p`.
    pub fn on_ground(p: &Place<R>) -> Self {
        FootSample {
            x: p.x,
            y: p.y,
            z: R::zero(),
            yaw: p.yaw,
        }
    }
}

/// The swing foot at fraction `u` ∈ [0, 1] of the single support, from `from` to `to`;
/// `outward` is +1 for the left foot, −1 for the right (direction of the W_y bulge).
pub fn swing_foot<R: Real>(
    shape: &SwingShape<R>,
    from: &Place<R>,
    to: &Place<R>,
    u: R,
    outward: R,
) -> FootSample<R> {
    let u = u.clamp_to(R::zero(), R::one());
    let (fh, fz, bulge) = match *shape {
        SwingShape::Cycloid { height, width } => {
            let th = R::of(2.0 * PI) * u;
            let (s, c) = (th.sin(), th.cos());
            let one_m_cos = R::one() - c;
            (
                (th - s) / R::of(2.0 * PI),
                height * R::of(0.5) * one_m_cos,
                width * R::of(0.5) * one_m_cos,
            )
        }
        SwingShape::Sinusoid { height } => {
            let c1 = (R::of(PI) * u).cos();
            let c2 = (R::of(2.0 * PI) * u).cos();
            (
                (R::one() - c1) * R::of(0.5),
                height * R::of(0.5) * (R::one() - c2),
                R::zero(),
            )
        }
    };
    let dyaw = wrap_pi(to.yaw - from.yaw);
    let yaw = from.yaw + dyaw * fh;
    // The bulge is lateral to the foot's current heading.
    let (sy, cy) = (yaw.sin(), yaw.cos());
    let b = bulge * outward;
    FootSample {
        x: from.x + (to.x - from.x) * fh - sy * b,
        y: from.y + (to.y - from.y) * fh + cy * b,
        z: fz,
        yaw,
    }
}

/// An angle wrapped into [−π, π].
pub fn wrap_pi<R: Real>(a: R) -> R {
    let two_pi = R::of(2.0 * PI);
    let mut x = a;
    // Bounded loop: plans never hold angles far outside (−2π, 2π]; larger inputs are clamped.
    let in_range = x.abs() < R::of(64.0);
    if !in_range {
        return R::zero();
    }
    for _ in 0..16 {
        if x > R::of(PI) {
            x -= two_pi;
        } else if x < R::of(-PI) {
            x += two_pi;
        } else {
            break;
        }
    }
    x
}
