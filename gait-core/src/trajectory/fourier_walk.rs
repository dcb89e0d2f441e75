//! Seed 001's Fourier CoM walked from rest to rest: the series of [`crate::trajectory::fourier`] drives the
//! CoM through the steady steps of a straight forward walk, the exact solver of
//! [`crate::trajectory::sampler`] through the start and the stop, with a C¹ blend between them.
//!
//! **Why a blend.** The Fourier CoM (seed 001 eqs 10-17) is the periodic solution of
//! c̈ = ω²(c − p) for a ZMP that repeats forever: it has no start and no stop. A robot starts at
//! rest with its CoM between the feet, which is not on the periodic orbit (at t = 0 the series
//! puts the CoM ≈ A·(1 − sech) to the side and moving). The exact bounded solution of
//! [`crate::trajectory::com`] starts and ends at rest and, away from both ends, converges to the periodic
//! one like e^{−ω·distance} (e^{−ωT} = 0.024 per step for TLIPFM with Table 2's T = 0.64 s), and
//! `gait-core/tests/fourier.rs` shows that in the middle of a long walk the two differ by less
//! than the series' truncation bound. So the walk uses, with walk time t (0 at the end of the
//! lead-in, seed 000's t = 0) and N steps of period T:
//!
//! ```text
//!   c(t)  = c_e(t) + w(t)·(c_f(t) − c_e(t))                                      (FW1)
//!   ċ(t)  = ċ_e(t) + w(t)·(ċ_f(t) − ċ_e(t)) + w'(t)·(c_f(t) − c_e(t))            (FW2)
//!   w(t)  = s((t − T)/T) − s((t − (N − 3)T)/T),   s(u) = 3u² − 2u³ on [0, 1]      (FW3)
//! ```
//!
//! (s = 0 before, 1 after): exact for step 0, blending in over step 1, the series alone over
//! steps 2 … N − 4, blending out over step N − 3, exact for the last two steps (the last step
//! closes the feet, which breaks the periodic pattern) and the lead-out. c and ċ are continuous
//! (s is C¹); the measured τ offset of TLIPFM rides on top unchanged (it is added to c_e by the
//! sampler). The ZMP reference stays the plan's (the same knots the series expands).
//!
//! **Conditions** (else [`GaitError::NotPeriodicWalk`]): a forward walk of the same step
//! length and width throughout ([`crate::ForwardWalk`], not a footstep list), at least
//! [`MIN_FOURIER_STEPS`] steps. Terms: 1 ≤ N_terms ≤ [`MAX_FOURIER_TERMS`].
//!
//! **Cost.** Building: the series in f64 once (≈ (N_terms + 512) harmonics × 4 knots). Per
//! sample: one more evaluation of the exact segment (two `exp`) and the series (one sin/cos
//! pair and O(N_terms) multiply-adds) while w > 0.

use crate::error::GaitError;
use crate::maths::real::Real;
use crate::trajectory::fourier::FourierCom;
use crate::trajectory::plan::{ForwardWalk, GaitParams, Plan};
use crate::trajectory::sampler::{GaitSample, Sampler};

/// Most Fourier terms per axis a walk may use (the capacity of the series).
pub const MAX_FOURIER_TERMS: usize = 24;
/// Default number of Fourier terms per axis (truncation ≤ 0.1 mm on Table 2, see the tests).
pub const DEFAULT_FOURIER_TERMS: u8 = 12;
/// Fewest steps of a walk with the Fourier CoM (one exact, one blend in, one blend out, two
/// exact at the end).
pub const MIN_FOURIER_STEPS: usize = 5;

/// Which solver gives the CoM of a walk (firmware token `com=`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ComMethod {
    /// Seed 000's exact piecewise solution from rest to rest ([`crate::trajectory::com`]).
    Exact,
    /// Seed 001's Fourier series through the steady steps ([`crate::trajectory::fourier`]), blended with
    /// the exact solution at the start and the stop (this module). Needs the crate feature
    /// `fourier-com` (default; without it a sampler refuses it: `GaitError::NotBuiltIn`).
    Fourier {
        /// Terms per axis, 1 ..= [`MAX_FOURIER_TERMS`].
        terms: u8,
    },
}

/// The Fourier series of a walk and where on the walk's timeline it drives the CoM.
#[derive(Clone, Debug, PartialEq)]
pub struct FourierBlend<R> {
    series: FourierCom<R, MAX_FOURIER_TERMS>,
    /// Seed 000's t = 0 on the sampler's clock, ns.
    walk_start_ns: u64,
    /// T, s.
    period: R,
    /// Start of the blend-in (T) and of the blend-out ((N − 3)T), s of walk time.
    blend_in: R,
    blend_out: R,
}

/// s(u) = 3u² − 2u³ on [0, 1] (0 before, 1 after) and its derivative ds/du.
fn smoothstep<R: Real>(u: R) -> (R, R) {
    if u <= R::zero() {
        (R::zero(), R::zero())
    } else if u >= R::one() {
        (R::one(), R::zero())
    } else {
        let three = R::of(3.0);
        (u * u * (three - (u + u)), R::of(6.0) * u * (R::one() - u))
    }
}

impl<R: Real> FourierBlend<R> {
    /// The series of `walk` (its Table 2 geometry with the timing and ZMP shape of `params`) with
    /// `terms` terms per axis; `walk_start_ns` is the end of the lead-in on the sampler's clock.
    pub fn new(
        walk: &ForwardWalk,
        params: &GaitParams<R>,
        terms: u8,
        walk_start_ns: u64,
    ) -> Result<Self, GaitError> {
        if walk.steps < MIN_FOURIER_STEPS || !(walk.s_first == -1 || walk.s_first == 1) {
            return Err(GaitError::NotPeriodicWalk);
        }
        // Step 0 stands on the foot that does not swing first: y = S_first·S_W (see plan.rs).
        let half_width = R::of(f64::from(walk.s_first) * walk.step_width);
        let series = FourierCom::from_params(
            params,
            R::of(walk.step_length),
            half_width,
            usize::from(terms),
        )?;
        let period = params.timing.period;
        let n = walk.steps as u32;
        Ok(FourierBlend {
            series,
            walk_start_ns,
            period,
            blend_in: period,
            blend_out: R::from_u32(n - 3) * period,
        })
    }

    /// The series.
    pub fn series(&self) -> &FourierCom<R, MAX_FOURIER_TERMS> {
        &self.series
    }

    /// Walk time (s) of the sampler time `time_ns` (integer seconds and nanoseconds converted
    /// apart, so no f64 is needed on the target).
    fn walk_time(&self, time_ns: u64) -> R {
        let secs = |ns: u64| {
            let whole = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
            let frac = (ns % 1_000_000_000) as u32;
            R::from_u32(whole) + R::from_u32(frac) * R::of(1e-9)
        };
        secs(time_ns.saturating_sub(self.walk_start_ns))
            - secs(self.walk_start_ns.saturating_sub(time_ns))
    }

    /// The blend weight w(t) of (FW3) and its derivative w'(t), 1/s.
    pub fn weight(&self, t: R) -> (R, R) {
        let (a, da) = smoothstep((t - self.blend_in) / self.period);
        let (b, db) = smoothstep((t - self.blend_out) / self.period);
        (a - b, (da - db) / self.period)
    }

    /// Applies (FW1)-(FW2) to the sample `g` of the exact solver, whose CoM without τ was
    /// `exact` (position, velocity) at its time.
    pub fn apply(&self, g: &mut GaitSample<R>, exact: ([R; 2], [R; 2])) {
        let t = self.walk_time(g.time_ns);
        let (w, dw) = self.weight(t);
        if w <= R::zero() && dw == R::zero() {
            return;
        }
        let (cf, vf, _) = self.series.sample(t);
        let (ce, ve) = exact;
        for ax in 0..2 {
            if let (Some(c), Some(v), Some(cf), Some(vf), Some(ce), Some(ve)) = (
                g.com.get_mut(ax),
                g.com_vel.get_mut(ax),
                cf.get(ax),
                vf.get(ax),
                ce.get(ax),
                ve.get(ax),
            ) {
                let d = *cf - *ce;
                *c += w * d;
                *v += w * (*vf - *ve) + dw * d;
            }
        }
    }
}

/// The streaming sampler of a walk with its CoM method: [`Sampler`] alone for
/// [`ComMethod::Exact`], with a [`FourierBlend`] for [`ComMethod::Fourier`].
#[derive(Clone, Debug)]
pub struct WalkSampler<R, const N: usize> {
    sampler: Sampler<R, N>,
    fourier: Option<FourierBlend<R>>,
}

impl<R: Real, const N: usize> WalkSampler<R, N> {
    /// The sampler of `plan` (built from `walk`) at dt with the CoM of `com`.
    pub fn new(
        plan: Plan<R, N>,
        walk: &ForwardWalk,
        com: ComMethod,
        dt: f64,
    ) -> Result<Self, GaitError> {
        let mut s = WalkSampler {
            sampler: Sampler::new(plan, dt)?,
            fourier: None,
        };
        s.load_fourier(walk, com)?;
        Ok(s)
    }

    /// Storage for a walk sampler ([`Sampler::idle`], done); [`WalkSampler::rebuild`] makes it
    /// one in place.
    // Inline: the storage is then written where it lives, not built on the stack and copied.
    #[inline(always)]
    pub fn idle() -> Self {
        WalkSampler {
            sampler: Sampler::idle(),
            fourier: None,
        }
    }

    /// Makes this sampler, in place, the one [`WalkSampler::new`] would return for the plan
    /// that `fill` writes (see [`Sampler::rebuild`]); done after an error.
    pub fn rebuild(
        &mut self,
        fill: impl FnOnce(&mut Plan<R, N>) -> Result<(), GaitError>,
        walk: &ForwardWalk,
        com: ComMethod,
        dt: f64,
    ) -> Result<(), GaitError> {
        self.fourier = None;
        self.sampler.rebuild(fill, dt)?;
        let loaded = self.load_fourier(walk, com);
        if loaded.is_err() {
            self.sampler.halt();
        }
        loaded
    }

    /// The Fourier blend of `com` over the sampler's plan (none for the exact solver).
    fn load_fourier(&mut self, walk: &ForwardWalk, com: ComMethod) -> Result<(), GaitError> {
        self.fourier = match com {
            ComMethod::Exact => None,
            #[cfg(feature = "fourier-com")]
            ComMethod::Fourier { terms } => Some(FourierBlend::new(
                walk,
                self.sampler.plan().params(),
                terms,
                self.sampler.walk_start_ns(),
            )?),
            #[cfg(not(feature = "fourier-com"))]
            ComMethod::Fourier { .. } => {
                let _ = walk;
                return Err(GaitError::NotBuiltIn);
            }
        };
        Ok(())
    }

    /// The exact-solver sampler underneath (plan, stage, clock).
    pub fn sampler(&self) -> &Sampler<R, N> {
        &self.sampler
    }

    /// The Fourier blend, when the walk uses it.
    pub fn fourier(&self) -> Option<&FourierBlend<R>> {
        self.fourier.as_ref()
    }

    /// True once the lead-out is over.
    pub fn is_done(&self) -> bool {
        self.sampler.is_done()
    }

    /// The end of the lead-in (seed 000's t = 0), ns.
    pub fn walk_start_ns(&self) -> u64 {
        self.sampler.walk_start_ns()
    }

    /// The next sample with the measured torque `tau` (N·m); see [`Sampler::next`].
    pub fn next(&mut self, tau: R) -> GaitSample<R> {
        match &self.fourier {
            None => self.sampler.next(tau),
            Some(f) => {
                // Outside the blend (w = w' = 0) the exact sample stands: no second evaluation.
                let t = f.walk_time(self.sampler.now_ns());
                if f.weight(t) == (R::zero(), R::zero()) {
                    return self.sampler.next(tau);
                }
                let exact = self.sampler.com_now();
                let mut g = self.sampler.next(tau);
                f.apply(&mut g, exact);
                g
            }
        }
    }
}
