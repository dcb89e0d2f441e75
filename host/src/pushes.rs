//! `walker pushes`: the largest torso push the firmware survives on the MuJoCo robot, in four
//! directions, while standing and while walking (the closed-loop issue, item 7).
//!
//! A push is a horizontal force on the torso spread over 10 ms ([`crate::sim::Push`]), given by
//! its impulse J (N·s) and its direction in the ground plane (0° forward, 90° left, 180°
//! backward, 270° right).
//!
//! - **Walking**: the plan (default Table 2) walked by the firmware's defaults, the push at
//!   `walk_at` s of simulated time (default 6 s: the middle of single support on the left foot
//!   in Table 2). Survived: no fall in the physics and the firmware ends the walk normally
//!   (exit `PlanDone`).
//! - **Standing**: the firmware without autostart stands ready (State = standing on its command
//!   port), is pushed `stand_after` s later (default 1 s) and is told to stop and turn its torque
//!   off [`STAND_HOLD`] s after standing ready. Survived: no fall and the run ends by that torque
//!   off (exit `Requested`). The time the firmware stands ready comes from a first run
//!   without a push (the same for every run: lock-step, virtual time), which must survive.
//!
//! The search ([`search`]) climbs in coarse steps of 2·`step` from 2·`step` until the first fall
//! or `max`, then tries the level one `step` below that fall: the result is the largest level
//! survived and the smallest level seen to fall, both to within `step`. It assumes that a push
//! harder than one that fell falls too — one run per level, no repetition, so a non-monotone
//! robot (a lucky foot placement) can report more than it reliably survives; every run is
//! listed in the table for that reason.

use std::fmt::Write as _;

use crate::commands::{CommandScript, ScriptCommand};
use crate::fil::{self, FilOptions};
use crate::progress::Progress;
use crate::sim::Push;
use walker_contract::codes::ExitCode;

/// Seconds from standing ready to the stop command in a standing run.
pub const STAND_HOLD: f64 = 3.0;

/// What the robot is doing when pushed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Condition {
    /// Standing ready, on command (no autostart).
    Standing,
    /// Walking the plan.
    Walking,
}

impl Condition {
    /// Lower-case name (also the output sub-folder's prefix).
    pub fn name(self) -> &'static str {
        match self {
            Condition::Standing => "standing",
            Condition::Walking => "walking",
        }
    }
}

/// The four push directions: name and angle in the ground plane, degrees.
pub const DIRECTIONS: [(&str, f64); 4] = [
    ("forward", 0.0),
    ("left", 90.0),
    ("backward", 180.0),
    ("right", 270.0),
];

/// One run of a search: the impulse (N·s) and whether the robot survived it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trial {
    /// Impulse, N·s.
    pub impulse: f64,
    /// Survived (see the module docs).
    pub survived: bool,
}

/// What a search found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SearchResult {
    /// Largest impulse survived, N·s (`None`: even the smallest level fell).
    pub survived: Option<f64>,
    /// Smallest impulse seen to fall, N·s (`None`: survived up to `max`).
    pub fell: Option<f64>,
    /// Every run, in order.
    pub trials: Vec<Trial>,
}

/// The climbing search of the module docs over levels k·`step` (k ≥ 1) up to `max`;
/// `survives(J)` runs one push.
pub fn search(
    step: f64,
    max: f64,
    mut survives: impl FnMut(f64) -> Result<bool, String>,
) -> Result<SearchResult, String> {
    if !(step.is_finite() && step > 0.0 && max.is_finite() && max >= step) {
        return Err(format!("push search: step {step} and max {max} N·s"));
    }
    let kmax = (max / step + 1e-9).floor() as u32;
    let mut out = SearchResult::default();
    let mut run = |k: u32, out: &mut SearchResult| -> Result<bool, String> {
        let impulse = f64::from(k) * step;
        let survived = survives(impulse)?;
        out.trials.push(Trial { impulse, survived });
        Ok(survived)
    };
    // Coarse climb: k = 2, 4, 6, … (the first coarse level is k = 2 unless kmax < 2).
    let mut last_ok = 0u32;
    let mut first_fall = None;
    let mut k = 2.min(kmax);
    while k <= kmax {
        if run(k, &mut out)? {
            last_ok = k;
            if k == kmax {
                break;
            }
            k = (k + 2).min(kmax);
        } else {
            first_fall = Some(k);
            break;
        }
    }
    if let Some(f) = first_fall {
        // The level between the last survived and the first fall, if there is one.
        let mut fell = f;
        if f >= last_ok + 2 {
            let mid = f - 1;
            if run(mid, &mut out)? {
                last_ok = mid;
            } else {
                fell = mid;
            }
        }
        out.fell = Some(f64::from(fell) * step);
    }
    out.survived = (last_ok > 0).then(|| f64::from(last_ok) * step);
    Ok(out)
}

/// The most runs [`search`] makes with `step` and `max` (every coarse level, then the one in
/// between); 0 when it would refuse them.
pub fn max_runs(step: f64, max: f64) -> usize {
    if !(step.is_finite() && step > 0.0 && max.is_finite() && max >= step) {
        return 0;
    }
    let kmax = (max / step + 1e-9).floor() as u32;
    let mut coarse = 0;
    let mut k = 2.min(kmax);
    while k <= kmax {
        coarse += 1;
        if k == kmax {
            break;
        }
        k = (k + 2).min(kmax);
    }
    coarse + 1
}

/// Options of [`run`].
#[derive(Clone, Debug)]
pub struct PushOptions {
    /// The runs: plan, robot (its own pushes are replaced), QEMU; `out_dir` holds one
    /// sub-folder per run and `pushes.md`.
    pub base: FilOptions,
    /// The search's resolution, N·s.
    pub step: f64,
    /// The largest impulse tried, N·s.
    pub max: f64,
    /// When a walking push lands, s of simulated time.
    pub walk_at: f64,
    /// How long after standing ready a standing push lands, s.
    pub stand_after: f64,
    /// Which conditions to search.
    pub conditions: Vec<Condition>,
}

/// One searched case.
#[derive(Clone, Debug)]
pub struct PushRow {
    /// Standing or walking.
    pub condition: Condition,
    /// Direction name.
    pub direction: &'static str,
    /// Direction, degrees.
    pub direction_deg: f64,
    /// When the push landed, s of simulated time.
    pub at_s: f64,
    /// What the search found.
    pub result: SearchResult,
}

/// One push run; `Ok(true)` if the robot survived it.
fn push_run(
    opts: &PushOptions,
    condition: Condition,
    push: Option<Push>,
    name: &str,
) -> Result<(bool, Option<u64>), String> {
    let mut sim = opts.base.sim.clone();
    sim.pushes = push.into_iter().collect();
    let fopts = FilOptions {
        sim,
        ..opts.base.in_sub(name)
    };
    let (r, ready) = match condition {
        Condition::Walking => (fil::run(&fopts, |_, _| {})?, None),
        Condition::Standing => {
            let script = CommandScript {
                command: vec![ScriptCommand {
                    t: STAND_HOLD,
                    stop: true,
                    ..ScriptCommand::default()
                }],
                enable_after: None,
            };
            match fil::run_commands(&fopts, &script, |_, _| {}) {
                Ok((r, d)) => (r, Some(d.ready_us)),
                // A fall ends the firmware before the script does: the driver is aborted.
                Err(e) if e.contains("aborted") => return Ok((false, None)),
                Err(e) => return Err(e),
            }
        }
    };
    let want = match condition {
        Condition::Walking => ExitCode::PlanDone,
        Condition::Standing => ExitCode::Requested,
    };
    Ok((
        r.sim.fall_started_us.is_none() && r.exit_code == Some(i32::from(want.code())),
        ready,
    ))
}

/// The most runs [`run`] makes with `opts`: the standing reference run and, per condition and
/// direction, [`max_runs`]; a search that ends sooner lowers the count as it ends.
pub fn planned_runs(opts: &PushOptions) -> usize {
    let standing = opts.conditions.contains(&Condition::Standing);
    usize::from(standing) + opts.conditions.len() * DIRECTIONS.len() * max_runs(opts.step, opts.max)
}

/// Searches every condition and direction; `progress` counts the runs (its total starts at
/// [`planned_runs`] and shrinks as each search ends).
pub fn run(opts: &PushOptions, progress: &Progress) -> Result<Vec<PushRow>, String> {
    let mut rows = Vec::new();
    let bound = max_runs(opts.step, opts.max);
    for &condition in &opts.conditions {
        let at_s = match condition {
            Condition::Walking => opts.walk_at,
            Condition::Standing => {
                let name = "standing-nopush";
                progress.start(name);
                let r = push_run(opts, condition, None, name);
                let outcome = match &r {
                    Ok((true, Some(ready_us))) => {
                        format!("stood ready at {:.2} s", *ready_us as f64 * 1e-6)
                    }
                    Ok(_) => "did not end by torque off".to_string(),
                    Err(e) => format!("error: {e}"),
                };
                progress.finish_case(name, &outcome);
                match r? {
                    (true, Some(ready_us)) => ready_us as f64 * 1e-6 + opts.stand_after,
                    _ => {
                        return Err(format!(
                            "standing without a push did not end by torque off: see {}",
                            opts.base.out_dir.join(name).display()
                        ))
                    }
                }
            }
        };
        for (direction, deg) in DIRECTIONS {
            let result = search(opts.step, opts.max, |j| {
                let name = format!("{}-{direction}-{j:.2}", condition.name());
                progress.start(&name);
                let push = Push {
                    at_s,
                    impulse_ns: j,
                    direction_rad: deg.to_radians(),
                    duration_s: 0.01,
                };
                let r = push_run(opts, condition, Some(push), &name).map(|(ok, _)| ok);
                let outcome = match &r {
                    Ok(true) => format!("{j:.2} N·s at {at_s:.2} s survived"),
                    Ok(false) => format!("{j:.2} N·s at {at_s:.2} s fell"),
                    Err(e) => format!("error: {e}"),
                };
                progress.finish_case(&name, &outcome);
                r
            })?;
            let (_, total) = progress.counts();
            progress.set_total(total.saturating_sub(bound.saturating_sub(result.trials.len())));
            rows.push(PushRow {
                condition,
                direction,
                direction_deg: deg,
                at_s,
                result,
            });
        }
    }
    progress.finish();
    Ok(rows)
}

/// The table of largest pushes survived (Markdown).
pub fn table(rows: &[PushRow], max: f64) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| condition | direction | push at (s) | largest survived (N·s) | smallest fell (N·s) | runs (N·s: ✓ survived, ✗ fell) |"
    );
    let _ = writeln!(s, "| --- | --- | ---: | ---: | ---: | --- |");
    for r in rows {
        let runs: Vec<String> = r
            .result
            .trials
            .iter()
            .map(|t| format!("{:.2} {}", t.impulse, if t.survived { "✓" } else { "✗" }))
            .collect();
        let _ = writeln!(
            s,
            "| {} | {} ({:.0}°) | {:.2} | {} | {} | {} |",
            r.condition.name(),
            r.direction,
            r.direction_deg,
            r.at_s,
            r.result
                .survived
                .map_or("none".into(), |j| format!("{j:.2}")),
            r.result
                .fell
                .map_or(format!("> {max:.2}"), |j| format!("{j:.2}")),
            runs.join(", ")
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A robot that survives up to `limit` N·s, recording what it was asked.
    fn threshold(limit: f64) -> impl FnMut(f64) -> Result<bool, String> {
        move |j| Ok(j <= limit + 1e-9)
    }

    /// The progress bound is the most runs a search makes: all coarse levels survived, or a
    /// fall at the last coarse level and the level in between.
    #[test]
    fn max_runs_bounds_every_search() {
        for (step, max) in [
            (0.25, 4.0),
            (0.25, 3.75),
            (0.5, 0.5),
            (0.1, 1.0),
            (1.0, 3.0),
        ] {
            let bound = max_runs(step, max);
            let kmax = (max / step + 1e-9).floor() as usize;
            let mut most = 0;
            for limit in 0..=kmax + 1 {
                let r = search(step, max, threshold(limit as f64 * step - step / 2.0)).unwrap();
                most = most.max(r.trials.len());
            }
            assert!(
                most <= bound && bound <= most + 1,
                "{step} {max}: {most} {bound}"
            );
        }
        assert_eq!(max_runs(0.0, 1.0), 0);
    }

    #[test]
    fn search_brackets_a_threshold_to_one_step() {
        // Threshold 1.3: coarse 0.5 ✓ 1.0 ✓ 1.5 ✗, then 1.25 ✓.
        let r = search(0.25, 4.0, threshold(1.3)).unwrap();
        assert_eq!(r.survived, Some(1.25));
        assert_eq!(r.fell, Some(1.5));
        let asked: Vec<f64> = r.trials.iter().map(|t| t.impulse).collect();
        assert_eq!(asked, [0.5, 1.0, 1.5, 1.25]);
        // Threshold 1.1: 1.25 falls too, so the smallest fall is 1.25.
        let r = search(0.25, 4.0, threshold(1.1)).unwrap();
        assert_eq!((r.survived, r.fell), (Some(1.0), Some(1.25)));
        // Every threshold between 0.25 and 3.9: survived ≤ threshold < fell = survived + step.
        for i in 1..156 {
            let limit = 0.25 + 0.0234 * f64::from(i);
            let r = search(0.25, 4.0, threshold(limit)).unwrap();
            let ok = r.survived.unwrap();
            let fell = r.fell.unwrap();
            assert!(ok <= limit + 1e-9 && limit < fell, "{limit}: {r:?}");
            assert!((fell - ok - 0.25).abs() < 1e-9, "{limit}: {r:?}");
            assert!(
                r.trials.len() <= 2 + (limit / 0.5) as usize,
                "{limit}: {r:?}"
            );
        }
    }

    #[test]
    fn search_reports_the_ends() {
        // Falls at the smallest level: 0.5 ✗, 0.25 ✗.
        let r = search(0.25, 4.0, threshold(0.1)).unwrap();
        assert_eq!((r.survived, r.fell), (None, Some(0.25)));
        assert_eq!(r.trials.len(), 2);
        // Survives everything up to max (odd number of steps: the last level is max itself).
        let r = search(0.25, 1.75, threshold(9.0)).unwrap();
        assert_eq!((r.survived, r.fell), (Some(1.75), None));
        let asked: Vec<f64> = r.trials.iter().map(|t| t.impulse).collect();
        assert_eq!(asked, [0.5, 1.0, 1.5, 1.75]);
        // Errors pass through; bad ranges are refused.
        assert!(search(0.25, 4.0, |_| Err("x".into())).is_err());
        assert!(search(0.0, 4.0, threshold(1.0)).is_err());
        assert!(search(0.5, 0.25, threshold(1.0)).is_err());
        assert!(search(f64::NAN, 4.0, threshold(1.0)).is_err());
    }

    #[test]
    fn the_table_lists_every_run() {
        let rows = [PushRow {
            condition: Condition::Walking,
            direction: "backward",
            direction_deg: 180.0,
            at_s: 6.0,
            result: search(0.25, 4.0, threshold(1.3)).unwrap(),
        }];
        let t = table(&rows, 4.0);
        assert!(
            t.contains("| walking | backward (180°) | 6.00 | 1.25 | 1.50 | 0.50 ✓, 1.00 ✓, 1.50 ✗, 1.25 ✓ |"),
            "{t}"
        );
    }
}
