//! Whole-body compensation: place the pelvis so that the CoM of the whole multi-body robot —
//! upper body, both thighs, calves and soles, swing leg included — follows the model's CoM.
//!
//! Every model of the seeds ignores the swing leg (19 % of the reference robot's mass, hung
//! 4.5 cm to the side of the pelvis): putting the pelvis on the model's CoM leaves the real CoM
//! displaced toward the swing leg, and the real ZMP with it. Here the model's CoM trajectory
//! c*(t) (which satisfies the model's ZMP relation with the reference) becomes the target of the
//! whole-body CoM:
//!
//! ```text
//!   c_wb(P) = ( M_u·(P + R_P·(f_u, 0, l_u)) + Σ_legs Σ_links m_i·r_i(P, feet) ) / M  (W1)
//!   P_{k+1} = P_k + G·(c* − c_wb(P_k))_xy,  G = M / (M_u + 2·(¾·m_t + ¼·m_calf))    (W2)
//! ```
//!
//! r_i are the link mass points from the leg IK/FK for pelvis P and the planned feet, f_u the
//! upper body's forward offset (`upper_body_forward`: 0 on the reference robot). Moving the
//! pelvis by δ moves c_wb by about δ/G ≈ 0.73·δ (G from the mass fractions), so each
//! fixed-point step (W2) shrinks the error by an order of magnitude or more;
//! [`WholeBody::pelvis_for_com`] takes a fixed number of steps (bounded cost: `iterations` + 1
//! two-leg IK + FK evaluations per sample).
//!
//! The multi-body ZMP of a motion (for tests and for the simulator's ground truth) is
//!
//! ```text
//!   p = Σ m_i((z̈_i + g)·x_i − ẍ_i·z_i) / Σ m_i(z̈_i + g)                          (W3)
//! ```
//!
//! With the CoM on c*, the remaining ZMP error comes only from the links' vertical
//! accelerations and the CoM height's variation (the swing foot lifts 3 cm), both small.

use crate::kinematics::leg::{LegKinematics, LegsIkReport, Pose};
use crate::kinematics::pipeline::{foot_pose, pelvis_pose};
use crate::maths::real::Real;
use crate::robot::{Robot, Side, JOINTS_PER_LEG, LEG_JOINTS};
use crate::trajectory::sampler::GaitSample;

/// Number of link mass points: the upper body and three per leg.
pub const MASS_POINTS: usize = 7;

/// The multi-body robot: its masses and the leg kinematics, converted once.
#[derive(Clone, Debug)]
pub struct WholeBody<R> {
    kin: LegKinematics<R>,
    upper_body: R,
    upper_body_height: R,
    upper_body_forward: R,
    thigh: R,
    calf: R,
    sole: R,
    total: R,
    gravity: R,
    gain: R,
    iterations: u8,
}

/// The result of a compensated sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Compensated<R> {
    /// The pelvis pose that puts the whole-body CoM on the target.
    pub pelvis: Pose<R>,
    /// The 12 joint angles for it (left leg then right leg).
    pub joints: [R; LEG_JOINTS],
    /// What the IK clamped.
    pub report: LegsIkReport<R>,
    /// Horizontal distance between the whole-body CoM and the target after the last step, m.
    pub residual: R,
}

impl<R: Real> WholeBody<R> {
    /// The multi-body model of `robot`, compensating with `iterations` fixed-point steps (W2).
    pub fn new(robot: &Robot, iterations: u8) -> Self {
        let m = &robot.masses;
        WholeBody {
            kin: LegKinematics::new(robot),
            upper_body: R::of(m.upper_body),
            upper_body_height: R::of(m.upper_body_height),
            upper_body_forward: R::of(m.upper_body_forward),
            thigh: R::of(m.thigh),
            calf: R::of(m.calf),
            sole: R::of(m.sole),
            total: R::of(m.total()),
            gravity: R::of(robot.gravity),
            // dc_wb/dP with the feet fixed: the upper body moves fully, the thigh and calf
            // mass points by about 3/4 and 1/4 (TLIPFM's fractions), the soles not at all.
            gain: R::of(m.total() / (m.upper_body + 2.0 * (0.75 * m.thigh + 0.25 * m.calf))),
            iterations,
        }
    }

    /// The leg kinematics.
    pub fn kinematics(&self) -> &LegKinematics<R> {
        &self.kin
    }

    /// The mass points (m, position) of the robot at pelvis `pelvis` with joints `q`: upper
    /// body, then thigh, calf, sole of the left and of the right leg.
    pub fn mass_points(&self, pelvis: &Pose<R>, q: &[R; LEG_JOINTS]) -> [(R, [R; 3]); MASS_POINTS] {
        let rot = pelvis.rotation();
        let (up, fwd) = (self.upper_body_height, self.upper_body_forward);
        // The upper-body mass sits l_u above P along the pelvis z axis and f_u along its x axis.
        let ub = [
            pelvis.x + rot[0][0] * fwd + rot[0][2] * up,
            pelvis.y + rot[1][0] * fwd + rot[1][2] * up,
            pelvis.z + rot[2][0] * fwd + rot[2][2] * up,
        ];
        let mut out = [(self.upper_body, ub); MASS_POINTS];
        for (i, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let leg: [R; JOINTS_PER_LEG] = core::array::from_fn(|j| q[JOINTS_PER_LEG * i + j]);
            let p = self.kin.points(side, pelvis, &leg);
            out[1 + 3 * i] = (self.thigh, p.thigh_mass);
            out[2 + 3 * i] = (self.calf, p.calf_mass);
            out[3 + 3 * i] = (self.sole, p.sole_mass);
        }
        out
    }

    /// The whole-body CoM (W1), m.
    pub fn com(&self, pelvis: &Pose<R>, q: &[R; LEG_JOINTS]) -> [R; 3] {
        let mut c = [R::zero(); 3];
        for (m, r) in self.mass_points(pelvis, q) {
            for k in 0..3 {
                c[k] += m * r[k];
            }
        }
        [c[0] / self.total, c[1] / self.total, c[2] / self.total]
    }

    /// The pelvis (at the sample's height and heading) whose whole-body CoM is `target` (W2),
    /// with the legs reaching the sample's feet.
    pub fn pelvis_for_com(&self, sample: &GaitSample<R>, target: [R; 2]) -> Compensated<R> {
        let mut pelvis = pelvis_pose(sample);
        let feet = [foot_pose(&sample.feet[0]), foot_pose(&sample.feet[1])];
        let (mut q, mut report) = self.kin.legs_ik(&pelvis, &feet[0], &feet[1]);
        let mut residual = R::zero();
        for _ in 0..=self.iterations {
            let c = self.com(&pelvis, &q);
            let (ex, ey) = (target[0] - c[0], target[1] - c[1]);
            residual = (ex * ex + ey * ey).sqrt();
            if !residual.is_finite() {
                break;
            }
            pelvis.x += ex * self.gain;
            pelvis.y += ey * self.gain;
            let (nq, nr) = self.kin.legs_ik(&pelvis, &feet[0], &feet[1]);
            q = nq;
            report = nr;
        }
        Compensated {
            pelvis,
            joints: q,
            report,
            residual,
        }
    }

    /// The compensated joint targets of a sample: the whole-body CoM on the model's CoM.
    pub fn joint_targets(&self, sample: &GaitSample<R>) -> Compensated<R> {
        self.pelvis_for_com(sample, [sample.com[0], sample.com[1]])
    }

    /// The multi-body ZMP (W3) from the mass points at three instants `dt` apart (the middle
    /// one is evaluated), by central differences. None when the robot is in free fall.
    pub fn zmp(&self, points: &[[(R, [R; 3]); MASS_POINTS]; 3], dt: R) -> Option<[R; 2]> {
        let (mut num_x, mut num_y, mut den) = (R::zero(), R::zero(), R::zero());
        let h2 = dt * dt;
        let [before, now, after] = points;
        for (((m, r0), (_, r1)), (_, r2)) in before.iter().zip(now).zip(after) {
            let (m, r0, r1, r2) = (*m, *r0, *r1, *r2);
            let acc: [R; 3] = core::array::from_fn(|k| (r2[k] - r1[k] - r1[k] + r0[k]) / h2);
            let f = m * (acc[2] + self.gravity);
            num_x += f * r1[0] - m * acc[0] * r1[2];
            num_y += f * r1[1] - m * acc[1] * r1[2];
            den += f;
        }
        if den > R::zero() {
            Some([num_x / den, num_y / den])
        } else {
            None
        }
    }
}
