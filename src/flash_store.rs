//! The parameter store's two slots ([`walker_contract::param_store`]) on a NOR flash region seen
//! through `embedded-storage`'s [`NorFlash`] (the trait flash drivers implement): slot i is the
//! i-th erase block of the region, so that erasing one slot never touches the other (a save cut
//! by a power loss leaves the other copy whole), and every write is read back before it counts.
//!
//! The board supplies the region ([`crate::board::Board::store_read`] /
//! [`crate::board::Board::store_write`]); the OpenCR's is two 256 KiB sectors of its own flash
//! (`boards::opencr`).

use embedded_storage::nor_flash::NorFlash;
use walker_contract::param_store::SLOT_LEN;

/// Bytes compared per read-back and the largest write unit the store pads a tail to.
const CHUNK: usize = 64;

/// Two parameter slots on a NOR flash region.
pub struct FlashStore<F> {
    flash: F,
}

impl<F: NorFlash> FlashStore<F> {
    /// The store on `flash`; `None` when the region holds fewer than two erase blocks, a block
    /// is smaller than a slot, or the flash reads or writes in units that do not divide
    /// [`CHUNK`] bytes.
    pub fn new(flash: F) -> Option<Self> {
        let unit_ok = |u: usize| u > 0 && CHUNK.is_multiple_of(u);
        let fits = F::ERASE_SIZE >= SLOT_LEN
            && flash.capacity() / F::ERASE_SIZE.max(1) >= 2
            && unit_ok(F::WRITE_SIZE)
            && unit_ok(F::READ_SIZE);
        fits.then_some(FlashStore { flash })
    }

    /// The flash offset of slot `slot` (0 or 1).
    fn offset(slot: usize) -> Option<u32> {
        if slot < 2 {
            u32::try_from(slot * F::ERASE_SIZE).ok()
        } else {
            None
        }
    }

    /// Reads slot `slot` into `buf` (at most [`SLOT_LEN`] bytes, a multiple of the flash's read
    /// unit); false on a bad slot or length or a read error.
    pub fn read(&mut self, slot: usize, buf: &mut [u8]) -> bool {
        let Some(off) = Self::offset(slot) else {
            return false;
        };
        buf.len() <= SLOT_LEN
            && buf.len().is_multiple_of(F::READ_SIZE)
            && self.flash.read(off, buf).is_ok()
    }

    /// Erases slot `slot`, programs `data` (at most [`SLOT_LEN`] bytes; a tail shorter than
    /// the write unit is padded with the erased value `0xFF`) and reads it back; true when the
    /// slot holds `data`.
    pub fn write(&mut self, slot: usize, data: &[u8]) -> bool {
        let Some(off) = Self::offset(slot) else {
            return false;
        };
        let Some(end) = u32::try_from(F::ERASE_SIZE)
            .ok()
            .and_then(|n| off.checked_add(n))
        else {
            return false;
        };
        if data.len() > SLOT_LEN || self.flash.erase(off, end).is_err() {
            return false;
        }
        let whole = data.len() - data.len() % F::WRITE_SIZE;
        let (body, tail) = data.split_at(whole);
        if !body.is_empty() && self.flash.write(off, body).is_err() {
            return false;
        }
        if !tail.is_empty() {
            let mut pad = [0xFFu8; CHUNK];
            let Some(p) = pad.get_mut(..tail.len()) else {
                return false;
            };
            p.copy_from_slice(tail);
            let Some(unit) = pad.get(..F::WRITE_SIZE) else {
                return false;
            };
            let Some(at) = u32::try_from(whole).ok().and_then(|w| off.checked_add(w)) else {
                return false;
            };
            if self.flash.write(at, unit).is_err() {
                return false;
            }
        }
        self.verify(off, data)
    }

    /// Whether the flash at `off` reads back as `data` (chunk by chunk, whole chunks: the
    /// slot's block extends past the data).
    fn verify(&mut self, off: u32, data: &[u8]) -> bool {
        let mut back = [0u8; CHUNK];
        for (i, want) in data.chunks(CHUNK).enumerate() {
            let Some(at) = u32::try_from(i * CHUNK)
                .ok()
                .and_then(|d| off.checked_add(d))
            else {
                return false;
            };
            if self.flash.read(at, &mut back).is_err() || back.get(..want.len()) != Some(want) {
                return false;
            }
        }
        true
    }

    /// The flash back.
    pub fn into_inner(self) -> F {
        self.flash
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_storage::nor_flash::{ErrorType, NorFlashErrorKind, ReadNorFlash};
    use proptest::prelude::*;
    use walker_contract::param_store;

    /// A NOR flash as the F7's behaves: erase sets a block to `0xFF`, programming only clears
    /// bits (AND); `cut_after` bytes programmed, then every operation fails (the power is gone).
    struct Nor<const W: usize, const E: usize> {
        mem: Vec<u8>,
        programmed: usize,
        cut_after: Option<usize>,
        erases: Vec<u32>,
    }

    impl<const W: usize, const E: usize> Nor<W, E> {
        fn new(blocks: usize) -> Self {
            Nor {
                mem: vec![0xFF; blocks * E],
                programmed: 0,
                cut_after: None,
                erases: Vec::new(),
            }
        }
        fn dead(&self) -> bool {
            self.cut_after.is_some_and(|n| self.programmed >= n)
        }
    }

    impl<const W: usize, const E: usize> ErrorType for Nor<W, E> {
        type Error = NorFlashErrorKind;
    }

    impl<const W: usize, const E: usize> ReadNorFlash for Nor<W, E> {
        const READ_SIZE: usize = 1;
        fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
            let o = offset as usize;
            let src = self
                .mem
                .get(o..o + bytes.len())
                .ok_or(NorFlashErrorKind::OutOfBounds)?;
            bytes.copy_from_slice(src);
            Ok(())
        }
        fn capacity(&self) -> usize {
            self.mem.len()
        }
    }

    impl<const W: usize, const E: usize> NorFlash for Nor<W, E> {
        const WRITE_SIZE: usize = W;
        const ERASE_SIZE: usize = E;
        fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
            embedded_storage::nor_flash::check_erase(self, from, to)?;
            if self.dead() {
                return Err(NorFlashErrorKind::Other);
            }
            self.erases.push(from);
            self.mem[from as usize..to as usize].fill(0xFF);
            Ok(())
        }
        fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
            embedded_storage::nor_flash::check_write(self, offset, bytes.len())?;
            for (i, b) in bytes.iter().enumerate() {
                if self.dead() {
                    return Err(NorFlashErrorKind::Other);
                }
                self.mem[offset as usize + i] &= b;
                self.programmed += 1;
            }
            Ok(())
        }
    }

    fn saved(seq: u32, gain: &str) -> Vec<u8> {
        let mut cfg = walker_contract::Config::default();
        walker_contract::params::apply(&mut cfg, format!("catch_gain={gain}").as_bytes()).unwrap();
        let mut buf = [0xFFu8; SLOT_LEN];
        let n = param_store::encode(&cfg, seq, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn each_slot_is_its_own_erase_block_and_reads_back_what_was_written() {
        let mut s = FlashStore::new(Nor::<1, 8192>::new(2)).unwrap();
        let a = saved(1, "0.5");
        assert!(s.write(0, &a));
        let b = saved(2, "0.7");
        assert!(s.write(1, &b));
        let mut buf = [0u8; SLOT_LEN];
        assert!(s.read(0, &mut buf));
        assert_eq!(&buf[..a.len()], &a[..]);
        assert!(buf[a.len()..].iter().all(|&x| x == 0xFF));
        assert!(s.read(1, &mut buf));
        assert_eq!(&buf[..b.len()], &b[..]);
        // Rewriting slot 0 erases block 0 only.
        assert!(s.write(0, &saved(3, "0.9")));
        let nor = s.into_inner();
        assert_eq!(nor.erases, vec![0, 8192, 0]);
        assert_eq!(&nor.mem[8192..8192 + b.len()], &b[..]);
    }

    #[test]
    fn a_tail_shorter_than_the_write_unit_is_padded_with_the_erased_value() {
        let mut s = FlashStore::new(Nor::<8, 4096>::new(2)).unwrap();
        let data: Vec<u8> = (0..37u8).collect();
        assert!(s.write(1, &data));
        let nor = s.into_inner();
        assert_eq!(&nor.mem[4096..4096 + 37], &data[..]);
        assert!(nor.mem[4096 + 37..].iter().all(|&x| x == 0xFF));
    }

    #[test]
    fn regions_the_store_cannot_use_and_bad_requests_are_refused() {
        // One erase block only, blocks smaller than a slot, a write unit of 128 bytes.
        assert!(FlashStore::new(Nor::<1, 8192>::new(1)).is_none());
        assert!(FlashStore::new(Nor::<1, 2048>::new(4)).is_none());
        assert!(FlashStore::new(Nor::<128, 8192>::new(2)).is_none());
        let mut s = FlashStore::new(Nor::<1, 4096>::new(3)).unwrap();
        let mut buf = [0u8; SLOT_LEN];
        assert!(!s.read(2, &mut buf));
        assert!(!s.write(2, &[1, 2, 3]));
        assert!(!s.write(0, &[0u8; SLOT_LEN + 1]));
        let mut big = [0u8; SLOT_LEN + 1];
        assert!(!s.read(0, &mut big));
    }

    #[test]
    fn a_write_that_does_not_read_back_fails() {
        // A block programmed without its erase: the AND leaves other bits than the data.
        let mut nor = Nor::<1, 4096>::new(2);
        nor.mem[..4].copy_from_slice(&[0x0F; 4]);
        let mut s = FlashStore::new(nor).unwrap();
        assert!(s.write(0, &[0xF0; 4]), "the erase comes first");
        struct NoErase(Nor<1, 4096>);
        impl ErrorType for NoErase {
            type Error = NorFlashErrorKind;
        }
        impl ReadNorFlash for NoErase {
            const READ_SIZE: usize = 1;
            fn read(&mut self, o: u32, b: &mut [u8]) -> Result<(), Self::Error> {
                self.0.read(o, b)
            }
            fn capacity(&self) -> usize {
                self.0.capacity()
            }
        }
        impl NorFlash for NoErase {
            const WRITE_SIZE: usize = 1;
            const ERASE_SIZE: usize = 4096;
            fn erase(&mut self, _: u32, _: u32) -> Result<(), Self::Error> {
                Ok(())
            }
            fn write(&mut self, o: u32, b: &[u8]) -> Result<(), Self::Error> {
                self.0.write(o, b)
            }
        }
        let mut s = FlashStore::new(NoErase(s.into_inner())).unwrap();
        assert!(!s.write(0, &[0x0F; 4]), "0xF0 AND 0x0F reads 0x00");
    }

    proptest! {
        /// A save cut after any number of programmed bytes leaves the other slot's copy, which
        /// the store's loader then takes.
        #[test]
        fn a_save_cut_anywhere_keeps_the_previous_copy(cut in 0usize..400) {
            let mut s = FlashStore::new(Nor::<1, 4096>::new(2)).unwrap();
            let old = saved(1, "0.5");
            prop_assert!(s.write(0, &old));
            let mut nor = s.into_inner();
            nor.cut_after = Some(nor.programmed + cut);
            let mut s = FlashStore::new(nor).unwrap();
            let new = saved(2, "0.7");
            let ok = s.write(1, &new);
            prop_assert_eq!(ok, cut >= new.len());
            let (mut a, mut b) = ([0u8; SLOT_LEN], [0u8; SLOT_LEN]);
            prop_assert!(s.read(0, &mut a) && s.read(1, &mut b));
            let mut cfg = walker_contract::Config::default();
            let outcome = param_store::load(&mut cfg, [&a, &b]);
            let (slot, seq, want) = if ok { (1, 2, 0.7) } else { (0, 1, 0.5) };
            prop_assert_eq!(outcome, param_store::StoreOutcome::Loaded { slot, seq });
            let gain = cfg.step_adaptation.gain;
            prop_assert!((gain - want).abs() < 1e-6, "{}", gain);
        }
    }
}
