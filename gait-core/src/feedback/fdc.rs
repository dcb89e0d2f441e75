//! Foot force difference control (fdc): the soles' heights in double support set the split of
//! the weight between the feet ([`FootForceControl`], [`FootForceState`]).
//!
//! # Law
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

use super::{IkOffsets, Measured, SampleCorrection};
use crate::trajectory::sampler::{GaitSample, SupportPhase};

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

/// The foot force difference control (gait-core [`crate::feedback::fdc`] F1–F4) as a sample
/// correction: the soles' heights from the loads answering the previous sample.
#[derive(Clone, Copy, Debug)]
pub struct FootForceCorrection {
    /// Gains and limits.
    pub control: FootForceControl,
    /// Its state Δz.
    pub state: FootForceState,
    dt_s: f32,
}

impl FootForceCorrection {
    /// `control` at ticks of `dt_s` seconds, Δz = 0.
    pub fn new(control: FootForceControl, dt_s: f32) -> Self {
        FootForceCorrection {
            control,
            state: FootForceState::default(),
            dt_s,
        }
    }
}

impl SampleCorrection for FootForceCorrection {
    fn update(&mut self, m: &Measured<'_>, _: &GaitSample<f32>, offsets: &mut IkOffsets) {
        let [pl, pr] = &m.previous.feet;
        let dz = self.state.update(
            &self.control,
            m.previous.zmp,
            [[pl.x, pl.y], [pr.x, pr.y]],
            m.loads,
            m.previous.phase,
            self.dt_s,
        );
        if self.state.dz != 0.0 {
            offsets.sole_dz = dz;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Side;

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
}
