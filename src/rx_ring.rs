//! A receive ring that a DMA stream fills in circular mode and the control loop reads once a
//! tick: the stream's remaining-transfer count (NDTR on the STM32) says where the DMA writes
//! next, the reader keeps where it stopped. No interrupt and no lock: the DMA is the only
//! writer of the ring, the reader the only owner of its cursor.
//!
//! The reader must come back before the DMA has written a whole ring of new bytes (a 1 KiB
//! ring at 1 Mbps: 10 ms); bytes overwritten before that are lost without notice, and the
//! command port's packets (CRC-16 checked) then fail and are asked again by the master.

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
    }
}
