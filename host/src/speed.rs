//! `walker speed`: the fastest forward velocity and the fastest turn rate the firmware sustains
//! for [`HOLD_S`] s on the MuJoCo robot, walking on command (docs/command-port.md, "Speed").
//!
//! One run per level: the firmware (no autostart) stands ready; 1 s later the command port gets
//! the level (forward: vx = v; turn: yaw rate ω in place), held until [`HOLD_S`] s after the
//! walk reaches it (the step generator's acceleration limits: v/a + 2 step periods), then stop;
//! the run ends by torque off once the robot stands. Measured over the hold window from the
//! truth (pelvis): the mean speed along the path (m/s) or the mean yaw rate (rad/s).
//!
//! **Sustained** = no fall in the physics, the run ends by the script's torque off (exit
//! `Requested`), and the measured mean is within [`SUSTAIN_TOLERANCE`] of the level, on either
//! side: commanding more than the feet can step (the step generator scales a footprint beyond
//! the leg's reach back to the largest that fits: the *delivered* velocity, reported per run)
//! does not count as walking faster, and neither does a pelvis that runs ahead of its footsteps
//! (steps that land longer than asked, soles that slip or scuff: the robot does not walk at the
//! commanded velocity either). The levels are searched with [`crate::pushes::search`] (climbing in steps of
//! 2·`step`, then the level between the last sustained and the first not: both to `step`).

use std::fmt::Write as _;

use crate::commands::{CommandScript, ScriptCommand};
use crate::fil::{self, FilOptions};
use crate::progress::Progress;
use gait_core::trajectory::command::{CommandLimits, StepGenerator, WalkCommand};
use gait_core::{Robot, Side};
use walker_contract::codes::{ExitCode, FaultKind};
use walker_contract::record::Record;

/// Seconds the level is held once reached.
pub const HOLD_S: f64 = 10.0;
/// Largest deviation of the measured mean from the level, as a share of the level, that still
/// counts as sustained (either side).
pub const SUSTAIN_TOLERANCE: f64 = 0.1;
/// Seconds from standing ready to the command.
const START_S: f64 = 1.0;

/// What is commanded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// Forward velocity vx, m/s.
    Forward,
    /// Yaw rate in place, rad/s.
    Turn,
}

impl Axis {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Axis::Forward => "forward",
            Axis::Turn => "turn",
        }
    }

    /// The walking command of level `v` (m/s or rad/s).
    pub fn command(self, v: f64) -> [f64; 3] {
        match self {
            Axis::Forward => [v, 0.0, 0.0],
            Axis::Turn => [0.0, 0.0, v],
        }
    }
}

/// One run at one level.
#[derive(Clone, Debug, PartialEq)]
pub struct SpeedRun {
    /// The level commanded (m/s or rad/s).
    pub level: f64,
    /// What the step generator steps for it after the reach limits (m/s or rad/s).
    pub delivered: f64,
    /// Measured mean over the hold (m/s or rad/s), `None` if the run fell before the hold ended.
    pub measured: Option<f64>,
    /// When the truth first marked a fall, s.
    pub fell_at: Option<f64>,
    /// The run ended by the script's torque off.
    pub ended_by_command: bool,
}

impl SpeedRun {
    /// The run in a few words (a progress line).
    pub fn outcome(&self) -> String {
        let verdict = match self.sustained() {
            true => "sustained",
            false => "not sustained",
        };
        let fell = match self.fell_at {
            Some(t) if t.is_finite() => format!(", fell at {t:.2} s"),
            Some(_) => ", fell".to_string(),
            None => String::new(),
        };
        let measured = self
            .measured
            .map_or("no mean".to_string(), |m| format!("mean {m:.3}"));
        format!(
            "{verdict} ({measured} for {:.3} delivered{fell})",
            self.delivered
        )
    }

    /// Sustained (see the module docs).
    pub fn sustained(&self) -> bool {
        self.fell_at.is_none()
            && self.ended_by_command
            && self
                .measured
                .is_some_and(|m| (m - self.level).abs() <= SUSTAIN_TOLERANCE * self.level)
    }
}

/// The script of one level: stand, the command at [`START_S`], stop after the ramp (the
/// acceleration limit's time plus three step periods `period_s`) and the hold; returns it and
/// the hold window (s from standing ready).
pub fn script(axis: Axis, level: f64, period_s: f64) -> (CommandScript, (f64, f64)) {
    let l = CommandLimits::DEFAULT;
    let acc = match axis {
        Axis::Forward => l.acc,
        Axis::Turn => l.yaw_acc,
    };
    // Three periods: the start phase, the step under way, and the servo-speed stretch of T.
    let ramp = level / acc + 3.0 * period_s;
    let hold = (START_S + ramp, START_S + ramp + HOLD_S);
    let [vx, vy, vyaw] = axis.command(level);
    let script = CommandScript {
        command: vec![
            ScriptCommand {
                t: 0.0,
                ..Default::default()
            },
            ScriptCommand {
                t: START_S,
                vx,
                vy,
                vyaw,
                ..Default::default()
            },
            ScriptCommand {
                t: hold.1,
                stop: true,
                ..Default::default()
            },
        ],
        enable_after: None,
    };
    (script, hold)
}

/// The velocity the step generator settles at for `axis` at `level` (f32, the firmware's
/// arithmetic): the reach limits' cap.
pub fn delivered(
    robot: &Robot,
    axis: Axis,
    level: f64,
    z_c: f64,
    half_width: f32,
    period_s: f32,
) -> Result<f64, String> {
    let feet = crate::commands::standing_feet(half_width);
    let mut g = StepGenerator::new(
        robot,
        z_c,
        CommandLimits::DEFAULT,
        half_width,
        period_s,
        feet,
        Side::Left,
    )
    .map_err(|e| format!("{e:?}"))?;
    let [vx, vy, w] = axis.command(level).map(|v| v as f32);
    let cmd = WalkCommand {
        vx,
        vy,
        yaw_rate: w,
    };
    for _ in 0..40 {
        g.next_step(&cmd);
    }
    let v = g.velocity();
    Ok(f64::from(match axis {
        Axis::Forward => v[0],
        Axis::Turn => v[2],
    }))
}

/// The mean speed along the pelvis path (forward) or the mean yaw rate (turn) between `t0` and
/// `t1` (s, the truth's clock) from the truth's columns `t`, x, y, yaw.
pub fn measured_mean(
    axis: Axis,
    t: &[f64],
    x: &[f64],
    y: &[f64],
    yaw: &[f64],
    (t0, t1): (f64, f64),
) -> Option<f64> {
    let idx: Vec<usize> = (0..t.len()).filter(|&i| t[i] >= t0 && t[i] <= t1).collect();
    let (&a, &b) = (idx.first()?, idx.last()?);
    let span = t[b] - t[a];
    if span < 0.9 * (t1 - t0) {
        return None;
    }
    Some(match axis {
        Axis::Forward => (x[b] - x[a]).hypot(y[b] - y[a]) / span,
        Axis::Turn => {
            // Unwrapped yaw: sum the wrapped increments.
            let turned: f64 = idx
                .windows(2)
                .map(|w| {
                    let d = yaw[w[1]] - yaw[w[0]];
                    d.sin().atan2(d.cos())
                })
                .sum();
            turned / span
        }
    })
}

/// Options of [`run`].
#[derive(Clone, Debug)]
pub struct SpeedOptions {
    /// The runs: the walk (its timing and width set the online walk's), robot, QEMU;
    /// `out_dir` holds one sub-folder per run and `speed.md`.
    pub base: FilOptions,
    /// Resolution of the forward search, m/s.
    pub step_v: f64,
    /// Resolution of the turn search, rad/s.
    pub step_w: f64,
}

/// One run of `axis` at `level` on the MuJoCo robot.
fn speed_run(opts: &SpeedOptions, axis: Axis, level: f64) -> Result<SpeedRun, String> {
    let mut extra = opts.base.extra_tokens.clone();
    extra.push("autostart=0".into());
    let (_, cfg) = fil::check_tokens(&opts.base.spec, &extra)?;
    let name = format!("{}-{level:.3}", axis.name());
    let fopts = opts.base.in_sub(&name);
    // The online walk's period is the configured (stretched) one, logged as Footstep id 0;
    // the script is made with the configured value first, the delivered speed with the logged.
    let (script, hold) = script(axis, level, cfg.walk.period);
    let deliver = |period: f64| {
        delivered(
            cfg.robot,
            axis,
            level,
            cfg.walk.z_c,
            cfg.walk.step_width as f32,
            period as f32,
        )
    };
    let (r, ready_us) = match fil::run_commands(&fopts, &script, |_, _| {}) {
        Ok((r, d)) => (r, Some(d.ready_us)),
        // A fall ends the firmware before the script does: the driver is aborted (the
        // delivered figure then with the unstretched period).
        Err(e) if e.contains("aborted") => {
            return Ok(SpeedRun {
                level,
                delivered: deliver(cfg.walk.period)?,
                measured: None,
                fell_at: Some(f64::NAN),
                ended_by_command: false,
            })
        }
        Err(e) => return Err(e),
    };
    let log = crate::report::decode_file(&r.log)?;
    let period_us = log.events.iter().find_map(|e| match e {
        Record::Fault(f) if f.kind == FaultKind::Footstep && f.id == 0 => Some(f.value),
        _ => None,
    });
    let delivered = deliver(period_us.map_or(cfg.walk.period, |p| f64::from(p) * 1e-6))?;
    let table = crate::report::read_truth(&r.truth)?;
    let col = |n: &str| {
        table
            .column(n)
            .ok_or_else(|| format!("truth: no column {n}"))
    };
    let fell_at = fil::fell_at(&table)?;
    let ready = ready_us.map_or(0.0, |u| u as f64 * 1e-6);
    let measured = measured_mean(
        axis,
        &table.t,
        col("pelvis_x_m")?,
        col("pelvis_y_m")?,
        col("pelvis_yaw_rad")?,
        (ready + hold.0, ready + hold.1),
    );
    Ok(SpeedRun {
        level,
        delivered,
        measured,
        fell_at,
        ended_by_command: r.exit_code == Some(i32::from(ExitCode::Requested.code())),
    })
}

/// One searched axis.
#[derive(Clone, Debug)]
pub struct SpeedRow {
    /// Forward or turn.
    pub axis: Axis,
    /// Largest level sustained.
    pub sustained: Option<f64>,
    /// Smallest level not sustained.
    pub failed: Option<f64>,
    /// Every run, in order.
    pub runs: Vec<SpeedRun>,
}

/// The axes searched: each with its resolution and its command limit.
fn axes(opts: &SpeedOptions) -> [(Axis, f64, f64); 2] {
    let l = CommandLimits::DEFAULT;
    [
        (Axis::Forward, opts.step_v, l.vx_forward),
        (Axis::Turn, opts.step_w, l.yaw_rate),
    ]
}

/// The most runs [`run`] makes with `opts` (the searches' bound,
/// [`crate::pushes::max_runs`]); a search that ends sooner lowers the count as it ends.
pub fn planned_runs(opts: &SpeedOptions) -> usize {
    axes(opts)
        .iter()
        .map(|&(_, step, max)| crate::pushes::max_runs(step, max))
        .sum()
}

/// Searches both axes up to the command limits; `progress` counts the runs (its total starts
/// at [`planned_runs`] and shrinks as each search ends).
pub fn run(opts: &SpeedOptions, progress: &Progress) -> Result<Vec<SpeedRow>, String> {
    let mut rows = Vec::new();
    for (axis, step, max) in axes(opts) {
        let mut runs = Vec::new();
        let found = crate::pushes::search(step, max, |level| {
            let name = format!("{}-{level:.3}", axis.name());
            progress.start(&name);
            let r = speed_run(opts, axis, level);
            let outcome = match &r {
                Ok(r) => r.outcome(),
                Err(e) => format!("error: {e}"),
            };
            progress.finish_case(&name, &outcome);
            let r = r?;
            let ok = r.sustained();
            runs.push(r);
            Ok(ok)
        })?;
        let bound = crate::pushes::max_runs(step, max);
        let (_, total) = progress.counts();
        progress.set_total(total.saturating_sub(bound.saturating_sub(found.trials.len())));
        rows.push(SpeedRow {
            axis,
            sustained: found.survived,
            failed: found.fell,
            runs,
        });
    }
    progress.finish();
    Ok(rows)
}

/// The table (Markdown): per axis the largest sustained level and every run.
pub fn table(rows: &[SpeedRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| axis | largest sustained | smallest not | runs: commanded → delivered by the steps, measured mean (verdict) |"
    );
    let _ = writeln!(s, "| --- | ---: | ---: | --- |");
    for r in rows {
        let unit = match r.axis {
            Axis::Forward => "m/s",
            Axis::Turn => "rad/s",
        };
        let runs: Vec<String> = r
            .runs
            .iter()
            .map(|x| {
                let why = if x.sustained() {
                    "✓".to_string()
                } else if x.fell_at.is_some() {
                    "✗ fell".to_string()
                } else if !x.ended_by_command {
                    "✗ run did not end by command".to_string()
                } else {
                    format!("✗ off by > {:.0} %", 100.0 * SUSTAIN_TOLERANCE)
                };
                format!(
                    "{:.3} → {:.3}, {} ({why})",
                    x.level,
                    x.delivered,
                    x.measured.map_or("n/a".into(), |m| format!("{m:.3}"))
                )
            })
            .collect();
        let _ = writeln!(
            s,
            "| {} ({unit}) | {} | {} | {} |",
            r.axis.name(),
            r.sustained.map_or("none".into(), |v| format!("{v:.3}")),
            r.failed
                .map_or("beyond the command limit".into(), |v| format!("{v:.3}")),
            runs.join("; ")
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_is_sustained_only_at_the_level_it_asked() {
        let ok = SpeedRun {
            level: 0.1,
            delivered: 0.1,
            measured: Some(0.095),
            fell_at: None,
            ended_by_command: true,
        };
        assert!(ok.sustained());
        // The feet step less than asked (the reach cap): 0.06 of 0.1 is not 0.1 sustained.
        assert!(!SpeedRun {
            measured: Some(0.06),
            ..ok.clone()
        }
        .sustained());
        // Nor does a pelvis that runs ahead of the footsteps (long landings, slipping soles).
        assert!(SpeedRun {
            measured: Some(0.109),
            ..ok.clone()
        }
        .sustained());
        assert!(!SpeedRun {
            measured: Some(0.112),
            ..ok.clone()
        }
        .sustained());
        assert!(!SpeedRun {
            fell_at: Some(7.0),
            ..ok.clone()
        }
        .sustained());
        assert!(!SpeedRun {
            ended_by_command: false,
            ..ok.clone()
        }
        .sustained());
        assert!(!SpeedRun {
            measured: None,
            ..ok
        }
        .sustained());
    }

    #[test]
    fn the_script_holds_the_level_after_the_ramp() {
        let (s, (h0, h1)) = script(Axis::Forward, 0.1, 0.8);
        // Ramp: 0.1 m/s at 0.1 m/s² = 1 s, plus three periods: the hold from 1 + 3.4 s.
        assert!((h0 - 4.4).abs() < 1e-12 && (h1 - h0 - HOLD_S).abs() < 1e-12);
        assert_eq!(s.command.len(), 3);
        assert_eq!(s.command[1].wire(), Ok([100, 0, 0]));
        assert!(s.command[2].stop && (s.command[2].t - h1).abs() < 1e-12);
        let (t, _) = script(Axis::Turn, 0.3, 0.8);
        assert_eq!(t.command[1].wire(), Ok([0, 0, 300]));
        // The scripts pass the parser's checks.
        let text = "[[command]]\nt = 0\n[[command]]\nt = 1\nvx = 0.1\n[[command]]\nt = 14.4\nstop = true\n";
        assert_eq!(CommandScript::parse(text).unwrap().command.len(), 3);
    }

    #[test]
    fn the_delivered_velocity_is_the_reach_cap() {
        // Table 2's z_c and T = 0.64 s: 0.067 m per step at the reach limit (command.rs docs),
        // ≈ 0.105 m/s; 0.05 m/s is within it.
        let slow = delivered(&Robot::reference(), Axis::Forward, 0.05, 0.217, 0.045, 0.64).unwrap();
        assert!((slow - 0.05).abs() < 1e-6, "{slow}");
        let capped =
            delivered(&Robot::reference(), Axis::Forward, 0.2, 0.217, 0.045, 0.64).unwrap();
        assert!(capped > 0.09 && capped < 0.12, "{capped}");
        let turn = delivered(&Robot::reference(), Axis::Turn, 0.2, 0.217, 0.045, 0.64).unwrap();
        assert!((turn - 0.2).abs() < 1e-6, "{turn}");
    }

    #[test]
    fn the_measured_mean_follows_the_pelvis() {
        // 0.08 m/s along 30° for 20 s sampled at 10 ms; a turn at 0.25 rad/s through ±π.
        let t: Vec<f64> = (0..2000).map(|i| f64::from(i) * 0.01).collect();
        let (s, c) = 30f64.to_radians().sin_cos();
        let x: Vec<f64> = t.iter().map(|t| 0.08 * t * c).collect();
        let y: Vec<f64> = t.iter().map(|t| 0.08 * t * s).collect();
        let yaw: Vec<f64> = t
            .iter()
            .map(|t| {
                let a = 0.25 * t;
                a.sin().atan2(a.cos())
            })
            .collect();
        let v = measured_mean(Axis::Forward, &t, &x, &y, &yaw, (5.0, 15.0)).unwrap();
        assert!((v - 0.08).abs() < 1e-9, "{v}");
        let w = measured_mean(Axis::Turn, &t, &x, &y, &yaw, (5.0, 15.0)).unwrap();
        assert!((w - 0.25).abs() < 1e-9, "{w}");
        // A window the truth does not cover (the run ended early): no figure.
        assert_eq!(
            measured_mean(Axis::Forward, &t, &x, &y, &yaw, (15.0, 25.0)),
            None
        );
    }
}
