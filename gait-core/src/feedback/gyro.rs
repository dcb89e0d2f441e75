//! Gyro balance feedback: damping of the trunk's rotation through the joints of the legs on the
//! ground (the classic ankle/hip gyro feedback of kid-size walking engines), applied by the firmware to
//! the joint targets of every walking tick.
//!
//! # Law
//! With the trunk's roll and pitch rates ω_x, ω_y (gyro, rad/s, body frame) and the joint
//! conventions of [`crate::kinematics::leg`] (positive = right-hand rule about the pelvis axes,
//! the same on both legs), each leg in contact with the ground gets
//!
//! ```text
//! Δq_ankle_pitch = sat(k_a·ω_y)   Δq_ankle_roll = sat(k_a·ω_x)
//! Δq_hip_pitch   = sat(k_h·ω_y)   Δq_hip_roll   = sat(k_h·ω_x)        sat = clamp to ±Δ_max
//! ```
//!
//! With the foot flat on the ground, a positive ankle pitch rotates the calf by −Δq about y
//! (backwards): a trunk pitching forward (ω_y > 0) is pushed back, and likewise about x; a
//! positive hip pitch rotates the pelvis backwards over the thigh. So the law is a damper: it
//! takes energy out of the rotation the position servos would otherwise only follow with their
//! lag. The swing leg is left alone (it would only move the foot in the air). Gains in seconds
//! (rad of joint per rad/s of trunk rate); 0 turns a term off. A missing or non-finite gyro
//! sample gives no correction.
//!
//! # The servos' stiffness
//! Δq acts through the position servo's spring: the damping torque per rad/s of trunk rate is
//! K·k. Servos stiffer than their datasheet (the firmware's servo survey measures K̂,
//! [`crate::measure::stiffness`]) would damp harder than the gains were chosen for and turn the
//! robot's steps into yaw, so with `follow_stiffness` both gains are scaled to keep the
//! datasheet servo's damping torque, down to half the configured gains:
//!
//! ```text
//! k ← k·clamp(K_n/K̂, 1/2, 1)                                                        (G3)
//! ```
//!
//! Softer servos keep the configured gains: the sweep of the servo family found scaling them up
//! no better (`docs/beyond.md`, "The servo survey"). The floor keeps the damping when K̂ reads
//! far above the datasheet (the survey's error: a CoM off the model reads the ankles stiff).

use super::{JointCorrection, JointInput, Measured};
use crate::robot::Side;
use crate::robot::LEG_JOINTS;
use crate::trajectory::sampler::SupportPhase;

/// The smallest share of the configured gains (G3) leaves.
pub const MIN_STIFFNESS_SCALE: f32 = 0.5;

/// Gyro feedback gains and limit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroFeedback {
    /// Ankle gain k_a, s.
    pub ankle: f32,
    /// Hip gain k_h, s.
    pub hip: f32,
    /// Largest correction of one joint, rad.
    pub max_rad: f32,
    /// Whether the gains follow the servos' measured stiffness (G3).
    pub follow_stiffness: bool,
}

impl GyroFeedback {
    /// The firmware's default: k_a = 0.1 s, k_h = 0.1 s, ±0.1 rad (with the compliance
    /// feed-forward of [`crate::feedback::compliance`] the hips' 0.1 s tracks better than 0.05 s; how it was
    /// chosen: `docs/beyond.md`, "Gyro damping").
    pub const DEFAULT: GyroFeedback = GyroFeedback {
        ankle: 0.1,
        hip: 0.1,
        max_rad: 0.1,
        follow_stiffness: true,
    };

    /// No feedback.
    pub const OFF: GyroFeedback = GyroFeedback {
        ankle: 0.0,
        hip: 0.0,
        max_rad: 0.1,
        follow_stiffness: false,
    };

    /// These gains for servos of measured stiffness `k_measured` against the datasheet's
    /// `k_nominal` (N·m/rad): (G3) with `follow_stiffness`, at least [`MIN_STIFFNESS_SCALE`]
    /// of them; unchanged without it, or for a stiffness that is not a positive finite number.
    pub fn for_stiffness(&self, k_nominal: f32, k_measured: f32) -> GyroFeedback {
        let f = k_nominal / k_measured;
        if !(self.follow_stiffness && f.is_finite() && f > 0.0 && k_nominal > 0.0) {
            return *self;
        }
        let f = libm::fmaxf(libm::fminf(f, 1.0), MIN_STIFFNESS_SCALE);
        GyroFeedback {
            ankle: self.ankle * f,
            hip: self.hip * f,
            ..*self
        }
    }

    /// Adds the feedback for trunk rates `gyro` = [ω_x, ω_y] to the 12 joint targets `q` (left
    /// leg then right leg, joint order) of the legs on the ground in `phase`.
    pub fn apply(&self, q: &mut [f32; 12], phase: SupportPhase, gyro: Option<[f32; 2]>) {
        self.for_each(phase, gyro, |j, d| {
            if let Some(v) = q.get_mut(j) {
                *v += d;
            }
        });
    }

    /// The corrections of [`GyroFeedback::apply`] one by one: `add(joint index, Δq rad)` for
    /// every joint it changes (the fixed-point path adds them to its I16F16 angles).
    pub fn for_each(
        &self,
        phase: SupportPhase,
        gyro: Option<[f32; 2]>,
        add: impl FnMut(usize, f32),
    ) {
        let Some([wx, wy]) = gyro.filter(|g| g.iter().all(|v| v.is_finite())) else {
            return;
        };
        let m = if self.max_rad.is_finite() {
            libm::fmaxf(self.max_rad, 0.0)
        } else {
            0.0
        };
        // fmin/fmax, not f32::clamp: no panic path (clamp asserts min ≤ max).
        let sat = |v: f32| {
            if v.is_finite() {
                libm::fminf(libm::fmaxf(v, -m), m)
            } else {
                0.0
            }
        };
        let (ankle_pitch, ankle_roll) = (sat(self.ankle * wy), sat(self.ankle * wx));
        let (hip_pitch, hip_roll) = (sat(self.hip * wy), sat(self.hip * wx));
        spread(phase, [hip_roll, hip_pitch, ankle_pitch, ankle_roll], add);
    }
}

/// [`GyroFeedback`] in integers for FPU-less cores: rates in µrad/s as the IMU sends them,
/// corrections in I16F16 rad bits (gains and limit converted once).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedGyroFeedback {
    /// Δq bits = ω (µrad/s) · k >> 32, ankle and hip.
    ankle_k: i64,
    hip_k: i64,
    /// Largest correction, I16F16 bits.
    max_bits: i64,
}

impl FixedGyroFeedback {
    /// The integer form of `g` (non-finite gains count as 0, as a non-finite product there).
    pub fn new(g: &GyroFeedback) -> Self {
        let k = |v: f32| {
            if v.is_finite() {
                (f64::from(v) * 1e-6 * 65536.0 * 4_294_967_296.0) as i64
            } else {
                0
            }
        };
        let m = if g.max_rad.is_finite() {
            libm::fmaxf(g.max_rad, 0.0)
        } else {
            0.0
        };
        FixedGyroFeedback {
            ankle_k: k(g.ankle),
            hip_k: k(g.hip),
            max_bits: (f64::from(m) * 65536.0) as i64,
        }
    }

    /// [`GyroFeedback::for_each`] for trunk rates `gyro` = [ω_x, ω_y] in µrad/s:
    /// `add(joint index, Δq in I16F16 rad bits)`.
    pub fn for_each(
        &self,
        phase: SupportPhase,
        gyro_urad_s: Option<[i32; 2]>,
        add: impl FnMut(usize, i32),
    ) {
        let Some([wx, wy]) = gyro_urad_s.map(|g| g.map(i64::from)) else {
            return;
        };
        let m = self.max_bits;
        // |ω| < 2³¹, |k| < 2³² for gains under ≈ 60 s: the product fits.
        let sat = |w: i64, k: i64| {
            let k = k.clamp(-(1 << 32), 1 << 32);
            ((w * k) >> 32).clamp(-m, m) as i32
        };
        let (ankle_pitch, ankle_roll) = (sat(wy, self.ankle_k), sat(wx, self.ankle_k));
        let (hip_pitch, hip_roll) = (sat(wy, self.hip_k), sat(wx, self.hip_k));
        spread(phase, [hip_roll, hip_pitch, ankle_pitch, ankle_roll], add);
    }
}

/// The four corrections [hip roll, hip pitch, ankle pitch, ankle roll] to the joints of the legs
/// on the ground in `phase`.
fn spread<T: Copy>(phase: SupportPhase, d: [T; 4], mut add: impl FnMut(usize, T)) {
    let [hip_roll, hip_pitch, ankle_pitch, ankle_roll] = d;
    let legs: [bool; 2] = match phase {
        SupportPhase::Single(Side::Left) => [true, false],
        SupportPhase::Single(Side::Right) => [false, true],
        _ => [true, true],
    };
    for (leg, on_ground) in legs.into_iter().enumerate() {
        if !on_ground {
            continue;
        }
        for (j, d) in [
            (1, hip_roll),
            (2, hip_pitch),
            (4, ankle_pitch),
            (5, ankle_roll),
        ] {
            add(6 * leg + j, d);
        }
    }
}

impl JointCorrection for GyroFeedback {
    fn correct_joints(
        &mut self,
        m: &Measured<'_>,
        input: &JointInput<'_>,
        q: &mut [f32; LEG_JOINTS],
    ) {
        self.apply(q, input.phase, m.gyro);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gains_follow_a_stiffer_servo_and_keep_a_softer_ones() {
        let g = GyroFeedback::DEFAULT;
        // 1.4 × the datasheet: both gains × 1/1.4 (G3); the limit stays.
        let s = g.for_stiffness(18.875, 1.4 * 18.875);
        assert!((s.ankle - 0.1 / 1.4).abs() < 1e-7 && (s.hip - 0.1 / 1.4).abs() < 1e-7);
        assert_eq!(s.max_rad, g.max_rad);
        // Far stiffer: half the gains at least.
        let s = g.for_stiffness(18.875, 1000.0);
        assert_eq!((s.ankle, s.hip), (0.05, 0.05));
        // Softer, or as stiff: unchanged.
        assert_eq!(g.for_stiffness(18.875, 9.0), g);
        assert_eq!(g.for_stiffness(18.875, 18.875), g);
        // Off, or no stiffness to follow: unchanged.
        let off = GyroFeedback {
            follow_stiffness: false,
            ..g
        };
        assert_eq!(off.for_stiffness(18.875, 40.0), off);
        for k in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(g.for_stiffness(18.875, k), g, "{k}");
        }
        assert_eq!(g.for_stiffness(f32::NAN, 40.0), g);
    }

    #[test]
    fn fixed_point_feedback_matches_the_f32_law() {
        let g = GyroFeedback {
            ankle: 0.1,
            hip: 0.05,
            max_rad: 0.02,
            follow_stiffness: false,
        };
        let x = FixedGyroFeedback::new(&g);
        for phase in [
            SupportPhase::Double,
            SupportPhase::Single(Side::Left),
            SupportPhase::Single(Side::Right),
        ] {
            for w in [[0.1f32, -0.3], [0.013, 0.002], [-2.0, 0.5]] {
                let mut q = [0.0f32; 12];
                g.apply(&mut q, phase, Some(w));
                let mut b = [0i32; 12];
                let raw = w.map(|v| (v * 1e6) as i32);
                x.for_each(phase, Some(raw), |j, d| b[j] += d);
                for (j, (&f, &i)) in q.iter().zip(b.iter()).enumerate() {
                    let got = i as f32 / 65536.0;
                    assert!(
                        (got - f).abs() <= 2.0 / 65536.0,
                        "{phase:?} {w:?} {j}: {got} vs {f}"
                    );
                }
            }
        }
        let mut n = 0;
        x.for_each(SupportPhase::Double, None, |_, _| n += 1);
        assert_eq!(n, 0);
    }

    #[test]
    fn damps_only_the_legs_on_the_ground_and_saturates() {
        let g = GyroFeedback {
            ankle: 0.1,
            hip: 0.05,
            max_rad: 0.02,
            follow_stiffness: false,
        };
        let mut q = [0.0f32; 12];
        g.apply(&mut q, SupportPhase::Single(Side::Left), Some([0.1, 0.1]));
        // Left leg only: hip roll/pitch 0.005, ankle pitch/roll 0.01.
        let expect = [0.0, 0.005, 0.005, 0.0, 0.01, 0.01];
        assert!(
            q[..6].iter().zip(expect).all(|(a, b)| (a - b).abs() < 1e-7),
            "{q:?}"
        );
        assert!(q[6..].iter().all(|v| *v == 0.0));
        // Double support: both legs; a large rate saturates at ±max.
        let mut q = [0.0f32; 12];
        g.apply(&mut q, SupportPhase::Double, Some([-5.0, 5.0]));
        for leg in 0..2 {
            assert_eq!(q[6 * leg + 4], 0.02);
            assert_eq!(q[6 * leg + 5], -0.02);
            assert_eq!(q[6 * leg + 2], 0.02);
            assert_eq!(q[6 * leg + 1], -0.02);
            assert_eq!(q[6 * leg], 0.0);
            assert_eq!(q[6 * leg + 3], 0.0);
        }
        // No or bad gyro: nothing.
        let mut q = [0.3f32; 12];
        g.apply(&mut q, SupportPhase::Double, None);
        g.apply(&mut q, SupportPhase::Double, Some([f32::NAN, 1.0]));
        assert!(q.iter().all(|v| *v == 0.3));
        // Off: nothing.
        GyroFeedback::OFF.apply(&mut q, SupportPhase::Double, Some([1.0, 1.0]));
        assert!(q.iter().all(|v| *v == 0.3));
    }
}
