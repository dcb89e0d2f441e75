//! Whole-body ZMP of a set of point masses (the simulator's ground truth).
//!
//! With point masses mᵢ at rᵢ = (xᵢ, yᵢ, zᵢ) (z measured from the ground plane) and
//! accelerations r̈ᵢ, the ground reaction's vertical force and its zero-moment point are
//!
//! ```text
//! F_z   = Σ mᵢ (z̈ᵢ + g)
//! ZMP_x = ( Σ mᵢ (z̈ᵢ + g) xᵢ − Σ mᵢ ẍᵢ zᵢ − L̇_y ) / F_z
//! ZMP_y = ( Σ mᵢ (z̈ᵢ + g) yᵢ − Σ mᵢ ÿᵢ zᵢ + L̇_x ) / F_z
//! ```
//!
//! where `L̇` is the rate of change of angular momentum *not* carried by the point masses minus
//! external moments (the simulator uses `L̇_y = J·φ̈ − τ_y`: the upper body's pitch inertia and an
//! external pitch disturbance torque; `L̇_x = 0`: link rotational inertia is otherwise neglected).

/// A point mass with its position and acceleration (world frame, z above the ground).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MassPoint {
    /// Mass, kg.
    pub mass: f64,
    /// Position, m.
    pub pos: [f64; 3],
    /// Acceleration, m/s².
    pub acc: [f64; 3],
}

/// ZMP and total vertical force of the ground reaction.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Zmp {
    /// ZMP on the ground, m.
    pub xy: [f64; 2],
    /// Σ mᵢ (z̈ᵢ + g), N (≤ 0 means the robot is in free fall / jumping).
    pub fz: f64,
}

/// Whole-body ZMP; `None` when the vertical force is not positive (no ground contact possible).
///
/// `ldot` = (L̇_x, L̇_y), the extra rate of angular momentum (see the module documentation).
pub fn whole_body_zmp(points: &[MassPoint], g: f64, ldot: [f64; 2]) -> Option<Zmp> {
    let mut fz = 0.0;
    let (mut nx, mut ny) = (0.0, 0.0);
    for p in points {
        let w = p.mass * (p.acc[2] + g);
        fz += w;
        nx += w * p.pos[0] - p.mass * p.acc[0] * p.pos[2];
        ny += w * p.pos[1] - p.mass * p.acc[1] * p.pos[2];
    }
    nx -= ldot[1];
    ny += ldot[0];
    if fz > 1e-9 && nx.is_finite() && ny.is_finite() {
        Some(Zmp {
            xy: [nx / fz, ny / fz],
            fz,
        })
    } else {
        None
    }
}

/// Centre of mass of the points, m.
pub fn center_of_mass(points: &[MassPoint]) -> [f64; 3] {
    let m: f64 = points.iter().map(|p| p.mass).sum();
    let mut c = [0.0; 3];
    for p in points {
        for (ci, pi) in c.iter_mut().zip(p.pos) {
            *ci += p.mass * pi;
        }
    }
    if m > 0.0 {
        c.map(|v| v / m)
    } else {
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_static_mass_is_its_projection() {
        let p = MassPoint {
            mass: 2.0,
            pos: [0.1, -0.2, 0.5],
            acc: [0.0; 3],
        };
        let z = whole_body_zmp(&[p], 9.81, [0.0; 2]).unwrap();
        assert!((z.xy[0] - 0.1).abs() < 1e-12 && (z.xy[1] + 0.2).abs() < 1e-12);
        assert!((z.fz - 2.0 * 9.81).abs() < 1e-12);
    }

    #[test]
    fn free_fall_has_no_zmp() {
        let p = MassPoint {
            mass: 1.0,
            pos: [0.0, 0.0, 0.5],
            acc: [0.0, 0.0, -9.81],
        };
        assert!(whole_body_zmp(&[p], 9.81, [0.0; 2]).is_none());
    }

    #[test]
    fn pitch_moment_shifts_zmp_backwards() {
        let p = MassPoint {
            mass: 1.0,
            pos: [0.0, 0.0, 0.5],
            acc: [0.0; 3],
        };
        // L̇_y = +0.981 N·m → ZMP_x = −0.1 m.
        let z = whole_body_zmp(&[p], 9.81, [0.0, 0.981]).unwrap();
        assert!((z.xy[0] + 0.1).abs() < 1e-12);
    }
}
