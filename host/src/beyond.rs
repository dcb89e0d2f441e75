//! `walker beyond`: the paper's open-loop methods and the two additions beyond it (whole-body
//! compensation, the feedback stabilizer) walked side by side in the firmware-in-the-loop setup, scored against the simulator's ground truth.
//!
//! Six runs of the same plan: LIPM, DLIPM, TLIPFM (the paper's pipeline, seed 000's exact CoM),
//! TLIPFM with seed 001's Fourier CoM (`com=fourier`, `gait_core::trajectory::fourier_walk`), TLIPFM +
//! whole-body compensation (`comp=wholebody`), TLIPFM + compensation + the feedback stabilizer
//! (`comp=wholebody stab=on`). The simulator's servos are XM430-class: speed limit 4.8 rad/s
//! (`SimConfig::servo_speed_limit`) and the torque–speed line of a 3.5 N·m stall torque with
//! 4.8 rad/s no-load speed (`SimConfig::servo_torque`, [`crate::sim::servo`]; `--stall-torque`
//! changes it, 0 turns it off).
//!
//! Per run, over the walking ticks (the log's support phase double / single, lead-in and
//! lead-out standing excluded), with the truth sampled at each tick's time (nearest row at or
//! before it, `report::TruthTable::at`):
//! * ZMP error against the firmware's reference: mean and max |e| per axis for the true ZMP
//!   (truth.csv) and for the measured one (foot sensors, ticks with a valid measurement);
//! * the fraction of walking ticks whose true ZMP is inside the support polygon of the plan's
//!   sample at that tick with a 5 mm margin (`gait_core::measure::support`; the k-th walking tick of the
//!   log is the k-th sample of the firmware's sampler, rebuilt here from the same tokens and
//!   the start-up timing adjustment);
//! * distance walked: truth pelvis x at the last gait sample the firmware commanded minus at
//!   the first (before torque off), against the plan's CoM travel over the same samples;
//! * peak joint speeds: the simulator's (true joint speeds over the walking ticks, at the truth
//!   rows) and those of the firmware's own joint targets for the walk it ran (its pipeline run
//!   on the host at dt, `gait_core::gait::dry_run`: no τ, no feedback shift — the shift
//!   is rate-limited to `stab_rate`);
//! * servo load: the peak |motor torque| per joint over the walking ticks and the fraction of
//!   walking ticks at which some motor was at its torque bound.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use gait_core::gait::{self, stretched, support_of, Targets};
use gait_core::robot::{JOINT_NAMES, LEG_JOINTS};
use gait_core::SupportPhase as PlanPhase;
use walker_contract::config::MAX_STEPS;
use walker_contract::record::{FaultKind, LoggedPhase, Record, POS_NA};
use walker_contract::{params, Config};

use crate::fil::{self, FilOptions};
use crate::planfile::{ComName, CompensationName, ModelName, WalkSpec};
use crate::report::{self, tick_rows};
use crate::sim::{ServoTorque, SimConfig};

/// XM430-class no-load speed, rad/s.
pub const XM430_SPEED_RAD_S: f64 = 4.8;
/// Margin of the "inside the support polygon" statistic, m.
pub const INSIDE_MARGIN_M: f64 = 0.005;

/// One of the six runs.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// Short name (also the output sub-folder).
    pub name: &'static str,
    /// Pendulum model.
    pub model: ModelName,
    /// CoM solver.
    pub com: ComName,
    /// Whole-body compensation.
    pub compensation: CompensationName,
    /// Feedback stabilizer.
    pub stabilizer: bool,
    /// Firmware tokens of this run, after the options' own (the ablation's feedback switches).
    pub tokens: &'static [&'static str],
}

/// The six runs of the report, in table order.
pub fn variants() -> [Variant; 6] {
    let v = |name, model, com, compensation, stabilizer| Variant {
        name,
        model,
        com,
        compensation,
        stabilizer,
        tokens: &[],
    };
    use ComName::{Exact, Fourier};
    use CompensationName::{None as Plain, Wholebody};
    [
        v("lipm", ModelName::Lipm, Exact, Plain, false),
        v("dlipm", ModelName::Dlipm, Exact, Plain, false),
        v("tlipfm", ModelName::Tlipfm, Exact, Plain, false),
        v("tlipfm-fourier", ModelName::Tlipfm, Fourier, Plain, false),
        v("tlipfm-wb", ModelName::Tlipfm, Exact, Wholebody, false),
        v("tlipfm-wb-fb", ModelName::Tlipfm, Exact, Wholebody, true),
    ]
}

/// The firmware's feedback switched off: no gyro damping, no compliance feed-forward and the
/// servos' factory Position I Gain, no catching step, no swing sole levelling, no landing hold, no
/// deflection integral from the servo survey (the paper's open
/// loop, as in `plans/table2-paper.toml` but at the plan's timing; `walker fil --open-loop`).
/// In the ablation's order: each part's switches after those of the part added before it, so
/// that the ablation's runs are its tails ([`still_off_from`]).
pub const OPEN_LOOP: &[&str] = &[
    "gyro_ankle=0",
    "gyro_hip=0",
    "compliance_roll=0",
    "compliance_pitch=0",
    "servo_i_roll=0",
    "servo_i_hip_roll=0",
    "catch_gain=0",
    "catch_level_pitch=0",
    "catch_level_roll=0",
    "landing_gain=0",
    "deflection_soft=0",
];

/// The tail of [`OPEN_LOOP`] from the switch `first` on: the parts not added yet when the
/// ablation has added every part before it (empty if `first` is not a switch of it).
fn still_off_from(first: &str) -> &'static [&'static str] {
    let at = OPEN_LOOP
        .iter()
        .position(|t| *t == first)
        .unwrap_or(OPEN_LOOP.len());
    OPEN_LOOP.split_at(at).1
}

/// The ablation of the closed-loop issue (item 4), in table order: the paper's three models
/// open loop, then TLIPFM with each part of the closed loop added in turn — gyro damping at
/// the ankles, at the hips (the gains are the firmware's defaults), the servos' compliance
/// handling (the feed-forward of their sag and the roll servos' Position I Gain), the catching
/// step, the swing sole kept level, the landing hold on the leg odometry, the deflection
/// integral from the servo survey (this run is the firmware's default), whole-body compensation
/// of the swing leg, the DCM/ZMP stabilizer.
pub fn ablation() -> [Variant; 12] {
    let v = |name, model, compensation, stabilizer, tokens| Variant {
        name,
        model,
        com: ComName::Exact,
        compensation,
        stabilizer,
        tokens,
    };
    use CompensationName::{None as Plain, Wholebody};
    use ModelName::{Dlipm, Lipm, Tlipfm};
    [
        v("lipm-open", Lipm, Plain, false, OPEN_LOOP),
        v("dlipm-open", Dlipm, Plain, false, OPEN_LOOP),
        v("tlipfm-open", Tlipfm, Plain, false, OPEN_LOOP),
        v(
            "+gyro-ankle",
            Tlipfm,
            Plain,
            false,
            still_off_from("gyro_hip=0"),
        ),
        v(
            "+gyro-hip",
            Tlipfm,
            Plain,
            false,
            still_off_from("compliance_roll=0"),
        ),
        v(
            "+compliance",
            Tlipfm,
            Plain,
            false,
            still_off_from("catch_gain=0"),
        ),
        v(
            "+catching step",
            Tlipfm,
            Plain,
            false,
            still_off_from("catch_level_pitch=0"),
        ),
        v(
            "+sole levelling",
            Tlipfm,
            Plain,
            false,
            still_off_from("landing_gain=0"),
        ),
        v(
            "+landing hold",
            Tlipfm,
            Plain,
            false,
            still_off_from("deflection_soft=0"),
        ),
        v("+servo survey (default)", Tlipfm, Plain, false, &[]),
        v("+wholebody", Tlipfm, Wholebody, false, &[]),
        v("+stabilizer", Tlipfm, Wholebody, true, &[]),
    ]
}

impl Variant {
    /// `base` walked as this variant (model, CoM solver, compensation, stabilizer).
    pub fn spec(&self, base: &WalkSpec) -> WalkSpec {
        WalkSpec {
            model: self.model,
            com: self.com,
            compensation: self.compensation,
            stabilizer: self.stabilizer,
            ..base.clone()
        }
    }
}

/// Mean and max |e| of one axis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AxisError {
    /// Samples.
    pub n: usize,
    /// Mean |e|, m.
    pub mean: f64,
    /// Max |e|, m.
    pub max: f64,
}

impl AxisError {
    /// From the errors (NaN skipped).
    pub fn of(e: impl Iterator<Item = f64>) -> Self {
        let (mut n, mut sum, mut max) = (0usize, 0.0, 0.0f64);
        for v in e.filter(|v| v.is_finite()) {
            n += 1;
            sum += v.abs();
            max = max.max(v.abs());
        }
        AxisError {
            n,
            mean: if n > 0 { sum / n as f64 } else { f64::NAN },
            max: if n > 0 { max } else { f64::NAN },
        }
    }
}

/// The numbers of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct RunMetrics {
    /// The variant.
    pub variant: Variant,
    /// Firmware exit code.
    pub exit_code: Option<i32>,
    /// The simulator saw a fall (time, s).
    pub fell_at: Option<f64>,
    /// Timing factor applied at start-up (1 = the plan's timing).
    pub timing_factor: f64,
    /// True ZMP − reference, x and y.
    pub true_err: [AxisError; 2],
    /// Measured ZMP − reference, x and y.
    pub meas_err: [AxisError; 2],
    /// Fraction of walking ticks with the true ZMP inside the support polygon (5 mm margin).
    pub inside: f64,
    /// Walking ticks scored.
    pub walking_ticks: usize,
    /// Truth pelvis x travel, m.
    pub walked: f64,
    /// Planned CoM x travel, m.
    pub planned: f64,
    /// Peak joint speed of the firmware's targets per joint, rad/s.
    pub peak_speed: [f64; LEG_JOINTS],
    /// Peak true joint speed per joint (both legs), rad/s (NaN: no truth columns).
    pub true_peak_speed: [f64; LEG_JOINTS],
    /// Peak |motor torque| per joint (both legs), N·m (NaN: no torque model).
    pub peak_torque: [f64; LEG_JOINTS],
    /// Fraction of walking ticks with some motor at its torque bound.
    pub torque_limited: f64,
    /// Reference samples that disagreed with the host's rebuild of the firmware's sampler.
    pub ref_mismatch: usize,
    /// Pelvis yaw at the end minus at the start, rad (NaN: not read).
    pub heading_drift: f64,
    /// Largest torso tilt from the vertical, rad (NaN: not read).
    pub max_tilt: f64,
}

/// The largest entry of a per-joint array and its joint's name (NaN entries skipped).
fn worst(per_joint: &[f64; LEG_JOINTS]) -> (&'static str, f64) {
    let (j, v) = per_joint
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .fold((usize::MAX, f64::NAN), |a, (j, &v)| {
            if a.1.is_nan() || v > a.1 {
                (j, v)
            } else {
                a
            }
        });
    (JOINT_NAMES.get(j).copied().unwrap_or("–"), v)
}

impl RunMetrics {
    /// The joint with the fastest target: (name, rad/s).
    pub fn worst_joint(&self) -> (&'static str, f64) {
        worst(&self.peak_speed)
    }

    /// The joint with the fastest true motion: (name, rad/s).
    pub fn worst_true_joint(&self) -> (&'static str, f64) {
        worst(&self.true_peak_speed)
    }

    /// The most loaded joint: (name, N·m).
    pub fn worst_torque_joint(&self) -> (&'static str, f64) {
        worst(&self.peak_torque)
    }
}

/// The firmware configuration the tokens give (as the firmware parses them).
pub fn firmware_config(tokens: &[String]) -> Result<Config, String> {
    let mut cfg = Config::default();
    let (tokens, _) = fil::merge_tokens(tokens.to_vec());
    let line = tokens.join(" ");
    params::apply(&mut cfg, line.as_bytes()).map_err(|e| fil::token_error(&e, &tokens))?;
    Ok(cfg)
}

/// `cfg` with the start-up timing adjustments the log reports (stretch factor, lowered swing).
pub fn adjusted_config(cfg: &Config, events: &[Record]) -> Config {
    let mut out = *cfg;
    for e in events {
        if let Record::Fault(f) = e {
            match f.kind {
                FaultKind::TimingStretched => {
                    out.walk = stretched(&cfg.walk, f.value.max(1) as u32);
                }
                FaultKind::SwingLowered => out.walk.h_z = f64::from(f.value.max(0)) * 1e-6,
                _ => {}
            }
        }
    }
    out
}

/// The plan file's walk with the start-up timing adjustments the log reports (for the
/// report's support bounds).
pub fn adjusted_spec(spec: &WalkSpec, events: &[Record]) -> WalkSpec {
    let mut out = spec.clone();
    for e in events {
        if let Record::Fault(f) = e {
            match f.kind {
                FaultKind::TimingStretched => {
                    let k = f64::from(f.value.max(1)) / 1000.0;
                    out.t1 = spec.t1 * k;
                    out.t2 = spec.t2 * k;
                    out.period = spec.period * k;
                }
                FaultKind::SwingLowered => out.h_z = f64::from(f.value.max(0)) * 1e-6,
                _ => {}
            }
        }
    }
    out
}

/// Truth columns used here.
#[derive(Clone, Debug, Default)]
struct TruthRows {
    t: Vec<f64>,
    zmp: Vec<[f64; 2]>,
    pelvis_x: Vec<f64>,
    /// Joint speeds by servo ID − 1, rad/s (NaN when the column is missing).
    joint_speed: Vec<[f64; 12]>,
    /// Motor torques by servo ID − 1, N·m (NaN: no torque model or missing).
    joint_torque: Vec<[f64; 12]>,
    /// Bitmask of motors at their torque bound.
    torque_limited: Vec<u16>,
}

impl TruthRows {
    fn index_at(&self, t: f64) -> Option<usize> {
        let (first, last) = (*self.t.first()?, *self.t.last()?);
        if t < first - 1e-9 || t > last + 1e-9 {
            return None;
        }
        Some(self.t.partition_point(|&v| v <= t + 1e-9).saturating_sub(1))
    }
}

/// The truth columns scored here, read through the one truth reader ([`report::read_truth`]).
fn read_truth(path: &Path) -> Result<TruthRows, String> {
    let table = report::read_truth(path)?;
    let pelvis_x = table
        .column("pelvis_x_m")
        .ok_or_else(|| format!("{}: no column pelvis_x_m", path.display()))?
        .to_vec();
    let n = table.t.len();
    // Optional (older truth files lack them): NaN.
    let per_joint = |name: fn(usize) -> String| -> Vec<[f64; 12]> {
        let cols: [Option<&[f64]>; 12] = std::array::from_fn(|j| table.column(&name(j + 1)));
        (0..n)
            .map(|i| {
                std::array::from_fn(|j| cols[j].and_then(|c| c.get(i)).copied().unwrap_or(f64::NAN))
            })
            .collect()
    };
    let joint_speed = per_joint(crate::sim::truth::joint_speed_column);
    let joint_torque = per_joint(crate::sim::truth::joint_torque_column);
    let lim = table.column("tq_limited");
    let torque_limited = (0..n)
        .map(|i| {
            lim.and_then(|c| c.get(i))
                .filter(|v| v.is_finite() && **v >= 0.0 && **v <= f64::from(u16::MAX))
                .map_or(0, |v| *v as u16)
        })
        .collect();
    Ok(TruthRows {
        t: table.t,
        zmp: table.zmp,
        pelvis_x,
        joint_speed,
        joint_torque,
        torque_limited,
    })
}

/// Scores one finished run (log + truth) of `cfg`'s walk (the tokens the firmware got).
pub fn score(
    variant: &Variant,
    cfg: &Config,
    log_path: &Path,
    truth_path: &Path,
    exit_code: Option<i32>,
    fell_at: Option<f64>,
) -> Result<RunMetrics, String> {
    let robot = *cfg.robot;
    let log = report::decode_file(log_path)?;
    let truth = read_truth(truth_path)?;
    let cfg = adjusted_config(cfg, &log.events);
    let timing_factor = stretch_factor(&log.events);
    let targets = Targets::new(&robot, cfg.compensation);
    let walk = cfg.walk_config();
    let dry = gait::dry_run::<MAX_STEPS>(&walk, &robot, &targets).map_err(|e| e.to_string())?;
    let mut sampler = gait::build_sampler::<MAX_STEPS>(&walk, &robot).map_err(|e| e.to_string())?;
    let rows = tick_rows(&log.ticks);

    let (mut te, mut me) = ([vec![], vec![]], [vec![], vec![]]);
    let (mut inside, mut walking, mut mismatch) = (0usize, 0usize, 0usize);
    let mut true_peak_speed = [f64::NAN; LEG_JOINTS];
    let mut peak_torque = [f64::NAN; LEG_JOINTS];
    let mut limited_ticks = 0usize;
    let peak = |acc: &mut [f64; LEG_JOINTS], v: &[f64; 12]| {
        for (j, x) in v.iter().enumerate() {
            let a = &mut acc[j % LEG_JOINTS];
            if x.is_finite() && (a.is_nan() || x.abs() > *a) {
                *a = x.abs();
            }
        }
    };
    let (mut first_com, mut last_com) = (None, None);
    let (mut t_first, mut t_last) = (None, None);
    for r in rows.iter().filter(|r| r.rec.zmp_ref[0] != POS_NA) {
        if sampler.is_done() {
            break;
        }
        let g = sampler.next(0.0);
        t_first.get_or_insert(r.t);
        t_last = Some(r.t);
        first_com.get_or_insert(g.com[0]);
        last_com = Some(g.com[0]);
        let walk_phase = matches!(
            r.rec.phase,
            LoggedPhase::Double | LoggedPhase::SingleLeft | LoggedPhase::SingleRight
        );
        if (f64::from(g.zmp[0]) - r.zmp_ref[0]).abs() > 1e-3
            || (f64::from(g.zmp[1]) - r.zmp_ref[1]).abs() > 1e-3
            || walk_phase != (g.phase != PlanPhase::Standing)
        {
            mismatch += 1;
        }
        if !walk_phase {
            continue;
        }
        walking += 1;
        let Some(i) = truth.index_at(r.t) else {
            continue;
        };
        let z = truth.zmp[i];
        peak(&mut true_peak_speed, &truth.joint_speed[i]);
        peak(&mut peak_torque, &truth.joint_torque[i]);
        if truth.torque_limited[i] != 0 {
            limited_ticks += 1;
        }
        for k in 0..2 {
            te[k].push(z[k] - r.zmp_ref[k]);
            if let Some(m) = r.measured() {
                me[k].push(m[k] - r.zmp_ref[k]);
            }
        }
        if let Some(poly) = support_of(&robot, &g) {
            if poly.contains_with_margin([z[0] as f32, z[1] as f32], INSIDE_MARGIN_M as f32) {
                inside += 1;
            }
        }
    }
    // The rest of the plan (the final hold) for the planned travel.
    while !sampler.is_done() {
        last_com = Some(sampler.next(0.0).com[0]);
    }
    // From the first to the last gait sample the firmware commanded (torque is off later).
    let pelvis_at = |t: Option<f64>| {
        t.and_then(|t| truth.index_at(t))
            .and_then(|i| truth.pelvis_x.get(i).copied())
    };
    let walked = match (pelvis_at(t_first), pelvis_at(t_last)) {
        (Some(a), Some(b)) => b - a,
        _ => f64::NAN,
    };
    let ax = |v: &Vec<f64>| AxisError::of(v.iter().copied());
    Ok(RunMetrics {
        variant: variant.clone(),
        exit_code,
        fell_at,
        timing_factor,
        true_err: [ax(&te[0]), ax(&te[1])],
        meas_err: [ax(&me[0]), ax(&me[1])],
        inside: if walking > 0 {
            inside as f64 / walking as f64
        } else {
            f64::NAN
        },
        walking_ticks: walking,
        walked,
        planned: match (first_com, last_com) {
            (Some(a), Some(b)) => f64::from(b - a),
            _ => f64::NAN,
        },
        peak_speed: dry.peak_speed,
        true_peak_speed,
        peak_torque,
        torque_limited: if walking > 0 {
            limited_ticks as f64 / walking as f64
        } else {
            f64::NAN
        },
        ref_mismatch: mismatch,
        heading_drift: f64::NAN,
        max_tilt: f64::NAN,
    })
}

/// The start-up stretch factor the log reports (1 when none).
pub fn stretch_factor(events: &[Record]) -> f64 {
    events
        .iter()
        .find_map(|e| match e {
            Record::Fault(f) if f.kind == FaultKind::TimingStretched => {
                Some(f64::from(f.value) / 1000.0)
            }
            _ => None,
        })
        .unwrap_or(1.0)
}

/// Options of [`run`].
#[derive(Clone, Debug)]
pub struct BeyondOptions {
    /// Firmware ELF.
    pub elf: PathBuf,
    /// The plan.
    pub spec: WalkSpec,
    /// Output folder (one sub-folder per run, `beyond.md`, `beyond.csv`).
    pub out_dir: PathBuf,
    /// QEMU machine.
    pub machine: String,
    /// Simulator seed.
    pub seed: u64,
    /// Extra firmware tokens for every run (e.g. `feasibility=off`).
    pub extra_tokens: Vec<String>,
    /// Extra firmware tokens for the feedback run only (e.g. gains).
    pub feedback_tokens: Vec<String>,
    /// Wall-clock limit per run.
    pub timeout: Duration,
    /// The simulator's servo torque model (`None`: unlimited torque).
    pub servo_torque: Option<ServoTorque>,
    /// The simulated robot (physics, floor, pushes); seed and servo torque are set per run
    /// from the fields above.
    pub sim: SimConfig,
}

/// Walks `variants` ([`variants`] or [`ablation`]) and scores them; `progress` counts the
/// finished walks.
pub fn run(
    opts: &BeyondOptions,
    variants: &[Variant],
    progress: &crate::progress::Progress,
) -> Result<Vec<RunMetrics>, String> {
    // Every variant's firmware command line is checked before the first run starts.
    let runs = variants
        .iter()
        .cloned()
        .map(|v| {
            let spec = v.spec(&opts.spec);
            let mut extra = opts.extra_tokens.clone();
            extra.extend(v.tokens.iter().map(|t| t.to_string()));
            if v.stabilizer {
                extra.extend(opts.feedback_tokens.iter().cloned());
            }
            let (_, cfg) =
                fil::check_tokens(&spec, &extra).map_err(|e| format!("run {}: {e}", v.name))?;
            Ok((v, spec, extra, cfg))
        })
        .collect::<Result<Vec<_>, String>>()?;
    let mut out = Vec::new();
    for (v, spec, extra, cfg) in runs {
        progress.start(v.name);
        let sim = SimConfig {
            seed: opts.seed,
            servo_speed_limit: XM430_SPEED_RAD_S,
            servo_torque: opts.servo_torque,
            ..opts.sim.clone()
        };
        let fopts = FilOptions {
            elf: opts.elf.clone(),
            spec,
            out_dir: opts.out_dir.join(v.name),
            machine: opts.machine.clone(),
            timeout: opts.timeout,
            sim,
            extra_tokens: extra,
        };
        let scored = walk_and_score(&v, &cfg, &fopts);
        match &scored {
            Ok(m) => progress.finish_case(v.name, &m.outcome()),
            Err(e) => progress.finish_case(v.name, &format!("error: {e}")),
        }
        out.push(scored?);
    }
    progress.finish();
    Ok(out)
}

/// One walk of `run` and its scores.
fn walk_and_score(v: &Variant, cfg: &Config, fopts: &FilOptions) -> Result<RunMetrics, String> {
    let r = fil::run(fopts, |_, _| {})?;
    let fell = r.sim.fall_started_us.map(|t| t as f64 * 1e-6);
    let mut m = score(v, cfg, &r.log, &r.truth, r.exit_code, fell)?;
    let f = fil::walk_figures(&r.truth, &fopts.spec)?;
    m.heading_drift = f.heading_drift;
    m.max_tilt = f.max_tilt;
    Ok(m)
}

impl RunMetrics {
    /// The run in a few words (a progress line): exit or fall, true ZMP error, distance.
    pub fn outcome(&self) -> String {
        let exit = match (self.exit_code, self.fell_at) {
            (_, Some(t)) => format!("fell at {t:.2} s"),
            (Some(c), None) => format!("exit {c}"),
            (None, None) => "killed".into(),
        };
        format!(
            "{exit}, true ZMP mean |e| x / y {} / {} mm, walked {:.3} of {:.3} m",
            mm(self.true_err[0].mean),
            mm(self.true_err[1].mean),
            self.walked,
            self.planned
        )
    }
}

fn mm(v: f64) -> String {
    if v.is_finite() {
        format!("{:.1}", v * 1e3)
    } else {
        "–".into()
    }
}

/// Header of `beyond.csv`: units as name suffixes (`_frac`: a fraction of the walking ticks);
/// an absent value (no fall, no truth column, no torque model) is an empty field.
pub const CSV_HEADER: &str = "run,exit_code,fell_at_s,timing_factor,true_mean_x_m,true_mean_y_m,true_max_x_m,true_max_y_m,meas_mean_x_m,meas_mean_y_m,meas_max_x_m,meas_max_y_m,inside_frac,walking_ticks,walked_m,planned_m,peak_speed_max_rad_s,true_peak_speed_max_rad_s,peak_torque_max_nm,torque_limited_frac,ref_mismatch,heading_drift_rad,max_tilt_rad";

/// The side-by-side table (Markdown).
pub fn table(runs: &[RunMetrics]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| run | exit | timing × | true ZMP mean \\|e\\| x / y (mm) | true max \\|e\\| x / y (mm) | measured mean \\|e\\| x / y (mm) | measured max x / y (mm) | true ZMP inside (5 mm margin) | walked / planned (m) | heading drift | torso tilt max | peak joint speed, true / target (rad/s) | peak motor torque (N·m) | time at torque bound |"
    );
    let _ = writeln!(
        s,
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- | ---: |"
    );
    let num = |v: f64, d: usize| {
        if v.is_finite() {
            format!("{v:.d$}")
        } else {
            "–".into()
        }
    };
    for r in runs {
        let (jn, jv) = r.worst_joint();
        let (tn, tv) = r.worst_true_joint();
        let (qn, qv) = r.worst_torque_joint();
        let exit = match (r.exit_code, r.fell_at) {
            (c, Some(t)) => format!("{c:?}, fell {t:.2} s"),
            (Some(c), None) => c.to_string(),
            (None, None) => "killed".into(),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {:.3} | {} / {} | {} / {} | {} / {} | {} / {} | {:.1} % | {:.3} / {:.3} | {}° | {}° | {} ({}) / {:.2} ({}) | {} ({}) | {} % |",
            r.variant.name,
            exit,
            r.timing_factor,
            mm(r.true_err[0].mean),
            mm(r.true_err[1].mean),
            mm(r.true_err[0].max),
            mm(r.true_err[1].max),
            mm(r.meas_err[0].mean),
            mm(r.meas_err[1].mean),
            mm(r.meas_err[0].max),
            mm(r.meas_err[1].max),
            r.inside * 100.0,
            r.walked,
            r.planned,
            num(r.heading_drift.to_degrees(), 1),
            num(r.max_tilt.to_degrees(), 1),
            num(tv, 2),
            tn,
            jv,
            jn,
            num(qv, 2),
            qn,
            num(r.torque_limited * 100.0, 1)
        );
    }
    s
}

/// One CSV row per run (written with the `csv` crate).
pub fn csv(runs: &[RunMetrics]) -> String {
    let mut out = ::csv::Writer::from_writer(Vec::new());
    let n = report::csv_number;
    let mut rows = vec![CSV_HEADER.split(',').map(String::from).collect::<Vec<_>>()];
    for r in runs {
        rows.push(vec![
            r.variant.name.to_string(),
            r.exit_code.map_or(String::new(), |c| c.to_string()),
            r.fell_at.map_or(String::new(), |t| n(t, 3)),
            n(r.timing_factor, 4),
            n(r.true_err[0].mean, 6),
            n(r.true_err[1].mean, 6),
            n(r.true_err[0].max, 6),
            n(r.true_err[1].max, 6),
            n(r.meas_err[0].mean, 6),
            n(r.meas_err[1].mean, 6),
            n(r.meas_err[0].max, 6),
            n(r.meas_err[1].max, 6),
            n(r.inside, 4),
            r.walking_ticks.to_string(),
            n(r.walked, 4),
            n(r.planned, 4),
            n(r.worst_joint().1, 3),
            n(r.worst_true_joint().1, 3),
            n(r.worst_torque_joint().1, 3),
            n(r.torque_limited, 4),
            r.ref_mismatch.to_string(),
            n(r.heading_drift, 4),
            n(r.max_tilt, 4),
        ]);
    }
    for row in rows {
        // Writing into memory cannot fail.
        let _ = out.write_record(row);
    }
    out.into_inner()
        .ok()
        .and_then(|b| String::from_utf8(b).ok())
        .unwrap_or_default()
}

/// The goal for compensation + feedback (the paper's TLIPFM figures on its real robot):
/// true ZMP mean |e| below these, m (sagittal, lateral).
pub const GOAL_MEAN_M: [f64; 2] = [0.011, 0.014];

/// The goal for compensation + feedback: mean |e| < 1.1 cm sagittal, 1.4 cm lateral.
pub fn meets_goal(r: &RunMetrics) -> bool {
    r.true_err[0].mean < GOAL_MEAN_M[0] && r.true_err[1].mean < GOAL_MEAN_M[1]
}

/// Every run's true mean |e| against the goal (Markdown): the verdict for compensation +
/// feedback (the last run) and, per run, each axis as a share of its goal.
pub fn goal_section(runs: &[RunMetrics]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Goal: true ZMP mean |e| < {:.0} mm sagittal and < {:.0} mm lateral (the paper's TLIPFM on its real robot).",
        GOAL_MEAN_M[0] * 1e3,
        GOAL_MEAN_M[1] * 1e3
    );
    if let Some(fb) = runs.last() {
        let _ = writeln!(
            s,
            "Compensation + feedback ({}): {}.\n",
            fb.variant.name,
            if meets_goal(fb) { "met" } else { "NOT met" }
        );
    }
    let _ = writeln!(s, "| run | sagittal: mean \\|e\\| (share of goal) | lateral: mean \\|e\\| (share of goal) | within goal |");
    let _ = writeln!(s, "| --- | ---: | ---: | --- |");
    let share = |e: &AxisError, k: usize| {
        if e.mean.is_finite() {
            format!(
                "{:.1} mm ({:.0} %)",
                e.mean * 1e3,
                e.mean / GOAL_MEAN_M[k] * 100.0
            )
        } else {
            "–".into()
        }
    };
    for r in runs {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} |",
            r.variant.name,
            share(&r.true_err[0], 0),
            share(&r.true_err[1], 1),
            if meets_goal(r) { "yes" } else { "no" }
        );
    }
    s
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use gait_core::Robot;

    #[test]
    fn axis_error_skips_nan() {
        let e = AxisError::of([0.01, -0.03, f64::NAN].into_iter());
        assert_eq!(e.n, 2);
        assert!((e.mean - 0.02).abs() < 1e-12 && (e.max - 0.03).abs() < 1e-12);
        assert!(AxisError::of(std::iter::empty()).mean.is_nan());
    }

    /// Metrics of a run named `name` with true ZMP mean errors `mean` (test data).
    pub(crate) fn metrics(name: &'static str, mean: [f64; 2]) -> RunMetrics {
        let mut v = variants()[0].clone();
        v.name = name;
        RunMetrics {
            variant: v,
            exit_code: Some(0),
            fell_at: None,
            timing_factor: 1.0,
            true_err: mean.map(|m| AxisError {
                n: 1,
                mean: m,
                max: m,
            }),
            meas_err: [AxisError::default(); 2],
            inside: 1.0,
            walking_ticks: 1,
            walked: 0.0,
            planned: 0.0,
            peak_speed: [0.0; LEG_JOINTS],
            true_peak_speed: [0.0; LEG_JOINTS],
            peak_torque: [0.0; LEG_JOINTS],
            torque_limited: 0.0,
            ref_mismatch: 0,
            heading_drift: 0.0,
            max_tilt: 0.0,
        }
    }

    #[test]
    fn goal_section_judges_each_run_against_the_papers_figures() {
        let runs = [
            metrics("a", [0.0055, 0.0154]),
            metrics("b", [0.0036, 0.0035]),
        ];
        let s = goal_section(&runs);
        assert!(s.contains("Compensation + feedback (b): met."), "{s}");
        assert!(
            s.contains("| a | 5.5 mm (50 %) | 15.4 mm (110 %) | no |"),
            "{s}"
        );
        assert!(
            s.contains("| b | 3.6 mm (33 %) | 3.5 mm (25 %) | yes |"),
            "{s}"
        );
        let s = goal_section(&runs[..1]);
        assert!(s.contains("Compensation + feedback (a): NOT met."), "{s}");
    }

    #[test]
    fn worst_joint_skips_nan_and_names_the_peak() {
        assert_eq!(worst(&[f64::NAN; LEG_JOINTS]).0, "–");
        let mut v = [f64::NAN; LEG_JOINTS];
        v[1] = 0.5;
        v[3] = 2.0;
        v[4] = 1.0;
        assert_eq!(worst(&v), (JOINT_NAMES[3], 2.0));
    }

    #[test]
    fn truth_joint_columns_are_read_by_name() {
        let dir = std::env::temp_dir().join(format!("walker-beyond-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("truth.csv");
        // The simulator's header, two rows; joint 4 (ID 4, left knee) loaded and at its bound.
        let row = |t: f64, lim: u16| {
            let mut s = format!("{t}");
            let cols: Vec<&str> = crate::sim::truth::HEADER.split(',').collect();
            let lim_at = cols.iter().position(|c| *c == "tq_limited").unwrap();
            for _ in 1..lim_at - 24 {
                s.push_str(",0");
            }
            for j in 1..=12 {
                s.push_str(&format!(",{}", if j == 4 { -3.0 } else { 0.1 }));
            }
            for j in 1..=12 {
                s.push_str(&format!(",{}", if j == 4 { 1.5 } else { -0.2 }));
            }
            s.push_str(&format!(",{lim}"));
            for _ in lim_at + 1..cols.len() {
                s.push_str(",0");
            }
            s
        };
        let text = format!(
            "{}\n{}\n{}\n",
            crate::sim::truth::HEADER,
            row(0.0, 0),
            row(0.001, 8)
        );
        std::fs::write(&path, text).unwrap();
        let t = read_truth(&path).unwrap();
        assert_eq!(t.t, vec![0.0, 0.001]);
        assert_eq!(t.joint_speed[1][3], -3.0);
        assert_eq!(t.joint_torque[1][3], 1.5);
        assert_eq!(t.joint_torque[0][11], -0.2);
        assert_eq!(t.torque_limited, vec![0, 8]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn variants_map_to_firmware_tokens() {
        let spec = WalkSpec::default();
        for v in variants().into_iter().chain(ablation()) {
            let s = v.spec(&spec);
            let mut tokens = fil::firmware_tokens(&s).unwrap();
            tokens.extend(v.tokens.iter().map(|t| t.to_string()));
            let cfg = firmware_config(&tokens).unwrap();
            assert_eq!(cfg.stabilizer_on, v.stabilizer, "{}", v.name);
            assert_eq!(
                cfg.compensation == walker_contract::config::Compensation::WholeBody,
                v.compensation == CompensationName::Wholebody
            );
            assert_eq!(cfg.model, gait_core::ModelKind::from(v.model));
            assert_eq!(cfg.com_fourier, v.com == ComName::Fourier, "{}", v.name);
        }
    }

    /// Each ablation run adds exactly one part to the one before it (after the three open-loop
    /// models), the open loop has every feedback off and the "(default)" run is the firmware's
    /// defaults.
    #[test]
    fn the_ablation_adds_one_part_at_a_time() {
        let spec = WalkSpec::default();
        let cfgs: Vec<Config> = ablation()
            .iter()
            .map(|v| {
                let mut tokens = fil::firmware_tokens(&v.spec(&spec)).unwrap();
                tokens.extend(v.tokens.iter().map(|t| t.to_string()));
                firmware_config(&tokens).unwrap()
            })
            .collect();
        let parts = |c: &Config| {
            [
                c.gyro_feedback.ankle > 0.0,
                c.gyro_feedback.hip > 0.0,
                c.compliance.roll > 0.0,
                c.step_adaptation.is_on(),
                c.step_adaptation.is_levelling(),
                c.step_adaptation.landing_gain > 0.0,
                c.deflection.soft_ki > 0.0,
                c.compensation == walker_contract::config::Compensation::WholeBody,
                c.stabilizer_on,
            ]
        };
        for c in &cfgs[..3] {
            assert_eq!(parts(c), [false; 9]);
        }
        for w in cfgs[2..].windows(2) {
            let (a, b) = (parts(&w[0]), parts(&w[1]));
            let added: Vec<usize> = (0..9).filter(|&i| b[i] && !a[i]).collect();
            assert_eq!(added.len(), 1, "{a:?} -> {b:?}");
            assert!((0..9).all(|i| !a[i] || b[i]), "{a:?} -> {b:?}");
        }
        let default_run = ablation()
            .iter()
            .position(|v| v.name.contains("default"))
            .unwrap();
        let base = firmware_config(&fil::firmware_tokens(&spec).unwrap()).unwrap();
        assert_eq!(parts(&cfgs[default_run]), parts(&base));
        assert_eq!(
            parts(&base),
            [true, true, true, true, true, true, true, false, false]
        );
    }

    #[test]
    fn the_log_adjustment_reproduces_the_firmware_walk() {
        let robot = Robot::reference();
        let cfg = Config::default();
        let targets = Targets::new(&robot, cfg.compensation);
        let t =
            gait::servo_timing::<MAX_STEPS>(&cfg.walk_config(), cfg.feasibility, &robot, &targets)
                .unwrap();
        let events: Vec<Record> = t
            .notes()
            .into_iter()
            .map(walker_contract::record::timing_fault)
            .map(|(kind, id, value)| {
                Record::Fault(walker_contract::record::FaultRecord {
                    seq: 0,
                    time_us: 0,
                    kind,
                    id,
                    value,
                })
            })
            .collect();
        assert_eq!(adjusted_config(&cfg, &events).walk, t.walk);
        let spec = adjusted_spec(&WalkSpec::default(), &events);
        assert_eq!(
            (spec.t1, spec.t2, spec.period),
            (t.walk.t1, t.walk.t2, t.walk.period)
        );
    }
}
