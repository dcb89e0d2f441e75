//! The CoM: the exact, bounded closed-form solution of the model ODE for a piecewise-linear ZMP.
//!
//! Per axis, ẍ = ω²(x − p) − τ/C_τ² (ω = 1/T_TF). On a segment with ZMP p(s) = p₀ + K·s
//! (local time s ∈ [0, D]) and τ = 0 the general solution is (erratum to eqs 21-26: the ZMP
//! enters by convolution; for a linear segment the particular solution is p itself):
//!
//! ```text
//!   x(s) = p₀ + K·s + A·e^{−ω(D − s)} + c·e^{−ω s}                               (C1)
//!   ẋ(s) = K + ω·A·e^{−ω(D − s)} − ω·c·e^{−ω s}                                  (C2)
//! ```
//!
//! Both exponentials are ≤ 1 inside the segment, so nothing overflows in f32 (the printed eqs
//! 23-26 use cosh/sinh of the global time, which grow by e^{T/T_TF} ≈ 42 per step).
//!
//! The divergent component of motion ξ = x + ẋ/ω obeys ξ̇ = ω(ξ − p): it is unstable forward
//! and stable backward, so it is computed **backward** from the final rest state ξ_end = p_end
//! (erratum "initial values"). From (C1, C2), ξ(s) = p(s) + K/ω + 2A·e^{−ω(D−s)}, hence with
//! ξ₁ = ξ(D) and p₁ = p(D):
//!
//! ```text
//!   A  = (ξ₁ − p₁ − K/ω) / 2                                                     (C3)
//!   ξ₀ = p₀ + K/ω + (ξ₁ − p₁ − K/ω)·e^{−ω D}                                      (C4)
//! ```
//!
//! The CoM itself, ẋ = ω(ξ − x), is stable forward: the stable-mode coefficient is re-anchored
//! at every segment start from the CoM position there, c = x₀ − p₀ − A·e^{−ωD} (C5). Position
//! and ξ are continuous, hence the velocity ẋ = ω(ξ − x) too. The walk begins with a lead-in
//! (ZMP held between the feet) starting with the CoM over the ZMP at rest: the CoM starts
//! moving before the ZMP does; after the lead-out the CoM has settled at rest over the ZMP.
//!
//! **τ as a measured input** (τ = J·φ̈ each sample): a constant τ shifts the bounded solution by
//! Δ = τ·T_TF²/C_τ² (forward for τ > 0). The causal bounded response to a measured τ(t) is the
//! stable filter ė = ω(Δ(t) − e) added to the planned CoM (x = x_plan + e, ẋ = ẋ_plan + ω(Δ − e)),
//! sampled exactly with τ held over each sample: e ← Δ + (e − Δ)·e^{−ω dt} (C6). It satisfies
//! the ODE exactly while τ is constant, and |e| ≤ max|Δ| for any bounded τ: a measured torque
//! can never make the CoM diverge (a divergent CoM is a fall).

use crate::maths::real::Real;

/// One step of (C4): the DCM at a segment's start from the DCM at its end.
pub fn dcm_back<R: Real>(omega: R, p0: [R; 2], p1: [R; 2], d: R, xi1: [R; 2]) -> [R; 2] {
    ZmpSpan::new(omega, p0, p1, d).dcm_back(omega, xi1)
}

/// e^{−ω d}: the stable mode's decay over a segment of `d` seconds ((C4), (C5)).
pub fn decay<R: Real>(omega: R, d: R) -> R {
    (-(omega * d)).exp()
}

/// One linear piece of the ZMP: from `p0` to `p1` over `d` seconds, with its decay e^{−ωd}
/// (given when it is known: a sampler computes the decay of each phase duration once, not at
/// every segment change — `exp` is a long library call without an FPU).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZmpSpan<R> {
    /// ZMP at the start, m.
    pub p0: [R; 2],
    /// ZMP at the end, m.
    pub p1: [R; 2],
    /// Duration, s.
    pub d: R,
    /// e^{−ωd} ([`decay`]).
    pub decay: R,
}

impl<R: Real> ZmpSpan<R> {
    /// The span from `p0` to `p1` over `d` seconds, its decay computed for `omega`.
    pub fn new(omega: R, p0: [R; 2], p1: [R; 2], d: R) -> Self {
        ZmpSpan {
            p0,
            p1,
            d,
            decay: decay(omega, d),
        }
    }

    /// The ZMP slope K = (p₁ − p₀)/d of both axes, m/s (0 for an empty span).
    fn slope(&self) -> [R; 2] {
        let [x1, y1] = self.p1;
        let [x0, y0] = self.p0;
        if self.d > R::zero() {
            [(x1 - x0) / self.d, (y1 - y0) / self.d]
        } else {
            [R::zero(); 2]
        }
    }

    /// (C4): the DCM at the span's start from the DCM `xi1` at its end.
    pub fn dcm_back(&self, omega: R, xi1: [R; 2]) -> [R; 2] {
        let k = self.slope();
        let axis = |p0: R, p1: R, k: R, xi1: R| {
            let kw = k / omega;
            p0 + kw + (xi1 - p1 - kw) * self.decay
        };
        [
            axis(self.p0[0], self.p1[0], k[0], xi1[0]),
            axis(self.p0[1], self.p1[1], k[1], xi1[1]),
        ]
    }
}

/// The coefficients (C1-C5) of one segment of the CoM solution, both axes.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct ComSegment<R> {
    /// ZMP at the segment start p₀, m.
    pub p0: [R; 2],
    /// ZMP slope K, m/s.
    pub slope: [R; 2],
    /// Unstable-mode amplitude A at the segment end, m (C3).
    pub a: [R; 2],
    /// Stable-mode amplitude c at the segment start, m (C5).
    pub c: [R; 2],
    /// Duration D, s.
    pub duration: R,
    /// e^{−ωD}, the stable mode's decay over the segment (C5), for [`ComSegment::end_position`].
    pub decay: R,
}

impl<R: Real> ComSegment<R> {
    /// The segment from ZMP `p0` to `p1` over `d` seconds, ending at DCM `xi1`, starting with
    /// the CoM at `x0`.
    pub fn new(omega: R, p0: [R; 2], p1: [R; 2], d: R, xi1: [R; 2], x0: [R; 2]) -> Self {
        Self::over(omega, &ZmpSpan::new(omega, p0, p1, d), xi1, x0)
    }

    /// The segment over `span` (its decay given), ending at DCM `xi1`, starting with the CoM
    /// at `x0`.
    pub fn over(omega: R, span: &ZmpSpan<R>, xi1: [R; 2], x0: [R; 2]) -> Self {
        let mut s = ComSegment {
            p0: span.p0,
            duration: span.d,
            decay: span.decay,
            ..Default::default()
        };
        s.slope = span.slope();
        for i in 0..2 {
            let k = s.slope[i];
            s.a[i] = (xi1[i] - span.p1[i] - k / omega) * R::of(0.5);
            s.c[i] = x0[i] - span.p0[i] - s.a[i] * span.decay;
        }
        s
    }

    /// ZMP p(s), m.
    pub fn zmp(&self, s: R) -> [R; 2] {
        [
            self.p0[0] + self.slope[0] * s,
            self.p0[1] + self.slope[1] * s,
        ]
    }

    /// CoM position and velocity at local time `s` (C1, C2).
    pub fn eval(&self, omega: R, s: R) -> ([R; 2], [R; 2]) {
        let eu = (-(omega * (self.duration - s))).exp();
        let es = (-(omega * s)).exp();
        self.eval_with(omega, s, eu, es)
    }

    /// (C1, C2) with the two exponentials e^{−ω(D−s)} and e^{−ωs} given.
    pub fn eval_with(&self, omega: R, s: R, eu: R, es: R) -> ([R; 2], [R; 2]) {
        let mut x = [R::zero(); 2];
        let mut v = [R::zero(); 2];
        for i in 0..2 {
            x[i] = self.p0[i] + self.slope[i] * s + self.a[i] * eu + self.c[i] * es;
            v[i] = self.slope[i] + omega * (self.a[i] * eu - self.c[i] * es);
        }
        (x, v)
    }

    /// CoM position at the segment end (the next segment's x₀).
    ///
    /// (C1) at s = D with e^{−ω(D−s)} = e⁰ = 1 and e^{−ωs} = e^{−ωD}, the stored decay: the
    /// value [`ComSegment::eval`] gives there, without its two `exp`.
    pub fn end_position(&self, omega: R) -> [R; 2] {
        self.eval_with(omega, self.duration, R::one(), self.decay).0
    }
}

/// The causal bounded response to a measured torque (C6), x axis.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct TauResponse<R> {
    /// Current CoM offset e, m.
    pub offset: R,
    /// Current steady offset Δ = τ·T_TF²/C_τ² for the held τ, m.
    pub target: R,
}

impl<R: Real> TauResponse<R> {
    /// Holds torque `tau` (N·m) from now until the next sample; `gain` is T_TF²/C_τ².
    /// A non-finite τ is treated as 0: it never reaches the CoM.
    pub fn hold(&mut self, tau: R, gain: R) {
        let t = if tau.is_finite() { tau } else { R::zero() };
        self.target = t * gain;
    }
    /// Advances the offset over one sample with `decay` = e^{−ω dt} (C6).
    pub fn advance(&mut self, decay: R) {
        self.offset = self.target + (self.offset - self.target) * decay;
    }
    /// Velocity contribution ω(Δ − e), m/s.
    pub fn velocity(&self, omega: R) -> R {
        omega * (self.target - self.offset)
    }
}
