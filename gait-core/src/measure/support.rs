//! Support polygons: the sole rectangles under the feet and their convex hull.
//!
//! A foot at [`Place`] `p = (x, y, ψ)` covers the sole rectangle of the robot description
//! (`L = sole_length` along the foot's heading, `W = sole_width` across it), centred under the
//! ankle. With the half sizes `a = L/2`, `b = W/2` and the rotation `R(ψ)`, its corners are
//!
//! ```text
//!   c_k = (x, y) + R(ψ)·l_k,   R(ψ) = [cos ψ  −sin ψ; sin ψ  cos ψ],
//!   l_k ∈ { (a, b), (−a, b), (−a, −b), (a, −b) }   (front-left, rear-left, rear-right,
//!                                                    front-right: counter-clockwise)
//! ```
//!
//! The support polygon is the convex hull of the corners of the supporting sole(s) (4 or 8
//! points), built with Andrew's monotone chain on a fixed array: sort the points by (x, y), then
//! keep the lower and the upper chain, dropping every point `b` after `a` with
//! `cross(a, b, c) = (b − a) × (c − a) ≤ 0`. The vertices come out counter-clockwise.
//!
//! The margin of a point `q` is its signed distance to the polygon boundary, positive inside:
//!
//! ```text
//!   inside:  m(q) = min_k  (e_k × (q − v_k)) / |e_k|      (e_k = v_{k+1} − v_k; for a convex
//!                                                          polygon the distance to the nearest
//!                                                          edge line is the distance to the
//!                                                          boundary)
//!   outside: m(q) = −min_k dist(q, segment v_k v_{k+1})
//! ```
//!
//! A degenerate hull (one point or a segment) has no inside: its margin is minus the distance.
//! Margins are never below [`FAR_OUTSIDE`] (−10³⁰ m); a non-finite point gets exactly that.

use crate::error::GaitError;
use crate::maths::real::Real;
use crate::robot::Robot;
use crate::trajectory::plan::Place;
use core::cmp::Ordering;
use heapless::Vec;

/// Most vertices a support polygon can have (the hull of two soles' 8 corners).
pub const MAX_VERTICES: usize = 8;

/// The margin reported for non-finite points and the floor of every margin, m.
pub const FAR_OUTSIDE: f64 = -1.0e30;

/// World-frame corners of the sole under a foot at `place`, counter-clockwise from the
/// front-left corner (front-left, rear-left, rear-right, front-right).
pub fn sole_corners<R: Real>(place: &Place<R>, robot: &Robot) -> Result<[[R; 2]; 4], GaitError> {
    let g = &robot.geometry;
    if !(g.sole_length.is_finite() && g.sole_width.is_finite() && place.is_finite()) {
        return Err(GaitError::NonFinite);
    }
    if g.sole_length <= 0.0 || g.sole_width <= 0.0 {
        return Err(GaitError::NonPositiveLength);
    }
    let a = R::of(0.5 * g.sole_length);
    let b = R::of(0.5 * g.sole_width);
    let local = [[a, b], [-a, b], [-a, -b], [a, -b]];
    let corners = local.map(|l| to_world(place, l));
    if corners.iter().flatten().all(|v| v.is_finite()) {
        Ok(corners)
    } else {
        Err(GaitError::NonFinite)
    }
}

/// The point `l` of the foot frame (x forward along the heading) in the world frame.
pub(crate) fn to_world<R: Real>(place: &Place<R>, l: [R; 2]) -> [R; 2] {
    let (s, c) = heading_sin_cos(place.yaw);
    [place.x + c * l[0] - s * l[1], place.y + s * l[0] + c * l[1]]
}

/// A sole's heading's (sin, cos): both from one evaluation (the f32 `sin` and `cos` are each a
/// whole `sin_cos`, and on a soft-float M3 the per-tick measured ZMP path would pay for two per
/// foot); a yaw of exactly 0, every sole of a straight walk, needs none.
pub(crate) fn heading_sin_cos<R: Real>(yaw: R) -> (R, R) {
    if yaw == R::zero() {
        (R::zero(), R::one())
    } else {
        crate::maths::fastmath::sin_cos_real(yaw)
    }
}

/// A convex support polygon of at most [`MAX_VERTICES`] vertices, counter-clockwise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupportPolygon<R> {
    points: [[R; 2]; MAX_VERTICES],
    len: usize,
}

impl<R: Real> SupportPolygon<R> {
    /// The sole rectangle under one foot at `place`.
    pub fn single(place: &Place<R>, robot: &Robot) -> Result<Self, GaitError> {
        let c = sole_corners(place, robot)?;
        Self::from_points(&c).ok_or(GaitError::NonFinite)
    }

    /// The convex hull of both soles (double support).
    pub fn double(left: &Place<R>, right: &Place<R>, robot: &Robot) -> Result<Self, GaitError> {
        let l = sole_corners(left, robot)?;
        let r = sole_corners(right, robot)?;
        let [l0, l1, l2, l3] = l;
        let [r0, r1, r2, r3] = r;
        Self::from_points(&[l0, l1, l2, l3, r0, r1, r2, r3]).ok_or(GaitError::NonFinite)
    }

    /// The convex hull of 1 to [`MAX_VERTICES`] finite points; `None` for no points, too many
    /// points or a non-finite coordinate.
    pub fn from_points(points: &[[R; 2]]) -> Option<Self> {
        if points.is_empty() || points.len() > MAX_VERTICES {
            return None;
        }
        if !points.iter().flatten().all(|v| v.is_finite()) {
            return None;
        }
        let mut all: Vec<[R; 2], MAX_VERTICES> = Vec::new();
        for p in points {
            all.push(*p).ok()?;
        }
        // Insertion sort: at most 8 points, and no general-purpose sort in the firmware's flash.
        for i in 1..all.len() {
            let mut j = i;
            while j > 0 && lexicographic(&all[j - 1], &all[j]) == core::cmp::Ordering::Greater {
                all.swap(j - 1, j);
                j -= 1;
            }
        }
        // Drop repeated points so that the chains never hold a zero-length edge.
        let mut sorted: Vec<[R; 2], MAX_VERTICES> = Vec::new();
        for p in all.iter() {
            if sorted
                .last()
                .is_none_or(|q| lexicographic(q, p) != Ordering::Equal)
            {
                sorted.push(*p).ok()?;
            }
        }

        let mut out = SupportPolygon {
            points: [[R::zero(); 2]; MAX_VERTICES],
            len: 0,
        };
        if let [only] = sorted.as_slice() {
            out.points = [*only; MAX_VERTICES];
            out.len = 1;
            return Some(out);
        }
        // Monotone chain: lower hull left to right, then upper hull right to left.
        let mut hull: Vec<[R; 2], { 2 * MAX_VERTICES }> = Vec::new();
        for p in sorted.iter() {
            while let [.., a, b] = hull.as_slice() {
                if cross(*a, *b, *p) > R::zero() {
                    break;
                }
                hull.pop();
            }
            hull.push(*p).ok()?;
        }
        let lower_len = hull.len() + 1;
        for p in sorted.iter().rev().skip(1) {
            while hull.len() >= lower_len {
                match hull.as_slice() {
                    [.., a, b] if cross(*a, *b, *p) <= R::zero() => {
                        hull.pop();
                    }
                    _ => break,
                }
            }
            hull.push(*p).ok()?;
        }
        // The upper chain ends on the first point again.
        hull.pop();
        for (slot, v) in out.points.iter_mut().zip(hull.iter()) {
            *slot = *v;
        }
        out.len = hull.len().min(MAX_VERTICES);
        Some(out)
    }

    /// The hull vertices, counter-clockwise.
    pub fn vertices(&self) -> &[[R; 2]] {
        self.points.get(..self.len).unwrap_or(&[])
    }

    /// Number of hull vertices (1 or 2 for a degenerate hull).
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when the polygon has no vertex (never the case for a constructed polygon).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Signed distance from `p` to the boundary, m: positive inside, negative outside, never
    /// below [`FAR_OUTSIDE`] (which is also the answer for a non-finite point).
    pub fn margin(&self, p: [R; 2]) -> R {
        let far = R::of(FAR_OUTSIDE);
        if !(p[0].is_finite() && p[1].is_finite()) {
            return far;
        }
        let v = self.vertices();
        let m = match v {
            [] => far,
            [a] => -hypot(p[0] - a[0], p[1] - a[1]),
            [a, b] => -segment_distance(p, *a, *b),
            _ => {
                let mut inside = true;
                let mut min_line: Option<R> = None;
                let mut min_seg: Option<R> = None;
                for (a, b) in v.iter().zip(v.iter().cycle().skip(1)) {
                    let d = [b[0] - a[0], b[1] - a[1]];
                    let len = hypot(d[0], d[1]);
                    if !is_positive(len) {
                        continue;
                    }
                    let signed = (d[0] * (p[1] - a[1]) - d[1] * (p[0] - a[0])) / len;
                    if signed < R::zero() {
                        inside = false;
                    }
                    min_line = Some(min_line.map_or(signed, |m| m.min(signed)));
                    let s = segment_distance(p, *a, *b);
                    min_seg = Some(min_seg.map_or(s, |m| m.min(s)));
                }
                if inside {
                    min_line.unwrap_or(far)
                } else {
                    -min_seg.unwrap_or(-far)
                }
            }
        };
        if m.is_finite() && m >= far {
            m
        } else {
            far
        }
    }

    /// True when `p` is inside with at least margin `m` (m); false for non-finite `p` or `m`.
    pub fn contains_with_margin(&self, p: [R; 2], m: R) -> bool {
        m.is_finite() && p[0].is_finite() && p[1].is_finite() && self.margin(p) >= m
    }
}

/// Total order on points: by x, then y (exact for finite values).
fn lexicographic<R: Real>(a: &[R; 2], b: &[R; 2]) -> Ordering {
    a[0].to_f64()
        .total_cmp(&b[0].to_f64())
        .then(a[1].to_f64().total_cmp(&b[1].to_f64()))
}

/// (a − o) × (b − o): positive when o → a → b turns counter-clockwise.
fn cross<R: Real>(o: [R; 2], a: [R; 2], b: [R; 2]) -> R {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// √(x² + y²) without overflow of the squares.
fn hypot<R: Real>(x: R, y: R) -> R {
    let (ax, ay) = (x.abs(), y.abs());
    let big = ax.max(ay);
    if !is_positive(big) {
        return R::zero();
    }
    let (u, v) = (ax / big, ay / big);
    big * (u * u + v * v).sqrt()
}

/// Distance from `p` to the segment `a b`.
fn segment_distance<R: Real>(p: [R; 2], a: [R; 2], b: [R; 2]) -> R {
    let d = [b[0] - a[0], b[1] - a[1]];
    let w = [p[0] - a[0], p[1] - a[1]];
    let dd = d[0] * d[0] + d[1] * d[1];
    let t = if dd > R::zero() {
        ((w[0] * d[0] + w[1] * d[1]) / dd).clamp_to(R::zero(), R::one())
    } else {
        R::zero()
    };
    hypot(w[0] - t * d[0], w[1] - t * d[1])
}

/// True when `x > 0` (false for NaN).
pub(crate) fn is_positive<R: Real>(x: R) -> bool {
    x > R::zero()
}
