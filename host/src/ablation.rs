//! `walker sweep --ablate`: which feedback and feed-forward of the firmware's defaults earns its
//! place on the robots of a family.
//!
//! The family ([`crate::sweep::Family`]) is walked with the defaults and once more per feature
//! of [`FEATURES`] with that feature off (its firmware tokens after the run's own). A feature
//! stays on by default only if, over the whole family, it is nowhere worse than off. Per case,
//! the defaults (`on`) are **worse** than the feature off when
//!
//! ```text
//! on falls and off does not, or
//! neither falls and |walked/planned − 1|_on > |walked/planned − 1|_off + 2 %, or
//! neither falls and a true ZMP mean |e| (x or y) is larger on than off by > 1 mm
//! ```
//!
//! and **better** in the mirror cases. Both falling is neither. The margins (2 % of the
//! distance, 1 mm) are the run-to-run spread of one-knob changes that do not touch the walk
//! (the friction and latency rows of the servo family).

use std::fmt::Write as _;

use crate::sweep::SweepRow;

/// One feature of the defaults and how it is switched off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Feature {
    /// Short name (the sub-folder of the ablation's output).
    pub name: &'static str,
    /// What it is.
    pub what: &'static str,
    /// The firmware tokens that switch it off (docs/parameters.md).
    pub off: &'static [&'static str],
}

/// The defaults' features the ablation switches off one at a time.
pub const FEATURES: [Feature; 9] = [
    Feature {
        name: "gyro",
        what: "gyro damping at the stance ankles and hips",
        off: &["gyro_ankle=0", "gyro_hip=0"],
    },
    Feature {
        name: "compliance",
        what: "servo compliance feed-forward",
        off: &["compliance_roll=0", "compliance_pitch=0"],
    },
    Feature {
        name: "integral",
        what: "Position I Gain on the roll servos",
        off: &["servo_i_roll=0", "servo_i_hip_roll=0"],
    },
    Feature {
        name: "catch",
        what: "catching step and the clock hold",
        off: &["catch_gain=0", "catch_hold_max=0"],
    },
    Feature {
        name: "level",
        what: "swing sole levelling",
        off: &["catch_level_pitch=0", "catch_level_roll=0"],
    },
    Feature {
        name: "landing",
        what: "landing hold on the leg odometry",
        off: &["landing_gain=0"],
    },
    Feature {
        name: "survey",
        what: "deflection integral from the servo survey's softness",
        off: &["deflection_soft=0"],
    },
    Feature {
        name: "gyro-follow",
        what: "gyro gains scaled down on servos the survey reads stiff",
        off: &["gyro_follow=0"],
    },
    Feature {
        name: "stretch",
        what: "timing stretch for the servos' speed",
        off: &["feasibility=off"],
    },
];

/// The sub-folder of the defaults' sweep.
pub const DEFAULTS: &str = "defaults";

/// Margin on the distance share before one run counts as worse, 1 (2 %).
pub const DISTANCE_MARGIN: f64 = 0.02;
/// Margin on a true ZMP mean |e| before one run counts as worse, m.
pub const ZMP_MARGIN: f64 = 0.001;

/// How the defaults compare with one feature off on one case.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Compare {
    /// The defaults are worse (why).
    Worse(String),
    /// The defaults are better (why).
    Better(String),
    /// Within the margins, or both fell.
    Same,
}

fn distance_error(r: &SweepRow) -> f64 {
    (r.figures.walked / r.figures.planned - 1.0).abs()
}

fn fell(r: &SweepRow) -> bool {
    r.figures.fell_at.is_some() || r.exit_code != Some(0)
}

/// `on` (the defaults) against `off` (the feature off) on one case (module doc).
pub fn compare(on: &SweepRow, off: &SweepRow) -> Compare {
    match (fell(on), fell(off)) {
        (true, false) => return Compare::Worse("falls".into()),
        (false, true) => return Compare::Better("stands".into()),
        (true, true) => return Compare::Same,
        (false, false) => {}
    }
    let mut worse = Vec::new();
    let mut better = Vec::new();
    let (d_on, d_off) = (distance_error(on), distance_error(off));
    let share = |r: &SweepRow| 100.0 * r.figures.walked / r.figures.planned;
    let d = format!("distance {:.0} % vs {:.0} %", share(on), share(off));
    // NaN never compares greater: a NaN distance counts as worse.
    if d_on.is_nan() || d_on > d_off + DISTANCE_MARGIN {
        worse.push(d);
    } else if d_off.is_nan() || d_off > d_on + DISTANCE_MARGIN {
        better.push(d);
    }
    for (axis, k) in [("x", 0), ("y", 1)] {
        let (e_on, e_off) = (on.true_err[k].mean, off.true_err[k].mean);
        let e = format!("ZMP {axis} {:.1} vs {:.1} mm", e_on * 1e3, e_off * 1e3);
        if e_on.is_nan() || e_on > e_off + ZMP_MARGIN {
            worse.push(e);
        } else if e_off.is_nan() || e_off > e_on + ZMP_MARGIN {
            better.push(e);
        }
    }
    if !worse.is_empty() {
        Compare::Worse(worse.join(", "))
    } else if !better.is_empty() {
        Compare::Better(better.join(", "))
    } else {
        Compare::Same
    }
}

/// The verdict on one feature over the family.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    /// The feature.
    pub feature: Feature,
    /// Cases where the defaults are worse than the feature off, with why.
    pub worse: Vec<(String, String)>,
    /// Cases where the defaults are better.
    pub better: Vec<(String, String)>,
    /// Cases of the defaults with no row of the feature off.
    pub missing: Vec<String>,
}

impl Verdict {
    /// Whether the feature earns its place: nowhere worse on, every case walked both ways.
    pub fn keeps(&self) -> bool {
        self.worse.is_empty() && self.missing.is_empty()
    }
}

/// The verdict on `feature` from the defaults' rows and the rows with it off (matched by case).
pub fn verdict(feature: Feature, defaults: &[SweepRow], off: &[SweepRow]) -> Verdict {
    let mut v = Verdict {
        feature,
        worse: Vec::new(),
        better: Vec::new(),
        missing: Vec::new(),
    };
    for on in defaults {
        let Some(o) = off.iter().find(|r| r.name == on.name) else {
            v.missing.push(on.name.clone());
            continue;
        };
        match compare(on, o) {
            Compare::Worse(why) => v.worse.push((on.name.clone(), why)),
            Compare::Better(why) => v.better.push((on.name.clone(), why)),
            Compare::Same => {}
        }
    }
    v
}

fn cell(r: Option<&SweepRow>) -> String {
    match r {
        None => "—".into(),
        Some(r) => {
            let share = 100.0 * r.figures.walked / r.figures.planned;
            let [ex, ey] = r.true_err.map(|e| e.mean * 1e3);
            match r.figures.fell_at {
                Some(t) => format!("fell {t:.1} s"),
                None => match r.exit_code {
                    Some(0) => format!("{share:.0} % · {ex:.0} / {ey:.0}"),
                    Some(c) => format!("stopped, exit {c}"),
                    None => "killed".into(),
                },
            }
        }
    }
}

/// The ablation's tables (Markdown): every case under the defaults and each feature off, then
/// the verdict per feature. `offs[i]` are the rows of [`FEATURES`]`[i]` off.
pub fn tables(defaults: &[SweepRow], offs: &[Vec<SweepRow>; FEATURES.len()]) -> String {
    let mut s = String::new();
    let _ = write!(s, "| case | defaults |");
    for f in FEATURES {
        let _ = write!(s, " {} off |", f.name);
    }
    let _ = write!(s, "\n| --- | ---: |");
    for _ in FEATURES {
        let _ = write!(s, " ---: |");
    }
    s.push('\n');
    for on in defaults {
        let _ = write!(s, "| {} | {} |", on.name, cell(Some(on)));
        for rows in offs {
            let _ = write!(s, " {} |", cell(rows.iter().find(|r| r.name == on.name)));
        }
        s.push('\n');
    }
    let _ = writeln!(
        s,
        "\nEach cell: walked / planned · true ZMP mean |e| x / y (mm); or when the robot fell; or the firmware's stop code (a stop counts as a fall in the verdict).\n"
    );
    let _ = writeln!(
        s,
        "| feature | switched off by | defaults worse than off | defaults better than off | verdict |"
    );
    let _ = writeln!(s, "| --- | --- | --- | --- | --- |");
    for (f, rows) in FEATURES.iter().zip(offs) {
        let v = verdict(*f, defaults, rows);
        let list = |xs: &[(String, String)]| {
            if xs.is_empty() {
                "none".to_string()
            } else {
                xs.iter()
                    .map(|(c, why)| format!("{c} ({why})"))
                    .collect::<Vec<_>>()
                    .join("; ")
            }
        };
        let said = if !v.missing.is_empty() {
            format!("not walked: {}", v.missing.join(", "))
        } else if v.keeps() {
            "keep on".into()
        } else {
            "off by default, or fix".into()
        };
        let _ = writeln!(
            s,
            "| {} ({}) | `{}` | {} | {} | {said} |",
            f.name,
            f.what,
            f.off.join(" "),
            list(&v.worse),
            list(&v.better)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::beyond::AxisError;
    use crate::fil::WalkFigures;

    fn row(name: &str, walked: f64, zmp_mm: [f64; 2], fell: Option<f64>) -> SweepRow {
        let e = |mm: f64| AxisError {
            n: 100,
            mean: mm * 1e-3,
            max: 2.0 * mm * 1e-3,
        };
        SweepRow {
            name: name.into(),
            what: String::new(),
            exit_code: Some(if fell.is_some() { 13 } else { 0 }),
            true_err: [e(zmp_mm[0]), e(zmp_mm[1])],
            figures: WalkFigures {
                fell_at: fell,
                walked,
                planned: 0.26,
                heading_drift: 0.0,
                max_tilt: 0.05,
            },
        }
    }

    #[test]
    fn falls_outrank_distance_and_zmp() {
        let stands = row("a", 0.10, [40.0, 30.0], None);
        let falls = row("a", 0.26, [1.0, 1.0], Some(3.0));
        assert_eq!(compare(&falls, &stands), Compare::Worse("falls".into()));
        assert_eq!(compare(&stands, &falls), Compare::Better("stands".into()));
        assert_eq!(compare(&falls, &falls), Compare::Same);
    }

    #[test]
    fn margins_decide_distance_and_zmp() {
        let base = row("a", 0.26, [6.0, 10.0], None);
        // 1.5 % further from the plan and 0.9 mm: within the margins.
        let near = row("a", 0.26 * 1.015, [6.9, 10.9], None);
        assert_eq!(compare(&near, &base), Compare::Same);
        // Overshooting counts like falling short: 105 % is as far as 95 %.
        let over = row("a", 0.26 * 1.05, [6.0, 10.0], None);
        let under = row("a", 0.26 * 0.95, [6.0, 10.0], None);
        assert_eq!(compare(&over, &under), Compare::Same);
        let short = row("a", 0.26 * 0.9, [6.0, 10.0], None);
        assert!(
            matches!(compare(&short, &base), Compare::Worse(w) if w.starts_with("distance 90 %"))
        );
        let lateral = row("a", 0.26, [6.0, 11.5], None);
        assert!(
            matches!(compare(&lateral, &base), Compare::Worse(w) if w == "ZMP y 11.5 vs 10.0 mm")
        );
        assert!(matches!(compare(&base, &lateral), Compare::Better(_)));
        // Worse on one axis and better on another is worse.
        let mixed = row("a", 0.26 * 0.5, [1.0, 1.0], None);
        assert!(matches!(compare(&mixed, &base), Compare::Worse(_)));
        let nan = row("a", f64::NAN, [6.0, 10.0], None);
        assert!(matches!(compare(&nan, &base), Compare::Worse(_)));
    }

    #[test]
    fn a_feature_is_kept_only_if_nowhere_worse_and_every_case_walked() {
        let on = vec![
            row("nominal", 0.27, [6.0, 10.0], None),
            row("weak", 0.15, [50.0, 13.0], None),
        ];
        let off_better_on_weak = vec![
            row("nominal", 0.29, [16.0, 11.0], None),
            row("weak", 0.26, [10.0, 11.0], None),
        ];
        let v = verdict(FEATURES[0], &on, &off_better_on_weak);
        assert!(!v.keeps());
        assert_eq!(v.worse.len(), 1);
        assert_eq!(v.worse[0].0, "weak");
        assert_eq!(v.better.len(), 1);
        assert_eq!(v.better[0].0, "nominal");
        let off_worse = vec![
            row("nominal", 0.29, [16.0, 11.0], None),
            row("weak", 0.10, [60.0, 20.0], Some(4.0)),
        ];
        assert!(verdict(FEATURES[0], &on, &off_worse).keeps());
        let v = verdict(FEATURES[0], &on, &off_worse[..1]);
        assert!(!v.keeps());
        assert_eq!(v.missing, vec!["weak".to_string()]);
        let md = tables(&on, &std::array::from_fn(|_| off_worse.clone()));
        assert!(
            md.contains("| weak | 58 % · 50 / 13 | fell 4.0 s |"),
            "{md}"
        );
        assert!(md.contains("| keep on |"), "{md}");
    }

    #[test]
    fn features_have_distinct_names_and_valid_tokens() {
        let mut names: Vec<_> = FEATURES.iter().map(|f| f.name).collect();
        names.push(DEFAULTS);
        names.sort();
        names.dedup();
        assert_eq!(names.len(), FEATURES.len() + 1);
        for f in FEATURES {
            let tokens: Vec<String> = f.off.iter().map(|t| t.to_string()).collect();
            crate::beyond::firmware_config(&tokens).unwrap_or_else(|e| panic!("{}: {e}", f.name));
        }
    }
}
