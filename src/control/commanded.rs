//! Walking on command in the loop: the command port polled each tick (bounded: at most
//! [`RX_PER_TICK`] bytes, each reply sent at once), the commands logged as they change
//! (`CommandReceived` fault records), the online walk of gait-core
//! ([`gait_core::trajectory::online::OnlineWalk`]: standing, starting, walking, stopping) built from the
//! configured walk's timing and swing, its footsteps logged (`Footstep` fault records), and the
//! status registers published.
//!
//! **The command deadman** ([`CommandLink::deadman`]): in Mode = walk, with the online walk,
//! no valid command write (an accepted WRITE, SYNC WRITE or BULK WRITE: one that advances
//! Command Count; Heartbeat (72) is one that changes no command) for `deadman_ms` stops the
//! walk as a master's Mode = stop does (the velocity 0, the port's step list emptied) and also
//! drops the listed steps the walk took: the step under way lands, the generator's stop steps
//! close the feet, the robot stands (torque on). Logged as a `Deadman` fault record and the
//! command fields it changed (`CommandReceived`, so the host's replay sees the zero command);
//! Stop Code reads 13 until a master writes Mode. Never armed for the autostart plan.
//!
//! The online walk starts standing with the feet at (0, ±`step_width`), heading 0, the CoM at
//! rest on their midpoint at `z_c`; it steps with the configured walk's T, t1, t2 (after the
//! servo-speed check's stretch) and swing shape, the command limits of
//! [`gait_core::trajectory::command::CommandLimits::DEFAULT`]. `servo_lead` does not apply to it.

use gait_core::trajectory::command::{CommandLimits, WalkCommand};
use gait_core::trajectory::online::{
    ListedStep, OnlineParams, OnlineWalk, WalkMode, DEFAULT_ZMP_INSET, STEP_QUEUE_LEN,
};
use gait_core::trajectory::plan::SwingShape;
use gait_core::{GaitError, Place, Robot, Side, SupportPhase};
use walker_contract::codes::CommandField;
use walker_contract::command_port::{CommandPort, Mode, PortState, PortStatus, REPLY_MAX};
use walker_contract::footstep_log;

use crate::board::Board;
use crate::record::{FaultKind, LogWriter};
use crate::Config;

/// Bytes taken from the command port per tick at most.
pub const RX_PER_TICK: usize = 64;

/// The online walk of `cfg` (see the module docs).
// Out of line: its temporaries get a frame of their own, not the caller's (start-up
// stack: scripts/stack-depth.py, BENCHMARKS.md "RAM").
#[inline(never)]
pub fn online_walk(cfg: &Config, robot: &Robot) -> Result<OnlineWalk<f32>, GaitError> {
    let w = &cfg.walk;
    let swing = if cfg.swing_sinusoid {
        SwingShape::Sinusoid { height: w.h_z }
    } else {
        SwingShape::Cycloid {
            height: w.h_z,
            width: w.w_y,
        }
    };
    let p = OnlineParams {
        z_c: w.z_c,
        period: f64::from(period_us(cfg)) * 1e-6,
        t1: w.t1,
        t2: w.t2,
        half_width: w.step_width,
        swing,
        limits: CommandLimits::DEFAULT,
        dt: cfg.dt_s(),
        zmp_inset: DEFAULT_ZMP_INSET,
        heading_gain: f64::from(cfg.heading_gain),
        position_gain: f64::from(cfg.position_gain),
    };
    let y = w.step_width as f32;
    let feet = [
        Place {
            x: 0.0,
            y,
            yaw: 0.0,
        },
        Place {
            x: 0.0,
            y: -y,
            yaw: 0.0,
        },
    ];
    OnlineWalk::new(robot, p, feet)
}

/// The online walk's step period, µs: the configured (stretched) T rounded up to a whole µs, so
/// that the `Footstep` record (id 0) logging it gives the host the exact value.
pub fn period_us(cfg: &Config) -> i32 {
    let us = libm::ceil(cfg.walk.period * 1e6);
    if us.is_finite() && us > 0.0 && us < 1e9 {
        us as i32
    } else {
        0
    }
}

/// The command port in the loop.
pub struct CommandLink {
    /// The device (control table and decoder).
    pub port: CommandPort,
    logged: [i32; 4],
    count: u16,
    /// Time of the last valid command write seen (µs, the board's clock).
    last_write_us: u64,
    /// The runs log their parameters that differ from the defaults after their start-up
    /// record (`ParamValue` records; [`super::run_on_enable`]'s runs).
    pub log_params: bool,
    /// What the boot's load of the saved parameters found, logged (`ParamStore`) after the
    /// next start-up record.
    pub store_note: Option<walker_contract::param_store::StoreOutcome>,
}

impl Default for CommandLink {
    fn default() -> Self {
        Self::new()
    }
}

impl CommandLink {
    /// A fresh port: mode stand, velocity 0.
    pub fn new() -> Self {
        let port = CommandPort::new();
        let logged = port.table.raw_command();
        CommandLink {
            port,
            logged,
            count: 0,
            last_write_us: 0,
            log_params: false,
            store_note: None,
        }
    }

    /// Sets Mode from the firmware's side (the standby's torque off until the enable), taken as
    /// the logged command's mode: a master's next Mode write that differs is logged.
    pub fn set_mode(&mut self, m: Mode) {
        self.port.table.set_mode(m);
        if let Some(logged) = self.logged.first_mut() {
            *logged = i32::from(m.code());
        }
    }

    /// Reads what arrived (at most [`RX_PER_TICK`] bytes), answers each instruction, and logs
    /// the command fields that changed.
    pub fn poll<B: Board>(&mut self, board: &mut B, log: &mut LogWriter) {
        let mut rx = [0u8; RX_PER_TICK];
        let n = board.command_rx(&mut rx);
        let mut reply = [0u8; REPLY_MAX];
        for &b in rx.iter().take(n) {
            let len = self.port.push(b, &mut reply);
            if let Some(r) = reply.get(..len).filter(|r| !r.is_empty()) {
                board.command_tx(r);
            }
        }
        if self.note_writes(board.now_us()) {
            self.log_changes(board, log);
        }
    }

    /// Notes whether valid command writes came since the last call (Command Count moved):
    /// then `now_us` is the last write's time.
    fn note_writes(&mut self, now_us: u64) -> bool {
        let count = self.port.table.command_count();
        if count == self.count {
            return false;
        }
        self.count = count;
        self.last_write_us = now_us;
        true
    }

    /// Logs the command fields that changed since the last logged command
    /// (`CommandReceived`).
    fn log_changes<B: Board>(&mut self, board: &mut B, log: &mut LogWriter) {
        let now = board.now_us();
        let cmd = self.port.table.raw_command();
        for ((field, v), old) in CommandField::ALL.iter().zip(cmd).zip(self.logged.iter()) {
            if v != *old {
                let rec = super::fault(now, FaultKind::CommandReceived, field.code(), v);
                log.write(board, rec);
            }
        }
        self.logged = cmd;
    }

    /// Time since the last valid command write, µs, if the deadman is armed: Mode = walk.
    pub fn silent_us(&self, now_us: u64) -> Option<u64> {
        (self.mode() == Mode::Walk).then(|| now_us.saturating_sub(self.last_write_us))
    }

    /// The command deadman (see the module docs), checked after [`CommandLink::poll`]: armed
    /// in Mode = walk; with no valid command write for `limit_us` it stops the port's command
    /// ([`walker_contract::command_port::CommandTable::deadman_stop`]) and the walk's listed
    /// steps, logs it, and returns true (the tick it fires).
    pub fn deadman<B: Board>(
        &mut self,
        board: &mut B,
        log: &mut LogWriter,
        walk: &mut OnlineWalk<f32>,
        limit_us: u64,
    ) -> bool {
        let now = board.now_us();
        match self.silent_us(now) {
            Some(silent) if silent >= limit_us => {
                self.port.table.deadman_stop();
                walk.clear_steps();
                let ms = i32::try_from(silent / 1000).unwrap_or(i32::MAX);
                log.write(board, super::fault(now, FaultKind::Deadman, 0, ms));
                self.log_changes(board, log);
                crate::fw_log!(warn, "command deadman: no command write for {} ms", ms);
                true
            }
            _ => false,
        }
    }

    /// In Mode = walk, moves the port's step list into the online walk (while it has room):
    /// each entry becomes an explicit step (mm and mrad → m and rad).
    pub fn feed_steps(&mut self, walk: &mut OnlineWalk<f32>) {
        if self.mode() != Mode::Walk {
            return;
        }
        while walk.queued() < STEP_QUEUE_LEN {
            let Some(e) = self.port.table.take_step() else {
                return;
            };
            let side = if e.side == 1 { Side::Left } else { Side::Right };
            let d = [e.dx, e.dy, e.dyaw].map(|v| f32::from(v) * 0.001);
            walk.push_step(ListedStep { side, d });
        }
    }

    /// The commanded mode.
    pub fn mode(&self) -> Mode {
        self.port.table.mode()
    }

    /// The commanded velocity (zero unless the mode is walk).
    pub fn velocity(&self) -> WalkCommand<f32> {
        self.port.table.velocity()
    }

    /// Publishes the status.
    pub fn publish(&mut self, s: &PortStatus) {
        self.port.table.set_status(s);
    }
}

/// The port state of an online walk mode.
pub fn state_of(m: &WalkMode<f32>) -> PortState {
    match m {
        WalkMode::Standing(_) => PortState::Standing,
        WalkMode::Starting(_) | WalkMode::Walking(_) => PortState::Walking,
        WalkMode::Stopping(_) => PortState::Stopping,
    }
}

/// The Support Foot register's value of a phase: 0 both, 1 left, 2 right.
pub fn support_code(p: SupportPhase) -> u8 {
    match p {
        SupportPhase::Single(Side::Left) => 1,
        SupportPhase::Single(Side::Right) => 2,
        _ => 0,
    }
}

/// Logs a committed footstep as `Footstep` records (the contract's
/// [`walker_contract::footstep_log`]: the heading hold's correction δ if any, µrad; the
/// position hold's correction c if any, µm; an explicit step's travel if it was one, mm, mm,
/// mrad; the footprint x, y in µm and yaw in µrad).
pub fn log_footstep<B: Board>(
    board: &mut B,
    log: &mut LogWriter,
    side: Side,
    place: &Place<f32>,
    turn: f32,
    shift: [f32; 2],
    given: Option<[f32; 3]>,
) {
    let now = board.now_us();
    let scaled = |v: f32, k: f32| {
        let m = libm::roundf(v * k);
        if m.is_finite() {
            m as i32
        } else {
            0
        }
    };
    let micro = |v: f32| scaled(v, 1e6);
    footstep_log::encode_footstep(
        footstep_log::foot_code(side == Side::Left),
        [micro(place.x), micro(place.y), micro(place.yaw)],
        micro(turn),
        shift.map(micro),
        given.map(|d| d.map(|v| scaled(v, 1000.0))),
        |id, value| log.write(board, super::fault(now, FaultKind::Footstep, id, value)),
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use dxl::packet::BROADCAST_ID;
    use dxl::Instruction;
    use walker_contract::command_port::{HEARTBEAT, MODE, PORT_ID};

    /// The bytes of `ins` to `id`.
    fn packet(ins: Instruction<'_>, id: u8) -> Vec<u8> {
        let mut buf = [0u8; 64];
        let n = ins.encode(&mut buf, id).unwrap();
        buf[..n].to_vec()
    }

    /// Feeds `bytes` to the link's port at `now_us` as [`CommandLink::poll`] does.
    fn feed(link: &mut CommandLink, bytes: &[u8], now_us: u64) {
        link.port.feed(bytes, |_| {});
        link.note_writes(now_us);
    }

    const LIMIT: u64 = 500_000;

    fn due(link: &CommandLink, now_us: u64) -> bool {
        link.silent_us(now_us).is_some_and(|s| s >= LIMIT)
    }

    /// Armed in Mode = walk only: due `deadman_ms` after the last valid write (WRITE to the
    /// port's ID or broadcast, the Heartbeat included), not before; a READ, a PING or a
    /// rejected write does not reset it; Mode = stand / stop disarm it.
    #[test]
    fn the_deadman_is_due_deadman_ms_after_the_last_valid_write_in_mode_walk() {
        let mut l = CommandLink::new();
        let mode = |m: u8| {
            packet(
                Instruction::Write {
                    addr: MODE.addr,
                    data: &[m],
                },
                PORT_ID,
            )
        };
        let beat = |id: u8| {
            packet(
                Instruction::Write {
                    addr: HEARTBEAT.addr,
                    data: &[0x5A],
                },
                id,
            )
        };
        // Standing (Mode = stand, the power-on mode): never armed.
        assert_eq!(l.silent_us(10_000_000), None);
        feed(&mut l, &mode(2), 1_000_000);
        assert_eq!(l.silent_us(1_000_000), Some(0));
        assert!(!due(&l, 1_499_999));
        assert!(due(&l, 1_500_000));
        // A heartbeat resets it.
        feed(&mut l, &beat(PORT_ID), 1_300_000);
        assert!(!due(&l, 1_799_999));
        assert!(due(&l, 1_800_000));
        // So does a broadcast write (no reply).
        feed(&mut l, &beat(BROADCAST_ID), 1_700_000);
        assert!(!due(&l, 2_199_999));
        // Not a READ, a PING, a rejected write (mode 7: Data Range; State: Access).
        let read = packet(Instruction::Read { addr: 128, len: 20 }, PORT_ID);
        feed(&mut l, &read, 2_000_000);
        feed(&mut l, &packet(Instruction::Ping, PORT_ID), 2_000_000);
        feed(&mut l, &mode(7), 2_100_000);
        let state = Instruction::Write {
            addr: 128,
            data: &[1],
        };
        feed(&mut l, &packet(state, PORT_ID), 2_100_000);
        // Another device's write neither.
        feed(&mut l, &beat(PORT_ID + 1), 2_100_000);
        assert!(due(&l, 2_200_000));
        // Mode = stop, Mode = stand: disarmed however long the silence.
        for m in [3, 1] {
            feed(&mut l, &mode(m), 3_000_000);
            assert_eq!(l.silent_us(60_000_000), None, "mode {m}");
        }
        // Walk again: armed from that write.
        feed(&mut l, &mode(2), 4_000_000);
        assert!(!due(&l, 4_499_999) && due(&l, 4_500_000));
    }
}
