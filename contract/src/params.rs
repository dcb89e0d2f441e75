//! Run-time parameters: ONE table ([`PARAMS`]) declares every `key=value` token that overrides
//! [`Config`] — its name, plan-file key, unit, domain (range or words), default and meaning.
//! From it come the firmware's parser ([`apply`]), the host's plan emitter and validator
//! (`walker_host::planfile` runs this very parser on the tokens it emits) and the docs' table
//! (`docs/parameters.md`, [`write_markdown`]; a test checks it is current).
//!
//! The QEMU firmware reads the tokens from its semihosting command line (qemu `-append`).
//! Parsed without allocation; the first bad token is reported with its key.
//!
//! Tokens are separated by spaces, tabs or NULs. The first token is skipped when it is not a
//! `key=value` pair (qemu puts the kernel's file name first); the bare words `lockstep`
//! ([`crate::lockstep::PIPE_WORD`]) and `realtime` ([`REALTIME_WORD`]) are accepted anywhere
//! (the board reads them), as are `store=PATH` ([`STORE_WORD`], the QEMU board's parameter
//! store) and `lockstep=PREFIX` (its lock-step pipes); any other bare word is an error.
//!
//! Every range is physical: a walk parameter beyond it (`d2=1e38`, `h_z=10`) is refused here,
//! naming the key, before gait-core sees the plan (gait-core then checks the walk as a whole:
//! phase order, reach, ZMP on the sole — a rejected plan is a configuration error too).
//!
//! The index of a key in [`PARAMS`] is its code in the log's `ConfigRejected` fault record:
//! new keys are appended.

use core::fmt;

use crate::config::{Arithmetic, Compensation, Config, Feasibility, MAX_STEPS};
use gait_core::ModelKind;

/// The values a parameter takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Domain {
    /// A decimal number in `min ..= max` (`min` itself excluded when `min_open`).
    Num {
        /// Lower bound.
        min: f64,
        /// Upper bound (included).
        max: f64,
        /// The lower bound is excluded (`0 < x`).
        min_open: bool,
    },
    /// An unsigned decimal integer in `min ..= max`.
    Int {
        /// Lower bound (included).
        min: u32,
        /// Upper bound (included).
        max: u32,
    },
    /// One of these words.
    Word(&'static [&'static str]),
}

/// A parsed parameter value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// A number of a [`Domain::Num`].
    Num(f64),
    /// A number of a [`Domain::Num`] that the configuration keeps in f32 (written as f32).
    Num32(f32),
    /// An integer of a [`Domain::Int`].
    Int(u32),
    /// The index of the word in a [`Domain::Word`].
    Word(usize),
}

impl Value {
    /// The value as the setters take it: the number, the integer, or the word's index.
    pub fn as_f64(self) -> f64 {
        match self {
            Value::Num(x) => x,
            Value::Num32(x) => f64::from(x),
            Value::Int(i) => f64::from(i),
            Value::Word(i) => i as f64,
        }
    }
}

/// One run-time parameter.
#[derive(Clone, Copy)]
pub struct Param {
    /// The firmware's token key.
    pub key: &'static str,
    /// The plan file's top-level key (`None`: set it in the plan's `[firmware]` table).
    pub plan_key: Option<&'static str>,
    /// Unit (empty for words and counts).
    pub unit: &'static str,
    /// The values it takes.
    pub domain: Domain,
    /// What it sets, in one line.
    pub doc: &'static str,
    get: fn(&Config) -> Option<Value>,
}

impl fmt::Debug for Param {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Param")
            .field("key", &self.key)
            .field("domain", &self.domain)
            .finish()
    }
}

impl Param {
    /// Parses `v` in this parameter's domain.
    pub fn parse(&self, v: &str) -> Result<Value, ArgErrorKind> {
        parse_value(&self.domain, v)
    }

    /// Parses `v` and sets it in `cfg` (the firmware's parser, [`apply_one`]).
    pub fn apply(&self, cfg: &mut Config, v: &str) -> Result<(), ArgErrorKind> {
        apply_one(cfg, self.key, v)
    }

    /// The value `cfg` holds (`None`: not set, the firmware's behaviour without the key).
    pub fn value(&self, cfg: &Config) -> Option<Value> {
        (self.get)(cfg)
    }

    /// Writes `v` as token text (what [`Param::parse`] reads back to the same value).
    pub fn write_value(&self, v: Value, out: &mut impl fmt::Write) -> fmt::Result {
        match (v, self.domain) {
            (Value::Word(i), Domain::Word(words)) => {
                out.write_str(words.get(i).copied().unwrap_or("?"))
            }
            (Value::Num(x), _) => write!(out, "{x}"),
            (Value::Num32(x), _) => write!(out, "{x}"),
            (Value::Int(x), _) => write!(out, "{x}"),
            (Value::Word(i), _) => write!(out, "{i}"),
        }
    }

    /// Writes the domain as text (`0 ..= 0.1`, `0 < x ≤ 1`, `lipm | dlipm | tlipfm`).
    pub fn write_domain(&self, out: &mut impl fmt::Write) -> fmt::Result {
        match self.domain {
            Domain::Num { min, max, min_open } if min_open => write!(out, "{min} < x ≤ {max}"),
            Domain::Num { min, max, .. } => write!(out, "{min} ..= {max}"),
            Domain::Int { min, max } => write!(out, "{min} ..= {max}"),
            Domain::Word(words) => {
                for (i, w) in words.iter().enumerate() {
                    if i > 0 {
                        out.write_str(" \\| ")?;
                    }
                    write!(out, "`{w}`")?;
                }
                Ok(())
            }
        }
    }

    /// A value outside the domain (for tests of the validators): above the range, or a word
    /// that is not in the list.
    pub fn out_of_domain(&self, out: &mut impl fmt::Write) -> fmt::Result {
        match self.domain {
            Domain::Num { max, .. } => write!(out, "{}", max * 2.0 + 1.0),
            Domain::Int { max, .. } if max < u32::MAX => write!(out, "{}", u64::from(max) + 1),
            Domain::Int { .. } => out.write_str("-1"),
            Domain::Word(_) => out.write_str("no_such_word"),
        }
    }
}

/// Parses `v` in `domain` as the setters take it ([`Value::as_f64`]); out of line, once for
/// every key.
#[inline(never)]
fn parse_number(domain: &Domain, v: &str) -> Result<f64, ArgErrorKind> {
    parse_value(domain, v).map(Value::as_f64)
}

/// Parses `v` in `domain` (numbers: finite decimals only, [`decimal`]).
fn parse_value(domain: &Domain, v: &str) -> Result<Value, ArgErrorKind> {
    match *domain {
        Domain::Num { min, max, min_open } => {
            let x = num(v)?;
            let above = if min_open { x > min } else { x >= min };
            if above && x <= max {
                Ok(Value::Num(x))
            } else {
                Err(ArgErrorKind::OutOfRange)
            }
        }
        Domain::Int { min, max } => {
            let x: u32 = v.parse().map_err(|_| ArgErrorKind::BadValue)?;
            if (min..=max).contains(&x) {
                Ok(Value::Int(x))
            } else {
                Err(ArgErrorKind::OutOfRange)
            }
        }
        Domain::Word(words) => words
            .iter()
            .position(|w| *w == v)
            .map(Value::Word)
            .ok_or(ArgErrorKind::BadValue),
    }
}

/// Seconds → µs (the value is range-checked, ≤ 60 s).
fn secs_us(s: f64) -> u32 {
    libm::round(s * 1e6) as u32
}

/// µs → seconds.
fn us_secs(us: u32) -> f64 {
    f64::from(us) / 1e6
}

/// `text` on the host; empty in the firmware (the docs are the host's: flash).
const fn target_text(text: &'static str) -> &'static str {
    if cfg!(target_os = "none") {
        ""
    } else {
        text
    }
}

const fn range(min: f64, max: f64) -> Domain {
    Domain::Num {
        min,
        max,
        min_open: false,
    }
}

const fn positive(max: f64) -> Domain {
    Domain::Num {
        min: 0.0,
        max,
        min_open: true,
    }
}

const fn int(min: u32, max: u32) -> Domain {
    Domain::Int { min, max }
}

/// Longest step or lead phase, s (gait-core's `plan::MAX_SEGMENT`).
const MAX_PHASE_S: f64 = gait_core::trajectory::plan::MAX_SEGMENT;
const ON_OFF: &[&str] = &["off", "on"];

/// Declares the parameters once and generates from that one list: the metadata table
/// [`PARAMS`] (host, docs, tests), the key table [`KEYS`] (the log's key index) and the
/// firmware's parser [`apply_one`] (a `match` on the key: no table of function pointers in
/// flash).
macro_rules! params {
    ($({
        key: $key:literal,
        plan_key: $plan:expr,
        unit: $unit:literal,
        domain: $dom:expr,
        doc: $doc:literal,
        set: |$c:ident, $v:ident| $set:block,
        get: |$g:ident| $get:block,
    }),* $(,)?) => {
        /// Every parameter, in the order of its key index (see the module docs).
        pub static PARAMS: &[Param] = &[$(Param {
            key: $key,
            plan_key: $plan,
            unit: $unit,
            domain: $dom,
            doc: target_text($doc),
            get: |$g| $get,
        }),*];

        /// Every key, in the order of [`PARAMS`] (its index is the key's code in the log).
        pub static KEYS: &[&str] = KEYS_ARRAY;
        const KEYS_ARRAY: &[&str] = &[$($key),*];

        /// The domain of every key, in the order of [`KEYS`].
        static DOMAINS: &[Domain] = &[$($dom),*];

        /// Applies one `key=value` pair: the value is parsed in the key's domain, then set.
        /// (The key is looked up once in [`KEYS`]; each key's setter is chosen by its index,
        /// a compile-time constant: no string compare per key and no function pointers.)
        pub fn apply_one(cfg: &mut Config, key: &str, v: &str) -> Result<(), ArgErrorKind> {
            let idx = key_index(key);
            let domain = DOMAINS
                .get(usize::from(idx))
                .ok_or(ArgErrorKind::UnknownKey)?;
            let x = parse_number(domain, v)?;
            $({
                const INDEX: u8 = key_position(KEYS_ARRAY, $key);
                if idx == INDEX {
                    let $v = x;
                    let $c = cfg;
                    $set
                    return Ok(());
                }
            })*
            Err(ArgErrorKind::UnknownKey)
        }
    };
}

params! {
    {
        key: "model",
        plan_key: Some("model"),
        unit: "",
        domain: Domain::Word(&["lipm", "dlipm", "tlipfm"]),
        doc: "pendulum model",
        set: |c, v| {
            c.model = match v as usize {
                0 => ModelKind::Lipm,
                1 => ModelKind::Dlipm,
                _ => ModelKind::Tlipfm,
            }
        },
        get: |c| {
            Some(Value::Word(match c.model {
                ModelKind::Lipm => 0,
                ModelKind::Dlipm => 1,
                ModelKind::Tlipfm => 2,
            }))
        },
    },
    {
        key: "dt",
        plan_key: Some("dt"),
        unit: "s",
        domain: range(0.001, 0.02),
        doc: "tick period = gait sample time",
        set: |c, v| { c.tick_period_us = secs_us(v) },
        get: |c| { Some(Value::Num(us_secs(c.tick_period_us))) },
    },
    {
        key: "steps",
        plan_key: Some("steps"),
        unit: "",
        domain: int(1, MAX_STEPS as u32),
        doc: "number of steps N",
        set: |c, v| { c.walk.steps = v as usize },
        get: |c| { Some(Value::Int(u32::try_from(c.walk.steps).unwrap_or(u32::MAX))) },
    },
    {
        key: "step_length",
        plan_key: Some("step_length"),
        unit: "m",
        domain: range(-0.1, 0.1),
        doc: "step length S_L (gait-core checks the leg's reach)",
        set: |c, v| { c.walk.step_length = v },
        get: |c| { Some(Value::Num(c.walk.step_length)) },
    },
    {
        key: "step_width",
        plan_key: Some("step_width"),
        unit: "m",
        domain: positive(0.2),
        doc: "step width S_W (each foot at y = ±S_W)",
        set: |c, v| { c.walk.step_width = v },
        get: |c| { Some(Value::Num(c.walk.step_width)) },
    },
    {
        key: "s_first",
        plan_key: Some("s_first"),
        unit: "",
        domain: Domain::Word(&["-1", "1", "+1"]),
        doc: "first swing foot (−1 left, 1 right)",
        set: |c, v| { c.walk.s_first = if v as usize == 0 { -1 } else { 1 } },
        get: |c| { Some(Value::Word(usize::from(c.walk.s_first >= 0))) },
    },
    {
        key: "d1",
        plan_key: Some("d1"),
        unit: "m",
        domain: range(0.0, 0.1),
        doc: "natural ZMP: start behind the support foot",
        set: |c, v| { c.walk.d1 = v },
        get: |c| { Some(Value::Num(c.walk.d1)) },
    },
    {
        key: "d2",
        plan_key: Some("d2"),
        unit: "m",
        domain: range(0.0, 0.1),
        doc: "natural ZMP: end ahead of the support foot",
        set: |c, v| { c.walk.d2 = v },
        get: |c| { Some(Value::Num(c.walk.d2)) },
    },
    {
        key: "a",
        plan_key: Some("a"),
        unit: "m",
        domain: range(0.0, 0.05),
        doc: "natural ZMP: half travel under the sole",
        set: |c, v| { c.walk.a = v },
        get: |c| { Some(Value::Num(c.walk.a)) },
    },
    {
        key: "b",
        plan_key: Some("b"),
        unit: "m",
        domain: range(0.0, 0.05),
        doc: "continuous ZMP half travel (also selects `zmp=continuous`; unset: `a`)",
        set: |c, v| {
            c.zmp_b = Some(v);
            c.zmp_continuous = true;
        },
        get: |c| { c.zmp_b.map(Value::Num) },
    },
    {
        key: "zmp",
        plan_key: Some("zmp"),
        unit: "",
        domain: Domain::Word(&["natural", "continuous"]),
        doc: "ZMP shape: seed 000's natural (d1, d2, a) or seed 001's continuous (b)",
        set: |c, v| { c.zmp_continuous = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.zmp_continuous))) },
    },
    {
        key: "z_c",
        plan_key: Some("z_c"),
        unit: "m",
        domain: positive(1.0),
        doc: "CoM (pelvis point) height",
        set: |c, v| { c.walk.z_c = v },
        get: |c| { Some(Value::Num(c.walk.z_c)) },
    },
    {
        key: "w_y",
        plan_key: Some("w_y"),
        unit: "m",
        domain: range(0.0, 0.1),
        doc: "swing bulge W_y (cycloid)",
        set: |c, v| { c.walk.w_y = v },
        get: |c| { Some(Value::Num(c.walk.w_y)) },
    },
    {
        key: "h_z",
        plan_key: Some("h_z"),
        unit: "m",
        domain: range(0.0, 0.1),
        doc: "swing height H_z",
        set: |c, v| { c.walk.h_z = v },
        get: |c| { Some(Value::Num(c.walk.h_z)) },
    },
    {
        key: "swing",
        plan_key: Some("swing"),
        unit: "",
        domain: Domain::Word(&["cycloid", "sinusoid"]),
        doc: "swing-foot profile: seed 000's cycloid (h_z, w_y) or seed 001's sinusoid (h_z)",
        set: |c, v| { c.swing_sinusoid = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.swing_sinusoid))) },
    },
    {
        key: "t1",
        plan_key: Some("t1"),
        unit: "s",
        domain: positive(MAX_PHASE_S),
        doc: "end of the first double support",
        set: |c, v| { c.walk.t1 = v },
        get: |c| { Some(Value::Num(c.walk.t1)) },
    },
    {
        key: "t2",
        plan_key: Some("t2"),
        unit: "s",
        domain: positive(MAX_PHASE_S),
        doc: "end of the single support",
        set: |c, v| { c.walk.t2 = v },
        get: |c| { Some(Value::Num(c.walk.t2)) },
    },
    {
        key: "period",
        plan_key: Some("period"),
        unit: "s",
        domain: positive(MAX_PHASE_S),
        doc: "step period T",
        set: |c, v| { c.walk.period = v },
        get: |c| { Some(Value::Num(c.walk.period)) },
    },
    {
        key: "lead_in",
        plan_key: Some("lead_in"),
        unit: "s",
        domain: positive(MAX_PHASE_S),
        doc: "standing before the first step",
        set: |c, v| { c.walk.lead_in = v },
        get: |c| { Some(Value::Num(c.walk.lead_in)) },
    },
    {
        key: "lead_out",
        plan_key: Some("lead_out"),
        unit: "s",
        domain: positive(MAX_PHASE_S),
        doc: "standing after the last step",
        set: |c, v| { c.walk.lead_out = v },
        get: |c| { Some(Value::Num(c.walk.lead_out)) },
    },
    {
        key: "ramp",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 60.0),
        doc: "smooth move to the initial pose",
        set: |c, v| { c.ramp_us = secs_us(v) },
        get: |c| { Some(Value::Num(us_secs(c.ramp_us))) },
    },
    {
        key: "hold",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 60.0),
        doc: "final hold before torque off",
        set: |c, v| { c.final_hold_us = secs_us(v) },
        get: |c| { Some(Value::Num(us_secs(c.final_hold_us))) },
    },
    {
        key: "settle",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 10.0),
        doc: "a graded stop's longest walk to a standstill before it lowers the robot",
        set: |c, v| { c.settle_us = secs_us(v) },
        get: |c| { Some(Value::Num(us_secs(c.settle_us))) },
    },
    {
        key: "lower",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 10.0),
        doc: "a graded stop's lowering to the crouch before torque off (0: hold the pose)",
        set: |c, v| { c.lower_us = secs_us(v) },
        get: |c| { Some(Value::Num(us_secs(c.lower_us))) },
    },
    {
        key: "crouch",
        plan_key: None,
        unit: "m",
        domain: range(0.0, 0.08),
        doc: "how far the crouch lowers the pelvis below z_c",
        set: |c, v| { c.crouch_m = v as f32 },
        get: |c| { Some(Value::Num32(c.crouch_m)) },
    },
    {
        key: "min_load",
        plan_key: None,
        unit: "N",
        domain: range(0.0, 1.0e4),
        doc: "minimum foot load for the measured ZMP",
        set: |c, v| { c.min_load_n = v as f32 },
        get: |c| { Some(Value::Num32(c.min_load_n)) },
    },
    {
        key: "feet",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["required", "optional"]),
        doc: "a foot board missing at start-up stops / is tolerated",
        set: |c, v| { c.feet_required = v as usize == 0 },
        get: |c| { Some(Value::Word(usize::from(!c.feet_required))) },
    },
    {
        key: "reply_timeout_us",
        plan_key: None,
        unit: "µs",
        domain: int(50, 100_000),
        doc: "master reply timeout",
        set: |c, v| { c.reply_timeout_us = v as u32 },
        get: |c| { Some(Value::Int(c.reply_timeout_us)) },
    },
    {
        key: "read_poll_us",
        plan_key: None,
        unit: "µs",
        domain: int(1, 1000),
        doc: "longest wait for one reply byte",
        set: |c, v| { c.read_poll_us = v as u32 },
        get: |c| { Some(Value::Int(c.read_poll_us)) },
    },
    {
        key: "attempts",
        plan_key: None,
        unit: "",
        domain: int(1, 10),
        doc: "start-up transaction attempts",
        set: |c, v| { c.startup_attempts = v as u8 },
        get: |c| { Some(Value::Int(u32::from(c.startup_attempts))) },
    },
    {
        key: "baud",
        plan_key: None,
        unit: "bit/s",
        domain: int(9600, 4_500_000),
        doc: "servo bus baud rate",
        set: |c, v| { c.bus_baud = v as u32 },
        get: |c| { Some(Value::Int(c.bus_baud)) },
    },
    {
        key: "return_delay_us",
        plan_key: None,
        unit: "µs",
        domain: int(0, 508),
        doc: "modelled Return Delay Time (QEMU)",
        set: |c, v| { c.return_delay_us = v as u32 },
        get: |c| { Some(Value::Int(c.return_delay_us)) },
    },
    {
        key: "compute_us",
        plan_key: None,
        unit: "µs",
        domain: int(0, 1_000_000),
        doc: "modelled compute time per tick (QEMU); 0: the bench's instructions per tick ÷ core_mhz",
        set: |c, v| { c.compute_us = v as u32 },
        get: |c| { Some(Value::Int(c.compute_us)) },
    },
    {
        key: "core_mhz",
        plan_key: None,
        unit: "MHz",
        domain: int(1, 1_000),
        doc: "modelled core clock for the compute time per tick (QEMU)",
        set: |c, v| { c.core_mhz = v as u32 },
        get: |c| { Some(Value::Int(c.core_mhz)) },
    },
    {
        key: "watchdog_ms",
        plan_key: None,
        unit: "ms",
        domain: int(1, 10_000),
        doc: "watchdog timeout",
        set: |c, v| { c.watchdog_ms = v as u32 },
        get: |c| { Some(Value::Int(c.watchdog_ms)) },
    },
    {
        key: "hold_ticks",
        plan_key: None,
        unit: "ticks",
        domain: int(0, 65_535),
        doc: "missed replies bridged with the last good value",
        set: |c, v| { c.supervisor.hold_ticks = v as u16 },
        get: |c| { Some(Value::Int(u32::from(c.supervisor.hold_ticks))) },
    },
    {
        key: "stopping_ticks",
        plan_key: None,
        unit: "ticks",
        domain: int(0, 65_535),
        doc: "pose held before torque off after a stop",
        set: |c, v| { c.supervisor.stopping_ticks = v as u16 },
        get: |c| { Some(Value::Int(u32::from(c.supervisor.stopping_ticks))) },
    },
    {
        key: "overrun_burst",
        plan_key: None,
        unit: "ticks",
        domain: int(1, 65_535),
        doc: "consecutive overruns that stop the robot",
        set: |c, v| { c.supervisor.overrun_burst = v as u16 },
        get: |c| { Some(Value::Int(u32::from(c.supervisor.overrun_burst))) },
    },
    {
        key: "tilt_limit",
        plan_key: None,
        unit: "rad",
        domain: positive(core::f64::consts::PI),
        doc: "fall threshold (tilt from vertical)",
        set: |c, v| { c.supervisor.tilt_limit_rad = v as f32 },
        get: |c| { Some(Value::Num32(c.supervisor.tilt_limit_rad)) },
    },
    {
        key: "imu_cutoff",
        plan_key: None,
        unit: "Hz",
        domain: positive(1.0e4),
        doc: "φ̈ low-pass cutoff",
        set: |c, v| { c.imu_cutoff_hz = v as f32 },
        get: |c| { Some(Value::Num32(c.imu_cutoff_hz)) },
    },
    {
        key: "comp",
        plan_key: Some("compensation"),
        unit: "",
        domain: Domain::Word(&["none", "wholebody"]),
        doc: "pelvis placement: the paper's pipeline / whole-body compensation",
        set: |c, v| {
            c.compensation = if v as usize == 1 {
                Compensation::WholeBody
            } else {
                Compensation::None
            }
        },
        get: |c| {
            Some(Value::Word(usize::from(
                c.compensation == Compensation::WholeBody,
            )))
        },
    },
    {
        key: "stab",
        plan_key: Some("stabilizer"),
        unit: "",
        domain: Domain::Word(ON_OFF),
        doc: "ZMP/DCM feedback stabilizer (gait-core `stabilizer`; plan file: true / false)",
        set: |c, v| { c.stabilizer_on = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.stabilizer_on))) },
    },
    {
        key: "stab_kp",
        plan_key: None,
        unit: "",
        domain: range(0.0, 10.0),
        doc: "stabilizer: proportional gain k_p on the DCM error estimate",
        set: |c, v| { c.stabilizer.kp = v },
        get: |c| { Some(Value::Num(c.stabilizer.kp)) },
    },
    {
        key: "stab_ki",
        plan_key: None,
        unit: "1/s",
        domain: range(0.0, 100.0),
        doc: "stabilizer: integral gain k_i",
        set: |c, v| { c.stabilizer.ki = v },
        get: |c| { Some(Value::Num(c.stabilizer.ki)) },
    },
    {
        key: "stab_leak",
        plan_key: None,
        unit: "1/s",
        domain: range(0.0, 100.0),
        doc: "stabilizer: leak λ of the integral",
        set: |c, v| { c.stabilizer.leak = v },
        get: |c| { Some(Value::Num(c.stabilizer.leak)) },
    },
    {
        key: "stab_kg",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 1.0),
        doc: "stabilizer: gyro gain k_g",
        set: |c, v| { c.stabilizer.kg = v },
        get: |c| { Some(Value::Num(c.stabilizer.kg)) },
    },
    {
        key: "stab_k",
        plan_key: None,
        unit: "",
        domain: range(0.0, 100.0),
        doc: "stabilizer: DCM gain k of p − p_ref = (1 + k)(ξ − ξ_ref)",
        set: |c, v| { c.stabilizer.dcm_k = v },
        get: |c| { Some(Value::Num(c.stabilizer.dcm_k)) },
    },
    {
        key: "stab_max",
        plan_key: None,
        unit: "m",
        domain: range(0.0, gait_core::feedback::stabilizer::MAX_SHIFT_CEILING_M),
        doc: "stabilizer: saturation of the CoM shift",
        set: |c, v| { c.stabilizer.max_shift = v },
        get: |c| { Some(Value::Num(c.stabilizer.max_shift)) },
    },
    {
        key: "stab_rate",
        plan_key: None,
        unit: "m/s",
        domain: positive(1.0),
        doc: "stabilizer: rate limit of the CoM shift",
        set: |c, v| { c.stabilizer.max_rate = v },
        get: |c| { Some(Value::Num(c.stabilizer.max_rate)) },
    },
    {
        key: "stab_margin",
        plan_key: None,
        unit: "m",
        domain: range(0.0, 0.05),
        doc: "stabilizer: ZMP command margin inside the support polygon",
        set: |c, v| { c.stabilizer.margin = v },
        get: |c| { Some(Value::Num(c.stabilizer.margin)) },
    },
    {
        key: "stab_cutoff",
        plan_key: None,
        unit: "Hz",
        domain: positive(1000.0),
        doc: "stabilizer: ZMP error low-pass cutoff",
        set: |c, v| { c.stabilizer.cutoff_hz = v },
        get: |c| { Some(Value::Num(c.stabilizer.cutoff_hz)) },
    },
    {
        key: "stab_lateral",
        plan_key: None,
        unit: "1",
        domain: range(0.0, 1.0),
        doc: "stabilizer: weight w_y of the lateral axis (gait-core stabilizer S3′; 0 = sagittal only)",
        set: |c, v| { c.stabilizer.lateral = v },
        get: |c| { Some(Value::Num(c.stabilizer.lateral)) },
    },
    {
        key: "feasibility",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["stretch", "lower", "off"]),
        doc: "servo-speed check at start-up: stretch the step timing, lower the swing, or only warn",
        set: |c, v| {
            c.feasibility = match v as usize {
                0 => Feasibility::Stretch,
                1 => Feasibility::Lower,
                _ => Feasibility::Off,
            }
        },
        get: |c| {
            Some(Value::Word(match c.feasibility {
                Feasibility::Stretch => 0,
                Feasibility::Lower => 1,
                Feasibility::Off => 2,
            }))
        },
    },
    {
        key: "gyro_ankle",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 1.0),
        doc: "gyro damping gain at the ankles of the legs on the ground (gait-core gyro)",
        set: |c, v| { c.gyro_feedback.ankle = v as f32 },
        get: |c| { Some(Value::Num32(c.gyro_feedback.ankle)) },
    },
    {
        key: "gyro_hip",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 1.0),
        doc: "gyro damping gain at the hips of the legs on the ground",
        set: |c, v| { c.gyro_feedback.hip = v as f32 },
        get: |c| { Some(Value::Num32(c.gyro_feedback.hip)) },
    },
    {
        key: "gyro_max",
        plan_key: None,
        unit: "rad",
        domain: range(0.0, 0.3),
        doc: "largest gyro correction of one joint",
        set: |c, v| { c.gyro_feedback.max_rad = v as f32 },
        get: |c| { Some(Value::Num32(c.gyro_feedback.max_rad)) },
    },
    {
        key: "compliance_roll",
        plan_key: None,
        unit: "1",
        domain: range(0.0, 1.5),
        doc: "fraction of the servos' predicted static sag added to the hip-roll and ankle-roll targets (gait-core compliance; 0 = off)",
        set: |c, v| { c.compliance.roll = v as f32 },
        get: |c| { Some(Value::Num32(c.compliance.roll)) },
    },
    {
        key: "compliance_pitch",
        plan_key: None,
        unit: "1",
        domain: range(0.0, 1.5),
        doc: "the same for the hip-pitch, knee and ankle-pitch targets",
        set: |c, v| { c.compliance.pitch = v as f32 },
        get: |c| { Some(Value::Num32(c.compliance.pitch)) },
    },
    {
        key: "servo_stiffness",
        plan_key: None,
        unit: "N·m/rad",
        domain: range(1.0, 200.0),
        doc: "position servos' joint stiffness K = (P/128)·(stall torque/885)·(4096/2π) (XM430-W350, P 800: 18.875)",
        set: |c, v| { c.compliance.stiffness = v as f32 },
        get: |c| { Some(Value::Num32(c.compliance.stiffness)) },
    },
    {
        key: "compliance_follow",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["0", "1"]),
        doc: "1: the sag feed-forward takes the servo survey's stiffness (at the present supply, at most 3× softer than servo_stiffness) once measured; 0 (default): servo_stiffness",
        set: |c, v| { c.compliance_follow = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.compliance_follow))) },
    },
    {
        key: "compliance_max",
        plan_key: None,
        unit: "rad",
        domain: range(0.0, 0.3),
        doc: "largest compliance correction of one joint",
        set: |c, v| { c.compliance.max_rad = v as f32 },
        get: |c| { Some(Value::Num32(c.compliance.max_rad)) },
    },
    {
        key: "fdc_gain",
        plan_key: None,
        unit: "m/(N·s)",
        domain: range(0.0, 0.01),
        doc: "foot force difference control in double support: gain k_f (gait-core fdc F3; 0 = off)",
        set: |c, v| { c.foot_force.gain = v as f32 },
        get: |c| { Some(Value::Num32(c.foot_force.gain)) },
    },
    {
        key: "fdc_leak",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 10.0),
        doc: "foot force difference control: leak time constant T_v (0 = no leak)",
        set: |c, v| { c.foot_force.leak_s = v as f32 },
        get: |c| { Some(Value::Num32(c.foot_force.leak_s)) },
    },
    {
        key: "fdc_max",
        plan_key: None,
        unit: "m",
        domain: range(0.0, 0.03),
        doc: "foot force difference control: largest height difference of the soles",
        set: |c, v| { c.foot_force.max_m = v as f32 },
        get: |c| { Some(Value::Num32(c.foot_force.max_m)) },
    },
    {
        key: "catch_gain",
        plan_key: None,
        unit: "1",
        domain: range(0.0, 3.0),
        doc: "catching step: gain k of the capture-point error beyond the deadband on the swing foot's landing place (gait-core catch A3; 0 = off)",
        set: |c, v| { c.step_adaptation.gain = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.gain)) },
    },
    {
        key: "catch_deadband_x",
        plan_key: None,
        unit: "m",
        domain: range(0.0, 0.1),
        doc: "catching step: forward/backward capture-point error the ankles hold (A3)",
        set: |c, v| { c.step_adaptation.deadband_m[0] = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.deadband_m[0])) },
    },
    {
        key: "catch_deadband_y",
        plan_key: None,
        unit: "m",
        domain: range(0.0, 0.1),
        doc: "catching step: sideways capture-point error the ankles hold (A3)",
        set: |c, v| { c.step_adaptation.deadband_m[1] = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.deadband_m[1])) },
    },
    {
        key: "catch_max_x",
        plan_key: None,
        unit: "m",
        domain: range(0.0, 0.08),
        doc: "catching step: largest forward/backward move of the landing place (A4)",
        set: |c, v| { c.step_adaptation.max_x_m = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.max_x_m)) },
    },
    {
        key: "catch_max_out",
        plan_key: None,
        unit: "m",
        domain: range(0.0, 0.08),
        doc: "catching step: largest outward move of the landing place (A4; never inward)",
        set: |c, v| { c.step_adaptation.max_out_m = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.max_out_m)) },
    },
    {
        key: "catch_level_pitch",
        plan_key: None,
        unit: "1",
        domain: range(0.0, 1.5),
        doc: "catching step: swing sole levelling gain on the trunk's pitch off its baseline (A10; 0 = off)",
        set: |c, v| { c.step_adaptation.level_pitch = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.level_pitch)) },
    },
    {
        key: "catch_level_roll",
        plan_key: None,
        unit: "1",
        domain: range(0.0, 1.5),
        doc: "catching step: swing sole levelling gain on the trunk's roll off its baseline (A10; 0 = off)",
        set: |c, v| { c.step_adaptation.level_roll = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.level_roll)) },
    },
    {
        key: "catch_hold_max",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 0.5),
        doc: "catching step: longest hold of the plan's clock in one single support while the caught swing foot is on its way (A11; 0 = off)",
        set: |c, v| { c.step_adaptation.hold_max_s = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.hold_max_s)) },
    },
    {
        key: "catch_hold_settle",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 0.5),
        doc: "catching step: time the held clock waits after the swing foot's offset arrived (A11)",
        set: |c, v| { c.step_adaptation.hold_settle_s = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.hold_settle_s)) },
    },
    {
        key: "catch_speed",
        plan_key: None,
        unit: "m/s",
        domain: range(0.0, 2.0),
        doc: "catching step: largest speed of the feet's and the body's offsets from the plan",
        set: |c, v| { c.step_adaptation.speed_m_s = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.speed_m_s)) },
    },
    {
        key: "catch_body_speed",
        plan_key: None,
        unit: "m/s",
        domain: range(0.0, 2.0),
        doc: "catching step: largest speed of the body's offset from the plan (A7)",
        set: |c, v| { c.step_adaptation.body_speed_m_s = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.body_speed_m_s)) },
    },
    {
        key: "deflection_ki",
        plan_key: None,
        unit: "1/s",
        domain: range(0.0, 50.0),
        doc: "servo deflection feedback: integral gain k_i driving the stance leg's pitch joints (or those of deflection_joints) to their targets from the servos' Present Position (gait-core deflection D2; 0 = off, no position reads)",
        set: |c, v| { c.deflection.ki = v as f32 },
        get: |c| { Some(Value::Num32(c.deflection.ki)) },
    },
    {
        key: "deflection_max",
        plan_key: None,
        unit: "rad",
        domain: range(0.0, gait_core::feedback::deflection::MAX_CORRECTION_RAD),
        doc: "servo deflection feedback: largest correction of one joint",
        set: |c, v| { c.deflection.max_rad = v as f32 },
        get: |c| { Some(Value::Num32(c.deflection.max_rad)) },
    },
    {
        key: "deflection_joints",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["pitch", "roll", "both"]),
        doc: "servo deflection feedback: the stance leg's joints it drives (hip pitch, knee, ankle pitch; hip and ankle roll; or both)",
        set: |c, v| { c.deflection.joints = gait_core::feedback::deflection::JointSet::BY_INDEX.get(v as usize).copied().unwrap_or(gait_core::feedback::deflection::JointSet::PITCH) },
        get: |c| { gait_core::feedback::deflection::JointSet::BY_INDEX.iter().position(|s| *s == c.deflection.joints).map(Value::Word) },
    },
    {
        key: "sole_poses",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["planned", "measured"]),
        doc: "where the measured ZMP places the load cells: the plan's feet, or each landing surveyed in its double support by forward kinematics of the 12 servos' Present Position (gait-core odometry; one leg's six servos read on each of two ticks a step)",
        set: |c, v| { c.sole_poses_measured = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.sole_poses_measured))) },
    },
    {
        key: "heading_gain",
        plan_key: None,
        unit: "1/step",
        domain: range(0.0, 1.0),
        doc: "online walk: heading hold, share of the gyro-measured heading error each walking step turns back (gait-core online H2; 0 = off)",
        set: |c, v| { c.heading_gain = v as f32 },
        get: |c| { Some(Value::Num32(c.heading_gain)) },
    },
    {
        key: "position_gain",
        plan_key: None,
        unit: "1/step",
        domain: range(0.0, 1.0),
        doc: "online walk: position hold, share of the surveyed feet's distance from the commanded track each walking step corrects (gait-core online P2, needs sole_poses=measured; 0 = off)",
        set: |c, v| { c.position_gain = v as f32 },
        get: |c| { Some(Value::Num32(c.position_gain)) },
    },
    {
        key: "fault_nan",
        plan_key: None,
        unit: "tick",
        domain: int(0, u32::MAX),
        doc: "test: inject a NaN joint target at this walk tick",
        set: |c, v| { c.fault_nan_tick = Some(v as u32) },
        get: |c| { c.fault_nan_tick.map(Value::Int) },
    },
    {
        key: "stop_at",
        plan_key: None,
        unit: "tick",
        domain: int(0, u32::MAX),
        doc: "test: request a stop at this walk tick",
        set: |c, v| { c.stop_at_tick = Some(v as u32) },
        get: |c| { c.stop_at_tick.map(Value::Int) },
    },
    {
        key: "cut_save",
        plan_key: None,
        unit: "B",
        domain: int(0, 4096),
        doc: "test: the next parameter save loses power after this many bytes of its slot (QEMU board)",
        set: |c, v| { c.fault_cut_save = Some(v as u32) },
        get: |c| { c.fault_cut_save.map(Value::Int) },
    },
    {
        key: "math",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["f32", "fixed"]),
        doc: "per-sample gait work: f32, or the fixed-point sampler and integer-only IK (firmware built with `--features fixed-gait`; otherwise refused at start-up, exit 2)",
        set: |c, v| {
            c.arithmetic = if v as usize == 1 {
                Arithmetic::Fixed
            } else {
                Arithmetic::F32
            }
        },
        get: |c| { Some(Value::Word(usize::from(c.arithmetic == Arithmetic::Fixed))) },
    },
    {
        key: "com",
        plan_key: Some("com"),
        unit: "",
        domain: Domain::Word(&["exact", "fourier"]),
        doc: "CoM solver: seed 000's exact solution, or seed 001's Fourier series through the steady steps (blended with the exact one at start and stop; f32, forward walks of ≥ 5 steps)",
        set: |c, v| { c.com_fourier = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.com_fourier))) },
    },
    {
        key: "fourier_terms",
        plan_key: Some("fourier_terms"),
        unit: "",
        domain: int(1, gait_core::trajectory::fourier_walk::MAX_FOURIER_TERMS as u32),
        doc: "terms per axis of the Fourier CoM (`com=fourier`)",
        set: |c, v| { c.fourier_terms = v as u8 },
        get: |c| { Some(Value::Int(u32::from(c.fourier_terms))) },
    },
    {
        key: "servo_lead",
        plan_key: None,
        unit: "s",
        domain: range(0.0, crate::config::MAX_SERVO_LEAD_S),
        doc: "servo-lag feed-forward: joint targets are the gait's this far ahead of the reference (rounded to ticks)",
        set: |c, v| { c.servo_lead_s = v as f32 },
        get: |c| { Some(Value::Num32(c.servo_lead_s)) },
    },
    {
        key: "servo_i_roll",
        plan_key: None,
        unit: "",
        domain: int(0, 16383),
        doc: "Position I Gain (register 82) written at start-up to the ankle-roll servos (the hip rolls': servo_i_hip_roll): integral action against the stance leg's load sag (0: the factory default, no write)",
        set: |c, v| { c.servo_i_roll = v as u16 },
        get: |c| { Some(Value::Int(u32::from(c.servo_i_roll))) },
    },
    {
        key: "servo_i_hip_roll",
        plan_key: None,
        unit: "",
        domain: int(0, 16383),
        doc: "Position I Gain (register 82) written at start-up to the hip-roll servos (0: the factory default, no write)",
        set: |c, v| { c.servo_i_hip_roll = v as u16 },
        get: |c| { Some(Value::Int(u32::from(c.servo_i_hip_roll))) },
    },
    {
        key: "servo_i_pitch",
        plan_key: None,
        unit: "",
        domain: int(0, 16383),
        doc: "Position I Gain written at start-up to the hip-pitch, knee and ankle-pitch servos (0: factory default)",
        set: |c, v| { c.servo_i_pitch = v as u16 },
        get: |c| { Some(Value::Int(u32::from(c.servo_i_pitch))) },
    },
    {
        key: "fault_nan_com",
        plan_key: None,
        unit: "tick",
        domain: int(0, u32::MAX),
        doc: "test: make the gait sample's CoM NaN at this walk tick (the finite check before the IK stops, exit 18)",
        set: |c, v| { c.fault_nan_com_tick = Some(v as u32) },
        get: |c| { c.fault_nan_com_tick.map(Value::Int) },
    },
    {
        key: "stale_ms",
        plan_key: None,
        unit: "ms",
        domain: int(1, 10_000),
        doc: "longest time without a plausible sensor reply before the robot stops (exit 19)",
        set: |c, v| { c.sensor_stale_ms = v as u32 },
        get: |c| { Some(Value::Int(c.sensor_stale_ms)) },
    },
    {
        key: "force_factor",
        plan_key: None,
        unit: "",
        domain: range(1.0, 20.0),
        doc: "foot forces above m·g·force_factor (one foot or both) are implausible",
        set: |c, v| { c.force_factor = v as f32 },
        get: |c| { Some(Value::Num32(c.force_factor)) },
    },
    {
        key: "off_attempts",
        plan_key: None,
        unit: "",
        domain: int(1, 10),
        doc: "rounds of torque off + Torque Enable read-back before the servo power is cut",
        set: |c, v| { c.torque_off_attempts = v as u8 },
        get: |c| { Some(Value::Int(u32::from(c.torque_off_attempts))) },
    },
    {
        key: "servo_temp_max",
        plan_key: None,
        unit: "°C",
        domain: int(1, 100),
        doc: "servo monitor: highest Present Temperature",
        set: |c, v| { c.servo_limits.temperature_max_c = v as u8 },
        get: |c| { Some(Value::Int(u32::from(c.servo_limits.temperature_max_c))) },
    },
    {
        key: "servo_volt_min",
        plan_key: None,
        unit: "V",
        domain: range(0.0, 30.0),
        doc: "servo monitor: lowest Present Input Voltage",
        set: |c, v| { c.servo_limits.voltage_min_v = v as f32 },
        get: |c| { Some(Value::Num32(c.servo_limits.voltage_min_v)) },
    },
    {
        key: "servo_volt_max",
        plan_key: None,
        unit: "V",
        domain: range(0.0, 30.0),
        doc: "servo monitor: highest Present Input Voltage",
        set: |c, v| { c.servo_limits.voltage_max_v = v as f32 },
        get: |c| { Some(Value::Num32(c.servo_limits.voltage_max_v)) },
    },
    {
        key: "servo_current_max",
        plan_key: None,
        unit: "A",
        domain: range(0.0, 20.0),
        doc: "servo monitor: highest |Present Current| (over it in two READs of a servo in a row: stop)",
        set: |c, v| { c.servo_limits.current_max_a = v as f32 },
        get: |c| { Some(Value::Num32(c.servo_limits.current_max_a)) },
    },
    {
        key: "autostart",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["0", "1"]),
        doc: "1: walk the configured forward plan at power-on (demos, the FIL tests); 0 (default): stand up and wait for the command port",
        set: |c, v| { c.autostart = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.autostart))) },
    },
    {
        key: "servo_misses",
        plan_key: None,
        unit: "READs",
        domain: int(1, 20),
        doc: "servo monitor READs of one servo unanswered in a row that make it lost (stop ServoLost)",
        set: |c, v| { c.servo_limits.miss_limit = v as u8 },
        get: |c| { Some(Value::Int(u32::from(c.servo_limits.miss_limit))) },
    },
    {
        key: "wait_enable",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["0", "1"]),
        doc: "1: torque stays off until a Mode write of stand or walk on the command port, at power-on and after every stop (the default of the OpenCR and OpenCM builds); 0: start at once, the run ends at the first stop",
        set: |c, v| { c.wait_enable = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.wait_enable))) },
    },
    {
        key: "rest",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["0", "1"]),
        doc: "1: an operator's stop (Mode = torque off) walks to a standstill, lowers to the crouch and rests there with torque on (State 6); a second Mode = torque off turns torque off; 0: torque off after the crouch's hold (a limp robot does not keep the crouch)",
        set: |c, v| { c.rest = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.rest))) },
    },
    {
        key: "deadman_ms",
        plan_key: None,
        unit: "ms",
        domain: int(50, 10_000),
        doc: "command deadman: in Mode = walk, no valid command write on the command port for this long stops the online walk to standing (Stop Code 13)",
        set: |c, v| { c.deadman_ms = v as u32 },
        get: |c| { Some(Value::Int(c.deadman_ms)) },
    },
    {
        key: "catch_level_joints",
        plan_key: None,
        unit: "1",
        domain: range(0.0, 1.5),
        doc: "catching step: swing sole levelling gain on the swing leg's pitch lag, the hip pitch's and knee's Present Position against their IK targets and the ankle's against its own (A10; 0 = off, no position reads; keep < 1)",
        set: |c, v| { c.step_adaptation.level_joints = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.level_joints)) },
    },
    {
        key: "catch_hold_lag",
        plan_key: None,
        unit: "m",
        domain: range(0.0, 0.05),
        doc: "catching step: the plan's clock also holds in the landing while the swing sole, by forward kinematics of the Present Position, is farther than this from where its targets put it (A11; 0 = off, no position reads)",
        set: |c, v| { c.step_adaptation.hold_lag_m = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.hold_lag_m)) },
    },
    {
        key: "landing_gain",
        plan_key: None,
        unit: "1/step",
        domain: range(0.0, 1.0),
        doc: "plan walk: landing hold, share of the feet's midpoint's surveyed distance (along the stance heading) from where the plan and the catches put it that the next landing place corrects (gait-core catch A8-A9, needs sole_poses=measured; 0 = off; the online walk: position_gain)",
        set: |c, v| { c.step_adaptation.landing_gain = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.landing_gain)) },
    },
    {
        key: "landing_lateral",
        plan_key: None,
        unit: "1/step",
        domain: range(0.0, 1.0),
        doc: "plan walk: the landing hold across the stance heading, share of the feet's midpoint's sideways distance the next landing place corrects (gait-core catch A9; 0 = off: sideways the plan's)",
        set: |c, v| { c.step_adaptation.landing_lateral = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.landing_lateral)) },
    },
    {
        key: "landing_ramp",
        plan_key: None,
        unit: "s",
        domain: range(0.0, 1.0),
        doc: "plan walk: landing hold, time over which its move enters the swing foot's landing place after lift-off (gait-core catch A9)",
        set: |c, v| { c.step_adaptation.landing_ramp_s = v as f32 },
        get: |c| { Some(Value::Num32(c.step_adaptation.landing_ramp_s)) },
    },
    {
        key: "deflection_soft",
        plan_key: None,
        unit: "1/s",
        domain: range(0.0, 50.0),
        doc: "servo deflection feedback: integral gain added per unit of the leg servos' softness measured standing before the first step (gait-core deflection D6, stiffness K3; 0 = none; the survey runs while this or gyro_follow is on)",
        set: |c, v| { c.deflection.soft_ki = v as f32 },
        get: |c| { Some(Value::Num32(c.deflection.soft_ki)) },
    },
    {
        key: "gyro_follow",
        plan_key: None,
        unit: "",
        domain: Domain::Word(&["0", "1"]),
        doc: "1 (default): the gyro damping's gains × K_n/K̂ when the servo survey measures the leg servos stiffer than servo_stiffness (gait-core gyro G3); 0: the gains as set",
        set: |c, v| { c.gyro_feedback.follow_stiffness = v as usize == 1 },
        get: |c| { Some(Value::Word(usize::from(c.gyro_feedback.follow_stiffness))) },
    },
    {
        key: "robot",
        plan_key: Some("robot"),
        unit: "",
        domain: Domain::Word(&gait_core::robot::ROBOT_NAMES),
        doc: "the robot walked, by its description (gait-core `robot/`): tku-x (the reference robot) or op3 (ROBOTIS OP3); sets baud to the robot's (a later baud= overrides it)",
        set: |c, v| {
            if let Some(r) = gait_core::robot::ROBOTS.get(v as usize) {
                c.robot = r;
                c.bus_baud = r.bus.baud;
            }
        },
        get: |c| {
            gait_core::robot::ROBOT_NAMES
                .iter()
                .position(|&n| n == c.robot.name)
                .map(Value::Word)
        },
    },
}

/// Key index meaning "not a known key".
pub const UNKNOWN_KEY: u8 = 0xFF;
/// Key index (the `ConfigRejected` fault record's id) meaning "the command line could not be
/// read: longer than [`CMDLINE_MAX`]" (value = [`CMDLINE_MAX`]).
pub const CMDLINE_TOO_LONG: u8 = 0xFD;

/// The QEMU firmware's semihosting command-line buffer, bytes. QEMU's SYS_GET_CMDLINE hands
/// over the kernel's file name, a space and the `-append` text with a NUL, and refuses (the
/// firmware then reads nothing) when that does not fit: the host checks
/// [`cmdline_fits`] before it starts QEMU.
pub const CMDLINE_MAX: usize = 1024;

/// True when `kernel` (the ELF path as given to QEMU's `-kernel`) and the `-append` text fit
/// the firmware's [`CMDLINE_MAX`]: `len(kernel) + 1 + len(append) + 1 ≤ CMDLINE_MAX`.
pub const fn cmdline_fits(kernel_len: usize, append_len: usize) -> bool {
    kernel_len + append_len + 2 <= CMDLINE_MAX
}

/// The fault-injection parameters (tests only): never saved ([`crate::param_store`]).
pub const TEST_ONLY: [&str; 4] = ["fault_nan", "fault_nan_com", "stop_at", "cut_save"];

/// A board's word, not a parameter: `store=PATH`, the host file prefix of the QEMU board's
/// parameter store (`PATH0`, `PATH1`: [`crate::param_store`]'s two slots); [`apply`] skips it.
pub const STORE_WORD: &str = "store";

/// A board's word, not a parameter: `realtime`, the QEMU board holds its virtual time back to
/// the host's wall clock (for any master on the command port; docs/lockstep.md); [`apply`]
/// skips it.
pub const REALTIME_WORD: &str = "realtime";

/// The parameter of `key`.
pub fn find(key: &str) -> Option<&'static Param> {
    PARAMS.iter().find(|p| p.key == key)
}

/// The parameter whose plan-file key is `plan_key`.
pub fn find_plan_key(plan_key: &str) -> Option<&'static Param> {
    PARAMS.iter().find(|p| p.plan_key == Some(plan_key))
}

/// What was wrong with a token.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub enum ArgErrorKind {
    /// The key is not known.
    UnknownKey,
    /// The value does not parse (number, word).
    BadValue,
    /// The value parses but is out of range.
    OutOfRange,
    /// A bare word other than `lockstep` (or the program name) where `key=value` is expected.
    StrayWord,
    /// The key was given before on the same command line (the position is the second one's).
    Repeated,
}

impl ArgErrorKind {
    /// In a few words.
    pub const fn reason(self) -> &'static str {
        match self {
            ArgErrorKind::UnknownKey => "unknown key",
            ArgErrorKind::BadValue => "bad value",
            ArgErrorKind::OutOfRange => "out of range",
            ArgErrorKind::StrayWord => "not a key=value pair",
            ArgErrorKind::Repeated => "given twice",
        }
    }
}

/// Longest key kept in an [`ArgError`], bytes.
const KEY_MAX: usize = 24;

/// The first bad token.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ArgError {
    /// What was wrong.
    pub kind: ArgErrorKind,
    /// Index of the key in [`PARAMS`], or [`UNKNOWN_KEY`].
    pub key_index: u8,
    /// Position of the token on the command line (0 = first token).
    pub position: u8,
    key: [u8; KEY_MAX],
    key_len: u8,
}

impl ArgError {
    /// The key (or bare word) as written, truncated to 24 bytes.
    pub fn key(&self) -> &str {
        let n = usize::from(self.key_len).min(KEY_MAX);
        self.key
            .get(..n)
            .and_then(|k| core::str::from_utf8(k).ok())
            .unwrap_or("?")
    }
}

impl fmt::Display for ArgError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "`{}`: {}", self.key(), self.kind.reason())?;
        if self.kind == ArgErrorKind::OutOfRange {
            if let Some(p) = find(self.key()) {
                f.write_str(" (")?;
                p.write_domain(f)?;
                if !p.unit.is_empty() {
                    write!(f, " {}", p.unit)?;
                }
                f.write_str(")")?;
            }
        }
        Ok(())
    }
}

/// The index of `key` in `keys` at compile time ([`UNKNOWN_KEY`] when absent).
// Evaluated in `const` items only (an out-of-range index would be a build error); `i < len`.
#[allow(clippy::indexing_slicing)]
const fn key_position(keys: &[&str], key: &str) -> u8 {
    let mut i = 0;
    while i < keys.len() {
        if const_eq(keys[i].as_bytes(), key.as_bytes()) {
            return i as u8;
        }
        i += 1;
    }
    UNKNOWN_KEY
}

/// Byte-wise equality usable in `const` evaluation.
// `i < a.len() == b.len()`: both indexings are in range.
#[allow(clippy::indexing_slicing)]
const fn const_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

fn key_index(key: &str) -> u8 {
    KEYS.iter()
        .position(|k| *k == key)
        .and_then(|i| u8::try_from(i).ok())
        .unwrap_or(UNKNOWN_KEY)
}

/// Significant digits kept by [`decimal`] (a `u64` holds any 19-digit number); later digits
/// only move the decimal exponent (before the point) or are dropped (after it), a relative
/// change below 1e-18, far under f64's 1.1e-16.
const MAX_DIGITS: u32 = 19;

/// Decimal exponents beyond this give ±∞ / 0 (f64 ends at 1.8e308 and 4.9e-324).
const MAX_EXP10: i32 = 400;

/// `10^e` for `0 ≤ e ≤ 22`, exact (every power of ten up to 1e22 is an f64, and so is each
/// product of the loop).
fn pow10_exact(e: u32) -> f64 {
    let mut p = 1.0f64;
    for _ in 0..e.min(22) {
        p *= 10.0;
    }
    p
}

/// `mant · 10^exp` as f64. Correctly rounded (the same f64 as `str::parse`) when
/// `mant ≤ 2⁵³` and `|exp| ≤ 22` (Clinger's fast path: one exact operand pair, one rounding),
/// which covers every ordinary parameter (≤ 15 significant digits, e.g. `0.005`, `-1e-3`,
/// `3000000`); otherwise within a few ulp (one rounding per factor of 1e22).
fn scale10(mant: u64, exp: i32) -> f64 {
    const EXACT: u64 = 1 << 53;
    if mant == 0 || exp < -MAX_EXP10 {
        return 0.0;
    }
    if exp > MAX_EXP10 {
        return f64::INFINITY;
    }
    let (mut mant, mut exp) = (mant, exp);
    // Move surplus exponent into the mantissa while it stays exact (e.g. `123e25`).
    while exp > 22 {
        match mant.checked_mul(10) {
            Some(m) if m <= EXACT => {
                mant = m;
                exp -= 1;
            }
            _ => break,
        }
    }
    let mut x = mant as f64;
    while exp > 22 {
        x *= pow10_exact(22);
        exp -= 22;
    }
    while exp < -22 {
        x /= pow10_exact(22);
        exp += 22;
    }
    if exp >= 0 {
        x * pow10_exact(exp as u32)
    } else {
        x / pow10_exact(exp.unsigned_abs())
    }
}

/// A decimal number: `[+-] digits [. digits] [(e|E) [+-] digits]`, at least one digit in the
/// mantissa (`.5` and `5.` are fine, `.`, `e3`, `1e`, `inf`, `nan`, `0x1`, spaces are not).
/// The digits accumulate in a `u64` ([`MAX_DIGITS`]), the exponent in an `i32`, and the value
/// is converted once ([`scale10`]) — no `core::num::dec2flt` (≈ 13 KB of tables and code).
fn decimal(v: &str) -> Option<f64> {
    let b = v.as_bytes();
    let (neg, mut i) = match b.first() {
        Some(b'-') => (true, 1),
        Some(b'+') => (false, 1),
        _ => (false, 0),
    };
    let (mut mant, mut digits, mut exp) = (0u64, 0u32, 0i32);
    let (mut any, mut dot) = (false, false);
    while let Some(&c) = b.get(i) {
        match c {
            b'0'..=b'9' => {
                any = true;
                if mant == 0 && c == b'0' {
                    // A leading zero: only its place counts.
                    exp -= i32::from(dot);
                } else if digits < MAX_DIGITS {
                    mant = mant * 10 + u64::from(c - b'0');
                    digits += 1;
                    exp -= i32::from(dot);
                } else {
                    exp += i32::from(!dot);
                }
                exp = exp.clamp(-2 * MAX_EXP10, 2 * MAX_EXP10);
            }
            b'.' if !dot => dot = true,
            b'e' | b'E' => break,
            _ => return None,
        }
        i += 1;
    }
    if !any {
        return None;
    }
    if i < b.len() {
        // b[i] is the exponent letter.
        i += 1;
        let eneg = match b.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let rest = b.get(i..).unwrap_or(&[]);
        if rest.is_empty() {
            return None;
        }
        let mut e = 0i32;
        for &c in rest {
            if !c.is_ascii_digit() {
                return None;
            }
            e = (e * 10 + i32::from(c - b'0')).min(4 * MAX_EXP10);
        }
        exp += if eneg { -e } else { e };
    }
    let x = scale10(mant, exp);
    Some(if neg { -x } else { x })
}

/// A finite decimal; a well-formed decimal beyond f64 (`1e400`) is out of range.
fn num(v: &str) -> Result<f64, ArgErrorKind> {
    match decimal(v) {
        Some(x) if x.is_finite() => Ok(x),
        Some(_) => Err(ArgErrorKind::OutOfRange),
        None => Err(ArgErrorKind::BadValue),
    }
}

fn error(kind: ArgErrorKind, key: &[u8], position: usize) -> ArgError {
    let mut k = [0u8; KEY_MAX];
    let n = key.len().min(KEY_MAX);
    if let (Some(dst), Some(src)) = (k.get_mut(..n), key.get(..n)) {
        dst.copy_from_slice(src);
    }
    let idx = core::str::from_utf8(key).map_or(UNKNOWN_KEY, key_index);
    ArgError {
        kind,
        key_index: if kind == ArgErrorKind::StrayWord {
            UNKNOWN_KEY
        } else {
            idx
        },
        position: u8::try_from(position).unwrap_or(u8::MAX),
        key: k,
        key_len: u8::try_from(n).unwrap_or(0),
    }
}

/// Which keys of [`PARAMS`] a command line has set (one bit per key index; 0xFF, unknown,
/// never set).
#[derive(Default)]
struct Seen([u64; 4]);

impl Seen {
    /// Marks `index`; false when it was marked before.
    fn first(&mut self, index: u8) -> bool {
        let (word, bit) = (usize::from(index / 64), 1u64 << (index % 64));
        match self.0.get_mut(word) {
            Some(w) if *w & bit != 0 => false,
            Some(w) => {
                *w |= bit;
                true
            }
            None => true,
        }
    }
}

/// Applies every `key=value` token of `cmdline` to `cfg` (see the module docs); stops at the
/// first bad token. A key given twice is refused ([`ArgErrorKind::Repeated`], at the second
/// token): which of the two should win is the writer's to say. `cfg` may be partly updated
/// when an error is returned.
pub fn apply(cfg: &mut Config, cmdline: &[u8]) -> Result<(), ArgError> {
    let tokens = cmdline
        .split(|&b| b == b' ' || b == b'\t' || b == 0 || b == b'\n' || b == b'\r')
        .filter(|t| !t.is_empty());
    let mut seen = Seen::default();
    for (pos, tok) in tokens.enumerate() {
        let Some(eq) = tok.iter().position(|&b| b == b'=') else {
            if tok == crate::lockstep::PIPE_WORD.as_bytes()
                || tok == REALTIME_WORD.as_bytes()
                || pos == 0
            {
                continue; // the board's words, or the program name
            }
            return Err(error(ArgErrorKind::StrayWord, tok, pos));
        };
        let (key, rest) = tok.split_at(eq);
        if key == STORE_WORD.as_bytes() || key == crate::lockstep::PIPE_WORD.as_bytes() {
            continue; // the board's (the QEMU board's parameter store, its lock-step pipes)
        }
        let val = rest.get(1..).unwrap_or(&[]);
        let (Ok(k), Ok(v)) = (core::str::from_utf8(key), core::str::from_utf8(val)) else {
            return Err(error(ArgErrorKind::BadValue, key, pos));
        };
        let index = key_index(k);
        if index != UNKNOWN_KEY && !seen.first(index) {
            return Err(error(ArgErrorKind::Repeated, key, pos));
        }
        apply_one(cfg, k, v).map_err(|kind| error(kind, key, pos))?;
    }
    Ok(())
}

/// Writes the parameter table as Markdown (`docs/parameters.md` is this text).
pub fn write_markdown(out: &mut impl fmt::Write) -> fmt::Result {
    out.write_str(
        "# Run-time parameters\n\n\
         Generated from `contract/src/params.rs` (`PARAMS`); a test fails when this file is \
         stale\n(regenerate: `WALKER_BLESS=1 cargo test --target host-tuple -p walker-contract`).\n\n\
         The firmware reads them as `key=value` tokens (QEMU: the semihosting command line);\n\
         `walker fil` emits them from the plan file: a key with a plan key is a top-level key of \
         the plan,\nany other is set in the plan's `[firmware]` table under its token key.\n\n\
         | key | plan key | unit | values | default | sets |\n\
         | --- | --- | --- | --- | --- | --- |\n",
    )?;
    let d = Config::default();
    for p in PARAMS.iter() {
        write!(out, "| `{}` | ", p.key)?;
        match p.plan_key {
            Some(k) => write!(out, "`{k}`")?,
            None => write!(out, "`[firmware] {}`", p.key)?,
        }
        write!(out, " | {} | ", p.unit)?;
        p.write_domain(out)?;
        out.write_str(" | ")?;
        match p.value(&d) {
            Some(v) => p.write_value(v, out)?,
            None => out.write_str("unset")?,
        }
        writeln!(out, " | {} |", p.doc)?;
    }
    Ok(())
}

/// Writes one parameter's facts on one line (the per-key lines of `docs/tuning.md`): unit,
/// default, values, where a plan file sets it, and what it sets.
pub fn write_facts(p: &Param, out: &mut impl fmt::Write) -> fmt::Result {
    write!(out, "`{}`", p.key)?;
    if !p.unit.is_empty() {
        write!(out, " · unit {}", p.unit)?;
    }
    out.write_str(" · default ")?;
    match p.value(&Config::default()) {
        Some(v) => p.write_value(v, out)?,
        None => out.write_str("unset")?,
    }
    out.write_str(" · values ")?;
    p.write_domain(out)?;
    match p.plan_key {
        Some(k) => write!(out, " · plan key `{k}`")?,
        None => write!(out, " · plan `[firmware] {}`", p.key)?,
    }
    write!(out, " · {}", p.doc)
}

/// `text` with the line after every `<!-- facts KEY -->` marker replaced by [`write_facts`] of
/// KEY, and the keys of [`PARAMS`] that have no marker (`docs/tuning.md` is checked with it).
#[cfg(test)]
fn with_current_facts(text: &str) -> (std::string::String, std::vec::Vec<&'static str>) {
    use std::string::String;
    let mut out = String::new();
    let mut seen = std::vec::Vec::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        out.push_str(line);
        out.push('\n');
        let Some(key) = line
            .strip_prefix("<!-- facts ")
            .and_then(|r| r.strip_suffix(" -->"))
        else {
            continue;
        };
        let p = find(key).unwrap_or_else(|| panic!("docs/tuning.md: unknown key {key}"));
        seen.push(p.key);
        lines.next();
        write_facts(p, &mut out).unwrap();
        out.push('\n');
    }
    let missing = PARAMS
        .iter()
        .map(|p| p.key)
        .filter(|k| !seen.contains(k))
        .collect();
    (out, missing)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::format;
    use std::string::{String, ToString};
    use std::vec::Vec;

    fn parse(s: &str) -> Result<Config, ArgError> {
        let mut c = Config::default();
        apply(&mut c, s.as_bytes()).map(|()| c)
    }

    #[test]
    fn empty_and_program_name() {
        assert_eq!(parse(""), Ok(Config::default()));
        assert_eq!(
            parse("target/thumbv7em-none-eabihf/release/qemu lockstep\0"),
            Ok(Config::default())
        );
        // The board's words with a value: skipped, not parameters.
        assert_eq!(
            parse("elf lockstep=/tmp/walker-ls-1 store=/tmp/s realtime dt=0.01"),
            parse("elf dt=0.01")
        );
        assert_ne!(parse("elf dt=0.01"), Ok(Config::default()));
    }

    #[test]
    fn every_key_parses() {
        let c = parse(
            "/x/qemu lockstep model=lipm dt=0.002 steps=4 step_length=0.03 step_width=0.05 \
             s_first=1 d1=0.011 d2=0.012 a=0.003 zmp=natural z_c=0.2 w_y=0.001 h_z=0.025 \
             swing=sinusoid t1=0.1 t2=0.5 period=0.7 lead_in=1.0 lead_out=1.2 ramp=0.5 \
             hold=2 min_load=3.5 feet=optional reply_timeout_us=800 read_poll_us=10 \
             attempts=2 baud=3000000 return_delay_us=4 compute_us=300 core_mhz=72 watchdog_ms=40 \
             hold_ticks=7 stopping_ticks=50 overrun_burst=3 tilt_limit=0.5 imu_cutoff=10 \
             fault_nan=12 stop_at=99 b=0.002 comp=wholebody stab=on stab_kp=0.5 stab_ki=3 \
             stab_leak=0.1 stab_kg=0.15 stab_k=2 stab_max=0.015 stab_rate=0.1 stab_margin=0.004 \
             stab_cutoff=20 feasibility=lower",
        )
        .unwrap();
        assert_eq!(c.compensation, Compensation::WholeBody);
        assert!(c.stabilizer_on);
        let st = c.stabilizer;
        assert_eq!((st.kp, st.ki, st.leak, st.kg), (0.5, 3.0, 0.1, 0.15));
        assert_eq!((st.dcm_k, st.max_shift, st.max_rate), (2.0, 0.015, 0.1));
        assert_eq!((st.margin, st.cutoff_hz), (0.004, 20.0));
        assert!(st.is_valid());
        assert_eq!(c.feasibility, Feasibility::Lower);
        assert_eq!(c.model, ModelKind::Lipm);
        assert_eq!(c.tick_period_us, 2000);
        assert_eq!(c.walk.steps, 4);
        assert_eq!(c.walk.s_first, 1);
        assert_eq!((c.walk.t1, c.walk.t2, c.walk.period), (0.1, 0.5, 0.7));
        assert_eq!((c.walk.lead_in, c.walk.lead_out), (1.0, 1.2));
        assert_eq!((c.walk.d1, c.walk.d2, c.walk.a), (0.011, 0.012, 0.003));
        assert_eq!((c.walk.z_c, c.walk.w_y, c.walk.h_z), (0.2, 0.001, 0.025));
        assert!(c.swing_sinusoid && c.zmp_continuous);
        assert_eq!(c.zmp_b, Some(0.002));
        assert_eq!((c.ramp_us, c.final_hold_us), (500_000, 2_000_000));
        assert_eq!(c.min_load_n, 3.5);
        assert!(!c.feet_required);
        assert_eq!(
            (c.reply_timeout_us, c.read_poll_us, c.startup_attempts),
            (800, 10, 2)
        );
        assert_eq!(
            (c.bus_baud, c.return_delay_us, c.compute_us, c.core_mhz),
            (3_000_000, 4, 300, 72)
        );
        assert_eq!(c.watchdog_ms, 40);
        assert_eq!(c.supervisor.hold_ticks, 7);
        assert_eq!(c.supervisor.stopping_ticks, 50);
        assert_eq!(c.supervisor.overrun_burst, 3);
        assert_eq!(c.supervisor.tilt_limit_rad, 0.5);
        assert_eq!(c.imu_cutoff_hz, 10.0);
        assert_eq!((c.fault_nan_tick, c.stop_at_tick), (Some(12), Some(99)));
    }

    /// A small deterministic generator for the decimal tests (proptest's ChaCha, seeded).
    struct Gen(proptest::test_runner::TestRng);
    impl Gen {
        fn new(seed: u64) -> Self {
            let mut s = [0u8; 32];
            s[..8].copy_from_slice(&seed.to_le_bytes());
            let algorithm = proptest::test_runner::RngAlgorithm::ChaCha;
            Gen(proptest::test_runner::TestRng::from_seed(algorithm, &s))
        }
        fn below(&mut self, n: u64) -> u64 {
            use proptest::prelude::RngExt;
            self.0.random_range(0..n)
        }
        fn digits(&mut self, s: &mut String, n: u64) {
            for _ in 0..n {
                s.push(char::from(b'0' + self.below(10) as u8));
            }
        }
    }

    #[test]
    fn decimal_matches_str_parse() {
        let fixed = [
            "0.005",
            "0.217",
            "-1e-3",
            "3000000",
            "0",
            "-0",
            "+1",
            ".5",
            "5.",
            "1E+5",
            "2e0",
            "0.0001",
            "100000",
            "4500000",
            "0.170962",
            "0.970934",
            "9.81",
            "1e22",
            "1e-22",
            "123e25",
            "0.1",
            "0.2",
            "0.3",
            "1.7976931348623157e308",
            "2.2250738585072014e-308",
            "1e-400",
            "00012.5000",
            "0.000000000000000000000000123",
            "12345678901234567890123",
            "1.2345678901234567890123e-5",
        ];
        let mut g = Gen::new(0x9E37_79B9_7F4A_7C15);
        let mut cases: Vec<String> = fixed.iter().map(|s| s.to_string()).collect();
        for _ in 0..6000 {
            let mut s = String::new();
            match g.below(3) {
                0 => s.push('-'),
                1 if g.below(4) == 0 => s.push('+'),
                _ => {}
            }
            let int = g.below(7);
            let frac = g.below(9);
            g.digits(&mut s, int);
            if frac > 0 || int == 0 || g.below(5) == 0 {
                s.push('.');
                g.digits(&mut s, frac.max(u64::from(int == 0)));
            }
            if g.below(3) == 0 {
                s.push(if g.below(2) == 0 { 'e' } else { 'E' });
                match g.below(3) {
                    0 => s.push('-'),
                    1 => s.push('+'),
                    _ => {}
                }
                s.push_str(&g.below(13).to_string());
            }
            cases.push(s);
        }
        let mut fast = 0;
        for s in &cases {
            let ours = decimal(s).unwrap_or_else(|| panic!("{s} rejected"));
            let theirs32: f32 = s.parse().unwrap();
            let theirs64: f64 = s.parse().unwrap();
            assert_eq!(
                (ours as f32).to_bits(),
                theirs32.to_bits(),
                "{s}: {ours} as f32 vs {theirs32}"
            );
            // ≤ 15 significant digits and a small exponent: the very same f64.
            let sig = s
                .split(['e', 'E'])
                .next()
                .unwrap()
                .trim_start_matches(['+', '-', '0', '.'])
                .replace('.', "");
            let sig = sig.trim_end_matches('0');
            if sig.len() <= 15 && theirs64.abs() < 1e15 && theirs64.abs() > 1e-7 {
                assert_eq!(
                    ours.to_bits(),
                    theirs64.to_bits(),
                    "{s}: {ours} vs {theirs64}"
                );
                fast += 1;
            } else if theirs64 != 0.0 {
                let rel = ((ours - theirs64) / theirs64).abs();
                assert!(rel < 1e-15, "{s}: {ours} vs {theirs64}");
            }
        }
        assert!(fast > 5000, "{fast}");
    }

    #[test]
    fn decimal_rejects_what_is_not_a_finite_decimal() {
        for s in [
            "", "+", "-", ".", "-.", "e5", ".e1", "1e", "1e+", "1e-", "1.2.3", "1e5.0", "1e1e1",
            "inf", "-inf", "infinity", "nan", "NaN", "0x10", " 1", "1 ", "1_000", "--1", "+-1",
            "1,5", "١", "1ee3", "1e+-3",
        ] {
            assert_eq!(num(s), Err(ArgErrorKind::BadValue), "{s:?}");
            if let Ok(x) = s.parse::<f64>() {
                assert!(!x.is_finite(), "{s:?} parses to {x} in core");
            }
        }
        assert_eq!(num("1e-400"), Ok(0.0));
        for s in ["1e400", "-1e309", "1.8e308"] {
            assert_eq!(num(s), Err(ArgErrorKind::OutOfRange), "{s:?}");
        }
        let p = Param {
            domain: range(0.0, 10.0),
            ..PARAMS[1]
        };
        assert_eq!(p.parse("-0.001"), Err(ArgErrorKind::OutOfRange));
        assert_eq!(p.parse("0.5e1"), Ok(Value::Num(5.0)));
    }

    #[test]
    fn every_key_is_handled() {
        for (i, p) in PARAMS.iter().enumerate() {
            let k = p.key;
            let mut c = Config::default();
            // A value no key accepts: the error must be about the value, not the key.
            let e = apply_one(&mut c, k, "%");
            assert!(matches!(e, Err(ArgErrorKind::BadValue)), "{k}: {e:?}");
            assert_eq!(key_index(k), i as u8);
            // Out of its domain: refused, naming the key.
            let mut bad = String::new();
            p.out_of_domain(&mut bad).unwrap();
            let line = format!("elf {k}={bad}");
            let e = apply(&mut c, line.as_bytes()).unwrap_err();
            assert_eq!(e.key(), k, "{line}");
            assert!(
                matches!(e.kind, ArgErrorKind::OutOfRange | ArgErrorKind::BadValue),
                "{line}: {e:?}"
            );
        }
        let keys: Vec<&str> = PARAMS.iter().map(|p| p.key).collect();
        let mut sorted = keys.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), keys.len(), "a key is declared twice");
        let plan: Vec<&str> = PARAMS.iter().filter_map(|p| p.plan_key).collect();
        let mut sorted = plan.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), plan.len(), "a plan key is declared twice");
    }

    /// Each default, written as token text, parses back to the very same `Config`; so does
    /// a value set away from the default.
    #[test]
    fn every_value_round_trips_through_its_text() {
        let d = Config::default();
        for p in PARAMS.iter() {
            let Some(v) = p.value(&d) else {
                continue;
            };
            let mut text = String::new();
            p.write_value(v, &mut text).unwrap();
            let mut c = Config::default();
            p.apply(&mut c, &text).unwrap();
            assert_eq!(c, d, "{}={text}", p.key);
        }
        let mut c = Config::default();
        apply(
            &mut c,
            b"elf model=dlipm dt=0.002 ramp=0.25 tilt_limit=0.4 min_load=2.5 stab=on b=0.003",
        )
        .unwrap();
        let mut line = String::from("elf");
        for p in PARAMS.iter() {
            if let Some(v) = p.value(&c) {
                line.push(' ');
                line.push_str(p.key);
                line.push('=');
                p.write_value(v, &mut line).unwrap();
            }
        }
        let mut back = Config::default();
        apply(&mut back, line.as_bytes()).unwrap();
        assert_eq!(back, c, "{line}");
    }

    /// Physically absurd walks are refused by the parser, naming the key (the host runs this
    /// same parser on the tokens of a plan file).
    #[test]
    fn absurd_walk_values_name_their_key() {
        for (line, key) in [
            ("elf d2=1e38", "d2"),
            ("elf d1=1.7976931348623157e308", "d1"),
            ("elf h_z=10", "h_z"),
        ] {
            let e = parse(line).unwrap_err();
            assert_eq!((e.kind, e.key()), (ArgErrorKind::OutOfRange, key), "{line}");
            assert!(e.to_string().contains(key), "{e}");
        }
    }

    #[test]
    fn the_docs_table_is_current() {
        let mut text = String::new();
        write_markdown(&mut text).unwrap();
        for p in PARAMS.iter() {
            assert!(text.contains(&format!("| `{}` |", p.key)), "{}", p.key);
        }
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/parameters.md");
        if std::env::var_os("WALKER_BLESS").is_some() {
            std::fs::write(path, &text).unwrap();
        }
        let on_disk = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            on_disk == text,
            "docs/parameters.md is stale: WALKER_BLESS=1 cargo test --target host-tuple -p walker-contract"
        );
    }

    /// Every key of the table has its facts line in the tuning guide, generated from the table
    /// (the advice around it is prose).
    #[test]
    fn the_tuning_guide_covers_every_key() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/tuning.md");
        let on_disk = std::fs::read_to_string(path).unwrap_or_default();
        let (text, missing) = with_current_facts(&on_disk);
        assert!(
            missing.is_empty(),
            "docs/tuning.md has no section for {missing:?}"
        );
        for p in PARAMS.iter() {
            assert_eq!(
                on_disk
                    .matches(&format!("<!-- facts {} -->", p.key))
                    .count(),
                1,
                "{}",
                p.key
            );
        }
        if std::env::var_os("WALKER_BLESS").is_some() {
            std::fs::write(path, &text).unwrap();
        }
        assert!(
            on_disk == text,
            "docs/tuning.md facts are stale: WALKER_BLESS=1 cargo test --target host-tuple -p walker-contract"
        );
    }

    #[test]
    fn a_repeated_key_is_refused_at_its_second_token() {
        let e = parse("elf lockstep t1=0.1 dt=0.002 t1=0.12").unwrap_err();
        assert_eq!(
            (e.kind, e.key(), e.position),
            (ArgErrorKind::Repeated, "t1", 4)
        );
        assert_eq!(
            Some(usize::from(e.key_index)),
            KEYS.iter().position(|k| *k == "t1")
        );
        assert_eq!(e.to_string(), "`t1`: given twice");
        // The same value twice is refused too, and so is a word key.
        let e = parse("elf stab=on stab=on").unwrap_err();
        assert_eq!(
            (e.kind, e.key(), e.position),
            (ArgErrorKind::Repeated, "stab", 2)
        );
        // The last key of the table (the bit set's far end) and the first.
        let last = KEYS[KEYS.len() - 1];
        let first = KEYS[0];
        // A value in the last key's domain: its upper bound, or its first word.
        let in_domain = match PARAMS[PARAMS.len() - 1].domain {
            Domain::Num { max, .. } => max.to_string(),
            Domain::Int { max, .. } => max.to_string(),
            Domain::Word(words) => words[0].to_string(),
        };
        let line = format!("elf {first}=lipm {last}={in_domain} {first}=dlipm");
        let e = parse(&line).unwrap_err();
        assert_eq!(
            (e.kind, e.key(), e.key_index),
            (ArgErrorKind::Repeated, first, 0)
        );
        // Different keys are not repeats; an unknown key twice is an unknown key.
        assert!(parse(&format!("elf {first}=lipm {last}={in_domain}")).is_ok());
        let e = parse("elf stepz=1 stepz=2").unwrap_err();
        assert_eq!(e.kind, ArgErrorKind::UnknownKey);
        // Every key once: accepted.
        let every: Vec<String> = PARAMS
            .iter()
            .filter_map(|p| {
                let v = p.value(&Config::default())?;
                let mut t = format!("{}=", p.key);
                p.write_value(v, &mut t).ok()?;
                Some(t)
            })
            .collect();
        assert!(every.len() > 40);
        assert_eq!(parse(&every.join(" ")).map(|_| ()), Ok(()));
        let twice = format!("{} {}", every.join(" "), every[every.len() - 1]);
        assert_eq!(parse(&twice).unwrap_err().kind, ArgErrorKind::Repeated);
    }

    #[test]
    fn bad_tokens_name_the_key() {
        let e = parse("elf lockstep model=lipm dt=0.5").unwrap_err();
        assert_eq!(e.kind, ArgErrorKind::OutOfRange);
        assert_eq!(e.key(), "dt");
        assert_eq!(e.key_index, 1);
        assert_eq!(e.position, 3);
        let e = parse("elf stepz=3").unwrap_err();
        assert_eq!(
            (e.kind, e.key(), e.key_index),
            (ArgErrorKind::UnknownKey, "stepz", 0xFF)
        );
        let e = parse("elf model=lipmm").unwrap_err();
        assert_eq!((e.kind, e.key()), (ArgErrorKind::BadValue, "model"));
        let e = parse("elf t1=nan").unwrap_err();
        assert_eq!((e.kind, e.key()), (ArgErrorKind::BadValue, "t1"));
        let e = parse("elf steps=0").unwrap_err();
        assert_eq!(e.kind, ArgErrorKind::OutOfRange);
        let e = parse("elf steps=1000").unwrap_err();
        assert_eq!(e.kind, ArgErrorKind::OutOfRange);
        let e = parse("elf lockstep oops").unwrap_err();
        assert_eq!(
            (e.kind, e.key(), e.position),
            (ArgErrorKind::StrayWord, "oops", 2)
        );
        let e = parse("a_very_long_key_name_that_goes_on=1").unwrap_err();
        assert_eq!(e.key(), "a_very_long_key_name_tha");
        let e = parse("elf =1").unwrap_err();
        assert_eq!((e.kind, e.key()), (ArgErrorKind::UnknownKey, ""));
        let e = parse("elf stab_max=0.03").unwrap_err();
        assert_eq!((e.kind, e.key()), (ArgErrorKind::OutOfRange, "stab_max"));
        let e = parse("elf stab_rate=0").unwrap_err();
        assert_eq!(e.kind, ArgErrorKind::OutOfRange);
        let e = parse("elf comp=full").unwrap_err();
        assert_eq!((e.kind, e.key()), (ArgErrorKind::BadValue, "comp"));
        let d = Config::default();
        assert_eq!(
            d.compensation,
            Compensation::None,
            "the paper's methods by default"
        );
        assert!(!d.stabilizer_on);
        assert_eq!(d.feasibility, Feasibility::Stretch);
        let e = parse("elf tilt_limit=0").unwrap_err();
        assert_eq!(e.kind, ArgErrorKind::OutOfRange);
        assert!(parse("model=dlipm").is_ok(), "first token may be a pair");
        let bad = [b'e', b' ', b'm', b'o', b'd', b'e', b'l', b'=', 0xFF];
        let mut c = Config::default();
        assert_eq!(
            apply(&mut c, &bad).unwrap_err().kind,
            ArgErrorKind::BadValue
        );
    }
}
