//! The three inverted-pendulum models of seed 000 and their precomputed constants.
//!
//! All three reduce to one linear ODE per horizontal axis (seed 000 eq 4 with the ZMP `p`, the
//! erratum's form):
//!
//! ```text
//!     ẍ = (x − p) / T_TF²  −  τ / C_τ²          ÿ = (y − p_y) / T_TF²
//! ```
//!
//! derived from the torque balance about the support point, Σ mᵢ (g·xᵢ − zᵢ·ẍᵢ) = τ, with every
//! mass on its own horizontal plane and its horizontal position a fixed fraction of the CoM's:
//!
//! * **TLIPFM** (seed 000 eqs 2-4; erratum: g belongs in the denominator of T_TF²): upper body
//!   M_u at (x, z_c + l_u), thigh m_t at (3x/4, 3z_c/4), calf + sole m_c at (x/4, z_c/4):
//!   `C_τ² = M_u z_c + M_u l_u + 9 m_t z_c/16 + m_c z_c/16`,
//!   `T_TF² = C_τ² / ((M_u + 3 m_t/4 + m_c/4) g)`.
//! * **DLIPM** (ref \[26\] of seed 000, not in the seeds; our reading, per the errata): the upper
//!   body M_u as one mass at the CoM point (x, z_c), the whole support leg m_l = m_t + m_c as one
//!   mass at its midpoint (x/2, z_c/2): `C² = M_u z_c + m_l z_c/4`, `T² = C² / ((M_u + m_l/2) g)`.
//! * **LIPM**: the whole robot M as one mass at (x, z_c): `C² = M z_c`, `T² = z_c / g`.
//!
//! With m_t = m_c = l_u = 0 the TLIPFM constants equal the LIPM ones (tested).
//! The swing leg is in none of the models (seed 000 ignores it too).
//!
//! τ = J·φ̈ (seed 000 eq 1), J in kg·m² (the paper prints "kg/cm²"; kg·m² is the consistent
//! reading), φ the upper-body pitch about +y. With constant ZMP and τ, the bounded CoM rests at
//! `p + τ·T_TF²/C_τ²`: a positive τ shifts it forward ([`Model::tau_offset`]).

use crate::error::GaitError;
use crate::maths::real::Real;
use crate::robot::Robot;

/// Which pendulum model the generator uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelKind {
    /// Linear inverted pendulum: one mass at the CoM.
    Lipm,
    /// Double-link LIPM: upper body plus the support leg as one mass at its midpoint.
    Dlipm,
    /// Three-mass LIPM plus flywheel (seed 000).
    Tlipfm,
}

impl ModelKind {
    /// All three models, in the order of seed 000 Table 3.
    pub const ALL: [ModelKind; 3] = [ModelKind::Lipm, ModelKind::Dlipm, ModelKind::Tlipfm];

    /// Short lower-case name (`lipm`, `dlipm`, `tlipfm`).
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Lipm => "lipm",
            ModelKind::Dlipm => "dlipm",
            ModelKind::Tlipfm => "tlipfm",
        }
    }
}

/// A pendulum model built once from the robot: the constants of eq 4, precomputed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Model<R> {
    /// Which model.
    pub kind: ModelKind,
    /// CoM (pelvis point) height z_c, m.
    pub z_c: R,
    /// Time constant T_TF (e-folding time of the unstable mode), s.
    pub t_tf: R,
    /// ω = 1 / T_TF, 1/s.
    pub omega: R,
    /// Torque gain 1/C_τ², 1/(kg·m).
    pub inv_c_tau_sq: R,
    /// T_TF²/C_τ²: CoM offset per unit torque at rest, m/(N·m).
    pub tau_to_offset: R,
    /// Upper-body inertia J, kg·m² (τ = J·φ̈).
    pub inertia: R,
}

/// The constants of a model in f64: (C_τ², T_TF²).
pub fn model_constants(kind: ModelKind, robot: &Robot, z_c: f64) -> Result<(f64, f64), GaitError> {
    robot.validate()?;
    if !z_c.is_finite() {
        return Err(GaitError::NonFinite);
    }
    if z_c <= 0.0 {
        return Err(GaitError::NonPositiveLength);
    }
    let m = &robot.masses;
    let g = robot.gravity;
    let (c2, weight) = match kind {
        ModelKind::Tlipfm => {
            let mu = m.upper_body;
            let mt = m.thigh;
            let mc = m.calf_and_sole();
            let c2 = mu * z_c + mu * m.upper_body_height + 9.0 * mt * z_c / 16.0 + mc * z_c / 16.0;
            (c2, (mu + 0.75 * mt + 0.25 * mc) * g)
        }
        ModelKind::Dlipm => {
            let mu = m.upper_body;
            let ml = m.thigh + m.calf_and_sole();
            (mu * z_c + ml * z_c / 4.0, (mu + ml / 2.0) * g)
        }
        ModelKind::Lipm => {
            let total = m.total();
            (total * z_c, total * g)
        }
    };
    if !(c2 > 0.0 && weight > 0.0) {
        return Err(GaitError::NonPositiveMass);
    }
    Ok((c2, c2 / weight))
}

impl<R: Real> Model<R> {
    /// Builds the model of `kind` for `robot` walking with its CoM at height `z_c` (m).
    pub fn new(kind: ModelKind, robot: &Robot, z_c: f64) -> Result<Self, GaitError> {
        let (c2, t2) = model_constants(kind, robot, z_c)?;
        let t = libm::sqrt(t2);
        Ok(Model {
            kind,
            z_c: R::of(z_c),
            t_tf: R::of(t),
            omega: R::of(1.0 / t),
            inv_c_tau_sq: R::of(1.0 / c2),
            tau_to_offset: R::of(t2 / c2),
            inertia: R::of(robot.masses.upper_body_inertia),
        })
    }

    /// C_τ = sqrt of the torque parameter, √(kg·m).
    pub fn c_tau(&self) -> R {
        (R::one() / self.inv_c_tau_sq).sqrt()
    }

    /// The steady CoM offset τ·T_TF²/C_τ² (m) that a constant torque τ (N·m) causes.
    pub fn tau_offset(&self, tau: R) -> R {
        tau * self.tau_to_offset
    }

    /// The model's CoM acceleration (eq 4): (x − p)/T_TF² − τ/C_τ².
    pub fn acceleration(&self, x: R, p: R, tau: R) -> R {
        self.omega * self.omega * (x - p) - tau * self.inv_c_tau_sq
    }

    /// The same model in another scalar type.
    pub fn cast<S: Real>(&self) -> Model<S> {
        Model {
            kind: self.kind,
            z_c: S::of(self.z_c.to_f64()),
            t_tf: S::of(self.t_tf.to_f64()),
            omega: S::of(self.omega.to_f64()),
            inv_c_tau_sq: S::of(self.inv_c_tau_sq.to_f64()),
            tau_to_offset: S::of(self.tau_to_offset.to_f64()),
            inertia: S::of(self.inertia.to_f64()),
        }
    }
}
