//! The ZMP-response log's wire format: one compact binary record per control tick plus a few event records,
//! framed so that a decoder fed an arbitrary byte stream finds every intact frame.
//!
//! # Framing
//! A frame on the wire is `COBS(payload ‖ crc16) ‖ 0x00`:
//! * `payload` = record type byte, u16 sequence number (LE), record body (below);
//! * `crc16` = CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR;
//!   check value of "123456789" = 0x29B1) over `payload`, little-endian;
//! * COBS (consistent overhead byte stuffing) removes every 0x00 from the frame, so 0x00 is
//!   only ever the frame delimiter. A decoder resynchronises at the next 0x00 whatever came
//!   before (start mid-frame, lost or corrupted bytes); a frame whose COBS structure, CRC,
//!   type or length is wrong is skipped and counted.
//!
//! All multi-byte fields are little-endian. `seq` is one counter shared by all record types
//! and wraps at 65536; a gap in `seq` means lost frames.
//!
//! # Tick record (type 0x01): 38-byte payload, exactly 40 bytes on the wire
//! | offset | size | field |
//! | --- | --- | --- |
//! | 0 | 1 | type = 0x01 |
//! | 1 | 2 | seq, u16 |
//! | 3 | 4 | time, u32 µs (nominal tick time; wraps after 71.6 min) |
//! | 7 | 3 | ZMP reference x, i24, units of 10 µm (±83.8 m; −2²³ = not available) |
//! | 10 | 3 | ZMP reference y, i24, 10 µm |
//! | 13 | 3 | measured ZMP x, i24, 10 µm |
//! | 16 | 3 | measured ZMP y, i24, 10 µm |
//! | 19 | 3 | CoM x, i24, 10 µm |
//! | 22 | 3 | CoM y, i24, 10 µm |
//! | 25 | 2 | τ = J·φ̈, i16, mN·m (saturating; −32768 = not available) |
//! | 27 | 1 | status: bits 0–2 support phase ([`LoggedPhase`]), bit 3 measured ZMP valid, bit 4 this tick overran, bits 5–6 fault state ([`FaultState`]), bit 7 reserved (0) |
//! | 28 | 2 | bus timeouts, u16 (cumulative, saturating) |
//! | 30 | 2 | bus CRC errors, u16 (cumulative, saturating) |
//! | 32 | 2 | servo status-packet errors, u16 (cumulative, saturating) |
//! | 34 | 2 | tick overruns, u16 (cumulative, saturating) |
//! | 36 | 2 | CRC-16 of bytes 0..36 |
//!
//! COBS adds one byte to a frame shorter than 254 bytes, the delimiter one more: 38 + 2 = 40
//! bytes per tick. At 1 kHz that is 40 kB/s = 400 kbit/s with 10 bits per byte, so the log
//! line needs at least 460 800 baud (87 % busy) — the OpenCR board uses 921 600 baud (43 %)
//! — or USB CDC.
//!
//! # Event records
//! * 0x02 start-up: `time u32, board u8 ([`BoardId`]), fw major u8, minor u8, patch u8,
//!   tick period u32 µs, bus baud u32, device count u8, flags u8 (bit 0 = bus probed),
//!   missing count u8 (≤ 16), missing ids [u8; count]`.
//! * 0x03 stop: `time u32, reason code u8, device id u8, value i32` ([`StopReason::code`], codes in [`crate::codes::StopCode`]).
//! * 0x04 fault: `time u32, kind u8 ([`FaultKind`]), device id u8, value i32`. Kinds (code:
//!   meaning, id, value): 1 device holding (device, ticks); 2 device recovered (device, ticks
//!   held); 3 target clamped (first joint, joint mask); 4 IMU non-finite (200, count); 5
//!   configuration rejected (key index, token position or `GaitError`); 6 start-up step failed
//!   (device, step code); 7 step timing stretched for the servo speed limit (worst joint
//!   index 0–11, total factor applied to t1, t2, T in 1/1000); 8 swing lowered for the servo
//!   speed limit (worst joint, new swing height in µm); 9 servo speed warning: the walk still
//!   needs a joint faster than the servo after the adjustment, or `feasibility=off` (worst
//!   joint, its peak speed in mrad/s).
//!
//! The tick record's CoM is the *commanded* CoM: the gait sample's CoM plus the feedback
//! stabilizer's shift when `stab=on`.
//!
//! The firmware writes with [`LogWriter`] into its board's [`LogSink`]; host tools decode with
//! [`RecordDecoder`] (log records; `dxl::Decoder` is the bus packets' decoder).

use crate::codes::wire_codes;
pub use crate::codes::{FaultKind, StopReason};
use gait_core::gait::TimingNote;

/// Largest payload (type + seq + body + CRC) of any record, bytes.
pub const MAX_PAYLOAD: usize = 48;
/// Largest encoded frame including the 0x00 delimiter, bytes.
pub const MAX_FRAME: usize = MAX_PAYLOAD + 2;
/// Encoded size of a tick record, bytes (including the delimiter).
pub const TICK_FRAME_LEN: usize = 40;
/// Most missing-device ids a start-up record carries.
pub const MAX_MISSING: usize = 16;
/// Position value meaning "not available" (i24 minimum).
pub const POS_NA: i32 = -0x80_0000;
/// τ value meaning "not available".
pub const TAU_NA: i16 = i16::MIN;
/// Position unit: metres per count (10 µm).
pub const POS_UNIT_M: f32 = 1.0e-5;

/// Record type bytes.
pub mod record_type {
    /// Per-tick ZMP-response record.
    pub const TICK: u8 = 0x01;
    /// Start-up report.
    pub const STARTUP: u8 = 0x02;
    /// Stop reason.
    pub const STOP: u8 = 0x03;
    /// Fault event.
    pub const FAULT: u8 = 0x04;
}

wire_codes! {
    /// Support phase of the gait (3 bits in the status byte).
    pub enum LoggedPhase {
        /// Both feet on the ground, walking.
        Double = 0,
        /// Left foot supporting, right foot swinging.
        SingleLeft = 1,
        /// Right foot supporting, left foot swinging.
        SingleRight = 2,
        /// Standing still (before the first or after the last step).
        Standing = 3,
        /// Stopped by the supervisor.
        Stopped = 4,
    }
}

wire_codes! {
    /// Supervisor state as logged (2 bits in the status byte).
    pub enum FaultState {
        /// Everything fresh.
        Ok = 0,
        /// At least one device is on last-good hold.
        Holding = 1,
        /// Stopping: holding the pose before torque off.
        Stopping = 2,
        /// Torque is off.
        TorqueOff = 3,
    }
}

impl FaultState {
    /// From the 2 bits of the status byte (every value decodes).
    pub fn from_bits(b: u8) -> Self {
        Self::try_from(b & 3).unwrap_or(Self::TorqueOff)
    }
}

wire_codes! {
    /// Which board wrote the log.
    pub enum BoardId {
        /// Unknown / host.
        Unknown = 0,
        /// QEMU mps2 (firmware-in-the-loop).
        QemuMps2 = 1,
        /// ROBOTIS OpenCR 1.0.
        OpenCr = 2,
        /// ROBOTIS OpenCM 9.04.
        OpenCm = 3,
    }
}

impl BoardId {
    /// From the wire code (unknown codes decode as [`BoardId::Unknown`]).
    pub fn from_code(b: u8) -> Self {
        Self::try_from(b).unwrap_or(Self::Unknown)
    }
}

/// Cumulative bus error counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub struct BusCounters {
    /// Replies that did not arrive in time.
    pub timeouts: u16,
    /// Replies with a bad CRC.
    pub crc: u16,
    /// Status packets with the error field set.
    pub status: u16,
}

/// Per-tick ZMP-response record (quantized; see the module docs for the layout).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub struct TickRecord {
    /// Sequence number (set by [`LogWriter`]).
    pub seq: u16,
    /// Nominal tick time, µs (truncated to 32 bits).
    pub time_us: u32,
    /// ZMP reference (x, y), 10 µm units, [`POS_NA`] when not available.
    pub zmp_ref: [i32; 2],
    /// Measured ZMP (x, y), 10 µm units.
    pub zmp_meas: [i32; 2],
    /// CoM (x, y), 10 µm units.
    pub com: [i32; 2],
    /// τ = J·φ̈, mN·m, [`TAU_NA`] when not available.
    pub tau_mnm: i16,
    /// Support phase.
    pub phase: LoggedPhase,
    /// Measured ZMP valid (enough load on the foot sensors).
    pub zmp_valid: bool,
    /// This tick overran its deadline.
    pub overrun: bool,
    /// Supervisor state.
    pub fault: FaultState,
    /// Bus error counters.
    pub bus: BusCounters,
    /// Tick overruns since boot (saturating).
    pub overruns: u16,
}

impl Default for TickRecord {
    fn default() -> Self {
        TickRecord {
            seq: 0,
            time_us: 0,
            zmp_ref: [POS_NA; 2],
            zmp_meas: [POS_NA; 2],
            com: [POS_NA; 2],
            tau_mnm: TAU_NA,
            phase: LoggedPhase::Standing,
            zmp_valid: false,
            overrun: false,
            fault: FaultState::Ok,
            bus: BusCounters::default(),
            overruns: 0,
        }
    }
}

/// Metres → 10 µm counts in i24 range; non-finite → [`POS_NA`].
pub fn pos_from_m(m: f32) -> i32 {
    if !m.is_finite() {
        return POS_NA;
    }
    let v = libm::roundf(m / POS_UNIT_M);
    if v >= 8_388_607.0 {
        8_388_607
    } else if v <= -8_388_607.0 {
        -8_388_607
    } else {
        v as i32
    }
}

/// 10 µm counts → metres; [`POS_NA`] → NaN.
pub fn pos_to_m(v: i32) -> f32 {
    if v == POS_NA {
        f32::NAN
    } else {
        v as f32 * POS_UNIT_M
    }
}

/// N·m → mN·m, saturating; non-finite → [`TAU_NA`].
pub fn tau_from_nm(t: f32) -> i16 {
    if !t.is_finite() {
        return TAU_NA;
    }
    // In range after the clamp: the cast keeps the value.
    gait_core::maths::fastmath::round_i32(t * 1000.0).clamp(-32_767, 32_767) as i16
}

/// mN·m → N·m; [`TAU_NA`] → NaN.
pub fn tau_to_nm(v: i16) -> f32 {
    if v == TAU_NA {
        f32::NAN
    } else {
        f32::from(v) * 1.0e-3
    }
}

impl TickRecord {
    /// Sets the ZMP reference from metres.
    pub fn set_zmp_ref_m(&mut self, x: f32, y: f32) {
        self.zmp_ref = [pos_from_m(x), pos_from_m(y)];
    }
    /// Sets the measured ZMP from metres.
    pub fn set_zmp_meas_m(&mut self, x: f32, y: f32) {
        self.zmp_meas = [pos_from_m(x), pos_from_m(y)];
    }
    /// Sets the CoM from metres.
    pub fn set_com_m(&mut self, x: f32, y: f32) {
        self.com = [pos_from_m(x), pos_from_m(y)];
    }
    /// Sets τ from N·m.
    pub fn set_tau_nm(&mut self, t: f32) {
        self.tau_mnm = tau_from_nm(t);
    }
}

/// Start-up report.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StartupRecord {
    /// Sequence number.
    pub seq: u16,
    /// Time, µs.
    pub time_us: u32,
    /// Board.
    pub board: BoardId,
    /// Firmware version (major, minor, patch).
    pub fw: [u8; 3],
    /// Tick period, µs.
    pub tick_period_us: u32,
    /// Servo bus baud rate.
    pub bus_baud: u32,
    /// Number of devices the firmware looks for on the bus.
    pub device_count: u8,
    /// The bus was probed (false: `missing` means nothing).
    pub probed: bool,
    /// Ids of the devices that did not answer (at most [`MAX_MISSING`]).
    pub missing: heapless::Vec<u8, MAX_MISSING>,
}

/// Stop record: why the supervisor stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub struct StopRecord {
    /// Sequence number.
    pub seq: u16,
    /// Time, µs.
    pub time_us: u32,
    /// Reason.
    pub reason: StopReason,
}

/// Fault event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub struct FaultRecord {
    /// Sequence number.
    pub seq: u16,
    /// Time, µs.
    pub time_us: u32,
    /// What happened.
    pub kind: FaultKind,
    /// Device id or joint index (0 when not applicable).
    pub id: u8,
    /// Kind-specific value.
    pub value: i32,
}

/// Any log record.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Record {
    /// Per-tick record.
    Tick(TickRecord),
    /// Start-up report.
    Startup(StartupRecord),
    /// Stop reason.
    Stop(StopRecord),
    /// Fault event.
    Fault(FaultRecord),
}

impl Record {
    /// The record's sequence number.
    pub fn seq(&self) -> u16 {
        match self {
            Record::Tick(r) => r.seq,
            Record::Startup(r) => r.seq,
            Record::Stop(r) => r.seq,
            Record::Fault(r) => r.seq,
        }
    }
    fn set_seq(&mut self, seq: u16) {
        match self {
            Record::Tick(r) => r.seq = seq,
            Record::Startup(r) => r.seq = seq,
            Record::Stop(r) => r.seq = seq,
            Record::Fault(r) => r.seq = seq,
        }
    }
}

// ---------------------------------------------------------------- CRC-16/CCITT-FALSE

/// `CRC_TABLE[x]`: the CRC register after shifting the byte `x` (in bits 15..8) through eight
/// rounds of the polynomial ([`dxl::crc::msb_first_table`]). One lookup per byte (512 bytes of
/// flash; a nibble table of 32 bytes would take two lookups a byte on the control tick's
/// ≈ 40 log bytes).
static CRC_TABLE: [u16; 256] = dxl::crc::msb_first_table(0x1021);

/// CRC-16/CCITT-FALSE of `data` (poly 0x1021, init 0xFFFF).
pub fn crc16_ccitt(data: &[u8]) -> u16 {
    data.iter().fold(0xFFFF_u16, |crc, &b| {
        // `(crc >> 8) ^ b` < 256: the lookup always succeeds.
        let x = usize::from((crc >> 8) as u8 ^ b);
        (crc << 8) ^ CRC_TABLE.get(x).copied().unwrap_or(0)
    })
}

// ---------------------------------------------------------------- payload building

struct Cursor<'a> {
    buf: &'a mut [u8],
    pos: usize,
    ok: bool,
}

impl<'a> Cursor<'a> {
    fn new(buf: &'a mut [u8]) -> Self {
        Cursor {
            buf,
            pos: 0,
            ok: true,
        }
    }
    fn put(&mut self, bytes: &[u8]) {
        match self.buf.get_mut(self.pos..self.pos + bytes.len()) {
            Some(dst) => {
                dst.copy_from_slice(bytes);
                self.pos += bytes.len();
            }
            None => self.ok = false,
        }
    }
    /// [`put`](Self::put) of a fixed number of bytes: an array store, N byte stores once
    /// inlined (a tick record has 16 fields; a `memcpy` call each would be a library call on
    /// the M3's tick).
    fn put_n<const N: usize>(&mut self, bytes: [u8; N]) {
        let dst = self.buf.get_mut(self.pos..self.pos + N);
        match dst.and_then(|d| <&mut [u8; N]>::try_from(d).ok()) {
            Some(dst) => {
                *dst = bytes;
                self.pos += N;
            }
            None => self.ok = false,
        }
    }
    fn u8(&mut self, v: u8) {
        self.put_n([v]);
    }
    fn u16(&mut self, v: u16) {
        self.put_n(v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.put_n(v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.put_n(v.to_le_bytes());
    }
    fn i24(&mut self, v: i32) {
        let b = v.to_le_bytes();
        self.put_n([b[0], b[1], b[2]]);
    }
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let s = self.buf.get(self.pos..self.pos + N)?;
        self.pos += N;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Some(a)
    }
    fn u8(&mut self) -> Option<u8> {
        self.take::<1>().map(|a| a[0])
    }
    fn u16(&mut self) -> Option<u16> {
        self.take::<2>().map(u16::from_le_bytes)
    }
    fn i16(&mut self) -> Option<i16> {
        self.take::<2>().map(i16::from_le_bytes)
    }
    fn u32(&mut self) -> Option<u32> {
        self.take::<4>().map(u32::from_le_bytes)
    }
    fn i32(&mut self) -> Option<i32> {
        self.take::<4>().map(i32::from_le_bytes)
    }
    fn i24(&mut self) -> Option<i32> {
        // Sign-extend by placing the 3 bytes in the top of an i32.
        self.take::<3>()
            .map(|b| i32::from_le_bytes([0, b[0], b[1], b[2]]) >> 8)
    }
    fn done(&self) -> bool {
        self.pos == self.buf.len()
    }
}

fn clamp_i24(v: i32) -> i32 {
    if v == POS_NA {
        POS_NA
    } else {
        v.clamp(-0x7F_FFFF, 0x7F_FFFF)
    }
}

fn status_byte(r: &TickRecord) -> u8 {
    (r.phase.code() & 7)
        | (u8::from(r.zmp_valid) << 3)
        | (u8::from(r.overrun) << 4)
        | ((r.fault.code() & 3) << 5)
}

/// Builds the payload (without CRC) of a record; returns its length or None if it does not fit.
fn build_payload(rec: &Record, out: &mut [u8]) -> Option<usize> {
    let mut c = Cursor::new(out);
    match rec {
        Record::Tick(r) => {
            c.u8(record_type::TICK);
            c.u16(r.seq);
            c.u32(r.time_us);
            for v in r
                .zmp_ref
                .iter()
                .chain(r.zmp_meas.iter())
                .chain(r.com.iter())
            {
                c.i24(clamp_i24(*v));
            }
            c.put_n(r.tau_mnm.to_le_bytes());
            c.u8(status_byte(r));
            c.u16(r.bus.timeouts);
            c.u16(r.bus.crc);
            c.u16(r.bus.status);
            c.u16(r.overruns);
        }
        Record::Startup(r) => {
            c.u8(record_type::STARTUP);
            c.u16(r.seq);
            c.u32(r.time_us);
            c.u8(r.board.code());
            c.put(&r.fw);
            c.u32(r.tick_period_us);
            c.u32(r.bus_baud);
            c.u8(r.device_count);
            c.u8(u8::from(r.probed));
            c.u8(r.missing.len() as u8);
            c.put(&r.missing);
        }
        Record::Stop(r) => {
            c.u8(record_type::STOP);
            c.u16(r.seq);
            c.u32(r.time_us);
            let (code, id, value) = r.reason.code();
            c.u8(code);
            c.u8(id);
            c.i32(value);
        }
        Record::Fault(r) => {
            c.u8(record_type::FAULT);
            c.u16(r.seq);
            c.u32(r.time_us);
            c.u8(r.kind.code());
            c.u8(r.id);
            c.i32(r.value);
        }
    }
    if c.ok {
        Some(c.pos)
    } else {
        None
    }
}

/// COBS-encodes `src` into `dst` followed by the 0x00 delimiter; returns the length written
/// or 0 when `dst` is too small.
fn cobs_encode(src: &[u8], dst: &mut [u8]) -> usize {
    // Worst case: one code byte per 254 data bytes, plus the first code byte and delimiter.
    if dst.len() < src.len() + src.len() / 254 + 2 {
        return 0;
    }
    let mut code_pos = 0usize;
    let mut out = 1usize;
    let mut code: u8 = 1;
    for &b in src {
        if b == 0 {
            if let Some(slot) = dst.get_mut(code_pos) {
                *slot = code;
            }
            code_pos = out;
            out += 1;
            code = 1;
        } else {
            if let Some(slot) = dst.get_mut(out) {
                *slot = b;
            }
            out += 1;
            code += 1;
            if code == 0xFF {
                if let Some(slot) = dst.get_mut(code_pos) {
                    *slot = code;
                }
                code_pos = out;
                out += 1;
                code = 1;
            }
        }
    }
    if let Some(slot) = dst.get_mut(code_pos) {
        *slot = code;
    }
    if let Some(slot) = dst.get_mut(out) {
        *slot = 0;
    }
    out + 1
}

/// COBS-decodes `src` (without delimiter) into `dst`; None on a malformed frame.
fn cobs_decode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    let mut i = 0usize;
    let mut o = 0usize;
    while i < src.len() {
        let code = *src.get(i)?;
        if code == 0 {
            return None;
        }
        i += 1;
        let n = usize::from(code) - 1;
        let run = src.get(i..i + n)?;
        dst.get_mut(o..o + n)?.copy_from_slice(run);
        i += n;
        o += n;
        if code != 0xFF && i < src.len() {
            *dst.get_mut(o)? = 0;
            o += 1;
        }
    }
    Some(o)
}

/// Encodes one record as a complete frame (COBS, CRC, delimiter) into `out`.
/// Returns the frame length, or 0 when `out` is too small ([`MAX_FRAME`] always suffices).
pub fn encode(rec: &Record, out: &mut [u8]) -> usize {
    let mut payload = [0u8; MAX_PAYLOAD];
    let Some(n) = payload
        .get_mut(..MAX_PAYLOAD - 2)
        .and_then(|p| build_payload(rec, p))
    else {
        return 0;
    };
    let crc = payload.get(..n).map_or(0, crc16_ccitt);
    match payload.get_mut(n..n + 2) {
        Some(c) => c.copy_from_slice(&crc.to_le_bytes()),
        None => return 0,
    }
    payload.get(..n + 2).map_or(0, |p| cobs_encode(p, out))
}

fn parse_payload(p: &[u8]) -> Result<Record, RecordError> {
    let mut r = Reader { buf: p, pos: 0 };
    let ty = r.u8().ok_or(RecordError::Length)?;
    let seq = r.u16().ok_or(RecordError::Length)?;
    let time_us = r.u32().ok_or(RecordError::Length)?;
    let rec = match ty {
        record_type::TICK => {
            let mut v = [0i32; 6];
            for x in v.iter_mut() {
                *x = r.i24().ok_or(RecordError::Length)?;
            }
            let tau = r.i16().ok_or(RecordError::Length)?;
            let st = r.u8().ok_or(RecordError::Length)?;
            let phase = LoggedPhase::try_from(st & 7).map_err(|_| RecordError::Field)?;
            if st & 0x80 != 0 {
                return Err(RecordError::Field);
            }
            let timeouts = r.u16().ok_or(RecordError::Length)?;
            let crc = r.u16().ok_or(RecordError::Length)?;
            let status = r.u16().ok_or(RecordError::Length)?;
            let overruns = r.u16().ok_or(RecordError::Length)?;
            Record::Tick(TickRecord {
                seq,
                time_us,
                zmp_ref: [v[0], v[1]],
                zmp_meas: [v[2], v[3]],
                com: [v[4], v[5]],
                tau_mnm: tau,
                phase,
                zmp_valid: st & 0x08 != 0,
                overrun: st & 0x10 != 0,
                fault: FaultState::from_bits(st >> 5),
                bus: BusCounters {
                    timeouts,
                    crc,
                    status,
                },
                overruns,
            })
        }
        record_type::STARTUP => {
            let board = BoardId::from_code(r.u8().ok_or(RecordError::Length)?);
            let fw = r.take::<3>().ok_or(RecordError::Length)?;
            let tick_period_us = r.u32().ok_or(RecordError::Length)?;
            let bus_baud = r.u32().ok_or(RecordError::Length)?;
            let device_count = r.u8().ok_or(RecordError::Length)?;
            let probed = r.u8().ok_or(RecordError::Length)? & 1 != 0;
            let count = usize::from(r.u8().ok_or(RecordError::Length)?);
            if count > MAX_MISSING {
                return Err(RecordError::Field);
            }
            let mut missing = heapless::Vec::new();
            for _ in 0..count {
                let id = r.u8().ok_or(RecordError::Length)?;
                missing.push(id).map_err(|_| RecordError::Field)?;
            }
            Record::Startup(StartupRecord {
                seq,
                time_us,
                board,
                fw,
                tick_period_us,
                bus_baud,
                device_count,
                probed,
                missing,
            })
        }
        record_type::STOP => {
            let code = r.u8().ok_or(RecordError::Length)?;
            let id = r.u8().ok_or(RecordError::Length)?;
            let value = r.i32().ok_or(RecordError::Length)?;
            let reason = StopReason::from_code(code, id, value).ok_or(RecordError::Field)?;
            Record::Stop(StopRecord {
                seq,
                time_us,
                reason,
            })
        }
        record_type::FAULT => {
            let kind = FaultKind::from_code(r.u8().ok_or(RecordError::Length)?);
            let id = r.u8().ok_or(RecordError::Length)?;
            let value = r.i32().ok_or(RecordError::Length)?;
            Record::Fault(FaultRecord {
                seq,
                time_us,
                kind,
                id,
                value,
            })
        }
        other => return Err(RecordError::UnknownType(other)),
    };
    if r.done() {
        Ok(rec)
    } else {
        Err(RecordError::Length)
    }
}

/// Why a frame was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub enum RecordError {
    /// Malformed COBS (a zero code or a run past the end).
    Cobs,
    /// CRC mismatch.
    Crc,
    /// Unknown record type.
    UnknownType(u8),
    /// Payload too short or too long for its type.
    Length,
    /// A field holds an impossible value.
    Field,
    /// The frame was longer than [`MAX_FRAME`] (bytes dropped until the next delimiter).
    Overlong,
}

/// What the decoder has seen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RecordDecoderStats {
    /// Frames decoded.
    pub frames: u32,
    /// Frames rejected (any [`RecordError`]).
    pub rejected: u32,
    /// Of those, CRC mismatches.
    pub crc_errors: u32,
    /// Bytes thrown away in rejected frames.
    pub skipped_bytes: u32,
    /// Frames whose sequence number was not the previous one + 1.
    pub seq_gaps: u32,
}

/// Streaming, allocation-free frame decoder. Feed it any byte stream; it never panics and
/// its memory is bounded by [`MAX_FRAME`].
#[derive(Clone, Debug)]
pub struct RecordDecoder {
    buf: [u8; MAX_FRAME],
    len: usize,
    overlong: bool,
    last_seq: Option<u16>,
    stats: RecordDecoderStats,
}

impl Default for RecordDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl RecordDecoder {
    /// A fresh decoder (may start mid-frame: the first partial frame is then rejected).
    pub const fn new() -> Self {
        RecordDecoder {
            buf: [0; MAX_FRAME],
            len: 0,
            overlong: false,
            last_seq: None,
            stats: RecordDecoderStats {
                frames: 0,
                rejected: 0,
                crc_errors: 0,
                skipped_bytes: 0,
                seq_gaps: 0,
            },
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> RecordDecoderStats {
        self.stats
    }

    fn reject(&mut self, e: RecordError, bytes: usize) -> Option<Result<Record, RecordError>> {
        self.stats.rejected = self.stats.rejected.saturating_add(1);
        if e == RecordError::Crc {
            self.stats.crc_errors = self.stats.crc_errors.saturating_add(1);
        }
        self.stats.skipped_bytes = self.stats.skipped_bytes.saturating_add(bytes as u32);
        Some(Err(e))
    }

    /// Feeds one byte; returns a decoded record or a rejection at each frame end.
    pub fn push(&mut self, byte: u8) -> Option<Result<Record, RecordError>> {
        if byte != 0 {
            if let Some(slot) = self.buf.get_mut(self.len) {
                *slot = byte;
                self.len += 1;
            } else {
                self.overlong = true;
                self.stats.skipped_bytes = self.stats.skipped_bytes.saturating_add(1);
            }
            return None;
        }
        // Delimiter.
        let n = self.len;
        self.len = 0;
        if core::mem::take(&mut self.overlong) {
            return self.reject(RecordError::Overlong, n + 1);
        }
        if n == 0 {
            return None; // Empty frame (repeated delimiters): idle line, not an error.
        }
        let mut payload = [0u8; MAX_FRAME];
        let Some(m) = self
            .buf
            .get(..n)
            .and_then(|src| cobs_decode(src, &mut payload))
        else {
            return self.reject(RecordError::Cobs, n + 1);
        };
        if m < 3 {
            return self.reject(RecordError::Length, n + 1);
        }
        let Some((body, crc_bytes)) = payload.get(..m).and_then(|f| f.split_at_checked(m - 2))
        else {
            return self.reject(RecordError::Length, n + 1);
        };
        let crc = match crc_bytes {
            [lo, hi] => u16::from_le_bytes([*lo, *hi]),
            _ => return self.reject(RecordError::Length, n + 1),
        };
        if crc16_ccitt(body) != crc {
            return self.reject(RecordError::Crc, n + 1);
        }
        match parse_payload(body) {
            Ok(rec) => {
                self.stats.frames = self.stats.frames.saturating_add(1);
                let seq = rec.seq();
                if let Some(prev) = self.last_seq {
                    if seq != prev.wrapping_add(1) {
                        self.stats.seq_gaps = self.stats.seq_gaps.saturating_add(1);
                    }
                }
                self.last_seq = Some(seq);
                Some(Ok(rec))
            }
            Err(e) => self.reject(e, n + 1),
        }
    }

    /// Feeds a slice, calling `f` for every frame end (record or rejection).
    pub fn feed(&mut self, bytes: &[u8], mut f: impl FnMut(Result<Record, RecordError>)) {
        for &b in bytes {
            if let Some(r) = self.push(b) {
                f(r);
            }
        }
    }
}

/// The fault record (kind, id, value) that logs a note of the servo-speed check.
pub fn timing_fault(n: TimingNote) -> (FaultKind, u8, i32) {
    match n {
        TimingNote::Stretched { joint, milli } => (
            FaultKind::TimingStretched,
            joint,
            i32::try_from(milli).unwrap_or(i32::MAX),
        ),
        TimingNote::Lowered { joint, um } => (
            FaultKind::SwingLowered,
            joint,
            i32::try_from(um).unwrap_or(i32::MAX),
        ),
        TimingNote::TooFast { joint, mrad_s } => (FaultKind::SpeedLimit, joint, mrad_s),
    }
}

/// Sink of the encoded record frames (a board's log UART); best effort, never blocks for
/// long and never fails: a sink that cannot keep up drops bytes (the decoder resynchronises).
pub trait LogSink {
    /// Writes encoded log bytes.
    fn write_log(&mut self, bytes: &[u8]);
}

/// Assigns sequence numbers and writes encoded records to a [`LogSink`].
#[derive(Clone, Debug, Default)]
pub struct LogWriter {
    next_seq: u16,
    dropped: u32,
    last_fault: u8,
}

impl LogWriter {
    /// A writer starting at sequence number 0.
    pub const fn new() -> Self {
        LogWriter {
            next_seq: 0,
            dropped: 0,
            last_fault: 0,
        }
    }

    /// Records that could not be encoded (should never happen; counted for diagnostics).
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// The code of the last fault record written that is a fault ([`FaultKind::is_fault`]),
    /// 0 none: the command port's Fault Kind register.
    pub fn last_fault(&self) -> u8 {
        self.last_fault
    }

    /// Stamps `rec` with the next sequence number, encodes it and writes it to `sink`.
    pub fn write(&mut self, sink: &mut impl LogSink, mut rec: Record) {
        if let Record::Fault(f) = &rec {
            if f.kind.is_fault() {
                self.last_fault = f.kind.code();
            }
        }
        rec.set_seq(self.next_seq);
        self.next_seq = self.next_seq.wrapping_add(1);
        let mut frame = [0u8; MAX_FRAME];
        let n = encode(&rec, &mut frame);
        match frame.get(..n) {
            Some(f) if n > 0 => sink.write_log(f),
            _ => self.dropped = self.dropped.saturating_add(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    fn sample_tick(seq: u16) -> TickRecord {
        let mut r = TickRecord {
            seq,
            time_us: 123_456 + u32::from(seq) * 1000,
            phase: LoggedPhase::SingleLeft,
            zmp_valid: true,
            overrun: seq.is_multiple_of(7),
            fault: FaultState::Holding,
            bus: BusCounters {
                timeouts: 3,
                crc: 1,
                status: 65535,
            },
            overruns: 9,
            ..TickRecord::default()
        };
        r.set_zmp_ref_m(0.0123, -0.045);
        r.set_zmp_meas_m(-29.99, 29.99);
        r.set_com_m(0.0, 1.0e-5);
        r.set_tau_nm(-0.1234);
        r
    }

    fn all_records() -> Vec<Record> {
        let mut missing = heapless::Vec::new();
        for id in [3u8, 111, 200] {
            missing.push(id).ok();
        }
        vec![
            Record::Tick(sample_tick(0)),
            Record::Tick(TickRecord::default()),
            Record::Startup(StartupRecord {
                seq: 1,
                time_us: 5,
                board: BoardId::QemuMps2,
                fw: [0, 1, 0],
                tick_period_us: 1000,
                bus_baud: 1_000_000,
                device_count: 15,
                probed: true,
                missing,
            }),
            Record::Stop(StopRecord {
                seq: 2,
                time_us: 99,
                reason: StopReason::Fall { tilt_mrad: 712 },
            }),
            Record::Stop(StopRecord {
                seq: 3,
                time_us: 99,
                reason: StopReason::DeviceLost { id: 7 },
            }),
            Record::Fault(FaultRecord {
                seq: 4,
                time_us: 1,
                kind: FaultKind::DeviceHolding,
                id: 111,
                value: -5,
            }),
        ]
    }

    fn decode_all(bytes: &[u8]) -> (Vec<Record>, RecordDecoderStats) {
        let mut d = RecordDecoder::new();
        let mut out = Vec::new();
        d.feed(bytes, |r| {
            if let Ok(r) = r {
                out.push(r)
            }
        });
        (out, d.stats())
    }

    #[test]
    fn crc_check_value() {
        assert_eq!(crc16_ccitt(b"123456789"), 0x29B1);
    }

    /// Bit by bit, straight from the definition.
    fn crc16_ccitt_bitwise(data: &[u8]) -> u16 {
        let mut crc = 0xFFFF_u16;
        for &b in data {
            crc ^= u16::from(b) << 8;
            for _ in 0..8 {
                crc = if crc & 0x8000 != 0 {
                    (crc << 1) ^ 0x1021
                } else {
                    crc << 1
                };
            }
        }
        crc
    }

    #[test]
    fn crc_matches_the_bitwise_definition() {
        let mut x = 0x1234_5678_u32;
        for len in 0..200 {
            let data: Vec<u8> = (0..len)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 17;
                    x ^= x << 5;
                    x as u8
                })
                .collect();
            assert_eq!(crc16_ccitt(&data), crc16_ccitt_bitwise(&data), "len {len}");
        }
        for b in 0..=255u8 {
            assert_eq!(crc16_ccitt(&[b]), crc16_ccitt_bitwise(&[b]));
        }
    }

    #[test]
    fn tick_frame_is_40_bytes() {
        let mut buf = [0u8; MAX_FRAME];
        for r in [sample_tick(5), TickRecord::default()] {
            let n = encode(&Record::Tick(r), &mut buf);
            assert_eq!(n, TICK_FRAME_LEN);
            assert_eq!(buf[n - 1], 0);
            assert!(buf[..n - 1].iter().all(|&b| b != 0));
        }
    }

    #[test]
    fn round_trip_every_record() {
        for rec in all_records() {
            let mut buf = [0u8; MAX_FRAME];
            let n = encode(&rec, &mut buf);
            assert!(n > 0 && n <= MAX_FRAME);
            let (got, st) = decode_all(&buf[..n]);
            assert_eq!(got, vec![rec.clone()]);
            assert_eq!(st.rejected, 0);
        }
    }

    #[test]
    fn quantization() {
        let r = sample_tick(0);
        assert!((pos_to_m(r.zmp_ref[0]) - 0.0123).abs() < 6e-6);
        assert!((pos_to_m(r.zmp_meas[0]) + 29.99).abs() < 1e-4);
        assert_eq!(pos_from_m(f32::NAN), POS_NA);
        assert_eq!(pos_from_m(1.0e6), 8_388_607);
        assert_eq!(pos_from_m(-1.0e6), -8_388_607);
        assert!(pos_to_m(POS_NA).is_nan());
        assert_eq!(tau_from_nm(f32::INFINITY), TAU_NA);
        assert_eq!(tau_from_nm(100.0), 32767);
        assert_eq!(tau_from_nm(-0.1234), -123);
        assert!((tau_to_nm(-123) + 0.123).abs() < 1e-6);
    }

    #[test]
    fn small_buffer_gives_zero() {
        let mut buf = [0u8; 10];
        assert_eq!(encode(&Record::Tick(sample_tick(0)), &mut buf), 0);
    }

    fn stream(n: u16) -> Vec<u8> {
        let mut w = LogWriter::new();
        struct V(Vec<u8>);
        impl LogSink for V {
            fn write_log(&mut self, b: &[u8]) {
                self.0.extend_from_slice(b)
            }
        }
        let mut v = V(Vec::new());
        for i in 0..n {
            w.write(&mut v, Record::Tick(sample_tick(i)));
        }
        v.0
    }

    #[test]
    fn the_last_fault_skips_events_and_notices() {
        struct Null;
        impl LogSink for Null {
            fn write_log(&mut self, _: &[u8]) {}
        }
        let fault = |kind| {
            Record::Fault(FaultRecord {
                seq: 0,
                time_us: 0,
                kind,
                id: 0,
                value: 0,
            })
        };
        let mut w = LogWriter::new();
        for (kind, last) in [
            (FaultKind::ResetCause, 0),
            (FaultKind::TimingStretched, 0),
            (FaultKind::SwingLowered, 0),
            (FaultKind::SpeedLimit, 9),
            (FaultKind::Footstep, 9),
            (FaultKind::CatchStep, 9),
            (FaultKind::DeviceHolding, 1),
            (FaultKind::CommandReceived, 1),
            (FaultKind::TimingStretched, 1),
        ] {
            w.write(&mut Null, fault(kind));
            assert_eq!(w.last_fault(), last, "after {kind:?}");
        }
    }

    #[test]
    fn writer_numbers_records() {
        let (got, st) = decode_all(&stream(300));
        assert_eq!(got.len(), 300);
        for (i, r) in got.iter().enumerate() {
            assert_eq!(r.seq(), i as u16);
        }
        assert_eq!(st.seq_gaps, 0);
    }

    #[test]
    fn mid_stream_start() {
        let s = stream(10);
        for start in 0..TICK_FRAME_LEN {
            let (got, st) = decode_all(&s[start..]);
            let expect_full = if start == 0 { 10 } else { 9 };
            assert_eq!(got.len(), expect_full, "start {start}");
            assert!(st.rejected <= 1);
            if let Some(first) = got.first() {
                assert_eq!(first.seq(), 10 - expect_full as u16);
            }
        }
    }

    #[test]
    fn corrupted_bytes_are_skipped_and_counted() {
        let mut s = stream(20);
        // Flip one byte inside frames 3 and 11 (never the delimiter).
        s[3 * 40 + 10] ^= 0x5A;
        s[11 * 40 + 25] ^= 0x01;
        let (got, st) = decode_all(&s);
        assert_eq!(got.len(), 18);
        assert_eq!(st.rejected, 2);
        assert_eq!(st.seq_gaps, 2);
        // A dropped byte in frame 5, inserted garbage before frame 8.
        let mut s = stream(10);
        s.remove(5 * 40 + 3);
        s.splice(8 * 40 - 1..8 * 40 - 1, [1u8, 2, 3, 0xFF].iter().copied());
        let (got, _) = decode_all(&s);
        assert_eq!(got.len(), 8);
    }

    #[test]
    fn overlong_garbage_is_bounded() {
        let mut s = vec![0x55u8; 1000];
        s.push(0);
        s.extend(stream(2));
        let (got, st) = decode_all(&s);
        assert_eq!(got.len(), 2);
        assert_eq!(st.rejected, 1);
    }

    #[test]
    fn random_streams_never_panic() {
        // xorshift: deterministic pseudo-random bytes, some frames interleaved.
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut rnd = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let good = stream(50);
        let mut d = RecordDecoder::new();
        let mut ok = 0;
        for round in 0..200 {
            let len = (rnd() % 500) as usize;
            let mut buf: Vec<u8> = (0..len)
                .map(|_| {
                    let v = rnd();
                    // Bias towards zeros and small codes to exercise COBS paths.
                    if v % 5 == 0 {
                        0
                    } else {
                        (v >> 8) as u8
                    }
                })
                .collect();
            if round % 4 == 0 {
                // Garbage that does not end in a delimiter swallows the first frame after it;
                // the second one is always found.
                buf.extend_from_slice(&good[..80]);
            }
            d.feed(&buf, |r| {
                if r.is_ok() {
                    ok += 1
                }
            });
        }
        assert!(ok >= 50, "found {ok}");
        assert!(d.stats().rejected > 0);
    }

    #[test]
    fn cobs_long_runs() {
        let src: Vec<u8> = (0..600u32).map(|i| (i % 255 + 1) as u8).collect();
        let mut enc = vec![0u8; 700];
        let n = cobs_encode(&src, &mut enc);
        assert!(n > 0);
        assert!(enc[..n - 1].iter().all(|&b| b != 0));
        let mut dec = vec![0u8; 700];
        let m = cobs_decode(&enc[..n - 1], &mut dec).unwrap();
        assert_eq!(&dec[..m], &src[..]);
        let src = [0u8, 0, 1, 0];
        let n = cobs_encode(&src, &mut enc);
        let m = cobs_decode(&enc[..n - 1], &mut dec).unwrap();
        assert_eq!(&dec[..m], &src[..]);
    }
}
