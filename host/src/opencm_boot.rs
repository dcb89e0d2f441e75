//! The host side of ROBOTIS' OpenCM 9.04 USB bootloader: `walker flash --board opencm` without
//! an SWD probe.
//!
//! The OpenCM 9.04 (STM32F103CB, 128 KiB flash in 1 KiB pages) ships with a 12 KiB bootloader
//! at 0x0800_0000 that takes an image over its USB CDC port and programs it from 0x0800_3000.
//! ROBOTIS' host tool for it is `opencm9.04_ld` (the Arduino core's upload tool, called as
//! `opencm9.04_ld PORT 57600 IMAGE.bin 1 opencm`); this module speaks the same protocol.
//!
//! # Protocol
//!
//! Text commands, one per USB packet, answered by lines that end in `\n`; the image goes as
//! raw bytes. The bootloader takes a packet as a command when it is longer than 3 bytes with
//! `A` first and `&` third (`AT&LD`, `AT&GO`, `AT&NAME`, ...; `AT` alone answers `OK`).
//!
//! - Entering the bootloader: at reset it stays in its command loop when the reset was a
//!   watchdog reset (RCC_CSR IWDGRSTF) or the USER button (PC15, high while pressed) is held;
//!   otherwise it jumps to the image at once. An Arduino sketch of ROBOTIS' core resets by
//!   its watchdog when the host sets the line to 1200 baud or when the first USB packet after
//!   the port is opened starts with `CM9` (the loader sends `CM9X`, closes the port, waits
//!   1 s and opens it again). The walker firmware has no USB stack: hold USER while plugging
//!   the USB cable in (or while resetting). [`request_bootloader`] does the sketch's reset
//!   request anyway; the bootloader ignores it.
//! - `AT&NAME\n` → `CM-904\n`. On V1.03 the command loop starts by printing a banner and the
//!   prompt `\r\n-` without a newline, so the first answer reads `-CM-904` (the loader looks
//!   for lines starting `-`): answers are matched by their end here.
//! - `AT&LD` → the bootloader erases 0x0800_3000..=0x0801_F7FF (114 pages of 1 KiB; the last
//!   2 KiB of flash, 0x0801_F800.., are not erased: the bootloader keeps its control table
//!   there, `AT&CTRST` resets it), then answers `Ready..\n`, starts a 1 ms timer, waits 100 ms
//!   (and on V1.03 for the first packet), and takes every USB packet as image bytes: it
//!   programs them as little-endian words at consecutive addresses from 0x0800_3000, reads
//!   each word back, and adds the bytes to an 8-bit sum. The download ends when no packet has
//!   come for more than 16 ms. The last byte of the last packet is the host's checksum: the
//!   sum of the image bytes modulo 256. The bootloader answers `Success..\n` when its sum of the
//!   other bytes equals it (or when that byte is `*`, a wildcard) and `Fail..\n` otherwise.
//! - `AT&GO` → no answer: the bootloader disconnects USB and jumps to the reset vector at
//!   0x0800_3004 (it loads neither the stack pointer from 0x0800_3000 nor VTOR).
//!
//! `opencm9.04_ld` 1.0.4 (the one the Arduino core ships): open, send `CM9X`, close, wait 1 s,
//! open (3 tries 500 ms apart), `AT&NAME\n`, `\r\n` and read until the prompt, `AT&LD`, wait
//! for `-Re…`, the image in 64-byte writes back to back, the checksum byte, wait 100 ms, read
//! the result, and on `Success` wait 200 ms and send `AT&GO`. (1.0.3 on the same author's
//! GitHub: 1024-byte writes, up to 5 attempts on `Fail`.)
//!
//! # What is worked around
//!
//! - Every USB packet is programmed as whole words: a packet whose length is not a multiple of
//!   4 has the stale bytes of the previous packet's buffer programmed after it, and the next
//!   packet starts at the next word. So the image goes in [`CHUNK`] = 64-byte writes (one
//!   full-speed packet each, as 1.0.4), the checksum byte alone after them ([`transfer`]). A
//!   short packet in the middle would shift the rest of the image and the 8-bit sum would
//!   not see it.
//! - V1.03 programs nothing from a packet of 1 byte (that is how the checksum byte stays out
//!   of flash): an image whose length is 1 more than a multiple of 64 would lose its last
//!   byte, unseen by the sum (1.0.4 has this bug). The image is padded with 0xFF to a multiple
//!   of 4 bytes ([`sendable`]), so its last packet is never 1 byte.
//! - The end of the image is a pause of more than 16 ms, so the writes go back to back
//!   without a flush or a progress display between them; and the first packet goes at once
//!   after `Ready..` (the CM-9 bootloader source ends the download when nothing has come
//!   16 ms after its 100 ms wait; V1.03 waits for the first packet).
//! - The bootloader checks its end address only after programming a word: an image over
//!   114 KiB has a word programmed into the kept control-table page before `Overflow!`.
//!   Images over [`APP_REGION`] are refused before anything is sent.
//! - `AT&LD` is not sent again while the bootloader may still be erasing (it would take it as
//!   the next command after the download and erase again): no `Ready..` in time is final. A
//!   `Fail..` or a lost result starts over with `AT&LD` (after [`Timeouts::settle`]).
//! - The bootloader has no read command: the 8-bit sum is the only check (it finds any single
//!   wrong byte, not two that cancel or a swap). A checksum byte of `*` (0x2A, 1 image in 256)
//!   disables even that: such an image is sent with 4 more 0xFF bytes (the flash after the
//!   image is erased to 0xFF anyway), which changes the sum.
//!
//! # Why hand-written
//!
//! No crate speaks it; it is a few text lines and a byte sum.
//!
//! # Sources
//!
//! - ROBOTIS-GIT/OpenCM9.04: `arduino/opencm_arduino/opencm9.04/platform.txt` (the upload
//!   line), `boards.txt` (`upload.maximum_size=116736`), `variants/OpenCM904/bsp/opencm/
//!   ldscript/opencm_flash.ld` (FLASH 0x0800_3000, 114K), `variants/OpenCM904/hw/usb_cdc/
//!   usbd_cdc_interface.c` (`JUMP_BOOT_STR "CM9X"`, the 1200-baud reset), `variants/OpenCM904/
//!   variant.cpp` (pin 23 = PC15 USER_BUTTON), `bootloaders/opencm_boot.bin` (the bootloader
//!   V1.03, a binary: its strings and its disassembly give the entry test, the erase range,
//!   the V1.03 differences and the answers above) and `tools/opencm_tools_0.0.2/linux64/
//!   opencm9.04_ld` (1.0.4, a binary: the sequence above from its disassembly).
//! - chcbaram/stm32ld: `main_OpenCM.c` (the loader's source, 1.0.1–1.0.3: `OpenCM_Cmd_Init`,
//!   `OpenCM_WriteFlash`, the commands and answers).
//! - robotis-pandora/ROBOTIS_CM9_Series (parent of commit 1a39053, which removed it):
//!   `Firmware/bootloader_0x08000000/main.c` (`SerialMonitor`, the CM-9 series bootloader the
//!   OpenCM 9.04's derives from), `usb_endp.c` (`EP3_OUT_Callback`, `WriteFlash64`),
//!   `hw_config.h` (`FLASH_START_ADDRESS 0x8003000`, 1 KiB pages).
//!
//! # Untested on hardware
//!
//! All of it: the protocol is read from ROBOTIS' sources and binaries and run here against a
//! simulated bootloader ([`tests`](self)). In particular not known from a board: whether the
//! boards sold today carry V1.03 (the one in the Arduino core), how long the erase takes (the
//! F103 datasheet's page erase is 20–40 ms, so up to 4.6 s; the default wait is 10 s), and
//! whether an OS splits the 64-byte writes into other USB packets.

use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

/// Where the bootloader programs the image (and starts it from).
pub const APP_BASE: u32 = 0x0800_3000;
/// The region `AT&LD` erases: 0x0800_3000..0x0801_F800 (114 KiB).
pub const APP_REGION: usize = 114 * 1024;
/// The first address the bootloader keeps (its control table, the last 2 KiB of flash).
pub const RESERVED_BASE: u32 = APP_BASE + APP_REGION as u32;
/// The default image limit: the whole erased region.
pub const DEFAULT_LIMIT: usize = APP_REGION;
/// One flash page of the STM32F103CB.
pub const PAGE: usize = 1024;
/// Bytes of one write of the image: one full-speed USB packet, a multiple of 4.
pub const CHUNK: usize = 64;
/// Asks for the board's name.
pub const CMD_NAME: &[u8] = b"AT&NAME\n";
/// Erases the region and starts the download.
pub const CMD_LOAD: &[u8] = b"AT&LD";
/// Starts the image.
pub const CMD_GO: &[u8] = b"AT&GO";
/// The OpenCM 9.04 bootloader's answer to [`CMD_NAME`].
pub const BOARD_NAME: &str = "CM-904";
/// The answer to [`CMD_LOAD`] once the region is erased.
pub const READY: &str = "Ready..";
/// The answer after a download whose sum matched.
pub const SUCCESS: &str = "Success..";
/// The answer after a download whose sum did not match.
pub const FAIL: &str = "Fail..";
/// A checksum byte the bootloader accepts whatever the sum.
pub const WILDCARD: u8 = b'*';
/// What an Arduino sketch of ROBOTIS' core takes as a request to reset into the bootloader.
pub const JUMP_MAGIC: &[u8] = b"CM9X";
/// How long the loader waits after [`JUMP_MAGIC`] before it opens the port again.
pub const JUMP_WAIT: Duration = Duration::from_secs(1);
/// Messages the bootloader prints when programming a word fails.
pub const BOARD_ERRORS: [&str; 3] = ["Failed!", "Overflow!", "flash writing error!"];

/// The checksum byte: the sum of the image bytes modulo 256.
pub fn checksum(image: &[u8]) -> u8 {
    image.iter().fold(0u8, |s, &b| s.wrapping_add(b))
}

/// The image as sent: padded with 0xFF to a multiple of 4 bytes (whole words: no stale bytes
/// programmed after it, no last packet of 1 byte), and 4 more 0xFF bytes when its checksum
/// would be [`WILDCARD`] (which the bootloader takes as "do not check"). 0xFF leaves erased
/// flash as it is.
pub fn sendable(image: &[u8]) -> Vec<u8> {
    let mut data = image.to_vec();
    data.resize(image.len().next_multiple_of(4), 0xFF);
    if checksum(&data) == WILDCARD {
        data.extend([0xFF; 4]);
    }
    data
}

/// The writes of a download, in order: `data` in [`CHUNK`]-byte pieces (the last may be
/// shorter), then the checksum byte alone.
pub fn transfer(data: &[u8]) -> Vec<Vec<u8>> {
    let mut out: Vec<Vec<u8>> = data.chunks(CHUNK).map(<[u8]>::to_vec).collect();
    out.push(vec![checksum(data)]);
    out
}

/// Pages of [`PAGE`] bytes that `AT&LD` erases.
pub const ERASED_PAGES: usize = APP_REGION / PAGE;

/// How long the client waits for each answer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Timeouts {
    /// The board name (`opencm9.04_ld`: 2.5 s).
    pub answer: Duration,
    /// `Ready..` after `AT&LD`: the erase of 114 pages (20–40 ms each).
    pub erase: Duration,
    /// `Success..` or `Fail..` after the checksum byte (the bootloader waits 16 ms of silence).
    pub result: Duration,
    /// The pause before `AT&GO` or another `AT&LD` (the bootloader waits 100 ms after its
    /// answer; `opencm9.04_ld` 200 ms).
    pub settle: Duration,
}

impl Default for Timeouts {
    fn default() -> Self {
        Timeouts {
            answer: Duration::from_millis(1500),
            erase: Duration::from_secs(10),
            result: Duration::from_secs(2),
            settle: Duration::from_millis(200),
        }
    }
}

/// What [`Bootloader::flash`] does.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FlashOptions {
    /// The largest image accepted, bytes (at most [`APP_REGION`]).
    pub limit: usize,
    /// Start the firmware after a download the bootloader accepted.
    pub jump: bool,
    /// Attempts of the name query and of the download, at least 1.
    pub attempts: u32,
    /// Answer timeouts.
    pub timeouts: Timeouts,
}

impl Default for FlashOptions {
    fn default() -> Self {
        FlashOptions {
            limit: DEFAULT_LIMIT,
            jump: true,
            attempts: 3,
            timeouts: Timeouts::default(),
        }
    }
}

/// Where [`Bootloader::flash`] is, for a progress display.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Stage {
    /// The bootloader answered its name.
    Connected {
        /// `CM-904`.
        board_name: String,
    },
    /// `AT&LD` sent: the bootloader erases (attempt `attempt`).
    Erasing {
        /// 1 for the first download, more after a `Fail..`.
        attempt: u32,
    },
    /// `done` of `total` bytes sent (reported after the last write only: the writes must
    /// not pause).
    Writing {
        /// Bytes sent so far.
        done: usize,
        /// Bytes to send.
        total: usize,
    },
    /// Waiting for the bootloader's verdict on the checksum.
    Checking,
    /// Starting the firmware.
    Jumping,
}

/// What [`Bootloader::flash`] did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FlashReport {
    /// The board's name (`CM-904`).
    pub board_name: String,
    /// Bytes of the image given.
    pub image_len: usize,
    /// Bytes sent (the image padded with 0xFF, see [`sendable`]).
    pub sent_len: usize,
    /// The checksum byte sent.
    pub checksum: u8,
    /// Downloads started (`AT&LD` sent).
    pub downloads: u32,
    /// Name queries or downloads repeated after a lost answer or a `Fail..`.
    pub retries: u32,
    /// Lines that were not the awaited answer (banner, prompt, error messages).
    pub other_lines: Vec<String>,
    /// The firmware was started.
    pub jumped: bool,
    /// Time of the last erase.
    pub erase_time: Duration,
    /// Time of the last download (the writes and the verdict).
    pub write_time: Duration,
    /// Time of the whole exchange.
    pub total_time: Duration,
}

/// Why one attempt failed.
#[derive(Debug)]
enum Fail {
    /// No answer before the timeout.
    Timeout { step: &'static str, after: Duration },
    /// The bootloader answered `Fail..`.
    Rejected(String),
    /// No `Ready..` after `AT&LD`: final (see the module doc).
    NoReady(Duration),
    /// The port failed: final.
    Io { step: &'static str, err: io::Error },
}

impl Fail {
    fn text(&self, attempts: u32) -> String {
        let n = format!("{attempts} attempt{}", if attempts == 1 { "" } else { "s" });
        match self {
            Fail::Timeout { step, after } => {
                format!("{step}: no answer within {} ms ({n})", after.as_millis())
            }
            Fail::Rejected(line) => format!(
                "the bootloader answered {line:?}: its sum of the bytes it programmed is not the checksum sent ({n})"
            ),
            Fail::NoReady(after) => format!(
                "AT&LD: no \"{READY}\" within {} ms (the erase); not sent again while the board may still be erasing",
                after.as_millis()
            ),
            Fail::Io { step, err } => format!("{step}: serial port: {err}"),
        }
    }
}

/// How long the client sleeps when a read returns nothing at once.
const IDLE: Duration = Duration::from_millis(1);

/// A client of the bootloader on any byte stream whose reads time out (a serial port).
pub struct Bootloader<P> {
    port: P,
    rx: Vec<u8>,
    opts: FlashOptions,
    retries: u32,
    other: Vec<String>,
}

impl<P: Read + Write> Bootloader<P> {
    /// A client on `port` with `opts`.
    pub fn new(port: P, opts: FlashOptions) -> Self {
        Bootloader {
            port,
            rx: Vec::new(),
            opts,
            retries: 0,
            other: Vec::new(),
        }
    }

    /// The port (e.g. the simulated board of a test).
    pub fn port(&self) -> &P {
        &self.port
    }

    /// The port back.
    pub fn into_inner(self) -> P {
        self.port
    }

    /// Writes one command (one USB packet) and flushes it.
    fn send(&mut self, step: &'static str, bytes: &[u8]) -> Result<(), Fail> {
        self.port
            .write_all(bytes)
            .and_then(|_| self.port.flush())
            .map_err(|err| Fail::Io { step, err })
    }

    /// The next complete line received, without its `\r` and blanks; `None` if none is
    /// complete yet.
    fn next_line(&mut self) -> Option<String> {
        loop {
            let end = self.rx.iter().position(|&b| b == b'\n')?;
            let line: Vec<u8> = self.rx.drain(..=end).collect();
            let text = String::from_utf8_lossy(&line).trim().to_string();
            if !text.is_empty() {
                return Some(text);
            }
        }
    }

    /// Waits up to `timeout` for a line `want` takes; other lines are kept for the report.
    fn wait_line<T>(
        &mut self,
        step: &'static str,
        timeout: Duration,
        mut want: impl FnMut(&str) -> Option<T>,
    ) -> Result<T, Fail> {
        let deadline = Instant::now() + timeout;
        let mut buf = [0u8; 256];
        loop {
            while let Some(line) = self.next_line() {
                match want(&line) {
                    Some(v) => return Ok(v),
                    None => self.other.push(line),
                }
            }
            if Instant::now() >= deadline {
                return Err(Fail::Timeout {
                    step,
                    after: timeout,
                });
            }
            match self.port.read(&mut buf) {
                Ok(0) => std::thread::sleep(IDLE),
                Ok(n) => self.rx.extend_from_slice(&buf[..n]),
                Err(e) => match e.kind() {
                    io::ErrorKind::TimedOut => {}
                    io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted => {
                        std::thread::sleep(IDLE)
                    }
                    _ => return Err(Fail::Io { step, err: e }),
                },
            }
        }
    }

    /// Discards what the port holds (the banner, the prompt); returns the byte count.
    pub fn drain(&mut self) -> Result<usize, String> {
        let deadline = Instant::now() + Duration::from_secs(2);
        let mut buf = [0u8; 256];
        let mut n = self.rx.len();
        self.rx.clear();
        while Instant::now() < deadline {
            match self.port.read(&mut buf) {
                Ok(0) => break,
                Ok(k) => n += k,
                Err(e) => match e.kind() {
                    io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock => break,
                    io::ErrorKind::Interrupted => {}
                    _ => return Err(format!("serial port: {e}")),
                },
            }
        }
        Ok(n)
    }

    /// The board's name (`AT&NAME`), asked up to `attempts` times; an answer other than
    /// `CM-904` (another CM-9 board, another flash layout) is an error.
    pub fn read_board_name(&mut self) -> Result<String, String> {
        let attempts = self.opts.attempts.max(1);
        let t = self.opts.timeouts.answer;
        let mut k = 1;
        loop {
            let r = self.send("AT&NAME", CMD_NAME).and_then(|_| {
                self.wait_line("AT&NAME", t, |l| l.contains("CM-9").then(|| l.to_string()))
            });
            match r {
                Ok(line) => {
                    let name = line[line.find("CM-9").unwrap_or(0)..].to_string();
                    return match name == BOARD_NAME {
                        true => Ok(name),
                        false => Err(format!(
                            "AT&NAME: the bootloader answered {line:?}, not {BOARD_NAME:?} (the OpenCM 9.04): its flash layout may differ, nothing was sent"
                        )),
                    };
                }
                Err(Fail::Timeout { .. }) if k < attempts => {
                    k += 1;
                    self.retries += 1;
                }
                Err(e) => return Err(e.text(k)),
            }
        }
    }

    /// One download: `AT&LD`, `Ready..`, the writes of [`transfer`], the verdict. `Ok(true)`
    /// for `Success..`; `Err(Fail::Rejected)` for `Fail..`.
    fn download(
        &mut self,
        data: &[u8],
        erase_time: &mut Duration,
        progress: &mut dyn FnMut(Stage),
    ) -> Result<(), Fail> {
        let t = Instant::now();
        self.send("AT&LD", CMD_LOAD)?;
        let erase = self.opts.timeouts.erase;
        self.wait_line("AT&LD (erase)", erase, |l| l.ends_with(READY).then_some(()))
            .map_err(|e| match e {
                Fail::Timeout { after, .. } => Fail::NoReady(after),
                e => e,
            })?;
        *erase_time = t.elapsed();
        // Back to back: a pause over 16 ms ends the download on the board.
        for w in transfer(data) {
            self.port
                .write_all(&w)
                .map_err(|err| Fail::Io { step: "image", err })?;
        }
        self.port
            .flush()
            .map_err(|err| Fail::Io { step: "image", err })?;
        progress(Stage::Writing {
            done: data.len(),
            total: data.len(),
        });
        progress(Stage::Checking);
        let verdict = self.wait_line("checksum", self.opts.timeouts.result, |l| {
            (l.ends_with(SUCCESS) || l.ends_with(FAIL)).then(|| l.to_string())
        })?;
        match verdict.ends_with(SUCCESS) {
            true => Ok(()),
            false => Err(Fail::Rejected(verdict)),
        }
    }

    /// Sends `AT&GO` (no answer: the bootloader disconnects USB and starts the image).
    pub fn go(&mut self) -> Result<(), String> {
        self.send("AT&GO", CMD_GO).map_err(|e| e.text(1))
    }

    /// Flashes `image` at 0x0800_3000: board name, `AT&LD` (erase), the image and its checksum,
    /// the verdict (a `Fail..` or a lost verdict: the download again, up to `attempts`), and
    /// (if the options say so) `AT&GO`. An image over the options' limit is refused before
    /// anything is sent.
    pub fn flash(
        &mut self,
        image: &[u8],
        progress: &mut dyn FnMut(Stage),
    ) -> Result<FlashReport, String> {
        let o = self.opts.clone();
        if o.limit > APP_REGION {
            return Err(format!(
                "limit of {} B is over the bootloader's region of {APP_REGION} B (0x{APP_BASE:08X}..0x{RESERVED_BASE:08X})",
                o.limit
            ));
        }
        if image.is_empty() {
            return Err("the image is empty".into());
        }
        let data = sendable(image);
        if data.len() > o.limit {
            return Err(format!(
                "the image is {} B ({:.1} KiB), over the limit of {} B ({:.1} KiB): nothing was sent",
                data.len(),
                data.len() as f64 / 1024.0,
                o.limit,
                o.limit as f64 / 1024.0
            ));
        }
        let start = Instant::now();
        self.retries = 0;
        self.other.clear();
        self.drain()?;
        let board_name = self.read_board_name()?;
        progress(Stage::Connected {
            board_name: board_name.clone(),
        });
        let attempts = o.attempts.max(1);
        let mut downloads = 0;
        let mut erase_time = Duration::ZERO;
        let write_time;
        loop {
            downloads += 1;
            progress(Stage::Erasing { attempt: downloads });
            let t = Instant::now();
            match self.download(&data, &mut erase_time, progress) {
                Ok(()) => {
                    write_time = t.elapsed().saturating_sub(erase_time);
                    break;
                }
                Err(Fail::Rejected(_) | Fail::Timeout { .. }) if downloads < attempts => {
                    self.retries += 1;
                    std::thread::sleep(o.timeouts.settle);
                    self.drain()?;
                }
                Err(e) => return Err(e.text(downloads)),
            }
        }
        if o.jump {
            std::thread::sleep(o.timeouts.settle);
            progress(Stage::Jumping);
            self.go()?;
        }
        Ok(FlashReport {
            board_name,
            image_len: image.len(),
            sent_len: data.len(),
            checksum: checksum(&data),
            downloads,
            retries: self.retries,
            other_lines: self.other.clone(),
            jumped: o.jump,
            erase_time,
            write_time,
            total_time: start.elapsed(),
        })
    }
}

/// What an image not linked for the OpenCM's bootloader is told to do.
const LINK_HINT: &str =
    "link it for the bootloader at 0x0800_3000 (feature board-opencm, memory.x's OpenCM layout)";

/// The bytes to flash from a file: an ELF's loadable bytes for 0x0800_3000 or the file itself
/// (a raw binary for 0x0800_3000); with a description of which. A segment outside
/// 0x0800_3000..0x0801_F800 is an error.
pub fn load_image(bytes: &[u8]) -> Result<(Vec<u8>, String), String> {
    crate::opencr_boot::load_image_at(bytes, APP_BASE, APP_REGION, LINK_HINT)
}

/// Checks that `image` starts with a Cortex-M vector table for 0x0800_3000: an initial stack
/// pointer in the STM32F103CB's 20 KiB of SRAM and a Thumb reset vector inside the image.
pub fn check_vector_table(image: &[u8]) -> Result<(), String> {
    crate::opencr_boot::check_vector_table_at(
        image,
        &crate::opencr_boot::VectorTable {
            base: APP_BASE,
            sram: 0x2000_0000..=0x2000_5000,
            chip: "STM32F103CB",
            hint: LINK_HINT,
        },
    )
}

/// The reset request of ROBOTIS' loader for a running Arduino sketch: opens `dev` at 1200 baud
/// (the core resets on that line coding too), writes [`JUMP_MAGIC`], closes it and waits
/// [`JUMP_WAIT`]. The walker firmware has no USB stack and the bootloader ignores the bytes.
pub fn request_bootloader(dev: &str) -> Result<(), String> {
    let mut port = crate::capture::open_serial(dev, 1200)?;
    port.write_all(JUMP_MAGIC)
        .and_then(|_| port.flush())
        .map_err(|e| format!("reset request on {dev}: {e}"))?;
    drop(port);
    std::thread::sleep(JUMP_WAIT);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::VecDeque;

    /// The STM32F103CB's flash.
    const FLASH_SIZE: usize = 128 * 1024;
    const FLASH_BASE: u32 = 0x0800_0000;
    /// What the simulated control-table page holds (it must survive a flash).
    const TABLE_BYTE: u8 = 0x5C;

    /// The OpenCM 9.04 bootloader V1.03 as the sources describe it, behind a port: every
    /// `write` is one USB packet (longer writes are cut into 64-byte packets), a `read` with
    /// nothing to give times out, and a read while a download has packets ends it (the host
    /// has gone quiet for more than 16 ms).
    struct SimBoard {
        flash: Vec<u8>,
        out: VecDeque<u8>,
        /// The USB receive buffer: a short packet leaves the previous packet's bytes after it.
        usb_buf: [u8; 64],
        last_len: usize,
        downloading: bool,
        packets: usize,
        addr: u32,
        sum: u32,
        errors: Vec<&'static str>,
        /// Commands received, in order.
        log: Vec<String>,
        jumped: bool,
        erases: usize,
        /// Answers to AT&NAME to drop.
        mute_name: u32,
        /// Drop every "Ready.." answer.
        mute_ready: bool,
        /// Verdicts to drop.
        mute_verdict: u32,
        /// Flip this byte of the image (offset) in this many downloads.
        corrupt: Option<(usize, u32)>,
        received: usize,
    }

    impl SimBoard {
        fn new() -> Self {
            let mut flash: Vec<u8> = (0..FLASH_SIZE).map(|i| (i * 7 % 251) as u8).collect();
            let table = (RESERVED_BASE - FLASH_BASE) as usize;
            flash[table..].fill(TABLE_BYTE);
            let mut out = VecDeque::new();
            out.extend(b"\r\nSYSTEM O.K. (OpenCM9.04 Boot loader V1.03)\r\nCommand :AT&LD, L(oad), AT&GO, G(o), AT&GM, AT&RST, AT&CTRST, AT&NAME, AT\r\n-");
            SimBoard {
                flash,
                out,
                usb_buf: [0; 64],
                last_len: 0,
                downloading: false,
                packets: 0,
                addr: APP_BASE,
                sum: 0,
                errors: Vec::new(),
                log: Vec::new(),
                jumped: false,
                erases: 0,
                mute_name: 0,
                mute_ready: false,
                mute_verdict: 0,
                corrupt: None,
                received: 0,
            }
        }

        fn app(&self, len: usize) -> &[u8] {
            let off = (APP_BASE - FLASH_BASE) as usize;
            &self.flash[off..off + len]
        }

        fn table_intact(&self) -> bool {
            let table = (RESERVED_BASE - FLASH_BASE) as usize;
            self.flash[table..].iter().all(|&b| b == TABLE_BYTE)
        }

        fn say(&mut self, s: &str) {
            self.out.extend(s.as_bytes());
        }

        /// One USB packet.
        fn packet(&mut self, p: &[u8]) {
            self.usb_buf[..p.len()].copy_from_slice(p);
            self.last_len = p.len();
            if self.downloading {
                self.packets += 1;
                self.program(p.len());
                return;
            }
            let cmd = String::from_utf8_lossy(p).into_owned();
            self.log.push(cmd.trim_end().to_string());
            if !(p.len() > 3 && p[0] == b'A' && p[2] == b'&') {
                if p.starts_with(b"AT") {
                    self.say("OK\n");
                }
                return;
            }
            if p.starts_with(b"AT&LD") {
                self.erases += 1;
                let from = (APP_BASE - FLASH_BASE) as usize;
                let to = (RESERVED_BASE - FLASH_BASE) as usize;
                self.flash[from..to].fill(0xFF);
                if !self.mute_ready {
                    self.say("Ready..\n");
                }
                self.downloading = true;
                self.packets = 0;
                self.received = 0;
                self.addr = APP_BASE;
                self.sum = 0;
            } else if p.starts_with(b"AT&GO") {
                self.jumped = true;
            } else if p.starts_with(b"AT&NAME") {
                if self.mute_name > 0 {
                    self.mute_name -= 1;
                } else {
                    self.say("CM-904\n");
                }
            }
        }

        /// `WriteFlash64` of V1.03 over the packet in `usb_buf[..n]`.
        fn program(&mut self, n: usize) {
            if let Some((at, left)) = self.corrupt.as_mut() {
                if *left > 0 && (self.received..self.received + n).contains(at) {
                    self.usb_buf[*at - self.received] ^= 0x10;
                    *left -= 1;
                }
            }
            self.received += n;
            let rest = 4 - n % 4;
            let mut i = 0;
            while i < n {
                let word = [
                    self.usb_buf[i],
                    self.usb_buf[i + 1],
                    self.usb_buf[i + 2],
                    self.usb_buf[i + 3],
                ];
                if n > 1 {
                    let off = (self.addr - FLASH_BASE) as usize;
                    // NOR flash: programming only clears bits.
                    for (k, b) in word.iter().enumerate() {
                        self.flash[off + k] &= b;
                    }
                    if self.flash[off..off + 4] != word {
                        self.errors.push("Failed!");
                        self.say("\r\n Failed!");
                        break;
                    }
                    if self.addr > RESERVED_BASE - 1 {
                        self.errors.push("Overflow!");
                        self.say("\r\n Overflow!");
                        break;
                    }
                }
                self.addr += 4;
                self.sum += word.iter().map(|&b| u32::from(b)).sum::<u32>();
                i += 4;
            }
            if rest != 4 {
                for k in 0..rest {
                    self.sum -= u32::from(self.usb_buf[i - rest + k]);
                }
            }
        }

        /// More than 16 ms without a packet: the download's end and the verdict.
        fn idle(&mut self) {
            if !self.downloading || self.packets == 0 {
                return;
            }
            self.downloading = false;
            let received = u32::from(self.usb_buf[self.last_len - 1]);
            let sum = self.sum.wrapping_sub(received);
            let verdict = match sum & 0xFF == received || received == u32::from(WILDCARD) {
                true => "Success..\n",
                false => "Fail..\n",
            };
            if self.mute_verdict > 0 {
                self.mute_verdict -= 1;
            } else {
                self.say(verdict);
            }
        }
    }

    impl Write for SimBoard {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            for p in buf.chunks(64) {
                self.packet(p);
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Read for SimBoard {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            if self.out.is_empty() {
                self.idle();
            }
            if self.out.is_empty() {
                return Err(io::Error::new(io::ErrorKind::TimedOut, "no bytes"));
            }
            let n = buf.len().min(self.out.len());
            for b in buf.iter_mut().take(n) {
                *b = self.out.pop_front().unwrap_or(0);
            }
            Ok(n)
        }
    }

    fn quick() -> FlashOptions {
        FlashOptions {
            timeouts: Timeouts {
                answer: Duration::from_millis(30),
                erase: Duration::from_millis(30),
                result: Duration::from_millis(30),
                settle: Duration::ZERO,
            },
            ..FlashOptions::default()
        }
    }

    fn bytes(seed: u32, n: usize) -> Vec<u8> {
        let mut x = seed.wrapping_mul(2_654_435_761).max(1);
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                x as u8
            })
            .collect()
    }

    fn flash_sim(
        board: SimBoard,
        image: &[u8],
        opts: FlashOptions,
    ) -> (Result<FlashReport, String>, SimBoard, Vec<Stage>) {
        let mut stages = Vec::new();
        let mut client = Bootloader::new(board, opts);
        let r = client.flash(image, &mut |s| stages.push(s));
        (r, client.into_inner(), stages)
    }

    #[test]
    fn a_whole_flash_programs_the_image_at_0x08003000() {
        // 1 more than a multiple of 64: padded to 40_004, the last packet has 4 bytes.
        let image = bytes(1, 40_001);
        let (r, board, stages) = flash_sim(SimBoard::new(), &image, quick());
        let r = r.expect("flash");
        assert_eq!(board.app(image.len()), &image[..]);
        assert_eq!(board.app(40_004)[40_001..], [0xFF; 3]);
        assert!(board.table_intact());
        assert!(board.errors.is_empty(), "{:?}", board.errors);
        assert!(board.jumped);
        assert_eq!(board.log, ["AT&NAME", "AT&LD", "AT&GO"]);
        assert_eq!(board.packets, 40_004usize.div_ceil(64) + 1);
        assert_eq!(r.board_name, "CM-904");
        assert_eq!(
            (r.image_len, r.sent_len, r.downloads, r.retries),
            (40_001, 40_004, 1, 0)
        );
        assert_eq!(r.checksum, checksum(&sendable(&image)));
        // The banner and the prompt were drained; nothing else came.
        assert!(r.other_lines.is_empty(), "{:?}", r.other_lines);
        assert_eq!(
            stages,
            [
                Stage::Connected {
                    board_name: "CM-904".into()
                },
                Stage::Erasing { attempt: 1 },
                Stage::Writing {
                    done: 40_004,
                    total: 40_004
                },
                Stage::Checking,
                Stage::Jumping,
            ]
        );
    }

    #[test]
    fn the_first_answer_after_the_prompt_is_recognised() {
        // Not drained: the prompt "\r\n-" glues to the name's line ("-CM-904").
        let mut client = Bootloader::new(SimBoard::new(), quick());
        assert_eq!(client.read_board_name(), Ok("CM-904".to_string()));
        assert!(client.other.iter().any(|l| l.starts_with("SYSTEM O.K.")));
    }

    #[test]
    fn an_image_of_the_whole_region_fits_and_leaves_the_control_table() {
        let image = bytes(2, APP_REGION);
        let (r, board, _) = flash_sim(SimBoard::new(), &image, quick());
        if checksum(&image) == WILDCARD {
            // One byte appended: over the region; the seed does not do this.
            assert!(r.is_err());
            return;
        }
        r.expect("flash");
        assert_eq!(board.app(APP_REGION), &image[..]);
        assert!(board.table_intact() && board.errors.is_empty());
    }

    #[test]
    fn a_corrupted_byte_is_rejected_then_sent_again() {
        let image = bytes(3, 5_000);
        let mut board = SimBoard::new();
        board.corrupt = Some((1234, 1));
        let (r, board, _) = flash_sim(board, &image, quick());
        let r = r.expect("second download");
        assert_eq!((r.downloads, r.retries, board.erases), (2, 1, 2));
        assert_eq!(board.app(image.len()), &image[..]);
    }

    #[test]
    fn a_byte_corrupted_every_time_fails() {
        let image = bytes(4, 5_000);
        let mut board = SimBoard::new();
        board.corrupt = Some((4_999, u32::MAX));
        let (r, board, _) = flash_sim(board, &image, quick());
        let e = r.expect_err("always corrupted");
        assert!(e.contains("\"Fail..\"") && e.contains("3 attempts"), "{e}");
        assert!(!board.jumped && board.erases == 3);
        assert_ne!(board.app(image.len()), &image[..]);
    }

    #[test]
    fn a_lost_name_answer_is_asked_again() {
        let image = bytes(5, 300);
        let mut board = SimBoard::new();
        board.mute_name = 2;
        let (r, board, _) = flash_sim(board, &image, quick());
        assert_eq!(r.expect("third query").retries, 2);
        assert_eq!(board.app(300), &image[..]);
        let mut board = SimBoard::new();
        board.mute_name = 3;
        let (r, board, _) = flash_sim(board, &image, quick());
        let e = r.expect_err("never answers");
        assert!(
            e.contains("AT&NAME: no answer within 30 ms (3 attempts)"),
            "{e}"
        );
        assert_eq!(board.erases, 0);
    }

    #[test]
    fn a_lost_ready_is_final_and_a_lost_verdict_downloads_again() {
        let image = bytes(6, 3_000);
        let mut board = SimBoard::new();
        board.mute_ready = true;
        let (r, board, _) = flash_sim(board, &image, quick());
        let e = r.expect_err("no Ready");
        assert!(e.contains("AT&LD") && e.contains("Ready.."), "{e}");
        assert_eq!(board.log.iter().filter(|c| *c == "AT&LD").count(), 1);
        let mut board = SimBoard::new();
        board.mute_verdict = 1;
        let (r, board, _) = flash_sim(board, &image, quick());
        assert_eq!(r.expect("second download").downloads, 2);
        assert_eq!(board.app(image.len()), &image[..]);
        let mut board = SimBoard::new();
        board.mute_verdict = 3;
        let (r, _, _) = flash_sim(board, &image, quick());
        let e = r.expect_err("no verdict");
        assert!(
            e.contains("checksum: no answer within 30 ms (3 attempts)"),
            "{e}"
        );
    }

    #[test]
    fn an_oversized_image_is_refused_before_anything_is_sent() {
        let image = bytes(7, APP_REGION + 1);
        let (r, board, _) = flash_sim(SimBoard::new(), &image, quick());
        let e = r.expect_err("too big");
        assert!(e.contains("nothing was sent"), "{e}");
        assert!(board.log.is_empty() && board.table_intact());
        let opts = FlashOptions {
            limit: 1024,
            ..quick()
        };
        let (r, board, _) = flash_sim(SimBoard::new(), &bytes(7, 1025), opts);
        assert!(r
            .expect_err("over the limit")
            .contains("over the limit of 1024 B"));
        assert!(board.log.is_empty());
        let opts = FlashOptions {
            limit: APP_REGION + 1,
            ..quick()
        };
        let (r, _, _) = flash_sim(SimBoard::new(), &bytes(7, 10), opts);
        assert!(r
            .expect_err("limit")
            .contains("over the bootloader's region"));
    }

    #[test]
    fn the_simulated_bootloader_overflows_into_the_table_as_the_real_one() {
        // Why the limit matters: past 114 KiB a word lands in the kept page first.
        let mut board = SimBoard::new();
        let data = vec![0u8; APP_REGION + 64];
        board.packet(b"AT&LD");
        for w in transfer(&data) {
            board.write_all(&w).expect("in memory");
        }
        assert!(board.errors.contains(&"Overflow!"));
        assert!(!board.table_intact());
    }

    #[test]
    fn a_last_packet_of_one_byte_is_not_programmed_unseen() {
        // Why the image is padded to whole words: 65 bytes in writes of 64 + 1 + checksum.
        let image = bytes(10, 65);
        let mut board = SimBoard::new();
        board.packet(b"AT&LD");
        for w in [&image[..64], &image[64..], &[checksum(&image)]] {
            board.write_all(w).expect("in memory");
        }
        board.idle();
        let out: Vec<u8> = board.out.drain(..).collect();
        assert!(String::from_utf8_lossy(&out).ends_with("Success..\n"));
        assert_eq!(board.app(64), &image[..64]);
        assert_eq!(board.app(65)[64], 0xFF);
        // As sent here: 68 bytes, all programmed.
        let (r, board, _) = flash_sim(SimBoard::new(), &image, quick());
        assert_eq!(r.expect("flash").sent_len, 68);
        assert_eq!(board.app(65), &image[..]);
    }

    #[test]
    fn a_short_packet_in_the_middle_shifts_the_image_unseen() {
        // Why every write but the last is a multiple of 4: the sum still matches.
        let image = bytes(8, 200);
        let mut board = SimBoard::new();
        board.packet(b"AT&LD");
        board.write_all(&image[..30]).expect("in memory");
        board.write_all(&image[30..]).expect("in memory");
        board.write_all(&[checksum(&image)]).expect("in memory");
        board.idle();
        let out: Vec<u8> = board.out.drain(..).collect();
        assert!(String::from_utf8_lossy(&out).ends_with("Success..\n"));
        assert_ne!(board.app(200), &image[..]);
    }

    #[test]
    fn no_jump_leaves_the_board_in_the_bootloader() {
        let opts = FlashOptions {
            jump: false,
            ..quick()
        };
        let image = bytes(9, 1000);
        let (r, board, stages) = flash_sim(SimBoard::new(), &image, opts);
        assert!(!r.expect("flash").jumped && !board.jumped);
        assert!(!stages.contains(&Stage::Jumping));
        assert_eq!(board.app(1000), &image[..]);
    }

    #[test]
    fn another_board_name_is_refused() {
        struct Cm900(SimBoard);
        impl Write for Cm900 {
            fn write(&mut self, b: &[u8]) -> io::Result<usize> {
                if b.starts_with(b"AT&NAME") {
                    self.0.say("CM-900\n");
                    return Ok(b.len());
                }
                self.0.write(b)
            }
            fn flush(&mut self) -> io::Result<()> {
                Ok(())
            }
        }
        impl Read for Cm900 {
            fn read(&mut self, b: &mut [u8]) -> io::Result<usize> {
                self.0.read(b)
            }
        }
        let mut client = Bootloader::new(Cm900(SimBoard::new()), quick());
        let e = client.flash(&[1, 2, 3], &mut |_| {}).expect_err("CM-900");
        assert!(
            e.contains("\"CM-900\"") && e.contains("nothing was sent"),
            "{e}"
        );
        assert_eq!(client.port().0.erases, 0);
    }

    #[test]
    fn a_wildcard_checksum_is_avoided() {
        let mut image = vec![0u8; 12];
        image[0] = WILDCARD;
        assert_eq!(checksum(&image), WILDCARD);
        let data = sendable(&image);
        assert_eq!(data.len(), 16);
        assert_ne!(checksum(&data), WILDCARD);
        // The bootloader would take a wrong image with '*' as its checksum.
        let mut board = SimBoard::new();
        let (r, board2, _) = flash_sim(SimBoard::new(), &image, quick());
        assert_eq!(r.expect("flash").sent_len, 16);
        assert_eq!(board2.app(16), &data[..]);
        board.packet(b"AT&LD");
        board.write_all(&[1, 2, 3, 4]).expect("in memory");
        board.write_all(&[WILDCARD]).expect("in memory");
        board.idle();
        assert!(board
            .out
            .iter()
            .copied()
            .collect::<Vec<u8>>()
            .ends_with(b"Success..\n"));
    }

    /// A minimal ELF32 (little-endian, ARM) with loadable segments (paddr, file bytes).
    fn elf(segments: &[(u32, Vec<u8>)]) -> Vec<u8> {
        let ph_off = 52u32;
        let mut data_off = ph_off + 32 * segments.len() as u32;
        let mut out = Vec::new();
        out.extend(b"\x7fELF");
        out.extend([1, 1, 1, 0]);
        out.extend([0u8; 8]);
        out.extend(2u16.to_le_bytes());
        out.extend(40u16.to_le_bytes());
        out.extend(1u32.to_le_bytes());
        out.extend(0x0800_3009u32.to_le_bytes());
        out.extend(ph_off.to_le_bytes());
        out.extend(0u32.to_le_bytes());
        out.extend(0x0500_0200u32.to_le_bytes());
        out.extend(52u16.to_le_bytes());
        out.extend(32u16.to_le_bytes());
        out.extend((segments.len() as u16).to_le_bytes());
        out.extend(40u16.to_le_bytes());
        out.extend(0u16.to_le_bytes());
        out.extend(0u16.to_le_bytes());
        for (paddr, bytes) in segments {
            out.extend(1u32.to_le_bytes());
            out.extend(data_off.to_le_bytes());
            out.extend(paddr.to_le_bytes());
            out.extend(paddr.to_le_bytes());
            out.extend((bytes.len() as u32).to_le_bytes());
            out.extend((bytes.len() as u32).to_le_bytes());
            out.extend(5u32.to_le_bytes());
            out.extend(4u32.to_le_bytes());
            data_off += bytes.len() as u32;
        }
        for (_, bytes) in segments {
            out.extend(bytes);
        }
        out
    }

    #[test]
    fn an_elf_for_0x08003000_loads_and_one_for_0x08000000_is_refused() {
        let vectors = [0x2000_5000u32.to_le_bytes(), 0x0800_3009u32.to_le_bytes()].concat();
        let file = elf(&[(0x0800_3000, vectors.clone()), (0x0800_300C, vec![7; 4])]);
        let (image, kind) = load_image(&file).expect("ELF");
        let mut want = vectors;
        want.extend([0xFF; 4]);
        want.extend([7; 4]);
        assert_eq!(image, want);
        assert!(kind.contains("2 loadable"), "{kind}");
        assert_eq!(check_vector_table(&image), Ok(()));
        let e = load_image(&elf(&[(0x0800_0000, vec![0; 16])])).expect_err("at 0x08000000");
        assert!(
            e.contains("0x08000000") && e.contains("board-opencm"),
            "{e}"
        );
        // An OpenCR image (sector 5) is outside the region too.
        let e = load_image(&elf(&[(0x0804_0000, vec![0; 16])])).expect_err("OpenCR image");
        assert!(e.contains("0x08040000"), "{e}");
        // Into the kept control-table page.
        let e = load_image(&elf(&[(0x0801_F7F0, vec![0; 32])])).expect_err("into the table");
        assert!(e.contains("0x0801F810"), "{e}");
        // A raw binary with the OpenCR's vector table.
        let bin = [0x2005_0000u32.to_le_bytes(), 0x0804_0101u32.to_le_bytes()].concat();
        let e = check_vector_table(&[bin, vec![0; 64]].concat()).expect_err("OpenCR vectors");
        assert!(e.contains("0x08040101") && e.contains("0x08003000"), "{e}");
        let bin = [0x2005_0000u32.to_le_bytes(), 0x0800_3101u32.to_le_bytes()].concat();
        let e = check_vector_table(&[bin, vec![0; 0x200]].concat()).expect_err("OpenCR stack");
        assert!(e.contains("STM32F103CB"), "{e}");
    }

    proptest! {
        #[test]
        fn any_image_goes_through_the_simulated_bootloader(
            image in proptest::collection::vec(any::<u8>(), 1..3000)
        ) {
            let (r, board, _) = flash_sim(SimBoard::new(), &image, quick());
            let r = r.expect("flash");
            let data = sendable(&image);
            prop_assert_eq!(board.app(data.len()), &data[..]);
            prop_assert_eq!(&data[..image.len()], &image[..]);
            prop_assert_eq!(r.downloads, 1);
            prop_assert!(board.table_intact());
        }

        #[test]
        fn the_framing_keeps_words_whole_and_ends_with_the_sum(
            data in proptest::collection::vec(any::<u8>(), 1..1000)
        ) {
            let sent = sendable(&data);
            prop_assert_eq!(&sent[..data.len()], &data[..]);
            prop_assert!(sent[data.len()..].iter().all(|&b| b == 0xFF));
            prop_assert!(sent.len().is_multiple_of(4) && sent.len() - data.len() < 8);
            prop_assert_ne!(checksum(&sent), WILDCARD);
            let w = transfer(&sent);
            let (last, body) = w.split_last().expect("at least two writes");
            prop_assert_eq!(last, &vec![checksum(&sent)]);
            prop_assert_eq!(body.concat(), sent.clone());
            for p in &body[..body.len() - 1] {
                prop_assert_eq!(p.len(), CHUNK);
            }
            // The last data write: whole words, never the 1 byte V1.03 does not program.
            let tail = body.last().expect("data");
            prop_assert!(!tail.is_empty() && tail.len() <= CHUNK && tail.len().is_multiple_of(4));
        }

        #[test]
        fn the_sum_sees_any_single_wrong_byte(
            data in proptest::collection::vec(any::<u8>(), 1..500),
            at in any::<prop::sample::Index>(),
            delta in 1u8..=255,
        ) {
            let i = at.index(data.len());
            let mut bad = data.clone();
            bad[i] = bad[i].wrapping_add(delta);
            prop_assert_ne!(checksum(&bad), checksum(&data));
        }
    }

    /// `walker flash --board opencm` end to end through a pseudo-terminal: the command line,
    /// the reset request, the port opened by `serialport`, the simulated board on the other
    /// end (the byte stream cut into 64-byte packets again, as the USB host would).
    #[cfg(unix)]
    #[test]
    fn walker_flash_opencm_runs_over_a_pseudo_terminal() {
        use clap::Parser as _;
        use serialport::SerialPort as _;
        use std::sync::atomic::{AtomicBool, Ordering};
        use std::sync::Arc;
        let (mut master, slave) = serialport::TTYPort::pair().expect("a pseudo-terminal");
        let path = slave.name().expect("the pty's name");
        master
            .set_timeout(Duration::from_millis(5))
            .expect("timeout");
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = Arc::clone(&stop);
        let server = std::thread::spawn(move || {
            let mut board = SimBoard::new();
            board.out.clear();
            let mut pending: Vec<u8> = Vec::new();
            let mut buf = [0u8; 4096];
            let mut quiet = 0;
            while !stop2.load(Ordering::SeqCst) {
                match master.read(&mut buf) {
                    Ok(n) if n > 0 => {
                        quiet = 0;
                        pending.extend_from_slice(&buf[..n]);
                        if board.downloading {
                            while pending.len() >= 64 {
                                let p: Vec<u8> = pending.drain(..64).collect();
                                board.packet(&p);
                            }
                            continue;
                        }
                    }
                    _ => quiet += 1,
                }
                // A download ends after 50 ms of quiet here (16 ms on the board: a loaded
                // test machine may pause the client longer between two writes).
                if board.downloading && quiet < 10 {
                    continue;
                }
                if !pending.is_empty() {
                    let p: Vec<u8> = std::mem::take(&mut pending);
                    for c in p.chunks(64) {
                        board.packet(c);
                    }
                } else {
                    board.idle();
                }
                let out: Vec<u8> = board.out.drain(..).collect();
                master.write_all(&out).expect("to the pty");
            }
            board
        });
        let mut image = [0x2000_5000u32.to_le_bytes(), 0x0800_3101u32.to_le_bytes()].concat();
        image.extend(bytes(23, 20_000));
        let dir = std::env::temp_dir().join(format!("walker-flash-opencm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let file = dir.join("image.bin");
        std::fs::write(&file, &image).expect("image");
        let args = [
            "walker",
            "flash",
            "--board",
            "opencm",
            "--serial",
            &path,
            file.to_str().expect("UTF-8 path"),
        ];
        let cli = crate::cli::Cli::try_parse_from(args).expect("command line");
        let r = crate::cli::run(cli.command);
        stop.store(true, Ordering::SeqCst);
        let board = server.join().expect("the board's thread");
        drop(slave);
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(r, Ok(()));
        let data = sendable(&image);
        assert_eq!(board.app(data.len()), &data[..]);
        assert!(board.jumped && board.table_intact());
        // The reset request reached the bootloader as a packet it ignores.
        assert_eq!(board.log.first().map(String::as_str), Some("CM9X"));
    }
}
