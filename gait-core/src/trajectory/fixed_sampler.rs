//! The fixed-point sampler for cores without an FPU (Cortex-M0/M3), in the number formats of
//! [`crate::maths::fixed_point`].
//!
//! Per sample the work is integer only: two fixed-point exponentials (range reduction by ln 2
//! and a degree-10 polynomial, |error| < 1e-8), com.rs C1-C2, and for the swing foot one
//! fixed-point sin/cos pair (quadrant reduction and odd/even polynomials, |error| < 4e-7).
//! Once per segment (about every 0.15-0.34 s) the segment coefficients come from the `f32` plan
//! bookkeeping of [`Sampler`] — software floats on an FPU-less core, but off the per-sample path.

use crate::error::GaitError;
use crate::maths::fixed_point::{
    exp_neg, fx, fx_sat, fx_to_f32, mul30, mul_fac, mul_fx, sat32, sin_cos, Fx, ONE_FAC,
};
use crate::robot::Side;
use crate::trajectory::plan::{Place, Plan, SwingShape};
use crate::trajectory::sampler::{Sampler, StepPhase, SupportPhase, TAU_LIMIT};

/// A foot sample in fixed point.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct FixedFoot {
    /// x, m.
    pub x: Fx,
    /// y, m.
    pub y: Fx,
    /// Height above the ground, m.
    pub z: Fx,
    /// Heading, rad.
    pub yaw: Fx,
}

/// One gait sample in fixed point (same meaning as [`crate::GaitSample`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedSample {
    /// Time since the start of the lead-in, ns.
    pub time_ns: u64,
    /// ZMP reference, m.
    pub zmp: [Fx; 2],
    /// CoM (x, y, z_c), m.
    pub com: [Fx; 3],
    /// CoM velocity, m/s.
    pub com_vel: [Fx; 2],
    /// Left and right foot.
    pub feet: [FixedFoot; 2],
    /// Support phase.
    pub phase: SupportPhase,
    /// Support foot of the current step.
    pub support_foot: Option<Side>,
    /// Steps completed.
    pub steps_done: u32,
}

impl FixedFoot {
    /// The foot in f32.
    pub fn to_f32(&self) -> crate::trajectory::swing::FootSample<f32> {
        crate::trajectory::swing::FootSample {
            x: fx_to_f32(self.x),
            y: fx_to_f32(self.y),
            z: fx_to_f32(self.z),
            yaw: fx_to_f32(self.yaw),
        }
    }
}

impl FixedSample {
    /// The sample in f32 (for the log, the stabilizer and the support polygon).
    pub fn to_f32(&self) -> crate::GaitSample<f32> {
        crate::GaitSample {
            time_ns: self.time_ns,
            zmp: self.zmp.map(fx_to_f32),
            com: self.com.map(fx_to_f32),
            com_vel: self.com_vel.map(fx_to_f32),
            feet: [self.feet[0].to_f32(), self.feet[1].to_f32()],
            phase: self.phase,
            support_foot: self.support_foot,
            steps_done: self.steps_done,
        }
    }

    /// The sample with its CoM shifted by `shift` (m, saturating to the fixed-point range).
    pub fn shifted(&self, shift: [f32; 2]) -> FixedSample {
        let mut s = *self;
        for (c, d) in s.com.iter_mut().zip(shift) {
            *c = c.saturating_add(fx_sat(d));
        }
        s
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct FixedSegment {
    p0: [Fx; 2],
    slope: [Fx; 2],
    a: [Fx; 2],
    c: [Fx; 2],
    duration: Fx,
    /// 2⁴⁶ / duration bits, so that u = s/D = (s_bits · inv_duration) >> 16 in Fac units.
    inv_duration: i64,
}

#[derive(Clone, Copy, Debug, Default)]
struct FixedPlace {
    x: Fx,
    y: Fx,
    yaw: Fx,
}

impl FixedPlace {
    fn of(p: &Place<f32>) -> Self {
        FixedPlace {
            x: fx_sat(p.x),
            y: fx_sat(p.y),
            yaw: fx_sat(p.yaw),
        }
    }
    fn foot(&self) -> FixedFoot {
        FixedFoot {
            x: self.x,
            y: self.y,
            z: Fx::ZERO,
            yaw: self.yaw,
        }
    }
}

/// The step being walked, with its places in fixed point (see [`crate::trajectory::sampler::CurrentStep`]).
#[derive(Clone, Copy, Debug)]
struct FixedStep {
    swing: Side,
    from: FixedPlace,
    to: FixedPlace,
    phase: StepPhase,
}

/// The streaming sampler with integer-only work per sample.
#[derive(Clone, Debug)]
pub struct FixedSampler<const N: usize> {
    inner: Sampler<f32, N>,
    seg: FixedSegment,
    omega: Fx,
    z_c: Fx,
    tau_gain: Fx,
    decay_dt: i64,
    tau_offset: Fx,
    swing_height: Fx,
    swing_width: Fx,
    cycloid: bool,
    /// Feet on the ground and the current swing (side, from, to, phase), converted to fixed
    /// point once per segment.
    feet: [FixedPlace; 2],
    step: Option<FixedStep>,
}

impl<const N: usize> FixedSampler<N> {
    /// A fixed-point sampler over an `f32` plan at servo period `dt` (s).
    pub fn new(plan: Plan<f32, N>, dt: f64) -> Result<Self, GaitError> {
        let mut s = FixedSampler {
            inner: Sampler::new(plan, dt)?,
            ..FixedSampler::idle()
        };
        s.load_params(dt)?;
        Ok(s)
    }

    /// Storage for a fixed-point sampler ([`Sampler::idle`] inside, done);
    /// [`FixedSampler::rebuild`] makes it one in place.
    // Inline: the storage is then written where it lives, not built on the stack and copied.
    #[inline(always)]
    pub fn idle() -> Self {
        FixedSampler {
            inner: Sampler::idle(),
            seg: FixedSegment::default(),
            omega: Fx::ZERO,
            z_c: Fx::ZERO,
            tau_gain: Fx::ZERO,
            decay_dt: 0,
            tau_offset: Fx::ZERO,
            swing_height: Fx::ZERO,
            swing_width: Fx::ZERO,
            cycloid: true,
            feet: [FixedPlace::default(); 2],
            step: None,
        }
    }

    /// Makes this sampler, in place, the one [`FixedSampler::new`] would return for the plan
    /// that `fill` writes (see [`Sampler::rebuild`]); done after an error.
    pub fn rebuild(
        &mut self,
        fill: impl FnOnce(&mut Plan<f32, N>) -> Result<(), GaitError>,
        dt: f64,
    ) -> Result<(), GaitError> {
        self.inner.rebuild(fill, dt)?;
        let loaded = self.load_params(dt);
        if loaded.is_err() {
            self.inner.halt();
        }
        loaded
    }

    /// The fixed-point constants of the inner sampler's plan at `dt` and its first segment.
    fn load_params(&mut self, dt: f64) -> Result<(), GaitError> {
        let p = *self.inner.plan().params();
        let (h, w, cycloid) = match p.swing {
            SwingShape::Cycloid { height, width } => (height, width, true),
            SwingShape::Sinusoid { height } => (height, 0.0, false),
        };
        self.omega = fx(p.model.omega)?;
        self.z_c = fx(p.model.z_c)?;
        self.tau_gain = fx(p.model.tau_to_offset)?;
        self.decay_dt = (libm::exp(-(p.model.omega as f64) * dt) * ONE_FAC as f64) as i64;
        self.tau_offset = Fx::ZERO;
        self.swing_height = fx(h)?;
        self.swing_width = fx(w)?;
        self.cycloid = cycloid;
        // The segment, the feet and the swing step from the inner sampler's first segment.
        self.load_segment();
        Ok(())
    }

    /// The `f32` bookkeeping sampler (plan queue, stage).
    pub fn inner(&self) -> &Sampler<f32, N> {
        &self.inner
    }
    /// True once the lead-out is over.
    pub fn is_done(&self) -> bool {
        self.inner.is_done()
    }

    fn load_segment(&mut self) {
        let s = self.inner.segment();
        let conv = |v: [f32; 2]| v.map(fx_sat);
        let duration = fx_sat(s.duration);
        self.seg = FixedSegment {
            p0: conv(s.p0),
            slope: conv(s.slope),
            a: conv(s.a),
            c: conv(s.c),
            duration,
            inv_duration: (1i64 << 46) / (duration.to_bits().max(1) as i64),
        };
        let stance = self.inner.stance_feet();
        self.feet = [FixedPlace::of(&stance[0]), FixedPlace::of(&stance[1])];
        self.step = self.inner.current_step().map(|c| FixedStep {
            swing: c.swing,
            from: FixedPlace::of(&c.from),
            to: FixedPlace::of(&c.to),
            phase: c.phase,
        });
    }

    /// The sample now with the measured torque `tau_mnm` (mN·m, integer as read from the bus)
    /// held until the next sample; then advances by dt.
    pub fn next(&mut self, tau_mnm: i32) -> FixedSample {
        if self.inner.sync() {
            self.load_segment();
        }
        // Local time: ns → s in 2^16 units: ns·2^16/1e9 = ns·70369/2^30 (0.0002 % low).
        let ns = self.inner.local_ns() as i64;
        let s = Fx::from_bits(sat32((ns * 70_369) >> 30));
        let w = self.omega;
        let eu = exp_neg(mul_fx(w, self.seg.duration.saturating_sub(s)));
        let es = exp_neg(mul_fx(w, s));
        let mut x = [Fx::ZERO; 2];
        let mut v = [Fx::ZERO; 2];
        let mut zmp = [Fx::ZERO; 2];
        for i in 0..2 {
            let g = &self.seg;
            zmp[i] = g.p0[i].saturating_add(mul_fx(g.slope[i], s));
            x[i] = zmp[i]
                .saturating_add(mul_fac(g.a[i], eu))
                .saturating_add(mul_fac(g.c[i], es));
            let dv = mul_fac(g.a[i], eu).saturating_sub(mul_fac(g.c[i], es));
            v[i] = g.slope[i].saturating_add(mul_fx(w, dv));
        }
        // τ response (com.rs C6) in fixed point: Δ = τ·T²/C², e ← Δ + (e − Δ)·e^{−ω dt}.
        let lim = (TAU_LIMIT * 1000.0) as i32;
        // mN·m → N·m in 2^16 units: ×65.536 = ×4_294_967/2^16 (no division).
        let tau = Fx::from_bits(sat32((tau_mnm.clamp(-lim, lim) as i64 * 4_294_967) >> 16));
        let target = mul_fx(tau, self.tau_gain);
        let offset = self.tau_offset;
        x[0] = x[0].saturating_add(offset);
        v[0] = v[0].saturating_add(mul_fx(w, target.saturating_sub(offset)));
        self.tau_offset =
            target.saturating_add(mul_fac(offset.saturating_sub(target), self.decay_dt));

        let (phase, support) = self.inner.phase();
        let mut feet = [self.feet[0].foot(), self.feet[1].foot()];
        if let Some(st) = self.step {
            if let Some(slot) = feet.get_mut(st.swing.index()) {
                match st.phase {
                    StepPhase::SecondDouble => *slot = st.to.foot(),
                    StepPhase::Single => *slot = self.swing(&st.from, &st.to, s, st.swing),
                    StepPhase::FirstDouble => {}
                }
            }
        }
        let out = FixedSample {
            time_ns: self.inner.now_ns(),
            zmp,
            com: [x[0], x[1], self.z_c],
            com_vel: v,
            feet,
            phase,
            support_foot: support,
            steps_done: self.inner.steps_done(),
        };
        self.inner.tick();
        out
    }

    /// swing.rs in fixed point: u = s/D of the single support.
    fn swing(&self, from: &FixedPlace, to: &FixedPlace, s: Fx, side: Side) -> FixedFoot {
        // u = s/D in Fac bits, by the segment's precomputed reciprocal (no 64-bit division).
        let u = ((s.to_bits().max(0) as i64 * self.seg.inv_duration) >> 16).clamp(0, ONE_FAC);
        const INV_TWO_PI: i64 = 170_891_318; // 2^30 / 2π
        const TWO_PI: i64 = 411_775; // 2π · 2^16
        const PI: i64 = 205_887;
        let (fh, fz, bulge) = if self.cycloid {
            let th = Fx::from_bits(sat32((TWO_PI * u) >> 30));
            let (sn, cs) = sin_cos(th);
            // (θ − sin θ)/2π = u − sin θ/2π, in Fac units.
            let fh = u - mul30(sn, INV_TWO_PI);
            let one_m_cos = ONE_FAC - cs;
            (
                fh,
                mul_fac(self.swing_height, one_m_cos / 2),
                mul_fac(self.swing_width, one_m_cos / 2),
            )
        } else {
            let (_, c1) = sin_cos(Fx::from_bits(sat32((PI * u) >> 30)));
            let (_, c2) = sin_cos(Fx::from_bits(sat32((TWO_PI * u) >> 30)));
            (
                (ONE_FAC - c1) / 2,
                mul_fac(self.swing_height, (ONE_FAC - c2) / 2),
                Fx::ZERO,
            )
        };
        let lerp = |a: Fx, b: Fx| a.saturating_add(mul_fac(b.saturating_sub(a), fh));
        let yaw = lerp(from.yaw, to.yaw);
        let b = if side == Side::Left { bulge } else { -bulge };
        let (sy, cy) = if self.swing_width == Fx::ZERO {
            (0, ONE_FAC)
        } else {
            sin_cos(yaw)
        };
        FixedFoot {
            x: lerp(from.x, to.x).saturating_sub(mul_fac(b, sy)),
            y: lerp(from.y, to.y).saturating_add(mul_fac(b, cy)),
            z: fz,
            yaw,
        }
    }
}
