//! Plan / parameter files: a walk described in TOML.
//!
//! Every key is optional; a missing key takes its seed 000 Table 2 value
//! ([`ForwardWalk::table2`]). Keys (all SI units, flat at the top level):
//!
//! ```toml
//! model = "tlipfm"        # lipm | dlipm | tlipfm
//! dt = 0.001              # sample time of exports and simulations, s (1/1000 ..= 1/50)
//! # Table 2 forward walk
//! step_length = 0.02      # S_L, m
//! step_width = 0.045      # S_W (half the distance between the feet), m
//! s_first = -1            # -1: left foot swings first, +1: right foot first
//! steps = 14              # N
//! d1 = 0.01               # natural ZMP: start behind the support foot, m
//! d2 = 0.01               # natural ZMP: end ahead of the support foot, m
//! a = 0.004               # natural ZMP: half travel under the sole, m
//! z_c = 0.217             # CoM (pelvis point) height, m
//! w_y = 0.0               # swing bulge, m
//! h_z = 0.03              # swing height, m
//! t1 = 0.15               # end of the first double support, s
//! t2 = 0.49               # end of the single support, s
//! period = 0.64           # step period T, s
//! lead_in = 1.6           # standing before the first step, s
//! lead_out = 1.6          # standing after the last step, s
//! zmp = "natural"         # natural (d1, d2, a) | continuous (b)
//! b = 0.004               # continuous ZMP: half travel under the sole, m (default: a)
//! swing = "cycloid"       # cycloid (h_z, w_y) | sinusoid (h_z)
//! com = "exact"           # exact (seed 000's bounded solution) | fourier (seed 001's series through the steady steps; forward walks of ≥ 5 steps)
//! fourier_terms = 12      # terms per axis of the Fourier CoM (1 ..= 24)
//! compensation = "none"   # none (the paper's pipeline) | wholebody (multi-body CoM on the model CoM; firmware `comp=`)
//! stabilizer = false      # the firmware's ZMP/DCM feedback stabilizer (`stab=on`, default gains)
//!
//! # Any other firmware parameter, by its token key (docs/parameters.md lists them all):
//! [firmware]
//! feasibility = "off"
//! baud = 3000000
//!
//! # Instead of the forward walk (step_length, s_first, steps are then ignored):
//! # feet start side by side at x = 0, y = ±step_width; each entry is one step.
//! [[footsteps]]
//! side = "left"           # the foot that swings
//! x = 0.02
//! y = 0.045
//! yaw = 0.0               # rad
//! ```
//!
//! Errors name the field and the reason: `plans/x.toml: field `t2`: phase times must satisfy
//! 0 < t1 < t2 < T`. Unknown keys are errors (a typo must not silently fall back to Table 2).
//!
//! The keys, their ranges and the firmware tokens are the contract's parameter table
//! (`walker_contract::params::PARAMS`): [`WalkSpec::firmware_tokens`] emits a plan's tokens
//! from it, and [`WalkSpec::check`] runs the firmware's own parser on them first, so a value
//! out of its physical range (`d2 = 1e38`, `h_z = 10`) is refused here as on the robot.

use gait_core::trajectory::fourier_walk::{ComMethod, WalkSampler, DEFAULT_FOURIER_TERMS};
use gait_core::trajectory::plan::{SwingShape, Timing};
use gait_core::trajectory::zmp::ZmpShape;
use gait_core::{
    Footstep, ForwardWalk, GaitError, GaitParams, Model, ModelKind, Place, Plan, Robot, Side,
};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;
use walker_contract::params::{self as fw_params, ArgErrorKind, PARAMS};

/// Most footsteps a plan file may hold.
pub const PLAN_CAPACITY: usize = 64;
/// The plan type used by the host tools.
pub type HostPlan = Plan<f64, PLAN_CAPACITY>;
/// The sampler type used by the host tools.
pub type HostSampler = WalkSampler<f64, PLAN_CAPACITY>;
/// Default sample time, s (the firmware's 200 Hz tick; 1 kHz needs a 3 Mbps bus).
pub const DEFAULT_DT: f64 = 0.005;

/// A plan-file error: which field and why.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanError {
    /// The file, when the plan came from one.
    pub file: Option<String>,
    /// The field (`t2`, `footsteps[3].x`, …); empty when the whole file is at fault.
    pub field: String,
    /// The reason.
    pub reason: String,
}

impl PlanError {
    /// An error of `field`.
    pub fn new(field: impl Into<String>, reason: impl Into<String>) -> Self {
        PlanError {
            file: None,
            field: field.into(),
            reason: reason.into(),
        }
    }
    fn gait(field: &str, e: GaitError) -> Self {
        PlanError::new(field, e.to_string())
    }
    /// The same error, attributed to `file`.
    pub fn in_file(mut self, file: &str) -> Self {
        self.file = Some(file.to_string());
        self
    }
}

impl fmt::Display for PlanError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(file) = &self.file {
            write!(f, "{file}: ")?;
        }
        if self.field.is_empty() {
            write!(f, "{}", self.reason)
        } else {
            write!(f, "field `{}`: {}", self.field, self.reason)
        }
    }
}

impl std::error::Error for PlanError {}

/// The ZMP reference shape of a plan file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ZmpKind {
    /// Seed 000: natural ZMP (d1, d2, a).
    #[default]
    Natural,
    /// Seed 001: continuous forward-moving ZMP (b).
    Continuous,
}

/// The swing-foot profile of a plan file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum SwingKind {
    /// Seed 000 cycloid (h_z, w_y).
    #[default]
    Cycloid,
    /// Seed 001 sinusoid (h_z).
    Sinusoid,
}

/// How the pelvis is placed (plan-file spelling; the firmware's `comp=` token).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum CompensationName {
    /// The paper's pipeline: the pelvis point on the model's CoM.
    #[default]
    None,
    /// Whole-body compensation: the multi-body CoM on the model's CoM.
    Wholebody,
}

/// The CoM solver of a plan file (the firmware's `com=` token).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ComName {
    /// Seed 000's exact bounded solution.
    #[default]
    Exact,
    /// Seed 001's Fourier series through the steady steps.
    Fourier,
}

/// The model name of a plan file (and of the command line's `--model`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, Default, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ModelName {
    /// LIPM.
    Lipm,
    /// DLIPM.
    Dlipm,
    /// TLIPFM (seed 000).
    #[default]
    Tlipfm,
}

impl From<ModelName> for ModelKind {
    fn from(m: ModelName) -> ModelKind {
        match m {
            ModelName::Lipm => ModelKind::Lipm,
            ModelName::Dlipm => ModelKind::Dlipm,
            ModelName::Tlipfm => ModelKind::Tlipfm,
        }
    }
}

/// Which foot (plan-file spelling).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SideName {
    /// Left foot.
    Left,
    /// Right foot.
    Right,
}

impl From<SideName> for Side {
    fn from(s: SideName) -> Side {
        match s {
            SideName::Left => Side::Left,
            SideName::Right => Side::Right,
        }
    }
}

/// One explicit footstep.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FootstepSpec {
    /// The foot that swings.
    pub side: SideName,
    /// Landing x, m.
    pub x: f64,
    /// Landing y, m.
    pub y: f64,
    /// Landing heading, rad.
    #[serde(default)]
    pub yaw: f64,
}

/// A walk as described by a plan file (defaults = Table 2).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct WalkSpec {
    /// Pendulum model.
    pub model: ModelName,
    /// Sample time, s.
    pub dt: f64,
    /// S_L, m.
    pub step_length: f64,
    /// S_W, m.
    pub step_width: f64,
    /// S_first.
    pub s_first: i64,
    /// N.
    pub steps: i64,
    /// d1, m.
    pub d1: f64,
    /// d2, m.
    pub d2: f64,
    /// a, m.
    pub a: f64,
    /// z_c, m.
    pub z_c: f64,
    /// W_y, m.
    pub w_y: f64,
    /// H_z, m.
    pub h_z: f64,
    /// t1, s.
    pub t1: f64,
    /// t2, s.
    pub t2: f64,
    /// T, s.
    pub period: f64,
    /// Lead-in, s.
    pub lead_in: f64,
    /// Lead-out, s.
    pub lead_out: f64,
    /// ZMP shape.
    pub zmp: ZmpKind,
    /// Continuous-ZMP b, m (default: `a`).
    pub b: Option<f64>,
    /// Swing profile.
    pub swing: SwingKind,
    /// Explicit footsteps (replace the forward walk when present).
    pub footsteps: Option<Vec<FootstepSpec>>,
    /// The CoM solver.
    pub com: ComName,
    /// Terms per axis of the Fourier CoM (default 12).
    pub fourier_terms: Option<u8>,
    /// Pelvis placement (firmware only; host exports plot the model's plan).
    pub compensation: CompensationName,
    /// The firmware's feedback stabilizer on (firmware only).
    pub stabilizer: bool,
    /// Any other firmware parameter by its token key (the plan's `[firmware]` table).
    pub firmware: toml::Table,
    /// The robot the plan is written for, by its description's name (gait-core `ROBOT_NAMES`;
    /// default the reference robot): the plan is checked against its legs, and the firmware's
    /// `robot=` and the simulated robot follow it.
    pub robot: Option<String>,
}

impl Default for WalkSpec {
    fn default() -> Self {
        let t = ForwardWalk::table2();
        WalkSpec {
            model: ModelName::Tlipfm,
            dt: DEFAULT_DT,
            step_length: t.step_length,
            step_width: t.step_width,
            s_first: i64::from(t.s_first),
            steps: t.steps as i64,
            d1: t.d1,
            d2: t.d2,
            a: t.a,
            z_c: t.z_c,
            w_y: t.w_y,
            h_z: t.h_z,
            t1: t.t1,
            t2: t.t2,
            period: t.period,
            lead_in: t.lead_in,
            lead_out: t.lead_out,
            zmp: ZmpKind::Natural,
            b: None,
            swing: SwingKind::Cycloid,
            footsteps: None,
            com: ComName::Exact,
            fourier_terms: None,
            compensation: CompensationName::None,
            stabilizer: false,
            firmware: toml::Table::new(),
            robot: None,
        }
    }
}

/// Reads and checks a plan file.
pub fn load(path: &Path) -> Result<WalkSpec, PlanError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| {
        PlanError::new("", format!("cannot read the plan file: {e}")).in_file(&name)
    })?;
    let spec = parse(&text).map_err(|e| e.in_file(&name))?;
    spec.check(spec.robot()).map_err(|e| e.in_file(&name))?;
    Ok(spec)
}

/// Parses plan-file text (no semantic checks beyond types; see [`WalkSpec::check`]).
pub fn parse(text: &str) -> Result<WalkSpec, PlanError> {
    toml::from_str::<WalkSpec>(text).map_err(|e| toml_error(text, &e))
}

/// Turns a TOML error into a field error: the key is found from the error's position.
fn toml_error(text: &str, e: &toml::de::Error) -> PlanError {
    let msg = e.message().trim().to_string();
    // serde names unknown keys itself ("unknown field `foo`, expected one of …").
    if let Some(rest) = msg.strip_prefix("unknown field `") {
        if let Some(end) = rest.find('`') {
            let key = &rest[..end];
            let field = match e.span().map(|s| footstep_index(text, s.start)) {
                Some(Some(i)) => format!("footsteps[{i}].{key}"),
                _ => key.to_string(),
            };
            return PlanError::new(field, "unknown field (misspelt?)");
        }
    }
    if let Some(rest) = msg.strip_prefix("missing field `") {
        if let Some(end) = rest.find('`') {
            let key = &rest[..end];
            let field = match e.span().map(|s| footstep_index(text, s.start)) {
                Some(Some(i)) => format!("footsteps[{i}].{key}"),
                _ => key.to_string(),
            };
            return PlanError::new(field, "missing (required in every footstep)");
        }
    }
    let Some(span) = e.span() else {
        return PlanError::new("", msg);
    };
    let start = span.start.min(text.len());
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line_end = text[start..].find('\n').map_or(text.len(), |i| start + i);
    let line = &text[line_start..line_end];
    let line_no = text[..line_start].matches('\n').count() + 1;
    let key = line
        .split_once('=')
        .map(|(k, _)| k.trim().trim_matches('"').to_string())
        .filter(|k| !k.is_empty() && !k.starts_with('['));
    match key {
        Some(k) => {
            let field = match footstep_index(text, start) {
                Some(i) => format!("footsteps[{i}].{k}"),
                None => k,
            };
            PlanError::new(field, format!("{msg} (line {line_no})"))
        }
        None => PlanError::new("", format!("line {line_no}: {msg}")),
    }
}

/// Index of the `[[footsteps]]` table that the byte offset `pos` is in, if any.
fn footstep_index(text: &str, pos: usize) -> Option<usize> {
    // Up to the end of the line at `pos` (a span may point at the `[[footsteps]]` header).
    let pos = pos.min(text.len());
    let end = text[pos..].find('\n').map_or(text.len(), |i| pos + i);
    let before = &text[..end];
    let mut idx: Option<usize> = None;
    let mut count = 0usize;
    for line in before.lines() {
        let t = line.trim();
        if t.starts_with("[[")
            && t.trim_start_matches('[')
                .trim_start()
                .starts_with("footsteps")
        {
            idx = Some(count);
            count += 1;
        } else if t.starts_with('[') {
            idx = None;
        }
    }
    idx
}

/// A TOML value as firmware token text (strings unquoted, booleans as `on` / `off`).
fn toml_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        toml::Value::Boolean(b) => if *b { "on" } else { "off" }.to_string(),
        toml::Value::Integer(i) => i.to_string(),
        toml::Value::Float(x) => x.to_string(),
        // Dates, arrays, tables: no firmware value is one (the parser refuses the text).
        _ => "[not-a-number-or-word]".to_string(),
    }
}

fn finite(field: &str, v: f64) -> Result<f64, PlanError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(PlanError::gait(field, GaitError::NonFinite))
    }
}

fn positive(field: &str, v: f64) -> Result<f64, PlanError> {
    finite(field, v)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(PlanError::new(field, format!("must be positive (got {v})")))
    }
}

fn not_negative(field: &str, v: f64) -> Result<f64, PlanError> {
    finite(field, v)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(PlanError::new(
            field,
            format!("must not be negative (got {v})"),
        ))
    }
}

fn check_dt(dt: f64) -> Result<(), PlanError> {
    finite("dt", dt)?;
    if !(1.0 / 1000.0 - 1e-12..=1.0 / 50.0 + 1e-12).contains(&dt) {
        return Err(PlanError::new(
            "dt",
            format!("{} (got {dt})", GaitError::BadSampleTime),
        ));
    }
    Ok(())
}

impl WalkSpec {
    /// The model kind.
    pub fn model_kind(&self) -> ModelKind {
        self.model.into()
    }

    /// The ForwardWalk of the Table 2 fields.
    pub fn forward_walk(&self) -> ForwardWalk {
        ForwardWalk {
            step_length: self.step_length,
            step_width: self.step_width,
            s_first: self.s_first.clamp(-1, 1) as i8,
            steps: self.steps.max(0) as usize,
            d1: self.d1,
            d2: self.d2,
            a: self.a,
            z_c: self.z_c,
            w_y: self.w_y,
            h_z: self.h_z,
            t1: self.t1,
            t2: self.t2,
            period: self.period,
            lead_in: self.lead_in,
            lead_out: self.lead_out,
        }
    }

    /// The robot the plan is written for ([`WalkSpec::robot`]'s name; the reference robot when
    /// it names none or one [`WalkSpec::check`] refuses).
    pub fn robot(&self) -> &'static Robot {
        self.robot
            .as_deref()
            .and_then(Robot::by_name)
            .unwrap_or(&gait_core::robot::ROBOTS[0]) // the reference robot
    }

    /// Checks every field and builds the plan once for `robot`'s legs (errors name the field):
    /// first the firmware's parser on the plan's tokens (ranges of the parameter table, the
    /// robot's name), then the walk.
    pub fn check(&self, robot: &Robot) -> Result<(), PlanError> {
        self.firmware_config()?;
        self.sampler(robot, self.dt).map(|_| ())
    }

    /// The firmware's `key=value` tokens of this plan, in the order of the parameter table,
    /// with the plan field each came from (`d2`, `firmware.baud`). Errors: a `[firmware]` key
    /// that is not a firmware parameter, or one that has its own top-level plan key.
    pub fn firmware_fields(&self) -> Result<Vec<(String, String)>, PlanError> {
        for (k, _) in self.firmware.iter() {
            match fw_params::find(k) {
                None => {
                    let valid: Vec<&str> = PARAMS
                        .iter()
                        .filter(|p| p.plan_key.is_none())
                        .map(|p| p.key)
                        .collect();
                    return Err(PlanError::new(
                        format!("firmware.{k}"),
                        format!(
                            "not a firmware parameter (docs/parameters.md); valid keys: {}",
                            valid.join(", ")
                        ),
                    ));
                }
                Some(p) => {
                    if let Some(pk) = p.plan_key {
                        return Err(PlanError::new(
                            format!("firmware.{k}"),
                            format!("set it as the top-level plan key `{pk}`"),
                        ));
                    }
                }
            }
        }
        // The plan's top-level keys as the plan file names them (serde), unset ones absent.
        let plan = match toml::Value::try_from(self) {
            Ok(toml::Value::Table(t)) => t,
            Ok(_) => toml::Table::new(),
            Err(e) => return Err(PlanError::new("plan", e.to_string())),
        };
        let mut out = Vec::new();
        // The robot's token first: it sets the robot's own values (its bus speed) that the
        // plan's other tokens may override.
        let robot_first = PARAMS
            .iter()
            .filter(|p| p.key == "robot")
            .chain(PARAMS.iter().filter(|p| p.key != "robot"));
        for p in robot_first {
            let (field, text) = match p.plan_key {
                Some(pk) => match plan.get(pk) {
                    Some(v) => (pk.to_string(), toml_text(v)),
                    None => continue,
                },
                None => match self.firmware.get(p.key) {
                    Some(v) => (format!("firmware.{}", p.key), toml_text(v)),
                    None => continue,
                },
            };
            out.push((field, format!("{}={text}", p.key)));
        }
        Ok(out)
    }

    /// The firmware's `key=value` tokens of this plan (see [`WalkSpec::firmware_fields`]).
    pub fn firmware_tokens(&self) -> Result<Vec<String>, PlanError> {
        Ok(self
            .firmware_fields()?
            .into_iter()
            .map(|(_, t)| t)
            .collect())
    }

    /// The firmware configuration of this plan, parsed by the firmware's own parser; an
    /// error names the plan field and the parameter's range.
    pub fn firmware_config(&self) -> Result<walker_contract::Config, PlanError> {
        let mut cfg = walker_contract::Config::default();
        for (field, token) in self.firmware_fields()? {
            if let Err(e) = fw_params::apply(&mut cfg, token.as_bytes()) {
                let reason = match e.kind {
                    ArgErrorKind::OutOfRange | ArgErrorKind::BadValue => {
                        let value = token.split_once('=').map_or("", |(_, v)| v);
                        match value.parse::<f64>() {
                            Ok(x) if value.len() > 24 => format!("{e} (got {x:e})"),
                            _ => format!("{e} (got {value})"),
                        }
                    }
                    _ => e.to_string(),
                };
                return Err(PlanError::new(field, reason));
            }
        }
        Ok(cfg)
    }

    /// The gait parameters (field-by-field checks first).
    pub fn params(&self, robot: &Robot) -> Result<GaitParams<f64>, PlanError> {
        positive("z_c", self.z_c)?;
        let model = Model::<f64>::new(self.model_kind(), robot, self.z_c)
            .map_err(|e| PlanError::gait("z_c", e))?;
        positive("t1", self.t1)?;
        positive("t2", self.t2)?;
        positive("period", self.period)?;
        positive("lead_in", self.lead_in)?;
        positive("lead_out", self.lead_out)?;
        let max = gait_core::trajectory::plan::MAX_SEGMENT;
        for (f, v) in [
            ("period", self.period),
            ("lead_in", self.lead_in),
            ("lead_out", self.lead_out),
        ] {
            if v > max {
                return Err(PlanError::new(
                    f,
                    format!("{} (got {v})", GaitError::PeriodTooLong),
                ));
            }
        }
        if self.t2 <= self.t1 {
            return Err(PlanError::new(
                "t2",
                format!(
                    "{} (t1 = {}, t2 = {})",
                    GaitError::BadPhaseTimes,
                    self.t1,
                    self.t2
                ),
            ));
        }
        if self.period <= self.t2 {
            return Err(PlanError::new(
                "period",
                format!(
                    "{} (t2 = {}, T = {})",
                    GaitError::BadPhaseTimes,
                    self.t2,
                    self.period
                ),
            ));
        }
        let half_sole = robot.geometry.sole_length * 0.5;
        let zmp = match self.zmp {
            ZmpKind::Natural => {
                not_negative("d1", self.d1)?;
                not_negative("d2", self.d2)?;
                not_negative("a", self.a)?;
                if self.a >= half_sole {
                    return Err(PlanError::new(
                        "a",
                        format!(
                            "{} (a = {} m, half the sole = {half_sole} m)",
                            GaitError::ZmpOffsetOffSole,
                            self.a
                        ),
                    ));
                }
                ZmpShape::Natural {
                    d1: self.d1,
                    d2: self.d2,
                    a: self.a,
                }
            }
            ZmpKind::Continuous => {
                let b = self.b.unwrap_or(self.a);
                not_negative("b", b)?;
                if b >= half_sole {
                    return Err(PlanError::new(
                        "b",
                        format!(
                            "{} (b = {b} m, half the sole = {half_sole} m)",
                            GaitError::ZmpOffsetOffSole
                        ),
                    ));
                }
                ZmpShape::Continuous { b }
            }
        };
        not_negative("h_z", self.h_z)?;
        let swing = match self.swing {
            SwingKind::Cycloid => {
                not_negative("w_y", self.w_y)?;
                SwingShape::Cycloid {
                    height: self.h_z,
                    width: self.w_y,
                }
            }
            SwingKind::Sinusoid => SwingShape::Sinusoid { height: self.h_z },
        };
        let params = GaitParams {
            model,
            timing: Timing {
                t1: self.t1,
                t2: self.t2,
                period: self.period,
            },
            zmp,
            swing,
            lead_in: self.lead_in,
            lead_out: self.lead_out,
        };
        params.validate(robot).map_err(|e| PlanError::gait("", e))?;
        Ok(params)
    }

    /// Builds the footstep plan.
    pub fn plan(&self, robot: &Robot) -> Result<HostPlan, PlanError> {
        let params = self.params(robot)?;
        positive("step_width", self.step_width)?;
        let w = self.step_width;
        let start = Plan::<f64, PLAN_CAPACITY>::new(
            robot,
            params,
            Place::new(0.0, w, 0.0),
            Place::new(0.0, -w, 0.0),
        )
        .map_err(|e| PlanError::new("step_width", format!("{e} (the feet start at y = ±{w} m)")))?;
        match &self.footsteps {
            Some(list) => {
                if list.is_empty() {
                    return Err(PlanError::gait("footsteps", GaitError::EmptyPlan));
                }
                if list.len() > PLAN_CAPACITY {
                    return Err(PlanError::new(
                        "footsteps",
                        format!(
                            "{} ({} > {PLAN_CAPACITY})",
                            GaitError::CapacityExceeded,
                            list.len()
                        ),
                    ));
                }
                let mut plan = start;
                for (i, s) in list.iter().enumerate() {
                    finite(&format!("footsteps[{i}].x"), s.x)?;
                    finite(&format!("footsteps[{i}].y"), s.y)?;
                    finite(&format!("footsteps[{i}].yaw"), s.yaw)?;
                    plan.push(Footstep {
                        side: s.side.into(),
                        place: Place::new(s.x, s.y, s.yaw),
                    })
                    .map_err(|e| PlanError::gait(&format!("footsteps[{i}]"), e))?;
                }
                Ok(plan)
            }
            None => {
                finite("step_length", self.step_length)?;
                if !(self.s_first == -1 || self.s_first == 1) {
                    return Err(PlanError::new(
                        "s_first",
                        format!("{} (got {})", GaitError::BadStartFoot, self.s_first),
                    ));
                }
                if self.steps <= 0 {
                    return Err(PlanError::new(
                        "steps",
                        format!("{} (got {})", GaitError::EmptyPlan, self.steps),
                    ));
                }
                if self.steps as usize > PLAN_CAPACITY {
                    return Err(PlanError::new(
                        "steps",
                        format!(
                            "{} ({} > {PLAN_CAPACITY})",
                            GaitError::CapacityExceeded,
                            self.steps
                        ),
                    ));
                }
                self.forward_walk()
                    .plan::<f64, PLAN_CAPACITY>(robot, params)
                    .map_err(|e| match e {
                        GaitError::StepOutOfReach => PlanError::new(
                            "step_length",
                            format!(
                                "{e} (S_L = {} m, limit {:.3} m)",
                                self.step_length,
                                start.limits().max_length / 2.0
                            ),
                        ),
                        other => PlanError::gait("", other),
                    })
            }
        }
    }

    /// The CoM method of the plan.
    pub fn com_method(&self) -> ComMethod {
        match self.com {
            ComName::Exact => ComMethod::Exact,
            ComName::Fourier => ComMethod::Fourier {
                terms: self.fourier_terms.unwrap_or(DEFAULT_FOURIER_TERMS),
            },
        }
    }

    /// A sampler over the plan at sample time `dt` (the `dt` field, or an override).
    pub fn sampler(&self, robot: &Robot, dt: f64) -> Result<HostSampler, PlanError> {
        check_dt(dt)?;
        let plan = self.plan(robot)?;
        if self.com == ComName::Fourier && self.footsteps.is_some() {
            return Err(PlanError::gait("com", GaitError::NotPeriodicWalk));
        }
        WalkSampler::new(plan, &self.forward_walk(), self.com_method(), dt).map_err(|e| match e {
            GaitError::NotPeriodicWalk => PlanError::gait("com", e),
            GaitError::BadTermCount => PlanError::gait("fourier_terms", e),
            GaitError::BadSampleTime => PlanError::new(
                "dt",
                format!("dt = {dt} s is longer than the shortest phase (t1, t2 − t1, T − t2, lead_in, lead_out)"),
            ),
            other => PlanError::gait("dt", other),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use walker_contract::params::Domain;

    /// `value` as a TOML literal for the plan key / `[firmware]` key of `p`.
    fn literal(p: &walker_contract::params::Param, text: &str) -> String {
        match (p.plan_key, p.domain) {
            (Some("stabilizer"), _) => (text == "on").to_string(),
            (Some("s_first"), _) | (Some("steps"), _) => text.to_string(),
            (_, Domain::Word(_)) => format!("\"{text}\""),
            _ => text.to_string(),
        }
    }

    fn plan_text(p: &walker_contract::params::Param, text: &str) -> String {
        match p.plan_key {
            Some(k) => format!("{k} = {}\n", literal(p, text)),
            None => format!("[firmware]\n{} = {}\n", p.key, literal(p, text)),
        }
    }

    /// Every parameter of the contract's table is a plan key (top level or `[firmware]`), is
    /// emitted as its firmware token, is listed in docs/parameters.md, and is validated: a value
    /// out of its domain is refused naming the plan field.
    #[test]
    fn every_parameter_is_planned_emitted_documented_and_validated() {
        let docs = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../docs/parameters.md"
        ))
        .unwrap();
        let robot = Robot::reference();
        let d = walker_contract::Config::default();
        for p in PARAMS.iter() {
            assert!(
                docs.contains(&format!("| `{}` |", p.key)),
                "{} not in the docs",
                p.key
            );
            let mut text = String::new();
            match p.value(&d) {
                Some(v) => p.write_value(v, &mut text).unwrap(),
                None if p.key == "b" => text.push_str("0.004"),
                None => text.push('7'),
            }
            let src = plan_text(p, &text);
            let spec = parse(&src).unwrap_or_else(|e| panic!("{src}: {e}"));
            spec.check(&robot).unwrap_or_else(|e| panic!("{src}: {e}"));
            let tokens = spec.firmware_tokens().unwrap();
            assert!(
                tokens.contains(&format!("{}={text}", p.key)),
                "{src}: {tokens:?}"
            );
            let mut bad = String::new();
            p.out_of_domain(&mut bad).unwrap();
            if p.plan_key == Some("stabilizer") {
                continue; // a TOML bool has no third value
            }
            let src = plan_text(p, &bad);
            let field = match p.plan_key {
                Some(k) => k.to_string(),
                None => format!("firmware.{}", p.key),
            };
            let e = parse(&src).and_then(|s| s.check(&robot)).expect_err(&src);
            assert_eq!(e.field, field, "{src}: {e}");
        }
    }

    /// A plan names its robot (`robot = "op3"`): it is checked against that robot's legs, its
    /// firmware tokens start with `robot=` (so that the plan's own `baud` overrides the robot's
    /// bus speed), and an unknown robot is refused naming the key.
    #[test]
    fn a_plan_is_checked_against_the_robot_it_names() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../plans/op3-forward.toml");
        let spec = load(Path::new(path)).unwrap();
        assert_eq!(spec.robot().name, "op3");
        // Its z_c (0.235 m) is beyond the reference robot's 0.23 m legs.
        let e = spec.check(&Robot::reference()).unwrap_err();
        assert!(e.reason.contains("reach"), "{e}");
        let tokens = spec.firmware_tokens().unwrap();
        assert_eq!(tokens.first().map(String::as_str), Some("robot=op3"));
        let with_baud = parse("robot = \"op3\"\n[firmware]\nbaud = 1000000\n").unwrap();
        let cfg = with_baud.firmware_config().unwrap();
        assert_eq!((cfg.robot.name, cfg.bus_baud), ("op3", 1_000_000));
        let only_robot = parse("robot = \"op3\"\n")
            .unwrap()
            .firmware_config()
            .unwrap();
        assert_eq!(only_robot.bus_baud, 2_000_000);
        let e = parse("robot = \"nao\"\n")
            .unwrap()
            .check(&Robot::reference())
            .unwrap_err();
        assert_eq!(e.field, "robot", "{e}");
        assert_eq!(WalkSpec::default().robot().name, "tku-x");
    }

    #[test]
    fn absurd_walks_are_refused_naming_the_key() {
        let robot = Robot::reference();
        for (src, field) in [
            ("d2 = 1e38\n", "d2"),
            ("d1 = 1.7976931348623157e308\n", "d1"),
            ("h_z = 10\n", "h_z"),
        ] {
            let e = parse(src).unwrap().check(&robot).unwrap_err();
            assert_eq!(e.field, field, "{src}: {e}");
            assert!(e.reason.contains("out of range"), "{e}");
        }
    }

    #[test]
    fn firmware_table_keys_are_checked() {
        let robot = Robot::reference();
        let e = parse("[firmware]\nbaudd = 1\n")
            .unwrap()
            .check(&robot)
            .unwrap_err();
        assert_eq!(e.field, "firmware.baudd");
        let e = parse("[firmware]\nd1 = 0.01\n")
            .unwrap()
            .check(&robot)
            .unwrap_err();
        assert_eq!(e.field, "firmware.d1");
        let spec = parse("[firmware]\nfeasibility = \"off\"\nbaud = 3000000\n").unwrap();
        let cfg = spec.firmware_config().unwrap();
        assert_eq!(cfg.bus_baud, 3_000_000);
        assert_eq!(cfg.feasibility, walker_contract::config::Feasibility::Off);
        assert_eq!(cfg.walk, ForwardWalk::table2());
    }

    /// The plans shipped in `plans/` load, and the paper's open loop and the Fourier plan set
    /// what their comments say (against the firmware's defaults: the closed loop).
    #[test]
    fn shipped_plans_load_and_mean_what_they_say() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../plans");
        let mut n = 0;
        for e in std::fs::read_dir(dir).unwrap() {
            let path = e.unwrap().path();
            if path.extension().and_then(|x| x.to_str()) == Some("toml")
                // Run configurations (`walker fil --config`) are read by `crate::runconfig`.
                && !path
                    .file_name()
                    .and_then(|f| f.to_str())
                    .is_some_and(|f| f.starts_with("run-"))
                // Command scripts (`walker fil --commands`) are read by `crate::commands`.
                && !path
                    .file_name()
                    .and_then(|f| f.to_str())
                    .is_some_and(|f| f.starts_with("commands-"))
            {
                load(&path).unwrap_or_else(|err| panic!("{err}"));
                n += 1;
            }
        }
        assert!(n >= 4, "{n} plans");
        let d = walker_contract::Config::default();
        assert!(
            d.gyro_feedback.ankle > 0.0
                && d.feasibility != walker_contract::config::Feasibility::Off
        );
        let paper_spec = load(&std::path::Path::new(dir).join("table2-paper.toml")).unwrap();
        let paper = paper_spec.firmware_config().unwrap();
        // The plan file's `[firmware]` table is the open loop of `walker beyond` and `walker fil
        // --open-loop` at the paper's timing, no more and no less.
        let plain = WalkSpec {
            firmware: toml::Table::new(),
            ..paper_spec.clone()
        };
        let mut open: Vec<String> = crate::beyond::OPEN_LOOP
            .iter()
            .map(|t| t.to_string())
            .collect();
        open.push("feasibility=off".into());
        let run =
            |spec: &WalkSpec, extra: &[String]| crate::fil::check_tokens(spec, extra).unwrap().1;
        assert_eq!(run(&plain, &open), run(&paper_spec, &[]));
        assert_ne!(run(&plain, &[]), run(&paper_spec, &[]));
        assert_eq!(paper.model, ModelKind::Tlipfm);
        assert_eq!(paper.walk, ForwardWalk::table2());
        assert_eq!(paper.feasibility, walker_contract::config::Feasibility::Off);
        assert_eq!(
            (paper.gyro_feedback.ankle, paper.gyro_feedback.hip),
            (0.0, 0.0)
        );
        assert!(!paper.stabilizer_on && !paper.com_fourier);
        assert_eq!((paper.servo_i_roll, paper.servo_i_pitch), (0, 0));
        assert_eq!(paper.servo_i_hip_roll, 0);
        assert!(!paper.step_adaptation.is_on() && paper.compliance.roll == 0.0);
        assert!(d.step_adaptation.is_on());
        assert_eq!(
            paper.compensation,
            walker_contract::config::Compensation::None
        );
        let fourier = load(&std::path::Path::new(dir).join("table2-fourier.toml"))
            .unwrap()
            .firmware_config()
            .unwrap();
        assert!(fourier.com_fourier);
        assert_eq!(fourier.fourier_terms, 12);
    }
}
