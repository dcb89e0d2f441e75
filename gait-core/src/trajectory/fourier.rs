//! The Fourier-series CoM of seed 001 (Erbatur et al. 2009, eqs 3-17): a second solver for
//! periodic (steady-state) straight walking, next to the exact piecewise solution of
//! [`crate::trajectory::com`].
//!
//! **Model.** Per axis (seed 001 eqs 1-2, 8-9) c̈ = ω²(c − p), with ω² = g/z_c for the LIPM; here
//! ω is any of our models' `omega` = 1/T_TF (τ = 0). For a ZMP with period P,
//! p(t) = p̄ + Σ_k (a_k cos w_k t + b_k sin w_k t), w_k = 2πk/P, the only bounded solution is the
//! periodic one
//!
//! ```text
//!   c(t) = p̄ + Σ_k (a_k cos w_k t + b_k sin w_k t) / (1 + w_k²/ω²)              (F1)
//! ```
//!
//! (eqs 11, 15: the ZMP coefficients are the CoM ones times the factor), and a linear trend of
//! p passes to c unchanged (its second derivative is 0).
//!
//! **Time origin and geometry.** t = 0 is the *start of a step*: the ZMP is at the boundary
//! point B₀ between the previous support foot (−B, −A) and the support foot of step 0, (0, A).
//! Step n (t ∈ [nT, (n+1)T]) stands on (n·B, (−1)ⁿ·A) and its ZMP runs through the four knots
//! of [`crate::trajectory::zmp`]: p(nT) = B_n, p(nT + t₁) = S − a·e, p(nT + t₂) = S + a·e, p((n+1)T) = B_{n+1}.
//! With seed 001's t₁ = τ, t₂ = T − τ the boundary is the middle of the double support, which
//! is seed 001's origin (erratum to eq 3); it is also where our sampler's steps start, so step n
//! of a [`crate::trajectory::sampler::Sampler`] walk with support feet (n·B, (−1)ⁿ·A) is t ∈ [nT, (n+1)T]
//! here. A is signed: it is the y of step 0's support foot.
//!
//! **x** (eqs 3-6, 14-17): p_x(t) = (B/T)(t − T/2) + p̃_x(t), p̃_x periodic with period T,
//! piecewise linear through the knots; c_x = (B/T)(t − T/2) + α₀/2 + Σ_{k=1..N} (α_k cos +
//! β_k sin)(2πkt/T), with the factor **1 + 4π²k²/(ω²T²)** (erratum: eqs 15-17 print
//! 1 + π²k²/(ω²T²), wrong for a series of period T).
//!
//! **y** (eqs 7, 10-13): p_y is the trapezoid of Fig. 5 with period 2T (erratum: eq 7 needs its
//! k = 0 term, else p_y is 0 until T − τ and then jumps); c_y = a₀/2 + Σ_{k=1..N} (a_k cos +
//! b_k sin)(πkt/T), factor 1 + π²k²/(ω²T²). Both axes use harmonics k = 1..N of their own base
//! frequency (as eqs 10 and 14 do), so the y series of N terms has only its ⌈N/2⌉ odd harmonics
//! non-zero in the symmetric case (p_y(t + T) = −p_y(t)).
//!
//! **Exact coefficients.** Instead of the printed eqs 13 and 17, the coefficients are integrated
//! exactly piece by piece for any knots: on a piece p = p_u + s(t − u), t ∈ [u, v],
//!
//! ```text
//!   ∫ p cos wt dt = [p(t) sin wt / w + s cos wt / w²]_u^v                        (F2)
//!   ∫ p sin wt dt = [−p(t) cos wt / w + s sin wt / w²]_u^v
//! ```
//!
//! and a_k, b_k = (2/P)·Σ over the pieces. For seed 001's symmetric geometry they equal the
//! errata's simplified closed forms (tested):
//!
//! ```text
//!   b_k = ω²T²/(ω²T² + π²k²) · 4AT·sin(πkτ/T)/(π²k²τ)        (k odd; 0 for k even)   (eq 13)
//!   β_k = ω²T²/(ω²T² + 4π²k²) · δT²·sin(2πkτ/T)/(π²k²τ(T − 2τ))                     (eq 17)
//! ```
//!
//! and a_k = α_k = 0, α₀ = 0 (both periodic parts are odd about t = 0).
//!
//! **Eq 6, our reading.** δ = p̃_x(τ) is the peak of the periodic part. As printed,
//! δ = (T − 2τ)/T·(B/2 − b) moves the ZMP only ±b(T − 2τ)/T under the sole (erratum). We
//! implement the reading of [`crate::trajectory::zmp::ZmpShape::Continuous`]: the ZMP moves exactly ±b under
//! the sole in single support, i.e. δ = B(T − 2τ)/(2T) − b. The printed δ is our walk with
//! b replaced by b(T − 2τ)/T. Seed 001's numbers (Fig. 8): A = 0.1 m, B = 0.1 m, b = 0.04 m,
//! T = 1 s, τ = 0.2 s, N = 24: δ = −0.01 m ours, 0.006 m printed; Table II: 2T = 3 s,
//! T_s = 0.6 s, T_d = 0.9 s (τ = 0.45 s), 2A = 0.24 m, B = 0.1 m, 2b = 0.08 m: δ = −0.02 m
//! ours, 0.004 m printed (δ < 0 because b > B(T − 2τ)/(2T): in single support the ZMP moves
//! faster than the mean speed B/T, so the periodic part is below the trend at t = τ). The seed
//! gives no z_c.
//!
//! **Truncation bound.** For a continuous periodic piecewise-linear p, integrating by parts
//! twice gives |a_k + i·b_k| ≤ (2/P)·J/w_k², J = Σ_j |s_j − s_{j−1}| (the slope jumps over one
//! period), so the ZMP amplitudes fall like JP/(2π²k²) and the CoM ones, divided by the factor,
//! like Jω²P³/(8π⁴k⁴). [`FourierCom::truncation_bound`] is Σ_{k>N} √(a_k² + b_k²)/factor_k per
//! axis: the exact amplitudes for N < k ≤ N + [`TAIL_TERMS`], plus the analytic remainder
//! Jω²P³/(24π⁴M³) ≥ Σ_{k>M} (M = N + TAIL_TERMS). The same for the velocity
//! (remainder Jω²P²/(8π³M²)) and the series ZMP (remainder JP/(2π²M)). These bound the
//! truncation only, not the rounding of the evaluation (≈ 1e-6 m in f32).
//!
//! **Cost.** Building is O((N + TAIL_TERMS)·knots) in f64 (one sin/cos pair per knot, then a
//! rotation recurrence), sampling O(N): one sin/cos pair of the base angle πt/T, then the
//! rotation recurrence (cos, sin)((k+1)θ) = (cos, sin)(kθ) rotated by θ for y and by 2θ for x.

use crate::error::GaitError;
use crate::maths::real::Real;
use crate::trajectory::plan::{GaitParams, Timing};
use crate::trajectory::zmp::ZmpShape;
use core::f64::consts::PI;

/// Harmonics summed exactly (beyond the N kept terms) for the truncation bound.
pub const TAIL_TERMS: usize = 512;

/// A straight periodic walk: the ZMP geometry the Fourier solver expands.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeriodicWalk<R> {
    /// Step length B: x distance between consecutive support feet, m (signed).
    pub step_length: R,
    /// Half the lateral foot distance A, signed: the y of step 0's support foot, m.
    pub half_width: R,
    /// Step period T (half the walking period) and the single-support knots t1 < t2, s.
    pub timing: Timing<R>,
    /// ZMP shape: seed 001's `Continuous { b }`, or seed 000's `Natural`.
    pub zmp: ZmpShape<R>,
}

impl<R: Real> PeriodicWalk<R> {
    /// Seed 001 Fig. 5: half width A, step length B, ZMP travel ±b, step period T, t1 = τ, t2 = T − τ.
    pub fn seed001(a: R, b_step: R, b: R, period: R, tau: R) -> Self {
        PeriodicWalk {
            step_length: b_step,
            half_width: a,
            timing: Timing {
                t1: tau,
                t2: period - tau,
                period,
            },
            zmp: ZmpShape::Continuous { b },
        }
    }

    /// The walk of gait parameters `params` (their timing and ZMP shape) with step length B and
    /// signed half width A.
    pub fn from_params(params: &GaitParams<R>, step_length: R, half_width: R) -> Self {
        PeriodicWalk {
            step_length,
            half_width,
            timing: params.timing,
            zmp: params.zmp,
        }
    }
}

/// The walk in f64, validated, with the step-0 knots.
#[derive(Clone, Copy, Debug)]
struct Walk64 {
    b: f64,
    period: f64,
    /// Knot times 0, t1, t2, T.
    t: [f64; 4],
    /// x knots of step 0.
    x: [f64; 4],
    /// y knots of step 0.
    y: [f64; 4],
}

fn walk64<R: Real>(w: &PeriodicWalk<R>, omega: R) -> Result<Walk64, GaitError> {
    let (b, a) = (w.step_length.to_f64(), w.half_width.to_f64());
    let (t1, t2, period) = (
        w.timing.t1.to_f64(),
        w.timing.t2.to_f64(),
        w.timing.period.to_f64(),
    );
    let offs: [f64; 3] = match w.zmp {
        ZmpShape::Natural { d1, d2, a } => [d1.to_f64(), d2.to_f64(), a.to_f64()],
        ZmpShape::Continuous { b } => [b.to_f64(); 3],
    };
    let all = [
        b,
        a,
        t1,
        t2,
        period,
        omega.to_f64(),
        offs[0],
        offs[1],
        offs[2],
    ];
    if all.iter().any(|v| !v.is_finite()) {
        return Err(GaitError::NonFinite);
    }
    if period <= 0.0 {
        return Err(GaitError::NonPositivePeriod);
    }
    if !(t1 > 0.0 && t1 < t2 && t2 < period) {
        return Err(GaitError::BadPhaseTimes);
    }
    if omega.to_f64() <= 0.0 {
        return Err(GaitError::NonPositiveParameter);
    }
    if offs.iter().any(|v| *v < 0.0) {
        return Err(GaitError::ZmpOffsetOffSole);
    }
    // Previous support foot P = (−B, −A), this one S = (0, A), heading +x (see crate::trajectory::zmp).
    let (x0, y0, sole) = match w.zmp {
        ZmpShape::Natural { .. } => {
            let [d1, d2, a_sole] = offs;
            (0.5 * ((-b + d2) + (-d1)), 0.0, a_sole)
        }
        ZmpShape::Continuous { .. } => {
            let bb = offs[2];
            let after = period - t2;
            let lambda = after / (after + t1);
            (-b + bb + (b - 2.0 * bb) * lambda, -a + 2.0 * a * lambda, bb)
        }
    };
    Ok(Walk64 {
        b,
        period,
        t: [0.0, t1, t2, period],
        x: [x0, -sole, sole, x0 + b],
        y: [y0, a, a, -y0],
    })
}

/// (cos, sin) of k·θ_j for every knot j, advanced k → k + 1 by rotation.
struct Rotor<const M: usize> {
    base: [(f64, f64); M],
    cur: [(f64, f64); M],
}

impl<const M: usize> Rotor<M> {
    fn new(times: &[f64; M], period: f64) -> Self {
        let mut base = [(1.0, 0.0); M];
        for (b, t) in base.iter_mut().zip(times.iter()) {
            let th = 2.0 * PI * t / period;
            *b = (libm::cos(th), libm::sin(th));
        }
        Rotor { base, cur: base }
    }
    fn advance(&mut self) {
        for (c, b) in self.cur.iter_mut().zip(self.base.iter()) {
            *c = (c.0 * b.0 - c.1 * b.1, c.1 * b.0 + c.0 * b.1);
        }
    }
}

/// (F2) summed over the pieces: (a_k, b_k) given (cos, sin)(w·t_j) at every knot.
fn integrate(times: &[f64], values: &[f64], cs: &[(f64, f64)], w: f64, period: f64) -> (f64, f64) {
    let (mut ca, mut sa) = (0.0, 0.0);
    let pieces = times.windows(2).zip(values.windows(2)).zip(cs.windows(2));
    for ((t, p), c) in pieces {
        let (&[u, v], &[pu, pv], &[(cu, su), (cv, sv)]) = (t, p, c) else {
            continue;
        };
        let d = v - u;
        if d.is_nan() || d <= 0.0 {
            continue;
        }
        if w == 0.0 {
            ca += 0.5 * (pu + pv) * d;
            continue;
        }
        let s = (pv - pu) / d;
        ca += (pv * sv - pu * su) / w + s * (cv - cu) / (w * w);
        sa += (pu * cu - pv * cv) / w + s * (sv - su) / (w * w);
    }
    let f = 2.0 / period;
    (f * ca, f * sa)
}

/// Exact Fourier coefficients (a_k, b_k) = (2/P)∫ p·(cos, sin)(2πkt/P) dt of the piecewise-linear
/// curve through `(times[j], values[j])`, integrated over `[times[0], times[last]]` (one period);
/// `None` for mismatched lengths, fewer than two knots or a non-positive period.
pub fn fourier_coefficients(
    times: &[f64],
    values: &[f64],
    period: f64,
    k: u32,
) -> Option<(f64, f64)> {
    if times.len() != values.len() || times.len() < 2 || !period.is_finite() || period <= 0.0 {
        return None;
    }
    let w = 2.0 * PI * f64::from(k) / period;
    let mut cs = [(0.0, 0.0); 64];
    if times.len() > cs.len() {
        return None;
    }
    for (c, t) in cs.iter_mut().zip(times.iter()) {
        *c = (libm::cos(w * t), libm::sin(w * t));
    }
    Some(integrate(times, values, cs.get(..times.len())?, w, period))
}

/// Σ_j |s_j − s_{j−1}| over one period of a closed piecewise-linear curve (cyclic).
fn slope_jumps(times: &[f64], values: &[f64]) -> f64 {
    let mut first: Option<f64> = None;
    let mut prev: Option<f64> = None;
    let mut sum = 0.0;
    for (t, p) in times.windows(2).zip(values.windows(2)) {
        let (&[u, v], &[pu, pv]) = (t, p) else {
            continue;
        };
        if (v - u).is_nan() || v - u <= 0.0 {
            continue;
        }
        let s = (pv - pu) / (v - u);
        if let Some(q) = prev {
            sum += libm::fabs(s - q);
        }
        if first.is_none() {
            first = Some(s);
        }
        prev = Some(s);
    }
    if let (Some(f), Some(l)) = (first, prev) {
        sum += libm::fabs(f - l);
    }
    sum
}

/// Truncation bounds of one axis: (CoM, CoM velocity, series ZMP).
fn analytic_tail(j: f64, omega: f64, period: f64, m: f64) -> (f64, f64, f64) {
    let (w2, p) = (omega * omega, period);
    let pi2 = PI * PI;
    let com = j * w2 * p * p * p / (24.0 * pi2 * pi2 * m * m * m);
    let vel = j * w2 * p * p / (8.0 * pi2 * PI * m * m);
    let zmp = j * p / (2.0 * pi2 * m);
    (com, vel, zmp)
}

/// The Fourier-series CoM of a straight periodic walk with room for `K` terms per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FourierCom<R, const K: usize> {
    /// CoM coefficients per harmonic k = 1..=N: [α_k, β_k, a_k, b_k] (x cos, x sin, y cos, y sin).
    coef: [[R; 4]; K],
    /// N, the number of terms used.
    terms: usize,
    /// ω, 1/s.
    omega: R,
    /// Step period T, s.
    period: R,
    /// End of the first double support, s.
    t1: R,
    /// End of the single support, s.
    t2: R,
    /// Step length B, m.
    step_length: R,
    /// Means α₀/2 (x, relative to the trend (B/T)(t − T/2)) and a₀/2 (y).
    mean: [R; 2],
    /// x knots of step 0 at t = 0, t1, t2, T, m.
    knots_x: [R; 4],
    /// y knots of step 0, m.
    knots_y: [R; 4],
    /// CoM truncation bound (x, y), m.
    bound_com: [R; 2],
    /// CoM velocity truncation bound, m/s.
    bound_vel: [R; 2],
    /// Series ZMP truncation bound, m.
    bound_zmp: [R; 2],
}

fn floor_r<R: Real>(v: R) -> R {
    R::of(libm::floor(v.to_f64()))
}

fn interp<R: Real>(k: &[R; 4], t1: R, t2: R, period: R, s: R) -> R {
    let [k0, k1, k2, k3] = *k;
    if s <= t1 {
        k0 + (k1 - k0) * (s / t1)
    } else if s <= t2 {
        k1 + (k2 - k1) * ((s - t1) / (t2 - t1))
    } else {
        k2 + (k3 - k2) * ((s - t2) / (period - t2))
    }
}

/// Rounds a bound up a little so that casting to f32 cannot make it smaller.
fn up<R: Real>(v: f64) -> R {
    R::of(v * (1.0 + 1e-6) + 1e-15)
}

impl<R: Real, const K: usize> FourierCom<R, K> {
    /// Builds the series of `terms` harmonics per axis (1 ≤ terms ≤ K) for `walk` and the
    /// model's ω; computed in f64 and stored in `R` (the f32 build path).
    pub fn new(walk: &PeriodicWalk<R>, omega: R, terms: usize) -> Result<Self, GaitError> {
        if terms == 0 || terms > K {
            return Err(GaitError::BadTermCount);
        }
        let w = walk64(walk, omega)?;
        let om = omega.to_f64();
        let (t, p) = (w.period, w.period);
        // x: the periodic part p̃_x = p_x − (B/T)(t − T/2) on [0, T].
        let mut px = [0.0; 4];
        for ((o, x), tj) in px.iter_mut().zip(w.x.iter()).zip(w.t.iter()) {
            *o = x - w.b / t * (tj - 0.5 * t);
        }
        // y: two steps, [0, 2T], the second mirrored.
        let [_, t1, t2, _] = w.t;
        let ty = [0.0, t1, t2, t, t + t1, t + t2, 2.0 * t];
        let [y0, y1, y2, y3] = w.y;
        let py = [y0, y1, y2, y3, -y1, -y2, -y3];
        let mut rx = Rotor::new(&w.t, p);
        let mut ry = Rotor::new(&ty, 2.0 * p);
        let (ax0, _) = integrate(&w.t, &px, &rx.cur, 0.0, p);
        let (ay0, _) = integrate(&ty, &py, &ry.cur, 0.0, 2.0 * p);
        let mut coef = [[R::zero(); 4]; K];
        let (mut tail_c, mut tail_v, mut tail_z) = ([0.0f64; 2], [0.0f64; 2], [0.0f64; 2]);
        let last = terms + TAIL_TERMS;
        for k in 1..=last {
            let kf = k as f64;
            let wx = 2.0 * PI * kf / p;
            let wy = PI * kf / p;
            let (ax, bx) = integrate(&w.t, &px, &rx.cur, wx, p);
            let (ay, by) = integrate(&ty, &py, &ry.cur, wy, 2.0 * p);
            let fx = 1.0 + (wx / om) * (wx / om);
            let fy = 1.0 + (wy / om) * (wy / om);
            if let Some(c) = coef.get_mut(k - 1).filter(|_| k <= terms) {
                *c = [
                    R::of(ax / fx),
                    R::of(bx / fx),
                    R::of(ay / fy),
                    R::of(by / fy),
                ];
            } else {
                let (mx, my) = (libm::hypot(ax, bx), libm::hypot(ay, by));
                tail_z[0] += mx;
                tail_z[1] += my;
                tail_c[0] += mx / fx;
                tail_c[1] += my / fy;
                tail_v[0] += wx * mx / fx;
                tail_v[1] += wy * my / fy;
            }
            rx.advance();
            ry.advance();
        }
        let m = last as f64;
        let (cx, vx, zx) = analytic_tail(slope_jumps(&w.t, &px), om, p, m);
        let (cy, vy, zy) = analytic_tail(slope_jumps(&ty, &py), om, 2.0 * p, m);
        let tw = walk.timing;
        Ok(FourierCom {
            coef,
            terms,
            omega: R::of(om),
            period: R::of(p),
            t1: tw.t1,
            t2: tw.t2,
            step_length: R::of(w.b),
            mean: [R::of(0.5 * ax0), R::of(0.5 * ay0)],
            knots_x: w.x.map(R::of),
            knots_y: w.y.map(R::of),
            bound_com: [up(tail_c[0] + cx), up(tail_c[1] + cy)],
            bound_vel: [up(tail_v[0] + vx), up(tail_v[1] + vy)],
            bound_zmp: [up(tail_z[0] + zx), up(tail_z[1] + zy)],
        })
    }

    /// Builds from gait parameters (timing, ZMP shape, model ω) with step length B and signed
    /// half width A; see [`FourierCom::new`].
    pub fn from_params(
        params: &GaitParams<R>,
        step_length: R,
        half_width: R,
        terms: usize,
    ) -> Result<Self, GaitError> {
        Self::new(
            &PeriodicWalk::from_params(params, step_length, half_width),
            params.model.omega,
            terms,
        )
    }

    /// The number of terms N per axis.
    pub fn terms(&self) -> usize {
        self.terms
    }

    /// ω, 1/s.
    pub fn omega(&self) -> R {
        self.omega
    }

    /// The step period T, s (x period T, y period 2T).
    pub fn period(&self) -> R {
        self.period
    }

    /// CoM coefficients [α_k, β_k, a_k, b_k] of harmonic k = 1..=N (`None` otherwise).
    pub fn com_coefficients(&self, k: usize) -> Option<[R; 4]> {
        if k == 0 || k > self.terms {
            return None;
        }
        self.coef.get(k - 1).copied()
    }

    /// ZMP coefficients of harmonic k: the CoM ones times the factors 1 + w_k²/ω² (eqs 11, 15).
    pub fn zmp_coefficients(&self, k: usize) -> Option<[R; 4]> {
        let c = self.com_coefficients(k)?;
        let r = R::of(PI) * R::from_u32(k as u32) / (self.period * self.omega);
        let fy = R::one() + r * r;
        let fx = R::one() + R::of(4.0) * r * r;
        Some([c[0] * fx, c[1] * fx, c[2] * fy, c[3] * fy])
    }

    /// The constant terms (α₀/2 of the x periodic part about the trend (B/T)(t − T/2), a₀/2).
    pub fn mean(&self) -> [R; 2] {
        self.mean
    }

    /// Upper bound of the CoM truncation error Σ_{k>N} |c_k| per axis (x, y), m.
    pub fn truncation_bound(&self) -> [R; 2] {
        self.bound_com
    }

    /// Upper bound of the CoM velocity truncation error Σ_{k>N} w_k|c_k| (x, y), m/s.
    pub fn velocity_truncation_bound(&self) -> [R; 2] {
        self.bound_vel
    }

    /// Upper bound of the series ZMP's truncation error Σ_{k>N} |p_k| (x, y), m.
    pub fn zmp_truncation_bound(&self) -> [R; 2] {
        self.bound_zmp
    }

    /// The truncated series at time `t` (s, t = 0 at the start of step 0): CoM (x, y), CoM
    /// velocity, and the ZMP of the series c − c̈/ω², which the series satisfies exactly.
    pub fn sample(&self, t: R) -> ([R; 2], [R; 2], [R; 2]) {
        let period = self.period;
        let two_p = period + period;
        let tm = t - floor_r(t / two_p) * two_p;
        let base = R::of(PI) / period;
        let th = base * tm;
        let (s1, c1) = (th.sin(), th.cos());
        let (s2, c2) = (R::of(2.0) * s1 * c1, c1 * c1 - s1 * s1);
        let (mut cy, mut sy) = (R::one(), R::zero());
        let (mut cx, mut sx) = (R::one(), R::zero());
        let mut k = R::zero();
        let mut pos = [R::zero(); 2];
        let mut vel = [R::zero(); 2];
        let mut acc = [R::zero(); 2];
        for c in self.coef.iter().take(self.terms) {
            k += R::one();
            (cy, sy) = (cy * c1 - sy * s1, sy * c1 + cy * s1);
            (cx, sx) = (cx * c2 - sx * s2, sx * c2 + cx * s2);
            let [ax, bx, ay, by] = *c;
            let wy = k * base;
            let wx = wy + wy;
            let vx = ax * cx + bx * sx;
            let vy = ay * cy + by * sy;
            pos[0] += vx;
            pos[1] += vy;
            vel[0] += wx * (bx * cx - ax * sx);
            vel[1] += wy * (by * cy - ay * sy);
            acc[0] -= wx * wx * vx;
            acc[1] -= wy * wy * vy;
        }
        let slope = self.step_length / period;
        let trend = slope * (t - R::of(0.5) * period);
        let com = [trend + self.mean[0] + pos[0], self.mean[1] + pos[1]];
        let inv_w2 = R::one() / (self.omega * self.omega);
        let zmp = [com[0] - acc[0] * inv_w2, com[1] - acc[1] * inv_w2];
        (com, [slope + vel[0], vel[1]], zmp)
    }

    /// The exact piecewise-linear ZMP reference at time `t` (the knots of [`crate::trajectory::zmp`]).
    pub fn zmp_reference(&self, t: R) -> [R; 2] {
        let period = self.period;
        let n = floor_r(t / period);
        let s = t - n * period;
        let odd = n - R::of(2.0) * floor_r(n * R::of(0.5));
        let sign = R::one() - R::of(2.0) * odd;
        let x = n * self.step_length + interp(&self.knots_x, self.t1, self.t2, period, s);
        let y = sign * interp(&self.knots_y, self.t1, self.t2, period, s);
        [x, y]
    }
}
