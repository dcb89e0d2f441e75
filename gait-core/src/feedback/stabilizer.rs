//! ZMP/DCM feedback stabilizer: a bounded online shift of the commanded CoM (pelvis) that moves
//! the measured ZMP toward the reference.
//!
//! For the LIPM, ẍ = ω²(x − p) with ω² = g/z_c, the divergent component of motion (DCM)
//! ξ = x + ẋ/ω obeys ξ̇ = ω(ξ − p). Under the DCM tracking law
//! p = p_ref + (1 + k/ω)(ξ − ξ_ref) the ZMP error and the DCM error are proportional:
//!
//! ```text
//!   p − p_ref = (1 + k)·(ξ − ξ_ref)                    (S1)  (k: the DCM gain in units of ω)
//! ```
//!
//! so the measured ZMP error gives an estimate of the DCM error without a CoM velocity
//! measurement. The gyro adds the upper body's swing: the trunk's mass point l_u above the pelvis
//! moves at l_u·(φ̇_pitch, −φ̇_roll), whose DCM contribution is that velocity over ω:
//!
//! ```text
//!   e   = LPF_fc(p_meas − p_ref)                       (S2)  first order, cutoff f_c
//!   ê_ξ = e/(1 + k) + k_g·l_u·(φ̇_pitch, −φ̇_roll)       (S3)  k_g in s (≈ 1/ω for the full term)
//!   ê_ξ,y ← w_y·ê_ξ,y                                  (S3′) lateral weight w_y ∈ [0, 1]
//!   I  ← clamp(I + dt·(k_i·ê_ξ − λ·I), ±s_max)          (S4)  leaky integral, anti-windup
//!   δ* = −(k_p·ê_ξ + I),  |δ*| ≤ s_max                  (S5)  proportional + integral, saturated
//!   p_ref + δ* ∈ support polygon shrunk by m             (S7)  ZMP command limit (δ* scaled down)
//!   δ  ← δ_prev + (δ* − δ_prev)·min(1, v_max·dt/‖δ* − δ_prev‖∞)   (S6)  rate limit
//! ```
//!
//! (S3′) weighs the lateral axis: w_y = 1 is the law as written, w_y = 0 a sagittal-only
//! stabilizer (its lateral δ stays 0: the lateral error then feeds neither (S4) nor (S5)).
//!
//! δ is added to the commanded CoM (the pelvis point of the plain pipeline, the target of the
//! whole-body CoM with [`crate::kinematics::wholebody`]). Quasi-statically a CoM shift δ moves the ZMP by δ
//! (the ZMP of a resting body is under its CoM), so (S5) drives the ZMP error toward zero; the
//! non-minimum-phase term −δ̈/ω² of p = c − c̈/ω² is why the proportional gain stays small and
//! the rate (S6) is limited. (S7) treats p_ref + δ* as the ZMP the correction asks for and keeps
//! it inside the support polygon with margin m (or at least as deep as the reference itself
//! when the reference is closer to the edge than m).
//!
//! Robustness: a missing or non-finite measured ZMP feeds 0 into (S2) and freezes (S4); a
//! non-finite gyro counts as 0; any non-finite gain or state resets the stabilizer to δ = 0. The
//! output is always finite with ‖δ‖ ≤ s_max and changes by at most v_max·dt per component per
//! update (it moves along the segment toward δ*, so it stays in the disc; after a support
//! change it reaches the new polygon's limit at v_max). Cost: a few dozen flops plus one support-polygon margin per bisection
//! step ([`BISECTION_STEPS`] at most).

use super::{IkOffsets, Measured, SampleCorrection};
use crate::gait::SupportCache;
use crate::maths::real::Real;
use crate::measure::support::SupportPolygon;
use crate::robot::Robot;
use crate::trajectory::sampler::GaitSample;

/// Most bisection steps of the support-polygon limit (S7).
pub const BISECTION_STEPS: u8 = 6;

/// Hard ceiling of the saturation s_max, m (2 cm).
pub const MAX_SHIFT_CEILING_M: f64 = 0.02;

/// Gains and limits of the stabilizer (SI units; see the module docs for the equations).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StabilizerConfig {
    /// Proportional gain k_p on the DCM error estimate (S5), dimensionless.
    pub kp: f64,
    /// Integral gain k_i (S4), 1/s.
    pub ki: f64,
    /// Leak λ of the integral (S4), 1/s.
    pub leak: f64,
    /// Gyro gain k_g (S3), s.
    pub kg: f64,
    /// DCM gain k of (S1), dimensionless (≥ 0).
    pub dcm_k: f64,
    /// Saturation s_max of the shift (S4, S5), m; at most [`MAX_SHIFT_CEILING_M`].
    pub max_shift: f64,
    /// Rate limit v_max of the shift (S6), m/s.
    pub max_rate: f64,
    /// Margin m of the ZMP command inside the support polygon (S7), m.
    pub margin: f64,
    /// Cutoff f_c of the ZMP error filter (S2), Hz.
    pub cutoff_hz: f64,
    /// Weight w_y of the lateral axis (S3′), 0 ..= 1 (0: sagittal only).
    pub lateral: f64,
}

impl StabilizerConfig {
    /// The defaults tuned in the firmware-in-the-loop walk (`walker beyond`): k_p 0, k_i 2 /s,
    /// λ 0.1 /s, k_g 0.15 s (≈ 1/ω), k 1, s_max 2 cm, v_max 5 cm/s, m 5 mm, f_c 0.25 Hz, both
    /// axes (w_y 1).
    pub const fn default_gains() -> Self {
        StabilizerConfig {
            kp: 0.0,
            ki: 2.0,
            leak: 0.1,
            kg: 0.15,
            dcm_k: 1.0,
            max_shift: 0.02,
            max_rate: 0.05,
            margin: 0.005,
            cutoff_hz: 0.25,
            lateral: 1.0,
        }
    }

    /// True when every number is finite and in range (gains ≥ 0, 0 ≤ s_max ≤ 2 cm, rate,
    /// cutoff > 0, 0 ≤ w_y ≤ 1).
    pub fn is_valid(&self) -> bool {
        let nn = |v: f64| v.is_finite() && v >= 0.0;
        nn(self.kp)
            && nn(self.ki)
            && nn(self.leak)
            && nn(self.kg)
            && nn(self.dcm_k)
            && nn(self.max_shift)
            && self.max_shift <= MAX_SHIFT_CEILING_M
            && nn(self.margin)
            && self.max_rate.is_finite()
            && self.max_rate > 0.0
            && self.cutoff_hz.is_finite()
            && self.cutoff_hz > 0.0
            && (0.0..=1.0).contains(&self.lateral)
    }
}

impl Default for StabilizerConfig {
    fn default() -> Self {
        Self::default_gains()
    }
}

/// What the stabilizer sees in one tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StabilizerInput<'a, R> {
    /// ZMP reference the measurement is compared with, m.
    pub zmp_ref: [R; 2],
    /// Measured ZMP, m (`None` when not available).
    pub zmp_meas: Option<[R; 2]>,
    /// Gyro (roll rate, pitch rate) of the upper body, rad/s (`None` when not available).
    pub gyro: Option<[R; 2]>,
    /// The support polygon of the reference (`None`: no limit (S7)).
    pub support: Option<&'a SupportPolygon<R>>,
}

/// The stabilizer's state (O(1), no allocation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stabilizer<R> {
    /// Proportional gain k_p.
    kp: R,
    /// Integral gain k_i, 1/s.
    ki: R,
    /// Leak of the integral, 1/s.
    leak: R,
    /// 1/(1 + k) of the DCM error estimate, per axis: × w_y on the lateral one (S3′).
    inv_one_plus_k: [R; 2],
    /// k_g·l_u per axis: × w_y on the lateral one (S3′).
    gyro_gain_axis: [R; 2],
    /// Largest |δ| per axis, m.
    max_shift: R,
    /// Largest change of δ per update, m.
    max_step: R,
    /// Margin of the ZMP command inside the support polygon, m.
    margin: R,
    /// Update period, s.
    dt: R,
    /// Low-pass factor dt/(dt + τ) of the ZMP error filter.
    alpha: R,
    /// Filtered ZMP error e, m.
    err: [R; 2],
    /// Integral of the error, m·s.
    integral: [R; 2],
    /// Present shift δ, m.
    shift: [R; 2],
}

impl<R: Real> Stabilizer<R> {
    /// A stabilizer for updates `dt_s` apart, trunk mass point `upper_body_height` (l_u, m)
    /// above the pelvis. An invalid configuration or dt gives a stabilizer whose output is 0.
    pub fn new(cfg: &StabilizerConfig, dt_s: f64, upper_body_height: f64) -> Self {
        let ok = cfg.is_valid() && dt_s.is_finite() && dt_s > 0.0 && upper_body_height.is_finite();
        let c = if ok {
            *cfg
        } else {
            StabilizerConfig {
                kp: 0.0,
                ki: 0.0,
                kg: 0.0,
                max_shift: 0.0,
                ..StabilizerConfig::default_gains()
            }
        };
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s
        } else {
            0.005
        };
        let tau = 1.0 / (2.0 * core::f64::consts::PI * c.cutoff_hz);
        Stabilizer {
            kp: R::of(c.kp),
            ki: R::of(c.ki),
            leak: R::of(c.leak),
            inv_one_plus_k: [1.0, c.lateral].map(|w| R::of(w / (1.0 + c.dcm_k))),
            gyro_gain_axis: [1.0, c.lateral].map(|w| R::of(w * c.kg * upper_body_height)),
            max_shift: R::of(c.max_shift),
            max_step: R::of(c.max_rate * dt),
            margin: R::of(c.margin),
            dt: R::of(dt),
            alpha: R::of(dt / (dt + tau)),
            err: [R::zero(); 2],
            integral: [R::zero(); 2],
            shift: [R::zero(); 2],
        }
    }

    /// The present shift δ of the commanded CoM, m.
    pub fn shift(&self) -> [R; 2] {
        self.shift
    }

    /// The filtered ZMP error e (S2), m.
    pub fn error(&self) -> [R; 2] {
        self.err
    }

    /// Back to rest: δ = 0, filter and integral cleared.
    pub fn reset(&mut self) {
        self.err = [R::zero(); 2];
        self.integral = [R::zero(); 2];
        self.shift = [R::zero(); 2];
    }

    /// One update (S2–S7); returns the new shift δ of the commanded CoM, m.
    pub fn update(&mut self, input: &StabilizerInput<'_, R>) -> [R; 2] {
        let finite2 = |v: &[R; 2]| v[0].is_finite() && v[1].is_finite();
        let r = input.zmp_ref;
        let meas = input
            .zmp_meas
            .filter(|m| finite2(m) && finite2(&r))
            .map(|m| [m[0] - r[0], m[1] - r[1]]);
        let raw = meas.unwrap_or([R::zero(); 2]);
        let gyro = input
            .gyro
            .filter(finite2)
            .map_or([R::zero(); 2], |g| [g[1], -g[0]]);
        let zero = R::zero();
        let mut target = [zero; 2];
        for k in 0..2 {
            // (S2)
            self.err[k] += self.alpha * (raw[k] - self.err[k]);
            // (S3), (S3′)
            let e_xi = self.err[k] * self.inv_one_plus_k[k] + self.gyro_gain_axis[k] * gyro[k];
            // (S4): frozen while the measurement is missing.
            if meas.is_some() {
                let i =
                    self.integral[k] + self.dt * (self.ki * e_xi - self.leak * self.integral[k]);
                self.integral[k] = i.clamp_to(-self.max_shift, self.max_shift);
            }
            // (S5)
            target[k] = -(self.kp * e_xi + self.integral[k]);
        }
        let mut target = limit_norm(target, self.max_shift);
        // (S7) on the target.
        if let Some(poly) = input.support {
            target = self.limit_to_support(poly, r, target);
        }
        // (S6): along the segment toward the target (stays in the disc and the polygon).
        let d = [target[0] - self.shift[0], target[1] - self.shift[1]];
        let big = d[0].abs().max(d[1].abs());
        let s = if big > self.max_step && big > zero {
            self.max_step / big
        } else {
            R::one()
        };
        let next = [self.shift[0] + d[0] * s, self.shift[1] + d[1] * s];
        if finite2(&next) && finite2(&self.err) && finite2(&self.integral) {
            self.shift = next;
        } else {
            self.reset();
        }
        self.shift
    }

    /// Scales `d` toward 0 until `r + d` is inside `poly` with the margin (or as deep as `r`).
    fn limit_to_support(&self, poly: &SupportPolygon<R>, r: [R; 2], d: [R; 2]) -> [R; 2] {
        let at = |s: R| [r[0] + d[0] * s, r[1] + d[1] * s];
        let need = poly.margin(r).min(self.margin);
        if poly.margin(at(R::one())) >= need {
            return d;
        }
        // Bisection on the scale s ∈ [0, 1]: s = 0 always qualifies (margin(r) ≥ need).
        let (mut lo, mut hi) = (R::zero(), R::one());
        let half = R::of(0.5);
        for _ in 0..BISECTION_STEPS {
            let mid = (lo + hi) * half;
            if poly.margin(at(mid)) >= need {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        [d[0] * lo, d[1] * lo]
    }
}

/// `v` scaled down to norm at most `max` (0 for a non-finite `v`).
fn limit_norm<R: Real>(v: [R; 2], max: R) -> [R; 2] {
    let n = (v[0] * v[0] + v[1] * v[1]).sqrt();
    if !n.is_finite() {
        return [R::zero(); 2];
    }
    if n > max && n > R::zero() {
        let s = max / n;
        [v[0] * s, v[1] * s]
    } else {
        v
    }
}

/// The feedback stabilizer as a sample correction: δ from the measured ZMP's error against
/// the previous sample's reference, inside that sample's support polygon (cached).
#[derive(Clone, Debug)]
pub struct StabilizerCorrection<'r> {
    /// The stabilizer (gait-core [`crate::feedback::stabilizer`]).
    pub stabilizer: Stabilizer<f32>,
    on: bool,
    support: SupportCache,
    robot: &'r Robot,
}

impl<'r> StabilizerCorrection<'r> {
    /// `stabilizer` for `robot`; `on` = false leaves δ at 0 and the state untouched.
    pub fn new(stabilizer: Stabilizer<f32>, on: bool, robot: &'r Robot) -> Self {
        StabilizerCorrection {
            stabilizer,
            on,
            support: SupportCache::default(),
            robot,
        }
    }
}

impl SampleCorrection for StabilizerCorrection<'_> {
    fn update(&mut self, m: &Measured<'_>, _: &GaitSample<f32>, offsets: &mut IkOffsets) {
        if !self.on {
            return;
        }
        offsets.com_shift = self.stabilizer.update(&StabilizerInput {
            zmp_ref: m.previous.zmp,
            zmp_meas: m.zmp,
            gyro: m.gyro,
            support: self.support.get(self.robot, m.previous),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Robot;
    use crate::trajectory::plan::Place;

    fn stab(cfg: StabilizerConfig) -> Stabilizer<f64> {
        Stabilizer::new(&cfg, 0.005, 0.09)
    }

    fn input(r: [f64; 2], m: Option<[f64; 2]>) -> StabilizerInput<'static, f64> {
        StabilizerInput {
            zmp_ref: r,
            zmp_meas: m,
            gyro: None,
            support: None,
        }
    }

    #[test]
    fn a_constant_error_is_pushed_back_and_saturates() {
        let mut s = stab(StabilizerConfig::default());
        for _ in 0..2000 {
            s.update(&input([0.0, 0.0], Some([0.01, -0.03])));
        }
        let d = s.shift();
        assert!(d[0] < 0.0 && d[1] > 0.0, "{d:?}");
        assert!((d[0] * d[0] + d[1] * d[1]).sqrt() <= 0.02 + 1e-12);
    }

    #[test]
    fn the_lateral_weight_scales_the_lateral_axis_only() {
        // The same errors and gyro into w_y = 1, 0.5 and 0: the sagittal shift is the same
        // in all three, the lateral one scales with w_y (a linear law until a limit acts:
        // errors small enough that neither the norm, the rate nor the integral's clamp does).
        let run = |w: f64| {
            let mut s = stab(StabilizerConfig {
                kp: 0.3,
                lateral: w,
                ..StabilizerConfig::default()
            });
            let mut d = [0.0; 2];
            for i in 0..200 {
                let mut inp = input([0.0, 0.0], Some([0.002, -0.003]));
                inp.gyro = Some([0.05 * f64::from(i % 3), -0.02]);
                d = s.update(&inp);
            }
            d
        };
        let (full, half, none) = (run(1.0), run(0.5), run(0.0));
        assert!(full[0] < -1e-4 && full[1] > 1e-4, "both axes act: {full:?}");
        assert_eq!(half[0], full[0]);
        assert_eq!(none[0], full[0]);
        assert!(
            (half[1] - 0.5 * full[1]).abs() <= 1e-12 * full[1].abs().max(1.0),
            "{half:?}"
        );
        assert_eq!(none[1], 0.0);
        assert!(!StabilizerConfig {
            lateral: 1.5,
            ..StabilizerConfig::default()
        }
        .is_valid());
        assert!(!StabilizerConfig {
            lateral: f64::NAN,
            ..StabilizerConfig::default()
        }
        .is_valid());
    }

    #[test]
    fn missing_or_non_finite_data_never_moves_it() {
        let mut s = stab(StabilizerConfig {
            kg: 0.15,
            ..StabilizerConfig::default()
        });
        for i in 0..500 {
            let m = match i % 3 {
                0 => None,
                1 => Some([f64::NAN, 0.0]),
                _ => Some([f64::INFINITY, f64::NEG_INFINITY]),
            };
            let mut inp = input([0.0, 0.0], m);
            inp.gyro = Some([f64::NAN, f64::INFINITY]);
            assert_eq!(s.update(&inp), [0.0, 0.0]);
        }
        // A NaN reference with a finite measurement: no error either.
        assert_eq!(
            s.update(&input([f64::NAN, 0.0], Some([0.01, 0.0]))),
            [0.0; 2]
        );
    }

    #[test]
    fn rate_and_norm_are_limited_for_any_input() {
        let cfg = StabilizerConfig {
            kp: 50.0,
            ki: 500.0,
            kg: 1.0,
            ..StabilizerConfig::default()
        };
        let mut s = stab(cfg);
        let step = cfg.max_rate * 0.005 + 1e-12;
        let mut prev = [0.0; 2];
        let mut x = 0.1f64;
        for i in 0..5000 {
            x = (x * 3.7 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6); // chaotic in (0, 1)
            let m = [(x - 0.5) * 10.0, (0.5 - x) * (i % 7) as f64];
            let mut inp = input([0.0, 0.01], Some(m));
            inp.gyro = Some([x * 100.0, -x * 50.0]);
            let d = s.update(&inp);
            assert!(d[0].is_finite() && d[1].is_finite());
            assert!((d[0] * d[0] + d[1] * d[1]).sqrt() <= cfg.max_shift + 1e-12);
            assert!((d[0] - prev[0]).abs() <= step && (d[1] - prev[1]).abs() <= step);
            prev = d;
        }
    }

    #[test]
    fn the_zmp_command_stays_in_the_support_polygon() {
        let robot = Robot::reference();
        let foot = Place::<f64>::new(0.0, 0.045, 0.0);
        let poly = SupportPolygon::single(&foot, &robot).unwrap();
        let mut s = stab(StabilizerConfig {
            ki: 100.0,
            max_rate: 10.0,
            ..StabilizerConfig::default()
        });
        let r = [0.0, 0.045];
        for _ in 0..400 {
            let inp = StabilizerInput {
                zmp_ref: r,
                zmp_meas: Some([0.0, 0.2]), // far to the left: δ pushes right
                gyro: None,
                support: Some(&poly),
            };
            let d = s.update(&inp);
            assert!(
                poly.margin([r[0] + d[0], r[1] + d[1]]) >= 0.005 - 1e-9,
                "{d:?}"
            );
        }
        assert!(s.shift()[1] < -0.005, "it did move: {:?}", s.shift());
    }

    #[test]
    fn invalid_gains_give_zero_output() {
        let mut s = stab(StabilizerConfig {
            ki: f64::NAN,
            ..StabilizerConfig::default()
        });
        for _ in 0..100 {
            assert_eq!(s.update(&input([0.0; 2], Some([0.05, 0.05]))), [0.0; 2]);
        }
        assert!(!StabilizerConfig {
            max_shift: 0.05,
            ..StabilizerConfig::default()
        }
        .is_valid());
    }

    #[test]
    fn it_tracks_a_lagging_quasi_static_plant() {
        // Plant: ZMP = reference + bias + CoM shift (quasi-static), measured one tick late.
        let mut s = stab(StabilizerConfig::default());
        let bias = [0.006, -0.004];
        let mut last = [0.0; 2];
        for _ in 0..4000 {
            let m = [bias[0] + last[0], bias[1] + last[1]];
            last = s.update(&input([0.0; 2], Some(m)));
        }
        // The leak leaves a small residual: e = λ(1+k)/(k_i + λ(1+k))·bias.
        let e = [bias[0] + last[0], bias[1] + last[1]];
        assert!(
            e[0].abs() < 0.1 * bias[0].abs() && e[1].abs() < 0.1 * bias[1].abs(),
            "{e:?}"
        );
    }
}
