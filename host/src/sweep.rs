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
//! The cases run `--jobs N` at a time (each a QEMU process and a simulator thread); `--shard K/N`
//! runs the K-th of N interleaved parts of the case list (case i when i mod N = K − 1) and writes
//! its rows to `OUT/rows.csv`, and `walker sweep --merge DIR…` makes the table of the shards'
//! rows, so that a batch system (GNU parallel, Slurm, a CI matrix) can spread a sweep over
//! machines.
//!
//! Each run is scored like `walker beyond` ([`crate::beyond::score`]: true CoP − reference over
//! the walking ticks) and [`crate::fil::walk_figures`] (distance walked / planned, heading drift,
//! torso tilt), and the table says which of the goals each case misses: no fall,
//! ≥ 95 % of the planned distance, heading drift < 3°, ZMP mean |e| < 11 mm sagittal and
//! < 14 mm lateral.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use crate::beyond::{self, AxisError};
use crate::fil::{self, FilOptions, WalkFigures};
use crate::progress::Progress;
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

/// The families a sweep walks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Family {
    /// The reference robot's family: the nominal run and ten perturbations ([`cases`]).
    Reference,
    /// The servos a robot of this class really has ([`servo_cases`]): stall torque 2.5 – 5.0
    /// N·m, no-load speed 2.5 – 4.8 rad/s (and a weak servo, 3.0 N·m / 2.8 rad/s, also at the
    /// nominal stiffness), drive gains × 0.6 – 1.4, supply 10.5 – 12.6 V, link masses ± 15 %,
    /// the trunk's CoM ± 1 cm, floor friction 0.4, sensor and Present Position latency 10 ms.
    Servos,
}

impl Family {
    /// The family's cases, in table order (the nominal run first).
    pub fn cases(self) -> Vec<SweepCase> {
        match self {
            Family::Reference => cases().to_vec(),
            Family::Servos => servo_cases().to_vec(),
        }
    }
}

/// The servo family: the nominal run and one servo, supply, body or floor change per case, to
/// the ends of the ranges a robot of this class meets (a 3S battery near empty, a warm motor, a
/// different servo model: `stiff-weak` is a position servo whose stiffness stays the nominal
/// one while its torque tops out at 3.0 N·m, as a fixed-kp actuator with a torque limit; gear
/// backlash as the play of [`crate::sim::dynamixel`]).
pub fn servo_cases() -> [SweepCase; 21] {
    fn c(name: &'static str, what: &'static str, apply: fn(&mut SimConfig)) -> SweepCase {
        SweepCase { name, what, apply }
    }
    [
        c(
            "nominal",
            "XM430-W350, the plan's robot, friction 1",
            |_| {},
        ),
        c("stall2.5", "servo stall torque 2.5 N·m", |s| {
            s.xservo.stall_torque = 2.5
        }),
        c("stall5.0", "servo stall torque 5.0 N·m", |s| {
            s.xservo.stall_torque = 5.0
        }),
        c("speed2.5", "servo no-load speed 2.5 rad/s", |s| {
            s.xservo.no_load_speed = 2.5
        }),
        c("speed4.8", "servo no-load speed 4.8 rad/s", |s| {
            s.xservo.no_load_speed = 4.8
        }),
        c(
            "weak3.0/2.8",
            "servo 3.0 N·m stall, 2.8 rad/s no-load",
            |s| {
                s.xservo.stall_torque = 3.0;
                s.xservo.no_load_speed = 2.8;
            },
        ),
        c("gains×0.6", "servo gains × 0.6", |s| {
            s.xservo.gain_scale *= 0.6
        }),
        c("gains×1.4", "servo gains × 1.4", |s| {
            s.xservo.gain_scale *= 1.4
        }),
        c("supply10.5V", "servo supply 10.5 V", |s| {
            s.xservo.supply_voltage = 10.5
        }),
        c("supply12.6V", "servo supply 12.6 V", |s| {
            s.xservo.supply_voltage = 12.6
        }),
        c("mass-15", "link masses × 0.85", |s| {
            s.env.mass_scale *= 0.85
        }),
        c("mass+15", "link masses × 1.15", |s| {
            s.env.mass_scale *= 1.15
        }),
        c("friction0.4", "floor friction 0.4", |s| {
            s.env.floor_friction = 0.4
        }),
        c("latency+10ms", "sensor latency + 10 ms", |s| {
            s.noise.latency_us += 10_000
        }),
        c(
            "weak+supply10.5V",
            "weak servo (3.0 N·m, 2.8 rad/s) at 10.5 V",
            |s| {
                s.xservo.stall_torque = 3.0;
                s.xservo.no_load_speed = 2.8;
                s.xservo.supply_voltage = 10.5;
            },
        ),
        c(
            "weak+gains×0.6",
            "weak servo (3.0 N·m, 2.8 rad/s), gains × 0.6",
            |s| {
                s.xservo.stall_torque = 3.0;
                s.xservo.no_load_speed = 2.8;
                s.xservo.gain_scale *= 0.6;
            },
        ),
        c(
            "stiff-weak",
            "weak servo (3.0 N·m, 2.8 rad/s) at the nominal stiffness (gains × 4.1/3.0)",
            |s| {
                s.xservo.stall_torque = 3.0;
                s.xservo.no_load_speed = 2.8;
                s.xservo.gain_scale *= 4.1 / 3.0;
            },
        ),
        c("trunk+1cm", "upper body's CoM 1 cm forward", |s| {
            s.env.trunk_com_dx_m = 0.01
        }),
        c("trunk-1cm", "upper body's CoM 1 cm back", |s| {
            s.env.trunk_com_dx_m = -0.01
        }),
        c(
            "position+10ms",
            "servos' Present Position 10 ms late",
            |s| s.noise.position_latency_us += 10_000,
        ),
        c("backlash0.5", "gear backlash 0.5° at every joint", |s| {
            s.xservo.backlash = 0.5f64.to_radians()
        }),
    ]
}

/// The nominal run and the ten perturbations, in table order.
pub fn cases() -> [SweepCase; 11] {
    fn c(name: &'static str, what: &'static str, apply: fn(&mut SimConfig)) -> SweepCase {
        SweepCase { name, what, apply }
    }
    [
        c(
            "nominal",
            "XM430-W350, the plan's robot, friction 1",
            |_| {},
        ),
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
#[derive(Clone, Debug, PartialEq)]
pub struct SweepRow {
    /// The case's name.
    pub name: String,
    /// What it changes.
    pub what: String,
    /// The firmware's exit code.
    pub exit_code: Option<i32>,
    /// True CoP − reference over the walking ticks, x and y.
    pub true_err: [AxisError; 2],
    /// Distance, heading, tilt.
    pub figures: WalkFigures,
}

/// A part of the case list: the `index`-th (1-based) of `count` interleaved parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// 1 ..= `count`.
    pub index: usize,
    /// Parts, ≥ 1.
    pub count: usize,
}

impl Shard {
    /// The whole list.
    pub const ALL: Shard = Shard { index: 1, count: 1 };

    /// `K/N` with 1 ≤ K ≤ N.
    pub fn parse(s: &str) -> Result<Shard, String> {
        let bad = || format!("shard '{s}': expected K/N with 1 <= K <= N");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let index: usize = k.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index == 0 || index > count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }

    /// Whether case number `i` (0-based, table order) is in this part.
    pub fn has(&self, i: usize) -> bool {
        i % self.count == self.index - 1
    }
}

/// A row as one line of `rows.csv` (flat; NaN written as `NaN`, read back as NaN).
#[derive(Clone, Debug, Serialize, Deserialize)]
struct RowRecord {
    case: String,
    what: String,
    exit_code: Option<i32>,
    fell_at_s: Option<f64>,
    walked_m: f64,
    planned_m: f64,
    heading_drift_rad: f64,
    max_tilt_rad: f64,
    true_err_x_n: usize,
    true_err_x_mean_m: f64,
    true_err_x_max_m: f64,
    true_err_y_n: usize,
    true_err_y_mean_m: f64,
    true_err_y_max_m: f64,
}

impl From<&SweepRow> for RowRecord {
    fn from(r: &SweepRow) -> Self {
        let f = &r.figures;
        let [x, y] = r.true_err;
        RowRecord {
            case: r.name.clone(),
            what: r.what.clone(),
            exit_code: r.exit_code,
            fell_at_s: f.fell_at,
            walked_m: f.walked,
            planned_m: f.planned,
            heading_drift_rad: f.heading_drift,
            max_tilt_rad: f.max_tilt,
            true_err_x_n: x.n,
            true_err_x_mean_m: x.mean,
            true_err_x_max_m: x.max,
            true_err_y_n: y.n,
            true_err_y_mean_m: y.mean,
            true_err_y_max_m: y.max,
        }
    }
}

impl From<RowRecord> for SweepRow {
    fn from(r: RowRecord) -> Self {
        let axis = |n, mean, max| AxisError { n, mean, max };
        SweepRow {
            name: r.case,
            what: r.what,
            exit_code: r.exit_code,
            true_err: [
                axis(r.true_err_x_n, r.true_err_x_mean_m, r.true_err_x_max_m),
                axis(r.true_err_y_n, r.true_err_y_mean_m, r.true_err_y_max_m),
            ],
            figures: WalkFigures {
                fell_at: r.fell_at_s,
                walked: r.walked_m,
                planned: r.planned_m,
                heading_drift: r.heading_drift_rad,
                max_tilt: r.max_tilt_rad,
            },
        }
    }
}

/// Writes `rows` to `path` (CSV, one row per case).
pub fn write_rows(path: &Path, rows: &[SweepRow]) -> Result<(), String> {
    let err = |e: csv::Error| format!("{}: {e}", path.display());
    let mut w = csv::Writer::from_path(path).map_err(err)?;
    for r in rows {
        w.serialize(RowRecord::from(r)).map_err(err)?;
    }
    w.flush().map_err(|e| format!("{}: {e}", path.display()))
}

/// Reads the rows a sweep (or a shard of one) wrote to `path`.
pub fn read_rows(path: &Path) -> Result<Vec<SweepRow>, String> {
    let err = |e: csv::Error| format!("{}: {e}", path.display());
    let mut r = csv::Reader::from_path(path).map_err(err)?;
    r.deserialize::<RowRecord>()
        .map(|rec| rec.map(SweepRow::from).map_err(err))
        .collect()
}

/// The shards' rows in table order: every case once (a case twice or unknown is an error; the
/// cases no shard ran are returned by name).
pub fn merge(
    family: Family,
    parts: Vec<Vec<SweepRow>>,
) -> Result<(Vec<SweepRow>, Vec<&'static str>), String> {
    let order = family.cases();
    let mut slots: Vec<Option<SweepRow>> = vec![None; order.len()];
    for row in parts.into_iter().flatten() {
        let i = order
            .iter()
            .position(|c| c.name == row.name)
            .ok_or_else(|| format!("unknown sweep case '{}'", row.name))?;
        if slots[i].is_some() {
            return Err(format!("sweep case '{}' in two shards", row.name));
        }
        slots[i] = Some(row);
    }
    let missing = order
        .iter()
        .zip(&slots)
        .filter(|(_, s)| s.is_none())
        .map(|(c, _)| c.name)
        .collect();
    Ok((slots.into_iter().flatten().collect(), missing))
}

impl SweepRow {
    /// The run in a few words (a progress line): exit, distance, the goals missed.
    pub fn outcome(&self) -> String {
        let f = &self.figures;
        let exit = self
            .exit_code
            .map_or("killed".to_string(), |c| format!("exit {c}"));
        let missed = self.missed();
        format!(
            "{exit}, walked {:.3} m ({:.0} %), {}",
            f.walked,
            100.0 * f.walked / f.planned,
            match missed.is_empty() {
                true => "every goal met".to_string(),
                false => format!("missed: {}", missed.join("; ")),
            }
        )
    }

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
        let [ex, ey] = self.true_err.map(|e| e.mean);
        if ex.is_nan() || ex >= goal::ZMP_X {
            out.push(format!("ZMP x {:.1} mm", ex * 1e3));
        }
        if ey.is_nan() || ey >= goal::ZMP_Y {
            out.push(format!("ZMP y {:.1} mm", ey * 1e3));
        }
        out
    }
}

/// The cases of `family` in `shard`, in table order; with `only` non-empty, just the cases of
/// those names (an unknown name is an error).
pub fn shard_cases(
    family: Family,
    shard: Shard,
    only: &[String],
) -> Result<Vec<SweepCase>, String> {
    let all = family.cases();
    if let Some(bad) = only
        .iter()
        .find(|n| !all.iter().any(|c| c.name == n.as_str()))
    {
        let names: Vec<&str> = all.iter().map(|c| c.name).collect();
        return Err(format!(
            "no sweep case '{bad}' in this family (its cases: {})",
            names.join(", ")
        ));
    }
    Ok(all
        .into_iter()
        .enumerate()
        .filter(|(i, c)| shard.has(*i) && (only.is_empty() || only.iter().any(|n| n == c.name)))
        .map(|(_, c)| c)
        .collect())
}

/// Walks `cases` with `opts`, `jobs` at a time, and scores them (in the order given);
/// `progress` counts the finished walks ([`run_cases`]).
pub fn walk_cases(
    opts: &FilOptions,
    cases: &[SweepCase],
    jobs: usize,
    progress: &Progress,
) -> Result<Vec<SweepRow>, String> {
    let variant = beyond::variants()
        .into_iter()
        .find(|v| v.name == "tlipfm")
        .ok_or("no tlipfm variant")?;
    let mut tokens = fil::firmware_tokens(&opts.spec)?;
    tokens.extend(opts.extra_tokens.iter().cloned());
    let cfg = beyond::firmware_config(&tokens)?;
    let walk = |case: &SweepCase| -> Result<SweepRow, String> {
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
        Ok(SweepRow {
            name: case.name.into(),
            what: case.what.into(),
            exit_code: r.exit_code,
            true_err: metrics.true_err,
            figures,
        })
    };
    run_cases(cases, jobs, progress, walk)
}

/// Runs `walk` on every case, `jobs` at a time (each worker takes the next case), and returns
/// the results in the cases' order; `progress` hears of each case as it starts and as it
/// finishes ([`SweepRow::outcome`], or the error), so its k/N counts finished walks.
pub fn run_cases(
    cases: &[SweepCase],
    jobs: usize,
    progress: &Progress,
    walk: impl Fn(&SweepCase) -> Result<SweepRow, String> + Sync,
) -> Result<Vec<SweepRow>, String> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<SweepRow, String>>>> = Mutex::new(vec![None; cases.len()]);
    let worker = || loop {
        let i = next.fetch_add(1, Ordering::SeqCst);
        let Some(case) = cases.get(i) else {
            return;
        };
        progress.start(case.name);
        let row = walk(case);
        let outcome = match &row {
            Ok(r) => r.outcome(),
            Err(e) => format!("error: {e}"),
        };
        progress.finish_case(case.name, &outcome);
        if let Ok(mut res) = results.lock() {
            if let Some(slot) = res.get_mut(i) {
                *slot = Some(row);
            }
        }
    };
    std::thread::scope(|s| {
        for _ in 0..jobs.clamp(1, cases.len().max(1)) {
            s.spawn(worker);
        }
    });
    progress.finish();
    let results = results
        .into_inner()
        .map_err(|_| "a sweep worker panicked")?;
    results
        .into_iter()
        .map(|r| r.unwrap_or_else(|| Err("a sweep case did not run".into())))
        .collect()
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
        let [ex, ey] = r.true_err.map(|e| e.mean * 1e3);
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

    /// The servo family: names unique, the nominal run first and unchanged, every other case
    /// changes the simulated robot, within the ranges, and validates.
    #[test]
    fn the_servo_family_stays_in_its_ranges() {
        let nominal = SimConfig::default();
        let cs = servo_cases();
        assert_eq!(cs[0].name, "nominal");
        let mut names: Vec<_> = cs.iter().map(|c| c.name).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), cs.len());
        for c in cs.iter().skip(1) {
            let mut s = nominal.clone();
            (c.apply)(&mut s);
            let x = &s.xservo;
            assert!(
                format!("{s:?}") != format!("{nominal:?}"),
                "{} changes nothing",
                c.name
            );
            assert!((2.5..=5.0).contains(&x.stall_torque), "{}", c.name);
            assert!((2.5..=4.82).contains(&x.no_load_speed), "{}", c.name);
            assert!(
                (0.6 - 1e-9..=1.4 + 1e-9).contains(&x.gain_scale),
                "{}",
                c.name
            );
            assert!((10.5..=12.6).contains(&x.supply_voltage), "{}", c.name);
            assert!(
                (0.85 - 1e-9..=1.15 + 1e-9).contains(&s.env.mass_scale),
                "{}",
                c.name
            );
            assert!((0.4..=1.0).contains(&s.env.floor_friction), "{}", c.name);
            assert!(
                s.noise.latency_us <= nominal.noise.latency_us + 10_000,
                "{}",
                c.name
            );
            assert!(s.noise.position_latency_us <= 10_000, "{}", c.name);
            assert!(
                (0.0..=0.5f64.to_radians() + 1e-12).contains(&x.backlash),
                "{}",
                c.name
            );
            assert!(s.env.trunk_com_dx_m.abs() <= 0.01 + 1e-12, "{}", c.name);
            s.validate().unwrap_or_else(|e| panic!("{}: {e}", c.name));
        }
        assert_eq!(Family::Servos.cases().len(), cs.len());
        assert_eq!(Family::Reference.cases().len(), cases().len());
    }

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
        SweepRow {
            name: "x".into(),
            what: "y".into(),
            exit_code: Some(0),
            true_err: [e(zmp[0]), e(zmp[1])],
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

    /// The sweep's progress under a pipe (not a terminal): the parallel runner prints one plain
    /// line per case, `[k/N] case: outcome (elapsed …, ETA …)`, k = 1 … N once each however
    /// the three workers interleave, every case named once, no `\r`; the rows come back in
    /// table order and a failed walk is a line too.
    #[test]
    fn sweep_progress_under_a_pipe_prints_one_line_per_case() {
        let cs = servo_cases();
        let buf = crate::progress::SharedBuffer::default();
        let progress = Progress::lines(cs.len(), "walking", Box::new(buf.clone()));
        let rows = run_cases(&cs, 3, &progress, |case| {
            // Uneven durations so that the workers finish out of order.
            let i = cs.iter().position(|c| c.name == case.name).unwrap_or(0);
            std::thread::sleep(std::time::Duration::from_millis(2 + (7 * i as u64) % 11));
            match case.name {
                "friction0.4" => Err("QEMU did not start".into()),
                _ => Ok(SweepRow {
                    name: case.name.into(),
                    ..row(0.26, 1.0, [0.010, 0.013], None)
                }),
            }
        });
        assert_eq!(rows.unwrap_err(), "QEMU did not start");
        let text = buf.text();
        assert!(!text.contains('\r'), "{text:?}");
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), cs.len(), "{text}");
        let n = cs.len();
        for (k, line) in lines.iter().enumerate() {
            let head = format!("[{}/{n}] ", k + 1);
            assert!(line.starts_with(&head), "line {k}: {line}");
            assert!(line.contains(" (elapsed ") && line.ends_with(')'), "{line}");
        }
        assert!(lines[n - 1].ends_with(", done)"), "{text}");
        for c in &cs {
            let named = lines
                .iter()
                .filter(|l| l.contains(&format!("] {}: ", c.name)))
                .count();
            assert_eq!(named, 1, "{}: {text}", c.name);
        }
        assert!(
            text.contains("] friction0.4: error: QEMU did not start ("),
            "{text}"
        );
        assert!(text.contains("] nominal: exit 0, walked 0.260 m (100 %), every goal met ("));
        assert_eq!(progress.counts(), (n, n));
        // Without failures the rows come back in table order.
        let quiet = Progress::lines(cs.len(), "walking", Box::new(std::io::sink()));
        let rows = run_cases(&cs, 4, &quiet, |case| {
            Ok(SweepRow {
                name: case.name.into(),
                ..row(0.26, 1.0, [0.010, 0.013], None)
            })
        })
        .unwrap();
        let names: Vec<_> = rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, cs.map(|c| c.name));
    }

    /// Every case is in exactly one shard of any split, and the shards interleave the list.
    #[test]
    fn shards_partition_the_cases() {
        let n = cases().len();
        for count in 1..=n + 2 {
            for i in 0..n {
                let owners = (1..=count)
                    .filter(|&k| Shard { index: k, count }.has(i))
                    .count();
                assert_eq!(owners, 1, "case {i}, {count} shards");
            }
        }
        assert_eq!(Shard::parse("2/3"), Ok(Shard { index: 2, count: 3 }));
        for bad in ["0/3", "4/3", "1/0", "3", "a/b", "", "1/-2"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        assert!((0..n).all(|i| Shard::ALL.has(i)));
    }

    #[test]
    fn named_cases_are_walked_in_table_order_and_unknown_names_refused() {
        let names = |cs: Vec<SweepCase>| cs.iter().map(|c| c.name).collect::<Vec<_>>();
        let all = shard_cases(Family::Servos, Shard::ALL, &[]).unwrap();
        assert_eq!(all.len(), servo_cases().len());
        let only = ["stiff-weak".to_string(), "nominal".to_string()];
        let two = shard_cases(Family::Servos, Shard::ALL, &only).unwrap();
        assert_eq!(names(two), ["nominal", "stiff-weak"]);
        // The shard and the names both filter: case 0 (nominal) is in shard 1/2 only.
        let half = Shard { index: 2, count: 2 };
        assert!(shard_cases(Family::Servos, half, &only[1..])
            .unwrap()
            .is_empty());
        let Err(e) = shard_cases(Family::Reference, Shard::ALL, &only) else {
            panic!("a servo-family case accepted in the reference family");
        };
        assert!(e.contains("'stiff-weak'") && e.contains("torque-20"), "{e}");
    }

    /// Rows survive the CSV round trip bit for bit, NaN and a fall included, and the merge of
    /// shards gives the table order, names the cases no shard ran and refuses a case twice.
    #[test]
    fn shard_rows_round_trip_and_merge_in_table_order() {
        let named = |name: &str, r: SweepRow| SweepRow {
            name: name.into(),
            ..r
        };
        let a = named("mass+10", row(0.25, -1.5, [0.012, 0.009], Some(7.25)));
        let b = named("nominal", row(0.2731, 0.5, [0.0057, 0.0099], None));
        let c = named("drop5%", row(f64::NAN, f64::NAN, [f64::NAN; 2], None));
        let dir = std::env::temp_dir().join(format!("walker-sweep-rows-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p1 = dir.join("one.csv");
        let p2 = dir.join("two.csv");
        write_rows(&p1, &[a.clone(), c.clone()]).unwrap();
        write_rows(&p2, std::slice::from_ref(&b)).unwrap();
        let back1 = read_rows(&p1).unwrap();
        assert_eq!(back1[0], a);
        assert!(back1[1].figures.walked.is_nan() && back1[1].true_err[1].mean.is_nan());
        assert_eq!(back1[1].name, "drop5%");
        let back2 = read_rows(&p2).unwrap();
        let (rows, missing) = merge(Family::Reference, vec![back1.clone(), back2.clone()]).unwrap();
        let names: Vec<_> = rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["nominal", "mass+10", "drop5%"]);
        assert_eq!(missing.len(), cases().len() - 3);
        assert!(!missing.contains(&"nominal"));
        assert!(merge(Family::Reference, vec![back2.clone(), back2]).is_err());
        assert!(merge(Family::Reference, vec![vec![named("nope", b)]]).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
