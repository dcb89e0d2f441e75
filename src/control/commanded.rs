//! Walking on command in the loop: the command port polled each tick (bounded: at most
//! [`RX_PER_TICK`] bytes, each reply sent at once), the commands logged as they change
//! (`CommandReceived` fault records), the online walk of gait-core
//! ([`gait_core::trajectory::online::OnlineWalk`]: standing, starting, walking, stopping) built from the
//! configured walk's timing and swing, its footsteps logged (`Footstep` fault records), and the
//! status registers published.
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
        let count = self.port.table.command_count();
        if count != self.count {
            self.count = count;
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
