//! Servo compliance feed-forward: the position servos' static sag under the gait's loads,
//! predicted and added to the joint targets (the closed-loop issue's "servo-aware tracking").
//!
//! A position servo holds its joint with a spring: with Position P Gain `P` its torque is
//! `τ = K·(q_goal − q)`, `K = (P/128)·(τ_stall/885)·(4096/2π)` N·m/rad (XM430-W350 at the
//! factory gain 800: 18.9 N·m/rad; the simulated servo of the host is exactly this). A joint
//! that must deliver a torque τ therefore stands `τ/K` short of its goal. On the reference robot
//! in single support the stance leg's roll joints carry the body's weight a few centimetres off
//! their axes, so the pelvis sags towards the swing side — the robot shifts its weight only part
//! of the way (`docs/beyond.md`, "Where the lateral error comes from").
//!
//! # Model (quasi-static, per tick, from the planned sample)
//! The ground reaction of the model's CoM motion passes through the ZMP reference `p` towards
//! the CoM `c` (LIPM, ω² = g/z_c):
//!
//! ```text
//! F = M·(ω²(c_x − p_x), ω²(c_y − p_y), g)                                          (C1)
//! ```
//!
//! In single support foot s carries all of it at `p`. In double support (and standing) the load
//! is split along the line between the sole points `s_l`, `s_r`:
//! `λ_r = clamp(((p − s_l)·(s_r − s_l)) / |s_r − s_l|², 0, 1)`, `λ_l = 1 − λ_r`, each foot's
//! share `λ_i·F` at its centre of pressure `s_i + (p − λ_l s_l − λ_r s_r)` (so the two together
//! act at p). Joint j of leg i, at `o_j` with the unit axis `a_j` (world frame, forward
//! kinematics of the targets, [`LegKinematics::joint_axes`]), must deliver the torque that holds
//! everything distal to it (the foot's ground force and the weights `m_l·g` of the leg's mass
//! points below the joint, at `r_l`):
//!
//! ```text
//! τ_j = −a_j · ( (cop_i − o_j) × λ_i F  +  Σ_l (r_l − o_j) × (0, 0, −m_l g) )       (C2)
//! Δq_j = sat(k · τ_j / K),   sat = clamp to ±Δ_max                                  (C3)
//! ```
//!
//! so that the servo's sag `τ_j/K` lands the joint on the planned angle (`k` = 1: the full
//! model, 0: off; one gain for the roll joints, one for the pitch joints, none for the hip
//! yaw, whose load is the small vertical moment). The swing leg gets the weights of its own links only (its hip roll and pitch
//! hold the hanging leg). Neglected: the links' accelerations, the upper body's rotation, the
//! flywheel torque; the pelvis is taken from the sample (with whole-body compensation it stands
//! a few millimetres away, which changes the levers by as much). Cost: two leg chains
//! (12 sine/cosine pairs) and 6 cross products per tick (the moments grouped by joint origin:
//! the hip, the knee, the ankle).

use super::{JointCorrection, JointInput, Measured};
use crate::kinematics::leg::LegKinematics;
use crate::kinematics::pipeline::pelvis_pose;
use crate::robot::{Robot, Side, JOINTS_PER_LEG, LEG_JOINTS};
use crate::trajectory::sampler::{GaitSample, SupportPhase};

/// Feed-forward settings: gains, the servos' stiffness and the saturation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Compliance {
    /// Fraction k of the predicted sag added to the hip-roll and ankle-roll targets (0 = off,
    /// 1 = the full model).
    pub roll: f32,
    /// The same for the hip-pitch, knee and ankle-pitch targets.
    pub pitch: f32,
    /// Joint stiffness K of the position servos, N·m/rad.
    pub stiffness: f32,
    /// Largest correction of one joint, rad.
    pub max_rad: f32,
}

/// XM430-W350 stiffness at the factory Position P Gain 800 and 12 V, N·m/rad:
/// `(800/128)·(4.1/885)·(4096/2π)`.
pub const XM430_STIFFNESS: f32 = 18.875;

impl Compliance {
    /// The firmware's default: 0.75 of the model on the roll joints, 0.15 on the pitch joints,
    /// ±0.15 rad, beside the roll servos' own integral (the firmware's `servo_i_roll` 1250,
    /// `servo_i_hip_roll` 800), which removes the sag the model misses, so the model needs less
    /// than its full gain; a little on the pitch joints (the knee's sag) straightens the sagittal
    /// plane (much more shortens the steps). How it was chosen: `docs/beyond.md`, "Servo
    /// compliance".
    pub const DEFAULT: Compliance = Compliance {
        roll: 0.75,
        pitch: 0.15,
        stiffness: XM430_STIFFNESS,
        max_rad: 0.15,
    };

    /// No feed-forward.
    pub const OFF: Compliance = Compliance {
        roll: 0.0,
        pitch: 0.0,
        stiffness: XM430_STIFFNESS,
        max_rad: 0.15,
    };

    /// True when the feed-forward changes targets (a finite, non-zero gain and a positive
    /// finite stiffness).
    pub fn is_on(&self) -> bool {
        [self.roll, self.pitch]
            .iter()
            .any(|k| k.is_finite() && *k != 0.0)
            && self.stiffness.is_finite()
            && self.stiffness > 0.0
    }

    /// The gain k of joint `j` of a leg (joint order): roll joints, pitch joints, none at the
    /// hip yaw; a non-finite gain is 0.
    fn gain_of(&self, j: usize) -> f32 {
        let k = match j % JOINTS_PER_LEG {
            1 | 5 => self.roll,
            2..=4 => self.pitch,
            _ => 0.0,
        };
        if k.is_finite() {
            k
        } else {
            0.0
        }
    }
}

/// The robot's masses and leg kinematics for the load model, converted once.
#[derive(Clone, Debug)]
pub struct LoadModel {
    kin: LegKinematics<f32>,
    /// Total mass M, kg.
    mass: f32,
    /// Thigh, calf and sole masses of one leg, kg.
    links: [f32; 3],
    /// g, m/s².
    gravity: f32,
}

/// `a × b`.
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a − b`.
fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a · b`.
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a + b`.
fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `k a`.
fn scale(a: [f32; 3], k: f32) -> [f32; 3] {
    [k * a[0], k * a[1], k * a[2]]
}

impl LoadModel {
    /// The load model of `robot`.
    pub fn new(robot: &Robot) -> Self {
        let m = &robot.masses;
        LoadModel {
            kin: LegKinematics::new(robot),
            mass: m.total() as f32,
            links: [m.thigh as f32, m.calf as f32, m.sole as f32],
            gravity: robot.gravity as f32,
        }
    }

    /// The share of the ground reaction each foot carries in `s` (left, right), from (C1)'s
    /// split.
    pub fn load_split(&self, s: &GaitSample<f32>) -> [f32; 2] {
        match s.phase {
            SupportPhase::Single(Side::Left) => [1.0, 0.0],
            SupportPhase::Single(Side::Right) => [0.0, 1.0],
            SupportPhase::Double | SupportPhase::Standing => {
                let [l, r] = s.feet;
                let (dx, dy) = (r.x - l.x, r.y - l.y);
                let d2 = dx * dx + dy * dy;
                let t = ((s.zmp[0] - l.x) * dx + (s.zmp[1] - l.y) * dy) / d2;
                let lr = if t.is_finite() {
                    libm::fminf(libm::fmaxf(t, 0.0), 1.0)
                } else {
                    0.5
                };
                [1.0 - lr, lr]
            }
        }
    }

    /// The torques (C2) the 12 joints (left leg then right leg) must deliver for the sample `s`
    /// with its pelvis shifted by `shift` (m) and the joint angles `q`, N·m.
    pub fn joint_torques(
        &self,
        s: &GaitSample<f32>,
        shift: [f32; 2],
        q: &[f32; LEG_JOINTS],
    ) -> [f32; LEG_JOINTS] {
        let mut pelvis = pelvis_pose(s);
        pelvis.x += shift[0];
        pelvis.y += shift[1];
        let g = self.gravity;
        let z_c = s.com[2];
        let w2 = if z_c > 0.0 { g / z_c } else { 0.0 };
        let force_total = [
            self.mass * w2 * (s.com[0] - s.zmp[0]),
            self.mass * w2 * (s.com[1] - s.zmp[1]),
            self.mass * g,
        ];
        let split = self.load_split(s);
        let [l, r] = s.feet;
        let mix = [
            split[0] * l.x + split[1] * r.x,
            split[0] * l.y + split[1] * r.y,
        ];
        let mut tau = [0.0f32; LEG_JOINTS];
        // Both legs' points and joint axes (the pelvis rotation once).
        let legs = self.kin.legs_joint_axes(&pelvis, q);
        for (i, (pts, axes)) in legs.into_iter().enumerate() {
            let (Some(&share), Some(foot), Some(out)) = (
                split.get(i),
                s.feet.get(i),
                tau.get_mut(i * JOINTS_PER_LEG..(i + 1) * JOINTS_PER_LEG),
            ) else {
                continue;
            };
            let cop = [
                foot.x + s.zmp[0] - mix[0],
                foot.y + s.zmp[1] - mix[1],
                foot.z,
            ];
            let force = force_total.map(|v| v * share);
            // (C2) by joint origin: the three hip joints share the hip centre and their distal
            // links (thigh, calf, sole), the two ankle joints the ankle centre and the sole.
            // The weights' moment about o is Σ (r_l − o) × (0, 0, −m_l g) = (S − M o) × (0, 0,
            // −g) with S = Σ m_l r_l and M = Σ m_l over the links below: (−g v_y, g v_x, 0)
            // for v = S − M o. Three moments a leg instead of six joints' sums of up to four
            // cross products.
            let [m_thigh, m_calf, m_sole] = self.links;
            let below_ankle = (scale(pts.sole_mass, m_sole), m_sole);
            let below_knee = (
                add(below_ankle.0, scale(pts.calf_mass, m_calf)),
                m_calf + m_sole,
            );
            let below_hip = (
                add(below_knee.0, scale(pts.thigh_mass, m_thigh)),
                m_thigh + m_calf + m_sole,
            );
            let moment_about = |origin: [f32; 3], (sum, mass): ([f32; 3], f32)| {
                let c = cross(sub(cop, origin), force);
                let v = sub(sum, scale(origin, mass));
                [c[0] - g * v[1], c[1] + g * v[0], c[2]]
            };
            let moments = [
                moment_about(pts.hip, below_hip),
                moment_about(pts.knee, below_knee),
                moment_about(pts.ankle, below_ankle),
            ];
            for (j, (t, axis)) in out.iter_mut().zip(axes).enumerate() {
                let moment = moments.get(origin_of(j)).copied().unwrap_or([0.0; 3]);
                *t = -dot(axis, moment);
            }
        }
        tau
    }

    /// Adds the feed-forward (C3) of `c` to the 12 joint targets `q` of sample `s` (pelvis shifted
    /// by `shift`); returns the largest |Δq| applied, rad. Off, or a non-finite torque: nothing.
    pub fn apply(
        &self,
        c: &Compliance,
        q: &mut [f32; LEG_JOINTS],
        s: &GaitSample<f32>,
        shift: [f32; 2],
    ) -> f32 {
        if !c.is_on() {
            return 0.0;
        }
        let tau = self.joint_torques(s, shift, q);
        if !tau.iter().all(|t| t.is_finite()) {
            return 0.0;
        }
        let m = if c.max_rad.is_finite() {
            libm::fmaxf(c.max_rad, 0.0)
        } else {
            0.0
        };
        let mut largest = 0.0f32;
        for (j, (v, t)) in q.iter_mut().zip(tau).enumerate() {
            let k = c.gain_of(j) / c.stiffness;
            let d = libm::fminf(libm::fmaxf(k * t, -m), m);
            if d.is_finite() {
                *v += d;
                largest = libm::fmaxf(largest, libm::fabsf(d));
            }
        }
        largest
    }
}

/// The point joint `j` (joint order) turns about: 0 the hip centre (hip yaw, roll, pitch), 1 the
/// knee, 2 the ankle centre (ankle pitch, roll).
fn origin_of(j: usize) -> usize {
    match j {
        0..=2 => 0,
        3 => 1,
        _ => 2,
    }
}

/// The servos' predicted sag under the gait's loads, fed forward (gait-core
/// [`crate::feedback::compliance`] C3) as a joint correction.
#[derive(Clone, Debug)]
pub struct SagFeedForward {
    /// The loads' model.
    pub load: LoadModel,
    /// Gains (off: nothing added).
    pub compliance: Compliance,
}

impl JointCorrection for SagFeedForward {
    fn correct_joints(
        &mut self,
        _: &Measured<'_>,
        input: &JointInput<'_>,
        q: &mut [f32; LEG_JOINTS],
    ) {
        self.load
            .apply(&self.compliance, q, input.loaded, input.com_shift);
    }
}
