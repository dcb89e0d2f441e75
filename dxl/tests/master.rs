//! The bus master against a scripted mock bus (transport, direction pin and clock).

use std::cell::RefCell;
use std::collections::VecDeque;
use std::convert::Infallible;
use std::rc::Rc;

use dxl::table::{foot::FootForces, imu::ImuSample, x_series};

/// The reference robot's sensor boards (their IDs are the robot's: `walker-contract`).
mod ids {
    pub const FOOT_LEFT: u8 = 111;
    pub const FOOT_RIGHT: u8 = 112;
    pub const IMU: u8 = 200;
}
use dxl::*;
use embedded_io::ErrorKind;

/// Time to send one byte at 1 Mbps (10 bits).
const BYTE_US: u64 = 10;
const TIMEOUT_US: u64 = 1_000;

/// One scripted reply: bytes sent `delay_us` after the instruction was flushed.
#[derive(Clone)]
struct Reply {
    delay_us: u64,
    bytes: Vec<u8>,
    /// All bytes arrive at once (a FIFO or DMA buffer read late), not one per byte time.
    burst: bool,
}

#[derive(Default)]
struct Bus {
    now: u64,
    pin_high: bool,
    pin_log: Vec<bool>,
    pin_fails: bool,
    written: Vec<Vec<u8>>,
    pending: Vec<u8>,
    wrote_with_pin_low: bool,
    write_fails: bool,
    /// Echo our own transmission back (as some half-duplex adapters do).
    echo: bool,
    rx: VecDeque<(u64, u8)>,
    scripts: VecDeque<Vec<Reply>>,
    /// Calls of `read_bytes` that returned bytes.
    block_reads: u32,
}

#[derive(Clone, Default)]
struct Shared(Rc<RefCell<Bus>>);

impl Shared {
    fn script(&self, replies: Vec<Reply>) {
        self.0.borrow_mut().scripts.push_back(replies);
    }
    fn inject(&self, bytes: &[u8]) {
        let mut b = self.0.borrow_mut();
        let t = b.now;
        b.rx.extend(bytes.iter().map(|&x| (t, x)));
    }
    fn written(&self) -> Vec<Vec<u8>> {
        self.0.borrow().written.clone()
    }
    fn bus(&self) -> std::cell::RefMut<'_, Bus> {
        self.0.borrow_mut()
    }
}

struct MockTransport(Shared);
struct MockPin(Shared);
struct MockClock(Shared);

impl Transport for MockTransport {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), ErrorKind> {
        let mut b = self.0.bus();
        if b.write_fails {
            return Err(ErrorKind::BrokenPipe);
        }
        if !b.pin_high {
            b.wrote_with_pin_low = true;
        }
        b.pending.extend_from_slice(bytes);
        Ok(())
    }

    fn flush(&mut self) -> Result<(), ErrorKind> {
        let mut b = self.0.bus();
        let pkt = std::mem::take(&mut b.pending);
        b.now += pkt.len() as u64 * BYTE_US;
        let now = b.now;
        if b.echo {
            b.rx.extend(pkt.iter().map(|&x| (now, x)));
        }
        b.written.push(pkt);
        let replies = b.scripts.pop_front().unwrap_or_default();
        let mut t = now;
        for r in replies {
            t = t.max(now + r.delay_us);
            if r.burst {
                t += r.bytes.len() as u64 * BYTE_US;
            }
            for &x in &r.bytes {
                if !r.burst {
                    t += BYTE_US;
                }
                b.rx.push_back((t, x));
            }
        }
        Ok(())
    }

    fn read_byte(&mut self) -> Result<Option<u8>, ErrorKind> {
        let mut b = self.0.bus();
        match b.rx.front() {
            Some(&(t, x)) if t <= b.now => {
                b.rx.pop_front();
                Ok(Some(x))
            }
            _ => Ok(None),
        }
    }

    /// Block reads (as the firmware's link does): every byte that has arrived, up to
    /// `buf.len()`, so the master's leftover queue is exercised whenever a block holds more
    /// than the event that ends it (echo + reply, corrupted frames, junk).
    fn read_bytes(&mut self, buf: &mut [u8]) -> Result<usize, ErrorKind> {
        let mut b = self.0.bus();
        let mut n = 0;
        while let (Some(slot), Some(&(t, x))) = (buf.get_mut(n), b.rx.front()) {
            if t > b.now {
                break;
            }
            *slot = x;
            b.rx.pop_front();
            n += 1;
        }
        if n > 0 {
            b.block_reads += 1;
        }
        Ok(n)
    }
}

#[derive(Debug)]
struct PinError;

impl embedded_hal::digital::Error for PinError {
    fn kind(&self) -> embedded_hal::digital::ErrorKind {
        embedded_hal::digital::ErrorKind::Other
    }
}

impl embedded_hal::digital::ErrorType for MockPin {
    type Error = PinError;
}

impl embedded_hal::digital::OutputPin for MockPin {
    fn set_low(&mut self) -> Result<(), PinError> {
        let mut b = self.0.bus();
        b.pin_high = false;
        b.pin_log.push(false);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), PinError> {
        let mut b = self.0.bus();
        if b.pin_fails {
            return Err(PinError);
        }
        b.pin_high = true;
        b.pin_log.push(true);
        Ok(())
    }
}

impl Clock for MockClock {
    fn now_us(&self) -> u64 {
        let mut b = self.0.bus();
        b.now += 1;
        b.now
    }
}

type TestMaster = Master<MockTransport, MockPin, MockClock, 256>;

fn setup() -> (TestMaster, Shared) {
    let s = Shared::default();
    let mut m = Master::new(
        MockTransport(s.clone()),
        MockPin(s.clone()),
        MockClock(s.clone()),
    );
    m.set_timeout_us(TIMEOUT_US);
    (m, s)
}

fn status(id: u8, err: u8, data: &[u8]) -> Vec<u8> {
    let mut b = [0u8; 300];
    let n = encode_status(&mut b, id, StatusError::from_byte(err), data).unwrap();
    b[..n].to_vec()
}

fn reply(bytes: Vec<u8>) -> Reply {
    Reply {
        delay_us: 20,
        bytes,
        burst: false,
    }
}

fn late(bytes: Vec<u8>) -> Reply {
    Reply {
        delay_us: TIMEOUT_US + 500,
        bytes,
        burst: false,
    }
}

fn corrupt(mut bytes: Vec<u8>, at: usize) -> Vec<u8> {
    bytes[at] ^= 0x40;
    bytes
}

fn pos_bytes(v: i32) -> [u8; 4] {
    v.to_le_bytes()
}

#[test]
fn ping_reports_model_and_drives_the_direction_pin() {
    let (mut m, s) = setup();
    s.script(vec![reply(status(1, 0, &[0xFC, 0x03, 0x2E]))]);
    let info = m.ping(1).unwrap();
    assert_eq!(
        info,
        PingInfo {
            model: x_series::MODEL_XM430_W350,
            firmware: 0x2E
        }
    );
    assert_eq!(
        s.written(),
        vec![vec![
            0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x01, 0x19, 0x4E
        ]]
    );
    let b = s.bus();
    assert_eq!(b.pin_log, vec![true, false]);
    assert!(!b.wrote_with_pin_low);
    assert!(!b.pin_high);
    drop(b);
    assert_eq!(m.stats().tx_packets, 1);
    assert_eq!(m.stats().rx_status, 1);
    // Ping reply of the wrong size.
    s.script(vec![reply(status(1, 0, &[0xFC, 0x03]))]);
    assert_eq!(m.ping(1), Err(Error::Malformed));
    assert_eq!(m.ping(BROADCAST_ID), Err(Error::InvalidArgument));
}

#[test]
fn read_success_and_every_error_path() {
    let (mut m, s) = setup();
    let good = status(1, 0, &pos_bytes(2048));
    let mut buf = [0u8; 4];

    s.script(vec![reply(good.clone())]);
    m.read(1, x_series::PRESENT_POSITION.addr, &mut buf)
        .unwrap();
    assert_eq!(i32::from_le_bytes(buf), 2048);
    assert_eq!(
        s.written()[0],
        vec![0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x07, 0x00, 0x02, 0x84, 0x00, 0x04, 0x00, 0x1D, 0x15]
    );

    // Dropped reply.
    s.script(vec![]);
    assert_eq!(m.read(1, 132, &mut buf), Err(Error::Timeout));
    // Late reply (beyond the timeout) ...
    s.script(vec![late(good.clone())]);
    assert_eq!(m.read(1, 132, &mut buf), Err(Error::Timeout));
    // ... whose stale bytes must not confuse the next transaction.
    s.bus().now += 10 * TIMEOUT_US;
    s.script(vec![reply(status(1, 0, &pos_bytes(7)))]);
    m.read(1, 132, &mut buf).unwrap();
    assert_eq!(i32::from_le_bytes(buf), 7);
    // Corrupted byte in the data.
    s.script(vec![reply(corrupt(good.clone(), 10))]);
    assert_eq!(m.read(1, 132, &mut buf), Err(Error::Crc));
    // Garbage first, then a valid packet.
    let mut noisy = vec![0x00, 0xFF, 0x13, 0xFF, 0xFF, 0xFD, 0x37, 0xFF];
    noisy.extend_from_slice(&good);
    s.script(vec![reply(noisy)]);
    m.read(1, 132, &mut buf).unwrap();
    // Only another device answers.
    s.script(vec![reply(status(2, 0, &pos_bytes(1)))]);
    assert_eq!(m.read(1, 132, &mut buf), Err(Error::WrongId));
    // Another device answers first, then the right one.
    s.script(vec![
        reply(status(2, 0, &pos_bytes(1))),
        reply(good.clone()),
    ]);
    m.read(1, 132, &mut buf).unwrap();
    // Device error.
    s.script(vec![reply(status(1, 0x04, &[]))]);
    assert_eq!(
        m.read(1, 132, &mut buf),
        Err(Error::Status(StatusError {
            alert: false,
            code: Some(ErrorCode::DataRange)
        }))
    );
    // Hardware alert only: data is valid, the alert is counted.
    s.script(vec![reply(status(1, 0x80, &pos_bytes(5)))]);
    m.read(1, 132, &mut buf).unwrap();
    // Wrong data length.
    s.script(vec![reply(status(1, 0, &[1, 2]))]);
    assert_eq!(m.read(1, 132, &mut buf), Err(Error::Malformed));
    // A status packet without an error byte.
    let mut b = [0u8; 16];
    let n = encode(&mut b, 1, opcode::STATUS, &[]).unwrap();
    s.script(vec![reply(b[..n].to_vec())]);
    assert_eq!(m.read(1, 132, &mut buf), Err(Error::Malformed));
    // Truncated reply.
    s.script(vec![reply(good[..good.len() - 3].to_vec())]);
    assert_eq!(m.read(1, 132, &mut buf), Err(Error::Timeout));
    // A framing error (impossible LEN) followed by the real reply.
    let mut framed = vec![0xFF, 0xFF, 0xFD, 0x00, 0x01, 0xF0, 0xF0];
    framed.extend_from_slice(&good);
    s.script(vec![reply(framed)]);
    m.read(1, 132, &mut buf).unwrap();

    assert_eq!(
        m.read(BROADCAST_ID, 132, &mut buf),
        Err(Error::InvalidArgument)
    );
    let st = m.stats();
    assert_eq!(st.timeouts, 4);
    assert_eq!(st.crc_errors, 1);
    assert_eq!(st.wrong_id, 2);
    assert_eq!(st.status_errors, 1);
    assert_eq!(st.hardware_alerts, 1);
    assert_eq!(st.malformed, 3);
    assert!(m.decoder_stats().skipped_bytes > 0);
}

#[test]
fn echo_and_stale_input_are_ignored() {
    let (mut m, s) = setup();
    s.bus().echo = true;
    s.inject(&[0x12, 0x34, 0xFF, 0xFF]);
    s.script(vec![reply(status(3, 0, &[1]))]);
    let mut buf = [0u8; 1];
    m.read(3, x_series::MOVING.addr, &mut buf).unwrap();
    assert_eq!(buf, [1]);
    assert!(s.bus().rx.is_empty());
}

#[test]
fn block_reads_keep_the_bytes_after_an_event() {
    // An interrupted frame (its LEN covers the next reply's start), another device's
    // corrupted reply and then the reply, all in one burst: one block read takes the frame the decoder
    // wants; every event (framing, CRC) leaves the rest of the block queued, and the reply is
    // still found. Byte by byte (`read_byte`) the same stream gives the same result.
    let good = status(1, 0, &[0x10, 0x20]);
    let mut stream = vec![0xFF, 0xFF, 0xFD, 0x00, 0x02, 0x20, 0x00, 0x55, 0x00];
    stream.extend(corrupt(status(2, 0, &[0x10, 0x20]), 9));
    stream.extend(&good);
    for burst in [true, false] {
        let (mut m, s) = setup();
        s.script(vec![Reply {
            delay_us: 20,
            bytes: stream.clone(),
            burst,
        }]);
        let mut buf = [0u8; 2];
        m.read(1, 132, &mut buf).unwrap();
        assert_eq!(buf, [0x10, 0x20]);
        let d = m.decoder_stats();
        assert_eq!((d.packets, d.framing_errors), (1, 1), "burst {burst}");
        assert_eq!(d.crc_errors, 1, "burst {burst}");
        // A burst is read in a few blocks, not byte by byte.
        let reads = s.bus().block_reads;
        if burst {
            assert!(reads <= 6, "{reads} block reads");
        }
    }
}

#[test]
fn writes() {
    let (mut m, s) = setup();
    s.script(vec![reply(status(1, 0, &[]))]);
    m.write(1, x_series::GOAL_POSITION.addr, &pos_bytes(512))
        .unwrap();
    assert_eq!(
        s.written()[0],
        vec![
            0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x09, 0x00, 0x03, 0x74, 0x00, 0x00, 0x02, 0x00, 0x00,
            0xCA, 0x89
        ]
    );
    // Broadcast write: no reply awaited.
    m.write(BROADCAST_ID, x_series::TORQUE_ENABLE.addr, &[1])
        .unwrap();
    // Errors.
    s.script(vec![reply(status(1, 0x07, &[]))]);
    assert!(
        matches!(m.write(1, 7, &[9]), Err(Error::Status(e)) if e.code == Some(ErrorCode::Access))
    );
    s.script(vec![]);
    assert_eq!(m.write(1, 65, &[1]), Err(Error::Timeout));
    // REG WRITE + ACTION, REBOOT.
    s.script(vec![reply(status(2, 0, &[]))]);
    m.reg_write(2, 116, &pos_bytes(100)).unwrap();
    m.action(BROADCAST_ID).unwrap();
    s.script(vec![reply(status(2, 0, &[]))]);
    m.reboot(2).unwrap();
    s.script(vec![reply(status(2, 0, &[]))]);
    m.instruction(2, &Instruction::Action).unwrap();
    let w = s.written();
    assert_eq!(w[4][7], opcode::REG_WRITE);
    assert_eq!(w[5][7], opcode::ACTION);
    assert_eq!(
        w[6][..8],
        [0xFF, 0xFF, 0xFD, 0x00, 0x02, 0x03, 0x00, opcode::REBOOT]
    );
}

#[test]
fn group_writes_send_exact_bytes() {
    let (mut m, s) = setup();
    let (a, b) = (pos_bytes(150), pos_bytes(170));
    m.sync_write(116, 4, &[(1, &a), (2, &b)]).unwrap();
    let mut want = [0u8; 64];
    let n = encode_sync_write(&mut want, 116, 4, &[(1, &a), (2, &b)]).unwrap();
    assert_eq!(s.written()[0], want[..n].to_vec());
    assert_eq!(
        m.sync_write(116, 4, &[(1, &a[..2])]),
        Err(Error::InvalidArgument)
    );
    let entries = [
        BulkWriteEntry {
            id: 1,
            addr: 116,
            data: &a,
        },
        BulkWriteEntry {
            id: 111,
            addr: 9,
            data: &[0],
        },
    ];
    m.bulk_write(&entries).unwrap();
    let n = encode_bulk_write(&mut want, &entries).unwrap();
    assert_eq!(s.written()[1], want[..n].to_vec());
    // Nothing was awaited: no timeouts.
    assert_eq!(m.stats().timeouts, 0);
}

fn sync_read_with(replies: Vec<Reply>) -> (Vec<DeviceResult>, Vec<i32>, usize, TestMaster) {
    let (mut m, s) = setup();
    s.script(replies);
    let ids = [1u8, 2, 3];
    let mut out = [0u8; 12];
    let mut res = [Ok(()); 3];
    let ok = m.sync_read(132, 4, &ids, &mut out, &mut res).unwrap();
    let pos = out
        .chunks(4)
        .map(|c| i32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    (res.to_vec(), pos, ok, m)
}

#[test]
fn sync_read_reports_per_device() {
    let st = |id: u8, v: i32| status(id, 0, &pos_bytes(v));
    // All good.
    let (res, pos, ok, m) =
        sync_read_with(vec![reply(st(1, 10)), reply(st(2, 20)), reply(st(3, 30))]);
    assert_eq!((res, pos, ok), (vec![Ok(()); 3], vec![10, 20, 30], 3));
    assert_eq!(m.stats().timeouts, 0);
    // Device 2 silent: 1 and 3 still read.
    let (res, pos, ok, m) = sync_read_with(vec![reply(st(1, 10)), reply(st(3, 30))]);
    assert_eq!(res, vec![Ok(()), Err(Error::Timeout), Ok(())]);
    assert_eq!((pos[0], pos[2], ok), (10, 30, 2));
    assert_eq!(m.stats().timeouts, 1);
    // Device 2 corrupted.
    let (res, _, _, m) = sync_read_with(vec![
        reply(st(1, 10)),
        reply(corrupt(st(2, 20), 9)),
        reply(st(3, 30)),
    ]);
    assert_eq!(res, vec![Ok(()), Err(Error::Crc), Ok(())]);
    assert_eq!(m.stats().crc_errors, 1);
    // Device 3 late.
    let (res, _, _, _) = sync_read_with(vec![reply(st(1, 10)), reply(st(2, 20)), late(st(3, 30))]);
    assert_eq!(res, vec![Ok(()), Ok(()), Err(Error::Timeout)]);
    // Device 1 reports an error, garbage before device 2, an unknown device in between.
    let mut noisy = vec![0xFD, 0xFF, 0x00];
    noisy.extend(st(2, 20));
    let (res, pos, _, m) = sync_read_with(vec![
        reply(status(1, 0x01, &[])),
        reply(noisy),
        reply(st(9, 0)),
        reply(st(3, 30)),
    ]);
    assert!(matches!(res[0], Err(Error::Status(e)) if e.code == Some(ErrorCode::ResultFail)));
    assert_eq!(
        (&res[1..], &pos[1..]),
        (&[Ok(()), Ok(())][..], &[20, 30][..])
    );
    assert_eq!(m.stats().wrong_id, 1);
    // Wrong length from device 3.
    let (res, _, _, _) = sync_read_with(vec![
        reply(st(1, 10)),
        reply(st(2, 20)),
        reply(status(3, 0, &[1])),
    ]);
    assert_eq!(res[2], Err(Error::Malformed));
    // Nobody answers.
    let (res, _, ok, m) = sync_read_with(vec![]);
    assert_eq!((res, ok), (vec![Err(Error::Timeout); 3], 0));
    assert_eq!(m.stats().timeouts, 3);
}

#[test]
fn sync_read_sends_exact_bytes_and_checks_arguments() {
    let (mut m, s) = setup();
    let mut out = [0u8; 8];
    let mut res = [Ok(()); 2];
    s.script(vec![]);
    m.sync_read(132, 4, &[1, 2], &mut out, &mut res).unwrap();
    assert_eq!(
        s.written()[0],
        vec![
            0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x09, 0x00, 0x82, 0x84, 0x00, 0x04, 0x00, 0x01, 0x02,
            0xCE, 0xFA
        ]
    );
    assert_eq!(
        m.sync_read(132, 4, &[1], &mut out, &mut res),
        Err(Error::InvalidArgument)
    );
    assert_eq!(
        m.sync_read(132, 4, &[], &mut out, &mut res[..0]),
        Err(Error::InvalidArgument)
    );
    assert_eq!(
        m.sync_read(132, 4, &[1, 0xFE], &mut out, &mut res),
        Err(Error::InvalidArgument)
    );
    assert_eq!(
        m.sync_read(132, 8, &[1, 2], &mut out, &mut res),
        Err(Error::BufferTooSmall)
    );
    assert_eq!(
        m.fast_sync_read(132, 8, &[1, 2], &mut out, &mut res),
        Err(Error::BufferTooSmall)
    );
    assert_eq!(
        m.bulk_read(&[], &mut out, &mut res[..0]),
        Err(Error::InvalidArgument)
    );
    let req = [BulkReadRequest {
        id: 1,
        addr: 0,
        len: 9,
    }];
    assert_eq!(
        m.bulk_read(&req, &mut out, &mut res[..1]),
        Err(Error::BufferTooSmall)
    );
    // The driver's own transmit buffer is bounded too.
    let s2 = Shared::default();
    let mut small: Master<_, _, _, 16> = Master::new(
        MockTransport(s2.clone()),
        MockPin(s2.clone()),
        MockClock(s2.clone()),
    );
    assert_eq!(small.write(1, 0, &[0; 8]), Err(Error::BufferTooSmall));
    assert!(s2.written().is_empty());
}

#[test]
fn bulk_read_of_the_robot_sensors() {
    let (mut m, s) = setup();
    let left = FootForces {
        forces_mn: [5000, 5100, 4900, 5000],
        counter: 42,
    };
    let imu = ImuSample {
        gyro_urad_s: [1000, -2000, 3],
        accel_um_s2: [0, 100, 9_806_650],
        counter: 7,
    };
    s.script(vec![
        reply(status(ids::FOOT_LEFT, 0, &left.to_bytes())),
        // The right foot is silent.
        reply(status(ids::IMU, 0, &imu.to_bytes())),
        reply(corrupt(status(1, 0, &pos_bytes(2048)), 12)),
    ]);
    let reqs = [
        BulkReadRequest {
            id: ids::FOOT_LEFT,
            addr: 128,
            len: 18,
        },
        BulkReadRequest {
            id: ids::FOOT_RIGHT,
            addr: 128,
            len: 18,
        },
        BulkReadRequest {
            id: ids::IMU,
            addr: 128,
            len: 26,
        },
        BulkReadRequest {
            id: 1,
            addr: 132,
            len: 4,
        },
    ];
    let mut out = [0u8; 66];
    let mut res = [Ok(()); 4];
    let ok = m.bulk_read(&reqs, &mut out, &mut res).unwrap();
    assert_eq!(ok, 2);
    assert_eq!(res, [Ok(()), Err(Error::Timeout), Ok(()), Err(Error::Crc)]);
    assert_eq!(FootForces::from_bytes(&out[..18]), Some(left));
    assert_eq!(ImuSample::from_bytes(&out[36..62]), Some(imu));
    let mut want = [0u8; 64];
    let n = encode_bulk_read(&mut want, &reqs).unwrap();
    assert_eq!(s.written()[0], want[..n].to_vec());
}

fn fast_reply(parts: &[FastSyncPart<'_>]) -> Vec<u8> {
    let mut b = [0u8; 256];
    let n = encode_fast_sync_status(&mut b, 4, parts).unwrap();
    b[..n].to_vec()
}

fn part(id: u8, err: u8, data: &[u8]) -> FastSyncPart<'_> {
    FastSyncPart {
        id,
        error: StatusError::from_byte(err),
        data,
        crc_ok: true,
    }
}

#[test]
fn fast_sync_read() {
    let (a, b, c) = (pos_bytes(1), pos_bytes(-2), pos_bytes(0x00FD_FFFF));
    let run = |replies: Vec<Reply>| {
        let (mut m, s) = setup();
        s.script(replies);
        let mut out = [0u8; 12];
        let mut res = [Ok(()); 3];
        let ok = m
            .fast_sync_read(132, 4, &[1, 2, 3], &mut out, &mut res)
            .unwrap();
        let w = s.written();
        assert_eq!(w[0][7], opcode::FAST_SYNC_READ);
        (res, out, ok, m)
    };
    let all = fast_reply(&[part(1, 0, &a), part(2, 0, &b), part(3, 0, &c)]);
    let (res, out, ok, _) = run(vec![reply(all.clone())]);
    assert_eq!((res, ok), ([Ok(()); 3], 3));
    assert_eq!((&out[..4], &out[4..8], &out[8..]), (&a[..], &b[..], &c[..]));
    // One device reports an error, one is missing from the reply.
    let partial = fast_reply(&[part(1, 0x06, &a), part(3, 0x80, &c)]);
    let (res, out, ok, m) = run(vec![reply(partial)]);
    assert!(matches!(res[0], Err(Error::Status(e)) if e.code == Some(ErrorCode::DataLimit)));
    assert_eq!(
        (res[1], res[2], ok, &out[8..]),
        (Err(Error::Timeout), Ok(()), 1, &c[..])
    );
    assert_eq!(m.stats().hardware_alerts, 1);
    // A bad intermediate CRC (packet CRC recomputed so only the part is wrong).
    let mut bad = all.clone();
    // Part k starts at 8 + 8k (err, id, 4 data, 2 CRC): corrupt CRC2, the running CRC that
    // device 2 appended (device 3 computed its CRC over what it heard, i.e. the bad bytes).
    bad[22] ^= 1;
    let n = bad.len();
    let crc = dxl::crc::crc16(&bad[..n - 2]).to_le_bytes();
    bad[n - 2..].copy_from_slice(&crc);
    let (res, _, ok, _) = run(vec![reply(bad)]);
    assert_eq!((res, ok), ([Ok(()), Err(Error::Crc), Ok(())], 2));
    // Lost or corrupted reply: every device fails.
    let (res, _, ok, m) = run(vec![]);
    assert_eq!((res, ok), ([Err(Error::Timeout); 3], 0));
    assert_eq!(m.stats().timeouts, 3);
    let (res, _, _, _) = run(vec![reply(corrupt(all.clone(), 20))]);
    assert_eq!(res, [Err(Error::Crc); 3]);
    // A reply for another length is malformed.
    let mut b8 = [0u8; 64];
    let n = encode_fast_sync_status(&mut b8, 2, &[part(1, 0, &[1, 2])]).unwrap();
    let (res, _, _, _) = run(vec![reply(b8[..n].to_vec())]);
    assert_eq!(res, [Err(Error::Malformed); 3]);
    // Normal stuffed packets are decoded again afterwards.
    let (mut m, s) = setup();
    s.script(vec![]);
    let mut out = [0u8; 4];
    let mut res = [Ok(())];
    m.fast_sync_read(132, 4, &[1], &mut out, &mut res).unwrap();
    s.script(vec![reply(status(1, 0, &[0xFF, 0xFF, 0xFD, 0x01]))]);
    m.read(1, 132, &mut out).unwrap();
    assert_eq!(out, [0xFF, 0xFF, 0xFD, 0x01]);
}

#[test]
fn io_and_pin_failures() {
    let (mut m, s) = setup();
    s.bus().write_fails = true;
    let mut buf = [0u8; 4];
    assert_eq!(
        m.read(1, 132, &mut buf),
        Err(Error::Io(ErrorKind::BrokenPipe))
    );
    // The bus is released even though the write failed.
    assert!(!s.bus().pin_high);
    s.bus().write_fails = false;
    s.bus().pin_fails = true;
    assert_eq!(m.write(1, 65, &[1]), Err(Error::Pin));
    assert_eq!(m.stats().io_errors, 2);
    assert!(s.written().is_empty());
}

/// A UART implementing the `embedded_io` traits, to exercise [`IoTransport`].
struct Uart(Shared);

impl embedded_io::ErrorType for Uart {
    type Error = Infallible;
}

impl embedded_io::Read for Uart {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        // Blocking read: only called when `read_ready` said so.
        let mut t = MockTransport(self.0.clone());
        let b = t.read_byte().unwrap().expect("read called while not ready");
        buf[0] = b;
        Ok(1)
    }
}

impl embedded_io::ReadReady for Uart {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        let b = self.0.bus();
        Ok(matches!(b.rx.front(), Some(&(t, _)) if t <= b.now))
    }
}

impl embedded_io::Write for Uart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        // Accept at most 3 bytes per call to exercise `write_all`.
        let n = buf.len().min(3);
        MockTransport(self.0.clone()).write_all(&buf[..n]).unwrap();
        Ok(n)
    }
    fn flush(&mut self) -> Result<(), Infallible> {
        MockTransport(self.0.clone()).flush().unwrap();
        Ok(())
    }
}

#[test]
fn embedded_io_adaptor() {
    let s = Shared::default();
    let mut m: Master<_, _, _> = Master::new(
        IoTransport(Uart(s.clone())),
        MockPin(s.clone()),
        MockClock(s.clone()),
    );
    s.script(vec![reply(status(ids::IMU, 0, &[0x20, 0x5A, 1]))]);
    let info = m.ping(ids::IMU).unwrap();
    assert_eq!(info.model, dxl::table::imu::MODEL_NUMBER_VALUE);
    s.script(vec![]);
    assert_eq!(m.ping(ids::IMU), Err(Error::Timeout));
    assert_eq!(s.written().len(), 2);
    let (_t, _p, _c) = m.release();
}
