//! The command port: the firmware as a Dynamixel Protocol 2.0 device on a second serial port,
//! so any Dynamixel master (the official ROBOTIS SDK, `walker`) commands the walk with the
//! project's own codec on both ends.
//!
//! The device has ID [`PORT_ID`] (not on the servo bus: [`crate::bus_map::DEVICE_IDS`]) and
//! model number [`MODEL_NUMBER_VALUE`]. It answers PING, READ, WRITE, SYNC READ, SYNC WRITE,
//! BULK READ and BULK WRITE (its own entry); every other instruction gets the Instruction
//! error. Broadcast packets are executed without a reply except PING (the protocol's rule).
//!
//! # Control table (all values little-endian)
//! | addr | size | name | access | unit / values |
//! |---:|---:|---|---|---|
//! | 0 | 2 | Model Number | R | [`MODEL_NUMBER_VALUE`] |
//! | 6 | 1 | Firmware Version | R | [`FIRMWARE_VERSION_VALUE`] |
//! | 7 | 1 | ID | R | [`PORT_ID`] |
//! | 64 | 1 | Mode | RW | [`Mode`]: 0 torque off, 1 stand, 2 walk (velocity), 3 stop |
//! | 66 | 2 | Velocity X | RW | i16, mm/s forward, −100 ..= 200 |
//! | 68 | 2 | Velocity Y | RW | i16, mm/s leftward, −100 ..= 100 |
//! | 70 | 2 | Yaw Rate | RW | i16, mrad/s counter-clockwise, −600 ..= 600 |
//! | 72 | 1 | Heartbeat | RW | any value: a valid command write that changes no command (the deadman) |
//! | 80 | 8 | Step Entry | RW | dx, dy (i16 mm), dyaw (i16 mrad), side (1 left, 2 right), 0; each write appends to the step list |
//! | 128 | 1 | State | R | [`PortState`] |
//! | 129 | 1 | Support Foot | R | 0 both, 1 left, 2 right |
//! | 130 | 2 | Step Count | R | u16, steps finished since power-on |
//! | 132 | 2 | Measured ZMP X | R | i16, mm (robot frame) |
//! | 134 | 2 | Measured ZMP Y | R | i16, mm |
//! | 136 | 1 | ZMP Valid | R | 1 when the feet measure a ZMP |
//! | 137 | 1 | Stop Code | R | the supervisor's [`crate::StopCode`], else 13 ([`crate::StopCode::Deadman`]) after a deadman stop until Mode is written again, 0 none |
//! | 138 | 1 | Fault Kind | R | the last [`crate::FaultKind`] logged, 0 none |
//! | 139 | 1 | Step List Length | R | entries not yet stepped: in the port (≤ [`STEP_LIST_LEN`]) and taken by the walk (≤ 8) |
//! | 140 | 2 | Walk Velocity X | R | i16, mm/s: the velocity the feet step (after the limits) |
//! | 142 | 2 | Walk Velocity Y | R | i16, mm/s |
//! | 144 | 2 | Walk Yaw Rate | R | i16, mrad/s |
//! | 146 | 2 | Command Count | R | u16, accepted writes to the command registers (wraps) |
//! | 160 | 24 | Param Key | RW | a run-time parameter's key (docs/parameters.md), ASCII, NUL-padded |
//! | 184 | 16 | Param Value | RW | its value as token text (`0.25`, `on`), ASCII, NUL-padded |
//! | 200 | 1 | Param Op | RW | a write runs it: [`ParamOp`] 1 get, 2 set, 3 get by index, 4 save |
//! | 201 | 1 | Param Status | R | [`ParamStatus`] of the last op: 0 done, 1 pending, 2 unknown key, 3 bad value, 4 out of range, 5 refused while a run is going, 6 the store failed, 7 not in this board's build |
//! | 202 | 2 | Param Index | RW | u16, the parameter of op 3 (0 ..= Param Count − 1) |
//! | 204 | 2 | Param Count | R | u16, the number of run-time parameters |
//!
//! The velocity ranges are [`gait_core::trajectory::command::CommandLimits::DEFAULT`]'s in the wire's units.
//!
//! # Valid command writes and the deadman
//! A **valid command write** is a WRITE, SYNC WRITE or BULK WRITE (its own entry) addressed to
//! the port (its ID or broadcast) that the table accepts: every one advances Command Count by
//! one ([`CommandTable::command_count`]); a rejected write, a READ or a PING is none. Writing
//! Heartbeat (72, any value) is one that changes no command. In Mode = walk the firmware stops
//! the walk when none came for `deadman_ms` ([`CommandTable::deadman_stop`]).
//!
//! # Checks (the protocol's error statuses; a rejected write changes nothing)
//! * an address beyond the table or in a gap: **Data Range**; a read-only byte: **Access**;
//! * a write that covers part of a multi-byte register: **Data Length**;
//! * a value outside its register's range (mode > 3, |vx| beyond the limit, a step entry with
//!   side ∉ {1, 2} or beyond [`STEP_ENTRY_MAX`]): **Data Range**;
//! * a step entry with the step list full: **Data Limit**;
//! * a READ longer than the table: **Data Range**; a packet whose parameters do not fit its
//!   instruction: **Data Length**; an unknown instruction: **Instruction**.
//!
//! # Parameters
//! Every run-time parameter (the one table, [`crate::params::PARAMS`], with its domains) reads
//! and writes through the parameter registers: a master writes Param Key, Param Value and Param
//! Op in one WRITE (160, 41 bytes) — or Param Index and Param Op for op 3 — and reads Param
//! Status (and Param Key / Value) once it is no longer pending. The firmware serves an op at
//! its next tick ([`CommandTable::serve_param`]): a get fills Param Value (and, by index,
//! Param Key) with the value in force; a set parses and range-checks the value as the
//! semihosting command line does and applies it to the configuration of the next run — only
//! while no run is going (the firmware waits for the enable, `wait_enable`), else it is refused
//! ([`ParamStatus::Running`]) and nothing changes. A save (op 4, between runs too) writes the
//! configuration in force to the board's store ([`crate::param_store`]), loaded at the next
//! boot: the table only takes the request ([`CommandTable::take_save`]); the firmware answers
//! it ([`CommandTable::finish_save`]). A build without the parameters (the OpenCM 9.04's: no
//! flash for them) answers every op with [`ParamStatus::Unsupported`]
//! ([`CommandTable::answer_param`]) and changes nothing.
//!
//! Fixed-point units make a non-finite command unrepresentable on the wire; the typed
//! accessors ([`CommandTable::velocity`]) return finite values in SI units only.
//!
//! Everything is bounded: one packet of at most [`RX_PARAMS`] parameter bytes at a time,
//! replies built in a caller's buffer of [`REPLY_MAX`] bytes; no allocation, no panic.

use dxl::instruction::{ErrorCode, Instruction, ParseError, StatusError};
use dxl::packet::{Decoder, Packet, BROADCAST_ID};
use gait_core::trajectory::command::{CommandLimits, WalkCommand};

/// The command port's device ID (not used on the servo bus).
pub const PORT_ID: u8 = 150;
/// Model number the port answers PING with.
pub const MODEL_NUMBER_VALUE: u16 = 0x5A30;
/// Firmware version byte (the control table's layout version).
pub const FIRMWARE_VERSION_VALUE: u8 = 1;
/// Size of the control table, bytes.
pub const TABLE_LEN: usize = 206;
/// Entries of the step list.
pub const STEP_LIST_LEN: usize = 8;
/// Largest |dx|, |dy| (mm) and |dyaw| (mrad) of a step entry.
pub const STEP_ENTRY_MAX: [i16; 3] = [80, 80, 600];
/// Largest instruction parameter length the port decodes, bytes.
pub const RX_PARAMS: usize = 2 * TABLE_LEN + 16;
/// A reply buffer large enough for any reply (a READ of the whole table, stuffed).
pub const REPLY_MAX: usize = 2 * TABLE_LEN + 16;

/// A register of the table: address and size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Reg {
    /// Address.
    pub addr: u16,
    /// Size, bytes.
    pub len: u16,
}

const fn reg(addr: u16, len: u16) -> Reg {
    Reg { addr, len }
}

/// Model Number (R).
pub const MODEL_NUMBER: Reg = reg(0, 2);
/// Firmware Version (R).
pub const FIRMWARE_VERSION: Reg = reg(6, 1);
/// ID (R).
pub const ID: Reg = reg(7, 1);
/// Mode (RW, [`Mode`]).
pub const MODE: Reg = reg(64, 1);
/// Velocity X, mm/s (RW).
pub const VELOCITY_X: Reg = reg(66, 2);
/// Velocity Y, mm/s (RW).
pub const VELOCITY_Y: Reg = reg(68, 2);
/// Yaw rate, mrad/s (RW).
pub const YAW_RATE: Reg = reg(70, 2);
/// Heartbeat (RW, any value): a valid command write that changes no command.
pub const HEARTBEAT: Reg = reg(72, 1);
/// Step entry (RW; a write appends).
pub const STEP_ENTRY: Reg = reg(80, 8);
/// State (R, [`PortState`]).
pub const STATE: Reg = reg(128, 1);
/// Support foot (R).
pub const SUPPORT_FOOT: Reg = reg(129, 1);
/// Step count (R).
pub const STEP_COUNT: Reg = reg(130, 2);
/// Measured ZMP x, mm (R).
pub const ZMP_X: Reg = reg(132, 2);
/// Measured ZMP y, mm (R).
pub const ZMP_Y: Reg = reg(134, 2);
/// ZMP valid (R).
pub const ZMP_VALID: Reg = reg(136, 1);
/// Last stop code (R).
pub const STOP_CODE: Reg = reg(137, 1);
/// Last fault kind (R).
pub const FAULT_KIND: Reg = reg(138, 1);
/// Step list length (R).
pub const STEP_LIST: Reg = reg(139, 1);
/// Walk velocity x, mm/s (R).
pub const WALK_VX: Reg = reg(140, 2);
/// Walk velocity y, mm/s (R).
pub const WALK_VY: Reg = reg(142, 2);
/// Walk yaw rate, mrad/s (R).
pub const WALK_YAW: Reg = reg(144, 2);
/// Command count (R).
pub const COMMAND_COUNT: Reg = reg(146, 2);
/// Servo stiffness, 0.01 N·m/rad (R; the servo survey's, at the present supply; 0 not measured).
pub const SERVO_STIFFNESS: Reg = reg(148, 2);
/// Supply voltage, 0.1 V (R; the leg servos' Present Input Voltage last read; 0 none yet).
pub const SUPPLY_VOLTAGE: Reg = reg(150, 2);

/// Param Key (RW, ASCII, NUL-padded).
pub const PARAM_KEY: Reg = reg(160, 24);
/// Param Value (RW, ASCII token text, NUL-padded).
pub const PARAM_VALUE: Reg = reg(184, 16);
/// Param Op (RW, [`ParamOp`]; a write runs it).
pub const PARAM_OP: Reg = reg(200, 1);
/// Param Status (R, [`ParamStatus`]).
pub const PARAM_STATUS: Reg = reg(201, 1);
/// Param Index (RW, u16; op 3's parameter).
pub const PARAM_INDEX: Reg = reg(202, 2);
/// Param Count (R, u16).
pub const PARAM_COUNT: Reg = reg(204, 2);

/// The status registers as one block, State through Supply Voltage: what a master reads in one
/// READ ([`StatusBlock::decode`]).
pub const STATUS_BLOCK: Reg = reg(128, 24);

/// Every register, in address order.
pub const REGISTERS: [Reg; 30] = [
    MODEL_NUMBER,
    FIRMWARE_VERSION,
    ID,
    MODE,
    VELOCITY_X,
    VELOCITY_Y,
    YAW_RATE,
    HEARTBEAT,
    STEP_ENTRY,
    STATE,
    SUPPORT_FOOT,
    STEP_COUNT,
    ZMP_X,
    ZMP_Y,
    ZMP_VALID,
    STOP_CODE,
    FAULT_KIND,
    STEP_LIST,
    WALK_VX,
    WALK_VY,
    WALK_YAW,
    COMMAND_COUNT,
    SERVO_STIFFNESS,
    SUPPLY_VOLTAGE,
    PARAM_KEY,
    PARAM_VALUE,
    PARAM_OP,
    PARAM_STATUS,
    PARAM_INDEX,
    PARAM_COUNT,
];

/// The writable registers.
pub const WRITABLE: [Reg; 10] = [
    MODE,
    VELOCITY_X,
    VELOCITY_Y,
    YAW_RATE,
    HEARTBEAT,
    STEP_ENTRY,
    PARAM_KEY,
    PARAM_VALUE,
    PARAM_OP,
    PARAM_INDEX,
];

crate::codes::wire_codes! {
    /// What a write of Param Op asks for.
    pub enum ParamOp {
        /// The value of Param Key into Param Value.
        Get = 1,
        /// Param Value into the parameter of Param Key (between runs only).
        Set = 2,
        /// The key and the value of parameter number Param Index.
        GetByIndex = 3,
        /// The configuration in force into the board's store (between runs only).
        Save = 4,
    }
}

crate::codes::wire_codes! {
    /// The outcome of the last parameter op (Param Status).
    pub enum ParamStatus {
        /// Done (a get's text is in Param Value; a set is in force for the next run).
        Done = 0,
        /// Written, not served yet (the firmware serves it at its next tick).
        Pending = 1,
        /// No parameter has this key (or Param Index is beyond the last).
        UnknownKey = 2,
        /// The value does not parse (number, word) or the text is not ASCII.
        BadValue = 3,
        /// The value parses but is outside the parameter's domain.
        OutOfRange = 4,
        /// A set while a run is going: refused, nothing changed.
        Running = 5,
        /// The save failed (the board has no parameter store, or its write failed).
        StoreFailed = 6,
        /// Not in this board's build: the firmware answers every parameter op with it and
        /// changes nothing (the OpenCM 9.04: no flash for the parameter table and the store).
        Unsupported = 7,
    }
}

impl ParamStatus {
    /// In a few words.
    pub const fn reason(self) -> &'static str {
        match self {
            ParamStatus::Done => "done",
            ParamStatus::Pending => "pending",
            ParamStatus::UnknownKey => "unknown key",
            ParamStatus::BadValue => "bad value",
            ParamStatus::OutOfRange => "out of range",
            ParamStatus::Running => "refused while a run is going",
            ParamStatus::StoreFailed => "the store failed",
            ParamStatus::Unsupported => "not in this board's build",
        }
    }
}

/// The configuration a parameter op is served against.
pub enum ParamAccess<'a> {
    /// Between runs: sets apply to the next run's configuration.
    Settable(&'a mut crate::Config),
    /// A run is going: gets only.
    ReadOnly(&'a crate::Config),
}

/// What the higher level asks for (the Mode register).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mode {
    /// 0: torque off (the run ends).
    TorqueOff,
    /// 1: stand (walking slows to a stop through the acceleration limits, then stands).
    #[default]
    Stand,
    /// 2: walk at the commanded velocity (and the step list first, if any).
    Walk,
    /// 3: stop: like stand, the velocity registers are cleared.
    Stop,
}

impl Mode {
    /// The wire value.
    pub const fn code(self) -> u8 {
        match self {
            Mode::TorqueOff => 0,
            Mode::Stand => 1,
            Mode::Walk => 2,
            Mode::Stop => 3,
        }
    }

    /// From the wire value.
    pub const fn from_code(c: u8) -> Option<Self> {
        match c {
            0 => Some(Mode::TorqueOff),
            1 => Some(Mode::Stand),
            2 => Some(Mode::Walk),
            3 => Some(Mode::Stop),
            _ => None,
        }
    }
}

/// What the firmware is doing (the State register).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum PortState {
    /// 0: starting up (probe, ramp to the initial pose).
    #[default]
    Starting,
    /// 1: standing, ready for commands.
    Standing,
    /// 2: walking.
    Walking,
    /// 3: stopping (the last steps to standing; a supervisor stop's lowering and hold).
    Stopping,
    /// 4: stopped: torque off (see Stop Code). With `wait_enable` the firmware then waits for
    /// the operator's enable, as in Waiting.
    Stopped,
    /// 5: torque off since power-on, waiting for the operator's enable (a Mode write of stand
    /// or walk; `wait_enable`).
    Waiting,
    /// 6: stopped by the operator, resting in the crouch with torque on (`rest`; see Stop
    /// Code): a second Mode write of torque off turns torque off (then 4); stand or walk is the
    /// enable (`wait_enable`).
    Resting,
}

impl PortState {
    /// The wire value.
    pub const fn code(self) -> u8 {
        match self {
            PortState::Starting => 0,
            PortState::Standing => 1,
            PortState::Walking => 2,
            PortState::Stopping => 3,
            PortState::Stopped => 4,
            PortState::Waiting => 5,
            PortState::Resting => 6,
        }
    }

    /// From the wire value.
    pub const fn from_code(c: u8) -> Option<Self> {
        match c {
            0 => Some(PortState::Starting),
            1 => Some(PortState::Standing),
            2 => Some(PortState::Walking),
            3 => Some(PortState::Stopping),
            4 => Some(PortState::Stopped),
            5 => Some(PortState::Waiting),
            6 => Some(PortState::Resting),
            _ => None,
        }
    }
}

/// One entry of the step list: the swing foot's displacement in the support foot's frame
/// beyond the nominal in-place step (mm, mm, mrad).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct StepEntry {
    /// Forward, mm.
    pub dx: i16,
    /// Leftward, mm.
    pub dy: i16,
    /// Heading change, mrad.
    pub dyaw: i16,
    /// The swinging foot: 1 left, 2 right.
    pub side: u8,
}

impl StepEntry {
    /// The entry's 8 bytes.
    pub fn to_bytes(&self) -> [u8; 8] {
        let [a, b] = self.dx.to_le_bytes();
        let [c, d] = self.dy.to_le_bytes();
        let [e, f] = self.dyaw.to_le_bytes();
        [a, b, c, d, e, f, self.side, 0]
    }

    /// From 8 bytes, checked ([`STEP_ENTRY_MAX`], side 1 or 2, last byte 0).
    pub fn from_bytes(b: &[u8]) -> Option<Self> {
        let &[a, b1, c, d, e, f, side, z] = b else {
            return None;
        };
        let s = StepEntry {
            dx: i16::from_le_bytes([a, b1]),
            dy: i16::from_le_bytes([c, d]),
            dyaw: i16::from_le_bytes([e, f]),
            side,
        };
        let within = [s.dx, s.dy, s.dyaw]
            .iter()
            .zip(STEP_ENTRY_MAX)
            .all(|(v, m)| v.unsigned_abs() <= m.unsigned_abs());
        (within && (side == 1 || side == 2) && z == 0).then_some(s)
    }
}

/// The status the firmware publishes each tick.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct PortStatus {
    /// State.
    pub state: PortState,
    /// Support foot: 0 both, 1 left, 2 right.
    pub support: u8,
    /// Steps finished since power-on.
    pub step_count: u16,
    /// Measured ZMP (m), if the feet measure one.
    pub zmp_m: Option<[f32; 2]>,
    /// The stop code (0 none): the supervisor's; the deadman's is added by the table
    /// ([`CommandTable::set_status`]).
    pub stop_code: u8,
    /// The last fault kind logged (0 none).
    pub fault_kind: u8,
    /// The walking velocity the feet step (m/s, m/s, rad/s).
    pub walk_velocity: [f32; 3],
    /// Explicit steps the walk took from the step list and has not stepped yet.
    pub queued: usize,
    /// The leg servos' stiffness the servo survey measured, at the present supply, in the
    /// register's unit 0.01 N·m/rad (0: not measured).
    pub servo_stiffness_cnm: u16,
    /// The leg servos' supply voltage last read, in their Present Input Voltage's unit 0.1 V
    /// (0: none read yet).
    pub supply_dv: u16,
}

/// The status block as a master reads it ([`STATUS_BLOCK`]), in wire units.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct StatusBlock {
    /// State (None: a code this contract does not know).
    pub state: Option<PortState>,
    /// Support foot: 0 both, 1 left, 2 right.
    pub support: u8,
    /// Steps finished since power-on.
    pub step_count: u16,
    /// Measured ZMP (mm, mm), if valid.
    pub zmp_mm: Option<[i16; 2]>,
    /// The stop record's code (0 none).
    pub stop_code: u8,
    /// The last fault record's kind (0 none).
    pub fault_kind: u8,
    /// Step List Length: entries not yet stepped.
    pub step_list: u8,
    /// The velocity the feet step (mm/s, mm/s, mrad/s).
    pub walk_velocity: [i16; 3],
    /// Accepted command writes (wraps).
    pub command_count: u16,
    /// The servo survey's stiffness, 0.01 N·m/rad (0: not measured).
    pub servo_stiffness: u16,
    /// The supply voltage, 0.1 V (0: not read yet).
    pub supply_dv: u16,
}

impl StatusBlock {
    /// Decodes the [`STATUS_BLOCK`] bytes read from the port; None when `block` is shorter.
    pub fn decode(block: &[u8]) -> Option<Self> {
        let at = |r: Reg| {
            let off = usize::from(r.addr.checked_sub(STATUS_BLOCK.addr)?);
            block.get(off..off + usize::from(r.len))
        };
        let u8_of = |r: Reg| at(r).and_then(|b| b.first().copied());
        let u16_of =
            |r: Reg| at(r).and_then(|b| Some(u16::from_le_bytes([*b.first()?, *b.get(1)?])));
        let i16_of = |r: Reg| u16_of(r).map(|v| i16::from_le_bytes(v.to_le_bytes()));
        let zmp = [i16_of(ZMP_X)?, i16_of(ZMP_Y)?];
        Some(StatusBlock {
            state: PortState::from_code(u8_of(STATE)?),
            support: u8_of(SUPPORT_FOOT)?,
            step_count: u16_of(STEP_COUNT)?,
            zmp_mm: (u8_of(ZMP_VALID)? != 0).then_some(zmp),
            stop_code: u8_of(STOP_CODE)?,
            fault_kind: u8_of(FAULT_KIND)?,
            step_list: u8_of(STEP_LIST)?,
            walk_velocity: [i16_of(WALK_VX)?, i16_of(WALK_VY)?, i16_of(WALK_YAW)?],
            command_count: u16_of(COMMAND_COUNT)?,
            servo_stiffness: u16_of(SERVO_STIFFNESS)?,
            supply_dv: u16_of(SUPPLY_VOLTAGE)?,
        })
    }
}

/// Velocity limits of the wire (mm/s, mm/s, mrad/s): the default command limits.
pub const VELOCITY_RANGE: [(i16, i16); 3] = [
    (
        -((CommandLimits::DEFAULT.vx_backward * 1000.0) as i16),
        (CommandLimits::DEFAULT.vx_forward * 1000.0) as i16,
    ),
    (
        -((CommandLimits::DEFAULT.vy * 1000.0) as i16),
        (CommandLimits::DEFAULT.vy * 1000.0) as i16,
    ),
    (
        -((CommandLimits::DEFAULT.yaw_rate * 1000.0) as i16),
        (CommandLimits::DEFAULT.yaw_rate * 1000.0) as i16,
    ),
];

/// A float in SI units to the wire's milli-units, rounded half away from zero and saturated;
/// NaN and ±∞ → 0. Published every tick: the tests on the value's bits (±0, not finite), the
/// saturating `as i32` and the integer clamp cost no float compare (a library call each on
/// FPU-less cores).
pub fn milli_i16(v: f32) -> i16 {
    let bits = v.to_bits();
    if bits << 1 == 0 || !v.is_finite() {
        return 0;
    }
    gait_core::maths::fastmath::round_i32(v * 1000.0)
        .clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
}

/// The control table's memory and its access rules (the device side of the port).
#[derive(Clone, Debug)]
pub struct CommandTable {
    mem: [u8; TABLE_LEN],
    steps: heapless::Deque<StepEntry, STEP_LIST_LEN>,
    commands: u16,
    /// Steps the walk took from the list and has not stepped (published).
    queued: u8,
    /// The deadman stopped the walk and Mode was not written since.
    deadman: bool,
    /// Accepted writes of Mode (wraps).
    mode_writes: u16,
    /// A parameter op written and not served yet.
    param_op: Option<ParamOp>,
    /// A save taken and not answered yet.
    save: bool,
}

impl Default for CommandTable {
    fn default() -> Self {
        Self::new()
    }
}

fn span(r: Reg) -> core::ops::Range<usize> {
    usize::from(r.addr)..usize::from(r.addr) + usize::from(r.len)
}

/// The register holding byte `a`, if any.
fn register_of(a: usize) -> Option<Reg> {
    REGISTERS.iter().copied().find(|r| span(*r).contains(&a))
}

impl CommandTable {
    /// A fresh table: mode stand, velocity 0, state starting.
    pub fn new() -> Self {
        let mut t = CommandTable {
            mem: [0; TABLE_LEN],
            steps: heapless::Deque::new(),
            commands: 0,
            queued: 0,
            deadman: false,
            mode_writes: 0,
            param_op: None,
            save: false,
        };
        let count = u16::try_from(crate::params::PARAMS.len()).unwrap_or(u16::MAX);
        t.put(PARAM_COUNT, &count.to_le_bytes());
        t.put(MODEL_NUMBER, &MODEL_NUMBER_VALUE.to_le_bytes());
        t.put(FIRMWARE_VERSION, &[FIRMWARE_VERSION_VALUE]);
        t.put(ID, &[PORT_ID]);
        t.put(MODE, &[Mode::Stand.code()]);
        t
    }

    fn put(&mut self, r: Reg, data: &[u8]) {
        if let Some(s) = self.mem.get_mut(span(r)) {
            for (d, v) in s.iter_mut().zip(data) {
                *d = *v;
            }
        }
    }

    fn get_i16(&self, r: Reg) -> i16 {
        match self.mem.get(span(r)) {
            Some(&[a, b]) => i16::from_le_bytes([a, b]),
            _ => 0,
        }
    }

    /// READ access: `len` bytes at `addr` (Data Range beyond the table).
    pub fn read(&self, addr: u16, len: u16) -> Result<&[u8], ErrorCode> {
        dxl::table::read(&self.mem, addr, len)
    }

    /// WRITE access with the checks of the module docs; all or nothing.
    pub fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), ErrorCode> {
        let start = usize::from(addr);
        let end = start + data.len();
        if data.is_empty() || end > TABLE_LEN {
            return Err(ErrorCode::DataRange);
        }
        // Every byte in a known register; every register covered whole; all writable.
        let mut a = start;
        while a < end {
            let r = register_of(a).ok_or(ErrorCode::DataRange)?;
            if !WRITABLE.contains(&r) {
                return Err(ErrorCode::Access);
            }
            let s = span(r);
            if s.start < start || s.end > end {
                return Err(ErrorCode::DataLength);
            }
            a = s.end;
        }
        let covered = |r: Reg| {
            let s = span(r);
            (s.start >= start && s.end <= end)
                .then(|| data.get(s.start - start..s.end - start))
                .flatten()
        };
        let mut mode = None;
        if let Some(&[m]) = covered(MODE) {
            mode = Some(Mode::from_code(m).ok_or(ErrorCode::DataRange)?);
        }
        for (r, (lo, hi)) in [VELOCITY_X, VELOCITY_Y, YAW_RATE]
            .iter()
            .zip(VELOCITY_RANGE)
        {
            if let Some(&[a, b]) = covered(*r) {
                let v = i16::from_le_bytes([a, b]);
                if v < lo || v > hi {
                    return Err(ErrorCode::DataRange);
                }
            }
        }
        let mut param_op = None;
        if let Some(&[o]) = covered(PARAM_OP) {
            param_op = Some(ParamOp::try_from(o).map_err(|_| ErrorCode::DataRange)?);
        }
        let mut entry = None;
        if let Some(b) = covered(STEP_ENTRY) {
            entry = Some(StepEntry::from_bytes(b).ok_or(ErrorCode::DataRange)?);
            if self.steps.is_full() {
                return Err(ErrorCode::DataLimit);
            }
        }
        // Accepted: commit.
        if let Some(s) = self.mem.get_mut(start..end) {
            s.copy_from_slice(data);
        }
        if let Some(e) = entry {
            let _ = self.steps.push_back(e);
        }
        if mode == Some(Mode::Stop) {
            self.clear_command();
        }
        if mode.is_some() {
            self.deadman = false;
            self.mode_writes = self.mode_writes.wrapping_add(1);
        }
        if param_op.is_some() {
            self.param_op = param_op;
            self.put(PARAM_STATUS, &[ParamStatus::Pending.code()]);
        }
        self.commands = self.commands.wrapping_add(1);
        self.put(COMMAND_COUNT, &self.commands.to_le_bytes());
        self.put_step_list();
        Ok(())
    }

    /// Serves the parameter op written last, if any, against `cfg` (module docs "Parameters"):
    /// Param Status, and for a get Param Value (and Param Key), say how it went. Returns the
    /// status (`None`: no op was pending).
    pub fn serve_param(&mut self, cfg: ParamAccess<'_>) -> Option<ParamStatus> {
        let op = self.param_op.take()?;
        let status = self.param(op, cfg);
        self.put(PARAM_STATUS, &[status.code()]);
        Some(status)
    }

    fn param(&mut self, op: ParamOp, cfg: ParamAccess<'_>) -> ParamStatus {
        use crate::params::{find, ArgErrorKind, PARAMS};
        let param = match op {
            ParamOp::Save => {
                return match cfg {
                    ParamAccess::ReadOnly(_) => ParamStatus::Running,
                    ParamAccess::Settable(_) => {
                        self.save = true;
                        ParamStatus::Pending
                    }
                };
            }
            ParamOp::GetByIndex => {
                let i = usize::from(self.get_u16(PARAM_INDEX));
                let Some(p) = PARAMS.get(i) else {
                    return ParamStatus::UnknownKey;
                };
                self.put_text(PARAM_KEY, p.key);
                p
            }
            ParamOp::Get | ParamOp::Set => {
                let Some(key) = self.text(PARAM_KEY) else {
                    return ParamStatus::BadValue;
                };
                let Some(p) = find(key) else {
                    return ParamStatus::UnknownKey;
                };
                p
            }
        };
        let cfg: &crate::Config = match (op, cfg) {
            (ParamOp::Set, ParamAccess::ReadOnly(_)) => return ParamStatus::Running,
            (ParamOp::Set, ParamAccess::Settable(c)) => {
                let Some(v) = self.text(PARAM_VALUE) else {
                    return ParamStatus::BadValue;
                };
                // Parsed (and range-checked) before anything is set: a refused value changes
                // nothing.
                return match param.parse(v).and_then(|_| param.apply(c, v)) {
                    Ok(()) => ParamStatus::Done,
                    Err(ArgErrorKind::OutOfRange) => ParamStatus::OutOfRange,
                    Err(ArgErrorKind::UnknownKey) => ParamStatus::UnknownKey,
                    Err(_) => ParamStatus::BadValue,
                };
            }
            (_, ParamAccess::Settable(c)) => c,
            (_, ParamAccess::ReadOnly(c)) => c,
        };
        let mut text: heapless::String<{ PARAM_VALUE.len as usize }> = heapless::String::new();
        let written = match param.value(cfg) {
            Some(v) => param.write_value(v, &mut text),
            None => Ok(()),
        };
        if written.is_err() {
            // Longer than the register: the text would be cut, so none is given.
            text.clear();
        }
        self.put_text(PARAM_VALUE, &text);
        ParamStatus::Done
    }

    /// Answers the parameter op written last, if any, with `status` without serving it (Param
    /// Key and Param Value untouched): a build without the parameters answers
    /// [`ParamStatus::Unsupported`]. Returns the status (`None`: no op was pending).
    pub fn answer_param(&mut self, status: ParamStatus) -> Option<ParamStatus> {
        self.param_op.take()?;
        self.put(PARAM_STATUS, &[status.code()]);
        Some(status)
    }

    /// A save the firmware must run now (taken once; Param Status stays pending until
    /// [`CommandTable::finish_save`]).
    pub fn take_save(&mut self) -> bool {
        core::mem::take(&mut self.save)
    }

    /// Answers a save: done, or [`ParamStatus::StoreFailed`].
    pub fn finish_save(&mut self, saved: bool) {
        let s = if saved {
            ParamStatus::Done
        } else {
            ParamStatus::StoreFailed
        };
        self.put(PARAM_STATUS, &[s.code()]);
    }

    /// The ASCII text of a text register up to its first NUL (`None`: not ASCII).
    fn text(&self, r: Reg) -> Option<&str> {
        let bytes = self.mem.get(span(r))?;
        let n = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
        let t = bytes.get(..n)?;
        if !t.is_ascii() {
            return None;
        }
        core::str::from_utf8(t).ok()
    }

    /// Writes `t` into a text register, NUL-padded (cut to the register).
    fn put_text(&mut self, r: Reg, t: &str) {
        if let Some(m) = self.mem.get_mut(span(r)) {
            m.fill(0);
            for (d, b) in m.iter_mut().zip(t.bytes()) {
                *d = b;
            }
        }
    }

    fn get_u16(&self, r: Reg) -> u16 {
        match self.mem.get(span(r)) {
            Some(&[a, b]) => u16::from_le_bytes([a, b]),
            _ => 0,
        }
    }

    /// The commanded mode.
    pub fn mode(&self) -> Mode {
        self.mem
            .get(usize::from(MODE.addr))
            .and_then(|&m| Mode::from_code(m))
            .unwrap_or(Mode::Stand)
    }

    /// Velocity registers 0 and the step list empty (Mode = stop's effect).
    fn clear_command(&mut self) {
        for r in [VELOCITY_X, VELOCITY_Y, YAW_RATE] {
            self.put(r, &[0, 0]);
        }
        self.steps.clear();
        self.put_step_list();
    }

    /// The deadman's stop, from the firmware's side: what an accepted Mode = stop does (Mode 3,
    /// velocity 0, the step list emptied), but not a command write (Command Count unchanged);
    /// Stop Code then reads [`crate::StopCode::Deadman`] until a master writes Mode.
    pub fn deadman_stop(&mut self) {
        self.put(MODE, &[Mode::Stop.code()]);
        self.clear_command();
        self.deadman = true;
    }

    /// True after [`CommandTable::deadman_stop`] until a master writes Mode.
    pub fn deadman_stopped(&self) -> bool {
        self.deadman
    }

    /// Sets the mode from the firmware's side (after torque off, or to clear a stop).
    pub fn set_mode(&mut self, m: Mode) {
        self.put(MODE, &[m.code()]);
    }

    /// The commanded velocity in SI units (m/s, m/s, rad/s; finite, within the limits);
    /// zero unless the mode is [`Mode::Walk`].
    pub fn velocity(&self) -> WalkCommand<f32> {
        if self.mode() != Mode::Walk {
            return WalkCommand {
                vx: 0.0,
                vy: 0.0,
                yaw_rate: 0.0,
            };
        }
        WalkCommand {
            vx: f32::from(self.get_i16(VELOCITY_X)) / 1000.0,
            vy: f32::from(self.get_i16(VELOCITY_Y)) / 1000.0,
            yaw_rate: f32::from(self.get_i16(YAW_RATE)) / 1000.0,
        }
    }

    /// The command registers in their wire units: mode code, vx, vy (mm/s), yaw rate (mrad/s).
    pub fn raw_command(&self) -> [i32; 4] {
        let mode = self.mem.get(usize::from(MODE.addr)).copied().unwrap_or(0);
        [
            i32::from(mode),
            i32::from(self.get_i16(VELOCITY_X)),
            i32::from(self.get_i16(VELOCITY_Y)),
            i32::from(self.get_i16(YAW_RATE)),
        ]
    }

    /// Takes the oldest step-list entry.
    pub fn take_step(&mut self) -> Option<StepEntry> {
        let s = self.steps.pop_front();
        self.put_step_list();
        s
    }

    /// Accepted command writes so far (wraps).
    pub fn command_count(&self) -> u16 {
        self.commands
    }

    /// Accepted writes of Mode so far (wraps): a master's explicit mode, even the same value.
    pub fn mode_writes(&self) -> u16 {
        self.mode_writes
    }

    /// Publishes the State register alone (the rest of the status stays as last published).
    pub fn set_state(&mut self, s: PortState) {
        self.put(STATE, &[s.code()]);
    }

    /// Publishes the firmware's status in the status registers.
    pub fn set_status(&mut self, s: &PortStatus) {
        self.put(STATE, &[s.state.code()]);
        self.put(SUPPORT_FOOT, &[s.support]);
        self.put(STEP_COUNT, &s.step_count.to_le_bytes());
        let [zx, zy] = s.zmp_m.unwrap_or([0.0; 2]);
        self.put(ZMP_X, &milli_i16(zx).to_le_bytes());
        self.put(ZMP_Y, &milli_i16(zy).to_le_bytes());
        self.put(ZMP_VALID, &[u8::from(s.zmp_m.is_some())]);
        let stop = match s.stop_code {
            0 if self.deadman => crate::StopCode::Deadman.code(),
            c => c,
        };
        self.put(STOP_CODE, &[stop]);
        self.put(FAULT_KIND, &[s.fault_kind]);
        let [vx, vy, w] = s.walk_velocity;
        self.put(WALK_VX, &milli_i16(vx).to_le_bytes());
        self.put(WALK_VY, &milli_i16(vy).to_le_bytes());
        self.put(WALK_YAW, &milli_i16(w).to_le_bytes());
        self.put(SERVO_STIFFNESS, &s.servo_stiffness_cnm.to_le_bytes());
        self.put(SUPPLY_VOLTAGE, &s.supply_dv.to_le_bytes());
        self.queued = u8::try_from(s.queued).unwrap_or(u8::MAX);
        self.put_step_list();
    }

    /// Step List Length: the entries in the port and those the walk took but has not stepped.
    fn put_step_list(&mut self) {
        let n = u8::try_from(self.steps.len()).unwrap_or(u8::MAX);
        self.put(STEP_LIST, &[n.saturating_add(self.queued)]);
    }

    /// The published state.
    pub fn state(&self) -> PortState {
        self.mem
            .get(usize::from(STATE.addr))
            .and_then(|&s| PortState::from_code(s))
            .unwrap_or_default()
    }
}

/// The protocol's status for an error.
fn status_of(code: ErrorCode) -> StatusError {
    StatusError {
        alert: false,
        code: Some(code),
    }
}

/// The command port's device: the table plus the packet handling of one port.
#[derive(Clone, Debug, Default)]
pub struct CommandPort {
    /// The control table.
    pub table: CommandTable,
    decoder: Decoder<RX_PARAMS>,
}

impl CommandPort {
    /// A fresh port (table as [`CommandTable::new`]).
    pub fn new() -> Self {
        CommandPort {
            table: CommandTable::new(),
            decoder: Decoder::new(),
        }
    }

    /// Feeds one received byte; when it completes an instruction packet addressed to the
    /// port, executes it and returns the reply's length in `reply` (0 = no reply due).
    pub fn push(&mut self, byte: u8, reply: &mut [u8]) -> usize {
        let CommandPort { table, decoder } = self;
        match decoder.push(byte) {
            Some(Ok(p)) => handle(table, &p, reply),
            _ => 0,
        }
    }

    /// Feeds received bytes (at most `bytes.len()`); replies go to `out` through `send`.
    pub fn feed(&mut self, bytes: &[u8], mut send: impl FnMut(&[u8])) {
        let mut reply = [0u8; REPLY_MAX];
        for &b in bytes {
            let n = self.push(b, &mut reply);
            if let Some(r) = reply.get(..n).filter(|r| !r.is_empty()) {
                send(r);
            }
        }
    }
}

/// Executes one instruction packet on `table`; returns the reply's length in `reply` (0 = no
/// reply: not addressed to the port, or broadcast other than PING).
pub fn handle(table: &mut CommandTable, p: &Packet<'_>, reply: &mut [u8]) -> usize {
    let own = p.id == PORT_ID;
    if !own && p.id != BROADCAST_ID {
        return 0;
    }
    let status = |reply: &mut [u8], err: StatusError, data: &[u8]| {
        dxl::encode_status(reply, PORT_ID, err, data).unwrap_or(0)
    };
    let ins = match Instruction::parse(p) {
        Ok(i) => i,
        Err(ParseError::BadLength) if own => {
            return status(reply, status_of(ErrorCode::DataLength), &[])
        }
        Err(_) if own => return status(reply, status_of(ErrorCode::Instruction), &[]),
        Err(_) => return 0,
    };
    match ins {
        Instruction::Ping => {
            let [lo, hi] = MODEL_NUMBER_VALUE.to_le_bytes();
            status(reply, StatusError::OK, &[lo, hi, FIRMWARE_VERSION_VALUE])
        }
        Instruction::Read { addr, len } if own => match table.read(addr, len) {
            Ok(d) => status(reply, StatusError::OK, d),
            Err(e) => status(reply, status_of(e), &[]),
        },
        Instruction::Write { addr, data } => {
            let r = table.write(addr, data);
            if !own {
                return 0;
            }
            match r {
                Ok(()) => status(reply, StatusError::OK, &[]),
                Err(e) => status(reply, status_of(e), &[]),
            }
        }
        Instruction::SyncRead { addr, len, ids } if ids.contains(&PORT_ID) => {
            match table.read(addr, len) {
                Ok(d) => status(reply, StatusError::OK, d),
                Err(e) => status(reply, status_of(e), &[]),
            }
        }
        Instruction::SyncWrite(sw) => {
            if let Some(d) = sw.data_for(PORT_ID) {
                let _ = table.write(sw.addr, d);
            }
            0
        }
        Instruction::BulkRead(b) => match b.entries().find(|e| e.id == PORT_ID) {
            Some(e) => match table.read(e.addr, e.len) {
                Ok(d) => status(reply, StatusError::OK, d),
                Err(err) => status(reply, status_of(err), &[]),
            },
            None => 0,
        },
        Instruction::BulkWrite(b) => {
            if let Some(e) = b.entries().find(|e| e.id == PORT_ID) {
                let _ = table.write(e.addr, e.data);
            }
            0
        }
        _ if own => status(reply, status_of(ErrorCode::Instruction), &[]),
        _ => 0,
    }
}
