//! Log capture from the firmware's log UART (or a saved capture file).
//!
//! The firmware writes its ZMP-response log as binary COBS frames on a log sink (see
//! `walker_contract::record`): on the OpenCR board a UART at 921 600 baud (or USB CDC), in QEMU a
//! CMSDK UART that QEMU writes to a file or pipe. The records never go through defmt, so
//! `defmt-print` output from probe-rs/RTT carries only the firmware's debug text, not the log:
//! capture the UART (this command) or decode the QEMU serial file with `--from-file`.
//!
//! The serial port is opened with `open(2)` and configured raw with `termios` (libc): 8N1, no
//! flow control, `VMIN = 0`, `VTIME = 1` (reads return after 100 ms of silence). Standard
//! Linux rates up to 4 Mbaud are accepted (921 600 is `B921600`).
//!
//! The raw stream is written unchanged to `--out` (so it can be decoded again later) and the
//! decoded ticks to the same path with the extension `.csv`.

use crate::report::{tick_rows, write_events_csv, write_response_csv, DecodedLog, LogCollector};
use std::fs::File;
use std::io::{Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::os::unix::io::AsRawFd;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The termios speed constant for a baud rate.
pub fn baud_constant(baud: u32) -> Option<libc::speed_t> {
    Some(match baud {
        9600 => libc::B9600,
        19200 => libc::B19200,
        38400 => libc::B38400,
        57600 => libc::B57600,
        115200 => libc::B115200,
        230400 => libc::B230400,
        460800 => libc::B460800,
        500000 => libc::B500000,
        576000 => libc::B576000,
        921600 => libc::B921600,
        1000000 => libc::B1000000,
        1152000 => libc::B1152000,
        1500000 => libc::B1500000,
        2000000 => libc::B2000000,
        2500000 => libc::B2500000,
        3000000 => libc::B3000000,
        3500000 => libc::B3500000,
        4000000 => libc::B4000000,
        _ => return None,
    })
}

/// Opens `port` raw at `baud`.
pub fn open_serial(port: &Path, baud: u32) -> Result<File, String> {
    let speed = baud_constant(baud).ok_or_else(|| {
        format!("unsupported baud rate {baud} (use a standard rate such as 115200, 460800, 921600, 1000000, 2000000)")
    })?;
    if !port.exists() {
        return Err(format!("serial port {} not found (is the board plugged in? see `ls /dev/ttyUSB* /dev/ttyACM*`)", port.display()));
    }
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(libc::O_NOCTTY)
        .open(port)
        .map_err(|e| format!("cannot open serial port {}: {e}", port.display()))?;
    let fd = file.as_raw_fd();
    // SAFETY: `fd` is a valid open descriptor owned by `file` for the whole block; `tio` is a
    // plain C struct fully initialised by tcgetattr before use.
    unsafe {
        let mut tio: libc::termios = std::mem::zeroed();
        if libc::tcgetattr(fd, &mut tio) != 0 {
            return Err(format!(
                "{} is not a serial port: {}",
                port.display(),
                std::io::Error::last_os_error()
            ));
        }
        libc::cfmakeraw(&mut tio);
        tio.c_cflag |= libc::CLOCAL | libc::CREAD;
        tio.c_cflag &= !(libc::CSTOPB | libc::PARENB | libc::CRTSCTS);
        tio.c_iflag &= !(libc::IXON | libc::IXOFF | libc::IXANY);
        tio.c_cc[libc::VMIN] = 0;
        tio.c_cc[libc::VTIME] = 1;
        if libc::cfsetispeed(&mut tio, speed) != 0 || libc::cfsetospeed(&mut tio, speed) != 0 {
            return Err(format!("cannot set {baud} baud on {}", port.display()));
        }
        if libc::tcsetattr(fd, libc::TCSANOW, &tio) != 0 {
            return Err(format!(
                "cannot configure {}: {}",
                port.display(),
                std::io::Error::last_os_error()
            ));
        }
        libc::tcflush(fd, libc::TCIFLUSH);
    }
    Ok(file)
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_sigint(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

fn install_sigint() {
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe {
        libc::signal(libc::SIGINT, on_sigint as *const () as libc::sighandler_t);
    }
}

/// Options of a capture.
#[derive(Clone, Debug)]
pub struct CaptureOptions {
    /// Serial device.
    pub port: PathBuf,
    /// Baud rate.
    pub baud: u32,
    /// Raw output file.
    pub out: PathBuf,
    /// Stop after this long (None: until Ctrl-C).
    pub seconds: Option<f64>,
}

/// The CSV path beside a raw capture (`walk.log` → `walk.csv`).
pub fn csv_path(raw: &Path) -> PathBuf {
    raw.with_extension("csv")
}

/// The events CSV path beside a raw capture (`walk.log` → `walk.events.csv`).
pub fn events_path(raw: &Path) -> PathBuf {
    raw.with_extension("events.csv")
}

fn create_parent(p: &Path) -> Result<(), String> {
    if let Some(d) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).map_err(|e| format!("cannot create {}: {e}", d.display()))?;
    }
    Ok(())
}

/// Writes the decoded CSVs of a log beside `raw`; returns their paths.
pub fn write_decoded(log: &DecodedLog, raw: &Path) -> Result<Vec<PathBuf>, String> {
    let csv = csv_path(raw);
    let mut buf = Vec::new();
    write_response_csv(&tick_rows(&log.ticks), &mut buf).map_err(|e| e.to_string())?;
    std::fs::write(&csv, buf).map_err(|e| format!("cannot write {}: {e}", csv.display()))?;
    let ev = events_path(raw);
    let mut buf = Vec::new();
    write_events_csv(&log.events, &mut buf).map_err(|e| e.to_string())?;
    std::fs::write(&ev, buf).map_err(|e| format!("cannot write {}: {e}", ev.display()))?;
    Ok(vec![csv, ev])
}

/// Reads any byte source into `out` while decoding, until `deadline`, Ctrl-C or end of input
/// (a serial port returns 0 bytes on a read timeout: with `tty` such reads do not end it).
pub fn capture_stream(
    mut src: impl Read,
    tty: bool,
    out: &mut impl Write,
    deadline: Option<Instant>,
    mut progress: impl FnMut(&LogCollector),
) -> Result<DecodedLog, String> {
    let mut col = LogCollector::new();
    let mut buf = [0u8; 4096];
    let mut last_report = Instant::now();
    loop {
        if STOP.load(Ordering::SeqCst) || deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
        match src.read(&mut buf) {
            Ok(0) => {
                if !tty {
                    break;
                }
            }
            Ok(n) => {
                out.write_all(&buf[..n])
                    .map_err(|e| format!("cannot write the capture: {e}"))?;
                col.feed(&buf[..n]);
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(format!("read error: {e}")),
        }
        if last_report.elapsed() >= Duration::from_secs(1) {
            progress(&col);
            last_report = Instant::now();
        }
    }
    out.flush()
        .map_err(|e| format!("cannot write the capture: {e}"))?;
    Ok(col.finish())
}

/// Captures from the serial port (see the module docs).
pub fn capture(opts: &CaptureOptions) -> Result<DecodedLog, String> {
    let port = open_serial(&opts.port, opts.baud)?;
    create_parent(&opts.out)?;
    let mut out = File::create(&opts.out)
        .map_err(|e| format!("cannot create {}: {e}", opts.out.display()))?;
    install_sigint();
    let deadline = opts
        .seconds
        .map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    eprintln!(
        "capturing {} at {} baud into {}{}",
        opts.port.display(),
        opts.baud,
        opts.out.display(),
        opts.seconds
            .map_or(" (Ctrl-C to stop)".to_string(), |s| format!(" for {s} s"))
    );
    let log = capture_stream(port, true, &mut out, deadline, |c| {
        let l = c.log();
        eprint!(
            "\r{} bytes, {} ticks, {} events   ",
            l.bytes,
            l.ticks.len(),
            l.events.len()
        );
    })?;
    eprintln!();
    write_decoded(&log, &opts.out)?;
    Ok(log)
}

/// Decodes a saved capture and writes its CSVs beside `out` (or beside the capture).
pub fn from_file(input: &Path, out: Option<&Path>) -> Result<(DecodedLog, Vec<PathBuf>), String> {
    let bytes =
        std::fs::read(input).map_err(|e| format!("cannot read {}: {e}", input.display()))?;
    let log = crate::report::decode_bytes(&bytes);
    let target = out.unwrap_or(input);
    create_parent(target)?;
    if let Some(o) = out {
        if o != input {
            std::fs::write(o, &bytes).map_err(|e| format!("cannot write {}: {e}", o.display()))?;
        }
    }
    let files = write_decoded(&log, target)?;
    Ok((log, files))
}
