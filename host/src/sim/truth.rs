//! Ground-truth CSV log.
//!
//! One row per `log_every_us` of physics time (the instant the values describe; accelerations
//! are those of the motion state at that instant). Columns:
//!
//! `t_s, zmp_x, zmp_y, fz_n, com_x, com_y, com_z, pelvis_x, pelvis_y, pelvis_z, pelvis_roll,
//! pelvis_pitch, pelvis_yaw, support (L/R/D), stance (L/R), margin_m, l_f0..l_f3, r_f0..r_f3
//! (N, noiseless, sensor order front-left, front-right, rear-left, rear-right), gyro_x..z
//! (rad/s), acc_x..z (m/s²), tau_nm, falling (0/1), fall_angle, qd_1..qd_12` (joint speeds,
//! rad/s, by servo ID), `tq_1..tq_12` (motor torques, N·m; NaN without the torque model or while
//! falling), `tq_limited` (bit `ID − 1` set: that motor is at its torque bound), `l_contact,
//! r_contact` (each sole touches the ground, 0/1), `l_fx … l_mz, r_fx … r_mz` (each sole's
//! contact wrench in the world frame about its sole point, N and N·m; 0 in the kinematic
//! model), `other_contact` (a robot part other than a sole touches the ground, 0/1). With the
//! MuJoCo robot `zmp_x, zmp_y` is the true centre of pressure of the contact forces and
//! `fz_n` their vertical sum.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::body::Truth;

/// Header line of the truth CSV (without newline).
pub const HEADER: &str = "t_s,zmp_x,zmp_y,fz_n,com_x,com_y,com_z,pelvis_x,pelvis_y,pelvis_z,\
pelvis_roll,pelvis_pitch,pelvis_yaw,support,stance,margin_m,l_f0,l_f1,l_f2,l_f3,r_f0,r_f1,r_f2,r_f3,\
gyro_x,gyro_y,gyro_z,acc_x,acc_y,acc_z,tau_nm,falling,fall_angle,\
qd_1,qd_2,qd_3,qd_4,qd_5,qd_6,qd_7,qd_8,qd_9,qd_10,qd_11,qd_12,\
tq_1,tq_2,tq_3,tq_4,tq_5,tq_6,tq_7,tq_8,tq_9,tq_10,tq_11,tq_12,tq_limited,\
l_contact,r_contact,l_fx,l_fy,l_fz,l_mx,l_my,l_mz,r_fx,r_fy,r_fz,r_mx,r_my,r_mz,other_contact";

/// Writer of the truth CSV.
#[derive(Debug)]
pub struct TruthLog {
    out: BufWriter<File>,
    rows: u64,
}

impl TruthLog {
    /// Creates the file and writes the header.
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let mut out = BufWriter::new(File::create(path)?);
        writeln!(out, "{HEADER}")?;
        Ok(TruthLog { out, rows: 0 })
    }

    /// Appends one row.
    pub fn row(&mut self, t: &Truth) -> std::io::Result<()> {
        let mut s = format!("{:.6}", t.t_us as f64 * 1e-6);
        let mut put = |v: f64| {
            s.push(',');
            s.push_str(&format!("{v:.6}"));
        };
        for v in [t.zmp[0], t.zmp[1], t.fz] {
            put(v);
        }
        for v in t.com.iter().chain(&t.pelvis).chain(&t.pelvis_rpy) {
            put(*v);
        }
        let margin = if t.margin.is_finite() {
            t.margin
        } else {
            f64::NAN
        };
        s.push_str(&format!(
            ",{},{},{margin:.6}",
            t.support.code(),
            if t.stance_left { 'L' } else { 'R' }
        ));
        let mut put = |v: f64| {
            s.push(',');
            s.push_str(&format!("{v:.6}"));
        };
        for v in t.forces.iter().flatten().chain(&t.gyro).chain(&t.accel) {
            put(*v);
        }
        put(t.tau);
        s.push_str(&format!(",{},{:.6}", u8::from(t.falling), t.fall_angle));
        for v in t.joint_speed.iter().chain(&t.joint_torque) {
            s.push_str(&format!(",{v:.5}"));
        }
        s.push_str(&format!(",{}", t.torque_limited));
        s.push_str(&format!(
            ",{},{}",
            u8::from(t.sole_contact[0]),
            u8::from(t.sole_contact[1])
        ));
        for v in t.sole_wrench.iter().flatten() {
            s.push_str(&format!(",{v:.4}"));
        }
        s.push_str(&format!(",{}", u8::from(t.other_contact)));
        writeln!(self.out, "{s}")?;
        self.rows += 1;
        Ok(())
    }

    /// Rows written.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Flushes the file.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}
