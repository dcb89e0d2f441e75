//! Ground-truth CSV log.
//!
//! One row per `log_every_us` of physics time (the instant the values describe; accelerations
//! are those of the motion state at that instant). Every column name ends in its unit (`_m`,
//! `_rad`, `_rad_s`, `_m_s2`, `_n`, `_nm`, `_s`); a name without one is a code, flag or bitmask.
//! A value that is not available (a torque without the torque model or while falling, a margin
//! outside every support polygon) is an empty field. Columns:
//!
//! `t_s, zmp_x_m, zmp_y_m, fz_n, com_{x,y,z}_m, pelvis_{x,y,z}_m, pelvis_{roll,pitch,yaw}_rad,
//! support (L/R/D), stance (L/R), margin_m, l_f0_n..l_f3_n, r_f0_n..r_f3_n` (load cells,
//! noiseless, sensor order front-left, front-right, rear-left, rear-right), `gyro_{x,y,z}_rad_s,
//! acc_{x,y,z}_m_s2, tau_nm, falling (0/1), fall_angle_rad, qd_1_rad_s..qd_12_rad_s` (joint
//! speeds by servo ID), `tq_1_nm..tq_12_nm` (motor torques), `tq_limited` (bit `ID − 1` set:
//! that motor is at its torque bound), `l_contact, r_contact` (each sole touches the ground,
//! 0/1), `l_f{x,y,z}_n, l_m{x,y,z}_nm, r_f{x,y,z}_n, r_m{x,y,z}_nm` (each sole's contact wrench
//! in the world frame about its sole point; 0 in the kinematic model), `other_contact` (a robot
//! part other than a sole touches the ground, 0/1), `l_x_m, l_y_m, l_yaw_rad, r_x_m, r_y_m,
//! r_yaw_rad` (each sole point's place on the ground and heading, world frame). With the MuJoCo robot `zmp_x_m, zmp_y_m` is
//! the true centre of pressure of the contact forces and `fz_n` their vertical sum.
//! [`crate::report::read_truth`] is the one reader.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::body::TruthSample;

/// Header line of the truth CSV (without newline).
pub const HEADER: &str = "t_s,zmp_x_m,zmp_y_m,fz_n,com_x_m,com_y_m,com_z_m,pelvis_x_m,pelvis_y_m,pelvis_z_m,\
pelvis_roll_rad,pelvis_pitch_rad,pelvis_yaw_rad,support,stance,margin_m,\
l_f0_n,l_f1_n,l_f2_n,l_f3_n,r_f0_n,r_f1_n,r_f2_n,r_f3_n,\
gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,acc_x_m_s2,acc_y_m_s2,acc_z_m_s2,tau_nm,falling,fall_angle_rad,\
qd_1_rad_s,qd_2_rad_s,qd_3_rad_s,qd_4_rad_s,qd_5_rad_s,qd_6_rad_s,qd_7_rad_s,qd_8_rad_s,qd_9_rad_s,qd_10_rad_s,qd_11_rad_s,qd_12_rad_s,\
tq_1_nm,tq_2_nm,tq_3_nm,tq_4_nm,tq_5_nm,tq_6_nm,tq_7_nm,tq_8_nm,tq_9_nm,tq_10_nm,tq_11_nm,tq_12_nm,tq_limited,\
l_contact,r_contact,l_fx_n,l_fy_n,l_fz_n,l_mx_nm,l_my_nm,l_mz_nm,r_fx_n,r_fy_n,r_fz_n,r_mx_nm,r_my_nm,r_mz_nm,other_contact,\
l_x_m,l_y_m,l_yaw_rad,r_x_m,r_y_m,r_yaw_rad";

/// The truth column of joint `id`'s speed (rad/s).
pub fn joint_speed_column(id: usize) -> String {
    format!("qd_{id}_rad_s")
}

/// The truth column of joint `id`'s motor torque (N·m).
pub fn joint_torque_column(id: usize) -> String {
    format!("tq_{id}_nm")
}

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
    pub fn row(&mut self, t: &TruthSample) -> std::io::Result<()> {
        let mut s = format!("{:.6}", t.t_us as f64 * 1e-6);
        let put = |s: &mut String, v: f64, decimals: usize| {
            s.push(',');
            s.push_str(&crate::report::csv_number(v, decimals));
        };
        for v in [t.zmp[0], t.zmp[1], t.fz] {
            put(&mut s, v, 6);
        }
        for v in t.com.iter().chain(&t.pelvis).chain(&t.pelvis_rpy) {
            put(&mut s, *v, 6);
        }
        s.push_str(&format!(
            ",{},{}",
            t.support.code(),
            if t.stance_left { 'L' } else { 'R' }
        ));
        put(&mut s, t.margin, 6);
        for v in t.forces.iter().flatten().chain(&t.gyro).chain(&t.accel) {
            put(&mut s, *v, 6);
        }
        put(&mut s, t.tau, 6);
        s.push_str(&format!(",{}", u8::from(t.falling)));
        put(&mut s, t.fall_angle, 6);
        for v in t.joint_speed.iter().chain(&t.joint_torque) {
            put(&mut s, *v, 5);
        }
        s.push_str(&format!(",{}", t.torque_limited));
        s.push_str(&format!(
            ",{},{}",
            u8::from(t.sole_contact[0]),
            u8::from(t.sole_contact[1])
        ));
        for v in t.sole_wrench.iter().flatten() {
            put(&mut s, *v, 4);
        }
        s.push_str(&format!(",{}", u8::from(t.other_contact)));
        for v in t.soles.iter().flatten() {
            put(&mut s, *v, 6);
        }
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
