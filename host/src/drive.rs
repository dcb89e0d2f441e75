//! `walker drive`: keyboard teleoperation of the walk through the firmware's command port.
//!
//! The keys change the commanded velocity in steps; each change is sent at once as one WRITE of
//! the three velocity registers (Velocity X, Y, Yaw Rate: mm/s, mm/s, mrad/s) and Mode = walk
//! (docs/command-port.md):
//!
//! | key | does |
//! |---|---|
//! | ↑ / w, ↓ / s | forward velocity ± [`VX_STEP`] mm/s |
//! | ← / a, → / d | yaw rate ± [`YAW_STEP`] mrad/s (← turns left, counter-clockwise) |
//! | q, e | sideways velocity ± [`VY_STEP`] mm/s (q left, e right) |
//! | space | stop: velocity 0, Mode = stop (the walk slows to standing) |
//! | r | ready: Mode = stand, the enable of a firmware that waits for one (`wait_enable`: at power-on and after a stop, State = waiting or stopped) |
//! | t | torque off (Mode = 0): the graded stop (to standing, lowered, then limp); it ends a `walker fil` run |
//! | Esc, x, Ctrl-C | quit: Mode = stop (with `--sim`, then torque off, which ends the run) |
//!
//! The commanded velocity is clamped to the port's range ([`VELOCITY_RANGE`]), so a key never
//! produces a write the port would refuse. A status line, redrawn every [`STATUS_EVERY`] from
//! one READ of the status block ([`port::STATUS_BLOCK`]), shows the state, support foot, step
//! count, the velocity the feet step (after the acceleration limits), the measured ZMP and the
//! stop code and last fault. Each refresh also writes the port's Heartbeat register (72): a
//! valid command write that changes no command, so the firmware's command deadman
//! (`deadman_ms`, 500 ms) stops the walk only when `walker drive` itself stalls or loses the
//! port (Stop Code 13 on the status line; a key walks again).
//!
//! [`Teleop`], [`status_line`] and [`session`] are free of the terminal (tested against the
//! contract's own control table); `walker drive` (cli.rs) reads the keys with `crossterm` in
//! raw mode and talks to a TCP port (`--connect`, `--sim`) or a serial port (`--serial`).

use std::time::{Duration, Instant};

use walker_contract::command_port::{self as port, Mode, PortState, StatusBlock, VELOCITY_RANGE};

use crate::commands::PortMaster;

/// Forward velocity change per key, mm/s.
pub const VX_STEP: i16 = 10;
/// Sideways velocity change per key, mm/s.
pub const VY_STEP: i16 = 10;
/// Yaw-rate change per key, mrad/s.
pub const YAW_STEP: i16 = 100;
/// How often the status line is refreshed.
pub const STATUS_EVERY: Duration = Duration::from_millis(100);

/// A key of the teleoperation (independent of the terminal library).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Key {
    /// ↑ or w.
    Forward,
    /// ↓ or s.
    Backward,
    /// ← or a.
    TurnLeft,
    /// → or d.
    TurnRight,
    /// q.
    SideLeft,
    /// e.
    SideRight,
    /// Space.
    Stop,
    /// r.
    Ready,
    /// t.
    TorqueOff,
    /// Esc, x or Ctrl-C.
    Quit,
}

impl Key {
    /// The key of a character typed (letters in either case), if it is one.
    pub fn from_char(c: char) -> Option<Key> {
        Some(match c.to_ascii_lowercase() {
            'w' => Key::Forward,
            's' => Key::Backward,
            'a' => Key::TurnLeft,
            'd' => Key::TurnRight,
            'q' => Key::SideLeft,
            'e' => Key::SideRight,
            ' ' => Key::Stop,
            'r' => Key::Ready,
            't' => Key::TorqueOff,
            'x' => Key::Quit,
            _ => return None,
        })
    }
}

/// What a key asks of the port.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    /// Write the velocity (mm/s, mm/s, mrad/s), then Mode = walk.
    Walk([i16; 3]),
    /// Mode = stop (the port clears the velocity).
    Stop,
    /// Velocity 0, then Mode = stand (the enable of a waiting firmware).
    Ready,
    /// Mode = torque off.
    TorqueOff,
    /// Leave the session.
    Quit,
    /// Nothing to send (the velocity was already at its limit).
    Nothing,
}

/// The teleoperation's commanded velocity (wire units: mm/s, mm/s, mrad/s).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Teleop {
    /// The commanded velocity.
    pub velocity: [i16; 3],
}

impl Teleop {
    /// Applies a key: the new velocity (clamped to [`VELOCITY_RANGE`]) and what to send.
    pub fn key(&mut self, k: Key) -> Action {
        let delta = match k {
            Key::Forward => (0, VX_STEP),
            Key::Backward => (0, -VX_STEP),
            Key::SideLeft => (1, VY_STEP),
            Key::SideRight => (1, -VY_STEP),
            Key::TurnLeft => (2, YAW_STEP),
            Key::TurnRight => (2, -YAW_STEP),
            Key::Stop => {
                self.velocity = [0; 3];
                return Action::Stop;
            }
            Key::Ready => {
                self.velocity = [0; 3];
                return Action::Ready;
            }
            Key::TorqueOff => {
                self.velocity = [0; 3];
                return Action::TorqueOff;
            }
            Key::Quit => return Action::Quit,
        };
        let (axis, d) = delta;
        let before = self.velocity;
        if let (Some(v), Some(&(lo, hi))) = (self.velocity.get_mut(axis), VELOCITY_RANGE.get(axis))
        {
            *v = v.saturating_add(d).clamp(lo, hi);
        }
        if self.velocity == before {
            Action::Nothing
        } else {
            Action::Walk(self.velocity)
        }
    }
}

/// The command port as the teleoperation sees it.
pub trait Link {
    /// WRITE `data` at `addr`, the status checked.
    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), String>;
    /// One READ of the status block.
    fn status(&mut self) -> Result<StatusBlock, String>;
}

impl Link for PortMaster {
    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), String> {
        PortMaster::write(self, addr, data)
    }
    fn status(&mut self) -> Result<StatusBlock, String> {
        PortMaster::status(self)
    }
}

/// Sends an action's writes (none for [`Action::Quit`] and [`Action::Nothing`]).
pub fn send(link: &mut dyn Link, a: Action) -> Result<(), String> {
    match a {
        Action::Walk(v) => {
            let mut data = [0u8; 6];
            for (chunk, x) in data.chunks_exact_mut(2).zip(v) {
                chunk.copy_from_slice(&x.to_le_bytes());
            }
            link.write(port::VELOCITY_X.addr, &data)?;
            link.write(port::MODE.addr, &[Mode::Walk.code()])
        }
        Action::Stop => link.write(port::MODE.addr, &[Mode::Stop.code()]),
        Action::Ready => {
            link.write(port::VELOCITY_X.addr, &[0; 6])?;
            link.write(port::MODE.addr, &[Mode::Stand.code()])
        }
        Action::TorqueOff => link.write(port::MODE.addr, &[Mode::TorqueOff.code()]),
        Action::Quit | Action::Nothing => Ok(()),
    }
}

/// The status line: the firmware's state and what it walks, against the command.
pub fn status_line(s: &StatusBlock, t: &Teleop) -> String {
    let state = match s.state {
        Some(PortState::Starting) => "starting",
        Some(PortState::Standing) => "standing",
        Some(PortState::Walking) => "walking",
        Some(PortState::Stopping) => "stopping",
        Some(PortState::Stopped) => "STOPPED",
        Some(PortState::Waiting) => "WAITING (r: enable)",
        Some(PortState::Resting) => "RESTING (t: torque off, r: enable)",
        None => "state ?",
    };
    let support = match s.support {
        0 => "both",
        1 => "left",
        2 => "right",
        _ => "?",
    };
    let [cx, cy, cw] = t.velocity;
    let [wx, wy, ww] = s.walk_velocity;
    let zmp = s.zmp_mm.map_or("ZMP -".to_string(), |[x, y]| {
        format!("ZMP ({x:+4}, {y:+4}) mm")
    });
    let mut line = format!(
        "{state:<8} support {support:<5} steps {:>4} | cmd {cx:+4} {cy:+4} mm/s {cw:+4} mrad/s | walk {wx:+4} {wy:+4} {ww:+4} | {zmp}",
        s.step_count
    );
    if s.supply_dv != 0 {
        line += &format!(" | supply {:.1} V", f64::from(s.supply_dv) * 0.1);
    }
    if s.servo_stiffness != 0 {
        line += &format!(
            " | servos {:.1} N·m/rad",
            f64::from(s.servo_stiffness) * 0.01
        );
    }
    if s.stop_code != 0 {
        line += &format!(" | stop code {}", s.stop_code);
    }
    if s.fault_kind != 0 {
        line += &format!(" | last fault {}", s.fault_kind);
    }
    line
}

/// How a session ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ended {
    /// The user quit (Mode = stop sent).
    Quit,
    /// Torque off was sent and the firmware then reported State = stopped, or its port closed
    /// (a run without `wait_enable` ends resting in the crouch: the last status line says).
    TorqueOff,
    /// The firmware reports it stopped (State = stopped).
    Stopped,
}

/// The teleoperation loop: waits up to [`STATUS_EVERY`] for a key (`next_key`), sends what it
/// asks, and shows the status line (`show`) at least every [`STATUS_EVERY`], each time followed
/// by a WRITE of Heartbeat (the command deadman's keep-alive). Ends on quit (after sending Mode
/// = stop) or when the firmware reports State = stopped. Torque off (`t`) does not end it: the
/// firmware walks to a standstill, lowers the robot and rests in the crouch with torque on
/// (State = resting); a second `t` turns torque off. After a `t` a port that stops answering
/// (the firmware's run ended) ends the session too.
pub fn session(
    link: &mut dyn Link,
    mut next_key: impl FnMut(Duration) -> Result<Option<Key>, String>,
    mut show: impl FnMut(&str),
) -> Result<Ended, String> {
    let mut t = Teleop::default();
    let mut shown: Option<Instant> = None;
    let mut off_sent = false;
    let ended = |off_sent: bool, e: String| {
        if off_sent {
            Ok(Ended::TorqueOff)
        } else {
            Err(e)
        }
    };
    loop {
        if shown.is_none_or(|s| s.elapsed() >= STATUS_EVERY) {
            let st = match link.status() {
                Ok(st) => st,
                Err(e) => return ended(off_sent, e),
            };
            show(&status_line(&st, &t));
            shown = Some(Instant::now());
            if st.state == Some(PortState::Stopped) {
                return Ok(if off_sent {
                    Ended::TorqueOff
                } else {
                    Ended::Stopped
                });
            }
            if let Err(e) = link.write(port::HEARTBEAT.addr, &[0]) {
                return ended(off_sent, e);
            }
        }
        let Some(k) = next_key(STATUS_EVERY)? else {
            continue;
        };
        let a = t.key(k);
        if let Err(e) = send(link, a) {
            return ended(off_sent, e);
        }
        match a {
            Action::Quit => {
                send(link, Action::Stop)?;
                return Ok(Ended::Quit);
            }
            Action::TorqueOff => {
                off_sent = true;
                shown = None;
            }
            _ => shown = None,
        }
    }
}

/// Polls the status until State = standing (or stopped, or waiting for the enable), at most
/// `limit`; the last status.
pub fn wait_standing(link: &mut dyn Link, limit: Duration) -> Result<StatusBlock, String> {
    let start = Instant::now();
    loop {
        let st = link.status()?;
        if matches!(
            st.state,
            Some(
                PortState::Standing | PortState::Stopped | PortState::Waiting | PortState::Resting
            )
        ) || start.elapsed() >= limit
        {
            return Ok(st);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The keys, one line (printed before the session).
pub const HELP: &str = "keys: ↑/w ↓/s forward ±10 mm/s, ←/a →/d turn ±100 mrad/s, q/e side-step ±10 mm/s, space stop, r ready (enable), t torque off (the robot rests in the crouch; t again: off), Esc/x/Ctrl-C quit";

/// The key of a terminal key event (crossterm), if it is one.
pub fn key_of(
    code: crossterm::event::KeyCode,
    mods: crossterm::event::KeyModifiers,
) -> Option<Key> {
    use crossterm::event::{KeyCode, KeyModifiers};
    match code {
        KeyCode::Up => Some(Key::Forward),
        KeyCode::Down => Some(Key::Backward),
        KeyCode::Left => Some(Key::TurnLeft),
        KeyCode::Right => Some(Key::TurnRight),
        KeyCode::Esc => Some(Key::Quit),
        KeyCode::Char('c') if mods.contains(KeyModifiers::CONTROL) => Some(Key::Quit),
        KeyCode::Char(c) => Key::from_char(c),
        _ => None,
    }
}

/// The next key typed in the terminal within `wait` (key presses and repeats; other events
/// are skipped).
pub fn terminal_key(wait: Duration) -> Result<Option<Key>, String> {
    use crossterm::event::{self, Event, KeyEventKind};
    if !event::poll(wait).map_err(|e| format!("terminal: {e}"))? {
        return Ok(None);
    }
    match event::read().map_err(|e| format!("terminal: {e}"))? {
        Event::Key(k) if k.kind != KeyEventKind::Release => Ok(key_of(k.code, k.modifiers)),
        _ => Ok(None),
    }
}

/// The terminal in raw mode (keys arrive one by one, unechoed) until dropped.
pub struct RawTerminal;

impl RawTerminal {
    /// Enters raw mode; an error when stdin is not a terminal.
    pub fn enter() -> Result<Self, String> {
        crossterm::terminal::enable_raw_mode()
            .map_err(|e| format!("walker drive needs a terminal (raw mode: {e})"))?;
        Ok(RawTerminal)
    }
}

impl Drop for RawTerminal {
    fn drop(&mut self) {
        let _ = crossterm::terminal::disable_raw_mode();
    }
}

/// How long [`connect`] keeps trying (QEMU listens a moment after `walker fil` starts).
pub const CONNECT_WAIT: Duration = Duration::from_secs(60);

/// Connects a master to a TCP command port, retrying for [`CONNECT_WAIT`] (and giving up at
/// once when the `--sim` run has exited).
pub fn connect(addr: &str, mut run: Option<&mut SimRun>) -> Result<PortMaster, String> {
    let start = Instant::now();
    loop {
        match std::net::TcpStream::connect(addr) {
            Ok(s) => return Ok(PortMaster::new(s)),
            Err(e) if start.elapsed() >= CONNECT_WAIT => {
                return Err(format!("walker drive: cannot connect to {addr}: {e}"))
            }
            Err(_) => {}
        }
        if let Some(r) = run.as_deref_mut() {
            if let Ok(Some(status)) = r.child.try_wait() {
                return Err(format!(
                    "walker drive: the simulated robot's run ended ({status}) before its command port opened; see {}",
                    r.out.join("fil.err").display()
                ));
            }
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// `walker fil --command-port` in the background (`walker drive --sim`).
pub struct SimRun {
    child: std::process::Child,
    /// The command port (127.0.0.1).
    pub port: u16,
    out: std::path::PathBuf,
}

impl SimRun {
    /// Starts this executable's `fil --command-port` on a free port (the plan and ELF if
    /// given), its output in `out/fil.out` and `out/fil.err`.
    pub fn start(
        plan: Option<&std::path::Path>,
        robot: Option<&str>,
        elf: Option<&std::path::Path>,
        out: &std::path::Path,
    ) -> Result<Self, String> {
        std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
        let file = |n: &str| {
            std::fs::File::create(out.join(n)).map_err(|e| format!("{}: {e}", out.display()))
        };
        let port = crate::fil::free_port()?;
        let exe = std::env::current_exe().map_err(|e| format!("walker drive: {e}"))?;
        let mut c = std::process::Command::new(exe);
        c.arg("fil")
            .args(["--command-port", &port.to_string()])
            .arg("--out")
            .arg(out);
        if let Some(p) = plan {
            c.arg("--plan").arg(p);
        }
        if let Some(r) = robot {
            c.args(["--robot", r]);
        }
        if let Some(e) = elf {
            c.arg("--elf").arg(e);
        }
        let child = c
            .stdin(std::process::Stdio::null())
            .stdout(file("fil.out")?)
            .stderr(file("fil.err")?)
            .spawn()
            .map_err(|e| format!("walker drive: starting walker fil: {e}"))?;
        Ok(SimRun {
            child,
            port,
            out: out.to_path_buf(),
        })
    }

    /// Ends the run at once.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Waits up to `limit` for the run to end (torque off was sent); its report (fil.out).
    pub fn finish(&mut self, limit: Duration) -> Result<String, String> {
        let start = Instant::now();
        let status = loop {
            if let Some(s) = self.child.try_wait().map_err(|e| e.to_string())? {
                break s;
            }
            if start.elapsed() >= limit {
                self.kill();
                return Err(format!(
                    "walker drive: the run did not end within {limit:?}"
                ));
            }
            std::thread::sleep(Duration::from_millis(100));
        };
        let text = std::fs::read_to_string(self.out.join("fil.out")).unwrap_or_default();
        if status.success() {
            Ok(text)
        } else {
            Err(format!(
                "walker drive: the run ended with {status}: {text}see {}",
                self.out.join("fil.err").display()
            ))
        }
    }
}

impl Drop for SimRun {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            self.kill();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use walker_contract::command_port::{CommandTable, PortStatus};

    /// The port's own control table (the device side of the contract) as the link.
    struct TableLink {
        table: CommandTable,
        writes: Vec<(u16, Vec<u8>)>,
    }

    impl Link for TableLink {
        fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), String> {
            self.writes.push((addr, data.to_vec()));
            self.table
                .write(addr, data)
                .map_err(|e| format!("refused: {e:?}"))
        }
        fn status(&mut self) -> Result<StatusBlock, String> {
            let d = self
                .table
                .read(port::STATUS_BLOCK.addr, port::STATUS_BLOCK.len)
                .map_err(|e| format!("{e:?}"))?;
            StatusBlock::decode(d).ok_or_else(|| "short".to_string())
        }
    }

    fn link() -> TableLink {
        let mut table = CommandTable::new();
        table.set_status(&PortStatus {
            state: PortState::Standing,
            ..PortStatus::default()
        });
        TableLink {
            table,
            writes: Vec::new(),
        }
    }

    #[test]
    fn keys_step_the_velocity_and_clamp_it_to_the_port_range() {
        let mut t = Teleop::default();
        assert_eq!(t.key(Key::Forward), Action::Walk([10, 0, 0]));
        assert_eq!(t.key(Key::TurnLeft), Action::Walk([10, 0, 100]));
        assert_eq!(t.key(Key::SideRight), Action::Walk([10, -10, 100]));
        assert_eq!(t.key(Key::Backward), Action::Walk([0, -10, 100]));
        // Up to the forward limit, then nothing more to send.
        let vmax = VELOCITY_RANGE[0].1;
        let mut last = Action::Nothing;
        for _ in 0..100 {
            match t.key(Key::Forward) {
                Action::Nothing => break,
                a => last = a,
            }
        }
        assert_eq!(last, Action::Walk([vmax, -10, 100]));
        assert_eq!(t.key(Key::Forward), Action::Nothing);
        // Turning right all the way reaches the negative yaw limit.
        for _ in 0..100 {
            t.key(Key::TurnRight);
        }
        assert_eq!(t.velocity[2], VELOCITY_RANGE[2].0);
        assert_eq!(t.key(Key::Stop), Action::Stop);
        assert_eq!(t.velocity, [0; 3]);
        assert_eq!(t.key(Key::Quit), Action::Quit);
        assert_eq!(t.key(Key::TorqueOff), Action::TorqueOff);
        t.key(Key::Forward);
        assert_eq!(t.key(Key::Ready), Action::Ready);
        assert_eq!(t.velocity, [0; 3]);
    }

    #[test]
    fn letters_and_space_map_to_keys() {
        let keys: Vec<_> = "wsadqe trxW?".chars().map(Key::from_char).collect();
        use Key::*;
        assert_eq!(
            keys,
            [
                Some(Forward),
                Some(Backward),
                Some(TurnLeft),
                Some(TurnRight),
                Some(SideLeft),
                Some(SideRight),
                Some(Stop),
                Some(TorqueOff),
                Some(Ready),
                Some(Quit),
                Some(Forward),
                None
            ]
        );
    }

    #[test]
    fn terminal_keys_map_to_keys() {
        use crossterm::event::{KeyCode, KeyModifiers};
        let none = KeyModifiers::NONE;
        assert_eq!(key_of(KeyCode::Up, none), Some(Key::Forward));
        assert_eq!(key_of(KeyCode::Down, none), Some(Key::Backward));
        assert_eq!(key_of(KeyCode::Left, none), Some(Key::TurnLeft));
        assert_eq!(key_of(KeyCode::Right, none), Some(Key::TurnRight));
        assert_eq!(key_of(KeyCode::Esc, none), Some(Key::Quit));
        assert_eq!(key_of(KeyCode::Char(' '), none), Some(Key::Stop));
        assert_eq!(
            key_of(KeyCode::Char('c'), KeyModifiers::CONTROL),
            Some(Key::Quit)
        );
        assert_eq!(key_of(KeyCode::Char('c'), none), None);
        assert_eq!(key_of(KeyCode::Enter, none), None);
    }

    #[test]
    fn every_key_the_teleop_can_send_is_accepted_by_the_port() {
        // Random key sequences against the contract's table: no write is ever refused, and the
        // table's velocity is the teleop's.
        let all = [
            Key::Forward,
            Key::Backward,
            Key::TurnLeft,
            Key::TurnRight,
            Key::SideLeft,
            Key::SideRight,
            Key::Stop,
            Key::Ready,
        ];
        let mut seed = 0x2545_f491_u32;
        let mut l = link();
        let mut t = Teleop::default();
        for _ in 0..5000 {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            let k = all[(seed % all.len() as u32) as usize];
            let a = t.key(k);
            send(&mut l, a).unwrap();
            // raw_command: mode, vx, vy, yaw rate.
            let [_, vx, vy, w] = l.table.raw_command();
            assert_eq!([vx, vy, w], t.velocity.map(i32::from), "after {k:?}");
        }
    }

    #[test]
    fn a_session_sends_the_keys_and_stops_on_quit() {
        let mut l = link();
        let mut keys = [
            Some(Key::Forward),
            Some(Key::Forward),
            None,
            Some(Key::TurnLeft),
            Some(Key::Quit),
        ]
        .into_iter();
        let mut lines = Vec::new();
        let end = session(
            &mut l,
            |_| Ok(keys.next().flatten()),
            |s| lines.push(s.to_string()),
        )
        .unwrap();
        assert_eq!(end, Ended::Quit);
        let mode = port::MODE.addr;
        let vel = port::VELOCITY_X.addr;
        // A heartbeat after each status line.
        let beats = l
            .writes
            .iter()
            .filter(|w| **w == (port::HEARTBEAT.addr, vec![0]))
            .count();
        assert_eq!(beats, lines.len(), "{:?}", l.writes);
        assert_eq!(l.table.command_count() as usize, l.writes.len());
        l.writes.retain(|(a, _)| *a != port::HEARTBEAT.addr);
        assert_eq!(
            l.writes,
            [
                (vel, vec![10, 0, 0, 0, 0, 0]),
                (mode, vec![2]),
                (vel, vec![20, 0, 0, 0, 0, 0]),
                (mode, vec![2]),
                (vel, vec![20, 0, 0, 0, 100, 0]),
                (mode, vec![2]),
                (mode, vec![3]),
            ]
        );
        // Stop cleared the velocity in the table.
        assert_eq!(l.table.mode(), Mode::Stop);
        assert_eq!(l.table.raw_command(), [3, 0, 0, 0]);
        // A status line before the first key and after each key that sent something.
        assert!(lines.len() >= 4, "{lines:?}");
        assert!(lines[0].starts_with("standing"), "{}", lines[0]);
        assert!(
            lines.iter().any(|l| l.contains("cmd  +20   +0 mm/s +100")),
            "{lines:?}"
        );
    }

    /// With no key for a while the session still writes Heartbeat at every status refresh
    /// (every [`STATUS_EVERY`]), and nothing else: the command deadman stays quiet.
    #[test]
    fn a_session_without_keys_keeps_writing_heartbeats() {
        let mut l = link();
        let mut waits = 0;
        let started = Instant::now();
        let end = session(
            &mut l,
            |wait| {
                waits += 1;
                if waits > 5 {
                    return Ok(Some(Key::Quit));
                }
                std::thread::sleep(wait);
                Ok(None)
            },
            |_| {},
        )
        .unwrap();
        assert_eq!(end, Ended::Quit);
        let beats = l
            .writes
            .iter()
            .filter(|w| **w == (port::HEARTBEAT.addr, vec![0]))
            .count();
        assert!(beats >= 5, "{beats} heartbeats: {:?}", l.writes);
        // Never more than one a refresh period (the first at once).
        let periods = started.elapsed().as_secs_f64() / STATUS_EVERY.as_secs_f64();
        assert!(
            beats as f64 <= periods + 1.0,
            "{beats} in {periods:.1} periods"
        );
        assert_eq!(l.writes.last(), Some(&(port::MODE.addr, vec![3])));
    }

    /// A firmware that rests on the first torque off and turns torque off on the second.
    struct RestingLink {
        inner: TableLink,
        offs: usize,
        closed_after: Option<usize>,
    }

    impl Link for RestingLink {
        fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), String> {
            if self.closed_after.is_some_and(|n| self.offs >= n) {
                return Err("closed".into());
            }
            self.inner.write(addr, data)?;
            if addr == port::MODE.addr && data == [Mode::TorqueOff.code()] {
                self.offs += 1;
                let state = if self.offs == 1 {
                    PortState::Resting
                } else {
                    PortState::Stopped
                };
                self.inner.table.set_status(&PortStatus {
                    state,
                    stop_code: 7,
                    ..PortStatus::default()
                });
            }
            Ok(())
        }
        fn status(&mut self) -> Result<StatusBlock, String> {
            if self.closed_after.is_some_and(|n| self.offs >= n) {
                return Err("closed".into());
            }
            self.inner.status()
        }
    }

    #[test]
    fn torque_off_rests_first_and_the_second_t_turns_torque_off() {
        let mut l = RestingLink {
            inner: link(),
            offs: 0,
            closed_after: None,
        };
        let mut keys = [Some(Key::TorqueOff), None, Some(Key::TorqueOff), None, None].into_iter();
        let mut lines = Vec::new();
        let end = session(
            &mut l,
            |_| Ok(keys.next().flatten()),
            |s| lines.push(s.to_string()),
        )
        .unwrap();
        assert_eq!(end, Ended::TorqueOff);
        assert_eq!(l.offs, 2);
        assert!(lines.iter().any(|s| s.starts_with("RESTING")), "{lines:?}");
        assert!(lines.last().unwrap().starts_with("STOPPED"), "{lines:?}");
        // A firmware whose run ends at the first (its port closes): the session ends too.
        let mut l = RestingLink {
            inner: link(),
            offs: 0,
            closed_after: Some(1),
        };
        let mut keys = [Some(Key::TorqueOff), None].into_iter();
        let end = session(&mut l, |_| Ok(keys.next().flatten()), |_| {}).unwrap();
        assert_eq!(end, Ended::TorqueOff);
        // Without a torque off a closed port is an error.
        let mut l = RestingLink {
            inner: link(),
            offs: 0,
            closed_after: Some(0),
        };
        assert!(session(&mut l, |_| Ok(None), |_| {}).is_err());
    }

    #[test]
    fn a_session_ends_when_the_firmware_stops() {
        let mut l = link();
        l.table.set_status(&PortStatus {
            state: PortState::Stopped,
            stop_code: 13,
            ..PortStatus::default()
        });
        let mut lines = Vec::new();
        let end = session(&mut l, |_| Ok(None), |s| lines.push(s.to_string())).unwrap();
        assert_eq!(end, Ended::Stopped);
        assert!(lines[0].contains("STOPPED") && lines[0].contains("stop code 13"));
        assert!(l.writes.is_empty());
    }

    #[test]
    fn the_status_line_shows_the_walk() {
        let s = StatusBlock {
            state: Some(PortState::Walking),
            support: 1,
            step_count: 12,
            zmp_mm: Some([15, -3]),
            walk_velocity: [40, 0, -50],
            fault_kind: 7,
            servo_stiffness: 1133,
            supply_dv: 119,
            ..StatusBlock::default()
        };
        let line = status_line(
            &s,
            &Teleop {
                velocity: [50, 0, -100],
            },
        );
        assert_eq!(
            line,
            "walking  support left  steps   12 | cmd  +50   +0 mm/s -100 mrad/s | walk  +40   +0  -50 | ZMP ( +15,   -3) mm | supply 11.9 V | servos 11.3 N·m/rad | last fault 7"
        );
    }
}
