//! Distribution of the ground reaction over the feet and their four force sensors.
//!
//! Given the total vertical force `F` and the point where the sensors' centre of pressure
//! should be (the whole-body ZMP, clamped to the support polygon by the caller):
//!
//! * **Between the feet** (double support): with the ankles' ground projections `a_L`, `a_R`,
//!   the left share is `α = clamp(((z − a_R)·(a_L − a_R)) / |a_L − a_R|², 0, 1)`. Both feet get
//!   the same offset `δ = z − (α·a_L + (1 − α)·a_R)`, so the combined centre of pressure
//!   `α·(a_L + δ) + (1 − α)·(a_R + δ)` is exactly `z`.
//! * **Within a foot**: the foot's centre of pressure `c` (foot frame) is clamped to the sensor
//!   rectangle `[−a, a] × [−b, b]`; with `u = c_x/a`, `v = c_y/b` and the sensor signs
//!   `(sxᵢ, syᵢ)` the solutions of `Σf = F, Σf·x = F·c_x, Σf·y = F·c_y` are
//!   `fᵢ = F/4·(1 + u·sxᵢ + v·syᵢ + λ·sxᵢ·syᵢ)`; `λ = 0` is the least-norm solution and the
//!   simulator takes the `λ` nearest 0 that makes every force non-negative (it exists inside
//!   the rectangle; `λ = u·v` is the bilinear split). The result is continuous in `c`.

/// A foot in contact: the ground projection of its ankle and its heading.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FootContact {
    /// Ankle ground projection (sole point) x, y, m.
    pub xy: [f64; 2],
    /// Heading, rad.
    pub yaw: f64,
}

fn rotate(v: [f64; 2], a: f64) -> [f64; 2] {
    let (s, c) = a.sin_cos();
    [c * v[0] - s * v[1], s * v[0] + c * v[1]]
}

/// Forces (N) of the four sensors at `sensors` (foot frame; a rectangle symmetric about the
/// ankle, e.g. `(±0.040, ±0.025)`) carrying `total` N with centre of pressure `cop` (foot frame).
pub fn distribute_in_foot(total: f64, cop: [f64; 2], sensors: &[[f64; 2]; 4]) -> [f64; 4] {
    if total.is_nan() || total <= 0.0 {
        return [0.0; 4];
    }
    let a = sensors.iter().map(|s| s[0].abs()).fold(0.0, f64::max);
    let b = sensors.iter().map(|s| s[1].abs()).fold(0.0, f64::max);
    let u = if a > 0.0 {
        (cop[0] / a).clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let v = if b > 0.0 {
        (cop[1] / b).clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let sign = |x: f64| if x >= 0.0 { 1.0 } else { -1.0 };
    let base = sensors.map(|s| 1.0 + u * sign(s[0]) + v * sign(s[1]));
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for (s, b0) in sensors.iter().zip(base) {
        if sign(s[0]) * sign(s[1]) > 0.0 {
            lo = lo.max(-b0);
        } else {
            hi = hi.min(b0);
        }
    }
    let lambda = if lo > hi { u * v } else { 0.0f64.clamp(lo, hi) };
    let mut f = [0.0; 4];
    for ((fi, s), b0) in f.iter_mut().zip(sensors).zip(base) {
        *fi = (0.25 * total * (b0 + lambda * sign(s[0]) * sign(s[1]))).max(0.0);
    }
    f
}

/// Sensor forces (N) of the left and right foot so that their centre of pressure is `zmp`
/// (see the module documentation). Feet that are `None` carry nothing.
pub fn distribute(
    total: f64,
    zmp: [f64; 2],
    left: Option<FootContact>,
    right: Option<FootContact>,
    sensors: &[[f64; 2]; 4],
) -> [[f64; 4]; 2] {
    let foot = |f: &FootContact, share: f64, world_cop: [f64; 2]| {
        let local = rotate([world_cop[0] - f.xy[0], world_cop[1] - f.xy[1]], -f.yaw);
        distribute_in_foot(total * share, local, sensors)
    };
    match (left, right) {
        (None, None) => [[0.0; 4]; 2],
        (Some(l), None) => [foot(&l, 1.0, zmp), [0.0; 4]],
        (None, Some(r)) => [[0.0; 4], foot(&r, 1.0, zmp)],
        (Some(l), Some(r)) => {
            let d = [l.xy[0] - r.xy[0], l.xy[1] - r.xy[1]];
            let d2 = d[0] * d[0] + d[1] * d[1];
            let alpha = if d2 > 1e-12 {
                (((zmp[0] - r.xy[0]) * d[0] + (zmp[1] - r.xy[1]) * d[1]) / d2).clamp(0.0, 1.0)
            } else {
                0.5
            };
            let base = [
                alpha * l.xy[0] + (1.0 - alpha) * r.xy[0],
                alpha * l.xy[1] + (1.0 - alpha) * r.xy[1],
            ];
            let delta = [zmp[0] - base[0], zmp[1] - base[1]];
            let cl = [l.xy[0] + delta[0], l.xy[1] + delta[1]];
            let cr = [r.xy[0] + delta[0], r.xy[1] + delta[1]];
            [foot(&l, alpha, cl), foot(&r, 1.0 - alpha, cr)]
        }
    }
}

/// Centre of pressure (world) and total of sensor forces, for checks; `None` without load.
pub fn center_of_pressure(
    forces: &[[f64; 4]; 2],
    feet: [Option<FootContact>; 2],
    sensors: &[[f64; 2]; 4],
) -> Option<([f64; 2], f64)> {
    let mut total = 0.0;
    let mut m = [0.0; 2];
    for (ff, foot) in forces.iter().zip(feet) {
        let Some(foot) = foot else { continue };
        for (f, s) in ff.iter().zip(sensors) {
            let w = rotate(*s, foot.yaw);
            total += f;
            m[0] += f * (foot.xy[0] + w[0]);
            m[1] += f * (foot.xy[1] + w[1]);
        }
    }
    (total > 0.0).then(|| ([m[0] / total, m[1] / total], total))
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: [[f64; 2]; 4] = [
        [0.04, 0.025],
        [0.04, -0.025],
        [-0.04, 0.025],
        [-0.04, -0.025],
    ];

    #[test]
    fn least_norm_inside_and_nonnegative_everywhere() {
        let f = distribute_in_foot(40.0, [0.0, 0.0], &S);
        assert!(f.iter().all(|v| (v - 10.0).abs() < 1e-12));
        for &(cx, cy) in &[
            (0.039, 0.024),
            (-0.04, 0.0),
            (0.03, -0.02),
            (0.0, 0.025),
            (0.1, 0.1),
        ] {
            let f = distribute_in_foot(40.0, [cx, cy], &S);
            assert!(f.iter().all(|v| *v >= 0.0));
            let sum: f64 = f.iter().sum();
            assert!((sum - 40.0).abs() < 1e-9);
            let x: f64 = f.iter().zip(S).map(|(v, s)| v * s[0]).sum::<f64>() / sum;
            let y: f64 = f.iter().zip(S).map(|(v, s)| v * s[1]).sum::<f64>() / sum;
            assert!((x - cx.clamp(-0.04, 0.04)).abs() < 1e-9, "{cx} {x}");
            assert!((y - cy.clamp(-0.025, 0.025)).abs() < 1e-9, "{cy} {y}");
        }
    }
}
