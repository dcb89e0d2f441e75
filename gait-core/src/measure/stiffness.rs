//! The leg servos' stiffness, measured while the robot stands: the servo survey.
//!
//! A position servo without integral action holds its joint with a spring, `τ = K·(q_goal − q)`
//! ([`crate::feedback::compliance`]); its K is the datasheet's only for the datasheet's servo at
//! its nominal supply. The drive's PWM scales the motor's voltage, so K grows with the stall
//! torque, the supply voltage and the Position P Gain: a weaker motor, a sagging battery or a
//! warm servo all make it softer, by as much as half. While the robot stands on both feet before
//! its first step, the survey compares the pitch servos' (hip pitch, knee, ankle pitch: no
//! Position I Gain by default, so their steady error is the sag) Present Position `q̂_j` with
//! the goal `q_j` sent on the tick before and with the torque `τ_j` the load model (C2) says
//! each must deliver, and fits the one K that explains all of them (least squares of
//! `e_j = τ_j/K` over the joints j and the ticks n of the survey's window):
//!
//! ```text
//! e_j(n) = q_j(n − 1) − q̂_j(n)                                                    (K1)
//! K̂ = Σ τ_j(n)² / Σ τ_j(n)·e_j(n)                                                  (K2)
//! σ = clamp(K_n/K̂ − 1, 0, σ_max)     softness against the datasheet's K_n          (K3)
//! ```
//!
//! The window starts `settle` after the first standing tick (the ramp's lag decays) and takes
//! `span` of standing ticks; a walk that leaves standing before the window is full takes what
//! it has. A joint whose read failed (NaN) or whose torque is not finite is left out of the
//! sums. No sag at all (Σ τe ≤ 0: servos with integral action, which hold any load without
//! one) and too little load to tell (Σ τ² below [`MIN_TORQUE_NM`]² a sample) give no result:
//! the stiffness is then unknown, not infinite. Nor does a fit whose RMS sag
//! `sqrt(Σ τ²/n)/K̂` is below [`MIN_SAG_RAD`]: such a sag is the encoder's rounding of the goal
//! (servos with integral action read as noise), not a spring. A fit above [`MAX_STIFFNESS`] is
//! reported as that. Errors: the load model's masses (a heavier robot than modelled reads
//! softer, in proportion) and their places (a CoM ahead of or behind the model's moves every
//! pitch joint's torque: the ankles then read stiffer or softer), the gear's Coulomb friction
//! (it resists the sag: K̂ reads high by about friction/τ) and the encoder's step (1.5 mrad)
//! against sags of 10–30 mrad.
//!
//! The sums are one multiply-add pair per pitch joint a tick of the window; the firmware adds the
//! load model's torques (two leg chains) and one BULK READ of the six pitch servos' Present
//! Position on those ticks only.

use crate::robot::{ANKLE_PITCH, HIP_PITCH, JOINTS_PER_LEG, KNEE, LEG_JOINTS};
use crate::trajectory::sampler::SupportPhase;

/// The firmware's settling time before the window, s.
pub const SETTLE_S: f32 = 0.3;

/// The firmware's window, s (standing before the first step lasts the plan's lead-in).
pub const SPAN_S: f32 = 0.6;

/// The largest stiffness the survey reports, N·m/rad.
pub const MAX_STIFFNESS: f32 = 1000.0;

/// The smallest RMS sag the fit must explain for a result, rad: two encoder steps of an
/// X-series servo (2π/4096 = 1.53 mrad each).
pub const MIN_SAG_RAD: f32 = 0.003;

/// The smallest mean |τ| per surveyed joint sample for a result, N·m.
pub const MIN_TORQUE_NM: f32 = 0.02;

/// Largest softness σ (K3): a servo a third of its datasheet's stiffness or softer.
pub const MAX_SOFTNESS: f32 = 2.0;

/// What the survey found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stiffness {
    /// K̂ (K2), N·m/rad, in (0, [`MAX_STIFFNESS`]].
    pub k: f32,
    /// Joint samples in the sums.
    pub samples: u16,
}

impl Stiffness {
    /// The softness σ (K3) against the datasheet stiffness `k_nominal` (N·m/rad); 0 for a
    /// non-finite or non-positive `k_nominal`.
    pub fn softness(&self, k_nominal: f32) -> f32 {
        let s = k_nominal / self.k - 1.0;
        if s.is_finite() && k_nominal > 0.0 {
            // fmin/fmax, not f32::clamp: no panic path.
            libm::fminf(libm::fmaxf(s, 0.0), MAX_SOFTNESS)
        } else {
            0.0
        }
    }

    /// This stiffness at supply `volts` when it was measured at `surveyed_volts` (the drive's
    /// torque, and so K, scales with the supply); unchanged when either is not a positive
    /// finite number.
    pub fn at_supply(&self, volts: f32, surveyed_volts: f32) -> Stiffness {
        let k = self.k * volts / surveyed_volts;
        if volts > 0.0 && surveyed_volts > 0.0 && k.is_finite() && k > 0.0 {
            Stiffness {
                k: k.min(MAX_STIFFNESS),
                ..*self
            }
        } else {
            *self
        }
    }
}

/// The survey's state: the window and the sums of (K2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StiffnessSurvey {
    /// Standing ticks to let pass before the window.
    settle: u16,
    /// Standing ticks in the window.
    span: u16,
    /// Standing ticks seen.
    seen: u16,
    /// Σ τ², N²·m².
    tt: f32,
    /// Σ τ·e, N·m·rad.
    te: f32,
    /// Joint samples summed.
    samples: u16,
    /// The result, once the window closed (`Some(None)`: closed without a result).
    done: Option<Option<Stiffness>>,
}

impl StiffnessSurvey {
    /// A survey that starts `settle_s` after the first standing tick and lasts `span_s` (s) at
    /// tick period `dt_s`; a non-finite or non-positive period gives a survey that never
    /// opens its window (no result).
    pub fn new(settle_s: f32, span_s: f32, dt_s: f32) -> Self {
        let ticks = |s: f32| {
            let n = s / dt_s;
            if n.is_finite() && n > 0.0 {
                // Saturating float-to-int conversion.
                n as u16
            } else {
                0
            }
        };
        let ok = dt_s.is_finite() && dt_s > 0.0;
        StiffnessSurvey {
            settle: ticks(settle_s),
            span: if ok { ticks(span_s).max(1) } else { 0 },
            seen: 0,
            tt: 0.0,
            te: 0.0,
            samples: 0,
            done: if ok { None } else { Some(None) },
        }
    }

    /// A survey that is not wanted: closed from the start, without a result.
    pub const fn off() -> Self {
        StiffnessSurvey {
            settle: 0,
            span: 0,
            seen: 0,
            tt: 0.0,
            te: 0.0,
            samples: 0,
            done: Some(None),
        }
    }

    /// Whether the next tick's Present Positions are wanted: standing, the settling over, the
    /// window still open.
    pub fn wants(&self, phase: SupportPhase) -> bool {
        self.done.is_none() && phase == SupportPhase::Standing && self.seen >= self.settle
    }

    /// Whether the window has closed.
    pub fn is_done(&self) -> bool {
        self.done.is_some()
    }

    /// The result, once the window has closed (None before, or when it gave none).
    pub fn result(&self) -> Option<Stiffness> {
        self.done.flatten()
    }

    /// One tick in `phase` with the goals `sent` on the tick before (rad), this tick's Present
    /// Positions `present` (rad, NaN where not read) and the torques `tau` (N·m) the load model
    /// gives for the sent goals; the window closes after its span, or at the first tick that
    /// is not standing once it has samples. Returns the result when this tick closed it.
    pub fn add(
        &mut self,
        phase: SupportPhase,
        sent: &[f32; LEG_JOINTS],
        present: &[f32; LEG_JOINTS],
        tau: &[f32; LEG_JOINTS],
    ) -> Option<Option<Stiffness>> {
        if self.done.is_some() {
            return None;
        }
        if phase != SupportPhase::Standing {
            return (self.seen > self.settle).then(|| self.close());
        }
        self.seen = self.seen.saturating_add(1);
        if self.seen <= self.settle {
            return None;
        }
        for leg in 0..2 {
            for j in [HIP_PITCH, KNEE, ANKLE_PITCH].map(|j| leg * JOINTS_PER_LEG + j) {
                let (Some(&q), Some(&p), Some(&t)) = (sent.get(j), present.get(j), tau.get(j))
                else {
                    continue;
                };
                let e = q - p;
                if e.is_finite() && t.is_finite() {
                    self.tt += t * t;
                    self.te += t * e;
                    self.samples = self.samples.saturating_add(1);
                }
            }
        }
        (self.seen >= self.settle.saturating_add(self.span)).then(|| self.close())
    }

    /// Closes the window: (K2) from the sums.
    fn close(&mut self) -> Option<Stiffness> {
        let n = f32::from(self.samples);
        let enough = self.samples > 0 && self.tt >= n * MIN_TORQUE_NM * MIN_TORQUE_NM;
        let k = self.tt / self.te;
        // sqrt(Σ τ²/n)/K̂ ≥ MIN_SAG_RAD, squared.
        let sags = self.tt / n >= (MIN_SAG_RAD * k) * (MIN_SAG_RAD * k);
        let k = k.min(MAX_STIFFNESS);
        let r =
            (enough && sags && self.te > 0.0 && k.is_finite() && k > 0.0).then_some(Stiffness {
                k,
                samples: self.samples,
            });
        self.done = Some(r);
        r
    }
}
