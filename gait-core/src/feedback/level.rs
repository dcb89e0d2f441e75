//! The swing sole kept level: the swing leg's ankles turn the sole back by the trunk's
//! deviation from its attitude baseline and by the swing leg's measured lag ([`SoleLevel`];
//! part of the step adaptation, [`crate::feedback::catch::StepAdapter`]).
//!
//! # Law
//! The IK puts both soles parallel to the pelvis (level for an upright trunk). A trunk turned
//! off its baseline by (φ − φ̄, θ − θ̄) turns the swing sole with it: pushed back, the robot
//! lands its swing foot heel first, the heel pins the rotation before the foot is where the
//! catch wants it, and the robot rolls back over both heels. The swing leg's ankle targets
//! turn the sole back by the trunk's deviation:
//!
//! ```text
//!   Δq_ankle_pitch = −w·(k_θ·(θ − θ̄) + k_q·e_q),   Δq_ankle_roll = −k_φ·w·(φ − φ̄),
//!   e_q = (q̂_hp − q*_hp) + (q̂_k − q*_k) + (q̂_ap − q^s_ap)     the swing leg's pitch lag
//!   |Δq| ≤ Δq_max ([`MAX_LEVEL_RAD`])                                                 (A10)
//!   w ← w ± dt/T_r toward 1 on the swing leg, toward 0 on a leg on the ground
//! ```
//!
//! The three pitch joints are parallel, so the sole's pitch in the world is θ + q_hp + q_k +
//! q_ap and k_θ = 1 levels it exactly for joints that follow their targets; the ankle roll
//! turns the sole about the same axis as the trunk's roll up to the hip's pitch in between
//! (small in a swing), so k_φ = 1 levels it to first order. w ramps the correction in over T_r
//! after lift-off and out over T_r after touchdown (continuous joint targets; a foot on the
//! ground keeps the plan's ankle). A missing attitude holds the last deviation while w ramps.
//! The levelling runs with the catching step off (`gain` = 0) too, on the same baseline ((A2)
//! of [`crate::feedback::catch`], which feeds it the deviation).
//!
//! Servos that lag their targets turn the sole by the sum of their lags (k_q, the firmware's
//! `catch_level_joints`; 0 by default): e_q takes the Present Position q̂ (read at the start of
//! a tick) of the hip pitch and the knee against their targets q* of the tick before (the IK's,
//! before any correction: the plan's sole) and the ankle's against the target q^s it was sent
//! (its own lag, this correction included). Equal lags of the three parallel joints cancel
//! (their targets sum to the sole's pitch); what is left turns the sole. The ankle term closes
//! a loop through that servo with a tick's delay, e(k) ≈ e_o − k_q·e(k − 1): it converges for
//! k_q < 1 (at k_q = 1 it rings). A missing reading holds the last e_q of that leg; it is
//! forgotten once the leg is on the ground.

use crate::feedback::catch::StepAdaptation;
use crate::maths::real::Real;
use crate::robot::{Side, ANKLE_PITCH, ANKLE_ROLL, JOINTS_PER_LEG, LEG_JOINTS};
use crate::trajectory::sampler::SupportPhase;

/// Largest correction of an ankle joint by the swing sole's levelling (A10), rad.
pub const MAX_LEVEL_RAD: f32 = 0.3;

/// The swing sole's levelling (A10): the legs' weights and ankle corrections.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoleLevel {
    /// Gains k_θ, k_φ on the trunk's pitch and roll deviation.
    gains: [f32; 2],
    /// Gain k_q on the swing leg's measured pitch lag e_q.
    k_joints: f32,
    /// The measured pitch lag e_q per leg (left, right), rad.
    lag: [f32; 2],
    /// The per-tick weight step dt/T_r.
    step: f32,
    /// The weight w per leg (left, right), 0..1.
    w: [f32; 2],
    /// The trunk's last deviation from its baseline (pitch, roll), rad.
    dev: [f32; 2],
    /// The ankle corrections per leg (left, right): (pitch, roll), rad.
    level: [[f32; 2]; 2],
}

impl SoleLevel {
    /// The levelling of `cfg` (`level_pitch`, `level_roll`, `level_ramp_s`) with ticks of
    /// `dt_s` seconds; a non-positive or non-finite tick turns it off.
    pub fn new(cfg: &StepAdaptation, dt_s: f32) -> Self {
        let cfg = cfg.limited();
        let ok = dt_s.is_finite() && dt_s > 0.0;
        SoleLevel {
            gains: if ok {
                [cfg.level_pitch, cfg.level_roll]
            } else {
                [0.0; 2]
            },
            k_joints: if ok { cfg.level_joints } else { 0.0 },
            lag: [0.0; 2],
            // A ramp shorter than a tick: w jumps (at most one tick's step of 1).
            step: if ok && cfg.level_ramp_s > dt_s {
                dt_s / cfg.level_ramp_s
            } else {
                1.0
            },
            w: [0.0; 2],
            dev: [0.0; 2],
            level: [[0.0; 2]; 2],
        }
    }

    /// Whether the levelling runs (a finite positive gain on pitch, roll or the joints' lag).
    pub fn is_on(&self) -> bool {
        self.gains
            .iter()
            .chain([&self.k_joints])
            .any(|k| k.is_finite() && *k > 0.0)
    }

    /// The swing legs' measured pitch lag e_q (left, right), rad; a non-finite one keeps the
    /// leg's last.
    pub fn set_joint_lag(&mut self, lag: [f32; 2]) {
        for (l, v) in self.lag.iter_mut().zip(lag) {
            if v.is_finite() {
                *l = v;
            }
        }
    }

    /// One tick: the trunk's `deviation` from its baseline (pitch, roll), rad (`None` when
    /// not measured: the last one holds), and the support `phase`; the weights one tick toward
    /// the legs' phase, then the corrections from the deviation.
    pub fn update(&mut self, deviation: Option<[f32; 2]>, phase: SupportPhase) {
        if let Some(dev) = deviation {
            self.dev = dev;
        }
        let swing = phase.swing();
        let [dev_pitch, dev_roll] = self.dev;
        let [k_pitch, k_roll] = self.gains;
        let k_joints = self.k_joints;
        let step = self.step;
        for (((w, c), lag), side) in self
            .w
            .iter_mut()
            .zip(self.level.iter_mut())
            .zip(self.lag.iter_mut())
            .zip([Side::Left, Side::Right])
        {
            let swinging = swing == Some(side);
            let target = if swinging { 1.0 } else { 0.0 };
            *w += (target - *w).clamp_to(-step, step);
            if !swinging && *w <= 0.0 {
                *lag = 0.0;
            }
            let v = [
                -k_pitch * *w * dev_pitch - k_joints * *w * *lag,
                -k_roll * *w * dev_roll,
            ];
            *c = if v.iter().all(|x| x.is_finite()) {
                v.map(|x| x.clamp(-MAX_LEVEL_RAD, MAX_LEVEL_RAD))
            } else {
                [0.0; 2]
            };
        }
    }

    /// The ankle corrections (pitch, roll) of the left and the right leg, rad, each within
    /// ±[`MAX_LEVEL_RAD`].
    pub fn corrections(&self) -> [[f32; 2]; 2] {
        self.level
    }

    /// Adds the corrections to the joint targets `q` (left leg then right leg, rad).
    pub fn apply(&self, q: &mut [f32; LEG_JOINTS]) {
        for (leg, [pitch, roll]) in self.level.into_iter().enumerate() {
            let base = leg * JOINTS_PER_LEG;
            if let Some(v) = q.get_mut(base + ANKLE_PITCH) {
                *v += pitch;
            }
            if let Some(v) = q.get_mut(base + ANKLE_ROLL) {
                *v += roll;
            }
        }
    }
}
