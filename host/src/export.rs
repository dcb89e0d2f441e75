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

/// Whether `spec` can be exported at `dt`: no stabilizer (feedback on measurements, which an
/// export has not) and a plan the sampler accepts.
pub fn check_exportable(spec: &WalkSpec, robot: &Robot, dt: f64) -> Result<(), PlanError> {
    if spec.stabilizer {
        return Err(PlanError::new(
            "stabilizer",
            "the stabilizer is feedback on the robot's measurements: an export is open loop \
             (set it false, or walk the plan with `walker fil`)",
        ));
    }
    spec.sampler(robot, dt).map(|_| ())
}

/// Samples the plan at `dt` until the lead-out ends and solves the leg IK per sample.
pub fn export_rows(
    spec: &WalkSpec,
    robot: &Robot,
    dt: f64,
) -> Result<(Vec<ExportRow>, ExportSummary), PlanError> {
    check_exportable(spec, robot, dt)?;
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

/// A value as the export writes it: 9 decimals (1 nm, 1 nrad), `-0` as `0`.
fn field(v: f64) -> String {
    let f = format!("{v:.9}");
    if f == "-0.000000000" {
        "0.000000000".to_string()
    } else {
        f
    }
}

/// Writes the CSV (header and rows; 9 decimals: 1 nm, 1 nrad) with the `csv` crate.
pub fn write_csv(rows: &[ExportRow], w: impl Write) -> std::io::Result<()> {
    let mut out = csv::Writer::from_writer(w);
    out.write_record(
        LEAD_COLUMNS
            .iter()
            .map(|c| c.to_string())
            .chain(JOINT_NAMES.iter().map(|n| joint_column(n))),
    )?;
    for r in rows {
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
        out.write_record(lead.iter().chain(r.q.iter()).map(|v| field(*v)))?;
    }
    out.flush()
}

/// The header line of a plan file that says why `walker export` refuses the file:
/// `# Not exported: REASON` among the comment lines before the first key.
pub const NOT_EXPORTED: &str = "Not exported:";

/// The reason the header of a file's `text` gives for not exporting (see [`NOT_EXPORTED`]).
pub fn not_exported_reason(text: &str) -> Option<String> {
    text.lines()
        .map(str::trim)
        .take_while(|l| l.is_empty() || l.starts_with('#'))
        .find_map(|l| {
            l.trim_start_matches('#')
                .trim()
                .strip_prefix(NOT_EXPORTED)
                .map(|r| r.trim().to_string())
        })
}

/// Whether TOML `text` is a run configuration (`walker fil --config`: a `[plan]` table or
/// `plan_file`) rather than a plan file.
pub fn is_run_config(text: &str) -> bool {
    text.parse::<toml::Table>()
        .is_ok_and(|t| t.contains_key("plan") || t.contains_key("plan_file"))
}

/// The walk `walker export --plan FILE` samples: a plan file, or a run configuration's walk,
/// checked as [`export_rows`] checks it (at the plan's dt). A refusal carries the reason the
/// file's header gives, if it gives one ([`not_exported_reason`]).
pub fn load_for_export(path: &std::path::Path) -> Result<WalkSpec, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read the plan: {e}", path.display()))?;
    let loaded = if is_run_config(&text) {
        crate::runconfig::load(path).map(|rc| rc.spec)
    } else {
        crate::planfile::load(path).map_err(|e| e.to_string())
    };
    let checked = loaded.and_then(|spec| {
        check_exportable(&spec, spec.robot(), spec.dt)
            .map(|()| spec)
            .map_err(|e| format!("{}: {e}", path.display()))
    });
    checked.map_err(|e| match not_exported_reason(&text) {
        Some(why) => format!("{e} (the file's header: {NOT_EXPORTED} {why})"),
        None => e,
    })
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

#[cfg(test)]
mod shipped_plans {
    use super::*;

    /// Every file in plans/ exports (a plan, or a run configuration's walk) or its header says
    /// why not (`# Not exported: …`), never both; a refusal names that reason; a header that
    /// shows a `walker export --plan` command names its own file.
    #[test]
    fn every_shipped_plan_exports_or_says_why_not() {
        let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../plans"));
        let mut files: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        files.sort();
        let (mut exported, mut refused) = (0, 0);
        for path in &files {
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            let text = std::fs::read_to_string(path).unwrap();
            let why = not_exported_reason(&text);
            match (load_for_export(path), &why) {
                (Ok(spec), None) => {
                    let (rows, _) = export_rows(&spec, spec.robot(), spec.dt)
                        .unwrap_or_else(|e| panic!("{name}: {e}"));
                    assert!(rows.len() > 100, "{name}: {} rows", rows.len());
                    exported += 1;
                }
                (Ok(_), Some(w)) => panic!("{name} exports but its header says: {w}"),
                (Err(e), None) => panic!("{name} does not export and its header says not why: {e}"),
                (Err(e), Some(w)) => {
                    assert!(w.len() > 10, "{name}: reason {w:?}");
                    assert!(e.contains(w.as_str()) && e.contains(&name), "{name}: {e}");
                    refused += 1;
                }
            }
            for (i, _) in text.match_indices("walker export --plan ") {
                let named = text[i + "walker export --plan ".len()..]
                    .split([' ', '`'])
                    .next()
                    .unwrap_or("");
                assert!(
                    named.ends_with(&format!("/{name}")) || named == name,
                    "{name}'s header shows an export of {named}"
                );
            }
        }
        assert!(
            exported >= 9 && refused >= 1,
            "{exported} exported, {refused} refused"
        );
    }

    #[test]
    fn the_reason_is_read_from_the_header_only() {
        assert_eq!(
            not_exported_reason("# A plan.\n# Not exported: feedback.\nmodel = \"lipm\"\n"),
            Some("feedback.".into())
        );
        assert_eq!(
            not_exported_reason("model = \"lipm\"\n# Not exported: late.\n"),
            None
        );
        assert!(is_run_config("plan_file = \"table2.toml\"\n"));
        assert!(is_run_config("[plan]\ndt = 0.001\n"));
        assert!(!is_run_config("model = \"tlipfm\"\n"));
    }

    /// The CSV written with the `csv` crate has the bytes the hand-made one had: the header,
    /// 9 decimals, `-0` written as `0`, one `\n` per row.
    #[test]
    fn the_csv_keeps_its_bytes() {
        let row = ExportRow {
            t: 0.005,
            zmp: [-0.0000000001, 0.045],
            com: [0.0, -0.02, 0.217],
            feet: [[0.0, 0.045, 0.0], [0.0, -0.045, 0.0]],
            feet_yaw: [0.0, 0.0],
            q: [-0.1; LEG_JOINTS],
        };
        let mut out = Vec::new();
        write_csv(&[row], &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        let mut expect = header();
        expect.push('\n');
        expect.push_str("0.005000000,0.000000000,0.045000000,0.000000000,-0.020000000,0.217000000,0.000000000,0.045000000,0.000000000,0.000000000,-0.045000000,0.000000000");
        expect.push_str(&",-0.100000000".repeat(LEG_JOINTS));
        expect.push('\n');
        assert_eq!(text, expect);
    }
}
