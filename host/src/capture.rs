//! Log capture from the firmware's log UART (or a saved capture file).
//!
//! The firmware writes its ZMP-response log as binary COBS frames on a log sink (see
//! `walker_contract::record`): on the OpenCR board a UART at 921 600 baud (or USB CDC), in QEMU a
//! CMSDK UART that QEMU writes to a file or pipe. The records never go through defmt, so
//! `defmt-print` output from probe-rs/RTT carries only the firmware's debug text, not the log:
//! capture the UART (this command) or decode the QEMU serial file with `--from-file`. A raw
//! defmt stream saved from the firmware is decoded by `walker capture --defmt FILE --elf ELF`
//! ([`crate::defmt_log`]).
//!
//! The serial port is opened with the `serialport` crate (Linux, macOS, Windows): 8N1, no flow
//! control, any baud rate the driver accepts (921 600 by default), reads returning after 100 ms
//! of silence; `walker capture --list` lists the ports it finds. Ctrl-C (`ctrlc`), `--seconds`,
//! a hang-up (the USB adapter unplugged, the pseudo-terminal's other end closed) or a read
//! error all end the capture the same way: what was read is kept and its CSVs are written.
//!
//! The raw stream is written unchanged to `--out` (so it can be decoded again later) and the
//! decoded ticks to the same path with the extension `.csv`.

use crate::progress::{StatusLine, STATUS_EVERY};
use crate::report::{tick_rows, write_events_csv, write_response_csv, DecodedLog, LogCollector};
use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The longest `--seconds` accepted (a year): beyond it a deadline is meaningless.
pub const MAX_SECONDS: f64 = 365.0 * 24.0 * 3600.0;

/// Opens `port` (a device path, or `COM3` on Windows) at `baud`, 8N1, no flow control.
pub fn open_serial(port: &str, baud: u32) -> Result<Box<dyn serialport::SerialPort>, String> {
    if baud == 0 {
        return Err("baud rate 0: give the log UART's rate, e.g. 921600".into());
    }
    if cfg!(unix) && !Path::new(port).exists() {
        return Err(format!(
            "serial port {port} not found (is the board plugged in? `walker capture --list` lists the ports)"
        ));
    }
    serialport::new(port, baud)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(serialport::FlowControl::None)
        .timeout(Duration::from_millis(100))
        .open()
        .map_err(|e| match e.kind() {
            serialport::ErrorKind::NoDevice => format!(
                "serial port {port} not found or busy: {e} (`walker capture --list` lists the ports)"
            ),
            _ => format!("cannot open serial port {port} at {baud} baud: {e}"),
        })
}

/// The serial ports the system reports, one line each (`name  kind`).
pub fn list_ports() -> Result<Vec<String>, String> {
    let ports =
        serialport::available_ports().map_err(|e| format!("cannot list serial ports: {e}"))?;
    Ok(ports
        .into_iter()
        .map(|p| {
            let kind = match p.port_type {
                serialport::SerialPortType::UsbPort(u) => format!(
                    "USB {:04x}:{:04x}{}{}",
                    u.vid,
                    u.pid,
                    u.manufacturer.map(|m| format!(" {m}")).unwrap_or_default(),
                    u.product.map(|m| format!(" {m}")).unwrap_or_default()
                ),
                serialport::SerialPortType::PciPort => "PCI".into(),
                serialport::SerialPortType::BluetoothPort => "Bluetooth".into(),
                serialport::SerialPortType::Unknown => "unknown".into(),
            };
            format!("{}  {kind}", p.port_name)
        })
        .collect())
}

static STOP: AtomicBool = AtomicBool::new(false);

/// Makes Ctrl-C end a capture cleanly (once per process; later calls are no-ops).
fn install_ctrlc() -> Result<(), String> {
    static ONCE: std::sync::Once = std::sync::Once::new();
    let mut res = Ok(());
    ONCE.call_once(|| {
        res = ctrlc::set_handler(|| STOP.store(true, Ordering::SeqCst))
            .map_err(|e| format!("cannot install the Ctrl-C handler: {e}"));
    });
    res
}

/// How a capture ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CaptureEnd {
    /// `--seconds` elapsed.
    Deadline,
    /// Ctrl-C.
    Interrupted,
    /// End of input (a file), or the port hung up.
    HangUp,
    /// A read error (the message).
    Error(String),
}

impl std::fmt::Display for CaptureEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CaptureEnd::Deadline => f.write_str("time is up"),
            CaptureEnd::Interrupted => f.write_str("stopped by Ctrl-C"),
            CaptureEnd::HangUp => f.write_str("the port hung up (end of input)"),
            CaptureEnd::Error(e) => write!(f, "read error: {e}"),
        }
    }
}

/// Options of a capture.
#[derive(Clone, Debug)]
pub struct CaptureOptions {
    /// Serial device (a path, or `COM3` on Windows).
    pub port: String,
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

/// Reads any byte source into `out` while decoding, until `deadline`, Ctrl-C, end of input or
/// an error; returns the log and how it ended. A read that times out (`TimedOut`,
/// `WouldBlock`) only means silence on the line; with `tty`, a read of 0 bytes does too.
pub fn capture_stream(
    mut src: impl Read,
    tty: bool,
    out: &mut impl Write,
    deadline: Option<Instant>,
    mut progress: impl FnMut(&LogCollector),
) -> Result<(DecodedLog, CaptureEnd), String> {
    use std::io::ErrorKind;
    let mut col = LogCollector::new();
    let mut buf = [0u8; 4096];
    let mut last_report = Instant::now();
    let end = loop {
        if STOP.load(Ordering::SeqCst) {
            break CaptureEnd::Interrupted;
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            break CaptureEnd::Deadline;
        }
        match src.read(&mut buf) {
            Ok(0) if !tty => break CaptureEnd::HangUp,
            Ok(0) => {}
            Ok(n) => {
                out.write_all(&buf[..n])
                    .map_err(|e| format!("cannot write the capture: {e}"))?;
                col.feed(&buf[..n]);
            }
            Err(e) if matches!(e.kind(), ErrorKind::Interrupted) => continue,
            Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::WouldBlock) => {}
            Err(e) if matches!(e.kind(), ErrorKind::BrokenPipe | ErrorKind::UnexpectedEof) => {
                break CaptureEnd::HangUp
            }
            // EIO: a pseudo-terminal whose other end closed, a USB adapter unplugged.
            Err(e) if e.raw_os_error() == Some(5) => break CaptureEnd::HangUp,
            Err(e) => break CaptureEnd::Error(e.to_string()),
        }
        if last_report.elapsed() >= Duration::from_secs(1) {
            progress(&col);
            last_report = Instant::now();
        }
    };
    out.flush()
        .map_err(|e| format!("cannot write the capture: {e}"))?;
    Ok((col.finish(), end))
}

/// Captures from the serial port (see the module docs); the CSVs are written however the
/// capture ends.
pub fn capture(opts: &CaptureOptions) -> Result<(DecodedLog, CaptureEnd), String> {
    let port = open_serial(&opts.port, opts.baud)?;
    create_parent(&opts.out)?;
    let mut out = File::create(&opts.out)
        .map_err(|e| format!("cannot create {}: {e}", opts.out.display()))?;
    install_ctrlc()?;
    let deadline = match opts.seconds {
        Some(s) if s.is_finite() && s > 0.0 && s <= MAX_SECONDS => {
            Some(Instant::now() + Duration::from_secs_f64(s))
        }
        Some(s) => return Err(format!("--seconds {s}: not in (0, {MAX_SECONDS}]")),
        None => None,
    };
    eprintln!(
        "capturing {} at {} baud into {}{}",
        opts.port,
        opts.baud,
        opts.out.display(),
        opts.seconds
            .map_or(" (Ctrl-C to stop)".to_string(), |s| format!(" for {s} s"))
    );
    let status = StatusLine::stderr(STATUS_EVERY);
    let waiting = |since: Instant| {
        format!(
            "waiting for the first byte on {} ({} so far) …",
            opts.port,
            crate::progress::human(since.elapsed())
        )
    };
    let started = Instant::now();
    status.set(&waiting(started));
    let captured = capture_stream(port, true, &mut out, deadline, |c| {
        let l = c.log();
        status.set(&match l.bytes {
            0 => waiting(started),
            b => format!(
                "{b} bytes, {} ticks, {} events",
                l.ticks.len(),
                l.events.len()
            ),
        });
    });
    status.finish();
    let (log, end) = captured?;
    eprintln!("capture ended: {end}");
    write_decoded(&log, &opts.out)?;
    Ok((log, end))
}

/// Decodes a saved capture and writes its CSVs beside `out` (or beside the capture); the
/// reader's warnings. A capture that [`crate::report::check_log`] refuses (empty, garbage, no
/// start-up or no tick record) is an error and nothing is written.
pub fn from_file(
    input: &Path,
    out: Option<&Path>,
) -> Result<(DecodedLog, Vec<PathBuf>, Vec<String>), String> {
    let bytes =
        std::fs::read(input).map_err(|e| format!("cannot read {}: {e}", input.display()))?;
    let log = crate::report::decode_bytes(&bytes);
    let warnings = crate::report::check_log(&log, input)?;
    let target = out.unwrap_or(input);
    create_parent(target)?;
    if let Some(o) = out {
        if o != input {
            std::fs::write(o, &bytes).map_err(|e| format!("cannot write {}: {e}", o.display()))?;
        }
    }
    let files = write_decoded(&log, target)?;
    Ok((log, files, warnings))
}
