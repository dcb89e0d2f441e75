//! The simulated robot in full dynamics: MuJoCo 3.17 (through `mujoco-rs`) steps the model of
//! [`super::mjcf`], driven by twelve X-series servo models ([`super::dynamixel`]).
//!
//! # One physics step (`dt` = [`super::SimConfig::physics_dt_us`])
//!
//! 1. `mj_step1`: kinematics, contacts, velocity-dependent terms at time t.
//! 2. Each servo's controller reads its joint (encoder ticks, speed) and its registers and
//!    gives the motor torque, written as the joint's `motor` control; external forces (pushes,
//!    the seed's upper-body pitch torque, a forced fall) are written to the torso's
//!    `xfrc_applied`.
//! 3. `mj_step2`: contact forces, accelerations, sensors at time t, then integration to t + dt.
//! 4. The ground truth of time t is read off the data ([`TruthSample`]).
//!
//! # What the truth and the sensors are
//!
//! * Each sole's contact wrench is the sum of the contact forces between its sole box and the
//!   floor (or a floor tile), `F = Σ f_c`, `M = Σ (p_c − s) × f_c + τ_c` about the sole point s
//!   (τ_c: torsional friction about the normal). The true centre of pressure is the
//!   vertical-force-weighted mean of all sole contact points, `cop = Σ f_z,c·p_c / Σ f_z,c`.
//! * The foot boards' 4 load cells sit between foot and sole plate in the sole's plane at
//!   (±a, ±b); in the sole frame they carry `Σ Fᵢ = F_z`, `Σ Fᵢ·xᵢ = −M_y`, `Σ Fᵢ·yᵢ = M_x`,
//!   solved with the least-norm split `Fᵢ = F_z/4 − xᵢ·M_y/(4a²) + yᵢ·M_x/(4b²)` (a cell reads
//!   tension as well as compression). Their centre of pressure is the sole's true one.
//! * The IMU's gyro and accelerometer are MuJoCo's `gyro` and `accelerometer` sensors at the site
//!   `imu` (the pelvis point P, torso frame): rate in rad/s, specific force in m/s² (+g on z when
//!   upright).
//! * Falls are what the physics does: the truth marks a fall when the torso tilts beyond
//!   [`super::FallConfig::max_tilt_rad`], P drops below 60 % of its standing height, or any robot
//!   geom other than a sole touches the floor; the robot lies when P is below 35 % of its
//!   standing height. A forced fall ([`super::FallConfig::forced_at_s`]) is fault injection: a
//!   20 N horizontal shove on the torso for 0.5 s in the configured direction.
//!
//! # Start
//!
//! The robot stands at [`super::SimConfig::initial_q`] with both soles on the floor, held by
//! the weld `hold` (a person holding it) until all 12 servos have torque on (or from the start
//! with [`super::SimConfig::hold_until_torque`] off): a robot whose servos are off collapses.

use gait_core::measure::support::SupportPolygon;
use gait_core::trajectory::plan::Place;
use gait_core::Robot;
use mujoco_rs::prelude::*;
use mujoco_rs::wrappers::mj_model::MjtObjBase;

use super::body::{Support, TruthSample};
use super::dynamixel::{XServo, XServoOutput, XServoParams, XServoRegisters};
use super::mjcf::{model_xml, standing_height};
use super::rng::Rng;
use super::{SimConfig, SimError};

type V3 = [f64; 3];

/// Indices of the model's parts.
#[derive(Clone, Copy, Debug)]
struct Ids {
    torso: usize,
    soles: [usize; 2],
    sole_sites: [usize; 2],
    hold: usize,
    /// qpos index of the first hinge, qvel index of the first hinge.
    qpos0: usize,
    qvel0: usize,
    gyro: usize,
    accel: usize,
}

/// A push on the torso: an impulse spread evenly over a short time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Push {
    /// Start, s.
    pub at_s: f64,
    /// Impulse, N·s.
    pub impulse_ns: f64,
    /// Direction in the ground plane, rad (0 = +x forward, π/2 = +y left).
    pub direction_rad: f64,
    /// Duration over which the impulse is spread, s.
    pub duration_s: f64,
}

impl Push {
    /// Parses `T:IMPULSE:DIRECTION_DEG` (duration 10 ms), e.g. `3.2:1.5:0` (1.5 N·s forward at
    /// 3.2 s) or `4:1:90` (1 N·s to the left at 4 s).
    pub fn parse(s: &str) -> Result<Push, String> {
        let parts: Vec<&str> = s.split(':').collect();
        let bad = || format!("push `{s}`: expected T:IMPULSE_NS:DIRECTION_DEG, e.g. 3.2:1.5:0");
        if parts.len() != 3 {
            return Err(bad());
        }
        let n = |i: usize| -> Result<f64, String> {
            parts
                .get(i)
                .and_then(|p| p.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(bad)
        };
        let p = Push {
            at_s: n(0)?,
            impulse_ns: n(1)?,
            direction_rad: n(2)?.to_radians(),
            duration_s: 0.01,
        };
        if p.at_s < 0.0 || !(0.0..=50.0).contains(&p.impulse_ns) {
            return Err(format!(
                "push `{s}`: time must be ≥ 0 and impulse in [0, 50] N·s"
            ));
        }
        Ok(p)
    }
}

/// The MuJoCo robot.
pub struct MjBody {
    /// MuJoCo's model and state.
    data: MjData<Box<MjModel>>,
    /// Ids of the bodies, joints, sensors and geoms the body reads.
    ids: Ids,
    /// The robot the model was generated from.
    robot: Robot,
    /// The servo model's parameters.
    params: XServoParams,
    /// One position-mode servo model per joint.
    servos: [XServo; 12],
    /// Their last outputs (torque, PWM, current).
    outputs: [XServoOutput; 12],
    /// Joint angles at the truth's time, rad.
    q: [f64; 12],
    /// Joint speeds at the truth's time, rad/s.
    qd: [f64; 12],
    /// Physics time, µs (the truth describes `time_us − dt`).
    pub time_us: u64,
    dt_us: u64,
    truth: TruthSample,
    held: bool,
    standing_z: f64,
    cfg: SimConfig,
    dist_rng: Rng,
    tau: f64,
    fall_started_us: Option<u64>,
    fallen_at_us: Option<u64>,
    /// Largest distance of the true CoP outside the support polygon before any fall, m.
    pub max_outside: f64,
    total_mass: f64,
}

impl std::fmt::Debug for MjBody {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MjBody")
            .field("time_us", &self.time_us)
            .finish_non_exhaustive()
    }
}

fn id(model: &MjModel, kind: MjtObjBase, name: &str) -> Result<usize, SimError> {
    model
        .name_to_id(kind, name)
        .ok_or_else(|| SimError::Config(format!("MuJoCo model has no `{name}`")))
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `Rᵀ·v` for MuJoCo's row-major rotation matrix.
fn rot_t(m: &[f64; 9], v: V3) -> V3 {
    [
        m[0] * v[0] + m[3] * v[1] + m[6] * v[2],
        m[1] * v[0] + m[4] * v[1] + m[7] * v[2],
        m[2] * v[0] + m[5] * v[1] + m[8] * v[2],
    ]
}

/// ZYX roll, pitch, yaw of a row-major rotation matrix.
fn rpy(m: &[f64; 9]) -> V3 {
    [
        m[7].atan2(m[8]),
        (-m[6]).atan2((m[0] * m[0] + m[3] * m[3]).sqrt()),
        m[3].atan2(m[0]),
    ]
}

/// The least-norm split of a sole's vertical force and moments (sole frame, about the sole
/// point) over four load cells at `cells` (symmetric at (±a, ±b)).
pub fn load_cells(fz: f64, mx: f64, my: f64, cells: &[[f64; 2]; 4]) -> [f64; 4] {
    let a = cells.iter().map(|c| c[0].abs()).fold(0.0, f64::max);
    let b = cells.iter().map(|c| c[1].abs()).fold(0.0, f64::max);
    cells.map(|[x, y]| {
        let mut f = fz / 4.0;
        if a > 0.0 {
            f -= x * my / (4.0 * a * a);
        }
        if b > 0.0 {
            f += y * mx / (4.0 * b * b);
        }
        f
    })
}

impl MjBody {
    /// Builds the model of `cfg.robot` and the data at `cfg.initial_q`, held.
    pub fn new(cfg: &SimConfig) -> Result<Self, SimError> {
        let dt = cfg.physics_dt_us as f64 * 1e-6;
        let params = cfg.xservo;
        let mut q = cfg.initial_q;
        for (j, qj) in q.iter_mut().enumerate() {
            let side = if j < 6 {
                gait_core::Side::Left
            } else {
                gait_core::Side::Right
            };
            let l = cfg.robot.joint_limit(side, j % 6);
            *qj = qj.clamp(l.min, l.max);
        }
        let xml = model_xml(&cfg.robot, &params, &cfg.env, &q, dt, cfg.seed);
        if let Some(path) = &cfg.model_out {
            std::fs::write(path, &xml)?;
        }
        let model = MjModel::from_xml_string(&xml)
            .map_err(|e| SimError::Config(format!("MuJoCo rejected the model: {e:?}")))?;
        let ids = {
            let m = &model;
            let root = id(m, MjtObjBase::mjOBJ_JOINT, "root")?;
            let first = id(m, MjtObjBase::mjOBJ_JOINT, "l_hip_yaw")?;
            let sensor = |n: &str| -> Result<usize, SimError> {
                let s = id(m, MjtObjBase::mjOBJ_SENSOR, n)?;
                Ok(m.sensor_adr()[s] as usize)
            };
            let _ = root;
            Ids {
                torso: id(m, MjtObjBase::mjOBJ_BODY, "torso")?,
                soles: [
                    id(m, MjtObjBase::mjOBJ_GEOM, "l_sole")?,
                    id(m, MjtObjBase::mjOBJ_GEOM, "r_sole")?,
                ],
                sole_sites: [
                    id(m, MjtObjBase::mjOBJ_SITE, "l_sole")?,
                    id(m, MjtObjBase::mjOBJ_SITE, "r_sole")?,
                ],
                hold: id(m, MjtObjBase::mjOBJ_EQUALITY, "hold")?,
                qpos0: m.jnt_qposadr()[first] as usize,
                qvel0: m.jnt_dofadr()[first] as usize,
                gyro: sensor("imu_gyro")?,
                accel: sensor("imu_accel")?,
            }
        };
        let total_mass = model.totalmass();
        let mut data = MjData::new(Box::new(model));
        for (j, qj) in q.iter().enumerate() {
            data.qpos_mut()[ids.qpos0 + j] = *qj;
        }
        data.eq_active_mut()[ids.hold] = cfg.hold_until_torque;
        data.forward();
        let standing_z = standing_height(&cfg.robot, &q);
        let mut body = MjBody {
            data,
            ids,
            robot: cfg.robot,
            params,
            servos: [XServo::default(); 12],
            outputs: [XServoOutput::default(); 12],
            q,
            qd: [0.0; 12],
            time_us: 0,
            dt_us: cfg.physics_dt_us,
            truth: TruthSample::default(),
            held: cfg.hold_until_torque,
            standing_z,
            cfg: cfg.clone(),
            dist_rng: Rng::new(cfg.seed, 3),
            tau: 0.0,
            fall_started_us: None,
            fallen_at_us: None,
            max_outside: 0.0,
            total_mass,
        };
        body.truth = body.read_truth(0);
        Ok(body)
    }

    /// Joint angles, rad (left leg then right leg), at the truth's time.
    pub fn q(&self) -> &[f64; 12] {
        &self.q
    }

    /// Joint speeds, rad/s.
    pub fn qd(&self) -> &[f64; 12] {
        &self.qd
    }

    /// The servos' last outputs (torque, PWM, current), each in its servo's own direction (the
    /// joint's times its mounting sign).
    pub fn outputs(&self) -> &[XServoOutput; 12] {
        &self.outputs
    }

    /// The servo model.
    pub fn params(&self) -> &XServoParams {
        &self.params
    }

    /// Total mass of the model, kg.
    pub fn total_mass(&self) -> f64 {
        self.total_mass
    }

    /// The ground truth.
    pub fn truth(&self) -> &TruthSample {
        &self.truth
    }

    /// Whether the torso is still held (the servos have not all been switched on).
    pub fn held(&self) -> bool {
        self.held
    }

    /// When a fall started, µs.
    pub fn fall_started_us(&self) -> Option<u64> {
        self.fall_started_us
    }

    /// When the robot came to lie on the ground, µs.
    pub fn fallen_at_us(&self) -> Option<u64> {
        self.fallen_at_us
    }

    /// The whole state vector (qpos) for recording a video.
    pub fn qpos(&self) -> &[f64] {
        self.data.qpos()
    }

    /// Each sole's point (world, m) and rotation (row-major) as MuJoCo's kinematics place it.
    pub fn sole_sites(&self) -> [([f64; 3], [f64; 9]); 2] {
        let d = &self.data;
        self.ids
            .sole_sites
            .map(|s| (d.site_xpos()[s], d.site_xmat()[s]))
    }

    /// The torso's position (P, world, m) and rotation (row-major).
    pub fn torso(&self) -> ([f64; 3], [f64; 9]) {
        (
            self.data.xpos()[self.ids.torso],
            self.data.xmat()[self.ids.torso],
        )
    }

    /// Releases the hold now (tests of a standing robot whose servos are driven directly).
    pub fn release(&mut self) {
        self.held = false;
        self.data.eq_active_mut()[self.ids.hold] = false;
    }

    /// The horizontal force on the torso from pushes and a forced fall at time `t`, N.
    fn push_force(&self, t: f64) -> [f64; 2] {
        let mut f = [0.0; 2];
        for p in &self.cfg.pushes {
            if t >= p.at_s && t < p.at_s + p.duration_s {
                let mag = p.impulse_ns / p.duration_s;
                f[0] += mag * p.direction_rad.cos();
                f[1] += mag * p.direction_rad.sin();
            }
        }
        if let Some(at) = self.cfg.fall.forced_at_s {
            if t >= at && t < at + 0.5 {
                let a = self.cfg.fall.forced_direction;
                f[0] += 20.0 * a.cos();
                f[1] += 20.0 * a.sin();
            }
        }
        f
    }

    /// Advances one physics step with the servos' registers (`None`: a dead servo, limp).
    pub fn step(&mut self, regs: &[Option<XServoRegisters>; 12]) {
        let dt = self.dt_us as f64 * 1e-6;
        let t_us = self.time_us;
        let t = t_us as f64 * 1e-6;
        self.data.step1();
        let (p0, v0) = (self.ids.qpos0, self.ids.qvel0);
        let q: [f64; 12] = std::array::from_fn(|j| self.data.qpos()[p0 + j]);
        let qd: [f64; 12] = std::array::from_fn(|j| self.data.qvel()[v0 + j]);
        let mut all_on = true;
        for j in 0..12 {
            let r = regs[j].unwrap_or(XServoRegisters::defaults(0));
            all_on &= r.torque_on;
            let on = XServoRegisters {
                torque_on: r.torque_on && regs[j].is_some(),
                ..r
            };
            // The servo works in its own direction: the joint's times its mounting sign.
            let sign = f64::from(self.robot.mounting.get(j).copied().unwrap_or(1));
            self.outputs[j] =
                self.servos[j].update(&self.params, &on, sign * q[j], sign * qd[j], dt);
            self.data.ctrl_mut()[j] = sign * self.outputs[j].torque;
        }
        if self.held && all_on {
            self.release();
        }
        self.tau =
            self.cfg
                .disturbance
                .torque_at(self.time_us, self.dt_us, &mut self.dist_rng, self.tau);
        let push = self.push_force(t);
        let torso = self.ids.torso;
        let r = self.data.xmat()[torso];
        // The pitch torque acts about the torso's own y axis (second column of R).
        let tau = [r[1] * self.tau, r[4] * self.tau, r[7] * self.tau];
        self.data.xfrc_applied_mut()[torso] = [push[0], push[1], 0.0, tau[0], tau[1], tau[2]];
        self.data.step2();
        self.q = q;
        self.qd = qd;
        self.truth = self.read_truth(t_us);
        self.time_us = t_us + self.dt_us;
        self.update_falls(t_us);
    }

    fn update_falls(&mut self, t_us: u64) {
        let tr = self.truth;
        if self.fall_started_us.is_none() && tr.falling && !self.held {
            self.fall_started_us = Some(t_us);
        }
        if self.fall_started_us.is_none() && !self.held {
            let out = -tr.margin;
            if tr.margin.is_finite() && out > self.max_outside {
                self.max_outside = out;
            }
        }
        if self.fallen_at_us.is_none() && tr.pelvis[2] < 0.35 * self.standing_z {
            self.fallen_at_us = Some(t_us);
        }
    }

    fn read_truth(&self, t_us: u64) -> TruthSample {
        let d = &self.data;
        let ids = self.ids;
        let geom_body = d.model().geom_bodyid();
        let sole_of = |g: i32| ids.soles.iter().position(|&s| s as i32 == g);
        let is_robot = |g: i32| geom_body.get(g as usize).is_some_and(|&b| b != 0);
        let mut wrench = [[0.0f64; 6]; 2];
        let mut cop_num = [0.0f64; 2];
        let mut cop_den = 0.0;
        let mut other_contact = false;
        let sites = d.site_xpos();
        let site_m = d.site_xmat();
        for (i, c) in d.contact().iter().enumerate() {
            let (g1, g2) = (c.geom1, c.geom2);
            let (robot_geom, sign) = match (is_robot(g1), is_robot(g2)) {
                (true, false) => (g1, -1.0),
                (false, true) => (g2, 1.0),
                _ => continue,
            };
            let f6 = d.contact_force(i);
            let fr = &c.frame;
            // Force on geom2 from geom1 in world coordinates; flip it for geom1.
            let fw: V3 = std::array::from_fn(|k| {
                sign * (f6[0] * fr[k] + f6[1] * fr[3 + k] + f6[2] * fr[6 + k])
            });
            let tw: V3 = std::array::from_fn(|k| sign * f6[3] * fr[k]);
            let Some(s) = sole_of(robot_geom) else {
                if fw[2].abs() > 1e-6 || c.dist < 0.0 {
                    other_contact = true;
                }
                continue;
            };
            let sp = sites[ids.sole_sites[s]];
            let rel = [c.pos[0] - sp[0], c.pos[1] - sp[1], c.pos[2] - sp[2]];
            let m = cross(rel, fw);
            for k in 0..3 {
                wrench[s][k] += fw[k];
                wrench[s][3 + k] += m[k] + tw[k];
            }
            if fw[2] > 0.0 {
                cop_num[0] += fw[2] * c.pos[0];
                cop_num[1] += fw[2] * c.pos[1];
                cop_den += fw[2];
            }
        }
        let cells = self.robot.geometry.force_sensors;
        let mut forces = [[0.0; 4]; 2];
        let mut contact = [false; 2];
        let mut places = [Place::<f64>::new(0.0, 0.0, 0.0); 2];
        let mut sole_tilt = [[0.0; 2]; 2];
        let mut sole_z = [0.0; 2];
        for s in 0..2 {
            let m = &site_m[ids.sole_sites[s]];
            let f_local = rot_t(m, [wrench[s][0], wrench[s][1], wrench[s][2]]);
            let m_local = rot_t(m, [wrench[s][3], wrench[s][4], wrench[s][5]]);
            forces[s] = load_cells(f_local[2], m_local[0], m_local[1], &cells);
            contact[s] = wrench[s][2] > 1.0;
            let p = sites[ids.sole_sites[s]];
            let [roll, pitch, yaw] = rpy(m);
            places[s] = Place::new(p[0], p[1], yaw);
            sole_tilt[s] = [roll, pitch];
            sole_z[s] = p[2];
        }
        let poly = match contact {
            [true, true] => SupportPolygon::double(&places[0], &places[1], &self.robot).ok(),
            [true, false] => SupportPolygon::single(&places[0], &self.robot).ok(),
            [false, true] => SupportPolygon::single(&places[1], &self.robot).ok(),
            [false, false] => None,
        };
        let zmp = if cop_den > 1e-6 {
            [cop_num[0] / cop_den, cop_num[1] / cop_den]
        } else {
            self.truth.zmp
        };
        let margin = poly.as_ref().map_or(f64::NEG_INFINITY, |p| p.margin(zmp));
        let xm = d.xmat()[ids.torso];
        let tilt = xm[8].clamp(-1.0, 1.0).acos();
        let pelvis = d.xpos()[ids.torso];
        let sd = d.sensordata();
        let support = match contact {
            [true, true] => Support::Double,
            [false, true] => Support::Right,
            _ => Support::Left,
        };
        let falling = !self.held
            && (tilt > self.cfg.fall.max_tilt_rad
                || pelvis[2] < 0.6 * self.standing_z
                || other_contact);
        let mut limited = 0u16;
        let mut torque = [0.0; 12];
        for (j, o) in self.outputs.iter().enumerate() {
            let sign = f64::from(self.robot.mounting.get(j).copied().unwrap_or(1));
            torque[j] = sign * o.torque;
            if o.saturated {
                limited |= 1 << j;
            }
        }
        TruthSample {
            t_us,
            zmp,
            fz: cop_den,
            com: d.subtree_com()[ids.torso],
            pelvis,
            pelvis_rpy: rpy(&xm),
            support,
            stance_left: wrench[0][2] >= wrench[1][2],
            margin,
            forces,
            gyro: [sd[ids.gyro], sd[ids.gyro + 1], sd[ids.gyro + 2]],
            accel: [sd[ids.accel], sd[ids.accel + 1], sd[ids.accel + 2]],
            tau: self.tau,
            falling: falling || self.fall_started_us.is_some(),
            fall_angle: tilt,
            joint_speed: self.qd,
            joint_torque: torque,
            torque_limited: limited,
            sole_contact: contact,
            sole_wrench: wrench,
            other_contact,
            soles: places.map(|p| [p.x, p.y, p.yaw]),
            sole_tilt,
            sole_z,
            joint_position: self.q,
        }
    }
}
