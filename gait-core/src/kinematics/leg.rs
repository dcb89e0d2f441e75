//! Analytic 6-DOF leg kinematics: forward kinematics, closed-form inverse kinematics and a
//! joint-speed feasibility monitor.
//!
//! # Frames and chain
//!
//! World x forward, y left, z up. A [`Pose`] holds a position and ZYX angles:
//! `R(pose) = Rz(yaw)·Ry(pitch)·Rx(roll)`, with the elementary rotations
//!
//! ```text
//! Rx(a) = [1 0 0; 0 c −s; 0 s c]   Ry(a) = [c 0 s; 0 1 0; −s 0 c]   Rz(a) = [c −s 0; s c 0; 0 0 1]
//! ```
//!
//! Joint order per leg: q0 hip_yaw (z), q1 hip_roll (x), q2 hip_pitch (y), q3 knee (y),
//! q4 ankle_pitch (y), q5 ankle_roll (x). Zero = straight leg, sole flat; positive = right-hand
//! rule (knee flexion > 0; a crouch is q2 < 0, q3 > 0, q4 < 0). With σ = +1 (left) / −1
//! (right), thigh L1, calf L2, ankle height h, hip offset d, the sole point's offset
//! o = (o_x, σ·o_y, −h) from the ankle in the foot frame and e_z = (0, 0, 1):
//!
//! ```text
//! R_P  = R(pelvis)                         P = pelvis position
//! H    = P + R_P·(0, σ·d, 0)               hip (the three hip axes intersect)
//! R_T  = R_P·Rz(q0)·Rx(q1)·Ry(q2)          thigh frame
//! K    = H − L1·R_T·e_z                    knee
//! R_C  = R_T·Ry(q3)                        calf frame
//! A    = K − L2·R_C·e_z                    ankle (both ankle axes intersect)
//! R_F  = R_C·Ry(q4)·Rx(q5)                 foot frame
//! S    = A + R_F·o                         sole point (foot pose position)
//! ```
//!
//! Mass points: thigh (H + K)/2, calf (K + A)/2, sole S + h_s·R_F·e_z (h_s = sole mass height).
//! On the reference robot o = (0, 0, −h): the sole point is under the ankle.
//!
//! # Inverse kinematics (closed form)
//!
//! Given the pelvis pose (R_P, P) and the foot pose (R_F, S):
//!
//! ```text
//! A = S − R_F·o,   H = P + R_P·(0, σd, 0),   r = R_Fᵀ·(H − A)   (hip seen from the ankle)
//! ```
//!
//! From the chain, `r = Rx(−q5)·Ry(−q4)·v` with `v = Ry(−q3)·(0,0,L1) + (0,0,L2)
//! = (−L1·sin q3, 0, L2 + L1·cos q3)` and `|v|² = L1² + L2² + 2·L1·L2·cos q3`.
//!
//! 1. Reach: D = |r| is clamped to [D_min, D_max], D_max = |v| at q3 = max(knee_min, 0.02 rad)
//!    (the knee always stays slightly bent, away from the singularity) and D_min = |v| at the
//!    knee's upper limit; r is rescaled and `reach_deficit = |D − D_clamped|`.
//! 2. Knee (law of cosines, half-angle form, no cancellation near the straight leg):
//!    `a = √((L1+L2)² − D²)`, `b = √(D² − (L1−L2)²)`, `q3 = 2·atan2(a, b)`,
//!    `sin q3 = a·b/(2·L1·L2)`, `cos q3 = (b² − a²)/(4·L1·L2)`.
//! 3. Ankle roll: `Rx(−q5)·(w_x, 0, w_z) = (w_x, w_z·sin q5, w_z·cos q5)` so
//!    `q5 = atan2(r_y, r_z)`, `w_z = √(r_y² + r_z²)` (branch |q5| < π/2 when the hip is above
//!    the ankle).
//! 4. Ankle pitch: Ry(φ) adds φ to the angle atan2(x, z) of a vector in the xz plane, so
//!    `q4 = atan2(v_x, v_z) − atan2(w_x, w_z) = −atan2(L1·sin q3, L2 + L1·cos q3) − atan2(r_x, w_z)`.
//! 5. Hip: `M = Rz(q0)·Rx(q1)·Ry(q2) = R_Pᵀ·R_F·Rx(−q5)·Ry(−(q3 + q4))`, and since
//!    `Rz(q0)Rx(q1)Ry(q2) = [·  −s0·c1  ·; ·  c0·c1  ·; −c1·s2  s1  c1·c2]`:
//!    `q0 = atan2(−M01, M11)`, `q1 = atan2(M21, √(M01² + M11²))`, `q2 = atan2(−M20, M22)`
//!    (branch |q1| < π/2).
//!
//! q3, q4, q5 are clamped to the joint limits before step 5 (so the hip makes the best of a
//! clamped ankle), q0..q2 after it; every clamp sets its bit in [`IkSolution::limited`].
//! Non-finite inputs are replaced (NaN → 0, ±inf / |x| > 1000 m → ±1000 m) and flagged, so the
//! result is always finite and within the limits. Both legs use the same code (σ and the
//! mirrored limits of [`Robot::joint_limit`]).
//!
//! For `f32` the sines and cosines come from [`crate::maths::fastmath`] (a short polynomial instead of
//! libm's software-double `sinf`/`cosf` on the Cortex-M7F).
//!
//! # Feasibility
//!
//! [`JointSpeedMonitor`] differentiates a 12-joint trajectory sample by sample,
//! `|q_k − q_{k−1}| / (t_k − t_{k−1})` dated at the interval's midpoint, and keeps each joint's
//! peak in O(1) memory; [`check`] compares the worst one with the servo speed limit.

use crate::error::GaitError;
use crate::maths::fastmath::sin_cos_real;
use crate::maths::real::Real;
use crate::robot::{mirrored_limit, Robot, Side, JOINTS_PER_LEG, JOINT_NAMES, LEG_JOINTS};

/// A position (m) and ZYX orientation (rad): `R = Rz(yaw)·Ry(pitch)·Rx(roll)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose<R> {
    /// Position x (forward), m.
    pub x: R,
    /// Position y (left), m.
    pub y: R,
    /// Position z (up), m.
    pub z: R,
    /// Roll about x, rad (applied first).
    pub roll: R,
    /// Pitch about y, rad.
    pub pitch: R,
    /// Yaw about z, rad (applied last).
    pub yaw: R,
}

/// The six joint angles of one leg in joint order (hip_yaw … ankle_roll), rad.
pub type LegAngles<R> = [R; JOINTS_PER_LEG];

/// A 3-vector.
type V3<R> = [R; 3];
/// A rotation matrix stored as its three columns (the frame's x, y, z axes).
type Cols<R> = [V3<R>; 3];

impl<R: Real> Pose<R> {
    /// A pose from position and ZYX angles.
    pub fn new(x: R, y: R, z: R, roll: R, pitch: R, yaw: R) -> Self {
        Pose {
            x,
            y,
            z,
            roll,
            pitch,
            yaw,
        }
    }

    /// A level pose (roll = pitch = 0) with the given heading.
    pub fn level(x: R, y: R, z: R, yaw: R) -> Self {
        Pose {
            x,
            y,
            z,
            roll: R::zero(),
            pitch: R::zero(),
            yaw,
        }
    }

    /// The position (x, y, z).
    pub fn position(&self) -> [R; 3] {
        [self.x, self.y, self.z]
    }

    /// True when all six numbers are finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite()
            && self.y.is_finite()
            && self.z.is_finite()
            && self.roll.is_finite()
            && self.pitch.is_finite()
            && self.yaw.is_finite()
    }

    /// The rotation matrix, row-major (`m[i][j]` = row i, column j).
    pub fn rotation(&self) -> [[R; 3]; 3] {
        let c = rot_cols(self);
        [
            [c[0][0], c[1][0], c[2][0]],
            [c[0][1], c[1][1], c[2][1]],
            [c[0][2], c[1][2], c[2][2]],
        ]
    }

    /// The pose with position `p` and rotation columns `c` (ZYX angles extracted).
    fn from_cols(p: V3<R>, c: &Cols<R>) -> Self {
        // Row-major m[i][j] = c[j][i]: pitch = atan2(−m20, √(m00² + m10²)),
        // yaw = atan2(m10, m00), roll = atan2(m21, m22).
        let (m00, m10, m20) = (c[0][0], c[0][1], c[0][2]);
        let (m21, m22) = (c[1][2], c[2][2]);
        Pose {
            x: p[0],
            y: p[1],
            z: p[2],
            roll: m21.atan2(m22),
            pitch: (-m20).atan2((m00 * m00 + m10 * m10).sqrt()),
            yaw: m10.atan2(m00),
        }
    }
}

/// World positions of one leg's joints, sole point and link mass points, m.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LegPoints<R> {
    /// Hip joint centre.
    pub hip: [R; 3],
    /// Knee joint centre.
    pub knee: [R; 3],
    /// Ankle joint centre.
    pub ankle: [R; 3],
    /// Sole point: the ankle's projection on the bottom of the sole.
    pub sole: [R; 3],
    /// Thigh mass point (`masses.thigh_com` of the way from the hip to the knee).
    pub thigh_mass: [R; 3],
    /// Calf mass point (`masses.calf_com` of the way from the knee to the ankle).
    pub calf_mass: [R; 3],
    /// Sole mass point (`masses.sole_height` above the sole point, `masses.sole_com` from it).
    pub sole_mass: [R; 3],
}

/// The result of one leg's inverse kinematics.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IkSolution<R> {
    /// Joint angles in joint order, rad, always finite and within the joint limits.
    pub q: LegAngles<R>,
    /// How far (m) the hip–ankle distance was outside the leg's reach; 0 when reachable.
    pub reach_deficit: R,
    /// Bit j set when joint j was clamped to its limit.
    pub limited: u8,
    /// True when an input was NaN, infinite or absurdly large and was replaced.
    pub invalid_input: bool,
}

impl<R: Real> IkSolution<R> {
    /// True when the target was not met exactly (out of reach, a joint limited, bad input).
    pub fn clamped(&self) -> bool {
        self.limited != 0 || self.reach_deficit > R::zero() || self.invalid_input
    }
}

/// Report of a two-leg inverse kinematics ([`legs_ik`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LegsIkReport<R> {
    /// Reach deficit of the left and right leg, m.
    pub reach_deficit: [R; 2],
    /// Bit i set when joint i of the 12 (left leg 0..6, right leg 6..12) was clamped.
    pub limited: u16,
    /// True when an input was NaN, infinite or absurdly large.
    pub invalid_input: bool,
}

impl<R: Real> LegsIkReport<R> {
    /// True when either leg's target was not met exactly.
    pub fn clamped(&self) -> bool {
        self.limited != 0
            || self.reach_deficit[0] > R::zero()
            || self.reach_deficit[1] > R::zero()
            || self.invalid_input
    }
}

/// Smallest knee bend the IK ever returns, rad: keeps the leg off the straight-knee singularity.
pub const KNEE_MIN_BEND: f64 = 0.02;
/// Bound on input positions, m; larger magnitudes are clamped and flagged as invalid.
pub const MAX_POSITION: f64 = 1000.0;

/// The robot's leg description converted to `R` once, for repeated kinematics calls.
#[derive(Clone, Copy, Debug)]
pub struct LegKinematics<R> {
    hip_offset_y: R,
    thigh: R,
    calf: R,
    ankle_height: R,
    /// The sole point's (forward, outward) offset from the ankle's ground projection.
    sole_offset: [R; 2],
    sole_mass_height: R,
    /// `masses.thigh_com` − ½ and `masses.calf_com` − ½: the mass points from the links'
    /// middles, in link lengths (exactly 0 for a link's middle).
    mass_shift: [R; 2],
    /// `masses.sole_com`: the sole mass from the sole point, (forward, outward), m.
    sole_mass_offset: [R; 2],
    d_min: R,
    d_max: R,
    /// [min, max] per joint of the left leg (the right's from them, [`mirrored_limit`]).
    limits: [[R; 2]; JOINTS_PER_LEG],
}

/// `a·b` for 3-vectors.
#[inline(always)]
fn dot<R: Real>(a: &V3<R>, b: &V3<R>) -> R {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a + k·b`.
#[inline(always)]
fn axpy<R: Real>(a: &V3<R>, k: R, b: &V3<R>) -> V3<R> {
    [a[0] + k * b[0], a[1] + k * b[1], a[2] + k * b[2]]
}

/// Midpoint of a and b.
#[inline(always)]
fn mid<R: Real>(a: &V3<R>, b: &V3<R>) -> V3<R> {
    let h = R::of(0.5);
    [(a[0] + b[0]) * h, (a[1] + b[1]) * h, (a[2] + b[2]) * h]
}

/// `c0·u + s0·v` (a column combination).
#[inline(always)]
fn comb<R: Real>(cu: R, u: &V3<R>, cv: R, v: &V3<R>) -> V3<R> {
    [
        cu * u[0] + cv * v[0],
        cu * u[1] + cv * v[1],
        cu * u[2] + cv * v[2],
    ]
}

/// Columns of `R · Rz(a)` given (sin a, cos a).
#[inline(always)]
fn post_rz<R: Real>(m: &Cols<R>, (s, c): (R, R)) -> Cols<R> {
    [comb(c, &m[0], s, &m[1]), comb(-s, &m[0], c, &m[1]), m[2]]
}

/// Columns of `R · Ry(a)` given (sin a, cos a).
#[inline(always)]
fn post_ry<R: Real>(m: &Cols<R>, (s, c): (R, R)) -> Cols<R> {
    [comb(c, &m[0], -s, &m[2]), m[1], comb(s, &m[0], c, &m[2])]
}

/// Columns of `R · Rx(a)` given (sin a, cos a).
#[inline(always)]
fn post_rx<R: Real>(m: &Cols<R>, (s, c): (R, R)) -> Cols<R> {
    [m[0], comb(c, &m[1], s, &m[2]), comb(-s, &m[1], c, &m[2])]
}

/// Columns of `Rz(yaw)·Ry(pitch)·Rx(roll)`.
fn rot_cols<R: Real>(p: &Pose<R>) -> Cols<R> {
    let (sr, cr) = sin_cos_real(p.roll);
    let (sp, cp) = sin_cos_real(p.pitch);
    let (sy, cy) = sin_cos_real(p.yaw);
    [
        [cy * cp, sy * cp, -sp],
        [cy * sp * sr - sy * cr, sy * sp * sr + cy * cr, cp * sr],
        [cy * sp * cr + sy * sr, sy * sp * cr - cy * sr, cp * cr],
    ]
}

/// A pose with every number finite and positions within ±[`MAX_POSITION`]; true if changed.
fn sanitize<R: Real>(p: &Pose<R>) -> (Pose<R>, bool) {
    let lim = R::of(MAX_POSITION);
    let mut bad = false;
    let mut pos = |v: R| {
        if v.is_finite() && v.abs() <= lim {
            v
        } else {
            bad = true;
            // NaN → 0, ±inf and huge values → ±lim.
            if v > lim {
                lim
            } else if v < -lim {
                -lim
            } else {
                R::zero()
            }
        }
    };
    let (x, y, z) = (pos(p.x), pos(p.y), pos(p.z));
    let mut ang = |v: R| {
        if v.is_finite() {
            v
        } else {
            bad = true;
            R::zero()
        }
    };
    let (roll, pitch, yaw) = (ang(p.roll), ang(p.pitch), ang(p.yaw));
    (
        Pose {
            x,
            y,
            z,
            roll,
            pitch,
            yaw,
        },
        bad,
    )
}

/// `v` clamped to `[lim[0], lim[1]]` (NaN → the value nearest 0 in the range); sets `bit` in
/// `flags` when changed.
#[inline(always)]
fn limit<R: Real>(v: R, lim: &[R; 2], bit: u8, flags: &mut u8) -> R {
    if v >= lim[0] && v <= lim[1] {
        v
    } else {
        *flags |= bit;
        if v.is_finite() {
            v.clamp_to(lim[0], lim[1])
        } else {
            R::zero().clamp_to(lim[0], lim[1])
        }
    }
}

impl<R: Real> LegKinematics<R> {
    /// Converts the robot's geometry and joint limits to `R`.
    pub fn new(robot: &Robot) -> Self {
        let g = &robot.geometry;
        let (l1, l2) = (g.thigh, g.calf);
        let lim = |side: Side| -> [[R; 2]; JOINTS_PER_LEG] {
            core::array::from_fn(|j| {
                let l = robot.joint_limit(side, j);
                [R::of(l.min), R::of(l.max)]
            })
        };
        let knee = robot.joint_limit(Side::Left, 3);
        let reach = |q: f64| -> f64 {
            let (_, c) = sin_cos_real(R::of(q));
            let d2 = l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * c.to_f64();
            if d2 > 0.0 {
                R::of(d2).sqrt().to_f64()
            } else {
                0.0
            }
        };
        let d_max = reach(knee.min.max(KNEE_MIN_BEND));
        let d_min = reach(knee.max.min(core::f64::consts::PI)).max((l1 - l2).abs());
        LegKinematics {
            hip_offset_y: R::of(g.hip_offset_y),
            thigh: R::of(l1),
            calf: R::of(l2),
            ankle_height: R::of(g.ankle_height),
            sole_offset: [R::of(g.sole_offset[0]), R::of(g.sole_offset[1])],
            sole_mass_height: R::of(robot.masses.sole_height),
            mass_shift: [
                R::of(robot.masses.thigh_com - 0.5),
                R::of(robot.masses.calf_com - 0.5),
            ],
            sole_mass_offset: [
                R::of(robot.masses.sole_com[0]),
                R::of(robot.masses.sole_com[1]),
            ],
            d_min: R::of(d_min),
            d_max: R::of(d_max),
            limits: lim(Side::Left),
        }
    }

    /// Shortest hip–ankle distance the IK reaches (knee at its upper limit), m.
    pub fn min_reach(&self) -> R {
        self.d_min
    }

    /// Longest hip–ankle distance the IK reaches (knee bent [`KNEE_MIN_BEND`]), m.
    pub fn max_reach(&self) -> R {
        self.d_max
    }

    /// The [min, max] limits of the leg's six joints, rad.
    pub fn limits(&self, side: Side) -> [[R; 2]; JOINTS_PER_LEG] {
        let mut l = self.limits;
        if side == Side::Right {
            for (j, [min, max]) in l.iter_mut().enumerate() {
                if mirrored_limit(j) {
                    (*min, *max) = (-*max, -*min);
                }
            }
        }
        l
    }

    /// Hip position and the leg's frames: (hip, knee, ankle, sole, foot rotation columns).
    fn chain(&self, side: Side, pelvis: &Pose<R>, q: &LegAngles<R>) -> ([V3<R>; 4], Cols<R>) {
        let (points, rf, _) = self.chain_axes(side, pelvis, q);
        (points, rf)
    }

    /// [`Self::chain`] and the six joint axes in the world frame (joint order): hip yaw = the
    /// pelvis z, hip roll = x after the yaw, hip pitch = y after the roll (the knee and ankle
    /// pitch axes are parallel to it), ankle roll = x after the ankle pitch.
    #[inline(always)]
    fn chain_axes(
        &self,
        side: Side,
        pelvis: &Pose<R>,
        q: &LegAngles<R>,
    ) -> ([V3<R>; 4], Cols<R>, [V3<R>; JOINTS_PER_LEG]) {
        self.chain_axes_in(side, pelvis, &rot_cols(pelvis), q)
    }

    /// [`Self::chain_axes`] with the pelvis rotation's columns `rp` given (both legs share it).
    /// Forced inline only on the FPU targets (it is on the control tick's path); elsewhere one
    /// copy serves every caller (inlined at every call it would not fit the OpenCM's flash).
    #[cfg_attr(target_abi = "eabihf", inline(always))]
    fn chain_axes_in(
        &self,
        side: Side,
        pelvis: &Pose<R>,
        rp: &Cols<R>,
        q: &LegAngles<R>,
    ) -> ([V3<R>; 4], Cols<R>, [V3<R>; JOINTS_PER_LEG]) {
        let sigma = R::of(side.sign());
        let hip = axpy(&pelvis.position(), sigma * self.hip_offset_y, &rp[1]);
        let r_yaw = post_rz(rp, sin_cos_real(q[0]));
        let r_roll = post_rx(&r_yaw, sin_cos_real(q[1]));
        let rt = post_ry(&r_roll, sin_cos_real(q[2]));
        let knee = axpy(&hip, -self.thigh, &rt[2]);
        let rc = post_ry(&rt, sin_cos_real(q[3]));
        let ankle = axpy(&knee, -self.calf, &rc[2]);
        let r_pitch = post_ry(&rc, sin_cos_real(q[4]));
        let rf = post_rx(&r_pitch, sin_cos_real(q[5]));
        let below = axpy(&ankle, -self.ankle_height, &rf[2]);
        let ahead = axpy(&below, self.sole_offset[0], &rf[0]);
        let sole = axpy(&ahead, sigma * self.sole_offset[1], &rf[1]);
        let axes = [rp[2], r_yaw[0], r_roll[1], rt[1], rc[1], r_pitch[0]];
        ([hip, knee, ankle, sole], rf, axes)
    }

    /// World positions of the joints and mass points of a leg, and its joint axes (unit vectors,
    /// world frame, joint order; the three hip axes pass through the hip centre, the two ankle
    /// axes through the ankle centre).
    pub fn joint_axes(
        &self,
        side: Side,
        pelvis: &Pose<R>,
        q: &LegAngles<R>,
    ) -> (LegPoints<R>, [[R; 3]; JOINTS_PER_LEG]) {
        self.points_axes(side, self.chain_axes(side, pelvis, q))
    }

    /// [`Self::joint_axes`] of both legs (left, right) for the 12 joint angles `q` (joint
    /// order), the pelvis rotation evaluated once.
    pub fn legs_joint_axes(
        &self,
        pelvis: &Pose<R>,
        q: &[R; LEG_JOINTS],
    ) -> [(LegPoints<R>, [[R; 3]; JOINTS_PER_LEG]); 2] {
        let rp = rot_cols(pelvis);
        let leg = |i: usize| -> LegAngles<R> {
            core::array::from_fn(|j| q.get(i * JOINTS_PER_LEG + j).copied().unwrap_or(R::zero()))
        };
        [
            self.points_axes(
                Side::Left,
                self.chain_axes_in(Side::Left, pelvis, &rp, &leg(0)),
            ),
            self.points_axes(
                Side::Right,
                self.chain_axes_in(Side::Right, pelvis, &rp, &leg(1)),
            ),
        ]
    }

    /// The points and axes of a leg from its chain.
    #[cfg_attr(target_abi = "eabihf", inline(always))]
    fn points_axes(
        &self,
        side: Side,
        ([hip, knee, ankle, sole], rf, axes): ([V3<R>; 4], Cols<R>, [V3<R>; JOINTS_PER_LEG]),
    ) -> (LegPoints<R>, [[R; 3]; JOINTS_PER_LEG]) {
        // Each link's mass point: its middle plus (share − ½) of the link; the sole's is
        // `sole_height` up the foot's z and `sole_com` along its x and outward y. Zero shifts
        // add exact zeros: a robot with its masses in the middles gets the middles bit for bit.
        let [s_thigh, s_calf] = self.mass_shift;
        let along = |a: &V3<R>, b: &V3<R>, s: R| {
            let m = mid(a, b);
            [
                m[0] + (b[0] - a[0]) * s,
                m[1] + (b[1] - a[1]) * s,
                m[2] + (b[2] - a[2]) * s,
            ]
        };
        let [fwd, out] = self.sole_mass_offset;
        let out = match side {
            Side::Left => out,
            Side::Right => -out,
        };
        let up = axpy(&sole, self.sole_mass_height, &rf[2]);
        let points = LegPoints {
            hip,
            knee,
            ankle,
            sole,
            thigh_mass: along(&hip, &knee, s_thigh),
            calf_mass: along(&knee, &ankle, s_calf),
            sole_mass: axpy(&axpy(&up, fwd, &rf[0]), out, &rf[1]),
        };
        (points, axes)
    }

    /// Forward kinematics: the foot (sole point) pose in the world frame.
    pub fn fk(&self, side: Side, pelvis: &Pose<R>, q: &LegAngles<R>) -> Pose<R> {
        let ([_, _, _, sole], rf) = self.chain(side, pelvis, q);
        Pose::from_cols(sole, &rf)
    }

    /// Forward kinematics: the sole point S and the foot frame's rotation as its three columns
    /// (the foot's x, y and z axes in the world frame) — [`Self::fk`] without the ZYX angles.
    pub fn sole_frame(
        &self,
        side: Side,
        pelvis: &Pose<R>,
        q: &LegAngles<R>,
    ) -> ([R; 3], [[R; 3]; 3]) {
        let ([_, _, _, sole], rf) = self.chain(side, pelvis, q);
        (sole, rf)
    }

    /// Forward kinematics: world positions of the joints, sole point and mass points.
    pub fn points(&self, side: Side, pelvis: &Pose<R>, q: &LegAngles<R>) -> LegPoints<R> {
        self.joint_axes(side, pelvis, q).0
    }

    /// Closed-form inverse kinematics of one leg (see the module documentation).
    pub fn ik(&self, side: Side, pelvis: &Pose<R>, foot: &Pose<R>) -> IkSolution<R> {
        let (pelvis, bad_p) = sanitize(pelvis);
        let (foot, bad_f) = sanitize(foot);
        self.ik_frames(side, &pelvis, &rot_cols(&pelvis), &foot, bad_p || bad_f)
    }

    /// Inverse kinematics of both legs: angles left leg then right leg, and the report.
    pub fn legs_ik(
        &self,
        pelvis: &Pose<R>,
        left_foot: &Pose<R>,
        right_foot: &Pose<R>,
    ) -> ([R; LEG_JOINTS], LegsIkReport<R>) {
        let (pelvis, bad_p) = sanitize(pelvis);
        let rp = rot_cols(&pelvis);
        let (lf, bad_l) = sanitize(left_foot);
        let (rf, bad_r) = sanitize(right_foot);
        let l = self.ik_frames(Side::Left, &pelvis, &rp, &lf, bad_p || bad_l);
        let r = self.ik_frames(Side::Right, &pelvis, &rp, &rf, bad_p || bad_r);
        let [a0, a1, a2, a3, a4, a5] = l.q;
        let [b0, b1, b2, b3, b4, b5] = r.q;
        let report = LegsIkReport {
            reach_deficit: [l.reach_deficit, r.reach_deficit],
            limited: u16::from(l.limited) | (u16::from(r.limited) << JOINTS_PER_LEG),
            invalid_input: l.invalid_input || r.invalid_input,
        };
        ([a0, a1, a2, a3, a4, a5, b0, b1, b2, b3, b4, b5], report)
    }

    /// The IK proper, on sanitized inputs with the pelvis rotation already computed.
    fn ik_frames(
        &self,
        side: Side,
        pelvis: &Pose<R>,
        rp: &Cols<R>,
        foot: &Pose<R>,
        invalid_input: bool,
    ) -> IkSolution<R> {
        let zero = R::zero();
        let lims = self.limits(side);
        let (l1, l2) = (self.thigh, self.calf);
        let rf = rot_cols(foot);

        // Hip and ankle, and the hip seen from the ankle in the foot frame.
        let hip = axpy(
            &pelvis.position(),
            R::of(side.sign()) * self.hip_offset_y,
            &rp[1],
        );
        let sigma = R::of(side.sign());
        let above = axpy(&foot.position(), self.ankle_height, &rf[2]);
        let behind = axpy(&above, -self.sole_offset[0], &rf[0]);
        let ankle = axpy(&behind, -(sigma * self.sole_offset[1]), &rf[1]);
        let d = [hip[0] - ankle[0], hip[1] - ankle[1], hip[2] - ankle[2]];
        let mut r = [dot(&rf[0], &d), dot(&rf[1], &d), dot(&rf[2], &d)];

        // 1. Reach.
        let dist = dot(&r, &r).sqrt();
        let mut deficit = zero;
        let mut dd = dist;
        if dist > self.d_max {
            deficit = dist - self.d_max;
            dd = self.d_max;
            let k = self.d_max / dist;
            r = [r[0] * k, r[1] * k, r[2] * k];
        } else if dist < self.d_min || !dist.is_finite() {
            deficit = self.d_min - dist;
            dd = self.d_min;
            if dist > R::of(1e-9) {
                let k = self.d_min / dist;
                r = [r[0] * k, r[1] * k, r[2] * k];
            } else {
                r = [zero, zero, self.d_min];
            }
        }
        if !deficit.is_finite() {
            deficit = R::of(MAX_POSITION);
        }

        // 2. Knee, half-angle form of the law of cosines.
        let sum = l1 + l2;
        let diff = (l1 - l2).abs();
        let a = ((sum - dd) * (sum + dd)).max(zero).sqrt();
        let b = ((dd - diff) * (dd + diff)).max(zero).sqrt();
        let q3 = R::of(2.0) * a.atan2(b);
        let four_l1l2 = R::of(4.0) * l1 * l2;
        let s3 = R::of(2.0) * a * b / four_l1l2;
        let c3 = (b * b - a * a) / four_l1l2;

        // 3. Ankle roll, 4. ankle pitch.
        let wz = (r[1] * r[1] + r[2] * r[2]).sqrt();
        let q5 = if wz > zero { r[1].atan2(r[2]) } else { zero };
        let q4 = -(l1 * s3).atan2(l2 + l1 * c3) - r[0].atan2(wz);

        let mut flags = 0u8;
        let [lim0, lim1, lim2, lim3, lim4, lim5] = &lims;
        let q3 = limit(q3, lim3, 1 << 3, &mut flags);
        let q4 = limit(q4, lim4, 1 << 4, &mut flags);
        let q5 = limit(q5, lim5, 1 << 5, &mut flags);

        // 5. Hip: M = R_Pᵀ · R_F · Rx(−q5) · Ry(−(q3 + q4)).
        let (s5, c5) = sin_cos_real(q5);
        let (s34, c34) = sin_cos_real(q3 + q4);
        let n = post_ry(&post_rx(&rf, (-s5, c5)), (-s34, c34));
        let m01 = dot(&rp[0], &n[1]);
        let m11 = dot(&rp[1], &n[1]);
        let m21 = dot(&rp[2], &n[1]);
        let m20 = dot(&rp[2], &n[0]);
        let m22 = dot(&rp[2], &n[2]);
        let q0 = (-m01).atan2(m11);
        let q1 = m21.atan2((m01 * m01 + m11 * m11).sqrt());
        let q2 = (-m20).atan2(m22);
        let q0 = limit(q0, lim0, 1 << 0, &mut flags);
        let q1 = limit(q1, lim1, 1 << 1, &mut flags);
        let q2 = limit(q2, lim2, 1 << 2, &mut flags);

        IkSolution {
            q: [q0, q1, q2, q3, q4, q5],
            reach_deficit: deficit,
            limited: flags,
            invalid_input,
        }
    }
}

/// Forward kinematics: the foot (sole point) pose in the world frame for joint angles `q`.
pub fn leg_fk<R: Real>(robot: &Robot, side: Side, pelvis: &Pose<R>, q: &LegAngles<R>) -> Pose<R> {
    LegKinematics::new(robot).fk(side, pelvis, q)
}

/// Forward kinematics: world positions of the leg's joints, sole point and mass points.
pub fn leg_points<R: Real>(
    robot: &Robot,
    side: Side,
    pelvis: &Pose<R>,
    q: &LegAngles<R>,
) -> LegPoints<R> {
    LegKinematics::new(robot).points(side, pelvis, q)
}

/// Closed-form inverse kinematics of one leg: joint angles putting the foot at `foot`.
pub fn leg_ik<R: Real>(
    robot: &Robot,
    side: Side,
    pelvis: &Pose<R>,
    foot: &Pose<R>,
) -> IkSolution<R> {
    LegKinematics::new(robot).ik(side, pelvis, foot)
}

/// Inverse kinematics of both legs: 12 angles (left leg then right leg) and the report.
pub fn legs_ik<R: Real>(
    robot: &Robot,
    pelvis: &Pose<R>,
    left_foot: &Pose<R>,
    right_foot: &Pose<R>,
) -> ([R; LEG_JOINTS], LegsIkReport<R>) {
    LegKinematics::new(robot).legs_ik(pelvis, left_foot, right_foot)
}

/// Peak joint speeds of a 12-joint trajectory (left leg then right leg).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointSpeedReport {
    /// Peak |dq/dt| of each joint, rad/s (infinite if the joint was ever non-finite).
    pub peak_speed: [f64; LEG_JOINTS],
    /// Time of each joint's peak, s (midpoint of the sample interval).
    pub peak_time: [f64; LEG_JOINTS],
    /// Index (0..12) of the joint with the highest peak speed.
    pub worst_joint: usize,
    /// Time of the worst joint's peak, s.
    pub worst_time: f64,
    /// The highest peak speed, rad/s.
    pub worst_speed: f64,
    /// The servo speed limit, rad/s.
    pub limit: f64,
}

impl JointSpeedReport {
    /// Name of the worst joint (`l_hip_yaw` … `r_ankle_roll`).
    pub fn worst_joint_name(&self) -> &'static str {
        JOINT_NAMES.get(self.worst_joint).copied().unwrap_or("?")
    }
}

/// Why a trajectory cannot be followed: a joint faster than the servo.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Infeasible {
    /// Index (0..12) of the offending joint.
    pub joint: usize,
    /// Time of its peak speed, s.
    pub time: f64,
    /// Its peak speed, rad/s.
    pub speed: f64,
    /// The servo speed limit, rad/s.
    pub limit: f64,
}

impl Infeasible {
    /// Name of the offending joint (`l_hip_yaw` … `r_ankle_roll`).
    pub fn joint_name(&self) -> &'static str {
        JOINT_NAMES.get(self.joint).copied().unwrap_or("?")
    }
}

impl core::fmt::Display for Infeasible {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "joint {} reaches {:.3} rad/s at t = {:.4} s, above the servo limit {:.3} rad/s",
            self.joint_name(),
            self.speed,
            self.time,
            self.limit
        )
    }
}

/// Accepts the trajectory when no joint is faster than the limit, else names the worst joint.
pub fn check(report: &JointSpeedReport) -> Result<(), Infeasible> {
    if report.worst_speed <= report.limit {
        Ok(())
    } else {
        Err(Infeasible {
            joint: report.worst_joint,
            time: report.worst_time,
            speed: report.worst_speed,
            limit: report.limit,
        })
    }
}

/// Incremental joint-speed monitor (O(1) memory): push samples, then read the report.
#[derive(Clone, Copy, Debug)]
pub struct JointSpeedMonitor {
    dt: f64,
    limit: f64,
    prev_t: Option<f64>,
    prev_q: [Option<f64>; LEG_JOINTS],
    peak_speed: [f64; LEG_JOINTS],
    peak_time: [f64; LEG_JOINTS],
}

impl JointSpeedMonitor {
    /// A monitor for samples `dt` apart (used when timestamps do not increase), limit from `robot`.
    pub fn new(robot: &Robot, dt: f64) -> Result<Self, GaitError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(GaitError::NonPositiveParameter);
        }
        let limit = robot.servo.max_speed;
        if !(limit.is_finite() && limit > 0.0) {
            return Err(GaitError::NonPositiveParameter);
        }
        Ok(JointSpeedMonitor {
            dt,
            limit,
            prev_t: None,
            prev_q: [None; LEG_JOINTS],
            peak_speed: [0.0; LEG_JOINTS],
            peak_time: [0.0; LEG_JOINTS],
        })
    }

    /// Adds the sample `q` (12 angles, left leg then right leg) at time `t`, s.
    pub fn push<R: Real>(&mut self, t: f64, q: &[R; LEG_JOINTS]) {
        let t = match (t.is_finite(), self.prev_t) {
            (true, _) => t,
            (false, Some(p)) => p + self.dt,
            (false, None) => 0.0,
        };
        let step = match self.prev_t {
            Some(p) if t - p > 0.0 => t - p,
            _ => self.dt,
        };
        let t_mid = t - 0.5 * step;
        let joints = q.iter().zip(self.prev_q.iter_mut());
        let peaks = self.peak_speed.iter_mut().zip(self.peak_time.iter_mut());
        for ((qj, prev), (peak, peak_t)) in joints.zip(peaks) {
            let v = qj.to_f64();
            if !v.is_finite() {
                if *peak != f64::INFINITY {
                    *peak = f64::INFINITY;
                    *peak_t = t;
                }
                *prev = None;
                continue;
            }
            if let Some(p) = *prev {
                let speed = (v - p).abs() / step;
                if speed > *peak {
                    *peak = speed;
                    *peak_t = t_mid;
                }
            }
            *prev = Some(v);
        }
        self.prev_t = Some(t);
    }

    /// The peaks so far.
    pub fn report(&self) -> JointSpeedReport {
        let mut worst = 0usize;
        let mut worst_speed = f64::NEG_INFINITY;
        let mut worst_time = 0.0;
        for (j, (s, t)) in self
            .peak_speed
            .iter()
            .zip(self.peak_time.iter())
            .enumerate()
        {
            if *s > worst_speed {
                worst = j;
                worst_speed = *s;
                worst_time = *t;
            }
        }
        JointSpeedReport {
            peak_speed: self.peak_speed,
            peak_time: self.peak_time,
            worst_joint: worst,
            worst_time,
            worst_speed: worst_speed.max(0.0),
            limit: self.limit,
        }
    }
}
