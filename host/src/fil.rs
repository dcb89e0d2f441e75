//! Firmware in the loop: the firmware ELF built for the emulated board runs in QEMU
//! (`mps2-an500`, Cortex-M7) against the simulated robot, in lock-step, and its ZMP-response log
//! is captured and reported.
//!
//! QEMU starts through `scripts/qemu-run.sh` ([`crate::qemu`]), the one definition of its
//! command line. Wiring (see `docs/lockstep.md`): QEMU's UART0 (the servo bus) and UART2 (the lock-step
//! channel) connect as TCP clients to the simulator's two listening sockets; UART1 (the log)
//! goes to `OUT/walk.log`; the semihosting output (defmt frames) to `OUT/firmware.defmt`, decoded
//! after the run with the ELF's table into `OUT/firmware.log` ([`crate::defmt_log`]). The
//! walk's parameters reach the firmware as `key=value` tokens on its semihosting command line
//! (`-append`), so any forward-walk plan file can be walked. Time in the loop is the firmware's
//! virtual clock, so the result does not depend on how fast the host is.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use crate::planfile::WalkSpec;
use crate::sim::{self, SimConfig, SimSummary};

/// What to run.
#[derive(Clone, Debug)]
pub struct FilOptions {
    /// The board-qemu firmware ELF.
    pub elf: PathBuf,
    /// The walk.
    pub spec: WalkSpec,
    /// Output folder.
    pub out_dir: PathBuf,
    /// QEMU machine (a name of [`crate::qemu::machines`], e.g. `mps2-an500` Cortex-M7).
    pub machine: String,
    /// Wall-clock limit, s.
    pub timeout: Duration,
    /// The simulator's configuration (its ports and pipes are chosen here). The lock-step
    /// transport is the pipes (docs/lockstep.md); a `lockstep_port` (any) asks for the UARTs
    /// over TCP instead.
    pub sim: SimConfig,
    /// Extra `key=value` tokens for the firmware.
    pub extra_tokens: Vec<String>,
}

impl FilOptions {
    /// The same run with its output in the sub-folder `name` of [`FilOptions::out_dir`] (one
    /// run of a sweep, a push or a speed search).
    pub fn in_sub(&self, name: &str) -> FilOptions {
        FilOptions {
            out_dir: self.out_dir.join(name),
            ..self.clone()
        }
    }
}

/// What came out.
#[derive(Debug)]
pub struct FilResult {
    /// The firmware's exit code (semihosting), or None when QEMU was killed.
    pub exit_code: Option<i32>,
    /// The simulator's summary.
    pub sim: SimSummary,
    /// The captured log.
    pub log: PathBuf,
    /// The ground-truth CSV.
    pub truth: PathBuf,
    /// Wall-clock duration of the run.
    pub wall: Duration,
    /// The firmware's defmt output decoded to `OUT/firmware.log` (or why it could not be).
    pub firmware_log: Result<crate::defmt_log::DefmtLog, String>,
}

/// Decodes `OUT/firmware.defmt` into `OUT/firmware.log` with the ELF's defmt table.
fn decode_defmt(elf: &Path, out_dir: &Path) -> Result<crate::defmt_log::DefmtLog, String> {
    crate::defmt_log::decode_file(
        elf,
        &out_dir.join("firmware.defmt"),
        &out_dir.join("firmware.log"),
    )
}

/// The firmware command-line tokens of a forward-walk plan (the contract's parameter table,
/// [`WalkSpec::firmware_tokens`]).
pub fn firmware_tokens(spec: &WalkSpec) -> Result<Vec<String>, String> {
    if spec.footsteps.is_some() {
        return Err(
            "the firmware takes forward-walk plans only (footstep lists are host-side for now)"
                .into(),
        );
    }
    spec.firmware_tokens().map_err(|e| e.to_string())
}

/// The firmware's command-line tokens of a run: `lockstep`, the plan's tokens, `autostart=1`
/// (the plan walks at power-on; a command-script run appends `autostart=0`), then `extra`,
/// each key once ([`merge_tokens`]: a later token replaces an earlier one of the same key, as
/// the firmware refuses a key given twice).
fn command_tokens(spec: &WalkSpec, extra: &[String]) -> Result<Vec<String>, String> {
    let mut t = vec!["lockstep".to_string()];
    t.extend(firmware_tokens(spec)?);
    t.push("autostart=1".to_string());
    t.extend(extra.iter().cloned());
    Ok(merge_tokens(t).0)
}

/// The key of a `key=value` token (`None` for a bare word).
fn token_key(t: &str) -> Option<&str> {
    t.split_once('=').map(|(k, _)| k)
}

/// `tokens` with each key once: a later `key=value` replaces an earlier one of the same key
/// (in the earlier one's place); bare words are kept as they are. The firmware refuses a key
/// given twice, so the host, which layers the plan's tokens, the command's and the user's,
/// decides here; returns the replaced tokens as (earlier, winner) pairs.
pub fn merge_tokens(tokens: Vec<String>) -> (Vec<String>, Vec<(String, String)>) {
    let mut out: Vec<String> = Vec::with_capacity(tokens.len());
    let mut replaced = Vec::new();
    for t in tokens {
        let slot = token_key(&t).and_then(|k| out.iter().position(|o| token_key(o) == Some(k)));
        match slot {
            Some(i) => {
                if out[i] != t {
                    replaced.push((std::mem::replace(&mut out[i], t.clone()), t));
                }
            }
            None => out.push(t),
        }
    }
    (out, replaced)
}

/// The user's tokens (`extra`) that replace one of the plan's: "`t1=0.2` replaces the plan's
/// `t1=0.15`" lines, for a warning before a run.
pub fn token_overrides(spec: &WalkSpec, extra: &[String]) -> Vec<String> {
    let Ok(plan) = firmware_tokens(spec) else {
        return Vec::new();
    };
    let mut all = plan;
    all.push("autostart=1".to_string());
    all.extend(extra.iter().cloned());
    merge_tokens(all)
        .1
        .into_iter()
        .map(|(old, new)| format!("`{new}` replaces `{old}` (the later token wins)"))
        .collect()
}

/// The firmware's command line of a run (`lockstep`, the plan's tokens, then `extra`), checked
/// with the firmware's own parser (`walker_contract::params::apply`) on the host, so that a
/// misspelt key or a value out of range is refused before QEMU starts; the configuration the
/// firmware will start with.
pub fn check_tokens(
    spec: &WalkSpec,
    extra: &[String],
) -> Result<(Vec<String>, walker_contract::Config), String> {
    let t = command_tokens(spec, extra)?;
    let mut cfg = walker_contract::Config::default();
    walker_contract::params::apply(&mut cfg, t.join(" ").as_bytes())
        .map_err(|e| token_error(&e, &t))?;
    Ok((t, cfg))
}

/// A firmware parser error as a sentence: the token, the reason, the key's domain or the
/// list of valid keys.
pub fn token_error(e: &walker_contract::params::ArgError, tokens: &[String]) -> String {
    use walker_contract::params::{self as fw, ArgErrorKind};
    let token = tokens
        .get(usize::from(e.position))
        .map_or(e.key(), String::as_str);
    match e.kind {
        ArgErrorKind::UnknownKey => format!(
            "`{token}`: unknown firmware parameter `{}`; valid keys: {}",
            e.key(),
            fw::KEYS.join(", ")
        ),
        ArgErrorKind::BadValue | ArgErrorKind::OutOfRange => {
            let mut domain = String::new();
            if let Some(p) = fw::find(e.key()) {
                let _ = p.write_domain(&mut domain);
                if !p.unit.is_empty() {
                    domain.push(' ');
                    domain.push_str(p.unit);
                }
            }
            format!("`{token}`: {} (expected {domain})", e.kind.reason())
        }
        ArgErrorKind::StrayWord => format!("`{token}`: not a key=value pair"),
        ArgErrorKind::Repeated => format!(
            "`{token}`: the key `{}` is given twice (the firmware refuses repeated keys)",
            e.key()
        ),
    }
}

/// The `-append` text of a run (`lockstep`, the plan's tokens, the extra tokens), checked
/// against the firmware's semihosting buffer: QEMU hands the firmware the ELF path, a space and
/// this text, and refuses when that is longer than `CMDLINE_MAX` − 1 bytes — the firmware would
/// then read no parameter at all. Refused here, before anything starts.
pub fn qemu_append(opts: &FilOptions) -> Result<String, String> {
    let append = command_tokens(&opts.spec, &opts.extra_tokens)?.join(" ");
    let kernel = opts.elf.as_os_str().len();
    if walker_contract::params::cmdline_fits(kernel, append.len()) {
        Ok(append)
    } else {
        Err(format!(
            "the firmware command line is {} bytes (ELF path {kernel} + 1 + parameters {} + NUL),              over the firmware's {}-byte semihosting buffer: QEMU would pass no parameter at all.              Use fewer or shorter parameters (or a shorter ELF path)",
            kernel + append.len() + 2,
            append.len(),
            walker_contract::params::CMDLINE_MAX
        ))
    }
}

/// Runs the firmware in QEMU against the simulator; blocks until the firmware exits.
pub fn run(opts: &FilOptions, progress: impl Fn(f64, u64)) -> Result<FilResult, String> {
    run_inner(opts, PortDriver::None, progress).map(|(r, _)| r)
}

/// Runs the firmware without autostart and drives it through its command port (QEMU's UART3,
/// a TCP connection to the host) with `script` ([`crate::commands`]); blocks until the
/// firmware exits (the script ends with torque off). Returns what the driver did too.
pub fn run_commands(
    opts: &FilOptions,
    script: &crate::commands::CommandScript,
    progress: impl Fn(f64, u64),
) -> Result<(FilResult, crate::commands::DriveReport), String> {
    let (r, d) = run_commands_to_the_end(opts, script, progress)?;
    Ok((r, d?))
}

/// [`run_commands`], but a script the firmware ended before it finished (a fall: the driver's
/// error says "aborted") still gives the run, with the driver's error beside it.
pub fn run_commands_to_the_end(
    opts: &FilOptions,
    script: &crate::commands::CommandScript,
    progress: impl Fn(f64, u64),
) -> Result<(FilResult, Result<crate::commands::DriveReport, String>), String> {
    let mut o = opts.clone();
    o.extra_tokens.push("autostart=0".into());
    let (r, d) = run_inner(&o, PortDriver::Script(script), progress)?;
    match d {
        Some(Err(e)) if !e.contains("aborted") => Err(e),
        Some(d) => Ok((r, d)),
        None => Err("command driver: no report".into()),
    }
}

/// Runs the firmware without autostart with its command port (QEMU's UART3) listening on
/// `127.0.0.1:port` for any Dynamixel master (the ROBOTIS SDK, `walker drive`): QEMU is the TCP
/// server (`server=on,wait=off`: the firmware starts at once and answers whoever connects; a
/// master that disconnects can connect again). Blocks until the firmware exits — a master
/// writing Mode = 0 (torque off) ends the run (exit code 17, [`END_BY_COMMAND`]).
pub fn run_command_port(
    opts: &FilOptions,
    port: u16,
    progress: impl Fn(f64, u64),
) -> Result<FilResult, String> {
    let mut o = opts.clone();
    o.extra_tokens.push("autostart=0".into());
    run_inner(&o, PortDriver::External(port), progress).map(|(r, _)| r)
}

/// The firmware's exit code of a run ended by torque off on the command port (stop code
/// `Requested`).
pub const END_BY_COMMAND: i32 = walker_contract::codes::ExitCode::Requested.code() as i32;

/// A fresh path prefix for a run's lock-step pipes in the temporary directory (unique per
/// process and run; at most [`walker_contract::lockstep::PREFIX_MAX`] bytes).
fn lockstep_pipe_prefix() -> Result<PathBuf, String> {
    static RUNS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let p = std::env::temp_dir().join(format!("walker-ls-{}-{n}", std::process::id()));
    if p.as_os_str().len() > walker_contract::lockstep::PREFIX_MAX {
        return Err(format!(
            "lock-step pipes: {} is over {} bytes (set a shorter TMPDIR)",
            p.display(),
            walker_contract::lockstep::PREFIX_MAX
        ));
    }
    Ok(p)
}

/// A free TCP port on 127.0.0.1 (bound, read and released: another process may take it before
/// QEMU binds it, then QEMU fails to start and says so).
pub fn free_port() -> Result<u16, String> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| format!("command port: {e}"))
}

/// Who drives the command port (QEMU's UART3) of a run.
#[derive(Clone, Copy)]
enum PortDriver<'a> {
    /// Nobody: UART3 is `null` (a plan run with autostart).
    None,
    /// A command script, through the host's own master (QEMU connects to the host).
    Script(&'a crate::commands::CommandScript),
    /// An external master on `127.0.0.1:port` (QEMU listens).
    External(u16),
}

type DriveOutcome = Option<Result<crate::commands::DriveReport, String>>;

/// Simulated time a run goes on after the firmware's end (torque off), µs: how the robot
/// ended ([`crate::sim::EndPose`]; its truth in `OUT/truth-after.csv`).
pub const AFTER_END_US: u64 = 2_000_000;

fn run_inner(
    opts: &FilOptions,
    port: PortDriver<'_>,
    progress: impl Fn(f64, u64),
) -> Result<(FilResult, DriveOutcome), String> {
    // Checked before anything starts: the firmware's own parser, then the firmware's buffer.
    check_tokens(&opts.spec, &opts.extra_tokens)?;
    // The lock-step transport: the pipes, unless the simulator's configuration asks for the
    // UARTs (a lock-step TCP port).
    let pipes = match opts.sim.lockstep_port {
        Some(_) => None,
        None => Some(lockstep_pipe_prefix()?),
    };
    // A master on the command port: the firmware holds its virtual time back to the wall
    // clock. A master on the wall clock (a person, the ROBOTIS SDK) must not be outrun by the
    // walk (its heartbeats); and every master's bytes reach the firmware's UART through QEMU's
    // main loop, which a firmware blocked in the lock-step pipes' semihosting reads (QEMU's
    // global lock held) starves: the sleep lets the main loop run (docs/lockstep.md).
    let mut tokens = qemu_append(opts)?;
    if matches!(port, PortDriver::External(_) | PortDriver::Script(_)) {
        tokens = format!("{tokens} {}", walker_contract::params::REALTIME_WORD);
    }
    if let Some(p) = &pipes {
        tokens = format!(
            "{tokens} {}={}",
            walker_contract::lockstep::PIPE_WORD,
            p.display()
        );
    }
    if !walker_contract::params::cmdline_fits(opts.elf.as_os_str().len(), tokens.len()) {
        return Err(format!(
            "the firmware command line with the board's words ({tokens}) is over the firmware's {}-byte semihosting buffer: use a shorter TMPDIR or ELF path",
            walker_contract::params::CMDLINE_MAX
        ));
    }
    crate::qemu::check_machine(&opts.elf, &opts.machine)?;
    which("qemu-system-arm").ok_or_else(|| {
        "qemu-system-arm not found: install it with `sudo apt-get install -y qemu-system-arm`"
            .to_string()
    })?;
    if !opts.elf.is_file() {
        return Err(format!(
            "firmware ELF {} not found: build it with `cargo build --release --no-default-features --features board-qemu --bin qemu`",
            opts.elf.display()
        ));
    }
    std::fs::create_dir_all(&opts.out_dir)
        .map_err(|e| format!("{}: {e}", opts.out_dir.display()))?;
    let log = opts.out_dir.join("walk.log");
    let truth = opts.out_dir.join("truth.csv");
    let defmt = opts.out_dir.join("firmware.defmt");
    let _ = std::fs::remove_file(&log);

    let mut cfg = opts.sim.clone();
    let uarts = pipes.is_none();
    if uarts {
        cfg.port = 0;
        cfg.lockstep_port = Some(0);
    }
    cfg.lockstep_pipe = pipes;
    cfg.connect = false;
    cfg.log_truth = Some(truth.clone());
    cfg.after_end_us = AFTER_END_US;
    cfg.after_truth = Some(opts.out_dir.join("truth-after.csv"));
    let handle = sim::spawn(cfg).map_err(|e| format!("simulator: {e}"))?;
    let tcp = |a: Option<std::net::SocketAddr>| a.map(|a| format!("tcp:{a},nodelay=on"));
    let (bus_serial, lockstep_serial) = (tcp(handle.bus_addr()), tcp(handle.lockstep_addr()));
    let defmt_file =
        std::fs::File::create(&defmt).map_err(|e| format!("{}: {e}", defmt.display()))?;
    // The command port (UART3): a socket the host owns, QEMU connects to it.
    let port_listener = match port {
        PortDriver::Script(_) => Some(
            std::net::TcpListener::bind("127.0.0.1:0").map_err(|e| format!("command port: {e}"))?,
        ),
        PortDriver::None | PortDriver::External(_) => None,
    };
    let port_serial = match (&port_listener, port) {
        (Some(l), _) => format!(
            "tcp:{},nodelay=on",
            l.local_addr().map_err(|e| format!("command port: {e}"))?
        ),
        (None, PortDriver::External(p)) => external_port_serial(p),
        (None, _) => "null".to_string(),
    };
    let started = Instant::now();
    // Over the pipes (`lockstep=PREFIX`) UART0 and UART2 are unconnected.
    let serials = crate::qemu::Serials {
        bus: bus_serial.unwrap_or_else(|| "null".into()),
        log: format!("file:{}", log.display()),
        lockstep: lockstep_serial,
        lockstep_pipes: !uarts,
        command: Some(port_serial),
    };
    let mut child = crate::qemu::command(&opts.elf, &opts.machine, &serials, &tokens)
        .stdin(Stdio::null())
        .stdout(Stdio::from(defmt_file))
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(|e| format!("starting QEMU: {e}"))?;
    let p = handle.progress();
    let quit = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let driver = match (&port_listener, port) {
        (Some(l), PortDriver::Script(s)) => {
            l.set_nonblocking(false).ok();
            let (stream, _) = l.accept().map_err(|e| format!("command port: {e}"))?;
            Some(crate::commands::spawn_driver(
                stream,
                s.clone(),
                handle.progress(),
                std::sync::Arc::clone(&quit),
            ))
        }
        _ => None,
    };
    let mut driver = driver;
    let mut drove: DriveOutcome = None;
    let exit_code = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status.code(),
            Ok(None) => {}
            Err(e) => return Err(format!("waiting for QEMU: {e}")),
        }
        // A command driver that gave up (the port stopped answering) would leave the firmware
        // waiting for commands until the wall-clock limit: end the run with its error.
        if driver.as_ref().is_some_and(|d| d.is_finished()) {
            let outcome = driver
                .take()
                .map(|d| d.join().unwrap_or_else(|_| Err("driver panicked".into())));
            if let Some(Err(e)) = &outcome {
                // The firmware may have ended first (a fall stops it) and closed the port under
                // the driver: then its exit ends the run, and the script counts as aborted.
                let until = Instant::now() + Duration::from_secs(2);
                let ended = loop {
                    match child.try_wait() {
                        Ok(Some(status)) => break Some(status.code()),
                        Ok(None) if Instant::now() < until => {
                            std::thread::sleep(Duration::from_millis(50));
                        }
                        _ => break None,
                    }
                };
                if let Some(code) = ended {
                    drove = Some(Err(aborted_under_script(code, e)));
                    break code;
                }
                let _ = child.kill();
                let _ = child.wait();
                handle.stop();
                return Err(format!("command driver: {e}"));
            }
            drove = outcome;
        }
        if started.elapsed() > opts.timeout {
            quit.store(true, std::sync::atomic::Ordering::Relaxed);
            let _ = child.kill();
            let _ = child.wait();
            handle.stop();
            let defmt = match decode_defmt(&opts.elf, &opts.out_dir) {
                Ok(l) => {
                    format!(
                        "its defmt output: {}",
                        opts.out_dir.join("firmware.log").display()
                    ) + &format!(" ({})", l.summary())
                }
                Err(e) => format!("its defmt output was not decoded: {e}"),
            };
            return Err(format!(
                "firmware did not finish within {:?} (wall clock); {defmt}",
                opts.timeout
            ));
        }
        progress(
            p.time_us.load(std::sync::atomic::Ordering::Relaxed) as f64 * 1e-6,
            p.instructions.load(std::sync::atomic::Ordering::Relaxed),
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    quit.store(true, std::sync::atomic::Ordering::Relaxed);
    if let Some(d) = driver {
        // QEMU has ended: a driver that failed meanwhile (the port closed under it) failed
        // because the firmware ended under the script, as above.
        drove = Some(match d.join() {
            Ok(Err(e)) if !e.contains("aborted") => Err(aborted_under_script(exit_code, &e)),
            Ok(r) => r,
            Err(_) => Err("driver panicked".into()),
        });
    }
    let summary = handle.join().map_err(|e| format!("simulator: {e}"))?;
    Ok((
        FilResult {
            exit_code,
            sim: summary,
            log,
            truth,
            wall: started.elapsed(),
            firmware_log: decode_defmt(&opts.elf, &opts.out_dir),
        },
        drove,
    ))
}

/// A command driver's error `e` when the firmware ended (exit `code`) under its script: the
/// script counts as aborted (a fall ends the firmware first).
fn aborted_under_script(code: Option<i32>, e: &str) -> String {
    format!("aborted: the firmware ended (exit code {code:?}) under the script ({e})")
}

/// QEMU's chardev of a command port listening on `127.0.0.1:port`: QEMU is the server, does not
/// wait for a client before the firmware starts, and accepts a new one after a disconnect.
fn external_port_serial(port: u16) -> String {
    format!("tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on")
}

/// One line about the simulator's run.
pub fn summary_line(s: &SimSummary) -> String {
    let mut out = String::new();
    let _ = write!(
        out,
        "simulated {:.2} s, {} instructions on the bus ({} dropped, {} corrupted), lock-step messages {}",
        s.sim_time_us as f64 * 1e-6,
        s.bus.instructions,
        s.bus.dropped,
        s.bus.corrupted,
        s.lockstep_messages
    );
    if let Some(t) = s.fall_started_us {
        let _ = write!(out, ", FELL at {:.2} s", t as f64 * 1e-6);
    }
    if let Some(e) = &s.end {
        let _ = write!(out, "; ended {e}");
    }
    out
}

fn which(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .find(|p| is_exe(p))
}

fn is_exe(p: &Path) -> bool {
    p.is_file()
}

/// What a command-script run did: its footsteps against the commands, and the torso's final
/// pose in the physics against the commanded one.
#[derive(Clone, Debug, PartialEq)]
pub struct CommandFigures {
    /// Footsteps against the commands integrated through the step limits.
    pub footsteps: crate::commands::FootstepCheck,
    /// When the truth first marked a fall, s.
    pub fell_at: Option<f64>,
    /// The commanded displacement: the commanded feet's midpoint after the last step (x, y,
    /// m) and their heading (rad), from the start (0, 0, 0) ([`FootstepCheck::commanded_feet`]).
    ///
    /// [`FootstepCheck::commanded_feet`]: crate::commands::FootstepCheck::commanded_feet
    pub commanded: [f64; 3],
    /// The torso's (pelvis) displacement in the physics from the first truth row to the last
    /// (x, y, m) and its heading change (rad).
    pub walked: [f64; 3],
}

impl CommandFigures {
    /// |walked − commanded| in the plane, m: how far the torso ended from the commanded place.
    pub fn position_error(&self) -> f64 {
        let [cx, cy, _] = self.commanded;
        let [wx, wy, _] = self.walked;
        (wx - cx).hypot(wy - cy)
    }

    /// [`Self::position_error`] over the commanded path length ([`FootstepCheck::path`]).
    ///
    /// [`FootstepCheck::path`]: crate::commands::FootstepCheck::path
    pub fn path_error(&self) -> f64 {
        self.position_error() / self.footsteps.path.max(1e-9)
    }

    /// [`Self::position_error`] over the commanded net displacement; `None` when that is
    /// under 1 cm (a script that comes back to its start).
    pub fn displacement_error(&self) -> Option<f64> {
        let [cx, cy, _] = self.commanded;
        let d = cx.hypot(cy);
        (d >= 0.01).then(|| self.position_error() / d)
    }

    /// walked − commanded heading, rad (wrapped to ±π).
    pub fn heading_error(&self) -> f64 {
        let d = self.walked[2] - self.commanded[2];
        d.sin().atan2(d.cos())
    }

    /// One line for the terminal.
    pub fn line(&self) -> String {
        format!(
            "{}; {} footsteps, {} not the commands'; commanded ({:.3} m, {:.3} m, {:+.1}°) over a {:.3} m path, torso ({:.3} m, {:.3} m, {:+.1}°): position error {:.3} m = {:.1} % of the path, {} of the net displacement; heading error {:+.1}° (heading hold turned {:+.1}°)",
            self.fell_at
                .map_or("no fall".to_string(), |t| format!("FELL at {t:.2} s")),
            self.footsteps.steps,
            self.footsteps.mismatches.len(),
            self.commanded[0],
            self.commanded[1],
            self.commanded[2].to_degrees(),
            self.footsteps.path,
            self.walked[0],
            self.walked[1],
            self.walked[2].to_degrees(),
            self.position_error(),
            100.0 * self.path_error(),
            self.displacement_error()
                .map_or("n/a".to_string(), |e| format!("{:.1} %", 100.0 * e)),
            self.heading_error().to_degrees(),
            self.footsteps.turned.to_degrees()
        )
    }
}

/// When a truth table first marks a fall (its `falling` column), s.
pub fn fell_at(table: &crate::report::TruthTable) -> Result<Option<f64>, String> {
    let falling = table.column("falling").ok_or("truth: no column falling")?;
    Ok(falling
        .iter()
        .zip(&table.t)
        .find(|(f, _)| **f > 0.5)
        .map(|(_, t)| *t))
}

/// The figures of a command-script run: the log's footsteps replayed
/// ([`crate::commands::replay_footsteps`], with the firmware's own configuration of the run:
/// [`check_tokens`]) and the truth's pelvis pose.
pub fn command_figures(
    r: &FilResult,
    spec: &WalkSpec,
    extra: &[String],
) -> Result<CommandFigures, String> {
    let mut extra = extra.to_vec();
    extra.push("autostart=0".into());
    let (_, cfg) = check_tokens(spec, &extra)?;
    let log = crate::report::decode_file(&r.log)?;
    let footsteps = crate::commands::replay_footsteps(
        &log.events,
        cfg.robot,
        cfg.walk.z_c,
        cfg.walk.step_width as f32,
    )?;
    let [l, rt] = footsteps.commanded_feet;
    let mid = |a: f32, b: f32| 0.5 * (f64::from(a) + f64::from(b));
    let yaw = {
        let d = f64::from(rt.yaw - l.yaw);
        f64::from(l.yaw) + 0.5 * d.sin().atan2(d.cos())
    };
    let commanded = [mid(l.x, rt.x), mid(l.y, rt.y), yaw];
    let table = crate::report::read_truth(&r.truth)?;
    let col = |n: &str| {
        table
            .column(n)
            .ok_or_else(|| format!("truth: no column {n}"))
    };
    let (px, py, pyaw) = (
        col("pelvis_x_m")?,
        col("pelvis_y_m")?,
        col("pelvis_yaw_rad")?,
    );
    let first_last = |c: &[f64]| -> Result<(f64, f64), String> {
        match (c.first(), c.last()) {
            (Some(a), Some(b)) => Ok((*a, *b)),
            _ => Err("truth: empty".into()),
        }
    };
    let (x0, x1) = first_last(px)?;
    let (y0, y1) = first_last(py)?;
    let (w0, w1) = first_last(pyaw)?;
    let dyaw = w1 - w0;
    let fell_at = fell_at(&table)?;
    Ok(CommandFigures {
        footsteps,
        fell_at,
        commanded,
        walked: [x1 - x0, y1 - y0, dyaw.sin().atan2(dyaw.cos())],
    })
}

/// What the physics says of a walk: did the robot fall, how far did it go, how straight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WalkFigures {
    /// When the truth first marked a fall, s.
    pub fell_at: Option<f64>,
    /// Pelvis travel along x from the first to the last truth row, m, less the whole-body
    /// compensation's offset of the pelvis from the CoM at the end (0 without it).
    pub walked: f64,
    /// The plan's CoM travel along x, m.
    pub planned: f64,
    /// Pelvis yaw at the end minus at the start, rad.
    pub heading_drift: f64,
    /// Largest torso tilt from the vertical, rad.
    pub max_tilt: f64,
}

impl WalkFigures {
    /// One line for the terminal and the reports.
    pub fn line(&self) -> String {
        format!(
            "{}; walked {:.3} m of {:.3} m planned ({:.0} %); heading drift {:+.1}°; torso tilt up to {:.1}°",
            self.fell_at
                .map_or("no fall".to_string(), |t| format!("FELL at {t:.2} s")),
            self.walked,
            self.planned,
            100.0 * self.walked / self.planned,
            self.heading_drift.to_degrees(),
            self.max_tilt.to_degrees()
        )
    }
}

/// How far ahead of the plan's CoM whole-body compensation puts the pelvis at the plan's last
/// sample, m (0 without it): the simulated robot starts from the uncompensated pose, so the
/// pelvis travels this much further than the whole body's CoM it places on the plan's.
fn compensation_offset(spec: &WalkSpec, last: &gait_core::GaitSample<f64>) -> f64 {
    match spec.compensation {
        crate::planfile::CompensationName::None => 0.0,
        crate::planfile::CompensationName::Wholebody => {
            let wb = gait_core::kinematics::wholebody::WholeBody::<f64>::new(
                spec.robot(),
                gait_core::gait::WHOLEBODY_ITERATIONS,
            );
            wb.joint_targets(last).pelvis.x - last.com[0]
        }
    }
}

/// Reads the walk's figures off the simulator's truth CSV and the plan: the pelvis's travel
/// (less the whole-body compensation's offset) against the plan's CoM travel.
pub fn walk_figures(truth: &Path, spec: &WalkSpec) -> Result<WalkFigures, String> {
    walk_figures_of(&crate::report::read_truth(truth)?, truth, spec)
}

/// [`walk_figures`] of a truth table already read from `truth` (named in errors).
pub fn walk_figures_of(
    table: &crate::report::TruthTable,
    truth: &Path,
    spec: &WalkSpec,
) -> Result<WalkFigures, String> {
    let col = |n: &str| {
        table
            .column(n)
            .ok_or_else(|| format!("{}: no `{n}` column", truth.display()))
    };
    let (x, yaw, falling, tilt) = (
        col("pelvis_x_m")?,
        col("pelvis_yaw_rad")?,
        col("falling")?,
        col("fall_angle_rad")?,
    );
    let ends = |v: &[f64]| Some((*v.first()?, *v.last()?));
    let ((x0, x1), (yaw0, yaw1)) = ends(x)
        .zip(ends(yaw))
        .ok_or_else(|| format!("{}: no rows", truth.display()))?;
    let fell_at = falling
        .iter()
        .position(|f| *f == 1.0)
        .and_then(|i| table.t.get(i).copied());
    let max_tilt = tilt
        .iter()
        .copied()
        .filter(|a| a.is_finite())
        .fold(0.0, f64::max);
    let (first, last) = ((x0, yaw0), (x1, yaw1));
    let mut s = spec
        .sampler(spec.robot(), spec.dt)
        .map_err(|e| e.to_string())?;
    let first_sample = s.next(0.0);
    let mut last_sample = first_sample;
    while !s.is_done() {
        last_sample = s.next(0.0);
    }
    let (start, end) = (first_sample.com[0], last_sample.com[0]);
    Ok(WalkFigures {
        fell_at,
        walked: last.0 - first.0 - compensation_offset(spec, &last_sample),
        planned: end - start,
        heading_drift: last.1 - first.1,
        max_tilt,
    })
}

/// Where the soles really went (the truth's sole columns): how far each travelled against the
/// plan, and how far a loaded sole slid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoleFigures {
    /// Each sole's travel along x from the first to the last truth row (left, right), m.
    pub travel: [f64; 2],
    /// The plan's travel of each foot along x (left, right), m.
    pub planned: [f64; 2],
    /// The largest horizontal displacement of a sole within one stretch of rows where it
    /// carries at least [`LOADED_SHARE`] of the feet's vertical force, m.
    pub max_slip: f64,
}

/// Share of the feet's vertical force from which a sole counts as loaded (for the slip).
pub const LOADED_SHARE: f64 = 0.2;

impl SoleFigures {
    /// One line for the terminal.
    pub fn line(&self) -> String {
        let pct = |a: f64, p: f64| {
            if p.abs() > 1e-9 {
                format!("{:+.0} %", 100.0 * (a - p) / p)
            } else {
                "n/a".into()
            }
        };
        format!(
            "soles travelled {:.3} m (left) and {:.3} m (right) for {:.3} / {:.3} m planned ({}, {}); a loaded sole slid at most {:.1} mm",
            self.travel[0],
            self.travel[1],
            self.planned[0],
            self.planned[1],
            pct(self.travel[0], self.planned[0]),
            pct(self.travel[1], self.planned[1]),
            1e3 * self.max_slip
        )
    }
}

/// The soles' figures of a truth table (`None` when it has no sole columns: an older file) and
/// the plan's feet's travel `planned` (left, right; m).
pub fn sole_figures(table: &crate::report::TruthTable, planned: [f64; 2]) -> Option<SoleFigures> {
    let col = |n: &str| table.column(n);
    let (lx, ly, rx, ry) = (col("l_x_m")?, col("l_y_m")?, col("r_x_m")?, col("r_y_m")?);
    let (lf, rf) = (col("l_fz_n")?, col("r_fz_n")?);
    let travel = |x: &[f64]| match (x.first(), x.last()) {
        (Some(a), Some(b)) => b - a,
        _ => 0.0,
    };
    let mut max_slip = 0.0f64;
    for (x, y, f, g) in [(lx, ly, lf, rf), (rx, ry, rf, lf)] {
        let mut start: Option<(f64, f64)> = None;
        for i in 0..x.len().min(y.len()).min(f.len()).min(g.len()) {
            let total = f[i] + g[i];
            let loaded = total > 0.0 && f[i] >= LOADED_SHARE * total;
            match (loaded, start) {
                (true, None) => start = Some((x[i], y[i])),
                (true, Some((x0, y0))) => {
                    let d = (x[i] - x0).hypot(y[i] - y0);
                    if d.is_finite() {
                        max_slip = max_slip.max(d);
                    }
                }
                (false, _) => start = None,
            }
        }
    }
    Some(SoleFigures {
        travel: [travel(lx), travel(rx)],
        planned,
        max_slip,
    })
}

/// The plan's travel of each foot along x (left, right), m.
pub fn planned_feet_travel(spec: &WalkSpec) -> Result<[f64; 2], String> {
    let mut s = spec
        .sampler(spec.robot(), spec.dt)
        .map_err(|e| e.to_string())?;
    let first = s.next(0.0).feet;
    let mut last = first;
    while !s.is_done() {
        last = s.next(0.0).feet;
    }
    Ok([last[0].x - first[0].x, last[1].x - first[1].x])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_tokens_keep_each_key_once_and_the_later_value() {
        let t = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let (out, replaced) = merge_tokens(t(&[
            "lockstep",
            "t1=0.15",
            "stab=off",
            "autostart=1",
            "t1=0.2",
            "autostart=0",
            "stab=off",
        ]));
        assert_eq!(out, t(&["lockstep", "t1=0.2", "stab=off", "autostart=0"]));
        assert_eq!(
            replaced,
            vec![
                ("t1=0.15".to_string(), "t1=0.2".to_string()),
                ("autostart=1".to_string(), "autostart=0".to_string())
            ]
        );
        // The merged line passes the firmware's parser, which refuses the unmerged one.
        let spec = WalkSpec::default();
        let extra = t(&["t1=0.14", "autostart=0"]);
        let (tokens, cfg) = check_tokens(&spec, &extra).unwrap();
        assert_eq!(tokens.iter().filter(|t| t.starts_with("t1=")).count(), 1);
        assert_eq!(cfg.walk.t1, 0.14);
        assert!(!cfg.autostart);
        let mut raw = vec!["lockstep".to_string()];
        raw.extend(firmware_tokens(&spec).unwrap());
        raw.extend(extra.iter().cloned());
        let e = walker_contract::params::apply(
            &mut walker_contract::Config::default(),
            raw.join(" ").as_bytes(),
        )
        .unwrap_err();
        assert_eq!(e.kind, walker_contract::params::ArgErrorKind::Repeated);
        assert!(
            token_error(&e, &raw).contains("given twice"),
            "{}",
            token_error(&e, &raw)
        );
        let w = token_overrides(&spec, &extra);
        assert!(
            w.iter().any(|l| l.starts_with("`t1=0.14` replaces `t1=")),
            "{w:?}"
        );
    }

    #[test]
    fn sole_figures_measure_the_travel_and_the_slip_of_a_loaded_sole() {
        use std::collections::BTreeMap;
        // The left sole stands loaded and slides 3 mm along y, then lifts (unloaded), moves
        // 5 cm and lands loaded again; the right sole stands loaded at 0.01 m all along.
        let n = 10;
        let mut c: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        let lx: Vec<f64> = (0..n).map(|i| if i < 5 { 0.0 } else { 0.05 }).collect();
        let ly: Vec<f64> = (0..n)
            .map(|i| if i < 4 { 0.001 * i as f64 } else { 0.003 })
            .collect();
        let lf: Vec<f64> = (0..n)
            .map(|i| if i == 4 || i == 5 { 1.0 } else { 20.0 })
            .collect();
        c.insert("l_x_m".into(), lx);
        c.insert("l_y_m".into(), ly);
        c.insert("l_fz_n".into(), lf);
        c.insert("r_x_m".into(), vec![0.01; n]);
        c.insert("r_y_m".into(), vec![-0.09; n]);
        c.insert("r_fz_n".into(), vec![20.0; n]);
        let t = crate::report::TruthTable {
            t: (0..n).map(|i| i as f64 * 0.01).collect(),
            zmp: vec![[0.0; 2]; n],
            columns: c,
        };
        let f = sole_figures(&t, [0.04, 0.0]).unwrap();
        assert!((f.travel[0] - 0.05).abs() < 1e-12 && f.travel[1] == 0.0);
        // The 3 mm slide counts, the 5 cm swing (unloaded: 1 N of 21) does not.
        assert!((f.max_slip - 0.003).abs() < 1e-12, "{}", f.max_slip);
        assert!(f.line().contains("+25 %"), "{}", f.line());
        // An older truth file without the sole columns: no figures.
        let mut old = t.clone();
        old.columns.remove("l_x_m");
        assert_eq!(sole_figures(&old, [0.04, 0.0]), None);
    }

    #[test]
    fn command_figures_measure_the_end_pose_against_the_commanded_one() {
        let f = CommandFigures {
            footsteps: crate::commands::FootstepCheck {
                path: 0.5,
                ..Default::default()
            },
            fell_at: None,
            commanded: [0.3, 0.4, 170f64.to_radians()],
            walked: [0.33, 0.44, -170f64.to_radians()],
        };
        // (0.03, 0.04) off: 0.05 m, 10 % of the 0.5 m path and of the 0.5 m displacement.
        assert!((f.position_error() - 0.05).abs() < 1e-12);
        assert!((f.path_error() - 0.10).abs() < 1e-12);
        assert!((f.displacement_error().unwrap() - 0.10).abs() < 1e-12);
        // −170° − 170° wraps to +20°.
        assert!((f.heading_error().to_degrees() - 20.0).abs() < 1e-9);
        let back = CommandFigures {
            commanded: [0.004, -0.003, 0.0],
            ..f.clone()
        };
        assert_eq!(
            back.displacement_error(),
            None,
            "no ratio to a 5 mm displacement"
        );
        assert!(
            back.line().contains("n/a of the net displacement"),
            "{}",
            back.line()
        );
    }

    fn opts(elf: &str, extra: Vec<String>) -> FilOptions {
        FilOptions {
            elf: PathBuf::from(elf),
            spec: WalkSpec::default(),
            out_dir: PathBuf::from("unused"),
            machine: "mps2-an500".into(),
            timeout: Duration::from_secs(1),
            sim: SimConfig::default(),
            extra_tokens: extra,
        }
    }

    #[test]
    fn the_command_line_must_fit_the_firmware_buffer() {
        // Table 2's tokens fit with room to spare.
        let base = qemu_append(&opts("fw.elf", vec![])).unwrap();
        assert!(base.starts_with("lockstep "), "{base}");
        let room = walker_contract::params::CMDLINE_MAX - 2 - "fw.elf".len() - base.len();
        assert!(room > 300, "{room}");
        // Exactly full: ELF path + space + text + NUL = 1024 bytes (`pad(n)` adds n bytes: a
        // space and an (n − 1)-byte token).
        let pad = |n: usize| vec![format!("x={}", "9".repeat(n - 3))];
        let full = opts("fw.elf", pad(room));
        let text = qemu_append(&full).unwrap();
        assert_eq!("fw.elf".len() + 1 + text.len() + 1, 1024);
        // One byte more is refused, naming the sizes; so is a longer ELF path.
        let e = qemu_append(&opts("fw.elf", pad(room + 1))).unwrap_err();
        assert!(e.contains("1025 bytes") && e.contains("1024-byte"), "{e}");
        assert!(qemu_append(&opts("/x/fw.elf", pad(room))).is_err());
    }
}
