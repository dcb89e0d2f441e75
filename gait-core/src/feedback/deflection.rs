//! Servo deflection feedback: the stance leg's joints driven to their targets from the servos'
//! Present Position (joint-level correction; the closed-loop issue, item 1).
//!
//! A position servo holds its goal with a spring, `τ = K·(q_goal − q)` (K ≈ 19 N·m/rad for an
//! XM430-W350 at the factory P gain): a stance leg under the robot's weight stands a few degrees
//! away from its targets. [`crate::feedback::compliance`] predicts that sag from the planned load and adds
//! it to the targets (feed-forward); its pitch-joint share depends on the real centre of pressure,
//! which the plan does not know (a stance ankle yields under a CoM ahead of it and every step
//! lands long, more so the faster the walk). This feedback measures the
//! deflection instead. With the target q*_j the gait sent for joint j (the IK plus the
//! feed-forwards and the gyro feedback, before this correction), the servo's Present Position
//! q̂_j read one tick later and the tick Δt:
//!
//! ```text
//!   e_j = q*_j(k − 1) − q̂_j(k)                                  deflection, rad          (D1)
//!   c_j ← sat_{c_max}(c_j + k_i·Δt·e_j)    j in the leg of a single support on it        (D2)
//!   c_j ← c_j·(1 − Δt/T_l)                 j in the swing leg                             (D3)
//!   c_j   held                              double support, standing                      (D4)
//!   q_j = q*_j + c_j                        the target sent                               (D5)
//!   k_i = k_i,0 + k_σ·σ                     σ the servos' measured softness                (D6)
//! ```
//!
//! (D6): a position servo softer than the gravity pulling the robot over its ankles cannot hold
//! a single support by its own spring (the XM430's 19 N·m/rad is about twice the reference
//! robot's M·g·z_c; at 60 % of it the stance ankle yields and the robot falls backwards), and a
//! stiff one needs no integral, where the integral's lag only costs heading. So the firmware's
//! servo survey ([`crate::measure::stiffness`], standing before the first step) measures the
//! softness σ = K_n/K̂ − 1 and the gain grows with it from the configured k_i,0 (0 by
//! default).
//!
//! (D2) is an integral on the loaded leg only: a swinging leg's error is the servos' lag, not a
//! sag, and integrating it winds up (the servos' own Position I Gain does, `servo_i_pitch`); in
//! double support the two legs close a chain through the floor, where the joints cannot all reach
//! their targets and two integrators would push against each other, so they hold. Only the
//! joints in the mask act ([`JointSet::PITCH`] by default: hip pitch, knee, ankle pitch; the roll
//! joints' sag has its feed-forward; [`JointSet::ROLL`] and [`JointSet::PITCH_AND_ROLL`] by the
//! firmware's `deflection_joints`). A missing or non-finite Present Position or target leaves
//! that joint's correction as it is; gains and limits are sanitised once in
//! [`DeflectionFeedback::new`], so any configuration is total: every c_j is finite and
//! |c_j| ≤ c_max ≤ [`MAX_CORRECTION_RAD`]. Cost: one pass over the twelve joints a tick (not
//! in the bench, whose configuration has it off); the firmware reads the masked joints' Present
//! Position in one BULK READ only while k_i > 0 (130 bytes for the six pitch servos,
//! BENCHMARKS.md's bus budget).

use crate::robot::Side;
use crate::trajectory::sampler::SupportPhase;

/// Joints per leg.
const PER_LEG: usize = 6;

/// Hard ceiling of the correction c_max, rad (≈ 11°).
pub const MAX_CORRECTION_RAD: f64 = 0.2;

/// Which joints of a leg the feedback drives, by joint index in the leg (hip yaw 0 … ankle roll 5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct JointSet(pub [bool; PER_LEG]);

impl JointSet {
    /// Hip pitch, knee and ankle pitch.
    pub const PITCH: JointSet = JointSet([false, false, true, true, true, false]);
    /// Hip roll and ankle roll.
    pub const ROLL: JointSet = JointSet([false, true, false, false, false, true]);
    /// Hip roll, hip pitch, knee, ankle pitch and ankle roll.
    pub const PITCH_AND_ROLL: JointSet = JointSet([false, true, true, true, true, true]);
    /// The sets by the index of the firmware parameter `deflection_joints` (pitch, roll, both).
    pub const BY_INDEX: [JointSet; 3] = [Self::PITCH, Self::ROLL, Self::PITCH_AND_ROLL];

    /// Whether joint `j` of the 12 (left leg then right leg) is in the set.
    pub fn contains(&self, j: usize) -> bool {
        self.0.get(j % PER_LEG).copied().unwrap_or(false)
    }
}

/// Gains and limits (SI units; module docs (D1)–(D5)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeflectionConfig {
    /// Integral gain k_i, 1/s (0 = off).
    pub ki: f32,
    /// Largest correction c_max of one joint, rad.
    pub max_rad: f32,
    /// Time constant T_l of the swing leg's decay (D3), s.
    pub leak_s: f32,
    /// The joints that act.
    pub joints: JointSet,
    /// Gain per unit of the servos' measured softness σ ([`crate::measure::stiffness`] K3),
    /// 1/s: the firmware's servo survey raises k_i by `soft_ki·σ` (D6); 0: it does not.
    pub soft_ki: f32,
}

impl DeflectionConfig {
    /// Off (the firmware's default; `docs/beyond.md` has the runs).
    pub const OFF: DeflectionConfig = DeflectionConfig {
        ki: 0.0,
        max_rad: 0.1,
        leak_s: 0.1,
        joints: JointSet::PITCH,
        soft_ki: 0.0,
    };

    /// The firmware's default: no integral on servos as stiff as their datasheet says, and
    /// `soft_ki` 4/s per unit of softness, so a servo at 60 % of its datasheet's stiffness
    /// (σ = 0.67) gets k_i ≈ 2.7/s (D6). How it was chosen: `docs/beyond.md`, "The servo
    /// survey".
    pub const DEFAULT: DeflectionConfig = DeflectionConfig {
        soft_ki: 4.0,
        ..Self::OFF
    };

    /// The integral gain for the servos' softness σ (D6): `k_i + soft_ki·σ`, 1/s (k_i alone for
    /// a non-finite or negative σ or `soft_ki`).
    pub fn ki_for(&self, softness: f32) -> f32 {
        let extra = self.soft_ki * softness;
        if extra.is_finite() && extra > 0.0 {
            self.ki + extra
        } else {
            self.ki
        }
    }

    /// Whether the feedback acts (k_i > 0 and finite).
    pub fn is_on(&self) -> bool {
        self.ki.is_finite() && self.ki > 0.0
    }
}

/// The feedback's state: one correction per joint (left leg then right leg).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeflectionFeedback {
    /// k_i·Δt.
    gain: f32,
    /// c_max, rad.
    max: f32,
    /// 1 − Δt/T_l (0 when T_l ≤ Δt: the swing leg's correction drops at once).
    decay: f32,
    /// The acting joints.
    joints: JointSet,
    /// c_j, rad.
    correction: [f32; 2 * PER_LEG],
}

impl DeflectionFeedback {
    /// The feedback for configuration `cfg` at tick period `dt_s` (s); a non-finite or
    /// negative gain, limit or period turns it off, c_max is capped at [`MAX_CORRECTION_RAD`].
    pub fn new(cfg: &DeflectionConfig, dt_s: f32) -> Self {
        let ok = |v: f32| v.is_finite() && v > 0.0;
        let on = cfg.is_on() && ok(dt_s);
        let gain = if on { cfg.ki * dt_s } else { 0.0 };
        let max = if ok(cfg.max_rad) {
            cfg.max_rad.min(MAX_CORRECTION_RAD as f32)
        } else {
            0.0
        };
        let decay = if ok(cfg.leak_s) && ok(dt_s) {
            (1.0 - dt_s / cfg.leak_s).max(0.0)
        } else {
            0.0
        };
        DeflectionFeedback {
            gain: if gain.is_finite() { gain } else { 0.0 },
            max,
            decay,
            joints: cfg.joints,
            correction: [0.0; 2 * PER_LEG],
        }
    }

    /// Sets the integral gain to `ki` (1/s) at tick period `dt_s` (s), as [`Self::new`] does;
    /// the corrections stay.
    pub fn set_gain(&mut self, ki: f32, dt_s: f32) {
        let gain = ki * dt_s;
        self.gain = if gain.is_finite() && gain > 0.0 && dt_s > 0.0 {
            gain
        } else {
            0.0
        };
    }

    /// Whether it acts (a positive gain and limit).
    pub fn is_on(&self) -> bool {
        self.gain > 0.0 && self.max > 0.0
    }

    /// The corrections c_j, rad.
    pub fn correction(&self) -> &[f32; 2 * PER_LEG] {
        &self.correction
    }

    /// One tick, (D1)–(D4): `sent` the targets q* of the last tick before the correction,
    /// `present` the Present Positions read this tick (rad; NaN where not read), `phase` the
    /// gait's support phase.
    pub fn update(
        &mut self,
        phase: SupportPhase,
        sent: &[f32; 2 * PER_LEG],
        present: &[f32; 2 * PER_LEG],
    ) {
        if !self.is_on() {
            return;
        }
        let left_stance = match phase {
            SupportPhase::Single(Side::Left) => true,
            SupportPhase::Single(Side::Right) => false,
            // (D4)
            _ => return,
        };
        let (gain, max, decay) = (self.gain, self.max, self.decay);
        for (j, ((c, s), p)) in self
            .correction
            .iter_mut()
            .zip(sent)
            .zip(present)
            .enumerate()
        {
            if !self.joints.contains(j) {
                continue;
            }
            // Joints 0..6 are the left leg's (no indexing: nothing to panic on).
            if (j < PER_LEG) == left_stance {
                // (D1), (D2)
                let e = s - p;
                if e.is_finite() {
                    // fmin/fmax, not f32::clamp: no panic path.
                    *c = libm::fminf(libm::fmaxf(*c + gain * e, -max), max);
                }
            } else {
                // (D3)
                *c *= decay;
            }
        }
    }

    /// (D5): adds the corrections to the targets `q` (rad).
    pub fn apply(&self, q: &mut [f32; 2 * PER_LEG]) {
        for (v, c) in q.iter_mut().zip(self.correction) {
            *v += c;
        }
    }
}
