//! `walker sweep`: the robustness sweep of the closed-loop issue (item 5) — the same plan walked
//! by the firmware (its defaults: the closed loop) in the firmware-in-the-loop setup on the
//! MuJoCo robot, once nominal and once per perturbation of the robot family:
//!
//! | case | what changes |
//! | --- | --- |
//! | `torque-20` / `torque+20` | servo stall torque × 0.8 / × 1.2 (`XServoParams::stall_torque`) |
//! | `gains-20` / `gains+20` | servo drive gains × 0.8 / × 1.2 (`XServoParams::gain_scale`) |
//! | `mass-10` / `mass+10` | every link mass and inertia × 0.9 / × 1.1 (`EnvConfig::mass_scale`) |
//! | `friction0.5` / `friction0.75` | sole–floor friction 0.5 / 0.75 (nominal 1.0) |
//! | `latency+5ms` | the foot boards' and the IMU's samples 5 ms older |
//! | `drop5%` | 5 % of the status packets lost on the bus |
//!
//! Each run is scored like `walker beyond` ([`crate::beyond::score`]: true CoP − reference over
//! the walking ticks) and [`crate::fil::walk_figures`] (distance walked / planned, heading drift,
//! torso tilt), and the table says which of the goals each case misses: no fall,
//! ≥ 95 % of the planned distance, heading drift < 3°, ZMP mean |e| < 11 mm sagittal and
//! < 14 mm lateral.

use std::fmt::Write as _;

use crate::beyond::{self, RunMetrics};
use crate::fil::{self, FilOptions, WalkFigures};
use crate::sim::SimConfig;

/// The goals of the closed-loop issue, per run.
pub mod goal {
    /// Least share of the planned distance.
    pub const DISTANCE: f64 = 0.95;
    /// Largest heading drift, degrees.
    pub const HEADING_DEG: f64 = 3.0;
    /// Largest ZMP mean |e| sagittal (x), m.
    pub const ZMP_X: f64 = 0.011;
    /// Largest ZMP mean |e| lateral (y), m.
    pub const ZMP_Y: f64 = 0.014;
}

/// One perturbation of the simulated robot.
#[derive(Clone, Copy)]
pub struct SweepCase {
    /// Short name (also the output sub-folder).
    pub name: &'static str,
    /// What it changes, for the table.
    pub what: &'static str,
    /// Applies it to the nominal simulator.
    pub apply: fn(&mut SimConfig),
}

/// The nominal run and the ten perturbations, in table order.
pub fn cases() -> [SweepCase; 11] {
    fn c(name: &'static str, what: &'static str, apply: fn(&mut SimConfig)) -> SweepCase {
        SweepCase { name, what, apply }
    }
    [
        c("nominal", "XM430-W350, reference robot, friction 1", |_| {}),
        c("torque-20", "servo stall torque × 0.8", |s| {
            s.xservo.stall_torque *= 0.8
        }),
        c("torque+20", "servo stall torque × 1.2", |s| {
            s.xservo.stall_torque *= 1.2
        }),
        c("gains-20", "servo gains × 0.8", |s| {
            s.xservo.gain_scale *= 0.8
        }),
        c("gains+20", "servo gains × 1.2", |s| {
            s.xservo.gain_scale *= 1.2
        }),
        c("mass-10", "link masses × 0.9", |s| s.env.mass_scale *= 0.9),
        c("mass+10", "link masses × 1.1", |s| s.env.mass_scale *= 1.1),
        c("friction0.5", "floor friction 0.5", |s| {
            s.env.floor_friction = 0.5
        }),
        c("friction0.75", "floor friction 0.75", |s| {
            s.env.floor_friction = 0.75
        }),
        c("latency+5ms", "sensor latency + 5 ms", |s| {
            s.noise.latency_us += 5_000
        }),
        c("drop5%", "5 % of status packets lost", |s| {
            s.faults.p_drop = 0.05
        }),
    ]
}

/// One scored run of the sweep.
#[derive(Clone, Debug)]
pub struct SweepRow {
    /// The case's name.
    pub name: &'static str,
    /// What it changes.
    pub what: &'static str,
    /// The firmware's exit code.
    pub exit_code: Option<i32>,
    /// The ZMP and speed figures.
    pub metrics: RunMetrics,
    /// Distance, heading, tilt.
    pub figures: WalkFigures,
}

impl SweepRow {
    /// The goals this run misses (empty: all met).
    pub fn missed(&self) -> Vec<String> {
        let f = &self.figures;
        let mut out = Vec::new();
        if let Some(t) = f.fell_at {
            out.push(format!("fell at {t:.1} s"));
        }
        let share = f.walked / f.planned;
        if share.is_nan() || share < goal::DISTANCE {
            out.push(format!("distance {:.0} % < 95 %", 100.0 * share));
        }
        let h = f.heading_drift.to_degrees();
        if h.is_nan() || h.abs() >= goal::HEADING_DEG {
            out.push(format!("heading {h:+.1}°"));
        }
        let [ex, ey] = self.metrics.true_err.map(|e| e.mean);
        if ex.is_nan() || ex >= goal::ZMP_X {
            out.push(format!("ZMP x {:.1} mm", ex * 1e3));
        }
        if ey.is_nan() || ey >= goal::ZMP_Y {
            out.push(format!("ZMP y {:.1} mm", ey * 1e3));
        }
        out
    }
}

/// Walks every case and scores it; `progress(name)` before each run.
pub fn run(opts: &FilOptions, progress: impl Fn(&str)) -> Result<Vec<SweepRow>, String> {
    let variant = beyond::variants()
        .into_iter()
        .find(|v| v.name == "tlipfm")
        .ok_or("no tlipfm variant")?;
    let mut tokens = fil::firmware_tokens(&opts.spec)?;
    tokens.extend(opts.extra_tokens.iter().cloned());
    let cfg = beyond::firmware_config(&tokens)?;
    let mut out = Vec::new();
    for case in cases() {
        progress(case.name);
        let mut sim = opts.sim.clone();
        (case.apply)(&mut sim);
        let fopts = FilOptions {
            sim,
            ..opts.in_sub(case.name)
        };
        let r = fil::run(&fopts, |_, _| {})?;
        let fell = r.sim.fall_started_us.map(|t| t as f64 * 1e-6);
        let metrics = beyond::score(&variant, &cfg, &r.log, &r.truth, r.exit_code, fell)?;
        let figures = fil::walk_figures(&r.truth, &opts.spec)?;
        out.push(SweepRow {
            name: case.name,
            what: case.what,
            exit_code: r.exit_code,
            metrics,
            figures,
        });
    }
    Ok(out)
}

/// The sweep table (Markdown).
pub fn table(rows: &[SweepRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| case | what | exit | walked / planned | heading drift | torso tilt max | true ZMP mean \\|e\\| x / y (mm) | goals missed |"
    );
    let _ = writeln!(s, "| --- | --- | ---: | ---: | ---: | ---: | ---: | --- |");
    for r in rows {
        let f = &r.figures;
        let [ex, ey] = r.metrics.true_err.map(|e| e.mean * 1e3);
        let missed = r.missed();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.3} / {:.3} m ({:.0} %) | {:+.1}° | {:.1}° | {ex:.1} / {ey:.1} | {} |",
            r.name,
            r.what,
            r.exit_code.map_or("killed".into(), |c| c.to_string()),
            f.walked,
            f.planned,
            100.0 * f.walked / f.planned,
            f.heading_drift.to_degrees(),
            f.max_tilt.to_degrees(),
            if missed.is_empty() {
                "none".to_string()
            } else {
                missed.join("; ")
            }
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::beyond::AxisError;

    /// Every case changes the nominal simulator, and only in the knob it names.
    #[test]
    fn each_case_changes_one_knob() {
        let nominal = SimConfig::default();
        let cs = cases();
        assert_eq!(cs[0].name, "nominal");
        for c in cs.iter().skip(1) {
            let mut s = nominal.clone();
            (c.apply)(&mut s);
            let changed = [
                s.xservo.stall_torque != nominal.xservo.stall_torque,
                s.xservo.gain_scale != nominal.xservo.gain_scale,
                s.env.mass_scale != nominal.env.mass_scale,
                s.env.floor_friction != nominal.env.floor_friction,
                s.noise.latency_us != nominal.noise.latency_us,
                s.faults.p_drop != nominal.faults.p_drop,
            ];
            assert_eq!(
                changed.iter().filter(|c| **c).count(),
                1,
                "{}: {changed:?}",
                c.name
            );
            s.validate().unwrap_or_else(|e| panic!("{}: {e}", c.name));
        }
    }

    fn row(walked: f64, heading_deg: f64, zmp: [f64; 2], fell: Option<f64>) -> SweepRow {
        let e = |m: f64| AxisError {
            n: 1,
            mean: m,
            max: m,
        };
        let mut metrics = crate::beyond::tests::metrics("x", [0.0; 2]);
        metrics.true_err = [e(zmp[0]), e(zmp[1])];
        SweepRow {
            name: "x",
            what: "y",
            exit_code: Some(0),
            metrics,
            figures: WalkFigures {
                fell_at: fell,
                walked,
                planned: 0.26,
                heading_drift: heading_deg.to_radians(),
                max_tilt: 0.05,
            },
        }
    }

    #[test]
    fn missed_goals_are_named_and_met_goals_are_not() {
        assert!(row(0.26, 1.0, [0.010, 0.013], None).missed().is_empty());
        let m = row(0.2, -4.0, [0.02, 0.03], Some(5.0)).missed();
        assert_eq!(m.len(), 5, "{m:?}");
        assert!(m[0].starts_with("fell at 5.0"));
        assert!(m[1].contains("77 %"));
        assert!(m[2].contains("-4.0°"));
        // NaN figures count as missed, never as met.
        let m = row(f64::NAN, f64::NAN, [f64::NAN; 2], None).missed();
        assert_eq!(m.len(), 4, "{m:?}");
        let t = table(&[row(0.26, 1.0, [0.010, 0.013], None)]);
        assert!(t.contains("| none |"), "{t}");
    }
}
