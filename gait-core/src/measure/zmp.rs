//! The measured ZMP from the foot force sensors, and ZMP tracking-error statistics.
//!
//! Seed 000 measures the ZMP response with four force sensors in each sole and reports, per
//! axis, the sum of the absolute errors between the ZMP response and the reference (Table 3).
//!
//! Sensor i of a foot sits at `s_i` (foot frame, from the ankle's ground projection; taken from
//! `Robot::geometry.force_sensors`, order front-left, front-right, rear-left, rear-right). For a
//! foot at `(x, y, ψ)` its world position is `r_i = (x, y) + R(ψ)·s_i`. With the readings clamped
//! to compression, `f_i = max(F_i, 0)` (N), a foot's load and centre of pressure are
//!
//! ```text
//!   F_foot = Σ_i f_i,     c_foot = (x, y) + R(ψ)·(Σ_i f_i·s_i / F_foot)  (= Σ f_i r_i / Σ f_i)
//! ```
//!
//! and the measured ZMP over the loaded feet `K` (valid, `F_k > 0` and `F_k ≥ min_load`) is
//!
//! ```text
//!   p_zmp = Σ_{k∈K} F_k·c_k / Σ_{k∈K} F_k   (= Σ fᵢ·rᵢ / Σ fᵢ over their sensors)
//! ```
//!
//! which lies in the convex hull of the loaded feet's sensor points. A foot with a non-finite
//! reading or pose (or a load that overflows) is invalid: it carries no load and no ZMP. With no
//! loaded foot the robot is airborne and there is no ZMP.
//!
//! Error statistics, per axis `j` over the `n` samples that have a measured ZMP, with
//! `e = p_measured − p_reference` evaluated in `f64`:
//!
//! ```text
//!   S_j = Σ |e_j|,   mean_j = S_j / n,   RMS_j = √(Σ e_j² / n),   max_j = max |e_j|
//! ```
//!
//! [`FixedZmpMeter`] computes the same ZMP without floating point (FPU-less cores): forces in
//! whole mN (as the foot boards send them), sensor offsets and sole poses in I16F16 m, the
//! rotation by ψ with the fixed-point `sin_cos` (skipped at ψ = 0), and for both feet together
//! `p_zmp = (Σ_k F_k·(x_k, y_k) + R(ψ_k)·Σ_i f_i·s_i) / Σ_k F_k` in `i64` with two divisions.
//! No product can overflow: each reading is clamped to [0, 2²⁴] mN (16.8 kN, far beyond any
//! plausible load), the offsets to ±0.25 m, and the rotation takes sin and cos to 2⁻²⁰. It
//! agrees with the f32 formula to the I16F16 resolution (2⁻¹⁶ m ≈ 15 µm; test
//! `fixed_zmp_matches_f64`).
//!
//! The sum of squares is kept scaled (`Σ e² = scale²·ssq` with `scale = max |e|`), so it cannot
//! overflow; the sum saturates at `f64::MAX`. Memory is O(1).

use crate::error::GaitError;
use crate::maths::fixed_point::Fx;
use crate::maths::real::Real;
use crate::measure::support::{is_positive, to_world, SupportPolygon};
use crate::robot::Robot;
use crate::trajectory::fixed_sampler::FixedFoot;
use crate::trajectory::plan::Place;
use crate::trajectory::swing::FootSample;
use core::marker::PhantomData;

/// The four force readings of one foot, N, in the sensor order of the robot description.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct ForceReading<R> {
    /// Forces of the front-left, front-right, rear-left and rear-right sensors, N.
    pub forces: [R; 4],
}

impl<R: Real> ForceReading<R> {
    /// A reading from its four forces.
    pub fn new(forces: [R; 4]) -> Self {
        ForceReading { forces }
    }

    /// The forces clamped to compression (`max(F, 0)`); `None` when one is not finite.
    pub fn compression(&self) -> Option<[R; 4]> {
        if self.forces.iter().all(|f| f.is_finite()) {
            Some(self.forces.map(|f| f.max(R::zero())))
        } else {
            None
        }
    }
}

/// Anything that tells where a foot stands on the ground (its sole point and heading).
pub trait SolePose<R> {
    /// The ground projection of the sole point and the heading.
    fn sole_place(&self) -> Place<R>;

    /// The heading's (sin, cos) when the pose already has them (the ZMP then needs no sine and
    /// cosine of its own); `None`: computed from the heading (none at a heading of exactly 0).
    fn heading_sin_cos(&self) -> Option<(R, R)> {
        None
    }
}

impl<R: Real> SolePose<R> for Place<R> {
    fn sole_place(&self) -> Place<R> {
        *self
    }
}

impl<R: Real> SolePose<R> for FootSample<R> {
    fn sole_place(&self) -> Place<R> {
        Place {
            x: self.x,
            y: self.y,
            yaw: self.yaw,
        }
    }
}

/// World positions of a foot's force sensors (robot-description order).
pub fn sensor_positions<R: Real, P: SolePose<R>>(
    robot: &Robot,
    pose: &P,
) -> Result<[[R; 2]; 4], GaitError> {
    let place = pose.sole_place();
    if !place.is_finite() {
        return Err(GaitError::NonFinite);
    }
    let s = robot.geometry.force_sensors;
    let out = s.map(|si| to_world(&place, [R::of(si[0]), R::of(si[1])]));
    if out.iter().flatten().all(|v| v.is_finite()) {
        Ok(out)
    } else {
        Err(GaitError::NonFinite)
    }
}

/// Which feet carry load.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Contact {
    /// No foot is loaded (airborne, or no valid reading).
    None,
    /// Only the left foot is loaded.
    Left,
    /// Only the right foot is loaded.
    Right,
    /// Both feet are loaded.
    Both,
}

impl Contact {
    /// The contact state from which feet are loaded.
    pub fn from_loaded(left: bool, right: bool) -> Contact {
        match (left, right) {
            (false, false) => Contact::None,
            (true, false) => Contact::Left,
            (false, true) => Contact::Right,
            (true, true) => Contact::Both,
        }
    }
}

/// The measured ZMP and the loads it came from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredZmp<R> {
    /// The measured ZMP in the world frame, m; `None` when no foot is loaded.
    pub zmp: Option<[R; 2]>,
    /// Total compressive force of the valid feet (loaded or not), N.
    pub total_force: R,
    /// Left-foot load, N (0 when the foot is invalid).
    pub left_load: R,
    /// Right-foot load, N (0 when the foot is invalid).
    pub right_load: R,
    /// Which feet count for the ZMP (valid and at least `min_load`).
    pub contact: Contact,
    /// False when the left foot's readings or pose were not finite.
    pub left_valid: bool,
    /// False when the right foot's readings or pose were not finite.
    pub right_valid: bool,
}

/// One foot's load and centre of pressure (sensor offsets `sensors` in the foot frame, m);
/// `None` when the foot is invalid.
fn foot_pressure<R: Real, P: SolePose<R>>(
    sensors: &[[R; 2]; 4],
    pose: &P,
    reading: &ForceReading<R>,
) -> Option<(R, Option<[R; 2]>)> {
    let f = reading.compression()?;
    let place = pose.sole_place();
    if !place.is_finite() {
        return None;
    }
    let mut load = R::zero();
    let mut moment = [R::zero(); 2];
    for (fi, s) in f.iter().zip(sensors.iter()) {
        load += *fi;
        moment[0] += *fi * s[0];
        moment[1] += *fi * s[1];
    }
    if !(load.is_finite() && moment[0].is_finite() && moment[1].is_finite()) {
        return None;
    }
    if !is_positive(load) {
        return Some((R::zero(), None));
    }
    let l = [moment[0] / load, moment[1] / load];
    let c = match pose.heading_sin_cos() {
        Some((sin, cos)) => [
            place.x + cos * l[0] - sin * l[1],
            place.y + sin * l[0] + cos * l[1],
        ],
        None => to_world(&place, l),
    };
    if c[0].is_finite() && c[1].is_finite() {
        Some((load, Some(c)))
    } else {
        None
    }
}

/// The measured ZMP of both feet: each foot's sensor forces at their world positions, feet below
/// `min_load` (N) ignored, negative readings clamped to 0, non-finite feet invalid.
/// (Converts the robot's sensor offsets on every call; a loop keeps a [`ZmpMeter`].)
pub fn measured_zmp<R: Real, L: SolePose<R>, Q: SolePose<R>>(
    robot: &Robot,
    left: (&L, &ForceReading<R>),
    right: (&Q, &ForceReading<R>),
    min_load: R,
) -> MeasuredZmp<R> {
    ZmpMeter::new(robot, min_load).zmp(left, right)
}

/// [`measured_zmp`] with the robot's sensor offsets converted to `R` once (on an FPU without
/// double precision each `f64 → f32` is a library call, and there are 16 a tick).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZmpMeter<R> {
    /// Sensor offsets in the foot frame, m.
    sensors: [[R; 2]; 4],
    /// Least load of a foot that counts, N.
    min_load: R,
}

impl<R: Real> ZmpMeter<R> {
    /// The meter of `robot` with feet under `min_load` (N) ignored.
    pub fn new(robot: &Robot, min_load: R) -> Self {
        ZmpMeter {
            sensors: robot
                .geometry
                .force_sensors
                .map(|[x, y]| [R::of(x), R::of(y)]),
            min_load,
        }
    }

    /// The measured ZMP of both feet ([`measured_zmp`]).
    pub fn zmp<L: SolePose<R>, Q: SolePose<R>>(
        &self,
        left: (&L, &ForceReading<R>),
        right: (&Q, &ForceReading<R>),
    ) -> MeasuredZmp<R> {
        zmp_of(&self.sensors, left, right, self.min_load)
    }
}

/// [`measured_zmp`] on converted sensor offsets.
fn zmp_of<R: Real, L: SolePose<R>, Q: SolePose<R>>(
    sensors: &[[R; 2]; 4],
    left: (&L, &ForceReading<R>),
    right: (&Q, &ForceReading<R>),
    min_load: R,
) -> MeasuredZmp<R> {
    let mut l = foot_pressure(sensors, left.0, left.1);
    let mut r = foot_pressure(sensors, right.0, right.1);
    let load_of = |p: &Option<(R, Option<[R; 2]>)>| p.as_ref().map_or(R::zero(), |v| v.0);
    let mut total = load_of(&l) + load_of(&r);
    if !total.is_finite() {
        // Both loads are finite but their sum overflows: nothing trustworthy is left.
        l = None;
        r = None;
        total = R::zero();
    }
    let loaded = |p: &Option<(R, Option<[R; 2]>)>| match p {
        Some((load, Some(c))) if *load >= min_load => Some((*load, *c)),
        _ => None,
    };
    let (lk, rk) = (loaded(&l), loaded(&r));
    let zmp = match (lk, rk) {
        (None, None) => None,
        (Some((_, c)), None) | (None, Some((_, c))) => Some(c),
        (Some((fl, cl)), Some((fr, cr))) => {
            // c_l + (c_r − c_l)·F_r/(F_l + F_r): a convex combination, no overflow of F·c.
            let w = fr / (fl + fr);
            let z = [cl[0] + (cr[0] - cl[0]) * w, cl[1] + (cr[1] - cl[1]) * w];
            if z[0].is_finite() && z[1].is_finite() {
                Some(z)
            } else {
                None
            }
        }
    };
    MeasuredZmp {
        zmp,
        total_force: total,
        left_load: load_of(&l),
        right_load: load_of(&r),
        contact: Contact::from_loaded(lk.is_some(), rk.is_some()),
        left_valid: l.is_some(),
        right_valid: r.is_some(),
    }
}

/// The measured ZMP in fixed point (module docs): the robot's sensor offsets and the
/// minimum load converted once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedZmpMeter {
    /// Sensor offsets in the foot frame, I16F16 m bits.
    sensors: [[i64; 2]; 4],
    /// Least load of a foot that counts, mN.
    min_load_mn: i64,
}

/// One foot's load (mN) and its moment about the origin in the world axes
/// (mN · I16F16 m bits), `None` without a reading.
type FixedFootLoad = Option<(i64, [i64; 2])>;

impl FixedZmpMeter {
    /// The meter of `robot` with feet under `min_load_n` (N) ignored.
    pub fn new(robot: &Robot, min_load_n: f32) -> Self {
        // Offsets of a few cm: nearest I16F16 step (a plain product, not the `fixed` crate's
        // generic f64 conversion: ≈ 600 B less flash on the M3).
        let bits = |v: f64| {
            if v.is_finite() {
                libm::round(libm::fmin(libm::fmax(v, -0.25), 0.25) * 65536.0) as i64
            } else {
                0
            }
        };
        let min = if min_load_n.is_finite() {
            libm::roundf(min_load_n * 1000.0) as i64
        } else {
            0
        };
        FixedZmpMeter {
            sensors: robot
                .geometry
                .force_sensors
                .map(|s| [bits(s[0]), bits(s[1])]),
            min_load_mn: min,
        }
    }

    /// One foot: `forces` (mN, sensor order; `None` = no valid reading) at `foot`.
    fn foot(&self, foot: &FixedFoot, forces: Option<[i32; 4]>) -> FixedFootLoad {
        let f = forces?;
        let mut load = 0i64;
        let mut m = [0i64; 2];
        for (&fi, s) in f.iter().zip(self.sensors.iter()) {
            // f ≤ 2²⁴, |s| ≤ 2¹⁴: |m| ≤ 2⁴⁰.
            let fi = i64::from(fi.clamp(0, 1 << 24));
            load += fi;
            m[0] += fi * s[0];
            m[1] += fi * s[1];
        }
        let yaw = foot.yaw;
        if yaw != Fx::ZERO {
            let (sn, cs) = crate::maths::fixed_point::sin_cos(yaw);
            // sin, cos to 2⁻²⁰: products ≤ 2⁶⁰.
            let (sn, cs) = (sn >> 10, cs >> 10);
            m = [(m[0] * cs - m[1] * sn) >> 20, (m[0] * sn + m[1] * cs) >> 20];
        }
        // load ≤ 2²⁶, |x|, |y| < 2³¹: ≤ 2⁵⁷.
        let p = [
            load * i64::from(foot.x.to_bits()),
            load * i64::from(foot.y.to_bits()),
        ];
        Some((load, [p[0] + m[0], p[1] + m[1]]))
    }

    /// The measured ZMP (I16F16 m) of the feet at `left` / `right` with their forces (mN;
    /// `None` = no valid reading); `None` when no valid foot carries `min_load` (the f32
    /// [`measured_zmp`]'s `zmp`).
    pub fn zmp(
        &self,
        left: (&FixedFoot, Option<[i32; 4]>),
        right: (&FixedFoot, Option<[i32; 4]>),
    ) -> Option<[Fx; 2]> {
        let loaded = |p: FixedFootLoad| p.filter(|&(l, _)| l > 0 && l >= self.min_load_mn);
        let l = loaded(self.foot(left.0, left.1));
        let r = loaded(self.foot(right.0, right.1));
        let (load, m) = match (l, r) {
            (None, None) => return None,
            (Some(a), None) | (None, Some(a)) => a,
            // Sums of two terms ≤ 2⁵⁸.
            (Some((fl, ml)), Some((fr, mr))) => (fl + fr, [ml[0] + mr[0], ml[1] + mr[1]]),
        };
        let q = |v: i64| i32::try_from(v / load).ok().map(Fx::from_bits);
        Some([q(m[0])?, q(m[1])?])
    }
}

/// Error statistics of one axis, m (all zero before the first measured sample).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct AxisErrorStats {
    /// Number of samples with a measured ZMP.
    pub count: u64,
    /// Σ |e|, m (seed 000 Table 3).
    pub sum_abs: f64,
    /// Σ |e| / count, m.
    pub mean_abs: f64,
    /// √(Σ e² / count), m.
    pub rms: f64,
    /// max |e|, m.
    pub max_abs: f64,
}

/// Running sums of one axis (scaled sum of squares: Σ e² = scale²·ssq).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
struct AxisAcc {
    count: u64,
    sum_abs: f64,
    scale: f64,
    ssq: f64,
}

impl AxisAcc {
    fn push(&mut self, e: f64) {
        let a = libm::fabs(e);
        self.count = self.count.saturating_add(1);
        self.sum_abs = (self.sum_abs + a).min(f64::MAX);
        if a > self.scale {
            let r = self.scale / a;
            self.ssq = 1.0 + self.ssq * r * r;
            self.scale = a;
        } else if a > 0.0 {
            let r = a / self.scale;
            self.ssq += r * r;
        }
    }

    fn stats(&self) -> AxisErrorStats {
        if self.count == 0 {
            return AxisErrorStats::default();
        }
        let n = self.count as f64;
        let rms = self.scale * libm::sqrt(self.ssq / n);
        AxisErrorStats {
            count: self.count,
            sum_abs: self.sum_abs,
            mean_abs: self.sum_abs / n,
            rms: if rms.is_finite() { rms } else { self.scale },
            max_abs: self.scale,
        }
    }
}

/// ZMP tracking-error statistics, accumulated sample by sample in `f64`, O(1) memory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZmpErrorStats<R> {
    samples: u64,
    skipped: u64,
    invalid: u64,
    x: AxisAcc,
    y: AxisAcc,
    polygon_samples: u64,
    inside: u64,
    _real: PhantomData<R>,
}

impl<R: Real> Default for ZmpErrorStats<R> {
    fn default() -> Self {
        Self::new()
    }
}

impl<R: Real> ZmpErrorStats<R> {
    /// Empty statistics.
    pub fn new() -> Self {
        ZmpErrorStats {
            samples: 0,
            skipped: 0,
            invalid: 0,
            x: AxisAcc::default(),
            y: AxisAcc::default(),
            polygon_samples: 0,
            inside: 0,
            _real: PhantomData,
        }
    }

    /// Forgets every sample.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Adds one sample: the error `measured − reference`; a sample without a measured ZMP is
    /// counted as skipped, one with a non-finite number as invalid.
    pub fn push(&mut self, reference: [R; 2], measured: Option<[R; 2]>) {
        self.samples = self.samples.saturating_add(1);
        let Some(m) = measured else {
            self.skipped = self.skipped.saturating_add(1);
            return;
        };
        let ex = m[0].to_f64() - reference[0].to_f64();
        let ey = m[1].to_f64() - reference[1].to_f64();
        if !(ex.is_finite() && ey.is_finite()) {
            self.invalid = self.invalid.saturating_add(1);
            return;
        }
        self.x.push(ex);
        self.y.push(ey);
    }

    /// Like [`ZmpErrorStats::push`], and also counts whether the measured ZMP is inside
    /// `polygon` with at least `margin` (m).
    pub fn push_with_polygon(
        &mut self,
        reference: [R; 2],
        measured: Option<[R; 2]>,
        polygon: &SupportPolygon<R>,
        margin: R,
    ) {
        self.push(reference, measured);
        self.polygon_samples = self.polygon_samples.saturating_add(1);
        if measured.is_some_and(|m| polygon.contains_with_margin(m, margin)) {
            self.inside = self.inside.saturating_add(1);
        }
    }

    /// All samples pushed (measured, skipped and invalid).
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Samples without a measured ZMP.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Samples with a non-finite reference or measured ZMP.
    pub fn invalid(&self) -> u64 {
        self.invalid
    }

    /// Statistics of the x error.
    pub fn x(&self) -> AxisErrorStats {
        self.x.stats()
    }

    /// Statistics of the y error.
    pub fn y(&self) -> AxisErrorStats {
        self.y.stats()
    }

    /// Samples pushed with [`ZmpErrorStats::push_with_polygon`].
    pub fn polygon_samples(&self) -> u64 {
        self.polygon_samples
    }

    /// Of those, the samples whose measured ZMP was inside the polygon with the margin.
    pub fn inside_count(&self) -> u64 {
        self.inside
    }

    /// `inside_count / polygon_samples` (the time fraction at a fixed sample rate; 0 if none).
    pub fn inside_fraction(&self) -> f64 {
        if self.polygon_samples == 0 {
            0.0
        } else {
            self.inside as f64 / self.polygon_samples as f64
        }
    }
}
