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
//! r_yaw_rad` (each sole point's place on the ground and heading, world frame), `l_roll_rad,
//! l_pitch_rad, r_roll_rad, r_pitch_rad` (each sole's tilt: 0 flat, a pitch when it rocks on
//! its heel or toe; 0 in the kinematic model), `l_z_m, r_z_m` (each sole point's height: the
//! swing foot's lift; 0 in the kinematic model), `q_1_rad..q_12_rad` (joint positions by servo
//! ID, the simulator's joint coordinates). With the MuJoCo robot `zmp_x_m, zmp_y_m` is
//! the true centre of pressure of the contact forces and `fz_n` their vertical sum.
//! [`crate::report::read_truth`] is the one reader.

use std::fs::File;
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
l_x_m,l_y_m,l_yaw_rad,r_x_m,r_y_m,r_yaw_rad,l_roll_rad,l_pitch_rad,r_roll_rad,r_pitch_rad,l_z_m,r_z_m,\
q_1_rad,q_2_rad,q_3_rad,q_4_rad,q_5_rad,q_6_rad,q_7_rad,q_8_rad,q_9_rad,q_10_rad,q_11_rad,q_12_rad";

/// The truth column of joint `id`'s speed (rad/s).
pub fn joint_speed_column(id: usize) -> String {
    format!("qd_{id}_rad_s")
}

/// The truth column of joint `id`'s motor torque (N·m).
pub fn joint_torque_column(id: usize) -> String {
    format!("tq_{id}_nm")
}

/// Writer of the truth CSV (the `csv` crate).
#[derive(Debug)]
pub struct TruthLog {
    out: csv::Writer<File>,
    rows: u64,
}

impl TruthLog {
    /// Creates the file and writes the header.
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let mut out = csv::Writer::from_writer(File::create(path)?);
        out.write_record(HEADER.split(','))?;
        Ok(TruthLog { out, rows: 0 })
    }

    /// Appends one row.
    pub fn row(&mut self, t: &TruthSample) -> std::io::Result<()> {
        /// A number with `decimals` decimals (empty when not available).
        fn num(w: &mut csv::Writer<File>, v: f64, decimals: usize) -> csv::Result<()> {
            w.write_field(crate::report::csv_number(v, decimals))
        }
        let w = &mut self.out;
        w.write_field(format!("{:.6}", t.t_us as f64 * 1e-6))?;
        for v in [t.zmp[0], t.zmp[1], t.fz] {
            num(w, v, 6)?;
        }
        for v in t.com.iter().chain(&t.pelvis).chain(&t.pelvis_rpy) {
            num(w, *v, 6)?;
        }
        w.write_field(t.support.code().to_string())?;
        w.write_field(if t.stance_left { "L" } else { "R" })?;
        num(w, t.margin, 6)?;
        for v in t.forces.iter().flatten().chain(&t.gyro).chain(&t.accel) {
            num(w, *v, 6)?;
        }
        num(w, t.tau, 6)?;
        w.write_field(u8::from(t.falling).to_string())?;
        num(w, t.fall_angle, 6)?;
        for v in t.joint_speed.iter().chain(&t.joint_torque) {
            num(w, *v, 5)?;
        }
        w.write_field(t.torque_limited.to_string())?;
        w.write_field(u8::from(t.sole_contact[0]).to_string())?;
        w.write_field(u8::from(t.sole_contact[1]).to_string())?;
        for v in t.sole_wrench.iter().flatten() {
            num(w, *v, 4)?;
        }
        w.write_field(u8::from(t.other_contact).to_string())?;
        let tilt = t.sole_tilt.iter().flatten();
        for v in t.soles.iter().flatten().chain(tilt).chain(&t.sole_z) {
            num(w, *v, 6)?;
        }
        for v in &t.joint_position {
            num(w, *v, 5)?;
        }
        w.write_record(None::<&[u8]>)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The truth CSV written with the `csv` crate has the bytes of the hand-made one: the
    /// header, each value with its decimals joined by commas, an unavailable value (NaN) empty,
    /// `\n` after each row.
    #[test]
    fn truth_rows_keep_their_bytes() {
        let mut t = TruthSample {
            t_us: 1_234_567,
            zmp: [f64::NAN, -0.0123456789],
            fz: 35.5,
            stance_left: true,
            falling: true,
            torque_limited: 0b101,
            sole_contact: [true, false],
            other_contact: true,
            ..TruthSample::default()
        };
        t.joint_torque = [f64::NAN; 12];
        t.joint_speed[3] = -1.234567;
        t.sole_wrench[1][2] = 20.12345;
        t.soles[0] = [0.1, 0.045, -0.01];
        t.sole_tilt[1] = [0.002, -0.05];
        t.sole_z[0] = 0.03;
        t.joint_position[4] = -0.123456;
        let n = crate::report::csv_number;
        let mut fields = vec![format!("{:.6}", 1.234567)];
        fields.extend([t.zmp[0], t.zmp[1], t.fz].map(|v| n(v, 6)));
        fields.extend([0.0; 9].map(|v| n(v, 6)));
        fields.extend([t.support.code().to_string(), "L".into(), n(0.0, 6)]);
        fields.extend([0.0; 15].map(|v| n(v, 6)));
        fields.extend(["1".into(), n(0.0, 6)]);
        fields.extend(t.joint_speed.map(|v| n(v, 5)));
        fields.extend(t.joint_torque.map(|v| n(v, 5)));
        fields.extend(["5".into(), "1".into(), "0".into()]);
        fields.extend(t.sole_wrench.iter().flatten().map(|v| n(*v, 4)));
        fields.push("1".into());
        fields.extend(t.soles.iter().flatten().map(|v| n(*v, 6)));
        fields.extend(["0.000000", "0.000000", "0.002000", "-0.050000"].map(String::from));
        fields.extend(["0.030000", "0.000000"].map(String::from));
        fields.extend(t.joint_position.map(|v| n(v, 5)));
        let expect = format!("{HEADER}\n{}\n", fields.join(","));
        assert_eq!(fields.len(), HEADER.split(',').count());
        let path = std::env::temp_dir().join(format!("walker-truth-{}.csv", std::process::id()));
        let mut log = TruthLog::create(&path).unwrap();
        log.row(&t).unwrap();
        log.flush().unwrap();
        drop(log);
        let text = std::fs::read_to_string(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!(text, expect);
        assert!(text.contains("1.234567,,-0.012346,35.500000,"), "{text}");
    }
}
