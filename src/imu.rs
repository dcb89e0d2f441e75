//! IMU processing: the upper-body pitch acceleration φ̈ and torque τ = J·φ̈ from the gyro, and
//! the trunk tilt from the accelerometer (fall detection).
//!
//! # φ̈ filter
//! With the pitch rate ω_k (gyro y axis, rad/s) sampled every `dt` (the servo tick):
//!
//! ```text
//! d_k = (ω_k − ω_{k−1}) / dt                    backward difference
//! y_k = y_{k−1} + α (d_k − y_{k−1}),  α = 1 − exp(−2π f_c dt)   first-order low-pass
//! ```
//!
//! so `H(z) = (1 − z⁻¹)/dt · α / (1 − (1 − α) z⁻¹)`. For a pitch rate `A sin(Ω t)` the exact
//! φ̈ is `A Ω cos(Ω t)`; the filter's steady-state output is `A |H(e^{jΩdt})| sin(Ω t + arg H)`
//! ([`PitchAccel::response`] evaluates `|H|` and `arg H`). Well below the cutoff
//! `|H| ≈ Ω` and the output lags the exact φ̈ by about `dt/2 + (1 − α)/α · dt` (≈ 10.5 ms at
//! 1 kHz and 15 Hz): e.g. at 1.5 Hz (the gait's step frequency) the gain error is < 0.6 % and
//! the phase lag ≈ 5.7°. The default cutoff is [`DEFAULT_CUTOFF_HZ`] = 15 Hz.
//!
//! A non-finite gyro sample is dropped: the output holds its last value and the next good
//! sample is differenced against the last good one over the true elapsed time.
//!
//! # Tilt
//! From the accelerometer's specific force `a` (body frame; upright reads `(0, 0, +g)`):
//! roll = atan2(a_y, a_z), pitch = atan2(−a_x, √(a_y² + a_z²)), tilt from vertical =
//! atan2(√(a_x² + a_y²), a_z). A sample that is non-finite or whose norm is outside
//! [0.25 g, 4 g] (free fall, impact) is rejected and the last good tilt is held.
//!
//! # Attitude (fall detection)
//! The accelerometer alone mistakes the walk's accelerations for tilt and, while the robot tips
//! over, reads less than g (it detected falls 90-210 ms late in full dynamics). [`AttitudeFilter`]
//! integrates the gyro (body rates p, q, r) through the ZYX Euler-angle kinematics
//!
//! ```text
//! φ̇ = p + (q sin φ + r cos φ) tan θ,     θ̇ = q cos φ − r sin φ
//! ```
//!
//! and pulls the result towards the accelerometer's roll and pitch (above) with the
//! complementary gain `k = dt/(τ + dt)` (τ = [`ATTITUDE_TAU_S`]), only when the specific force's
//! norm is within [0.8 g, 1.2 g] (the robot is not accelerating much): a rotation is tracked at
//! once, a gyro bias `b` leaves a steady error of `b·τ` only. Tilt from vertical:
//! `cos(tilt) = cos φ · cos θ`.

//!
//! # Heading (the online walk's heading hold)
//! [`Heading`] integrates the yaw of the same kinematics with the attitude's roll φ and pitch θ,
//! less a bias b of the gyro's z axis estimated while the robot stands still:
//!
//! ```text
//! ψ̇ = (q sin φ + (r − b) cos φ) / cos θ,     still: b ← b + (r − b)·dt/τ_b
//! ```
//!
//! (τ_b = [`HEADING_BIAS_TAU_S`]; cos θ bounded below by 0.05). Nothing corrects ψ: a bias
//! left after standing drifts it by b·t.

/// Default low-pass cutoff of the φ̈ filter, Hz.
pub use walker_contract::config::DEFAULT_IMU_CUTOFF_HZ as DEFAULT_CUTOFF_HZ;
/// Standard gravity used for the accelerometer plausibility window, m/s².
const G: f32 = 9.80665;

/// φ̈ filter settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PitchAccelConfig {
    /// Sample period (the servo tick), s.
    pub dt_s: f32,
    /// Low-pass cutoff, Hz.
    pub cutoff_hz: f32,
    /// Upper-body pitch inertia J, kg·m².
    pub inertia: f32,
}

impl PitchAccelConfig {
    /// The reference robot's J with the default cutoff at sample period `dt_s`.
    pub fn reference(dt_s: f32) -> Self {
        let robot = gait_core::Robot::reference();
        PitchAccelConfig {
            dt_s,
            cutoff_hz: DEFAULT_CUTOFF_HZ,
            inertia: robot.masses.upper_body_inertia as f32,
        }
    }
}

/// Pitch-rate differentiator + low-pass → φ̈, τ = J·φ̈.
#[derive(Clone, Debug)]
pub struct PitchAccel {
    dt: f32,
    alpha: f32,
    inertia: f32,
    prev_rate: Option<f32>,
    gap: u32,
    acc: f32,
    rejected: u32,
}

impl PitchAccel {
    /// A filter at rest. A non-positive or non-finite `dt_s` or cutoff falls back to 1 ms /
    /// [`DEFAULT_CUTOFF_HZ`].
    pub fn new(cfg: PitchAccelConfig) -> Self {
        let dt = if cfg.dt_s.is_finite() && cfg.dt_s > 0.0 {
            cfg.dt_s
        } else {
            1.0e-3
        };
        let fc = if cfg.cutoff_hz.is_finite() && cfg.cutoff_hz > 0.0 {
            cfg.cutoff_hz
        } else {
            DEFAULT_CUTOFF_HZ
        };
        let inertia = if cfg.inertia.is_finite() {
            cfg.inertia
        } else {
            0.0
        };
        PitchAccel {
            dt,
            alpha: 1.0 - libm::expf(-core::f32::consts::TAU * fc * dt),
            inertia,
            prev_rate: None,
            gap: 1,
            acc: 0.0,
            rejected: 0,
        }
    }

    /// The smoothing factor α.
    pub fn alpha(&self) -> f32 {
        self.alpha
    }

    /// Feeds one pitch-rate sample (rad/s); returns the filtered φ̈ (rad/s²).
    pub fn update(&mut self, rate: f32) -> f32 {
        if !rate.is_finite() {
            self.rejected = self.rejected.saturating_add(1);
            self.gap = self.gap.saturating_add(1);
            return self.acc;
        }
        if let Some(prev) = self.prev_rate {
            let d = (rate - prev) / (self.dt * self.gap as f32);
            if d.is_finite() {
                self.acc += self.alpha * (d - self.acc);
            }
        }
        self.prev_rate = Some(rate);
        self.gap = 1;
        self.acc
    }

    /// Filtered φ̈, rad/s².
    pub fn accel(&self) -> f32 {
        self.acc
    }

    /// τ = J·φ̈, N·m.
    pub fn torque(&self) -> f32 {
        self.inertia * self.acc
    }

    /// Non-finite samples dropped so far.
    pub fn rejected(&self) -> u32 {
        self.rejected
    }

    /// Frequency response of the whole filter at `f_hz`: (|H|, arg H) with H in (rad/s²) per
    /// (rad/s); compare |H| with Ω = 2π f (an exact differentiator) and arg H with +π/2.
    pub fn response(&self, f_hz: f32) -> (f32, f32) {
        let w = core::f32::consts::TAU * f_hz * self.dt;
        let (s, c) = (libm::sinf(w), libm::cosf(w));
        // 1 − z⁻¹ with z⁻¹ = cos w − j sin w.
        let (dr, di) = (1.0 - c, s);
        // 1 − (1 − α) z⁻¹.
        let b = 1.0 - self.alpha;
        let (lr, li) = (1.0 - b * c, b * s);
        let num = sqrt(dr * dr + di * di);
        let den = sqrt(lr * lr + li * li);
        let gain = self.alpha * num / (den * self.dt);
        let phase = libm::atan2f(di, dr) - libm::atan2f(li, lr);
        (gain, phase)
    }
}

/// [`PitchAccel`] in integers for FPU-less cores (`math=fixed`): the same difference and
/// low-pass on the IMU's raw pitch rate (µrad/s), φ̈ in µrad/s² (`i64`), α in 2⁻³⁰, 1/dt in
/// 2⁻¹⁶ s⁻¹, τ in whole mN·m (what the fixed-point sampler takes). A missing sample (`None`)
/// holds the output like a non-finite one in the f32 filter. Agrees with it to < 1 mN·m
/// (test `fixed_pitch_filter_matches_the_f32_filter`).
#[derive(Clone, Debug)]
pub struct FixedPitchAccel {
    inv_dt16: i64,
    alpha30: i64,
    /// τ (mN·m) = φ̈ (µrad/s²) · `inertia_k` >> 32.
    inertia_k: i64,
    prev_rate: Option<i32>,
    gap: u32,
    acc: i64,
}

impl FixedPitchAccel {
    /// The filter of `cfg` at rest (the f32 filter's fallbacks for bad settings).
    pub fn new(cfg: PitchAccelConfig) -> Self {
        let f = PitchAccel::new(cfg);
        FixedPitchAccel {
            inv_dt16: (65536.0 / f64::from(f.dt)) as i64,
            alpha30: (f64::from(f.alpha) * (1u64 << 30) as f64) as i64,
            inertia_k: (f64::from(f.inertia) * 1e-3 * (1u64 << 32) as f64) as i64,
            prev_rate: None,
            gap: 1,
            acc: 0,
        }
    }

    /// Feeds one pitch-rate sample (µrad/s; `None` = no fresh sample).
    pub fn update(&mut self, rate_urad_s: Option<i32>) {
        let Some(rate) = rate_urad_s else {
            self.gap = self.gap.saturating_add(1);
            return;
        };
        if let Some(prev) = self.prev_rate {
            // |Δω| < 2³², 1/dt < 2³⁰ (dt ≥ 1 µs): < 2⁶² before the shift.
            let d = ((i64::from(rate) - i64::from(prev)) * self.inv_dt16) >> 16;
            let d = if self.gap > 1 {
                d / i64::from(self.gap)
            } else {
                d
            };
            // Rounded to nearest (a floor would drift the output down by ½ µrad/s² a sample
            // with a small α).
            let step = (d - self.acc).clamp(-(1 << 33), 1 << 33);
            self.acc += (self.alpha30 * step + (1 << 29)) >> 30;
        }
        self.prev_rate = Some(rate);
        self.gap = 1;
    }

    /// τ = J·φ̈, whole mN·m, rounded to nearest like the f32 path's `roundf` (a floor would
    /// report −1 mN·m for any tiny negative φ̈), saturating.
    pub fn torque_mnm(&self) -> i32 {
        let t = (self.acc.clamp(-(1 << 40), 1 << 40) * self.inertia_k + (1 << 31)) >> 32;
        t.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
    }
}

/// Trunk attitude from gravity, rad.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub struct Tilt {
    /// Roll about x.
    pub roll: f32,
    /// Pitch about y.
    pub pitch: f32,
    /// Angle between the body z axis and vertical (≥ 0).
    pub tilt: f32,
}

use gait_core::maths::fastmath::{sin_cos, sqrt};

/// Time constant of the attitude filter's accelerometer correction, s.
pub const ATTITUDE_TAU_S: f32 = 0.5;

/// Gyro + accelerometer complementary filter for roll and pitch (see the module doc).
#[derive(Clone, Debug, Default)]
pub struct AttitudeFilter {
    roll: f32,
    pitch: f32,
    started: bool,
}

impl AttitudeFilter {
    /// Upright until the first good accelerometer sample.
    pub const fn new() -> Self {
        AttitudeFilter {
            roll: 0.0,
            pitch: 0.0,
            started: false,
        }
    }

    /// Feeds one IMU sample: body rates (rad/s) and specific force (m/s²) over `dt_s` seconds;
    /// non-finite parts are ignored. Returns the attitude.
    pub fn update(&mut self, gyro: [f32; 3], accel: [f32; 3], dt_s: f32) -> Tilt {
        let [ax, ay, az] = accel;
        let n2 = ax * ax + ay * ay + az * az;
        let accel_ok =
            n2.is_finite() && ((0.25 * G) * (0.25 * G)..=(4.0 * G) * (4.0 * G)).contains(&n2);
        if !self.started {
            if accel_ok {
                self.roll = libm::atan2f(ay, az);
                self.pitch = libm::atan2f(-ax, sqrt(ay * ay + az * az));
                self.started = true;
            }
            return self.tilt();
        }
        let [p, q, r] = gyro;
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s
        } else {
            0.0
        };
        if p.is_finite() && q.is_finite() && r.is_finite() {
            let (sr, cr) = sin_cos(self.roll);
            // tan θ, bounded away from the gimbal singularity (θ = ±π/2: the robot lies).
            let (sp, cp) = sin_cos(self.pitch);
            let tp = sp / libm::fmaxf(cp, 0.05);
            self.roll += (p + (q * sr + r * cr) * tp) * dt;
            self.pitch += (q * cr - r * sr) * dt;
        }
        let quiet = accel_ok && ((0.8 * G) * (0.8 * G)..=(1.2 * G) * (1.2 * G)).contains(&n2);
        if quiet {
            let k = dt / (ATTITUDE_TAU_S + dt);
            let roll_a = libm::atan2f(ay, az);
            let pitch_a = libm::atan2f(-ax, sqrt(ay * ay + az * az));
            self.roll += k * wrap(roll_a - self.roll);
            self.pitch += k * (pitch_a - self.pitch);
        }
        self.roll = wrap(self.roll);
        self.pitch = self
            .pitch
            .clamp(-core::f32::consts::FRAC_PI_2, core::f32::consts::FRAC_PI_2);
        self.tilt()
    }

    /// The present attitude.
    pub fn tilt(&self) -> Tilt {
        let c = (sin_cos(self.roll).1 * sin_cos(self.pitch).1).clamp(-1.0, 1.0);
        Tilt {
            roll: self.roll,
            pitch: self.pitch,
            tilt: libm::atan2f(sqrt(1.0 - c * c), c),
        }
    }
}

/// Time constant of the heading's gyro-bias estimate while standing still, s.
pub const HEADING_BIAS_TAU_S: f32 = 2.0;

/// The gyro's yaw integrated (see the module doc, "Heading"), rad from the start.
#[derive(Clone, Debug, Default)]
pub struct Heading {
    yaw: f32,
    bias: f32,
}

impl Heading {
    /// Heading 0, no bias.
    pub const fn new() -> Self {
        Heading {
            yaw: 0.0,
            bias: 0.0,
        }
    }

    /// Feeds one gyro sample (body rates, rad/s) at the attitude `tilt` over `dt_s` seconds;
    /// `still`: the robot stands (the bias estimate follows r). Non-finite input is ignored.
    pub fn update(&mut self, gyro: [f32; 3], tilt: &Tilt, dt_s: f32, still: bool) -> f32 {
        let [_, q, r] = gyro;
        if !(q.is_finite() && r.is_finite() && dt_s.is_finite() && dt_s > 0.0) {
            return self.yaw;
        }
        if still {
            self.bias += (r - self.bias) * libm::fminf(dt_s / HEADING_BIAS_TAU_S, 1.0);
        }
        let (sr, cr) = sin_cos(tilt.roll);
        let cp = libm::fmaxf(sin_cos(tilt.pitch).1, 0.05);
        let yaw = self.yaw + (q * sr + (r - self.bias) * cr) / cp * dt_s;
        if yaw.is_finite() {
            self.yaw = yaw;
        }
        self.yaw
    }

    /// The heading, rad.
    pub fn yaw(&self) -> f32 {
        self.yaw
    }
}

/// π in 2⁻³⁰ rad.
const PI_30: i64 = 3_373_259_426;
/// 1 in 2⁻³⁰ units.
const ONE_30: i64 = 1 << 30;

/// [`AttitudeFilter`] in integers for FPU-less cores (`math=fixed`): the same equations on
/// the IMU's raw units (µrad/s, µm/s²), angles in 2⁻³⁰ rad (`i64`), sin/cos by
/// `gait_core::maths::fixed_point::sin_cos`, atan2 and √ by `gait_core::kinematics::fixed_ik` (|error| < 2e-8 rad
/// and exact floor); one 64-bit division per sample (tan θ). It agrees with the f32 filter
/// to ≈ 1e-4 rad (I16F16 sin/cos arguments; test `fixed_attitude_tracks_the_f32_filter`).
#[derive(Clone, Debug, Default)]
pub struct FixedAttitudeFilter {
    roll: i64,
    pitch: i64,
    started: bool,
    /// Δangle (2⁻³⁰ rad) = rate (µrad/s) · `dt_k` >> 20.
    dt_k: i64,
    /// Complementary gain k = dt/(τ + dt), 2⁻³⁰ units.
    k30: i64,
    /// Squared norm windows of the specific force, (µm/s²)²: plausible, quiet.
    ok2: [u64; 2],
    quiet2: [u64; 2],
}

impl FixedAttitudeFilter {
    /// Upright until the first good accelerometer sample, at sample period `dt_s` (s).
    pub fn new(dt_s: f32) -> Self {
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            f64::from(dt_s)
        } else {
            0.0
        };
        let g_um = f64::from(G) * 1e6;
        let sq = |f: f64| {
            let v = f * g_um;
            (v * v) as u64
        };
        FixedAttitudeFilter {
            roll: 0,
            pitch: 0,
            started: false,
            dt_k: (dt * 1e-6 * (1u64 << 50) as f64) as i64,
            k30: (dt / (f64::from(ATTITUDE_TAU_S) + dt) * ONE_30 as f64) as i64,
            ok2: [sq(0.25), sq(4.0)],
            quiet2: [sq(0.8), sq(1.2)],
        }
    }

    /// Feeds one IMU sample (body rates µrad/s, specific force µm/s²); returns the tilt
    /// from vertical, rad.
    pub fn update(&mut self, gyro_urad_s: [i32; 3], accel_um_s2: [i32; 3]) -> f32 {
        use gait_core::kinematics::fixed_ik::{atan2_fac, isqrt};
        let [ax, ay, az] = accel_um_s2.map(i64::from);
        let sq = |v: i64| v.unsigned_abs() * v.unsigned_abs();
        // < 3·2⁶² < 2⁶⁴.
        let n2 = sq(ax) + sq(ay) + sq(az);
        let within = |w: [u64; 2]| (w[0]..=w[1]).contains(&n2);
        let from_accel = || {
            // √(a_y² + a_z²) < 2³²: fits i64.
            let yz = isqrt(sq(ay) + sq(az)) as i64;
            (atan2_fac(ay, az), atan2_fac(-ax, yz))
        };
        if !self.started {
            if within(self.ok2) {
                (self.roll, self.pitch) = from_accel();
                self.started = true;
            }
            return self.tilt();
        }
        let [p, q, r] = gyro_urad_s.map(i64::from);
        let (sr, cr) = sin_cos30(self.roll);
        let (sp, cp) = sin_cos30(self.pitch);
        // tan θ (2⁻³⁰), bounded away from the gimbal singularity as in the f32 filter.
        let tp = (sp << 30) / cp.max(ONE_30 / 20);
        // Rates < 2³¹ µrad/s, factors ≤ 2³⁰·20: every product < 2⁶³.
        let qr = (q * sr + r * cr) >> 30;
        let roll_rate = p + ((qr * tp) >> 30);
        let pitch_rate = (q * cr - r * sr) >> 30;
        self.roll += (roll_rate * self.dt_k) >> 20;
        self.pitch += (pitch_rate * self.dt_k) >> 20;
        if within(self.quiet2) {
            let (roll_a, pitch_a) = from_accel();
            self.roll += (self.k30 * wrap30(roll_a - self.roll)) >> 30;
            self.pitch += (self.k30 * (pitch_a - self.pitch)) >> 30;
        }
        self.roll = wrap30(self.roll);
        self.pitch = self.pitch.clamp(-PI_30 / 2, PI_30 / 2);
        self.tilt()
    }

    /// Roll and pitch, rad.
    pub fn roll_pitch(&self) -> [f32; 2] {
        [self.roll, self.pitch].map(|a| a as f32 / ONE_30 as f32)
    }

    /// The present tilt from vertical, rad: cos(tilt) = cos φ · cos θ.
    pub fn tilt(&self) -> f32 {
        let c = ((sin_cos30(self.roll).1 * sin_cos30(self.pitch).1) >> 30).clamp(-ONE_30, ONE_30);
        let s = gait_core::kinematics::fixed_ik::isqrt((ONE_30 * ONE_30 - c * c) as u64) as i64;
        gait_core::kinematics::fixed_ik::atan2_fac(s, c) as f32 / ONE_30 as f32
    }
}

/// sin and cos (2⁻³⁰) of an angle in 2⁻³⁰ rad within [−π, π].
fn sin_cos30(a: i64) -> (i64, i64) {
    let bits = ((a + (1 << 13)) >> 14) as i32;
    gait_core::maths::fixed_point::sin_cos(gait_core::maths::fixed_point::Fx::from_bits(bits))
}

/// Wraps an angle in 2⁻³⁰ rad to (−π, π] (0 when it is more than 8 turns out).
fn wrap30(a: i64) -> i64 {
    let mut x = a;
    for _ in 0..8 {
        if x > PI_30 {
            x -= 2 * PI_30;
        } else if x <= -PI_30 {
            x += 2 * PI_30;
        } else {
            return x;
        }
    }
    0
}

/// Wraps an angle to (−π, π].
fn wrap(a: f32) -> f32 {
    use core::f32::consts::{PI, TAU};
    if !a.is_finite() {
        return 0.0;
    }
    let mut x = a;
    while x > PI {
        x -= TAU;
    }
    while x <= -PI {
        x += TAU;
    }
    x
}

/// Tilt from the accelerometer with last-good hold.
#[derive(Clone, Debug, Default)]
pub struct TiltEstimator {
    last: Tilt,
    rejected: u32,
}

impl TiltEstimator {
    /// Upright until the first good sample.
    pub const fn new() -> Self {
        TiltEstimator {
            last: Tilt {
                roll: 0.0,
                pitch: 0.0,
                tilt: 0.0,
            },
            rejected: 0,
        }
    }

    /// Feeds one accelerometer sample (m/s², body frame); returns the (held) tilt.
    pub fn update(&mut self, a: [f32; 3]) -> Tilt {
        let [ax, ay, az] = a;
        let n2 = ax * ax + ay * ay + az * az;
        let lo = 0.25 * G;
        let hi = 4.0 * G;
        if !(n2.is_finite() && n2 >= lo * lo && n2 <= hi * hi) {
            self.rejected = self.rejected.saturating_add(1);
            return self.last;
        }
        let t = Tilt {
            roll: libm::atan2f(ay, az),
            pitch: libm::atan2f(-ax, sqrt(ay * ay + az * az)),
            tilt: libm::atan2f(sqrt(ax * ax + ay * ay), az),
        };
        self.last = t;
        t
    }

    /// Last good tilt.
    pub fn last(&self) -> Tilt {
        self.last
    }

    /// Rejected samples so far.
    pub fn rejected(&self) -> u32 {
        self.rejected
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::TAU as TAU64;

    #[test]
    fn heading_integrates_yaw_and_removes_the_bias_learnt_standing() {
        let upright = Tilt {
            roll: 0.0,
            pitch: 0.0,
            tilt: 0.0,
        };
        let dt = 0.005;
        // Upright, r = 0.2 rad/s for 1 s: ψ = 0.2 rad.
        let mut h = Heading::new();
        for _ in 0..200 {
            h.update([0.0, 0.0, 0.2], &upright, dt, false);
        }
        assert!((h.yaw() - 0.2).abs() < 1e-4, "{}", h.yaw());
        // Rolled by φ = 0.3: ψ̇ = q sin φ + r cos φ (θ = 0).
        let rolled = Tilt {
            roll: 0.3,
            ..upright
        };
        let mut g = Heading::new();
        g.update([0.0, 0.1, 0.2], &rolled, 1.0, false);
        let want = 0.1 * 0.3f32.sin() + 0.2 * 0.3f32.cos();
        assert!((g.yaw() - want).abs() < 1e-3, "{} {want}", g.yaw());
        // A 0.01 rad/s bias: 20 s standing still learns it (e^-10 left), then 10 s walking
        // straight drifts ≤ 0.01 · e^-10 · 10 s + rounding instead of 0.1 rad.
        let mut b = Heading::new();
        for _ in 0..4000 {
            b.update([0.0, 0.0, 0.01], &upright, dt, true);
        }
        let at_start = b.yaw();
        for _ in 0..2000 {
            b.update([0.0, 0.0, 0.01], &upright, dt, false);
        }
        assert!(
            (b.yaw() - at_start).abs() < 1e-4,
            "drift {}",
            b.yaw() - at_start
        );
        // Non-finite samples change nothing.
        let before = b.yaw();
        b.update([0.0, f32::NAN, 0.0], &upright, dt, false);
        b.update([0.0, 0.0, 1.0], &upright, f32::INFINITY, false);
        assert_eq!(b.yaw(), before);
    }

    /// Feeds A sin(Ω t) for `settle` s, then fits the output to a sin + b cos over whole
    /// periods; returns (amplitude, phase) of the output relative to sin(Ω t).
    fn measure(f: &mut PitchAccel, dt: f64, a: f64, hz: f64) -> (f64, f64) {
        let settle = (2.0 / dt) as usize;
        // Whole periods only (callers pick frequencies with an integer number of samples).
        let per = (1.0 / (hz * dt)).round() as usize;
        let n = per * 4;
        let (mut s_sum, mut c_sum) = (0.0, 0.0);
        for k in 0..settle + n {
            let t = k as f64 * dt;
            let y = f.update((a * (TAU64 * hz * t).sin()) as f32) as f64;
            if k >= settle {
                s_sum += y * (TAU64 * hz * t).sin();
                c_sum += y * (TAU64 * hz * t).cos();
            }
        }
        let (sa, ca) = (2.0 * s_sum / n as f64, 2.0 * c_sum / n as f64);
        ((sa * sa + ca * ca).sqrt(), ca.atan2(sa))
    }

    #[test]
    fn reference_config_uses_robot_inertia() {
        let c = PitchAccelConfig::reference(1e-3);
        assert!((c.inertia - 0.026).abs() < 1e-7);
        assert_eq!(c.cutoff_hz, 15.0);
    }

    #[test]
    fn sinusoid_matches_documented_response() {
        let dt = 1e-3;
        for hz in [0.5f64, 1.25, 5.0, 12.5, 20.0, 40.0] {
            let mut f = PitchAccel::new(PitchAccelConfig::reference(dt as f32));
            let a = 0.8; // rad/s
            let (amp, ph) = measure(&mut f, dt, a, hz);
            let (g, p) = f.response(hz as f32);
            assert!(
                (amp - a * g as f64).abs() < 2e-3 * a * g as f64,
                "{hz} Hz: {amp} vs {}",
                a * g as f64
            );
            assert!((ph - p as f64).abs() < 2e-3, "{hz} Hz: {ph} vs {p}");
        }
    }

    #[test]
    fn low_frequency_is_close_to_analytic() {
        let dt = 1e-3;
        let hz = 1.25; // 800 samples per period (the step frequency is ≈ 1.5 Hz)
        let mut f = PitchAccel::new(PitchAccelConfig::reference(dt as f32));
        let a = 0.5;
        let (amp, ph) = measure(&mut f, dt, a, hz);
        let omega = TAU64 * hz;
        // Exact φ̈ = A Ω cos = A Ω sin(· + π/2).
        assert!(
            (amp / (a * omega) - 1.0).abs() < 0.006,
            "gain {}",
            amp / (a * omega)
        );
        let lag = core::f64::consts::FRAC_PI_2 - ph;
        let alpha = f.alpha() as f64;
        let expected_lag = omega * (dt / 2.0 + (1.0 - alpha) / alpha * dt);
        assert!(
            (lag - expected_lag).abs() < 0.01,
            "lag {lag} vs {expected_lag}"
        );
        assert!(lag > 0.0 && lag < 0.11);
        // τ amplitude follows J.
        assert!((f.torque() / f.accel() - 0.026).abs() < 1e-6);
    }

    #[test]
    fn constant_rate_gives_zero_torque() {
        let mut f = PitchAccel::new(PitchAccelConfig::reference(1e-3));
        for _ in 0..2000 {
            f.update(1.2);
        }
        assert!(f.accel().abs() < 1e-6);
        assert!(f.torque().abs() < 1e-7);
    }

    #[test]
    fn step_decays() {
        let mut f = PitchAccel::new(PitchAccelConfig::reference(1e-3));
        f.update(0.0);
        let peak = f.update(0.1);
        assert!((peak - f.alpha() * 100.0).abs() < 1e-3);
        for _ in 0..1000 {
            f.update(0.1);
        }
        assert!(f.accel().abs() < 1e-3);
    }

    #[test]
    fn non_finite_never_propagates() {
        let mut f = PitchAccel::new(PitchAccelConfig::reference(1e-3));
        let mut g = PitchAccel::new(PitchAccelConfig::reference(1e-3));
        for k in 0..500 {
            let w = (k as f32 * 0.01).sin();
            let bad = k % 50 == 7;
            let y = f.update(if bad { f32::NAN } else { w });
            if k % 50 == 9 {
                f.update(f32::INFINITY);
            }
            assert!(y.is_finite() && f.torque().is_finite());
            if !bad {
                g.update(w);
            }
        }
        assert!(f.rejected() >= 20);
        // Dropping samples of a smooth signal barely changes the output.
        assert!((f.accel() - g.accel()).abs() < 0.05);
        // Bad configuration falls back to sane values.
        let mut h = PitchAccel::new(PitchAccelConfig {
            dt_s: f32::NAN,
            cutoff_hz: -1.0,
            inertia: f32::NAN,
        });
        assert!(h.update(1.0).is_finite());
        assert!(h.update(2.0).is_finite());
        assert!(h.torque().is_finite());
    }

    #[test]
    fn tilt_from_gravity() {
        let mut t = TiltEstimator::new();
        let up = t.update([0.0, 0.0, G]);
        assert!(up.tilt.abs() < 1e-6 && up.roll.abs() < 1e-6 && up.pitch.abs() < 1e-6);
        // Pitched forward by 0.3 rad: gravity appears with −x component... a_x = −g sin θ.
        let th = 0.3f32;
        let p = t.update([-G * libm::sinf(th), 0.0, G * libm::cosf(th)]);
        assert!((p.pitch - th).abs() < 1e-5, "{p:?}");
        assert!((p.tilt - th).abs() < 1e-5);
        let r = t.update([0.0, G * libm::sinf(-0.2), G * libm::cosf(-0.2)]);
        assert!((r.roll + 0.2).abs() < 1e-5 && (r.tilt - 0.2).abs() < 1e-5);
        // Lying on the back: tilt ≈ π/2.
        let l = t.update([G, 0.0, 0.0]);
        assert!((l.tilt - core::f32::consts::FRAC_PI_2).abs() < 1e-5);
    }

    #[test]
    fn attitude_tracks_a_fast_rotation_without_lag() {
        // Tipping forward at 2 rad/s; the accelerometer of a tipping robot reads less than g
        // (here 0.7 g, still pointing "up" in the body): outside the quiet band it is not
        // used, and the gyro integration follows the true pitch exactly.
        let mut f = AttitudeFilter::new();
        f.update([0.0; 3], [0.0, 0.0, G], 0.005);
        let dt = 0.005;
        let mut t = Tilt::default();
        for _ in 0..60 {
            t = f.update([0.0, 2.0, 0.0], [0.0, 0.0, 0.7 * G], dt);
        }
        assert!((t.pitch - 0.6).abs() < 1e-4, "{t:?}");
        assert!((t.tilt - t.pitch).abs() < 1e-4);
        // The accelerometer-only estimate saw nothing.
        let mut a = TiltEstimator::new();
        assert!(a.update([0.0, 0.0, 0.7 * G]).tilt < 1e-6);
        // With a quiet accelerometer that reads the true tilted gravity, no error either.
        let mut f = AttitudeFilter::new();
        f.update([0.0; 3], [0.0, 0.0, G], dt);
        for k in 1..=60 {
            let th = 2.0 * dt * k as f32;
            t = f.update(
                [0.0, 2.0, 0.0],
                [-G * libm::sinf(th), 0.0, G * libm::cosf(th)],
                dt,
            );
        }
        assert!((t.pitch - 0.6).abs() < 1e-3, "{t:?}");
    }

    #[test]
    fn attitude_converges_to_gravity_and_rejects_accelerations() {
        let mut f = AttitudeFilter::new();
        let th = 0.3f32;
        // Started upright, then held pitched by 0.3 rad with a still gyro: converges with τ.
        f.update([0.0; 3], [0.0, 0.0, G], 0.005);
        let tilted = [-G * libm::sinf(th), 0.0, G * libm::cosf(th)];
        let mut t = Tilt::default();
        for _ in 0..(5.0 * ATTITUDE_TAU_S / 0.005) as usize {
            t = f.update([0.0; 3], tilted, 0.005);
        }
        assert!((t.pitch - th).abs() < 0.01 * th, "{t:?}");
        // A 0.5 g forward acceleration (norm 1.12 g) pulls little; a 2 g shock not at all.
        let before = f.tilt();
        let shock = f.update([0.0; 3], [2.0 * G, 0.0, G], 0.005);
        assert_eq!(shock.pitch, before.pitch);
        // Non-finite parts are ignored.
        let n = f.update([f32::NAN; 3], [f32::NAN; 3], 0.005);
        assert_eq!(n, before);
        // Roll, with a bias-free gyro: φ̇ = p at θ = 0.
        let mut f = AttitudeFilter::new();
        f.update([0.0; 3], [0.0, 0.0, G], 0.01);
        let r = f.update([1.0, 0.0, 0.0], [0.0, 0.0, G], 0.01);
        assert!(
            (r.roll - 0.01 * (1.0 - 0.01 / (ATTITUDE_TAU_S + 0.01))).abs() < 1e-6,
            "{r:?}"
        );
    }

    #[test]
    fn tilt_holds_on_bad_samples() {
        let mut t = TiltEstimator::new();
        let good = t.update([0.0, G * 0.1, G]);
        for bad in [
            [f32::NAN, 0.0, G],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 100.0 * G],
            [f32::INFINITY; 3],
        ] {
            assert_eq!(t.update(bad), good);
        }
        assert_eq!(t.rejected(), 4);
        assert_eq!(t.last(), good);
    }
    #[test]
    fn fixed_attitude_tracks_the_f32_filter() {
        // A tumbling motion with all three rates and a tilting, partly accelerating specific
        // force (quiet and not), 600 ticks at 5 ms, both filters fed the same integer sample.
        let dt = 0.005f32;
        let mut f = AttitudeFilter::new();
        let mut x = FixedAttitudeFilter::new(dt);
        let mut worst = [0.0f32; 3];
        for k in 0..600 {
            let t = k as f32 * dt;
            let gyro = [
                0.8 * libm::sinf(3.0 * t),
                1.5 * libm::cosf(2.0 * t),
                0.3 * libm::sinf(t),
            ];
            let (r, p) = (0.4 * libm::sinf(1.5 * t), 0.5 * libm::sinf(t));
            let gain = if k % 50 < 10 { 0.7 } else { 1.0 };
            let acc = [
                -G * gain * libm::sinf(p),
                G * gain * libm::sinf(r) * libm::cosf(p),
                G * gain * libm::cosf(r) * libm::cosf(p),
            ];
            let s = dxl::table::imu::ImuSample::from_si(gyro, acc, 0);
            let a = f.update(s.gyro_rad_s(), s.accel_m_s2(), dt);
            let b = x.update(s.gyro_urad_s, s.accel_um_s2);
            let [br, bp] = x.roll_pitch();
            for (w, d) in worst
                .iter_mut()
                .zip([a.roll - br, a.pitch - bp, a.tilt - b])
            {
                *w = w.max(d.abs());
            }
        }
        assert!(worst.iter().all(|&w| w < 2e-4), "{worst:?}");
        // Upright until a plausible sample; a 2 g shock is not used.
        let mut x = FixedAttitudeFilter::new(dt);
        assert_eq!(x.update([0; 3], [0; 3]), 0.0);
        let tilt = x.update([0; 3], [0, 0, 9_806_650]);
        assert!(tilt.abs() < 1e-6, "{tilt}");
        let shocked = x.update([0; 3], [2 * 9_806_650, 0, 9_806_650]);
        assert!(shocked.abs() < 1e-6, "{shocked}");
    }
    #[test]
    fn fixed_pitch_filter_matches_the_f32_filter() {
        // A 1.5 Hz pitch rate of 0.5 rad/s with a dropped sample every 37 ticks, at 5 ms.
        let cfg = PitchAccelConfig::reference(0.005);
        let mut f = PitchAccel::new(cfg);
        let mut x = FixedPitchAccel::new(cfg);
        let mut worst = 0.0f32;
        let mut peak = 0.0f32;
        for k in 0..800 {
            let w = 0.5 * libm::sinf(core::f32::consts::TAU * 1.5 * 0.005 * k as f32);
            let raw = (w * 1e6) as i32;
            if k % 37 == 36 {
                f.update(f32::NAN);
                x.update(None);
            } else {
                f.update(raw as f32 * 1e-6);
                x.update(Some(raw));
            }
            let t = f.torque() * 1000.0;
            peak = peak.max(t.abs());
            worst = worst.max((t - x.torque_mnm() as f32).abs());
        }
        // τ peaks near J·Ω·A (≈ 0.024 · 9.4 · 0.5 N·m ≈ 110 mN·m): not a trivial zero.
        assert!(peak > 50.0, "{peak}");
        assert!(worst <= 1.0, "{worst} mN·m");
    }
}
