//! Endpoints of the simulator (TCP, or the lock-step pipes) and the lock-step protocol
//! ([`walker_contract::lockstep`]).
//!
//! # Endpoints
//!
//! The bus is one TCP connection carrying raw Dynamixel 2.0 bytes (any Protocol 2.0 master can
//! use it, e.g. the ROBOTIS SDK through a socket-backed port handler). By default the simulator
//! **listens** on `127.0.0.1:port` and accepts one connection per channel — start the simulator
//! first ([`spawn`] returns once the sockets are bound), then QEMU with
//! `-serial tcp:127.0.0.1:PORT,nodelay=on` (and the lock-step UART likewise). With
//! [`SimConfig::connect`] the simulator connects instead (QEMU `server=on,wait=off`), retrying
//! until [`SimConfig::connect_timeout`]. TCP_NODELAY is set on every connection; a master on a
//! socket should set it too (pyserial's `socket://` does not: `host/tests/sdk/` shows how),
//! else a read sent right after a SYNC WRITE waits ≈ 40 ms for a delayed ACK. Free-running (no
//! lock-step), the physics runs before each reply, so on a loaded machine replies can be tens of
//! ms late: give such a master a packet-timeout margin.
//!
//! # Lock-step channel (fixed protocol)
//!
//! * firmware → simulator: [`lockstep::TIME`] (`0x5A`) + u64 little-endian virtual time in µs
//!   (9 bytes), at the start of every control tick and before bus bursts. The simulator runs
//!   its physics up to that time (whole physics steps; never backwards; no wall clock).
//! * simulator → firmware: after reading one complete instruction packet from the bus and
//!   writing its whole reply, [`lockstep::REPLY`] (`0xA5`), `n_lo`, `n_hi` = the number of bytes
//!   written on the bus for that instruction (0 for a broadcast SYNC WRITE, a dropped reply, a
//!   dead device, a packet with a bad CRC). Status packets on the bus are not instructions and
//!   are not acknowledged.
//!
//! Before executing each instruction, the simulator reads every lock-step byte already
//! received (non-blocking), so a time message the firmware sent before the instruction is
//! applied first (on loopback TCP the sender's bytes are queued at the receiver when its write
//! returns, and QEMU writes the UARTs in guest program order). Without a lock-step channel the
//! physics follows the wall clock since the bus connection.
//!
//! # Lock-step pipes ([`SimConfig::lockstep_pipe`], `walker fil`)
//!
//! The same protocol with the bus inside it, on two named pipes the simulator creates at
//! `PREFIX-to-sim` and `PREFIX-to-fw` (the firmware's word `lockstep=PREFIX`): one ordered
//! stream of time frames and packet frames (`0x50`, u16 LE length, one instruction packet) in,
//! and for every packet frame `0xA5`, the count and the reply bytes out. The simulator opens
//! its ends before QEMU starts (its read end non-blocking, its write end read-write, so that
//! neither open waits), waits for the firmware to open its ends, then reads blocking (the
//! firmware's exit, QEMU closing its end, ends the run) and removes the two names at the
//! firmware's first frame. On the pipes only, the controller board's IMU chip too: an SPI
//! frame (`0x53`, u16 LE length, the bytes out) is answered `0xA5`, the same count and the
//! chip's bytes ([`super::chip`]).

use std::io::{ErrorKind, Read, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::{SimConfig, SimError, SimSummary, Simulator};
use walker_contract::lockstep;

/// Live progress of a running simulator (read it from any thread).
#[derive(Debug, Default)]
pub struct SimProgress {
    /// Simulated time, µs.
    pub time_us: AtomicU64,
    /// Instruction packets handled.
    pub instructions: AtomicU64,
    /// Every channel is connected.
    pub connected: AtomicBool,
    /// A fall has started.
    pub falling: AtomicBool,
}

impl SimProgress {
    /// Publishes the simulator's time, fall and instruction count.
    fn publish(&self, sim: &Simulator) {
        self.time_us.store(sim.time_us(), Ordering::Relaxed);
        self.falling
            .store(sim.physics.fall_started_us().is_some(), Ordering::Relaxed);
        self.instructions
            .store(sim.bus.counters.instructions, Ordering::Relaxed);
    }
}

enum Endpoint {
    Listen(TcpListener),
    Connect(SocketAddr),
}

/// A simulator running on its own thread.
#[derive(Debug)]
pub struct SimHandle {
    bus_addr: Option<SocketAddr>,
    lockstep_addr: Option<SocketAddr>,
    progress: Arc<SimProgress>,
    stop: Arc<AtomicBool>,
    thread: JoinHandle<Result<SimSummary, SimError>>,
}

impl SimHandle {
    /// The bus address (the bound one when listening, useful with port 0); `None` with the
    /// lock-step pipes (the bus is inside them).
    pub fn bus_addr(&self) -> Option<SocketAddr> {
        self.bus_addr
    }

    /// The lock-step channel address.
    pub fn lockstep_addr(&self) -> Option<SocketAddr> {
        self.lockstep_addr
    }

    /// Live progress.
    pub fn progress(&self) -> Arc<SimProgress> {
        Arc::clone(&self.progress)
    }

    /// Asks the simulator to stop (it returns within ~20 ms).
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }

    /// Whether the simulator thread has returned.
    pub fn is_finished(&self) -> bool {
        self.thread.is_finished()
    }

    /// Waits for the simulator to return (when the master disconnects or after [`stop`](Self::stop)).
    pub fn join(self) -> Result<SimSummary, SimError> {
        self.thread.join().map_err(|_| SimError::Panicked)?
    }
}

/// Runs the simulator on the calling thread until the master disconnects.
pub fn run(config: SimConfig) -> Result<SimSummary, SimError> {
    spawn(config)?.join()
}

fn endpoint(cfg: &SimConfig, port: u16) -> Result<(Endpoint, SocketAddr), SimError> {
    let addr = SocketAddr::from((Ipv4Addr::LOCALHOST, port));
    if cfg.connect {
        Ok((Endpoint::Connect(addr), addr))
    } else {
        let l = TcpListener::bind(addr)?;
        let a = l.local_addr()?;
        Ok((Endpoint::Listen(l), a))
    }
}

/// Binds the sockets (listen mode) or creates the lock-step pipes, opens the truth log and
/// starts the simulator thread.
pub fn spawn(config: SimConfig) -> Result<SimHandle, SimError> {
    config.validate()?;
    // The simulator's ends: the pipes, or the bus socket and the lock-step socket.
    enum Wiring {
        Pipes(Pipes),
        Tcp(Endpoint, Option<Endpoint>),
    }
    let (wiring, bus_addr, lockstep_addr) = match &config.lockstep_pipe {
        Some(prefix) => (Wiring::Pipes(Pipes::create(prefix)?), None, None),
        None => {
            let (bus_ep, bus_addr) = endpoint(&config, config.port)?;
            let (ls_ep, lockstep_addr) = match config.lockstep_port {
                Some(p) => {
                    let (e, a) = endpoint(&config, p)?;
                    (Some(e), Some(a))
                }
                None => (None, None),
            };
            (Wiring::Tcp(bus_ep, ls_ep), Some(bus_addr), lockstep_addr)
        }
    };
    let sim = Simulator::new(&config)?;
    let progress = Arc::new(SimProgress::default());
    let stop = Arc::new(AtomicBool::new(false));
    let (p2, s2) = (Arc::clone(&progress), Arc::clone(&stop));
    let thread = std::thread::Builder::new()
        .name("walker-sim".into())
        .spawn(move || match wiring {
            Wiring::Pipes(pipes) => serve_pipes(sim, pipes, config, &p2, &s2),
            Wiring::Tcp(bus_ep, ls_ep) => serve(sim, bus_ep, ls_ep, config, &p2, &s2),
        })?;
    Ok(SimHandle {
        bus_addr,
        lockstep_addr,
        progress,
        stop,
        thread,
    })
}

fn establish(ep: Endpoint, deadline: Instant, stop: &AtomicBool) -> Result<TcpStream, SimError> {
    let s = match ep {
        Endpoint::Listen(l) => {
            l.set_nonblocking(true)?;
            loop {
                match l.accept() {
                    Ok((s, _)) => break s,
                    Err(e)
                        if e.kind() == ErrorKind::WouldBlock
                            || e.kind() == ErrorKind::Interrupted => {}
                    Err(e) => return Err(e.into()),
                }
                if stop.load(Ordering::SeqCst) || Instant::now() > deadline {
                    return Err(SimError::Timeout("no connection accepted".into()));
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        Endpoint::Connect(addr) => loop {
            match TcpStream::connect_timeout(&addr, Duration::from_millis(500)) {
                Ok(s) => break s,
                Err(e) => {
                    if stop.load(Ordering::SeqCst) || Instant::now() > deadline {
                        return Err(SimError::Timeout(format!("cannot connect to {addr}: {e}")));
                    }
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        },
    };
    s.set_nonblocking(false)?;
    s.set_nodelay(true)?;
    Ok(s)
}

/// Lock-step channel state.
struct Lockstep {
    stream: TcpStream,
    frame: [u8; 9],
    len: usize,
    open: bool,
    messages: u64,
    errors: u64,
}

impl Lockstep {
    /// Reads every byte available now and applies the complete time messages, publishing the
    /// simulated time after each (a firmware that only ticks, with no bus traffic, sends them
    /// as fast as they are taken: the drain may last, its progress must show).
    fn drain(&mut self, sim: &mut Simulator, progress: &SimProgress) -> Result<(), SimError> {
        let mut buf = [0u8; 512];
        while self.open {
            match self.stream.read(&mut buf) {
                Ok(0) => self.open = false,
                Ok(n) => {
                    for &b in &buf[..n] {
                        if self.len == 0 && b != lockstep::TIME {
                            self.errors += 1;
                            continue;
                        }
                        self.frame[self.len] = b;
                        self.len += 1;
                        if self.len == self.frame.len() {
                            self.len = 0;
                            self.messages += 1;
                            let mut t = [0u8; 8];
                            t.copy_from_slice(&self.frame[1..]);
                            sim.advance_to(u64::from_le_bytes(t))?;
                            progress.time_us.store(sim.time_us(), Ordering::Relaxed);
                        }
                    }
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => self.open = false,
            }
        }
        Ok(())
    }

    fn ack(&mut self, n: usize) -> Result<(), SimError> {
        if !self.open {
            return Ok(());
        }
        let msg = lockstep::reply_header(n);
        let mut done = 0;
        while done < msg.len() {
            match self.stream.write(&msg[done..]) {
                Ok(0) => {
                    self.open = false;
                    break;
                }
                Ok(k) => done += k,
                Err(e)
                    if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted =>
                {
                    std::thread::sleep(Duration::from_micros(200));
                }
                Err(_) => {
                    self.open = false;
                    break;
                }
            }
        }
        Ok(())
    }
}

fn serve(
    mut sim: Simulator,
    bus_ep: Endpoint,
    ls_ep: Option<Endpoint>,
    cfg: SimConfig,
    progress: &SimProgress,
    stop: &AtomicBool,
) -> Result<SimSummary, SimError> {
    let deadline = Instant::now() + cfg.connect_timeout;
    let mut bus = establish(bus_ep, deadline, stop)?;
    let mut ls = match ls_ep {
        Some(ep) => {
            let stream = establish(ep, deadline, stop)?;
            stream.set_nonblocking(true)?;
            Some(Lockstep {
                stream,
                frame: [0; 9],
                len: 0,
                open: true,
                messages: 0,
                errors: 0,
            })
        }
        None => None,
    };
    progress.connected.store(true, Ordering::SeqCst);
    bus.set_read_timeout(Some(Duration::from_millis(20)))?;
    let start = Instant::now();
    let mut buf = [0u8; 4096];
    let sync = |sim: &mut Simulator, ls: &mut Option<Lockstep>| -> Result<(), SimError> {
        match ls {
            Some(l) => l.drain(sim, progress)?,
            None => sim.advance_to(start.elapsed().as_micros() as u64)?,
        }
        progress.publish(sim);
        Ok(())
    };
    while !stop.load(Ordering::SeqCst) {
        match bus.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                for &b in &buf[..n] {
                    let Some(inc) = sim.push_byte(b) else {
                        continue;
                    };
                    sync(&mut sim, &mut ls)?;
                    if let Some(reply) = sim.respond(&inc) {
                        bus.write_all(&reply)?;
                        if let Some(l) = ls.as_mut() {
                            l.ack(reply.len())?;
                        }
                    }
                    progress.publish(&sim);
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                ) =>
            {
                sync(&mut sim, &mut ls)?;
            }
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::ConnectionReset
                        | ErrorKind::ConnectionAborted
                        | ErrorKind::BrokenPipe
                ) =>
            {
                break
            }
            Err(e) => return Err(e.into()),
        }
    }
    let mut summary = sim.summary();
    if let Some(l) = &ls {
        summary.lockstep_messages = l.messages;
        summary.lockstep_errors = l.errors;
        // The firmware is gone (its bus closed): the robot as it left it, for a while.
        summary.end = sim.after_end()?;
    }
    Ok(summary)
}

/// The simulator's ends of the lock-step pipes.
struct Pipes {
    /// `PREFIX-to-sim`, read (non-blocking until the firmware has opened its end).
    to_sim: std::fs::File,
    /// `PREFIX-to-fw`, written (opened read-write: the open does not wait for a reader).
    to_fw: std::fs::File,
    /// The two names, removed once the firmware's first frame came (it has opened both ends
    /// then), else when the run ends.
    paths: [std::path::PathBuf; 2],
}

impl Pipes {
    /// Creates the two named pipes at `prefix` (replacing stale ones) and opens the
    /// simulator's ends.
    fn create(prefix: &std::path::Path) -> Result<Pipes, SimError> {
        use std::os::unix::ffi::OsStrExt;
        use std::os::unix::fs::OpenOptionsExt;
        let name = |suffix: &str| {
            let mut p = prefix.as_os_str().to_owned();
            p.push(suffix);
            std::path::PathBuf::from(p)
        };
        let paths = [
            name(lockstep::TO_SIM_SUFFIX),
            name(lockstep::TO_FIRMWARE_SUFFIX),
        ];
        for p in &paths {
            let _ = std::fs::remove_file(p);
            let c = std::ffi::CString::new(p.as_os_str().as_bytes())
                .map_err(|_| SimError::Config(format!("{}: a NUL in the path", p.display())))?;
            // SAFETY: mkfifo with a NUL-terminated path that lives for the call.
            if unsafe { libc::mkfifo(c.as_ptr(), 0o600) } != 0 {
                let e = std::io::Error::last_os_error();
                return Err(SimError::Config(format!("mkfifo {}: {e}", p.display())));
            }
        }
        let to_sim = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(&paths[0])?;
        let to_fw = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&paths[1])?;
        Ok(Pipes {
            to_sim,
            to_fw,
            paths,
        })
    }

    /// Waits until the firmware has opened its write end (a non-blocking read then no longer
    /// finds the end of the file), then makes reads blocking; returns the bytes that read
    /// already took.
    fn establish(&mut self, deadline: Instant, stop: &AtomicBool) -> Result<Vec<u8>, SimError> {
        use std::os::unix::io::AsRawFd;
        let mut buf = [0u8; 4096];
        let early = loop {
            match self.to_sim.read(&mut buf) {
                // No writer yet.
                Ok(0) => {}
                Ok(n) => break buf[..n].to_vec(),
                Err(e) if e.kind() == ErrorKind::WouldBlock => break Vec::new(),
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(e.into()),
            }
            if stop.load(Ordering::SeqCst) || Instant::now() > deadline {
                return Err(SimError::Timeout(
                    "the firmware did not open the lock-step pipes".into(),
                ));
            }
            std::thread::sleep(Duration::from_millis(2));
        };
        let fd = self.to_sim.as_raw_fd();
        // SAFETY: fcntl on a descriptor this struct owns; only O_NONBLOCK is cleared.
        let ok = unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            flags >= 0 && libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK) == 0
        };
        if !ok {
            return Err(std::io::Error::last_os_error().into());
        }
        Ok(early)
    }

    fn remove_names(&self) {
        for p in &self.paths {
            let _ = std::fs::remove_file(p);
        }
    }
}

impl Drop for Pipes {
    fn drop(&mut self) {
        self.remove_names();
    }
}

/// Serves the firmware over the lock-step pipes until it closes its end (or a stop between
/// frames); see the module docs.
fn serve_pipes(
    mut sim: Simulator,
    mut pipes: Pipes,
    cfg: SimConfig,
    progress: &SimProgress,
    stop: &AtomicBool,
) -> Result<SimSummary, SimError> {
    let early = pipes.establish(Instant::now() + cfg.connect_timeout, stop)?;
    progress.connected.store(true, Ordering::SeqCst);
    let mut input =
        std::io::BufReader::with_capacity(1 << 16, early.as_slice().chain(&pipes.to_sim));
    let (mut messages, mut errors) = (0u64, 0u64);
    let mut packet = Vec::with_capacity(1024);
    let mut out = Vec::with_capacity(1024);
    let mut marker = [0u8; 1];
    let mut first = true;
    while !stop.load(Ordering::SeqCst) {
        match input.read_exact(&mut marker) {
            Ok(()) => {}
            Err(e) if e.kind() == ErrorKind::UnexpectedEof => break,
            Err(e) => return Err(e.into()),
        }
        if std::mem::take(&mut first) {
            pipes.remove_names();
        }
        match marker[0] {
            lockstep::TIME => {
                let mut t = [0u8; 8];
                if input.read_exact(&mut t).is_err() {
                    break;
                }
                messages += 1;
                sim.advance_to(u64::from_le_bytes(t))?;
            }
            lockstep::PACKET => {
                let mut len = [0u8; 2];
                if input.read_exact(&mut len).is_err() {
                    break;
                }
                packet.resize(lockstep::header_count(len[0], len[1]), 0);
                if input.read_exact(&mut packet).is_err() {
                    break;
                }
                // Every instruction the frame completes is answered; the frame gets one
                // announcement of all their reply bytes (0: none).
                out.clear();
                out.extend_from_slice(&[0; lockstep::HEADER_LEN]);
                for &b in &packet {
                    if let Some(inc) = sim.push_byte(b) {
                        if let Some(reply) = sim.respond(&inc) {
                            out.extend_from_slice(&reply);
                        }
                    }
                }
                let header = lockstep::reply_header(out.len() - lockstep::HEADER_LEN);
                out[..lockstep::HEADER_LEN].copy_from_slice(&header);
                if pipes.to_fw.write_all(&out).is_err() {
                    break;
                }
            }
            lockstep::SPI => {
                let mut len = [0u8; 2];
                if input.read_exact(&mut len).is_err() {
                    break;
                }
                let n = lockstep::header_count(len[0], len[1]);
                if n > lockstep::SPI_MAX {
                    errors += 1;
                }
                packet.resize(n, 0);
                if input.read_exact(&mut packet).is_err() {
                    break;
                }
                let miso = sim.spi(&packet);
                out.clear();
                out.extend_from_slice(&lockstep::reply_header(miso.len()));
                out.extend_from_slice(&miso);
                if pipes.to_fw.write_all(&out).is_err() {
                    break;
                }
            }
            _ => errors += 1,
        }
        progress.publish(&sim);
    }
    let mut summary = sim.summary();
    summary.lockstep_messages = messages;
    summary.lockstep_errors = errors;
    // The firmware is gone (its pipe closed): the robot as it left it, for a while.
    summary.end = sim.after_end()?;
    Ok(summary)
}
