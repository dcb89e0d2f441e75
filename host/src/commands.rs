//! Command scripts for the firmware's command port (`walker fil --commands FILE`) and the
//! host's side of the port: a Dynamixel master over a byte stream (the project's `dxl` codec).
//!
//! A script is TOML: `[[command]]` tables, each with `t` (s, counted from the moment the
//! firmware reports it stands ready: State = standing) and either a velocity — `vx`, `vy` (m/s,
//! robot frame) and `vyaw` (rad/s), omitted ones 0 — or `stop = true`. Commands are sent in
//! order when the simulated (virtual) time reaches them: the velocity registers, then Mode =
//! walk (or Mode = stop). After the last command the driver waits until the firmware stands
//! again and sends Mode = torque off: the run ends (stop `Requested`). A last command
//! `torque_off = true` sends Mode = torque off at its time, walking or not (the firmware's
//! graded stop: it walks to a standstill, lowers the robot, then turns torque off).
//!
//! A script for a firmware that waits for the operator's enable (`wait_enable=1`) says when to
//! give it: top-level `enable_after = S` (s): the driver finds State = waiting, waits S s of
//! virtual time with no write, then writes Mode = stand (the enable) and goes on as above.
//!
//! Between commands the driver writes the port's Heartbeat register every
//! [`HEARTBEAT_EVERY_US`] of virtual time (the firmware's command deadman, `deadman_ms`,
//! 500 ms by default, stops a walk without valid command writes). A command with
//! `silence = S` (s) plays a lost master instead: from its `t` nothing is sent for S s of virtual
//! time (no write, no heartbeat, no read), then the status block is read once
//! ([`DriveReport::silences`]) and the script goes on.
//!
//! The firmware logs every command as it takes it (`CommandReceived`) and every footstep
//! (`Footstep`): [`replay_footsteps`] integrates the logged commands through the step
//! generator exactly as the firmware does (f32) — the check that the footsteps are the
//! commands' ([`FootstepCheck`]).

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use dxl::{Decoder, ErrorCode, Instruction, Status};
use gait_core::trajectory::command::{CommandLimits, StepGenerator, WalkCommand};
use gait_core::{Place, Robot, Side};
use serde::Deserialize;
use walker_contract::command_port::{self as port, Mode, PortState, PORT_ID, VELOCITY_RANGE};
use walker_contract::footstep_log::{self, FootstepLog};
use walker_contract::record::Record;

use crate::sim::transport::SimProgress;

/// The foot of a listed step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Foot {
    /// The left foot swings.
    Left,
    /// The right foot swings.
    Right,
}

/// One explicit step of a script's footstep list: the swing foot's travel beyond the in-place
/// step in the support foot's frame (the port's Step Entry in SI units).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptStep {
    /// The foot that swings.
    pub foot: Foot,
    /// Forward, m.
    #[serde(default)]
    pub dx: f64,
    /// Leftward, m.
    #[serde(default)]
    pub dy: f64,
    /// Heading change, rad.
    #[serde(default)]
    pub dyaw: f64,
}

impl ScriptStep {
    /// The port's Step Entry (mm, mm, mrad), checked against its ranges.
    pub fn entry(&self) -> Result<port::StepEntry, String> {
        let mut v = [0i16; 3];
        for ((o, x), m) in v
            .iter_mut()
            .zip([self.dx, self.dy, self.dyaw])
            .zip(port::STEP_ENTRY_MAX)
        {
            let r = (x * 1000.0).round();
            if !r.is_finite() || r.abs() > f64::from(m) {
                return Err(format!("step {self:?}: {x} beyond ±{m} (milli-units)"));
            }
            *o = r as i16;
        }
        Ok(port::StepEntry {
            dx: v[0],
            dy: v[1],
            dyaw: v[2],
            side: match self.foot {
                Foot::Left => 1,
                Foot::Right => 2,
            },
        })
    }
}

/// One command of a script.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptCommand {
    /// When, s after the firmware stood ready.
    pub t: f64,
    /// Forward velocity, m/s.
    #[serde(default)]
    pub vx: f64,
    /// Leftward velocity, m/s.
    #[serde(default)]
    pub vy: f64,
    /// Yaw rate, rad/s.
    #[serde(default)]
    pub vyaw: f64,
    /// Stop (Mode = stop) instead of a velocity.
    #[serde(default)]
    pub stop: bool,
    /// A footstep list (`steps = [{ foot = "left", dx = 0.03 }, …]`, at most
    /// [`port::STEP_LIST_LEN`]): written to the step list before the velocity and Mode = walk;
    /// walked first, then the velocity's steps (with velocity 0 the robot stops after them).
    #[serde(default)]
    pub steps: Vec<ScriptStep>,
    /// A lost master: send nothing for this long, s (no velocity, stop or steps beside it).
    #[serde(default)]
    pub silence: f64,
    /// Mode = torque off at `t` (the last command, alone): the run ends by the firmware's stop.
    #[serde(default)]
    pub torque_off: bool,
}

impl ScriptCommand {
    /// The velocity registers' values (mm/s, mm/s, mrad/s), checked against the port's ranges.
    pub fn wire(&self) -> Result<[i16; 3], String> {
        let mut out = [0i16; 3];
        for ((o, v), (lo, hi)) in out
            .iter_mut()
            .zip([self.vx, self.vy, self.vyaw])
            .zip(VELOCITY_RANGE)
        {
            let m = (v * 1000.0).round();
            if !m.is_finite() || m < f64::from(lo) || m > f64::from(hi) {
                return Err(format!(
                    "command at t = {} s: {v} outside {} ..= {} (milli-units)",
                    self.t, lo, hi
                ));
            }
            *o = m as i16;
        }
        Ok(out)
    }
}

/// A command script.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandScript {
    /// The commands, in time order.
    pub command: Vec<ScriptCommand>,
    /// The firmware waits for the enable (`wait_enable=1`): give it this long after it reports
    /// State = waiting, s.
    #[serde(default)]
    pub enable_after: Option<f64>,
}

impl CommandScript {
    /// Parses and checks a script (times finite, non-negative and increasing, none within a
    /// silence; velocities in the port's ranges; `stop` without a velocity; `silence` alone).
    pub fn parse(text: &str) -> Result<Self, String> {
        let s: CommandScript = toml::from_str(text).map_err(|e| e.to_string())?;
        if let Some(e) = s.enable_after {
            if !(e.is_finite() && e >= 0.0) {
                return Err(format!("enable_after = {e}: a time in s, ≥ 0"));
            }
        }
        let mut last = -1.0;
        // The end of the last silence: the next command comes after it.
        let mut after = 0.0;
        for c in &s.command {
            if !(c.t.is_finite() && c.t >= 0.0 && c.t > last) {
                return Err(format!("command times must increase from 0: t = {}", c.t));
            }
            if c.t < after {
                return Err(format!("command at t = {} s: within a silence", c.t));
            }
            if !(c.silence.is_finite() && c.silence >= 0.0) {
                return Err(format!("command at t = {} s: silence {}", c.t, c.silence));
            }
            if c.silence > 0.0
                && (c.stop || c.vx != 0.0 || c.vy != 0.0 || c.vyaw != 0.0 || !c.steps.is_empty())
            {
                return Err(format!(
                    "command at t = {} s: silence with a velocity, a stop or steps",
                    c.t
                ));
            }
            last = c.t;
            after = c.t + c.silence;
            c.wire()?;
            if c.stop && (c.vx != 0.0 || c.vy != 0.0 || c.vyaw != 0.0 || !c.steps.is_empty()) {
                return Err(format!(
                    "command at t = {} s: stop with a velocity or steps",
                    c.t
                ));
            }
            let alone = !c.stop
                && c.silence == 0.0
                && c.vx == 0.0
                && c.vy == 0.0
                && c.vyaw == 0.0
                && c.steps.is_empty();
            if c.torque_off && !(alone && std::ptr::eq(c, s.command.last().unwrap_or(c))) {
                return Err(format!(
                    "command at t = {} s: torque_off must be the last command, alone",
                    c.t
                ));
            }
            if c.steps.len() > port::STEP_LIST_LEN {
                return Err(format!(
                    "command at t = {} s: {} steps, the port holds {}",
                    c.t,
                    c.steps.len(),
                    port::STEP_LIST_LEN
                ));
            }
            for st in &c.steps {
                st.entry()?;
            }
        }
        Ok(s)
    }

    /// Reads a script file.
    pub fn read(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::parse(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Time of the last command, s.
    pub fn end(&self) -> f64 {
        self.command.last().map_or(0.0, |c| c.t)
    }
}

/// How many times [`PortMaster::transact`] sends an instruction that gets no reply.
pub const PORT_ATTEMPTS: usize = 3;

/// A byte stream a [`PortMaster`] talks on: a TCP connection (QEMU's UART3) or a serial port.
/// Reads must time out (a short read timeout), not block for ever.
pub trait PortStream: Read + Write + Send {}

impl<T: Read + Write + Send> PortStream for T {}

/// A status from the port: its error code (`None`: OK) and data.
type PortStatus = (Option<ErrorCode>, Vec<u8>);

/// A Dynamixel master on the command port's byte stream.
pub struct PortMaster {
    stream: Box<dyn PortStream>,
    decoder: Decoder<{ port::RX_PARAMS }>,
    /// Wall-clock reply timeout.
    pub timeout: Duration,
}

impl PortMaster {
    /// A master on a TCP connection (no Nagle delay, 20 ms read timeout).
    pub fn new(stream: TcpStream) -> Self {
        let _ = stream.set_nodelay(true);
        let _ = stream.set_read_timeout(Some(Duration::from_millis(20)));
        Self::on(Box::new(stream))
    }

    /// A master on a serial port (8N1, `baud`; the board's command UART).
    pub fn serial(path: &str, baud: u32) -> Result<Self, String> {
        let mut p = crate::capture::open_serial(path, baud)?;
        p.set_timeout(Duration::from_millis(20))
            .map_err(|e| format!("{path}: {e}"))?;
        Ok(Self::on(Box::new(p)))
    }

    /// A master on any stream whose reads time out.
    pub fn on(stream: Box<dyn PortStream>) -> Self {
        PortMaster {
            stream,
            decoder: Decoder::new(),
            timeout: Duration::from_secs(5),
        }
    }

    /// Waits up to `limit` until the port answers, and leaves no late reply on the way: the
    /// firmware answers its command port from its control loop only, so instructions sent
    /// during its start-up (probe, servo-speed check) queue up and are all answered at once
    /// when the loop starts — replies that must not pass for the next instruction's. So: PING
    /// (2 s per try, few queue up) until one is answered, drop bytes until the line is quiet
    /// for 0.5 s, then a READ of the ID register must come back with the port's ID (a late
    /// PING reply would not: it carries the model number).
    pub fn wait_ready(&mut self, limit: Duration) -> Result<(), String> {
        let start = Instant::now();
        let timeout = self.timeout;
        self.timeout = Duration::from_secs(2);
        let id = [PORT_ID];
        let ready = loop {
            if self.transact_once(Instruction::Ping).is_ok() {
                self.drain_until_quiet(Duration::from_millis(500));
                let read_id = Instruction::Read {
                    addr: port::ID.addr,
                    len: port::ID.len,
                };
                if matches!(self.transact_once(read_id), Ok((None, d)) if d == id) {
                    break Ok(());
                }
            }
            if start.elapsed() >= limit {
                break Err(format!("command port: not ready within {limit:?}"));
            }
            self.drain_until_quiet(Duration::from_millis(200));
        };
        self.timeout = timeout;
        ready
    }

    /// Reads and drops bytes until none came for `quiet` (at most 10 s), then restarts the
    /// decoder.
    fn drain_until_quiet(&mut self, quiet: Duration) {
        let start = Instant::now();
        let mut last = Instant::now();
        let mut buf = [0u8; 256];
        while last.elapsed() < quiet && start.elapsed() < Duration::from_secs(10) {
            match self.stream.read(&mut buf) {
                Ok(0) => break,
                Ok(_) => last = Instant::now(),
                Err(_) => {}
            }
        }
        self.decoder = Decoder::new();
    }

    /// READ of `len` bytes at `addr`, the status checked.
    pub fn read(&mut self, addr: u16, len: u16) -> Result<Vec<u8>, String> {
        match self.transact(Instruction::Read { addr, len })? {
            (None, d) if d.len() == usize::from(len) => Ok(d),
            (None, d) => Err(format!(
                "command port: READ {addr}: {} bytes, not {len}",
                d.len()
            )),
            (Some(e), _) => Err(format!("command port: READ {addr}: {e:?}")),
        }
    }

    /// The status block ([`port::STATUS_BLOCK`]) in one READ.
    pub fn status(&mut self) -> Result<port::StatusBlock, String> {
        let d = self.read(port::STATUS_BLOCK.addr, port::STATUS_BLOCK.len)?;
        port::StatusBlock::decode(&d).ok_or_else(|| "command port: short status block".into())
    }

    /// Sends one instruction to the port and waits for its status: the error code (None =
    /// OK) and the data. Without a reply within [`PortMaster::timeout`] the instruction is sent
    /// again (the decoder restarted), up to [`PORT_ATTEMPTS`] times in all: every instruction
    /// the driver sends (READ, WRITE of a register to a value) can be repeated.
    pub fn transact(
        &mut self,
        ins: Instruction<'_>,
    ) -> Result<(Option<ErrorCode>, Vec<u8>), String> {
        let mut last = String::new();
        for _ in 0..PORT_ATTEMPTS {
            match self.transact_once(ins) {
                Err(e) if e.ends_with("no reply") => {
                    self.decoder = Decoder::new();
                    last = e;
                }
                other => return other,
            }
        }
        Err(format!("{last} ({PORT_ATTEMPTS} attempts)"))
    }

    fn transact_once(
        &mut self,
        ins: Instruction<'_>,
    ) -> Result<(Option<ErrorCode>, Vec<u8>), String> {
        self.send(ins)?;
        // The data length an OK status of this instruction carries: an OK status of another
        // length is the late reply to an earlier instruction (one sent again after its
        // timeout) and is skipped, not taken for this one's.
        let expect = match ins {
            Instruction::Ping => Some(3),
            Instruction::Read { len, .. } => Some(usize::from(len)),
            Instruction::Write { .. } => Some(0),
            _ => None,
        };
        let start = Instant::now();
        while start.elapsed() < self.timeout {
            if let Some((code, data)) = self.read_status()? {
                let late = code.is_none() && expect.is_some_and(|n| n != data.len());
                if !late {
                    return Ok((code, data));
                }
            }
        }
        Err("command port: no reply".into())
    }

    /// Encodes `ins` for the port and writes it.
    fn send(&mut self, ins: Instruction<'_>) -> Result<(), String> {
        let mut buf = [0u8; 600];
        let n = ins
            .encode(&mut buf, PORT_ID)
            .map_err(|e| format!("{e:?}"))?;
        self.stream
            .write_all(buf.get(..n).unwrap_or(&[]))
            .map_err(|e| format!("command port: {e}"))
    }

    /// Reads one byte (or times out: the stream's short read timeout) into the decoder; the
    /// status it completes, if any: (error code, data).
    fn read_status(&mut self) -> Result<Option<PortStatus>, String> {
        let mut byte = [0u8; 1];
        match self.stream.read(&mut byte) {
            Ok(0) => Err("command port closed".into()),
            Ok(_) => match self.decoder.push(byte[0]) {
                Some(Ok(p)) => {
                    let s = Status::from_packet(&p).map_err(|e| format!("{e:?}"))?;
                    Ok(Some((s.error.code, s.data.to_vec())))
                }
                _ => Ok(None),
            },
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(format!("command port: {e}")),
        }
    }

    /// WRITE, the status checked.
    pub fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), String> {
        match self.transact(Instruction::Write { addr, data })? {
            (None, _) => Ok(()),
            (Some(e), _) => Err(format!("command port: WRITE {addr}: {e:?}")),
        }
    }

    /// WRITEs sent one every `every` without waiting for their statuses (a master streaming
    /// commands at a fixed rate); the statuses are read as they come, and for up to
    /// [`PortMaster::timeout`] after the last send. Returns how many came back OK (an error
    /// status ends it with the write's index).
    pub fn write_paced(
        &mut self,
        writes: &[(u16, &[u8])],
        every: Duration,
    ) -> Result<usize, String> {
        let start = Instant::now();
        let mut ok = 0;
        for (k, &(addr, data)) in writes.iter().enumerate() {
            self.send(Instruction::Write { addr, data })?;
            let due = start + every * (k as u32 + 1);
            let last = k + 1 == writes.len();
            let until = if last {
                Instant::now() + self.timeout
            } else {
                due
            };
            while Instant::now() < until && !(last && ok == writes.len()) {
                match self.read_status()? {
                    Some((Some(e), _)) => {
                        return Err(format!("command port: paced WRITE {k}: {e:?}"))
                    }
                    Some((None, _)) => ok += 1,
                    None => {}
                }
            }
        }
        Ok(ok)
    }

    /// The State register.
    pub fn state(&mut self) -> Result<Option<PortState>, String> {
        let (e, d) = self.transact(Instruction::Read {
            addr: port::STATE.addr,
            len: 1,
        })?;
        match (e, d.first()) {
            (None, Some(&s)) => Ok(PortState::from_code(s)),
            _ => Err("command port: READ State failed".into()),
        }
    }
}

/// How often the driver writes Heartbeat between commands, virtual µs: well under the
/// firmware's default command deadman (500 ms).
pub const HEARTBEAT_EVERY_US: u64 = 100_000;

/// A silence of the script (a lost master): when the driver last wrote before it and the status
/// block it read after it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Silence {
    /// Virtual time of the last valid write before the silence (its reply), µs.
    pub last_write_us: u64,
    /// Virtual time the silence ended, µs.
    pub end_us: u64,
    /// The status block read after the silence.
    pub status: port::StatusBlock,
}

/// What the driver did: the virtual time the firmware stood ready, and when each command was
/// sent (virtual µs).
#[derive(Clone, Debug, Default)]
pub struct DriveReport {
    /// Virtual time of standing ready, µs.
    pub ready_us: u64,
    /// Virtual time each command was sent, µs.
    pub sent_us: Vec<u64>,
    /// The script's silences, in order.
    pub silences: Vec<Silence>,
    /// With `enable_after`: virtual time the firmware was first seen waiting, and the enable's
    /// write, µs.
    pub enable: Option<(u64, u64)>,
}

/// Drives a script on the port (see the module docs); `progress` is the simulator's virtual
/// clock; `quit` aborts.
pub fn drive(
    master: &mut PortMaster,
    script: &CommandScript,
    progress: &SimProgress,
    quit: &AtomicBool,
) -> Result<DriveReport, String> {
    let now = || progress.time_us.load(Ordering::Relaxed);
    let wait_state = |m: &mut PortMaster, want: PortState| -> Result<(), String> {
        loop {
            if quit.load(Ordering::Relaxed) {
                return Err("aborted".into());
            }
            if m.state()? == Some(want) {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    master.wait_ready(Duration::from_secs(120))?;
    let mut enable = None;
    if let Some(after) = script.enable_after {
        wait_state(master, PortState::Waiting)?;
        let seen = now();
        while now() < seen + (after * 1e6) as u64 {
            if quit.load(Ordering::Relaxed) {
                return Err("aborted".into());
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        master.write(port::MODE.addr, &[Mode::Stand.code()])?;
        enable = Some((seen, now()));
    }
    wait_state(master, PortState::Standing)?;
    let mut rep = DriveReport {
        ready_us: now(),
        sent_us: Vec::new(),
        silences: Vec::new(),
        enable,
    };
    let mut last_write = now();
    // Waits until virtual time `until`, writing Heartbeat every HEARTBEAT_EVERY_US.
    let wait_beating =
        |m: &mut PortMaster, until: u64, last_write: &mut u64| -> Result<(), String> {
            while now() < until {
                if quit.load(Ordering::Relaxed) {
                    return Err("aborted".into());
                }
                if now() >= last_write.saturating_add(HEARTBEAT_EVERY_US) {
                    m.write(port::HEARTBEAT.addr, &[0])?;
                    *last_write = now();
                }
                std::thread::sleep(Duration::from_millis(2));
            }
            Ok(())
        };
    for c in &script.command {
        let at = rep.ready_us + (c.t * 1e6) as u64;
        wait_beating(master, at, &mut last_write)?;
        rep.sent_us.push(now());
        if c.silence > 0.0 {
            let end = now() + (c.silence * 1e6) as u64;
            while now() < end {
                if quit.load(Ordering::Relaxed) {
                    return Err("aborted".into());
                }
                std::thread::sleep(Duration::from_millis(2));
            }
            rep.silences.push(Silence {
                last_write_us: last_write,
                end_us: now(),
                status: master.status()?,
            });
            continue;
        }
        if c.torque_off {
            master.write(port::MODE.addr, &[Mode::TorqueOff.code()])?;
            end_waiting(master, script)?;
            return Ok(rep);
        }
        if c.stop {
            master.write(port::MODE.addr, &[Mode::Stop.code()])?;
        } else {
            for st in &c.steps {
                master.write(port::STEP_ENTRY.addr, &st.entry()?.to_bytes())?;
            }
            let w = c.wire()?;
            let mut data = Vec::new();
            for v in w {
                data.extend_from_slice(&v.to_le_bytes());
            }
            master.write(port::VELOCITY_X.addr, &data)?;
            master.write(port::MODE.addr, &[Mode::Walk.code()])?;
        }
        last_write = now();
    }
    // Past the last command: wait for standing, then torque off ends the run.
    let settle = now() + 1_000_000;
    wait_beating(master, settle, &mut last_write)?;
    // A walk command last (a footstep list under velocity 0) walks on in Mode = walk until it
    // stands: the heartbeats go on.
    while master.state()? != Some(PortState::Standing) {
        wait_beating(master, now() + 20_000, &mut last_write)?;
    }
    master.write(port::MODE.addr, &[Mode::TorqueOff.code()])?;
    end_waiting(master, script)?;
    Ok(rep)
}

/// After the script's torque off: a firmware that waits for the enable (`enable_after`) waits
/// again once stopped (resting in the crouch after an operator's stop: one more Mode = torque
/// off turns torque off); Mode = torque off while it waits with torque off ends it.
fn end_waiting(master: &mut PortMaster, script: &CommandScript) -> Result<(), String> {
    if script.enable_after.is_none() {
        return Ok(());
    }
    loop {
        match master.state()? {
            Some(PortState::Stopped) => break,
            Some(PortState::Resting) => {
                master.write(port::MODE.addr, &[Mode::TorqueOff.code()])?;
                while master.state()? == Some(PortState::Resting) {
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
            _ => std::thread::sleep(Duration::from_millis(20)),
        }
    }
    master.write(port::MODE.addr, &[Mode::TorqueOff.code()])
}

/// Spawns the driver on `stream` in a thread.
pub fn spawn_driver(
    stream: TcpStream,
    script: CommandScript,
    progress: Arc<SimProgress>,
    quit: Arc<AtomicBool>,
) -> std::thread::JoinHandle<Result<DriveReport, String>> {
    std::thread::spawn(move || {
        let mut m = PortMaster::new(stream);
        drive(&mut m, &script, &progress, &quit)
    })
}

/// The footsteps of a log against the logged commands integrated through the generator.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FootstepCheck {
    /// Footsteps logged.
    pub steps: usize,
    /// Footsteps that differ from the generator's (index, logged, expected; µm / µrad).
    pub mismatches: Vec<(usize, [i32; 3], [i32; 3])>,
    /// The feet after the last step (left, right), m and rad.
    pub feet: [Place<f32>; 2],
    /// The feet after the last step of the commands alone (the same steps without the heading
    /// hold's corrections): the commanded end pose, m and rad.
    pub commanded_feet: [Place<f32>; 2],
    /// The commanded path: the commanded feet's midpoint's travel summed over the steps, m.
    pub path: f64,
    /// The heading hold's corrections logged (requested δ), summed, rad.
    pub turned: f64,
}

/// The online walk's feet standing at power-on: (0, ±`half_width`), heading 0 (left, right).
pub fn standing_feet(half_width: f32) -> [Place<f32>; 2] {
    [
        Place {
            x: 0.0,
            y: half_width,
            yaw: 0.0,
        },
        Place {
            x: 0.0,
            y: -half_width,
            yaw: 0.0,
        },
    ]
}

/// Replays a log's `CommandReceived` and `Footstep` records through [`StepGenerator`] (f32,
/// the firmware's arithmetic; a footstep's logged heading-hold correction, id s·16 + 3, and
/// position-hold correction, ids s·16 + 7, 8, are passed to [`StepGenerator::next_step_held`])
/// for `robot`'s walk of CoM height `z_c` and half width `half_width`, with
/// the step period the firmware logged (`Footstep` id 0): a new generator at each start from
/// standing, first swing = the logged step's side.
pub fn replay_footsteps(
    records: &[Record],
    robot: &Robot,
    z_c: f64,
    half_width: f32,
) -> Result<FootstepCheck, String> {
    let mut log = FootstepLog::new();
    let mut feet = standing_feet(half_width);
    let mut gen: Option<StepGenerator<f32>> = None;
    let mut pure: Option<StepGenerator<f32>> = None;
    let mut pure_feet = feet;
    let mut out = FootstepCheck::default();
    let midpoint = |f: &[Place<f32>; 2]| {
        [
            0.5 * (f64::from(f[0].x) + f64::from(f[1].x)),
            0.5 * (f64::from(f[0].y) + f64::from(f[1].y)),
        ]
    };
    let mut mid = midpoint(&feet);
    for r in records {
        let Record::Fault(f) = r else { continue };
        let Some(logged) = log.push(f.kind, f.id, f.value) else {
            continue;
        };
        let side = if logged.foot == footstep_log::foot_code(true) {
            Side::Left
        } else {
            Side::Right
        };
        let period = (f64::from(log.period_us().unwrap_or(0)) * 1e-6) as f32;
        let new_gen = |feet| {
            StepGenerator::new(
                robot,
                z_c,
                CommandLimits::DEFAULT,
                half_width,
                period,
                feet,
                side,
            )
            .map_err(|e| format!("{e:?}"))
        };
        if gen.as_ref().is_none_or(|g| g.is_standing()) {
            gen = Some(new_gen(feet)?);
        }
        if pure.as_ref().is_none_or(|g| g.is_standing()) {
            pure = Some(new_gen(pure_feet)?);
        }
        let Some(g) = gen.as_mut() else { continue };
        let [mode, vx, vy, w] = logged.command;
        let c = if mode == i32::from(Mode::Walk.code()) {
            WalkCommand {
                vx: vx as f32 / 1000.0,
                vy: vy as f32 / 1000.0,
                yaw_rate: w as f32 / 1000.0,
            }
        } else {
            WalkCommand::zero()
        };
        // The firmware's conversion of the port's units (f32 · 0.001).
        let listed = logged.given.map(|d| d.map(|v| v as f32 * 0.001));
        let turn = (f64::from(logged.turn) * 1e-6) as f32;
        let shift = logged.shift.map(|v| (f64::from(v) * 1e-6) as f32);
        let s = match listed {
            Some(d) => g.next_step_given(d),
            None => g.next_step_held(&c, turn, shift).0,
        };
        out.turned += f64::from(turn);
        feet = g.feet();
        if let Some(p) = pure.as_mut() {
            match listed {
                Some(d) => p.next_step_given(d),
                None => p.next_step(&c),
            };
            pure_feet = p.feet();
        }
        let m = midpoint(&pure_feet);
        out.path += (m[0] - mid[0]).hypot(m[1] - mid[1]);
        mid = m;
        let want = [s.place.x, s.place.y, s.place.yaw].map(|v| (v * 1e6).round() as i32);
        if logged.place != want || s.side != side {
            out.mismatches.push((out.steps, logged.place, want));
        }
        out.steps += 1;
    }
    out.feet = feet;
    out.commanded_feet = pure_feet;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stream whose reads give `rx` (then time out) and whose writes are dropped.
    struct Scripted {
        rx: std::collections::VecDeque<u8>,
    }

    impl Read for Scripted {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            match (self.rx.pop_front(), buf.first_mut()) {
                (Some(b), Some(slot)) => {
                    *slot = b;
                    Ok(1)
                }
                _ => Err(std::io::ErrorKind::TimedOut.into()),
            }
        }
    }

    impl Write for Scripted {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// A port that answers every packet written to it with a status of `error`, and notes
    /// when each came.
    struct Answering {
        rx: std::collections::VecDeque<u8>,
        error: dxl::StatusError,
        sent: std::sync::Arc<std::sync::Mutex<Vec<Instant>>>,
    }

    impl Read for Answering {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            match (self.rx.pop_front(), buf.first_mut()) {
                (Some(b), Some(slot)) => {
                    *slot = b;
                    Ok(1)
                }
                _ => {
                    std::thread::sleep(Duration::from_millis(1));
                    Err(std::io::ErrorKind::TimedOut.into())
                }
            }
        }
    }

    impl Write for Answering {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.sent.lock().unwrap().push(Instant::now());
            let mut b = [0u8; 32];
            let n = dxl::instruction::encode_status(&mut b, PORT_ID, self.error, &[]).unwrap();
            self.rx.extend(&b[..n]);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// Paced WRITEs go out one every period, without waiting for their statuses, and every
    /// OK status is counted; an error status ends the stream with the write's index.
    #[test]
    fn paced_writes_go_out_at_their_rate_and_count_the_statuses() {
        let sent = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let mut m = PortMaster::on(Box::new(Answering {
            rx: Default::default(),
            error: dxl::StatusError::OK,
            sent: sent.clone(),
        }));
        m.timeout = Duration::from_millis(300);
        let data = 7i16.to_le_bytes();
        let writes: Vec<(u16, &[u8])> = (0..20)
            .map(|_| (port::VELOCITY_X.addr, &data[..]))
            .collect();
        let period = Duration::from_millis(10);
        let before = Instant::now();
        assert_eq!(m.write_paced(&writes, period).unwrap(), 20);
        let t = sent.lock().unwrap().clone();
        assert_eq!(t.len(), 20);
        // Never ahead of the schedule (write k not before k periods from the start; a loaded
        // machine only delays them, so this holds at any load).
        for (k, at) in t.iter().enumerate() {
            let earliest = before + period * k as u32;
            assert!(*at >= earliest, "write {k} {:?} early", earliest - *at);
        }
        let mut m = PortMaster::on(Box::new(Answering {
            rx: Default::default(),
            error: dxl::StatusError {
                alert: false,
                code: Some(ErrorCode::DataRange),
            },
            sent,
        }));
        let e = m
            .write_paced(&writes, Duration::from_millis(1))
            .unwrap_err();
        assert!(e.contains("paced WRITE 0: DataRange"), "{e}");
    }

    /// A late reply (the status of a WRITE sent again after its timeout) waiting on the line
    /// is not taken for the next READ's, nor a late READ reply for a WRITE's; an error status
    /// (no data) is still the READ's answer.
    #[test]
    fn a_late_reply_of_another_length_is_not_taken_for_this_instructions() {
        let status = |error: dxl::StatusError, data: &[u8]| {
            let mut b = [0u8; 64];
            let n = dxl::instruction::encode_status(&mut b, PORT_ID, error, data).unwrap();
            b[..n].to_vec()
        };
        let ok = dxl::StatusError::OK;
        let master = |bytes: Vec<u8>| {
            let mut m = PortMaster::on(Box::new(Scripted { rx: bytes.into() }));
            m.timeout = Duration::from_millis(200);
            m
        };
        let mut m = master([status(ok, &[]), status(ok, &[7])].concat());
        assert_eq!(m.read(201, 1), Ok(vec![7]));
        let mut m = master([status(ok, &[1, 2]), status(ok, &[])].concat());
        assert_eq!(m.write(200, &[1]), Ok(()));
        let range = dxl::StatusError {
            alert: false,
            code: Some(ErrorCode::DataRange),
        };
        let mut m = master(status(range, &[]));
        assert!(m.read(201, 1).unwrap_err().contains("DataRange"));
        // Only late replies: no answer at all.
        let mut m = master(status(ok, &[]));
        assert!(m.read(201, 1).unwrap_err().contains("no reply"));
    }

    /// Every shipped file in plans/ loads as what its name says: `commands-*.toml` a command
    /// script whose velocities fit the port, `run-*.toml` a run configuration (its own
    /// tests), every other one a checked plan.
    #[test]
    fn every_shipped_plan_and_command_script_loads() {
        let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../plans"));
        let mut seen = (0, 0);
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if !name.ends_with(".toml") || name.starts_with("run-") {
                continue;
            }
            if name.starts_with("commands-") {
                let s = CommandScript::read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
                for c in &s.command {
                    c.wire().unwrap_or_else(|e| panic!("{name}: {e}"));
                }
                seen.0 += 1;
            } else {
                crate::planfile::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
                seen.1 += 1;
            }
        }
        assert!(seen.0 >= 3 && seen.1 >= 7, "scripts, plans: {seen:?}");
    }

    #[test]
    fn parses_the_demo_script_and_refuses_bad_ones() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../plans/commands-demo.toml");
        let s = CommandScript::read(Path::new(path)).unwrap();
        assert_eq!(s.command.first().map(|c| c.t), Some(0.0));
        assert!(s.command.last().is_some_and(|c| c.stop));
        assert_eq!(s.command[1].wire(), Ok([50, 0, 0]), "0.05 m/s forward");
        assert!(CommandScript::parse("[[command]]\nt = 0\nvx = 0.5\n").is_err());
        assert!(CommandScript::parse("[[command]]\nt = 1\n[[command]]\nt = 0.5\n").is_err());
        assert!(CommandScript::parse("[[command]]\nt = 1\nstop = true\nvx = 0.01\n").is_err());
        assert!(CommandScript::parse("[[command]]\nt = 1\nspeed = 1\n").is_err());
        // Footstep lists: in the port's units, checked against its ranges and length.
        let l = CommandScript::parse(
            "[[command]]\nt = 1\nsteps = [{ foot = \"right\", dx = 0.03, dyaw = -0.1 }]\n",
        )
        .unwrap();
        assert_eq!(
            l.command[0].steps[0].entry(),
            Ok(port::StepEntry {
                dx: 30,
                dy: 0,
                dyaw: -100,
                side: 2
            })
        );
        assert!(CommandScript::parse(
            "[[command]]\nt = 1\nsteps = [{ foot = \"left\", dx = 0.09 }]\n"
        )
        .is_err());
        assert!(
            CommandScript::parse("[[command]]\nt = 1\nsteps = [{ foot = \"middle\" }]\n").is_err()
        );
        assert!(CommandScript::parse(
            "[[command]]\nt = 1\nstop = true\nsteps = [{ foot = \"left\" }]\n"
        )
        .is_err());
        // A silence: alone, finite, and the next command after it.
        let q = CommandScript::parse("[[command]]\nt = 1\nsilence = 2.0\n[[command]]\nt = 3\n")
            .unwrap();
        assert_eq!(q.command[0].silence, 2.0);
        assert!(CommandScript::parse("[[command]]\nt = 1\nsilence = 2.0\nvx = 0.05\n").is_err());
        assert!(CommandScript::parse("[[command]]\nt = 1\nsilence = -1.0\n").is_err());
        assert!(
            CommandScript::parse("[[command]]\nt = 1\nsilence = 2.0\n[[command]]\nt = 2.5\n")
                .is_err()
        );
        // Torque off: the last command, alone.
        let off = CommandScript::parse(
            "[[command]]\nt = 1\nvx = 0.05\n[[command]]\nt = 3\ntorque_off = true\n",
        )
        .unwrap();
        assert!(off.command[1].torque_off);
        assert!(CommandScript::parse(
            "[[command]]\nt = 1\ntorque_off = true\n[[command]]\nt = 3\n"
        )
        .is_err());
        assert!(
            CommandScript::parse("[[command]]\nt = 1\ntorque_off = true\nvx = 0.05\n").is_err()
        );
        let nine = ["{ foot = \"left\" }"; 9].join(", ");
        assert!(CommandScript::parse(&format!("[[command]]\nt = 1\nsteps = [{nine}]\n")).is_err());
    }
}
