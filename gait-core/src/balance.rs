//! Gyro balance feedback: damping of the trunk's rotation through the joints of the legs on the
//! ground (the classic ankle/hip gyro feedback of kid-size walking engines), applied by the firmware to
//! the joint targets of every walking tick.
//!
//! # Law
//! With the trunk's roll and pitch rates ω_x, ω_y (gyro, rad/s, body frame) and the joint
//! conventions of [`crate::kinematics`] (positive = right-hand rule about the pelvis axes,
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
//! # Foot force difference control ([`FootForceControl`])
//! In double support the two legs close a chain through the floor: how the weight splits
//! between the feet is set by millimetres of leg length that stiff position servos do not
//! hold, and the plan's ZMP transfer from one foot to the other is not followed (the new foot
//! takes much of the weight as it lands and then unloads again, so the lateral ZMP error is
//! largest in double support). The control of
//! Kajita et al. (IROS 2010, "Biped walking stabilization based on linear inverted pendulum
//! tracking", foot force difference control) drives the difference of the feet's normal
//! forces to the one the ZMP reference asks for by the difference of the feet's heights:
//!
//! ```text
//! α    = sat₀¹( (p_ref − p_R)·(p_L − p_R) / |p_L − p_R|² )   share of the left foot    (F1)
//! ΔF_d = (2α − 1)·(F_L + F_R)                                 wanted F_L − F_R          (F2)
//! Δz ← Δz + dt·( k_f·((F_L − F_R) − ΔF_d) − Δz/T_v ),  |Δz| ≤ Δz_max                    (F3)
//! z_L += Δz/2,  z_R −= Δz/2                                   sole heights for the IK   (F4)
//! ```
//!
//! p_L, p_R the soles' planned positions, p_ref the ZMP reference, F_L, F_R the measured
//! normal forces (sum of a foot's load cells, N). A foot carrying more than its share is
//! lifted (its leg shortened) and the other lowered. The error is integrated in the plan's
//! double support only and only while both feet are measured; otherwise Δz only leaks back to
//! 0 with T_v. k_f in m/(N·s); 0 turns the control off.

use crate::robot::Side;
use crate::sampler::SupportPhase;

/// Gyro feedback gains and limit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroFeedback {
    /// Ankle gain k_a, s.
    pub ankle: f32,
    /// Hip gain k_h, s.
    pub hip: f32,
    /// Largest correction of one joint, rad.
    pub max_rad: f32,
}

impl GyroFeedback {
    /// The firmware's default: k_a = 0.1 s, k_h = 0.1 s, ±0.1 rad (with the compliance
    /// feed-forward of [`crate::compliance`] the hips' 0.1 s tracks better than 0.05 s; how it was
    /// chosen: `docs/beyond.md`, "Gyro damping").
    pub const DEFAULT: GyroFeedback = GyroFeedback {
        ankle: 0.1,
        hip: 0.1,
        max_rad: 0.1,
    };

    /// No feedback.
    pub const OFF: GyroFeedback = GyroFeedback {
        ankle: 0.0,
        hip: 0.0,
        max_rad: 0.1,
    };

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

/// Foot force difference control: gains and limits (equations F1–F4 of the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FootForceControl {
    /// Gain k_f, m/(N·s); 0 = off.
    pub gain: f32,
    /// Leak time constant T_v, s.
    pub leak_s: f32,
    /// Largest height difference |Δz|, m.
    pub max_m: f32,
}

impl FootForceControl {
    /// Off: the firmware's default (`docs/beyond.md`, "Foot force difference control").
    pub const OFF: FootForceControl = FootForceControl {
        gain: 0.0,
        leak_s: 0.5,
        max_m: 0.01,
    };
}

/// The state of [`FootForceControl`]: the feet's height difference Δz = z_L − z_R, m.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FootForceState {
    /// Δz, m.
    pub dz: f32,
}

impl FootForceState {
    /// One tick of F1–F3 (module docs): `zmp_ref` and `feet` (x, y of the left and right sole)
    /// of the sample the forces answer, `forces` = [F_L, F_R] in N (non-finite: not measured),
    /// `phase` that sample's; returns the sole height offsets [Δz/2, −Δz/2] of F4, m.
    pub fn update(
        &mut self,
        c: &FootForceControl,
        zmp_ref: [f32; 2],
        feet: [[f32; 2]; 2],
        forces: [f32; 2],
        phase: SupportPhase,
        dt: f32,
    ) -> [f32; 2] {
        let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
        let (gain, leak, max) = (
            finite(c.gain),
            finite(c.leak_s),
            libm::fmaxf(finite(c.max_m), 0.0),
        );
        let [l, r] = feet;
        let (ax, ay) = (l[0] - r[0], l[1] - r[1]);
        let len2 = ax * ax + ay * ay;
        let [fl, fr] = forces;
        let error = if phase == SupportPhase::Double
            && fl.is_finite()
            && fr.is_finite()
            && len2 > 1e-6
            && gain > 0.0
        {
            let alpha = ((zmp_ref[0] - r[0]) * ax + (zmp_ref[1] - r[1]) * ay) / len2;
            let alpha = libm::fminf(libm::fmaxf(alpha, 0.0), 1.0);
            let wanted = (2.0 * alpha - 1.0) * (fl + fr);
            (fl - fr) - wanted
        } else {
            0.0
        };
        let leak_rate = if leak > 0.0 { self.dz / leak } else { 0.0 };
        let next = self.dz + dt * (gain * error - leak_rate);
        self.dz = if next.is_finite() {
            libm::fminf(libm::fmaxf(next, -max), max)
        } else {
            0.0
        };
        [0.5 * self.dz, -0.5 * self.dz]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FEET: [[f32; 2]; 2] = [[0.0, 0.05], [0.0, -0.05]];

    #[test]
    fn force_difference_lifts_the_overloaded_foot_towards_the_wanted_split() {
        let c = FootForceControl {
            gain: 0.001,
            leak_s: 0.5,
            max_m: 0.01,
        };
        // Reference 1/4 of the way from the right sole to the left: α = 0.25, the left foot
        // should carry 10 of 40 N (ΔF_d = −20 N); it carries 30 (ΔF = +20 N): error 40 N.
        let mut st = FootForceState::default();
        let off = st.update(
            &c,
            [0.0, -0.025],
            FEET,
            [30.0, 10.0],
            SupportPhase::Double,
            0.005,
        );
        // Δz = dt·k_f·e = 0.005·0.001·40 = 2e-4 m: the left sole up 1e-4, the right down 1e-4.
        assert!((st.dz - 2e-4).abs() < 1e-9, "{}", st.dz);
        assert!(
            (off[0] - 1e-4).abs() < 1e-9 && (off[1] + 1e-4).abs() < 1e-9,
            "{off:?}"
        );
        // At the wanted split nothing is integrated: only the leak, Δz·(1 − dt/T_v).
        let before = st.dz;
        st.update(
            &c,
            [0.0, -0.025],
            FEET,
            [10.0, 30.0],
            SupportPhase::Double,
            0.005,
        );
        assert!((st.dz - before * (1.0 - 0.01)).abs() < 1e-9, "{}", st.dz);
        // A reference beyond a sole is that sole (α saturates): the right foot overloaded by
        // the whole weight lowers the left.
        let mut st = FootForceState::default();
        let right_overloaded = |st: &mut FootForceState| {
            st.update(
                &c,
                [0.0, 0.2],
                FEET,
                [0.0, 40.0],
                SupportPhase::Double,
                0.005,
            )
        };
        right_overloaded(&mut st);
        assert!((st.dz + 0.005 * 0.001 * 80.0).abs() < 1e-9, "{}", st.dz);
        // Saturates at ±max.
        for _ in 0..100_000 {
            right_overloaded(&mut st);
        }
        assert_eq!(st.dz, -0.01);
    }

    #[test]
    fn force_difference_only_leaks_outside_double_support_or_unmeasured() {
        let c = FootForceControl {
            gain: 0.001,
            leak_s: 0.5,
            max_m: 0.01,
        };
        for (phase, forces) in [
            (SupportPhase::Single(Side::Left), [40.0, 0.0]),
            (SupportPhase::Double, [f32::NAN, 10.0]),
            (SupportPhase::Double, [10.0, f32::INFINITY]),
        ] {
            let mut st = FootForceState { dz: 0.004 };
            st.update(&c, [0.0, 0.0], FEET, forces, phase, 0.005);
            assert!((st.dz - 0.004 * 0.99).abs() < 1e-9, "{phase:?}: {}", st.dz);
        }
        // Off (gain 0) and bad gains: nothing but the leak; non-finite never comes out.
        let mut st = FootForceState::default();
        let off = st.update(
            &FootForceControl::OFF,
            [0.0, 0.0],
            FEET,
            [40.0, 0.0],
            SupportPhase::Double,
            0.005,
        );
        assert_eq!(off, [0.0, 0.0]);
        let bad = FootForceControl {
            gain: f32::NAN,
            leak_s: f32::NAN,
            max_m: f32::INFINITY,
        };
        let off = st.update(
            &bad,
            [f32::NAN, 0.0],
            FEET,
            [40.0, 0.0],
            SupportPhase::Double,
            0.005,
        );
        assert!(off.iter().all(|v| v.is_finite()), "{off:?}");
        // Coincident soles: no split is defined, only the leak.
        let mut st = FootForceState { dz: 0.002 };
        st.update(
            &c,
            [0.0, 0.0],
            [[0.0, 0.0]; 2],
            [40.0, 0.0],
            SupportPhase::Double,
            0.005,
        );
        assert!((st.dz - 0.002 * 0.99).abs() < 1e-9);
    }

    #[test]
    fn fixed_point_feedback_matches_the_f32_law() {
        let g = GyroFeedback {
            ankle: 0.1,
            hip: 0.05,
            max_rad: 0.02,
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
