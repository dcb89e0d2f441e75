//! Plan export: the sampled plan with the 12 joint angles of the leg IK, as CSV.
//!
//! Columns (units as name suffixes): `t_s, zmp_x_m, zmp_y_m, com_x_m, com_y_m, com_z_m,
//! l_foot_x_m, l_foot_y_m, l_foot_z_m, r_foot_x_m, r_foot_y_m, r_foot_z_m` then the joint names
//! of [`gait_core::robot::JOINT_NAMES`] with `_rad` (`l_hip_yaw_rad` …). World frame, `t_s` from
//! the start of the lead-in. The pelvis is the CoM point
//! (x, y, z_c), upright, heading = the mean of the two feet's headings; the feet are level.
//!
//! The plan's open-loop choices are applied as the firmware applies them: the CoM solver
//! (`com`), and with `compensation = "wholebody"` the joints place the pelvis so that the
//! multi-body CoM is on the model's CoM (gait-core `wholebody`, the firmware's
//! [`gait_core::gait::WHOLEBODY_ITERATIONS`]; the `com_*` columns stay the model's CoM). A plan
//! with `stabilizer = true` is refused: the stabilizer is feedback on measurements, which an
//! export has not.

use crate::planfile::{CompensationName, PlanError, WalkSpec};
use gait_core::gait::WHOLEBODY_ITERATIONS;
use gait_core::kinematics::leg::{legs_ik, Pose};
use gait_core::kinematics::wholebody::WholeBody;
use gait_core::robot::{JOINT_NAMES, LEG_JOINTS};
use gait_core::Robot;
use std::io::Write;

/// The 12 leading columns of the export (the joint names follow).
pub const LEAD_COLUMNS: [&str; 12] = [
    "t_s",
    "zmp_x_m",
    "zmp_y_m",
    "com_x_m",
    "com_y_m",
    "com_z_m",
    "l_foot_x_m",
    "l_foot_y_m",
    "l_foot_z_m",
    "r_foot_x_m",
    "r_foot_y_m",
    "r_foot_z_m",
];

/// The column of joint `name` (an angle, rad).
pub fn joint_column(name: &str) -> String {
    format!("{name}_rad")
}

/// One row of the export.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExportRow {
    /// Time from the start of the lead-in, s.
    pub t: f64,
    /// ZMP reference (x, y), m.
    pub zmp: [f64; 2],
    /// CoM / pelvis point (x, y, z), m.
    pub com: [f64; 3],
    /// Feet sole points (left, right): x, y, z, m.
    pub feet: [[f64; 3]; 2],
    /// Feet headings (left, right), rad (not exported; used for the pelvis heading).
    pub feet_yaw: [f64; 2],
    /// Joint angles (left leg then right leg), rad.
    pub q: [f64; LEG_JOINTS],
}

impl ExportRow {
    /// The pelvis pose of this row.
    pub fn pelvis(&self) -> Pose<f64> {
        Pose::level(
            self.com[0],
            self.com[1],
            self.com[2],
            mean_angle(self.feet_yaw[0], self.feet_yaw[1]),
        )
    }
}

/// Summary of an export.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExportSummary {
    /// Rows written.
    pub rows: usize,
    /// Rows where the IK could not meet a foot target exactly (reach or joint limit).
    pub clamped_rows: usize,
    /// Largest reach deficit seen, m.
    pub worst_reach_deficit: f64,
}

/// The mean of two angles (on the circle).
pub fn mean_angle(a: f64, b: f64) -> f64 {
    (a.sin() + b.sin()).atan2(a.cos() + b.cos())
}

/// Samples the plan at `dt` until the lead-out ends and solves the leg IK per sample.
pub fn export_rows(
    spec: &WalkSpec,
    robot: &Robot,
    dt: f64,
) -> Result<(Vec<ExportRow>, ExportSummary), PlanError> {
    if spec.stabilizer {
        return Err(PlanError::new(
            "stabilizer",
            "the stabilizer is feedback on the robot's measurements: an export is open loop \
             (set it false, or walk the plan with `walker fil`)",
        ));
    }
    let wholebody = (spec.compensation == CompensationName::Wholebody)
        .then(|| WholeBody::<f64>::new(robot, WHOLEBODY_ITERATIONS));
    let mut sampler = spec.sampler(robot, dt)?;
    let mut rows = Vec::new();
    let mut summary = ExportSummary::default();
    // Bounded: a plan of 64 steps of at most 4 s plus two 4 s stands at ≥ 1 kHz.
    let limit = 1 + ((crate::planfile::PLAN_CAPACITY as f64 * 4.0 + 8.0) / dt) as usize;
    while !sampler.is_done() && rows.len() < limit {
        let s = sampler.next(0.0);
        let f = s.feet;
        let mut row = ExportRow {
            t: s.time_ns as f64 * 1e-9,
            zmp: s.zmp,
            com: s.com,
            feet: [[f[0].x, f[0].y, f[0].z], [f[1].x, f[1].y, f[1].z]],
            feet_yaw: [f[0].yaw, f[1].yaw],
            q: [0.0; LEG_JOINTS],
        };
        let (q, rep) = match &wholebody {
            Some(wb) => {
                let c = wb.joint_targets(&s);
                (c.joints, c.report)
            }
            None => {
                let pelvis = row.pelvis();
                let lf = Pose::level(f[0].x, f[0].y, f[0].z, f[0].yaw);
                let rf = Pose::level(f[1].x, f[1].y, f[1].z, f[1].yaw);
                legs_ik(robot, &pelvis, &lf, &rf)
            }
        };
        row.q = q;
        if rep.clamped() {
            summary.clamped_rows += 1;
        }
        summary.worst_reach_deficit = summary
            .worst_reach_deficit
            .max(rep.reach_deficit[0])
            .max(rep.reach_deficit[1]);
        rows.push(row);
    }
    summary.rows = rows.len();
    Ok((rows, summary))
}

/// The header line (without newline).
pub fn header() -> String {
    LEAD_COLUMNS
        .iter()
        .map(|c| c.to_string())
        .chain(JOINT_NAMES.iter().map(|n| joint_column(n)))
        .collect::<Vec<_>>()
        .join(",")
}

/// Writes the CSV (header and rows; 9 decimals: 1 nm, 1 nrad).
pub fn write_csv(rows: &[ExportRow], mut w: impl Write) -> std::io::Result<()> {
    writeln!(w, "{}", header())?;
    for r in rows {
        let mut line = String::with_capacity(256);
        let lead = [
            r.t,
            r.zmp[0],
            r.zmp[1],
            r.com[0],
            r.com[1],
            r.com[2],
            r.feet[0][0],
            r.feet[0][1],
            r.feet[0][2],
            r.feet[1][0],
            r.feet[1][1],
            r.feet[1][2],
        ];
        for (i, v) in lead.iter().chain(r.q.iter()).enumerate() {
            if i > 0 {
                line.push(',');
            }
            let f = format!("{v:.9}");
            line.push_str(if f == "-0.000000000" {
                "0.000000000"
            } else {
                &f
            });
        }
        writeln!(w, "{line}")?;
    }
    Ok(())
}

#[cfg(test)]
mod compensation_tests {
    use super::*;
    use gait_core::gait::{Compensation, Targets};

    /// `compensation = "wholebody"` exports the firmware's compensated joints (its f32
    /// `Targets::WholeBody` on the same samples, to f32 rounding), which differ from the plain
    /// IK's; `stabilizer = true` is refused naming the key.
    #[test]
    fn export_applies_wholebody_compensation_and_refuses_the_stabilizer() {
        let robot = Robot::reference();
        let plain = WalkSpec::default();
        let wb = WalkSpec {
            compensation: CompensationName::Wholebody,
            ..plain.clone()
        };
        let (rp, _) = export_rows(&plain, &robot, 0.005).unwrap();
        let (rw, _) = export_rows(&wb, &robot, 0.005).unwrap();
        assert_eq!(rp.len(), rw.len());
        let firmware = Targets::new(&robot, Compensation::WholeBody);
        let mut sampler32 = gait_core::gait::build_sampler::<64>(
            &wb.firmware_config().unwrap().walk_config(),
            &robot,
        )
        .unwrap();
        let (mut differ, mut worst) = (0.0f64, 0.0f64);
        for (p, w) in rp.iter().zip(&rw) {
            let g = sampler32.next(0.0);
            let (q32, _) = firmware.joints(&g, [0.0; 2]);
            for ((a, b), c) in p.q.iter().zip(&w.q).zip(&q32) {
                differ = differ.max((a - b).abs());
                worst = worst.max((f64::from(*c) - b).abs());
            }
        }
        assert!(
            differ > 0.01,
            "compensation changes the joints by {differ} rad"
        );
        assert!(worst < 1e-3, "export vs firmware compensation: {worst} rad");
        let fb = WalkSpec {
            stabilizer: true,
            ..plain
        };
        let e = export_rows(&fb, &robot, 0.005).unwrap_err();
        assert_eq!(e.field, "stabilizer");
    }
}
