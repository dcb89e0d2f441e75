//! Run-time parameters: `key=value` tokens that override [`Config`] (the QEMU firmware reads
//! them from its semihosting command line, qemu `-append`; a host tool turns a plan TOML into
//! this line). Parsed without allocation; the first bad token is reported with its key.
//!
//! Tokens are separated by spaces, tabs or NULs. The first token is skipped when it is not a
//! `key=value` pair (qemu puts the kernel's file name first); the bare word `lockstep` is
//! accepted anywhere (the board reads it); any other bare word is an error.
//!
//! | key | value | sets |
//! | --- | --- | --- |
//! | `model` | `lipm` \| `dlipm` \| `tlipfm` | pendulum model |
//! | `dt` | s, 0.001 ..= 0.02 | tick period = gait sample time |
//! | `steps` | 1 ..= [`crate::control::MAX_STEPS`] | N |
//! | `step_length`, `step_width`, `d1`, `d2`, `a`, `z_c`, `w_y`, `h_z` | m | the forward walk (Table 2 names) |
//! | `t1`, `t2`, `period`, `lead_in`, `lead_out` | s | step timing, standing before/after |
//! | `s_first` | −1 \| 1 | first swing foot (−1 left) |
//! | `zmp` | `natural` \| `continuous` | ZMP shape |
//! | `b` | m | continuous ZMP half travel (also selects `zmp=continuous`) |
//! | `swing` | `cycloid` \| `sinusoid` | swing-foot profile |
//! | `ramp` | s, 0 ..= 60 | smooth move to the initial pose |
//! | `hold` | s, 0 ..= 60 | final hold before torque off |
//! | `min_load` | N, ≥ 0 | minimum foot load for the measured ZMP |
//! | `feet` | `required` \| `optional` | a foot board missing at start-up stops / is tolerated |
//! | `reply_timeout_us` | 50 ..= 100000 | master reply timeout |
//! | `read_poll_us` | 1 ..= 1000 | one byte wait |
//! | `attempts` | 1 ..= 10 | start-up transaction attempts |
//! | `baud` | 9600 ..= 4500000 | bus baud rate |
//! | `return_delay_us` | 0 ..= 508 | modelled Return Delay Time (QEMU) |
//! | `compute_us` | 0 ..= 1000000 | modelled compute time per tick (QEMU) |
//! | `watchdog_ms` | 1 ..= 10000 | watchdog timeout |
//! | `hold_ticks`, `stopping_ticks`, `overrun_burst` | u16 | supervisor limits |
//! | `tilt_limit` | rad, 0 < x ≤ π | fall threshold |
//! | `imu_cutoff` | Hz, > 0 | φ̈ low-pass cutoff |
//! | `comp` | `none` \| `wholebody` | pelvis placement: the paper's pipeline / whole-body compensation |
//! | `stab` | `off` \| `on` | ZMP/DCM feedback stabilizer (gait-core `stabilizer`) |
//! | `stab_kp` | 0 ..= 10 | proportional gain k_p on the DCM error estimate |
//! | `stab_ki` | 1/s, 0 ..= 100 | integral gain k_i |
//! | `stab_leak` | 1/s, 0 ..= 100 | leak λ of the integral |
//! | `stab_kg` | s, 0 ..= 1 | gyro gain k_g |
//! | `stab_k` | 0 ..= 100 | DCM gain k of p − p_ref = (1 + k)(ξ − ξ_ref) |
//! | `stab_max` | m, 0 ..= 0.02 | saturation of the CoM shift |
//! | `stab_rate` | m/s, 0 < x ≤ 1 | rate limit of the CoM shift |
//! | `stab_margin` | m, 0 ..= 0.05 | ZMP command margin inside the support polygon |
//! | `stab_cutoff` | Hz, 0 < x ≤ 1000 | ZMP error low-pass cutoff |
//! | `feasibility` | `stretch` \| `lower` \| `off` | servo-speed check at start-up: stretch the step timing, lower the swing, or only warn |
//! | `fault_nan` | walk tick | inject a NaN joint target (test) |
//! | `stop_at` | walk tick | request a stop (test) |
//!
//! Values are range-checked here; the walk as a whole is checked by gait-core when the plan
//! is built (a rejected plan is a configuration error too, see [`crate::control`]).

use crate::control::{Compensation, Feasibility};
use crate::Config;
use gait_core::ModelKind;

/// Every key, in the order of their index in [`ArgError::key_index`] and the log's
/// `ConfigRejected` fault record.
pub const KEYS: [&str; 48] = [
    "model",
    "dt",
    "steps",
    "step_length",
    "step_width",
    "s_first",
    "d1",
    "d2",
    "a",
    "b",
    "zmp",
    "z_c",
    "w_y",
    "h_z",
    "swing",
    "t1",
    "t2",
    "period",
    "lead_in",
    "lead_out",
    "ramp",
    "hold",
    "min_load",
    "feet",
    "reply_timeout_us",
    "read_poll_us",
    "attempts",
    "baud",
    "return_delay_us",
    "compute_us",
    "watchdog_ms",
    "hold_ticks",
    "stopping_ticks",
    "overrun_burst",
    "tilt_limit",
    "imu_cutoff",
    "comp",
    "stab",
    "stab_kp",
    "stab_ki",
    "stab_leak",
    "stab_kg",
    "stab_k",
    "stab_max",
    "stab_rate",
    "stab_margin",
    "stab_cutoff",
    "feasibility",
];

/// Extra keys beyond [`KEYS`] (fault injection), indices continue after it.
pub const FAULT_KEYS: [&str; 2] = ["fault_nan", "stop_at"];

/// Key index meaning "not a known key".
pub const UNKNOWN_KEY: u8 = 0xFF;

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
}

/// Longest key kept in an [`ArgError`], bytes.
const KEY_MAX: usize = 24;

/// The first bad token.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ArgError {
    /// What was wrong.
    pub kind: ArgErrorKind,
    /// Index of the key in [`KEYS`] then [`FAULT_KEYS`], or [`UNKNOWN_KEY`].
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

fn key_index(key: &str) -> u8 {
    KEYS.iter()
        .chain(FAULT_KEYS.iter())
        .position(|k| *k == key)
        .map_or(UNKNOWN_KEY, |i| i as u8)
}

fn num(v: &str) -> Result<f64, ArgErrorKind> {
    let x: f64 = v.parse().map_err(|_| ArgErrorKind::BadValue)?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(ArgErrorKind::BadValue)
    }
}

fn num_in(v: &str, lo: f64, hi: f64) -> Result<f64, ArgErrorKind> {
    let x = num(v)?;
    if (lo..=hi).contains(&x) {
        Ok(x)
    } else {
        Err(ArgErrorKind::OutOfRange)
    }
}

fn int_in(v: &str, lo: u32, hi: u32) -> Result<u32, ArgErrorKind> {
    let x: u32 = v.parse().map_err(|_| ArgErrorKind::BadValue)?;
    if (lo..=hi).contains(&x) {
        Ok(x)
    } else {
        Err(ArgErrorKind::OutOfRange)
    }
}

fn u16_in(v: &str, lo: u16) -> Result<u16, ArgErrorKind> {
    let x: u16 = v.parse().map_err(|_| ArgErrorKind::BadValue)?;
    if x >= lo {
        Ok(x)
    } else {
        Err(ArgErrorKind::OutOfRange)
    }
}

/// `x` when it is > 0.
fn positive(x: f64) -> Result<f64, ArgErrorKind> {
    if x > 0.0 {
        Ok(x)
    } else {
        Err(ArgErrorKind::OutOfRange)
    }
}

/// Seconds → µs (value already range-checked to ≤ 60 s).
fn secs_us(s: f64) -> u32 {
    libm::round(s * 1e6) as u32
}

/// Applies one `key=value` pair.
fn apply_one(cfg: &mut Config, key: &str, v: &str) -> Result<(), ArgErrorKind> {
    let w = &mut cfg.walk;
    match key {
        "model" => {
            cfg.model = match v {
                "lipm" => ModelKind::Lipm,
                "dlipm" => ModelKind::Dlipm,
                "tlipfm" => ModelKind::Tlipfm,
                _ => return Err(ArgErrorKind::BadValue),
            }
        }
        "dt" => cfg.tick_period_us = secs_us(num_in(v, 0.001, 0.02)?),
        "steps" => w.steps = int_in(v, 1, crate::control::MAX_STEPS as u32)? as usize,
        "step_length" => w.step_length = num(v)?,
        "step_width" => w.step_width = num(v)?,
        "s_first" => {
            w.s_first = match v {
                "-1" => -1,
                "1" | "+1" => 1,
                _ => return Err(ArgErrorKind::BadValue),
            }
        }
        "d1" => w.d1 = num(v)?,
        "d2" => w.d2 = num(v)?,
        "a" => w.a = num(v)?,
        "b" => {
            cfg.zmp_b = Some(num(v)?);
            cfg.zmp_continuous = true;
        }
        "zmp" => {
            cfg.zmp_continuous = match v {
                "natural" => false,
                "continuous" => true,
                _ => return Err(ArgErrorKind::BadValue),
            }
        }
        "z_c" => w.z_c = num(v)?,
        "w_y" => w.w_y = num(v)?,
        "h_z" => w.h_z = num(v)?,
        "swing" => {
            cfg.swing_sinusoid = match v {
                "cycloid" => false,
                "sinusoid" => true,
                _ => return Err(ArgErrorKind::BadValue),
            }
        }
        "t1" => w.t1 = num(v)?,
        "t2" => w.t2 = num(v)?,
        "period" => w.period = num(v)?,
        "lead_in" => w.lead_in = num(v)?,
        "lead_out" => w.lead_out = num(v)?,
        "ramp" => cfg.ramp_us = secs_us(num_in(v, 0.0, 60.0)?),
        "hold" => cfg.final_hold_us = secs_us(num_in(v, 0.0, 60.0)?),
        "min_load" => cfg.min_load_n = num_in(v, 0.0, 1.0e4)? as f32,
        "feet" => {
            cfg.feet_required = match v {
                "required" => true,
                "optional" => false,
                _ => return Err(ArgErrorKind::BadValue),
            }
        }
        "reply_timeout_us" => cfg.reply_timeout_us = int_in(v, 50, 100_000)?,
        "read_poll_us" => cfg.read_poll_us = int_in(v, 1, 1000)?,
        "attempts" => cfg.startup_attempts = int_in(v, 1, 10)? as u8,
        "baud" => cfg.bus_baud = int_in(v, 9600, 4_500_000)?,
        "return_delay_us" => cfg.return_delay_us = int_in(v, 0, 508)?,
        "compute_us" => cfg.compute_us = int_in(v, 0, 1_000_000)?,
        "watchdog_ms" => cfg.watchdog_ms = int_in(v, 1, 10_000)?,
        "hold_ticks" => cfg.supervisor.hold_ticks = u16_in(v, 0)?,
        "stopping_ticks" => cfg.supervisor.stopping_ticks = u16_in(v, 0)?,
        "overrun_burst" => cfg.supervisor.overrun_burst = u16_in(v, 1)?,
        "tilt_limit" => {
            let x = num_in(v, 0.0, core::f64::consts::PI)?;
            if x <= 0.0 {
                return Err(ArgErrorKind::OutOfRange);
            }
            cfg.supervisor.tilt_limit_rad = x as f32;
        }
        "imu_cutoff" => {
            let x = num_in(v, 0.0, 1.0e4)?;
            if x <= 0.0 {
                return Err(ArgErrorKind::OutOfRange);
            }
            cfg.imu_cutoff_hz = x as f32;
        }
        "comp" => {
            cfg.compensation = match v {
                "none" => Compensation::None,
                "wholebody" => Compensation::WholeBody,
                _ => return Err(ArgErrorKind::BadValue),
            }
        }
        "stab" => {
            cfg.stabilizer_on = match v {
                "off" => false,
                "on" => true,
                _ => return Err(ArgErrorKind::BadValue),
            }
        }
        "stab_kp" => cfg.stabilizer.kp = num_in(v, 0.0, 10.0)?,
        "stab_ki" => cfg.stabilizer.ki = num_in(v, 0.0, 100.0)?,
        "stab_leak" => cfg.stabilizer.leak = num_in(v, 0.0, 100.0)?,
        "stab_kg" => cfg.stabilizer.kg = num_in(v, 0.0, 1.0)?,
        "stab_k" => cfg.stabilizer.dcm_k = num_in(v, 0.0, 100.0)?,
        "stab_max" => {
            cfg.stabilizer.max_shift = num_in(v, 0.0, gait_core::stabilizer::MAX_SHIFT_CEILING_M)?
        }
        "stab_rate" => cfg.stabilizer.max_rate = positive(num_in(v, 0.0, 1.0)?)?,
        "stab_margin" => cfg.stabilizer.margin = num_in(v, 0.0, 0.05)?,
        "stab_cutoff" => cfg.stabilizer.cutoff_hz = positive(num_in(v, 0.0, 1000.0)?)?,
        "feasibility" => {
            cfg.feasibility = match v {
                "stretch" => Feasibility::Stretch,
                "lower" => Feasibility::Lower,
                "off" => Feasibility::Off,
                _ => return Err(ArgErrorKind::BadValue),
            }
        }
        "fault_nan" => cfg.fault_nan_tick = Some(int_in(v, 0, u32::MAX)?),
        "stop_at" => cfg.stop_at_tick = Some(int_in(v, 0, u32::MAX)?),
        _ => return Err(ArgErrorKind::UnknownKey),
    }
    Ok(())
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
        position: position.min(255) as u8,
        key: k,
        key_len: n as u8,
    }
}

/// Applies every `key=value` token of `cmdline` to `cfg` (see the module docs); stops at the
/// first bad token. `cfg` may be partly updated when an error is returned.
pub fn apply(cfg: &mut Config, cmdline: &[u8]) -> Result<(), ArgError> {
    let tokens = cmdline
        .split(|&b| b == b' ' || b == b'\t' || b == 0 || b == b'\n' || b == b'\r')
        .filter(|t| !t.is_empty());
    for (pos, tok) in tokens.enumerate() {
        let Some(eq) = tok.iter().position(|&b| b == b'=') else {
            if tok == b"lockstep" || pos == 0 {
                continue; // the board's word, or the program name
            }
            return Err(error(ArgErrorKind::StrayWord, tok, pos));
        };
        let (key, rest) = tok.split_at(eq);
        let val = rest.get(1..).unwrap_or(&[]);
        let (Ok(k), Ok(v)) = (core::str::from_utf8(key), core::str::from_utf8(val)) else {
            return Err(error(ArgErrorKind::BadValue, key, pos));
        };
        apply_one(cfg, k, v).map_err(|kind| error(kind, key, pos))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
    }

    #[test]
    fn every_key_parses() {
        let c = parse(
            "/x/qemu lockstep model=lipm dt=0.002 steps=4 step_length=0.03 step_width=0.05 \
             s_first=1 d1=0.011 d2=0.012 a=0.003 zmp=natural z_c=0.2 w_y=0.001 h_z=0.025 \
             swing=sinusoid t1=0.1 t2=0.5 period=0.7 lead_in=1.0 lead_out=1.2 ramp=0.5 \
             hold=2 min_load=3.5 feet=optional reply_timeout_us=800 read_poll_us=10 \
             attempts=2 baud=3000000 return_delay_us=4 compute_us=300 watchdog_ms=40 \
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
            (c.bus_baud, c.return_delay_us, c.compute_us),
            (3_000_000, 4, 300)
        );
        assert_eq!(c.watchdog_ms, 40);
        assert_eq!(c.supervisor.hold_ticks, 7);
        assert_eq!(c.supervisor.stopping_ticks, 50);
        assert_eq!(c.supervisor.overrun_burst, 3);
        assert_eq!(c.supervisor.tilt_limit_rad, 0.5);
        assert_eq!(c.imu_cutoff_hz, 10.0);
        assert_eq!((c.fault_nan_tick, c.stop_at_tick), (Some(12), Some(99)));
    }

    #[test]
    fn every_key_is_handled() {
        for (i, k) in KEYS.iter().chain(FAULT_KEYS.iter()).enumerate() {
            let mut c = Config::default();
            // A value no key accepts: the error must be about the value, not the key.
            let e = apply_one(&mut c, k, "%");
            assert!(matches!(e, Err(ArgErrorKind::BadValue)), "{k}: {e:?}");
            assert_eq!(key_index(k), i as u8);
        }
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
