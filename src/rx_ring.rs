//! A receive ring that a DMA stream fills in circular mode and the control loop reads once a
//! tick: the stream's remaining-transfer count (NDTR on the STM32) says where the DMA writes
//! next, the reader keeps where it stopped. No interrupt and no lock: the DMA is the only
//! writer of the ring, the reader the only owner of its cursor.
//!
//! The reader must come back before the DMA has written a whole ring of new bytes (a 1 KiB
//! ring at 1 Mbps: 10 ms); bytes overwritten before that are lost without notice, and the
//! command port's packets (CRC-16 checked) then fail and are asked again by the master.
//!
//! [`LineRx`] is the same port in time, for a board whose UART hands the firmware bytes as fast
//! as it asks (QEMU's character devices hold the sender back instead of losing bytes): bytes
//! arrive no faster than the line carries them, 10 bits each at the baud rate, into a ring of
//! `N` bytes, and a byte that finds the ring full is lost and counted. With it a reader too slow
//! for the line shows up as lost bytes, as on the real board.

/// The reader's side of a circular DMA receive ring of `N` bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DmaRxCursor<const N: usize> {
    /// Where the next unread byte is, 0..N.
    read: usize,
}

impl<const N: usize> DmaRxCursor<N> {
    /// A cursor at the ring's start (where a freshly started stream writes first).
    pub const fn new() -> Self {
        DmaRxCursor { read: 0 }
    }

    /// Copies the bytes the DMA wrote since the last call into `out` and returns how many:
    /// `remaining` is the stream's remaining-transfer count (N − the write position; in
    /// circular mode 0 is read as N), `ring(i)` reads byte i of the ring. Bytes beyond `out`'s
    /// length stay for the next call; a count above N (a stream not set up) gives nothing.
    pub fn take(&mut self, remaining: usize, ring: impl Fn(usize) -> u8, out: &mut [u8]) -> usize {
        if N == 0 || remaining > N {
            return 0;
        }
        let write = (N - remaining) % N;
        let mut n = 0;
        for slot in out.iter_mut() {
            if self.read == write {
                break;
            }
            *slot = ring(self.read);
            self.read = (self.read + 1) % N;
            n += 1;
        }
        n
    }
}

use crate::board::LineTime;

/// A UART receiver in time (module docs): the line delivers at most `baud / 10` bytes per
/// second into a ring of `N` bytes that the firmware reads; arrivals beyond a full ring are
/// lost and counted.
#[derive(Debug)]
pub struct LineRx<const N: usize> {
    ring: heapless::Deque<u8, N>,
    line: LineTime,
    /// Since when the line has been busy without a break (the last time the sender had
    /// nothing), µs.
    busy_since_us: u64,
    /// Bytes carried since `busy_since_us`.
    carried: u64,
    lost: u32,
}

impl<const N: usize> LineRx<N> {
    /// Most bytes taken from the sender in one [`LineRx::arrive`] (bounded work: 41 ms of a
    /// 1 Mbps line).
    pub const MAX_ARRIVALS: u64 = 4096;

    /// An idle line at `baud` bit/s with an empty ring.
    pub const fn new(baud: u32) -> Self {
        LineRx {
            ring: heapless::Deque::new(),
            line: LineTime { baud },
            busy_since_us: 0,
            carried: 0,
            lost: 0,
        }
    }

    /// Delivers into the ring what the line can have carried by `now_us`: `next()` gives the
    /// sender's next byte (`None`: it has nothing now, the line goes idle). Bytes that find
    /// the ring full are lost ([`LineRx::lost`]). At most [`LineRx::MAX_ARRIVALS`] bytes per
    /// call; the rest stay with the sender.
    pub fn arrive(&mut self, now_us: u64, mut next: impl FnMut() -> Option<u8>) {
        let line_bytes = self
            .line
            .bytes_in_us(now_us.saturating_sub(self.busy_since_us));
        let credit = line_bytes
            .saturating_sub(self.carried)
            .min(Self::MAX_ARRIVALS);
        for _ in 0..credit {
            let Some(b) = next() else {
                self.busy_since_us = now_us;
                self.carried = 0;
                return;
            };
            self.carried += 1;
            if self.ring.push_back(b).is_err() {
                self.lost = self.lost.saturating_add(1);
            }
        }
    }

    /// Moves the bytes waiting in the ring into `out` (at most its length); how many.
    pub fn read(&mut self, out: &mut [u8]) -> usize {
        let mut n = 0;
        for slot in out.iter_mut() {
            let Some(b) = self.ring.pop_front() else {
                break;
            };
            *slot = b;
            n += 1;
        }
        n
    }

    /// Bytes lost to a full ring since the start (saturating).
    pub fn lost(&self) -> u32 {
        self.lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A DMA stream writing into a ring of N bytes: the bytes written and the remaining count.
    struct Dma<const N: usize> {
        ring: [u8; N],
        pos: usize,
    }

    impl<const N: usize> Dma<N> {
        fn receive(&mut self, bytes: &[u8]) {
            for &b in bytes {
                self.ring[self.pos] = b;
                self.pos = (self.pos + 1) % N;
            }
        }
        fn remaining(&self) -> usize {
            N - self.pos
        }
    }

    #[test]
    fn bytes_come_out_in_order_across_the_wrap_and_a_short_buffer_leaves_the_rest() {
        let mut dma = Dma::<8> {
            ring: [0; 8],
            pos: 0,
        };
        let mut c = DmaRxCursor::<8>::new();
        let mut out = [0u8; 16];
        assert_eq!(c.take(dma.remaining(), |i| dma.ring[i], &mut out), 0);
        dma.receive(&[1, 2, 3, 4, 5, 6]);
        assert_eq!(c.take(dma.remaining(), |i| dma.ring[i], &mut out), 6);
        assert_eq!(out[..6], [1, 2, 3, 4, 5, 6]);
        dma.receive(&[7, 8, 9, 10, 11]);
        let mut short = [0u8; 3];
        assert_eq!(c.take(dma.remaining(), |i| dma.ring[i], &mut short), 3);
        assert_eq!(short, [7, 8, 9]);
        assert_eq!(c.take(dma.remaining(), |i| dma.ring[i], &mut out), 2);
        assert_eq!(out[..2], [10, 11]);
        // A count the stream never shows (above N) gives nothing and moves nothing.
        assert_eq!(c.take(9, |i| dma.ring[i], &mut out), 0);
        assert_eq!(c.take(dma.remaining(), |i| dma.ring[i], &mut out), 0);
    }

    /// A sender with bytes queued at given times (µs), like a host writing packets into the
    /// QEMU character device.
    struct Sender {
        queued: std::collections::VecDeque<(u64, u8)>,
        now: u64,
    }

    impl Sender {
        fn next(&mut self) -> Option<u8> {
            match self.queued.front() {
                Some(&(t, b)) if t <= self.now => {
                    self.queued.pop_front();
                    Some(b)
                }
                _ => None,
            }
        }
    }

    /// `count` packets of `len` bytes (packet k: bytes k, k+1, …) sent every `every_us` µs,
    /// the first at `every_us / 2`.
    fn packets(count: u64, len: u64, every_us: u64) -> Sender {
        let mut queued = std::collections::VecDeque::new();
        for k in 0..count {
            for i in 0..len {
                queued.push_back((k * every_us + every_us / 2, (k + i) as u8));
            }
        }
        Sender { queued, now: 0 }
    }

    /// Polls the line every `period_us` until `end_us`, reading at most `per_poll` bytes each
    /// time; what was read.
    fn poll<const N: usize>(
        line: &mut LineRx<N>,
        s: &mut Sender,
        period_us: u64,
        end_us: u64,
        per_poll: usize,
    ) -> Vec<u8> {
        let mut got = Vec::new();
        let mut t = 0;
        while t <= end_us {
            s.now = t;
            line.arrive(t, || s.next());
            let mut out = vec![0u8; per_poll];
            let n = line.read(&mut out);
            got.extend_from_slice(&out[..n]);
            t += period_us;
        }
        got
    }

    #[test]
    fn the_line_delivers_ten_bits_per_byte_at_its_baud_rate() {
        // 5000 bytes queued at t = 0 on a 1 Mbps line: 100 bytes per ms.
        let mut s = packets(1, 5000, 0);
        let mut line = LineRx::<8192>::new(1_000_000);
        let mut out = vec![0u8; 8192];
        for (t, total) in [(1_000, 100), (2_500, 250), (10_000, 1000), (20_000, 2000)] {
            s.now = t;
            line.arrive(t, || s.next());
            assert_eq!(line.ring.len(), total, "at {t} µs");
        }
        assert_eq!(line.read(&mut out), 2000);
        // Idle (nothing queued), then a new packet at 30 ms: carried from when it came, not
        // from the idle time's credit.
        s.now = 25_000;
        s.queued.clear();
        line.arrive(25_000, || s.next());
        s.queued.extend((0..300).map(|i| (30_000, i as u8)));
        s.now = 30_000;
        line.arrive(30_000, || None); // the poll just before the bytes come: idle
        s.now = 31_000;
        line.arrive(31_000, || s.next());
        assert_eq!(line.read(&mut out), 100);
        assert_eq!(line.lost(), 0);
    }

    #[test]
    fn the_firmware_reader_keeps_up_with_100_commands_at_100_hz_and_a_one_byte_reader_does_not() {
        // 100 packets of 14 bytes (a Dynamixel WRITE of two bytes) every 10 ms at 1 Mbps; the
        // loop polls every 10 ms (dt) and reads up to 64 bytes, out of a 1 KiB ring.
        let mut s = packets(100, 14, 10_000);
        let sent: Vec<u8> = s.queued.iter().map(|&(_, b)| b).collect();
        let mut line = LineRx::<1024>::new(1_000_000);
        let got = poll(&mut line, &mut s, 10_000, 1_100_000, 64);
        assert_eq!(got, sent);
        assert_eq!(line.lost(), 0);
        // A reader of one byte per tick from a one-byte receive register (what a polled
        // UART data register gives): 13 of every 14 bytes are lost.
        let mut s = packets(100, 14, 10_000);
        let mut line = LineRx::<1>::new(1_000_000);
        let got = poll(&mut line, &mut s, 10_000, 1_100_000, 1);
        assert_eq!(got.len(), 100);
        assert_eq!(line.lost(), 1300);
        // A ring that holds the bytes but a reader slower than the sender: the backlog grows
        // until the ring is full, then bytes are lost.
        let mut s = packets(100, 14, 10_000);
        let mut line = LineRx::<256>::new(1_000_000);
        let got = poll(&mut line, &mut s, 10_000, 1_100_000, 8);
        assert_eq!(got.len(), 110 * 8);
        assert!(line.lost() > 0);
        assert_eq!(
            got.len() as u32 + line.lost() + line.ring.len() as u32,
            1400
        );
    }

    proptest! {
        /// Whatever the chunking of the arrivals and of the reads, a reader that keeps up
        /// (fewer than N bytes between its reads) gets every byte once, in order.
        #[test]
        fn a_reader_that_keeps_up_gets_every_byte_once(
            arrivals in proptest::collection::vec((0usize..16, 1usize..20), 1..60)
        ) {
            let mut dma = Dma::<16> { ring: [0; 16], pos: 0 };
            let mut c = DmaRxCursor::<16>::new();
            let (mut sent, mut got) = (Vec::new(), Vec::new());
            let mut next = 0u8;
            for (count, read_len) in arrivals {
                let bytes: Vec<u8> = (0..count).map(|_| { next = next.wrapping_add(1); next }).collect();
                dma.receive(&bytes);
                sent.extend_from_slice(&bytes);
                // Drain in reads of `read_len` until nothing is left.
                loop {
                    let mut out = vec![0u8; read_len];
                    let n = c.take(dma.remaining(), |i| dma.ring[i], &mut out);
                    got.extend_from_slice(&out[..n]);
                    if n < read_len {
                        break;
                    }
                }
            }
            prop_assert_eq!(got, sent);
        }

        /// Whatever the packets, the poll period and the reads: every byte sent is read once
        /// in order, lost, still in the ring or still with the sender; never more than the
        /// line can carry by each poll.
        #[test]
        fn the_line_conserves_bytes_and_never_beats_its_baud_rate(
            count in 1u64..40, len in 1u64..40, every_us in 0u64..5_000,
            period_us in 1u64..20_000, per_poll in 1usize..80,
        ) {
            let mut s = packets(count, len, every_us);
            let sent: Vec<u8> = s.queued.iter().map(|&(_, b)| b).collect();
            let mut line = LineRx::<64>::new(1_000_000);
            let mut got = Vec::new();
            let mut t = 0;
            let mut arrived = 0u64;
            while t <= count * every_us + 200_000 {
                s.now = t;
                let before = s.queued.len();
                line.arrive(t, || s.next());
                arrived += (before - s.queued.len()) as u64;
                // The line carries 100 bytes per ms: by t, at most 1 + t/10 bytes.
                prop_assert!(arrived <= t / 10 + 1, "{arrived} bytes by {t} µs");
                let mut out = vec![0u8; per_poll];
                let n = line.read(&mut out);
                got.extend_from_slice(&out[..n]);
                t += period_us;
            }
            let total = got.len() + line.lost() as usize + line.ring.len() + s.queued.len();
            prop_assert_eq!(total, sent.len());
            if line.lost() == 0 {
                prop_assert_eq!(&got[..], &sent[..got.len()]);
            }
        }
    }
}
