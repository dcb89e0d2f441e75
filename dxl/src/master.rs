//! Hardware-independent bus master (the controller side of a half-duplex Dynamixel bus).
//!
//! The driver owns three small abstractions:
//!
//! * a [`Transport`] moving bytes, whose read is *non-blocking* so that the driver can
//!   enforce reply timeouts ([`IoTransport`] adapts any `embedded_io` `Read + ReadReady +
//!   Write` UART);
//! * an [`OutputPin`] selecting the half-duplex direction: driven high before a packet is
//!   written, low again once the transmitter is flushed;
//! * a [`Clock`] giving microseconds for the timeouts.
//!
//! Every transaction flushes stale input, sends one instruction packet from a bounded
//! buffer, then waits for status packets, each within [`Master::timeout_us`] of the previous
//! event. Non-status packets (e.g. the echo of our own transmission) are ignored. Group
//! reads report a result *per device*: a missing or corrupted reply only fails that device.
//! Error counters are kept in [`BusStats`].

use core::ops::Range;

use embedded_hal::digital::OutputPin;
use embedded_io::{ErrorKind, Read, ReadReady, Write};

use crate::instruction::{
    encode_bulk_read, encode_bulk_write, encode_sync_write, BulkReadRequest, BulkWriteEntry,
    FastSyncParts, Instruction, Status, StatusError,
};
use crate::packet::{DecodeError, Decoder, DecoderStats, EncodeError, Packet, BROADCAST_ID};

/// Monotonic microsecond time source (the firmware's boards implement it: `board::Clock`).
pub trait Clock {
    /// Microseconds since an arbitrary start (boot).
    fn now_us(&self) -> u64;
}

impl<T: Clock + ?Sized> Clock for &mut T {
    fn now_us(&self) -> u64 {
        (**self).now_us()
    }
}

/// Byte transport of the bus.
pub trait Transport {
    /// Queues all bytes for transmission.
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), ErrorKind>;
    /// Blocks until every queued byte has left the transmitter.
    fn flush(&mut self) -> Result<(), ErrorKind>;
    /// Returns a received byte if one is available now; never blocks.
    fn read_byte(&mut self) -> Result<Option<u8>, ErrorKind>;
    /// Reads up to `buf.len()` received bytes (a block read); how many. The default reads
    /// one byte with [`read_byte`](Self::read_byte); a transport that can move a block at once
    /// (a FIFO, a DMA buffer, a lock-step emulation) overrides it, waiting no longer than its
    /// `read_byte` would for one byte.
    fn read_bytes(&mut self, buf: &mut [u8]) -> Result<usize, ErrorKind> {
        let Some(slot) = buf.first_mut() else {
            return Ok(0);
        };
        Ok(match self.read_byte()? {
            Some(b) => {
                *slot = b;
                1
            }
            None => 0,
        })
    }
}

/// Size of the master's receive block (bytes read from the transport at a time, at most).
pub const RX_BLOCK: usize = 64;

/// Adapts an `embedded_io` UART (`Read + ReadReady + Write`) to [`Transport`].
#[derive(Debug)]
pub struct IoTransport<T>(pub T);

impl<T: Read + ReadReady + Write> Transport for IoTransport<T> {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), ErrorKind> {
        Write::write_all(&mut self.0, bytes).map_err(|e| embedded_io::Error::kind(&e))
    }

    fn flush(&mut self) -> Result<(), ErrorKind> {
        Write::flush(&mut self.0).map_err(|e| embedded_io::Error::kind(&e))
    }

    fn read_byte(&mut self) -> Result<Option<u8>, ErrorKind> {
        let kind = |e: T::Error| embedded_io::Error::kind(&e);
        if !self.0.read_ready().map_err(kind)? {
            return Ok(None);
        }
        let mut b = [0u8; 1];
        match self.0.read(&mut b).map_err(kind)? {
            1 => Ok(Some(b[0])),
            _ => Ok(None),
        }
    }
}

/// Driver error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error {
    /// No (complete) reply before the deadline.
    Timeout,
    /// The reply failed its CRC check.
    Crc,
    /// The reply had the wrong shape (not a status packet, wrong data length, …).
    Malformed,
    /// Only replies from other devices arrived.
    WrongId,
    /// The device reported an error.
    Status(StatusError),
    /// The transport failed.
    Io(#[cfg_attr(feature = "defmt", defmt(Debug2Format))] ErrorKind),
    /// The direction pin failed.
    Pin,
    /// A buffer (the driver's or the caller's) is too small.
    BufferTooSmall,
    /// Inconsistent arguments (lengths, IDs).
    InvalidArgument,
}

impl From<EncodeError> for Error {
    fn from(e: EncodeError) -> Self {
        match e {
            EncodeError::BufferTooSmall => Error::BufferTooSmall,
            EncodeError::TooLong | EncodeError::InvalidArgument => Error::InvalidArgument,
        }
    }
}

/// Error counters of a [`Master`] (wrapping).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusStats {
    /// Instruction packets sent.
    pub tx_packets: u32,
    /// Status packets accepted.
    pub rx_status: u32,
    /// Expected replies that never came.
    pub timeouts: u32,
    /// Replies rejected for a bad CRC.
    pub crc_errors: u32,
    /// Framing errors and malformed replies.
    pub malformed: u32,
    /// Replies from unexpected devices.
    pub wrong_id: u32,
    /// Replies carrying a result error.
    pub status_errors: u32,
    /// Replies with the hardware-alert bit set.
    pub hardware_alerts: u32,
    /// Transport or pin failures.
    pub io_errors: u32,
}

/// Reply to a PING.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PingInfo {
    /// Model number.
    pub model: u16,
    /// Firmware version.
    pub firmware: u8,
}

/// Per-device outcome of a group read.
pub type DeviceResult = Result<(), Error>;

/// What the receiver saw next.
enum Event {
    Status(u8),
    Crc(u8),
    Framing,
    Timeout,
}

fn inc(c: &mut u32) {
    *c = c.wrapping_add(1);
}

/// Validates the current status packet and returns its data.
fn status_data<'a>(p: Option<Packet<'a>>, stats: &mut BusStats) -> Result<&'a [u8], Error> {
    let Some(st) = p.and_then(|p| Status::from_packet(&p).ok()) else {
        inc(&mut stats.malformed);
        return Err(Error::Malformed);
    };
    if st.error.alert {
        inc(&mut stats.hardware_alerts);
    }
    if !st.error.is_ok() {
        inc(&mut stats.status_errors);
        return Err(Error::Status(st.error));
    }
    Ok(st.data)
}

/// Copies a status reply's data into `out`, which must have the same length.
fn copy_reply(
    data: Result<&[u8], Error>,
    out: Option<&mut [u8]>,
    stats: &mut BusStats,
) -> DeviceResult {
    let data = data?;
    match out {
        Some(out) if out.len() == data.len() => {
            out.copy_from_slice(data);
            Ok(())
        }
        _ => {
            inc(&mut stats.malformed);
            Err(Error::Malformed)
        }
    }
}

/// Dynamixel Protocol 2.0 bus master with `N`-byte transmit and receive buffers.
#[derive(Debug)]
pub struct Master<T, P, C, const N: usize = 256> {
    transport: T,
    dir: P,
    clock: C,
    tx: [u8; N],
    rx: Decoder<N>,
    /// Received bytes not yet fed to the decoder: `block[head..tail]` (left over when an
    /// event ended a block early).
    block: [u8; RX_BLOCK],
    head: usize,
    tail: usize,
    timeout_us: u64,
    stats: BusStats,
}

/// The outcome of a group read: its devices that timed out counted in `stats`, the number
/// that answered correctly returned.
fn tally(results: &[DeviceResult], stats: &mut BusStats) -> usize {
    let missing = results
        .iter()
        .filter(|r| **r == Err(Error::Timeout))
        .count();
    stats.timeouts = stats.timeouts.wrapping_add(missing as u32);
    results.iter().filter(|r| r.is_ok()).count()
}

/// Checks the devices of a group read/write: 1 to 253 of them, one result slot each, every id a
/// device id (not broadcast).
fn check_targets(
    ids: impl ExactSizeIterator<Item = u8>,
    results: &[DeviceResult],
) -> Result<(), Error> {
    let n = ids.len();
    if n == 0 || n > 253 || n != results.len() {
        return Err(Error::InvalidArgument);
    }
    let mut ids = ids;
    if ids.any(|i| i > crate::packet::MAX_DEVICE_ID) {
        return Err(Error::InvalidArgument);
    }
    Ok(())
}

impl<T: Transport, P: OutputPin, C: Clock, const N: usize> Master<T, P, C, N> {
    /// Default reply timeout in µs.
    pub const DEFAULT_TIMEOUT_US: u64 = 3_000;
    /// Upper bound on stale bytes discarded before a transaction.
    const MAX_DRAIN: usize = N + 64;

    /// Creates a driver; the direction pin is left as it is until the first transaction.
    pub fn new(transport: T, dir: P, clock: C) -> Self {
        Master {
            transport,
            dir,
            clock,
            tx: [0; N],
            rx: Decoder::new(),
            block: [0; RX_BLOCK],
            head: 0,
            tail: 0,
            timeout_us: Self::DEFAULT_TIMEOUT_US,
            stats: BusStats::default(),
        }
    }

    /// Reply timeout in µs (per expected status packet).
    pub fn timeout_us(&self) -> u64 {
        self.timeout_us
    }

    /// Sets the reply timeout in µs.
    pub fn set_timeout_us(&mut self, us: u64) {
        self.timeout_us = us;
    }

    /// Error counters.
    pub fn stats(&self) -> BusStats {
        self.stats
    }

    /// Receive-level counters of the packet decoder.
    pub fn decoder_stats(&self) -> DecoderStats {
        self.rx.stats()
    }

    /// Gives back the transport, pin and clock.
    pub fn release(self) -> (T, P, C) {
        (self.transport, self.dir, self.clock)
    }

    /// Mutable access to the transport (e.g. to change the baud rate).
    pub fn transport_mut(&mut self) -> &mut T {
        &mut self.transport
    }

    fn io<R>(&mut self, r: Result<R, ErrorKind>) -> Result<R, Error> {
        r.map_err(|e| {
            inc(&mut self.stats.io_errors);
            Error::Io(e)
        })
    }

    /// Sends the first `len` bytes of the transmit buffer.
    fn send(&mut self, len: usize) -> Result<(), Error> {
        for _ in 0..Self::MAX_DRAIN {
            let r = self.transport.read_byte();
            if self.io(r)?.is_none() {
                break;
            }
        }
        self.head = 0;
        self.tail = 0;
        self.rx.reset();
        self.rx.set_stuffing(true);
        let bytes = self.tx.get(..len).ok_or(Error::BufferTooSmall)?;
        if self.dir.set_high().is_err() {
            inc(&mut self.stats.io_errors);
            return Err(Error::Pin);
        }
        let written = self
            .transport
            .write_all(bytes)
            .and_then(|()| self.transport.flush());
        // Release the bus even if the write failed.
        let released = self.dir.set_low();
        self.io(written)?;
        if released.is_err() {
            inc(&mut self.stats.io_errors);
            return Err(Error::Pin);
        }
        inc(&mut self.stats.tx_packets);
        Ok(())
    }

    fn deadline(&self) -> u64 {
        self.clock.now_us().saturating_add(self.timeout_us)
    }

    /// Reads bytes until a status packet, a decode error or the deadline.
    ///
    /// Block reads: it asks the transport for [`Decoder::wanted`] bytes (at most
    /// [`RX_BLOCK`]: the rest of the frame being received, never past the end of a valid
    /// reply) and feeds them to the decoder at once; bytes after an event (possible only
    /// when a broken frame is interrupted by a new packet) wait in `block` for the next call.
    fn poll(&mut self, deadline: u64) -> Result<Event, Error> {
        loop {
            if self.head >= self.tail {
                if self.clock.now_us() >= deadline {
                    return Ok(Event::Timeout);
                }
                let want = self.rx.wanted().clamp(1, RX_BLOCK);
                let dst = self.block.get_mut(..want).unwrap_or(&mut []);
                let r = self.transport.read_bytes(dst);
                let got = self.io(r)?;
                self.head = 0;
                self.tail = got.min(want);
                continue;
            }
            let pending = self.block.get(self.head..self.tail).unwrap_or(&[]);
            let (used, ev) = self.rx.feed(pending);
            self.head += used.max(1);
            let Some(ev) = ev else { continue };
            match ev {
                Ok(p) if p.instruction == crate::instruction::opcode::STATUS => {
                    inc(&mut self.stats.rx_status);
                    return Ok(Event::Status(p.id));
                }
                Ok(_) => {} // our own echo or another master's instruction
                Err(DecodeError::Crc { id }) => {
                    inc(&mut self.stats.crc_errors);
                    return Ok(Event::Crc(id));
                }
                Err(_) => {
                    inc(&mut self.stats.malformed);
                    return Ok(Event::Framing);
                }
            }
        }
    }

    /// Waits for the status packet of `id`; it is then available from `self.rx.packet()`.
    fn wait_status(&mut self, id: u8) -> Result<(), Error> {
        let deadline = self.deadline();
        let mut wrong_id = false;
        loop {
            match self.poll(deadline)? {
                Event::Status(pid) if pid == id => return Ok(()),
                Event::Status(_) => {
                    inc(&mut self.stats.wrong_id);
                    wrong_id = true;
                }
                Event::Crc(pid) if pid == id => return Err(Error::Crc),
                Event::Crc(_) | Event::Framing => {}
                Event::Timeout => {
                    inc(&mut self.stats.timeouts);
                    return Err(if wrong_id {
                        Error::WrongId
                    } else {
                        Error::Timeout
                    });
                }
            }
        }
    }

    /// Sends an instruction to `id` and, unless `id` is broadcast, checks its status reply.
    fn command(&mut self, id: u8, inst: &Instruction<'_>) -> Result<(), Error> {
        let n = inst.encode(&mut self.tx, id)?;
        self.send(n)?;
        if id == BROADCAST_ID {
            return Ok(());
        }
        self.wait_status(id)?;
        status_data(self.rx.packet(), &mut self.stats).map(|_| ())
    }

    /// Sends any instruction; waits for and checks the status unless `id` is broadcast.
    pub fn instruction(&mut self, id: u8, inst: &Instruction<'_>) -> Result<(), Error> {
        self.command(id, inst)
    }

    /// PING: returns the model number and firmware version.
    pub fn ping(&mut self, id: u8) -> Result<PingInfo, Error> {
        if id == BROADCAST_ID {
            return Err(Error::InvalidArgument);
        }
        let n = Instruction::Ping.encode(&mut self.tx, id)?;
        self.send(n)?;
        self.wait_status(id)?;
        match status_data(self.rx.packet(), &mut self.stats)? {
            &[lo, hi, firmware] => Ok(PingInfo {
                model: u16::from_le_bytes([lo, hi]),
                firmware,
            }),
            _ => {
                inc(&mut self.stats.malformed);
                Err(Error::Malformed)
            }
        }
    }

    /// READ `buf.len()` bytes at `addr` of device `id`.
    pub fn read(&mut self, id: u8, addr: u16, buf: &mut [u8]) -> Result<(), Error> {
        let len = u16::try_from(buf.len()).map_err(|_| Error::InvalidArgument)?;
        if id == BROADCAST_ID {
            return Err(Error::InvalidArgument);
        }
        let n = Instruction::Read { addr, len }.encode(&mut self.tx, id)?;
        self.send(n)?;
        self.wait_status(id)?;
        let data = status_data(self.rx.packet(), &mut self.stats);
        copy_reply(data, Some(buf), &mut self.stats)
    }

    /// WRITE `data` at `addr`; checks the status (no reply is awaited for broadcast).
    pub fn write(&mut self, id: u8, addr: u16, data: &[u8]) -> Result<(), Error> {
        self.command(id, &Instruction::Write { addr, data })
    }

    /// REG WRITE `data` at `addr` (executed by [`action`](Self::action)).
    pub fn reg_write(&mut self, id: u8, addr: u16, data: &[u8]) -> Result<(), Error> {
        self.command(id, &Instruction::RegWrite { addr, data })
    }

    /// ACTION (use [`BROADCAST_ID`] to trigger all registered writes at once).
    pub fn action(&mut self, id: u8) -> Result<(), Error> {
        self.command(id, &Instruction::Action)
    }

    /// REBOOT device `id`.
    pub fn reboot(&mut self, id: u8) -> Result<(), Error> {
        self.command(id, &Instruction::Reboot)
    }

    /// SYNC WRITE `len` bytes at `addr` to each `(id, data)`; no replies.
    pub fn sync_write(
        &mut self,
        addr: u16,
        len: u16,
        entries: &[(u8, &[u8])],
    ) -> Result<(), Error> {
        let n = encode_sync_write(&mut self.tx, addr, len, entries)?;
        self.send(n)
    }

    /// BULK WRITE; no replies.
    pub fn bulk_write(&mut self, entries: &[BulkWriteEntry<'_>]) -> Result<(), Error> {
        let n = encode_bulk_write(&mut self.tx, entries)?;
        self.send(n)
    }

    /// Collects group-read replies; device `i` has ID `id_at(i)` and output range `slot(i)`.
    fn collect(
        &mut self,
        count: usize,
        id_at: &dyn Fn(usize) -> Option<u8>,
        slot: &dyn Fn(usize) -> Option<Range<usize>>,
        out: &mut [u8],
        results: &mut [DeviceResult],
    ) -> Result<usize, Error> {
        results.iter_mut().for_each(|r| *r = Err(Error::Timeout));
        // Index of the first device whose reply may still come (replies arrive in order).
        let mut next = 0;
        let mut deadline = self.deadline();
        while next < count {
            let find = |pid: u8| (next..count).find(|&i| id_at(i) == Some(pid));
            let (idx, result) = match self.poll(deadline)? {
                Event::Timeout => break,
                Event::Framing => continue,
                Event::Status(pid) => {
                    let Some(idx) = find(pid) else {
                        inc(&mut self.stats.wrong_id);
                        continue;
                    };
                    let data = status_data(self.rx.packet(), &mut self.stats);
                    let dst = slot(idx).and_then(|r| out.get_mut(r));
                    (idx, copy_reply(data, dst, &mut self.stats))
                }
                Event::Crc(pid) => {
                    let Some(idx) = find(pid) else { continue };
                    (idx, Err(Error::Crc))
                }
            };
            if let Some(r) = results.get_mut(idx) {
                *r = result;
            }
            next = idx + 1;
            deadline = self.deadline();
        }
        Ok(tally(results, &mut self.stats))
    }

    /// Checks a SYNC READ / FAST SYNC READ request; returns the per-device length.
    fn check_sync(
        ids: &[u8],
        len: u16,
        out: &[u8],
        results: &[DeviceResult],
    ) -> Result<usize, Error> {
        check_targets(ids.iter().copied(), results)?;
        let l = usize::from(len);
        if out.len() < ids.len().saturating_mul(l) {
            return Err(Error::BufferTooSmall);
        }
        Ok(l)
    }

    /// SYNC READ `len` bytes at `addr` from each of `ids`.
    ///
    /// Device `i`'s data lands in `out[i*len..(i+1)*len]` and its outcome in `results[i]`
    /// (`results.len()` must equal `ids.len()`). Returns the number of devices that answered
    /// correctly; the outer error is reserved for bus-level failures.
    pub fn sync_read(
        &mut self,
        addr: u16,
        len: u16,
        ids: &[u8],
        out: &mut [u8],
        results: &mut [DeviceResult],
    ) -> Result<usize, Error> {
        let l = Self::check_sync(ids, len, out, results)?;
        let n = Instruction::SyncRead { addr, len, ids }.encode(&mut self.tx, BROADCAST_ID)?;
        self.send(n)?;
        let id_at = |i: usize| ids.get(i).copied();
        let slot = |i: usize| Some(i * l..(i + 1) * l);
        self.collect(ids.len(), &id_at, &slot, out, results)
    }

    /// BULK READ: each request's data lands in `out` consecutively, in request order.
    ///
    /// `results.len()` must equal `requests.len()`; returns the number of good replies.
    pub fn bulk_read(
        &mut self,
        requests: &[BulkReadRequest],
        out: &mut [u8],
        results: &mut [DeviceResult],
    ) -> Result<usize, Error> {
        check_targets(requests.iter().map(|r| r.id), results)?;
        let total: usize = requests.iter().map(|r| usize::from(r.len)).sum();
        if out.len() < total {
            return Err(Error::BufferTooSmall);
        }
        let n = encode_bulk_read(&mut self.tx, requests)?;
        self.send(n)?;
        let slot = |i: usize| {
            let start: usize = requests.get(..i)?.iter().map(|r| usize::from(r.len)).sum();
            Some(start..start + usize::from(requests.get(i)?.len))
        };
        let id_at = |i: usize| requests.get(i).map(|r| r.id);
        self.collect(requests.len(), &id_at, &slot, out, results)
    }

    /// FAST SYNC READ: like [`sync_read`](Self::sync_read), answered by one combined packet.
    ///
    /// The whole reply must arrive within `timeout_us × ids.len()`. If it is lost or its CRC
    /// fails, every device gets that error (the parts cannot be salvaged); otherwise each
    /// part is checked individually (error byte, intermediate CRC, ID).
    pub fn fast_sync_read(
        &mut self,
        addr: u16,
        len: u16,
        ids: &[u8],
        out: &mut [u8],
        results: &mut [DeviceResult],
    ) -> Result<usize, Error> {
        let l = Self::check_sync(ids, len, out, results)?;
        let inst = Instruction::FastSyncRead { addr, len, ids };
        let n = inst.encode(&mut self.tx, BROADCAST_ID)?;
        self.send(n)?;
        self.rx.set_stuffing(false);
        let wait = self.timeout_us.saturating_mul(ids.len() as u64);
        let deadline = self.clock.now_us().saturating_add(wait);
        let outcome = loop {
            match self.poll(deadline) {
                Ok(Event::Status(BROADCAST_ID)) => break Ok(()),
                Ok(Event::Status(_)) => inc(&mut self.stats.wrong_id),
                Ok(Event::Crc(BROADCAST_ID)) => break Err(Error::Crc),
                Ok(Event::Crc(_) | Event::Framing) => {}
                Ok(Event::Timeout) => break Err(Error::Timeout),
                Err(e) => break Err(e),
            }
        };
        self.rx.set_stuffing(true);
        if let Err(e) = outcome {
            if matches!(e, Error::Io(_)) {
                return Err(e);
            }
            results.iter_mut().for_each(|r| *r = Err(e));
            if e == Error::Timeout {
                self.stats.timeouts = self.stats.timeouts.wrapping_add(ids.len() as u32);
            }
            return Ok(0);
        }
        results.iter_mut().for_each(|r| *r = Err(Error::Timeout));
        let packet = self.rx.packet();
        let Some(parts) = packet.and_then(|p| FastSyncParts::parse(&p, len).ok()) else {
            inc(&mut self.stats.malformed);
            results.iter_mut().for_each(|r| *r = Err(Error::Malformed));
            return Ok(0);
        };
        let mut next = 0;
        for part in parts {
            let pos = ids
                .get(next..)
                .and_then(|r| r.iter().position(|&i| i == part.id));
            let Some(k) = pos else {
                inc(&mut self.stats.wrong_id);
                continue;
            };
            let idx = next + k;
            next = idx + 1;
            if part.error.alert {
                inc(&mut self.stats.hardware_alerts);
            }
            let r = if !part.crc_ok {
                inc(&mut self.stats.crc_errors);
                Err(Error::Crc)
            } else if !part.error.is_ok() {
                inc(&mut self.stats.status_errors);
                Err(Error::Status(part.error))
            } else {
                copy_reply(
                    Ok(part.data),
                    out.get_mut(idx * l..(idx + 1) * l),
                    &mut self.stats,
                )
            };
            if let Some(slot) = results.get_mut(idx) {
                *slot = r;
            }
        }
        Ok(tally(results, &mut self.stats))
    }
}
