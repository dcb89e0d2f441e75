//! ZMP-response report: decode a captured firmware log (with the firmware's own
//! [`walker_contract::record::RecordDecoder`]), write it as CSV, plot reference vs response with the
//! support-polygon bounds (seed 000 Figs. 14-16), and compute the Table 3 error statistics.
//!
//! Record counts: *good* = frames the decoder accepted (tick and event records), *bad* = frames
//! it rejected (COBS, CRC, type, length or field errors, overlong garbage; a capture that
//! starts mid-frame rejects its first partial frame) plus one for bytes left after the last
//! delimiter (a frame truncated by the end of the capture). Bad frames are counted, not fatal;
//! but a log with nothing decodable, or without a tick record in a walking phase, is refused
//! ([`check_walking`]): `walker report` exits 1 with the reason and writes nothing.
//!
//! Time: `t` is the firmware's tick clock in seconds (32-bit µs, unwrapped). The plan's time
//! is aligned on the walk start: the first tick whose phase leaves `standing` is the end of the
//! plan's lead-in; a log without that transition is taken to run on the plan's clock.
//!
//! Statistics (seed 000 Table 3), per axis over the ticks with a valid measured ZMP,
//! `e = measured − reference`: Σ|e|, mean |e|, RMS e, max |e| (gait-core's `ZmpErrorStats`).

use crate::planfile::{WalkSpec, PLAN_CAPACITY};
use crate::plot::{Dash, Figure, Panel, Series};
use gait_core::measure::support::SupportPolygon;
use gait_core::measure::zmp::{AxisErrorStats, ZmpErrorStats};
use gait_core::robot::{JOINT_NAMES, LEG_JOINTS};
use gait_core::{Robot, SupportPhase as PlanPhase};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};
use walker_contract::record::{
    BoardId, FaultState, LoggedPhase, Record, RecordDecoder, RecordDecoderStats, RecordError,
    StartupRecord, TickRecord, POS_NA, TAU_NA,
};

/// Rejections by cause.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RejectCounts {
    /// Malformed COBS.
    pub cobs: u64,
    /// CRC mismatch.
    pub crc: u64,
    /// Unknown record type.
    pub unknown_type: u64,
    /// Wrong length for the type.
    pub length: u64,
    /// Impossible field value.
    pub field: u64,
    /// Longer than any frame (garbage).
    pub overlong: u64,
}

impl RejectCounts {
    fn add(&mut self, e: RecordError) {
        match e {
            RecordError::Cobs => self.cobs += 1,
            RecordError::Crc => self.crc += 1,
            RecordError::UnknownType(_) => self.unknown_type += 1,
            RecordError::Length => self.length += 1,
            RecordError::Field => self.field += 1,
            RecordError::Overlong => self.overlong += 1,
        }
    }
}

/// A decoded log.
#[derive(Clone, Debug, Default)]
pub struct DecodedLog {
    /// Tick records in stream order.
    pub ticks: Vec<TickRecord>,
    /// Event records (start-up, stop, fault) in stream order.
    pub events: Vec<Record>,
    /// The decoder's counters.
    pub decoder: RecordDecoderStats,
    /// Rejections by cause.
    pub rejects: RejectCounts,
    /// Bytes after the last delimiter (an unterminated frame at the end).
    pub trailing_bytes: usize,
    /// Bytes fed.
    pub bytes: usize,
}

impl DecodedLog {
    /// Records decoded (ticks and events).
    pub fn good(&self) -> u64 {
        u64::from(self.decoder.frames)
    }
    /// Records rejected, plus one for an unterminated frame at the end.
    pub fn bad(&self) -> u64 {
        u64::from(self.decoder.rejected) + u64::from(self.trailing_bytes > 0)
    }
}

/// A streaming log decoder that keeps everything (for captures and files).
#[derive(Clone, Debug, Default)]
pub struct LogCollector {
    dec: RecordDecoder,
    log: DecodedLog,
}

impl LogCollector {
    /// A fresh collector.
    pub fn new() -> Self {
        Self::default()
    }
    /// Feeds bytes; returns how many tick records were added.
    pub fn feed(&mut self, bytes: &[u8]) -> usize {
        let before = self.log.ticks.len();
        let log = &mut self.log;
        self.dec.feed(bytes, |r| match r {
            Ok(Record::Tick(t)) => log.ticks.push(t),
            Ok(other) => log.events.push(other),
            Err(e) => log.rejects.add(e),
        });
        log.bytes += bytes.len();
        match bytes.iter().rposition(|&b| b == 0) {
            Some(i) => log.trailing_bytes = bytes.len() - i - 1,
            None => log.trailing_bytes += bytes.len(),
        }
        self.log.ticks.len() - before
    }
    /// The log so far.
    pub fn log(&self) -> &DecodedLog {
        &self.log
    }
    /// Ends the stream.
    pub fn finish(mut self) -> DecodedLog {
        self.log.decoder = self.dec.stats();
        self.log
    }
}

/// Decodes a whole byte stream.
pub fn decode_bytes(bytes: &[u8]) -> DecodedLog {
    let mut c = LogCollector::new();
    c.feed(bytes);
    c.finish()
}

/// Reads and decodes a log file.
pub fn decode_file(path: &Path) -> Result<DecodedLog, String> {
    let bytes =
        std::fs::read(path).map_err(|e| format!("cannot read the log {}: {e}", path.display()))?;
    Ok(decode_bytes(&bytes))
}

/// Metres from a 10 µm count (NaN when not available).
pub fn pos_m(v: i32) -> f64 {
    if v == POS_NA {
        f64::NAN
    } else {
        f64::from(v) * 1e-5
    }
}

/// N·m from mN·m (NaN when not available).
pub fn tau_nm(v: i16) -> f64 {
    if v == TAU_NA {
        f64::NAN
    } else {
        f64::from(v) * 1e-3
    }
}

/// Lower-case phase name.
pub fn phase_name(p: LoggedPhase) -> &'static str {
    match p {
        LoggedPhase::Double => "double",
        LoggedPhase::SingleLeft => "single_left",
        LoggedPhase::SingleRight => "single_right",
        LoggedPhase::Standing => "standing",
        LoggedPhase::Stopped => "stopped",
    }
}

fn fault_name(f: FaultState) -> &'static str {
    match f {
        FaultState::Ok => "ok",
        FaultState::Holding => "holding",
        FaultState::Stopping => "stopping",
        FaultState::TorqueOff => "torque_off",
    }
}

/// One tick in SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickRow {
    /// Firmware clock, s (unwrapped).
    pub t: f64,
    /// The record.
    pub rec: TickRecord,
    /// ZMP reference, m (NaN = not available).
    pub zmp_ref: [f64; 2],
    /// Measured ZMP, m (NaN = not available).
    pub zmp_meas: [f64; 2],
    /// CoM, m.
    pub com: [f64; 2],
    /// τ, N·m.
    pub tau: f64,
}

impl TickRow {
    /// The measured ZMP when valid.
    pub fn measured(&self) -> Option<[f64; 2]> {
        (self.rec.zmp_valid && self.zmp_meas.iter().all(|v| v.is_finite())).then_some(self.zmp_meas)
    }
}

/// Converts the tick records, unwrapping the 32-bit µs clock.
pub fn tick_rows(ticks: &[TickRecord]) -> Vec<TickRow> {
    let mut out = Vec::with_capacity(ticks.len());
    let mut prev: Option<(u32, i64)> = None;
    for r in ticks {
        let us = match prev {
            None => i64::from(r.time_us),
            Some((p, acc)) => acc + i64::from(r.time_us.wrapping_sub(p) as i32),
        };
        prev = Some((r.time_us, us));
        out.push(TickRow {
            t: us as f64 * 1e-6,
            rec: *r,
            zmp_ref: [pos_m(r.zmp_ref[0]), pos_m(r.zmp_ref[1])],
            zmp_meas: [pos_m(r.zmp_meas[0]), pos_m(r.zmp_meas[1])],
            com: [pos_m(r.com[0]), pos_m(r.com[1])],
            tau: tau_nm(r.tau_mnm),
        });
    }
    out
}

/// Header of `zmp_response.csv` (and of `walker capture`'s `<out>.csv`): units as name
/// suffixes; `zmp_valid`, `overrun` (0/1), `phase`, `fault` (names) and the counters have none.
pub const RESPONSE_HEADER: &str = "t_s,seq,zmp_ref_x_m,zmp_ref_y_m,zmp_meas_x_m,zmp_meas_y_m,zmp_valid,com_x_m,com_y_m,tau_nm,phase,fault,overrun,bus_timeouts,bus_crc_errors,bus_status_errors,tick_overruns";

/// A number as a CSV field with `decimals` decimals; a value that is not available
/// (non-finite) is an empty field, never `NaN`.
pub fn csv_number(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{v:.decimals$}")
    } else {
        String::new()
    }
}

/// Writes the tick rows as CSV with the `csv` crate (not-available values are empty fields).
pub fn write_response_csv(rows: &[TickRow], w: impl Write) -> std::io::Result<()> {
    let mut out = csv::Writer::from_writer(w);
    out.write_record(RESPONSE_HEADER.split(','))?;
    for r in rows {
        let b = r.rec.bus;
        out.write_record([
            format!("{:.6}", r.t),
            r.rec.seq.to_string(),
            csv_number(r.zmp_ref[0], 5),
            csv_number(r.zmp_ref[1], 5),
            csv_number(r.zmp_meas[0], 5),
            csv_number(r.zmp_meas[1], 5),
            u8::from(r.rec.zmp_valid).to_string(),
            csv_number(r.com[0], 5),
            csv_number(r.com[1], 5),
            csv_number(r.tau, 3),
            phase_name(r.rec.phase).to_string(),
            fault_name(r.rec.fault).to_string(),
            u8::from(r.rec.overrun).to_string(),
            b.timeouts.to_string(),
            b.crc.to_string(),
            b.status.to_string(),
            r.rec.overruns.to_string(),
        ])?;
    }
    out.flush()
}

/// One event as text: (seq, time µs, kind, detail in words: names, values with units).
pub fn event_text(r: &Record) -> (u16, u32, &'static str, String) {
    match r {
        Record::Startup(s) => (s.seq, s.time_us, "startup", startup_words(s)),
        Record::Stop(s) => (s.seq, s.time_us, "stop", stop_words(&s.reason)),
        Record::Fault(f) => (f.seq, f.time_us, "fault", fault_words(f)),
        Record::Tick(t) => (t.seq, t.time_us, "tick", String::new()),
    }
}

fn board_name(b: BoardId) -> &'static str {
    match b {
        BoardId::Unknown => "unknown board",
        BoardId::QemuMps2 => "QEMU mps2",
        BoardId::OpenCr => "OpenCR 1.0",
        BoardId::OpenCm => "OpenCM 9.04",
    }
}

fn startup_words(s: &StartupRecord) -> String {
    let period = f64::from(s.tick_period_us) * 1e-3;
    let rate = if s.tick_period_us > 0 {
        format!(" ({:.0} Hz)", 1e6 / f64::from(s.tick_period_us))
    } else {
        String::new()
    };
    let bus = if !s.probed {
        format!("{} devices expected, bus not probed", s.device_count)
    } else if s.missing.is_empty() {
        format!("{} devices, all answered the probe", s.device_count)
    } else {
        let ids: Vec<String> = s.missing.iter().map(u8::to_string).collect();
        format!("{} devices, missing ids {}", s.device_count, ids.join(", "))
    };
    format!(
        "{}, firmware {}.{}.{}, control tick {period:.3} ms{rate}, servo bus {} baud, {bus}",
        board_name(s.board),
        s.fw[0],
        s.fw[1],
        s.fw[2],
        s.bus_baud
    )
}

/// A joint index 0..12 by name (`l_knee`), else the number.
fn joint_word(j: u8) -> String {
    JOINT_NAMES
        .get(usize::from(j))
        .map_or_else(|| format!("joint {j}"), |n| (*n).to_string())
}

fn stop_words(r: &walker_contract::StopReason) -> String {
    use walker_contract::StopReason as S;
    match *r {
        S::DeviceMissing { id } => format!("device {id} did not answer the start-up probe"),
        S::DeviceLost { id } => format!("device {id} lost (too many missed replies in a row)"),
        S::Fall { tilt_mrad } => format!(
            "fall: trunk tilted {:.1}° ({tilt_mrad} mrad), beyond the limit",
            (f64::from(tilt_mrad) * 1e-3).to_degrees()
        ),
        S::OverrunBurst { count } => format!("{count} tick overruns in a row"),
        S::NonFiniteTarget { joint } => {
            format!("non-finite joint target ({})", joint_word(joint))
        }
        S::PlanDone => "plan done".into(),
        S::Requested => "stop requested".into(),
        S::NonFiniteSample { tick } => format!("non-finite gait sample at walk tick {tick}"),
        S::SensorStale { id, age_ms } => {
            format!("sensor {id} gave no plausible reply for {age_ms} ms")
        }
        S::ServoFault { id, check, reading } => {
            use walker_contract::codes::ServoCheck as C;
            let what = match check {
                C::HardwareError => format!("hardware error status 0x{reading:02X}"),
                C::Temperature => format!("temperature {reading} °C"),
                C::VoltageLow => {
                    format!("input voltage {:.1} V, too low", f64::from(reading) * 0.1)
                }
                C::VoltageHigh => {
                    format!("input voltage {:.1} V, too high", f64::from(reading) * 0.1)
                }
                C::Current => format!("current {reading} mA"),
                C::TorqueOff => "torque found off (browned out); torque turned on again".into(),
            };
            format!("servo {id} fault: {what}")
        }
        S::NotPowerOn { cause } => format!(
            "reset other than power-on ({}): not walking without a command",
            reset_word(cause)
        ),
        S::ServoLost { id } => format!("servo {id} lost (no reply to the servo monitor)"),
    }
}

fn reset_word(c: walker_contract::codes::ResetCause) -> &'static str {
    use walker_contract::codes::ResetCause as R;
    match c {
        R::PowerOn => "power-on",
        R::BrownOut => "brown-out",
        R::Watchdog => "watchdog",
        R::Software => "software reset",
        R::Pin => "reset pin",
        R::LowPower => "low-power management",
        R::Unknown => "unknown cause",
    }
}

fn fault_words(f: &walker_contract::record::FaultRecord) -> String {
    use walker_contract::codes::{
        CommandField, CrashCode, ResetCause, SensorRejection, StartupStep,
    };
    use walker_contract::FaultKind as K;
    let (id, v) = (f.id, f.value);
    match f.kind {
        K::DeviceHolding => format!(
            "device holding: device {id} missed its reply, last good value held ({v} ticks)"
        ),
        K::DeviceRecovered => {
            format!("device recovered: device {id} answered again after {v} ticks held")
        }
        K::TargetClamped => format!(
            "target clamped to its joint limit: first {}, joint mask 0x{v:03X}",
            joint_word(id)
        ),
        K::ImuNonFinite => {
            format!("IMU non-finite: sample replaced by the last good one ({v} so far)")
        }
        K::ConfigRejected => {
            let key = match id {
                0xFF => "an unknown key".to_string(),
                0xFE => "the plan (gait-core refused it)".to_string(),
                0xFD => "the command line (longer than the firmware's buffer)".to_string(),
                i => walker_contract::params::KEYS
                    .get(usize::from(i))
                    .map_or_else(|| format!("key index {i}"), |k| format!("`{k}`")),
            };
            let value = match id {
                0xFE => format!("gait-core error code {v}"),
                0xFD => format!("buffer {v} bytes"),
                _ => format!("token {v}"),
            };
            format!("configuration rejected: {key} ({value})")
        }
        K::StartupFailed => format!(
            "start-up step failed: device {id}, step {}",
            StartupStep::try_from(u8::try_from(v).unwrap_or(0))
                .map_or_else(|_| format!("code {v}"), |s| format!("{s:?}"))
        ),
        K::TimingStretched => format!(
            "step timing stretched ×{:.3} (t1, t2, T) for the servo speed limit, worst joint {}",
            f64::from(v) * 1e-3,
            joint_word(id)
        ),
        K::SwingLowered => format!(
            "swing lowered to {:.1} mm for the servo speed limit, worst joint {}",
            f64::from(v) * 1e-3,
            joint_word(id)
        ),
        K::SpeedLimit => format!(
            "servo speed limit exceeded: {} needs {:.2} rad/s",
            joint_word(id),
            f64::from(v) * 1e-3
        ),
        K::SensorRejected => format!(
            "sensor reply rejected: device {id}, {}",
            SensorRejection::try_from(u8::try_from(v).unwrap_or(0))
                .map_or_else(|_| format!("code {v}"), |s| format!("{s:?}"))
        ),
        K::TorqueOffUnconfirmed => format!(
            "torque off not confirmed: {v} servos (first: servo {id}); servo power cut anyway"
        ),
        K::ResetCause => format!(
            "reset cause: {} (reset flags 0x{v:02X})",
            ResetCause::try_from(id).map_or("unknown", reset_word)
        ),
        K::CrashRecord => format!(
            "previous run ended by a {} at control tick {v}",
            match CrashCode::try_from(id) {
                Ok(CrashCode::Panic) => "panic".to_string(),
                Ok(CrashCode::Watchdog) => "watchdog reset".to_string(),
                Err(_) => format!("crash (code {id})"),
            }
        ),
        K::CommandReceived => match CommandField::try_from(id) {
            Ok(CommandField::Mode) => format!("command: mode {v}"),
            Ok(CommandField::VelocityX) => format!("command: forward velocity {v} mm/s"),
            Ok(CommandField::VelocityY) => format!("command: leftward velocity {v} mm/s"),
            Ok(CommandField::YawRate) => format!("command: yaw rate {v} mrad/s"),
            Err(_) => format!("command: field {id}, value {v}"),
        },
        K::Footstep => {
            if id == 0 {
                return format!(
                    "footstep: online walk step period {:.3} s",
                    f64::from(v) * 1e-6
                );
            }
            let side = match id >> 4 {
                1 => "left",
                2 => "right",
                _ => "?",
            };
            match id & 0xF {
                0 => format!("footstep: {side} x {:.4} m", f64::from(v) * 1e-6),
                1 => format!("footstep: {side} y {:.4} m", f64::from(v) * 1e-6),
                2 => format!("footstep: {side} yaw {:.4} rad", f64::from(v) * 1e-6),
                3 => format!(
                    "footstep: heading hold correction {:.4} rad",
                    f64::from(v) * 1e-6
                ),
                4 => format!("footstep: explicit step travel x {v} mm"),
                5 => format!("footstep: explicit step travel y {v} mm"),
                6 => format!("footstep: explicit step turn {v} mrad"),
                c => format!("footstep: component {c}, value {v}"),
            }
        }
        K::CatchStep => {
            let side = match id >> 4 {
                1 => "left",
                2 => "right",
                _ => "?",
            };
            let mm = f64::from(v) * 1e-3;
            match id & 0xF {
                0 => format!("catching step moved the {side} foot's landing forward by up to {mm:.1} mm"),
                1 => format!("catching step moved the {side} foot's landing leftward by up to {mm:.1} mm"),
                2 => format!("landing hold moved the {side} foot's landing along the stance heading by {mm:.1} mm"),
                c => format!("catching step: the {side} foot, component {c}, {mm:.1} mm"),
            }
        }
        K::Deadman => format!(
            "command deadman: no valid command write for {v} ms in Mode = walk; the walk stops to standing"
        ),
        K::ParamStore => match id {
            0 => format!(
                "saved parameters loaded: slot {}, save number {}",
                v >> 24,
                v & 0x00FF_FFFF
            ),
            1 => "saved parameters: none saved, the defaults".into(),
            2 => "saved parameters: CORRUPT (no copy decodes), the defaults".into(),
            3 => "saved parameters: refused by the parser, the defaults".into(),
            4 => "saved parameters: no store on this board, the defaults".into(),
            c => format!("saved parameters: outcome {c}"),
        },
        K::ParamValue => {
            let x = f32::from_bits(v as u32);
            match walker_contract::params::PARAMS.get(usize::from(id)) {
                Some(p) => {
                    let mut text = String::new();
                    let value = match p.domain {
                        walker_contract::params::Domain::Word(_) => {
                            walker_contract::params::Value::Word(x as usize)
                        }
                        _ => walker_contract::params::Value::Num32(x),
                    };
                    let _ = p.write_value(value, &mut text);
                    format!("parameter {}={text}", p.key)
                }
                None => format!("parameter index {id} = {x}"),
            }
        }
        K::ServoProblem => {
            let code = u8::try_from((v >> 24) & 0xFF).unwrap_or(0);
            match walker_contract::StopReason::from_code(code, id, v & 0x00FF_FFFF) {
                Some(r) => format!("servo monitor: {}", stop_words(&r)),
                None => format!("servo monitor: servo {id}, stop code {code}"),
            }
        }
        K::ServoSurvey => match id {
            0 if v == 0 => "servo survey: too little load standing to measure the servos' stiffness".into(),
            0 => format!(
                "servo survey: leg servos' stiffness {:.2} N·m/rad",
                f64::from(v) * 1e-3
            ),
            1 => format!(
                "servo survey: deflection feedback gain {:.2} 1/s",
                f64::from(v) * 1e-3
            ),
            2 => format!(
                "servo survey: supply at the survey {:.2} V",
                f64::from(v) * 1e-3
            ),
            c => format!("servo survey: component {c}, value {v}"),
        },
        K::SensorsAbsent => {
            let has = |bit: u8| id & (1 << bit) != 0;
            let mut out = String::from("sensors:");
            if !(has(0) && has(1)) {
                out.push_str(" no foot sensors (no measured ZMP, no feedback from the loads: the ZMP stabilizer and the fdc idle; the odometry's landing surveys, and with them the landing hold, timed by the plan's load split);");
            }
            if !has(2) {
                out.push_str(" no IMU (no gyro feedback);");
            }
            out.pop();
            out
        }
        K::Other(c) => format!("fault kind {c} (unknown to this reader): id {id}, value {v}"),
    }
}

/// Writes the event records as CSV (the `csv` crate: the detail is quoted as CSV quotes).
pub fn write_events_csv(events: &[Record], w: impl Write) -> std::io::Result<()> {
    let mut out = csv::Writer::from_writer(w);
    out.write_record(["seq", "time_us", "kind", "detail"])?;
    for e in events {
        let (seq, t, kind, detail) = event_text(e);
        out.write_record([seq.to_string(), t.to_string(), kind.to_string(), detail])?;
    }
    out.flush()
}

/// Table 3 statistics of one run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorSummary {
    /// Tick records looked at.
    pub ticks: u64,
    /// Of those, without a valid measured ZMP.
    pub skipped: u64,
    /// Of those, with a non-finite reference.
    pub invalid: u64,
    /// Sagittal (x) error.
    pub x: AxisErrorStats,
    /// Lateral (y) error.
    pub y: AxisErrorStats,
}

/// Error statistics of `measured − reference` over the rows.
pub fn error_stats(rows: &[TickRow]) -> ErrorSummary {
    let mut s = ZmpErrorStats::<f64>::new();
    for r in rows {
        s.push(r.zmp_ref, r.measured());
    }
    ErrorSummary::of(&s)
}

impl ErrorSummary {
    /// The summary of accumulated statistics.
    pub fn of(s: &ZmpErrorStats<f64>) -> Self {
        ErrorSummary {
            ticks: s.samples(),
            skipped: s.skipped(),
            invalid: s.invalid(),
            x: s.x(),
            y: s.y(),
        }
    }
}

/// Support-polygon bounds of the plan over time (plan clock).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SupportBounds {
    /// Plan time of each sample, s.
    pub t: Vec<f64>,
    /// Min and max x of the support polygon, m.
    pub x: Vec<[f64; 2]>,
    /// Min and max y of the support polygon, m.
    pub y: Vec<[f64; 2]>,
    /// End of the lead-in, s.
    pub walk_start: f64,
}

/// Runs the plan through gait-core and records the support polygon's bounds at every sample:
/// the support sole in single support, the hull of both soles otherwise.
pub fn support_bounds(spec: &WalkSpec, robot: &Robot, dt: f64) -> Result<SupportBounds, String> {
    let mut s = spec.sampler(robot, dt).map_err(|e| e.to_string())?;
    let mut out = SupportBounds {
        walk_start: s.walk_start_ns() as f64 * 1e-9,
        ..Default::default()
    };
    let limit = 1 + ((PLAN_CAPACITY as f64 * 4.0 + 8.0) / dt) as usize;
    while !s.is_done() && out.t.len() < limit {
        let g = s.next(0.0);
        let place = |i: usize| gait_core::Place {
            x: g.feet[i].x,
            y: g.feet[i].y,
            yaw: g.feet[i].yaw,
        };
        let poly = match g.phase {
            PlanPhase::Single(side) => SupportPolygon::single(&place(side.index()), robot),
            _ => SupportPolygon::double(&place(0), &place(1), robot),
        }
        .map_err(|e| format!("support polygon: {e}"))?;
        let (mut x, mut y) = (
            [f64::INFINITY, f64::NEG_INFINITY],
            [f64::INFINITY, f64::NEG_INFINITY],
        );
        for v in poly.vertices() {
            x = [x[0].min(v[0]), x[1].max(v[0])];
            y = [y[0].min(v[1]), y[1].max(v[1])];
        }
        out.t.push(g.time_ns as f64 * 1e-9);
        out.x.push(x);
        out.y.push(y);
    }
    Ok(out)
}

/// How the log's clock maps to the plan's: `plan_t = t + offset`.
#[derive(Clone, Debug, PartialEq)]
pub struct Alignment {
    /// Offset, s.
    pub offset: f64,
    /// How it was found.
    pub how: String,
}

/// Aligns the log on the plan's walk start (first tick leaving `standing`).
pub fn align(rows: &[TickRow], walk_start: f64) -> Alignment {
    for w in rows.windows(2) {
        if w[0].rec.phase == LoggedPhase::Standing && is_walking(w[1].rec.phase) {
            return Alignment {
                offset: walk_start - w[1].t,
                how: format!("walk start (first walking tick at t = {:.3} s = plan's end of lead-in {walk_start:.3} s)", w[1].t),
            };
        }
    }
    Alignment {
        offset: 0.0,
        how: "no standing → walking transition in the log: log clock = plan clock".into(),
    }
}

/// A ground-truth trace (the simulator's truth CSV, or any CSV with a time and a ZMP column),
/// on the log's clock.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TruthTable {
    /// Time, s.
    pub t: Vec<f64>,
    /// ZMP (x, y), m.
    pub zmp: Vec<[f64; 2]>,
    /// Every column by its header name, one value per row of `t` (an empty or non-numeric
    /// field is NaN; `support`/`stance` letters are NaN here).
    pub columns: BTreeMap<String, Vec<f64>>,
}

impl TruthTable {
    /// The ZMP at time `t` (nearest sample at or before `t`, none outside the trace).
    pub fn at(&self, t: f64) -> Option<[f64; 2]> {
        self.index_at(t).and_then(|i| self.zmp.get(i).copied())
    }

    /// The row at or before `t` (none outside the trace).
    pub fn index_at(&self, t: f64) -> Option<usize> {
        let first = *self.t.first()?;
        let last = *self.t.last()?;
        if t < first - 1e-9 || t > last + 1e-9 {
            return None;
        }
        Some(self.t.partition_point(|&v| v <= t + 1e-9).saturating_sub(1))
    }

    /// One column by name.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns.get(name).map(Vec::as_slice)
    }

    /// Whether every named column is present.
    pub fn has(&self, names: &[&str]) -> bool {
        names.iter().all(|n| self.columns.contains_key(*n))
    }
}

/// Reads a truth CSV (the one reader of truth files): a header with `t_s` (or `t`, `time`) and
/// `zmp_x_m`/`zmp_y_m` (or `zmp_x`, `zmp_true_x`, `true_zmp_x`, `zmp_truth_x`), s and m, on
/// the log's clock (the simulator's columns: [`crate::sim::truth`]); `#` lines are comments; every other column is kept by name. A row whose time is
/// empty is skipped; a malformed time or ZMP is an error naming the line and column.
pub fn read_truth(path: &Path) -> Result<TruthTable, String> {
    let mut rd = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .flexible(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| format!("cannot read the truth file {}: {e}", path.display()))?;
    let header: Vec<String> = rd
        .headers()
        .map_err(|e| format!("{}: {e}", path.display()))?
        .iter()
        .map(str::to_string)
        .collect();
    if header.iter().all(String::is_empty) {
        return Err(format!("{}: empty truth file", path.display()));
    }
    // The first column named one of `names` (the error names the first of them).
    let col = |names: &[&str]| {
        let first = names.first().copied().unwrap_or_default();
        header
            .iter()
            .position(|h| names.contains(&h.as_str()))
            .ok_or_else(|| format!("{}: no `{first}` column in {header:?}", path.display()))
    };
    // The true ZMP on `axis` under each name the truth files give it.
    let zmp_col = |axis: char| {
        let names = [
            format!("zmp_{axis}_m"),
            format!("zmp_{axis}"),
            format!("zmp_true_{axis}"),
            format!("true_zmp_{axis}"),
            format!("zmp_truth_{axis}"),
        ];
        col(&names.each_ref().map(String::as_str))
    };
    let ct = col(&["t_s", "t", "time"])?;
    let (cx, cy) = (zmp_col('x')?, zmp_col('y')?);
    let mut out = TruthTable::default();
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); header.len()];
    for (n, rec) in rd.records().enumerate() {
        let rec = rec.map_err(|e| format!("{}: {e}", path.display()))?;
        let strict = |i: usize| -> Result<f64, String> {
            let s = rec.get(i).unwrap_or("");
            if s.is_empty() {
                return Ok(f64::NAN);
            }
            s.parse::<f64>().map_err(|e| {
                format!(
                    "{}: data line {}: column {}: {e}",
                    path.display(),
                    n + 1,
                    header.get(i).map_or("?", String::as_str)
                )
            })
        };
        let t = strict(ct)?;
        if !t.is_finite() {
            continue;
        }
        out.t.push(t);
        out.zmp.push([strict(cx)?, strict(cy)?]);
        for (i, c) in cols.iter_mut().enumerate() {
            c.push(
                rec.get(i)
                    .and_then(|s| s.parse::<f64>().ok())
                    .unwrap_or(f64::NAN),
            );
        }
    }
    out.columns = header.into_iter().zip(cols).collect();
    Ok(out)
}

/// Options of a report.
#[derive(Clone, Debug)]
pub struct ReportOptions {
    /// The captured log.
    pub log: PathBuf,
    /// Output folder.
    pub out_dir: PathBuf,
    /// Optional ground-truth ZMP CSV.
    pub truth: Option<PathBuf>,
    /// The plan the firmware walked (for the support bounds).
    pub spec: WalkSpec,
    /// Name of the plan (for the report).
    pub plan_name: String,
}

/// What a report found.
#[derive(Clone, Debug)]
pub struct ReportSummary {
    /// The decoded log.
    pub log: DecodedLog,
    /// Tick rows.
    pub rows: Vec<TickRow>,
    /// Measured vs reference.
    pub stats: ErrorSummary,
    /// Measured vs truth, when a truth file was given.
    pub truth_stats: Option<ErrorSummary>,
    /// Clock alignment.
    pub alignment: Alignment,
    /// Files written.
    pub files: Vec<PathBuf>,
    /// The plan as the firmware walked it (the options' plan with the logged start-up
    /// adjustments): the plan drawn in the figures and the MCAP.
    pub spec: WalkSpec,
    /// What the reader warns of (a cut log, a partial truth file); also in report.md and
    /// stats.json.
    pub warnings: Vec<String>,
    /// The start-up's plan adjustments, in words.
    pub adjustments: Vec<String>,
}

/// A Table 3 style markdown table of one run.
pub fn stats_table(s: &ErrorSummary) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "| axis | samples | Σ\\|e\\| (m) | mean \\|e\\| (m) | RMS e (m) | max \\|e\\| (m) |"
    );
    let _ = writeln!(t, "| --- | ---: | ---: | ---: | ---: | ---: |");
    for (name, a) in [("x (sagittal)", &s.x), ("y (lateral)", &s.y)] {
        let _ = writeln!(
            t,
            "| {name} | {} | {:.6} | {:.6} | {:.6} | {:.6} |",
            a.count, a.sum_abs, a.mean_abs, a.rms, a.max_abs
        );
    }
    t
}

/// A finite number as JSON, else `null` (JSON has no NaN).
fn json_num(v: f64) -> serde_json::Value {
    serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, serde_json::Value::Number)
}

fn axis_json(a: &AxisErrorStats) -> serde_json::Value {
    serde_json::json!({
        "count": a.count,
        "sum_abs": json_num(a.sum_abs),
        "mean_abs": json_num(a.mean_abs),
        "rms": json_num(a.rms),
        "max_abs": json_num(a.max_abs),
    })
}

/// The statistics as a JSON object (metres; a statistic without samples is `null`).
pub fn stats_json(s: &ErrorSummary) -> serde_json::Value {
    serde_json::json!({
        "ticks": s.ticks,
        "skipped": s.skipped,
        "invalid": s.invalid,
        "x": axis_json(&s.x),
        "y": axis_json(&s.y),
    })
}

fn write_file(path: &Path, data: &[u8], files: &mut Vec<PathBuf>) -> Result<(), String> {
    std::fs::write(path, data).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    files.push(path.to_path_buf());
    Ok(())
}

/// Points (t, value) of one plotted line.
pub type Polyline = Vec<(f64, f64)>;

/// One axis of the support bounds (min, max) on the log's clock over `[t0, t1]`. Before the
/// plan (the firmware's move to the initial pose) and after it (the final hold) both feet stand
/// where the plan starts and ends, so the first and the last bounds extend to the log's ends.
pub fn bounds_on_log_clock(
    bounds: &SupportBounds,
    axis: usize,
    offset: f64,
    t0: f64,
    t1: f64,
) -> (Polyline, Polyline) {
    let (mut lo, mut hi) = (Vec::new(), Vec::new());
    let pick = |i: usize| if axis == 0 { bounds.x[i] } else { bounds.y[i] };
    let n = bounds.t.len();
    if n == 0 {
        return (lo, hi);
    }
    let first = bounds.t[0] - offset;
    if first > t0 + 1e-9 {
        let b = pick(0);
        lo.push((t0, b[0]));
        hi.push((t0, b[1]));
    }
    for (i, &tp) in bounds.t.iter().enumerate() {
        let t = tp - offset;
        if t < t0 - 1e-9 || t > t1 + 1e-9 {
            continue;
        }
        let b = pick(i);
        lo.push((t, b[0]));
        hi.push((t, b[1]));
    }
    let last = bounds.t[n - 1] - offset;
    if last < t1 - 1e-9 {
        let b = pick(n - 1);
        lo.push((t1.max(t0), b[0]));
        hi.push((t1.max(t0), b[1]));
    }
    (lo, hi)
}

/// The ZMP figure: reference (dash-dot), response (solid), support bounds (dashed), truth
/// (dotted) in the sagittal and the lateral plane over time.
pub fn zmp_figure(
    title: &str,
    rows: &[TickRow],
    bounds: &SupportBounds,
    offset: f64,
    truth: Option<&TruthTable>,
) -> Figure {
    let (t0, t1) = match (rows.first(), rows.last()) {
        (Some(a), Some(b)) => (a.t, b.t),
        _ => (0.0, 0.0),
    };
    let mut panels = Vec::new();
    for (axis, name) in [(0usize, "sagittal plane (x)"), (1, "lateral plane (y)")] {
        let mut series = Vec::new();
        let (lo, hi) = bounds_on_log_clock(bounds, axis, offset, t0, t1);
        let gray = [110, 110, 110];
        series.push(Series {
            label: "support polygon min/max".into(),
            color: gray,
            dash: Dash::Dashed,
            width: 1.0,
            points: lo,
        });
        series.push(Series {
            label: String::new(),
            color: gray,
            dash: Dash::Dashed,
            width: 1.0,
            points: hi,
        });
        series.push(Series {
            label: "ZMP response".into(),
            color: [200, 30, 30],
            dash: Dash::Solid,
            width: 1.2,
            points: rows
                .iter()
                .map(|r| (r.t, r.measured().map_or(f64::NAN, |m| m[axis])))
                .collect(),
        });
        series.push(Series {
            label: "ZMP reference".into(),
            color: [30, 80, 200],
            dash: Dash::DashDot,
            width: 1.5,
            points: rows.iter().map(|r| (r.t, r.zmp_ref[axis])).collect(),
        });
        if let Some(tr) = truth {
            series.push(Series {
                label: "ZMP truth".into(),
                color: [20, 150, 60],
                dash: Dash::Dotted,
                width: 1.2,
                points: tr
                    .t
                    .iter()
                    .zip(&tr.zmp)
                    .map(|(&t, z)| (t, z[axis]))
                    .collect(),
            });
        }
        panels.push(Panel {
            title: format!("ZMP, {name}"),
            x_label: "t (s)".into(),
            y_label: format!("ZMP {} (m)", if axis == 0 { "x" } else { "y" }),
            series,
        });
    }
    Figure {
        title: title.into(),
        width: 1100,
        panel_height: 360,
        columns: 1,
        panels,
    }
}

/// The plan's joint targets, rad, on the log's clock (`t = plan_t − offset`): the joint angles
/// of the plan's IK ([`crate::export::export_rows`]), by servo ID − 1. `None` when the plan
/// cannot be exported.
pub fn planned_joint_angles(
    spec: &WalkSpec,
    robot: &Robot,
    dt: f64,
    offset: f64,
) -> Option<(Vec<f64>, Vec<[f64; LEG_JOINTS]>)> {
    let (rows, _) = crate::export::export_rows(spec, robot, dt).ok()?;
    Some(rows.iter().map(|r| (r.t - offset, r.q)).unzip())
}

/// The plan's joint speeds, rad/s, on the log's clock: [`planned_joint_angles`] differentiated
/// centrally. `None` when the plan cannot be exported.
pub fn planned_joint_speeds(
    spec: &WalkSpec,
    robot: &Robot,
    dt: f64,
    offset: f64,
) -> Option<(Vec<f64>, Vec<[f64; LEG_JOINTS]>)> {
    let (t, q) = planned_joint_angles(spec, robot, dt, offset)?;
    if t.len() < 3 {
        return None;
    }
    let v = (0..t.len())
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(t.len() - 1));
            std::array::from_fn(|j| (q[b][j] - q[a][j]) / (t[b] - t[a]))
        })
        .collect();
    Some((t, v))
}

/// Per-joint panels (left leg left, right leg right, hip to ankle downwards) of the truth
/// columns `column(1)` … `column(12)` (by servo ID, e.g.
/// [`crate::sim::truth::joint_speed_column`]), with an optional planned line per joint.
/// `None` when the truth lacks the columns or they hold no finite value.
pub fn joint_figure(
    title: &str,
    truth: &TruthTable,
    column: fn(usize) -> String,
    unit: &str,
    planned: Option<&(Vec<f64>, Vec<[f64; LEG_JOINTS]>)>,
) -> Option<Figure> {
    let cols: Vec<&[f64]> = (1..=LEG_JOINTS)
        .map(|id| truth.column(&column(id)))
        .collect::<Option<_>>()?;
    if !cols.iter().any(|c| c.iter().any(|v| v.is_finite())) {
        return None;
    }
    let mut panels = Vec::new();
    for k in 0..LEG_JOINTS / 2 {
        for j in [k, k + LEG_JOINTS / 2] {
            let mut series = Vec::new();
            if let Some((pt, pv)) = planned {
                series.push(Series {
                    label: "plan (IK)".into(),
                    color: [30, 80, 200],
                    dash: Dash::DashDot,
                    width: 1.5,
                    points: pt.iter().zip(pv).map(|(&t, v)| (t, v[j])).collect(),
                });
            }
            series.push(Series {
                // One line alone needs no legend.
                label: if planned.is_some() { "simulated" } else { "" }.into(),
                color: [200, 30, 30],
                dash: Dash::Solid,
                width: 1.2,
                points: truth
                    .t
                    .iter()
                    .copied()
                    .zip(cols[j].iter().copied())
                    .collect(),
            });
            panels.push(Panel {
                title: format!("{} (ID {})", JOINT_NAMES[j].replace('_', " "), j + 1),
                x_label: "t (s)".into(),
                y_label: unit.into(),
                series,
            });
        }
    }
    Some(Figure {
        title: title.into(),
        width: 1100,
        panel_height: 230,
        columns: 2,
        panels,
    })
}

/// The foot-force figure: each sole's four load cells (`l_f0_n..l_f3_n`, `r_f0_n..r_f3_n`:
/// front-left, front-right, rear-left, rear-right) and its contact force `l_fz_n` / `r_fz_n`
/// when present.
/// `None` when the truth has no load-cell columns.
pub fn foot_force_figure(title: &str, truth: &TruthTable) -> Option<Figure> {
    let colors = [[30, 80, 200], [20, 150, 60], [220, 120, 0], [150, 40, 160]];
    let names = ["front-left", "front-right", "rear-left", "rear-right"];
    let mut panels = Vec::new();
    for (side, name) in [("l", "left sole"), ("r", "right sole")] {
        let mut series = Vec::new();
        for (k, (c, n)) in colors.iter().zip(names).enumerate() {
            let v = truth.column(&format!("{side}_f{k}_n"))?;
            series.push(Series {
                label: format!("load cell {k} ({n})"),
                color: *c,
                dash: Dash::Solid,
                width: 1.0,
                points: truth.t.iter().copied().zip(v.iter().copied()).collect(),
            });
        }
        if let Some(v) = truth.column(&format!("{side}_fz_n")) {
            series.push(Series {
                label: "contact force, vertical".into(),
                color: [0, 0, 0],
                dash: Dash::Dashed,
                width: 1.5,
                points: truth.t.iter().copied().zip(v.iter().copied()).collect(),
            });
        }
        panels.push(Panel {
            title: format!("{name}: vertical forces"),
            x_label: "t (s)".into(),
            y_label: "force (N)".into(),
            series,
        });
    }
    Some(Figure {
        title: title.into(),
        width: 1100,
        panel_height: 330,
        columns: 1,
        panels,
    })
}

fn write_figure(
    fig: &Figure,
    dir: &Path,
    stem: &str,
    files: &mut Vec<PathBuf>,
) -> Result<(), String> {
    write_file(
        &dir.join(format!("{stem}.svg")),
        fig.to_svg()?.as_bytes(),
        files,
    )?;
    write_file(&dir.join(format!("{stem}.png")), &fig.to_png()?, files)
}

/// True for the phases of a walk (double or single support).
pub fn is_walking(p: LoggedPhase) -> bool {
    matches!(
        p,
        LoggedPhase::Double | LoggedPhase::SingleLeft | LoggedPhase::SingleRight
    )
}

/// Checks a firmware log before any figure is drawn from it: refuses what is not a whole run
/// (an empty file; nothing decodable, e.g. random bytes; no start-up record, i.e. not from
/// the firmware's start; no tick record) with a one-line reason, and returns warnings for what
/// is readable but incomplete: no stop record (the log was cut: where it ends is said).
pub fn check_log(log: &DecodedLog, path: &Path) -> Result<Vec<String>, String> {
    let name = path.display();
    if log.bytes == 0 {
        return Err(format!(
            "the log {name} is empty (0 bytes): nothing to report"
        ));
    }
    if log.good() == 0 {
        return Err(format!(
            "the log {name} holds no firmware log record ({} bytes, {} bad frames): not a walker log (COBS frames with CRC-16, see src/log.rs)?",
            log.bytes,
            log.bad()
        ));
    }
    if !log.events.iter().any(|e| matches!(e, Record::Startup(_))) {
        return Err(format!(
            "the log {name} has no start-up record ({} tick records, {} events): not a whole firmware run (a capture started after the firmware's start-up?)",
            log.ticks.len(),
            log.events.len()
        ));
    }
    if log.ticks.is_empty() {
        return Err(format!(
            "the log {name} has no tick record ({} events: {}): the firmware stopped before its control loop",
            log.events.len(),
            events_line(&log.events)
        ));
    }
    let mut warnings = Vec::new();
    if !log.events.iter().any(|e| matches!(e, Record::Stop(_))) {
        let rows = tick_rows(&log.ticks);
        let (first, last) = match (rows.first(), rows.last()) {
            (Some(a), Some(b)) => (a, b),
            _ => return Ok(warnings),
        };
        warnings.push(format!(
            "the log {name} has no stop record: it ends at t = {:.3} s (the log begins at {:.3} s), in {} ({}): cut mid-run? Everything after that is missing",
            last.t,
            first.t,
            phase_name(last.rec.phase),
            fault_name(last.rec.fault)
        ));
    }
    Ok(warnings)
}

fn events_line(events: &[Record]) -> String {
    events
        .iter()
        .map(|e| {
            let (_, _, kind, detail) = event_text(e);
            format!("{kind} {detail}")
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// Refuses a log that cannot be reported on ([`check_log`]), or one without a tick record in a
/// walking phase (the firmware never walked); returns [`check_log`]'s warnings.
pub fn check_walking(log: &DecodedLog, path: &Path) -> Result<Vec<String>, String> {
    let warnings = check_log(log, path)?;
    if !log.ticks.iter().any(|t| is_walking(t.phase)) {
        return Err(format!(
            "the log {} has no walking record ({} tick records, none in double or single support; {} events{}{}): the firmware did not walk",
            path.display(),
            log.ticks.len(),
            log.events.len(),
            if log.events.is_empty() { "" } else { ": " },
            events_line(&log.events)
        ));
    }
    Ok(warnings)
}

/// How much of the log's time span `[first tick, last tick]` the truth's time span covers:
/// (share 0..=1, truth start, truth end, log start, log end).
pub fn truth_coverage(rows: &[TickRow], truth: &TruthTable) -> (f64, f64, f64, f64, f64) {
    let (l0, l1) = match (rows.first(), rows.last()) {
        (Some(a), Some(b)) => (a.t, b.t),
        _ => (0.0, 0.0),
    };
    let (t0, t1) = match (truth.t.first(), truth.t.last()) {
        (Some(a), Some(b)) => (*a, *b),
        _ => (f64::NAN, f64::NAN),
    };
    let overlap = (t1.min(l1) - t0.max(l0)).max(0.0);
    let share = if l1 > l0 {
        if overlap.is_finite() {
            overlap / (l1 - l0)
        } else {
            0.0
        }
    } else {
        f64::from(u8::from(t0 <= l0 && l0 <= t1))
    };
    (share, t0, t1, l0, l1)
}

/// A warning when the truth covers less than 99 % of the log's time, saying how much.
pub fn truth_warning(rows: &[TickRow], truth: &TruthTable, path: &Path) -> Option<String> {
    let (share, t0, t1, l0, l1) = truth_coverage(rows, truth);
    (share < 0.99).then(|| {
        format!(
            "the truth file {} covers {:.0} % of the log (truth {t0:.3} s to {t1:.3} s, log {l0:.3} s to {l1:.3} s): the measured − true statistics and the truth figures cover only that part",
            path.display(),
            100.0 * share
        )
    })
}

/// Writes the whole report; returns what it found. A log that [`check_walking`] refuses is an
/// error (nothing is written). The plan is drawn as the firmware walked it: with the start-up's
/// logged adjustments (`TimingStretched`, `SwingLowered`: [`crate::beyond::adjusted_spec`],
/// the firmware's own `gait_core::gait::stretched`), so `opts.spec` is the plan as configured.
pub fn run(opts: &ReportOptions, robot: &Robot) -> Result<ReportSummary, String> {
    let log = decode_file(&opts.log)?;
    let mut warnings = check_walking(&log, &opts.log)?;
    let spec = crate::beyond::adjusted_spec(&opts.spec, &log.events);
    let adjustments = adjustment_lines(&opts.spec, &spec);
    std::fs::create_dir_all(&opts.out_dir)
        .map_err(|e| format!("cannot create {}: {e}", opts.out_dir.display()))?;
    let rows = tick_rows(&log.ticks);
    let stats = error_stats(&rows);
    let mut files = Vec::new();

    let mut csv = Vec::new();
    write_response_csv(&rows, &mut csv).map_err(|e| e.to_string())?;
    write_file(&opts.out_dir.join("zmp_response.csv"), &csv, &mut files)?;
    let mut ev = Vec::new();
    write_events_csv(&log.events, &mut ev).map_err(|e| e.to_string())?;
    write_file(&opts.out_dir.join("events.csv"), &ev, &mut files)?;

    // Support bounds from the same plan, sampled at the log's tick period.
    let dt = tick_period(&log).clamp(0.001, 0.02);
    let bounds = support_bounds(&spec, robot, dt)?;
    let alignment = align(&rows, bounds.walk_start);

    let truth = match &opts.truth {
        Some(p) => Some(read_truth(p)?),
        None => None,
    };
    if let (Some(tr), Some(p)) = (&truth, &opts.truth) {
        if tr.t.is_empty() {
            return Err(format!("the truth file {} has no data row", p.display()));
        }
        warnings.extend(truth_warning(&rows, tr, p));
    }
    let outcome = truth
        .as_ref()
        .and_then(|tr| outcome_json(tr, &opts.spec).ok());
    let truth_stats = truth.as_ref().map(|tr| {
        let mut s = ZmpErrorStats::<f64>::new();
        for r in &rows {
            if let Some(z) = tr.at(r.t) {
                s.push(z, r.measured());
            }
        }
        ErrorSummary::of(&s)
    });

    let model = opts.spec.model_kind().name().to_uppercase();
    let fig = zmp_figure(
        &format!("ZMP reference vs response ({model}, {})", opts.plan_name),
        &rows,
        &bounds,
        alignment.offset,
        truth.as_ref(),
    );
    write_figure(&fig, &opts.out_dir, "zmp_response", &mut files)?;
    let mut figures = vec!["zmp_response"];
    if let Some(tr) = &truth {
        let planned = planned_joint_speeds(&spec, robot, dt, alignment.offset);
        let speeds = joint_figure(
            &format!("Joint speeds: plan vs simulated robot ({model})"),
            tr,
            crate::sim::truth::joint_speed_column,
            "speed (rad/s)",
            planned.as_ref(),
        );
        let torques = joint_figure(
            &format!("Motor torques of the simulated robot ({model})"),
            tr,
            crate::sim::truth::joint_torque_column,
            "torque (N·m)",
            None,
        );
        let forces = foot_force_figure(&format!("Foot forces, simulated robot ({model})"), tr);
        for (fig, stem) in [
            (speeds, "joint_speeds"),
            (torques, "joint_torques"),
            (forces, "foot_forces"),
        ] {
            if let Some(fig) = fig {
                write_figure(&fig, &opts.out_dir, stem, &mut files)?;
                figures.push(stem);
            }
        }
    }

    // report.md
    let mut md = String::new();
    let _ = writeln!(md, "# ZMP response report\n");
    let _ = writeln!(md, "- log: `{}` ({} bytes)", opts.log.display(), log.bytes);
    let _ = writeln!(
        md,
        "- plan: {} (model {model}) — used for the support-polygon bounds",
        opts.plan_name
    );
    if adjustments.is_empty() {
        let _ = writeln!(md, "- plan adjustments at start-up: none logged");
    }
    for a in &adjustments {
        let _ = writeln!(
            md,
            "- plan adjustment at start-up, applied to the plan drawn here: {a}"
        );
    }
    for w in &warnings {
        let _ = writeln!(md, "- **warning**: {w}");
    }
    let _ = writeln!(
        md,
        "- records: {} good ({} ticks, {} events), {} bad (COBS {}, CRC {}, type {}, length {}, field {}, overlong {}, unterminated at end {}), {} sequence gaps",
        log.good(),
        log.ticks.len(),
        log.events.len(),
        log.bad(),
        log.rejects.cobs,
        log.rejects.crc,
        log.rejects.unknown_type,
        log.rejects.length,
        log.rejects.field,
        log.rejects.overlong,
        u8::from(log.trailing_bytes > 0),
        log.decoder.seq_gaps
    );
    if let (Some(a), Some(b)) = (rows.first(), rows.last()) {
        let _ = writeln!(md, "- time: {:.3} s to {:.3} s (firmware clock)", a.t, b.t);
    }
    let _ = writeln!(md, "- alignment: {}", alignment.how);
    let _ = writeln!(
        md,
        "- bus errors at the end: {} timeouts, {} CRC errors, {} status errors, {} tick overruns",
        rows.last().map_or(0, |r| r.rec.bus.timeouts),
        rows.last().map_or(0, |r| r.rec.bus.crc),
        rows.last().map_or(0, |r| r.rec.bus.status),
        rows.last().map_or(0, |r| r.rec.overruns)
    );
    let _ = writeln!(
        md,
        "\n## ZMP tracking error (seed 000 Table 3): measured − reference\n"
    );
    let _ = writeln!(
        md,
        "{} ticks, {} without a valid measured ZMP.\n",
        stats.ticks, stats.skipped
    );
    md.push_str(&stats_table(&stats));
    if let Some(ts) = &truth_stats {
        let _ = writeln!(md, "\n## Measured − true ZMP (sensor error)\n");
        md.push_str(&stats_table(ts));
    }
    let _ = writeln!(
        md,
        "\n## Plot\n\n![ZMP reference vs response](zmp_response.svg)\n"
    );
    let _ = writeln!(md, "Reference dash-dot, response solid, support-polygon min/max dashed (PNG: zmp_response.png).");
    for stem in &figures[1..] {
        let _ = writeln!(md, "\n![{stem}]({stem}.svg)\n");
    }
    if !log.events.is_empty() {
        let _ = writeln!(
            md,
            "\n## Events\n\n| seq | time (µs) | kind | detail |\n| ---: | ---: | --- | --- |"
        );
        for e in &log.events {
            let (seq, t, kind, detail) = event_text(e);
            let _ = writeln!(md, "| {seq} | {t} | {kind} | {detail} |");
        }
    }
    write_file(&opts.out_dir.join("report.md"), md.as_bytes(), &mut files)?;

    let json = serde_json::json!({
        "log": opts.log.display().to_string(),
        "plan": opts.plan_name,
        "model": opts.spec.model_kind().name(),
        "records": {
            "good": log.good(),
            "bad": log.bad(),
            "ticks": log.ticks.len(),
            "events": log.events.len(),
            "seq_gaps": log.decoder.seq_gaps,
            "bytes": log.bytes,
        },
        "zmp_error": stats_json(&stats),
        "truth_error": truth_stats.as_ref().map(stats_json),
        "outcome": outcome,
        "plan_adjustments": adjustments,
        "warnings": warnings,
        "figures": figures,
    });
    let json = serde_json::to_string_pretty(&json).map_err(|e| e.to_string())? + "\n";
    write_file(
        &opts.out_dir.join("stats.json"),
        json.as_bytes(),
        &mut files,
    )?;

    Ok(ReportSummary {
        log,
        rows,
        stats,
        truth_stats,
        alignment,
        files,
        spec,
        warnings,
        adjustments,
    })
}

/// The start-up's adjustments of the plan (`adjusted` against `configured`), in words.
pub fn adjustment_lines(configured: &WalkSpec, adjusted: &WalkSpec) -> Vec<String> {
    let mut out = Vec::new();
    if adjusted.period != configured.period {
        out.push(format!(
            "step timing stretched ×{:.3} for the servo speed limit (t1 {:.3} → {:.3} s, t2 {:.3} → {:.3} s, T {:.3} → {:.3} s)",
            adjusted.period / configured.period,
            configured.t1,
            adjusted.t1,
            configured.t2,
            adjusted.t2,
            configured.period,
            adjusted.period
        ));
    }
    if adjusted.h_z != configured.h_z {
        out.push(format!(
            "swing lowered for the servo speed limit (h_z {:.4} → {:.4} m)",
            configured.h_z, adjusted.h_z
        ));
    }
    out
}

/// The walk's outcome in the physics (the simulator's truth): what `walker fil` prints as its
/// "in the physics:" line ([`crate::fil::walk_figures_of`], [`crate::fil::sole_figures`]), as
/// the `outcome` object of stats.json. An error when the truth lacks the columns.
pub fn outcome_json(truth: &TruthTable, spec: &WalkSpec) -> Result<serde_json::Value, String> {
    let w = crate::fil::walk_figures_of(truth, Path::new("truth"), spec)?;
    let soles = crate::fil::planned_feet_travel(spec)
        .ok()
        .and_then(|p| crate::fil::sole_figures(truth, p));
    Ok(serde_json::json!({
        "fell": w.fell_at.is_some(),
        "fell_at_s": w.fell_at.map_or(serde_json::Value::Null, json_num),
        "walked_m": json_num(w.walked),
        "planned_m": json_num(w.planned),
        "walked_share": json_num(w.walked / w.planned),
        "heading_drift_rad": json_num(w.heading_drift),
        "max_tilt_rad": json_num(w.max_tilt),
        "soles": soles.map(|f| serde_json::json!({
            "left_travel_m": json_num(f.travel[0]),
            "right_travel_m": json_num(f.travel[1]),
            "left_planned_m": json_num(f.planned[0]),
            "right_planned_m": json_num(f.planned[1]),
            "max_slip_m": json_num(f.max_slip),
        })),
    }))
}

/// The tick period of a log, s: from its start-up record, else the median tick spacing,
/// else 1 ms.
pub fn tick_period(log: &DecodedLog) -> f64 {
    for e in &log.events {
        if let Record::Startup(s) = e {
            if s.tick_period_us > 0 {
                return f64::from(s.tick_period_us) * 1e-6;
            }
        }
    }
    let mut d: Vec<u32> = log
        .ticks
        .windows(2)
        .map(|w| w[1].time_us.wrapping_sub(w[0].time_us))
        .filter(|&v| v > 0)
        .collect();
    if d.is_empty() {
        return 0.001;
    }
    d.sort_unstable();
    f64::from(d[d.len() / 2]) * 1e-6
}

/// Compares runs: their Table 3 statistics side by side, as markdown.
pub fn compare_table(runs: &[(String, DecodedLog, ErrorSummary)]) -> String {
    let mut t = String::new();
    let names: Vec<&str> = runs.iter().map(|r| r.0.as_str()).collect();
    let _ = writeln!(t, "| statistic | {} |", names.join(" | "));
    let _ = writeln!(t, "| --- |{}", " ---: |".repeat(runs.len()));
    type Get = fn(&ErrorSummary) -> f64;
    let rows: [(&str, Get); 8] = [
        ("Σ\\|e_x\\| (m)", |s| s.x.sum_abs),
        ("mean \\|e_x\\| (m)", |s| s.x.mean_abs),
        ("RMS e_x (m)", |s| s.x.rms),
        ("max \\|e_x\\| (m)", |s| s.x.max_abs),
        ("Σ\\|e_y\\| (m)", |s| s.y.sum_abs),
        ("mean \\|e_y\\| (m)", |s| s.y.mean_abs),
        ("RMS e_y (m)", |s| s.y.rms),
        ("max \\|e_y\\| (m)", |s| s.y.max_abs),
    ];
    for (label, get) in rows {
        let vals: Vec<String> = runs.iter().map(|r| format!("{:.6}", get(&r.2))).collect();
        let _ = writeln!(t, "| {label} | {} |", vals.join(" | "));
    }
    let counts: Vec<String> = runs.iter().map(|r| format!("{}", r.2.x.count)).collect();
    let _ = writeln!(
        t,
        "| samples with a measured ZMP | {} |",
        counts.join(" | ")
    );
    let good: Vec<String> = runs
        .iter()
        .map(|r| format!("{} / {}", r.1.good(), r.1.bad()))
        .collect();
    let _ = writeln!(t, "| records good / bad | {} |", good.join(" | "));
    t
}

/// Ranks the runs by one statistic (smallest first), e.g. `tlipfm < dlipm < lipm`.
pub fn ranking(
    runs: &[(String, DecodedLog, ErrorSummary)],
    get: fn(&ErrorSummary) -> f64,
) -> String {
    let mut v: Vec<(&str, f64)> = runs.iter().map(|r| (r.0.as_str(), get(&r.2))).collect();
    v.sort_by(|a, b| a.1.total_cmp(&b.1));
    v.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(" < ")
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_servo_problem_record_reads_as_its_stop_reason() {
        use walker_contract::codes::ServoCheck;
        use walker_contract::record::FaultRecord;
        use walker_contract::{FaultKind, StopReason};
        for r in [
            StopReason::ServoLost { id: 4 },
            StopReason::ServoFault {
                id: 7,
                check: ServoCheck::Temperature,
                reading: 71,
            },
            StopReason::ServoFault {
                id: 4,
                check: ServoCheck::TorqueOff,
                reading: 0,
            },
        ] {
            let (_, id, _) = r.code();
            let f = FaultRecord {
                seq: 0,
                time_us: 0,
                kind: FaultKind::ServoProblem,
                id,
                value: r.servo_problem_value(),
            };
            assert_eq!(
                super::fault_words(&f),
                format!("servo monitor: {}", super::stop_words(&r))
            );
        }
    }

    use super::*;

    /// `zmp_response.csv` written with the `csv` crate has the bytes of the hand-made one:
    /// the header, a not-available value empty, names and counters as they are, `\n` rows.
    #[test]
    fn response_rows_keep_their_bytes() {
        let rec = TickRecord {
            seq: 7,
            zmp_valid: true,
            overruns: 2,
            ..TickRecord::default()
        };
        let row = TickRow {
            t: 1.5,
            rec,
            zmp_ref: [0.0123456, f64::NAN],
            zmp_meas: [-0.00001, 0.045],
            com: [0.1, -0.02],
            tau: f64::NAN,
        };
        let mut out = Vec::new();
        write_response_csv(&[row], &mut out).unwrap();
        let expect = format!(
            "{RESPONSE_HEADER}\n1.500000,7,0.01235,,-0.00001,0.04500,1,0.10000,-0.02000,,{},{},{},{},{},{},2\n",
            phase_name(rec.phase),
            fault_name(rec.fault),
            u8::from(rec.overrun),
            rec.bus.timeouts,
            rec.bus.crc,
            rec.bus.status
        );
        assert_eq!(String::from_utf8(out).unwrap(), expect);
    }

    fn bounds() -> SupportBounds {
        SupportBounds {
            t: vec![1.0, 1.5, 2.0],
            x: vec![[-0.05, 0.05], [0.0, 0.1], [0.02, 0.12]],
            y: vec![[-0.1, 0.1], [-0.1, 0.0], [-0.09, 0.09]],
            walk_start: 1.2,
        }
    }

    #[test]
    fn bounds_cover_the_ramp_and_the_final_hold() {
        // Log clock = plan clock − 0.5: the plan spans 0.5..1.5 s of a log from 0 to 3 s.
        let (lo, hi) = bounds_on_log_clock(&bounds(), 0, 0.5, 0.0, 3.0);
        assert_eq!(
            lo,
            vec![
                (0.0, -0.05),
                (0.5, -0.05),
                (1.0, 0.0),
                (1.5, 0.02),
                (3.0, 0.02)
            ]
        );
        assert_eq!(hi.first(), Some(&(0.0, 0.05)));
        assert_eq!(hi.last(), Some(&(3.0, 0.12)));
        let (lo, _) = bounds_on_log_clock(&bounds(), 1, 0.5, 0.0, 3.0);
        assert_eq!(lo.last(), Some(&(3.0, -0.09)));
    }

    #[test]
    fn bounds_inside_the_log_window_are_not_padded() {
        let (lo, _) = bounds_on_log_clock(&bounds(), 0, 0.0, 1.0, 2.0);
        assert_eq!(lo, vec![(1.0, -0.05), (1.5, 0.0), (2.0, 0.02)]);
        // A log window inside the plan: clipped, no padding.
        let (lo, _) = bounds_on_log_clock(&bounds(), 0, 0.0, 1.2, 1.7);
        assert_eq!(lo, vec![(1.5, 0.0)]);
        let empty = SupportBounds::default();
        assert!(bounds_on_log_clock(&empty, 0, 0.0, 0.0, 1.0).0.is_empty());
    }
}
