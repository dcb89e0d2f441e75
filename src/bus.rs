//! The Dynamixel master (`dxl::Master`) over a board's servo bus and clock.
//!
//! # Ownership
//! `dxl::Master` owns its transport, but the board that provides the bus also provides the
//! tick timer, the log sink and the watchdog. [`BoardMaster`] therefore wraps a master whose transport
//! ([`Link`]) holds `&mut B` for the whole run, and gives the board back through
//! [`BoardMaster::board`] between transactions. The master's clock ([`LinkClock`]) reads a
//! `Cell<u64>` that the link refreshes from the board after every transport call, so the
//! master always sees the board's time (virtual under QEMU, where the bus transport itself
//! advances the clock) without a second borrow of the board. Every transaction goes through
//! [`BoardMaster::master`], which re-reads the clock first.
//!
//! # Bytes and timeouts
//! * [`dxl::Transport::write_all`] collects the packet, [`dxl::Transport::flush`] sends it
//!   with one [`ServoBus::send`] (the board turns the half-duplex line around itself, so the
//!   master's direction pin is [`NoDir`]).
//! * [`dxl::Transport::read_bytes`] (the master's block read of the rest of a reply frame)
//!   and [`dxl::Transport::read_byte`] are `recv(buf, poll)` with a short `poll`
//!   ([`Config::read_poll_us`], default [`DEFAULT_READ_POLL_US`]): on the real board it waits
//!   at most that long for a byte; under QEMU lock-step a byte of the announced reply comes
//!   at once and a read beyond it returns at once with the virtual clock advanced by `poll`,
//!   so the master's reply timeout ([`Config::reply_timeout_us`]) elapses deterministically
//!   in `poll` steps. The stale-input drain the master does before each packet reads with a
//!   zero timeout (no time passes when nothing is pending).

use core::cell::Cell;
use core::convert::Infallible;

use dxl::{BusStats, Master};
use embedded_hal::digital::{ErrorType, OutputPin};
use embedded_io::ErrorKind;

use crate::board::{BusError, Clock, ServoBus};
use crate::record::BusCounters;
use crate::Config;
use gait_core::robot::BusDescription;

/// Default longest wait for one reply byte, µs.
pub use walker_contract::config::DEFAULT_READ_POLL_US;
/// Size of the master's transmit and receive buffers and of the link's packet buffer, bytes.
pub const PACKET_BUF: usize = 256;

/// The half-duplex direction pin of the master: the boards switch direction inside
/// [`ServoBus::send`], so this pin does nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoDir;

impl ErrorType for NoDir {
    type Error = Infallible;
}

impl OutputPin for NoDir {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// The master's clock: the board time as last seen by the [`Link`].
#[derive(Clone, Copy, Debug)]
pub struct LinkClock<'t>(&'t Cell<u64>);

impl dxl::Clock for LinkClock<'_> {
    fn now_us(&self) -> u64 {
        self.0.get()
    }
}

fn kind_of(e: BusError) -> ErrorKind {
    match e {
        BusError::Hardware => ErrorKind::Other,
        BusError::UnsupportedBaud => ErrorKind::Unsupported,
        BusError::TooLong => ErrorKind::OutOfMemory,
        BusError::Timeout => ErrorKind::TimedOut,
    }
}

/// `dxl::Transport` over a board's [`ServoBus`] (see the module docs).
pub struct Link<'b, B: ServoBus + Clock> {
    board: &'b mut B,
    time: &'b Cell<u64>,
    /// The packet being written, `tx[..tx_len]` (sent whole by `flush`).
    tx: [u8; PACKET_BUF],
    tx_len: usize,
    poll_us: u32,
    draining: bool,
}

impl<'b, B: ServoBus + Clock> Link<'b, B> {
    fn refresh(&self) {
        self.time.set(self.board.now_us());
    }

    /// Marks the start of a transaction: the master's next reads are the stale-input drain.
    fn begin(&mut self) {
        self.draining = true;
        self.tx_len = 0;
        self.refresh();
    }
}

impl<B: ServoBus + Clock> dxl::Transport for Link<'_, B> {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), ErrorKind> {
        self.draining = false;
        // One block copy (heapless' `extend_from_slice` clones byte by byte).
        let end = self.tx_len + bytes.len();
        match self.tx.get_mut(self.tx_len..end) {
            Some(dst) => {
                dst.copy_from_slice(bytes);
                self.tx_len = end;
                Ok(())
            }
            None => {
                self.tx_len = 0;
                Err(ErrorKind::OutOfMemory)
            }
        }
    }

    fn flush(&mut self) -> Result<(), ErrorKind> {
        if self.tx_len == 0 {
            return Ok(());
        }
        let r = self.board.send(self.tx.get(..self.tx_len).unwrap_or(&[]));
        self.tx_len = 0;
        self.refresh();
        r.map_err(kind_of)
    }

    fn read_byte(&mut self) -> Result<Option<u8>, ErrorKind> {
        let mut b = [0u8; 1];
        let n = self.read_bytes(&mut b)?;
        let [byte] = b;
        Ok((n == 1).then_some(byte))
    }

    /// One `recv` of the whole block with the poll timeout: under QEMU lock-step the reply
    /// bytes come at once; on the OpenCR the read returns what arrived within the poll.
    fn read_bytes(&mut self, buf: &mut [u8]) -> Result<usize, ErrorKind> {
        let timeout = if self.draining { 0 } else { self.poll_us };
        let r = self.board.recv(buf, timeout);
        self.refresh();
        r.map(|n| n.min(buf.len())).map_err(kind_of)
    }
}

/// The master type the firmware uses.
pub type BusMaster<'b, B> = Master<Link<'b, B>, NoDir, LinkClock<'b>, PACKET_BUF>;

/// The Dynamixel master bound to a board for the whole run (see the module docs).
pub struct BoardMaster<'b, B: ServoBus + Clock> {
    master: BusMaster<'b, B>,
    /// Who is on the bus: the configured robot's description.
    devices: &'static BusDescription,
}

impl<'b, B: ServoBus + Clock> BoardMaster<'b, B> {
    /// Binds a master to `board`; `time` is the clock cell shared with the master (declare it
    /// before the bus: `let time = Cell::new(0); let bus = BoardMaster::new(&mut board, &time, &cfg);`).
    pub fn new(board: &'b mut B, time: &'b Cell<u64>, cfg: &Config) -> Self {
        time.set(board.now_us());
        let link = Link {
            board,
            time,
            tx: [0; PACKET_BUF],
            tx_len: 0,
            poll_us: cfg.read_poll_us.max(1),
            draining: true,
        };
        let mut master = Master::new(link, NoDir, LinkClock(time));
        master.set_timeout_us(u64::from(cfg.reply_timeout_us.max(1)));
        BoardMaster {
            master,
            devices: &cfg.robot.bus,
        }
    }

    /// The devices on this bus (the configured robot's IDs). A real board's build walks its
    /// own robot ([`crate::control::BUILD_ROBOT`]: another `robot=` is refused at start-up),
    /// whose bus is a constant there: the code for the sensors it does not have folds away.
    pub fn devices(&self) -> &'static BusDescription {
        #[cfg(all(
            any(feature = "board-opencm", feature = "board-opencr"),
            target_os = "none"
        ))]
        {
            let _ = self.devices;
            &crate::control::BUILD_ROBOT.bus
        }
        #[cfg(not(all(
            any(feature = "board-opencm", feature = "board-opencr"),
            target_os = "none"
        )))]
        {
            self.devices
        }
    }

    /// The master, ready for one transaction (the clock is re-read from the board).
    pub fn master(&mut self) -> &mut BusMaster<'b, B> {
        self.master.transport_mut().begin();
        &mut self.master
    }

    /// The board, between transactions (tick timer, log, watchdog, …).
    pub fn board(&mut self) -> &mut B {
        &mut *self.master.transport_mut().board
    }

    /// The master's cumulative error counters.
    pub fn stats(&self) -> BusStats {
        self.master.stats()
    }

    /// The counters in the log's form (saturating to u16).
    pub fn counters(&self) -> BusCounters {
        counters(&self.master.stats())
    }
}

fn sat16(v: u32) -> u16 {
    u16::try_from(v).unwrap_or(u16::MAX)
}

/// `dxl::BusStats` → the log's [`BusCounters`]: timeouts, CRC errors (including framing and
/// malformed replies) and status-packet errors, each saturating at 65535.
pub fn counters(s: &BusStats) -> BusCounters {
    BusCounters {
        timeouts: sat16(s.timeouts),
        crc: sat16(s.crc_errors.saturating_add(s.malformed)),
        status: sat16(s.status_errors),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fake_robot::trace::FakeBoard;

    #[test]
    fn ping_through_the_link_and_timeouts_are_exact() {
        let mut board = FakeBoard::robot();
        board.remove(5);
        let time = Cell::new(0);
        let cfg = Config::default();
        let mut bus = BoardMaster::new(&mut board, &time, &cfg);
        let info = bus.master().ping(1);
        assert!(info.is_ok(), "{info:?}");
        let t0 = bus.board().now_us();
        assert_eq!(bus.master().ping(5), Err(dxl::Error::Timeout));
        let t1 = bus.board().now_us();
        // 10-byte PING at 1 Mbps = 100 µs, then exactly the reply timeout (poll steps of 20 µs).
        assert_eq!(t1 - t0, 100 + u64::from(cfg.reply_timeout_us));
        assert_eq!(bus.stats().timeouts, 1);
        assert_eq!(bus.counters().timeouts, 1);
    }

    #[test]
    fn counters_saturate() {
        let s = BusStats {
            timeouts: 70_000,
            crc_errors: 3,
            malformed: 4,
            status_errors: 5,
            ..BusStats::default()
        };
        let c = counters(&s);
        assert_eq!((c.timeouts, c.crc, c.status), (65535, 7, 5));
    }

    #[test]
    fn no_dir_pin() {
        let mut p = NoDir;
        assert!(p.set_high().is_ok() && p.set_low().is_ok());
    }
}
