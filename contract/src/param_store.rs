//! The saved parameters: the run-time parameters as `key=value` tokens (the command line's
//! form, [`crate::params`]) in two copies ("slots") of a board's non-volatile store, so that a
//! power cut while one is written leaves the other whole.
//!
//! # A slot ([`SLOT_LEN`] bytes)
//! | offset | size | content |
//! |---:|---:|---|
//! | 0 | 4 | magic `WPRM` |
//! | 4 | 2 | format, [`FORMAT`] (u16 LE) |
//! | 6 | 2 | text length n (u16 LE) |
//! | 8 | 4 | sequence number (u32 LE): one more than the slot written before |
//! | 12 | n | the tokens, ASCII, one space between them: every parameter with a value but the fault injections ([`crate::params::TEST_ONLY`]) |
//! | 12 + n | 2 | CRC-16 (Dynamixel 2.0's, [`dxl::crc::crc16`]) of bytes 0 .. 12 + n |
//!
//! A save writes the slot that does not hold the newest copy, with the next sequence number; a
//! load takes the newest slot that decodes and whose tokens the parameter parser accepts
//! (applied to a copy: all or nothing), else the other, else the defaults. Erased flash (all
//! `0xFF`) or a store never written (all `0x00`, or shorter than a header) is
//! [`SlotError::Empty`]; anything else that does not decode is corrupt.
//!
//! Written by hand (no crate keeps two CRC-checked copies in a `no_std`, allocation-free
//! form with the firmware's own parser); bounded: one slot buffer of the caller's.

use crate::config::Config;
use crate::params::{apply, PARAMS, TEST_ONLY};

/// Bytes of one slot (the text is at most `SLOT_LEN` − 14).
pub const SLOT_LEN: usize = 4096;
/// The slot format this firmware writes and reads.
pub const FORMAT: u16 = 1;
const MAGIC: [u8; 4] = *b"WPRM";
const HEADER: usize = 12;
const CRC_LEN: usize = 2;

/// Why a slot did not decode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotError {
    /// Never written (erased or empty).
    Empty,
    /// Not a slot (no magic).
    Magic,
    /// Another format.
    Format,
    /// A text length beyond the slot.
    Length,
    /// The CRC does not match (a torn or damaged write).
    Crc,
}

/// A slot that decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Saved<'a> {
    /// Its sequence number.
    pub seq: u32,
    /// Its tokens.
    pub text: &'a [u8],
}

/// Decodes one slot (see the module docs).
pub fn decode(slot: &[u8]) -> Result<Saved<'_>, SlotError> {
    let Some(head) = slot.get(..HEADER) else {
        return Err(SlotError::Empty);
    };
    if slot.iter().all(|&b| b == 0xFF) || slot.iter().all(|&b| b == 0) {
        return Err(SlotError::Empty);
    }
    let [m0, m1, m2, m3, f0, f1, n0, n1, s0, s1, s2, s3] = *head else {
        return Err(SlotError::Empty);
    };
    if [m0, m1, m2, m3] != MAGIC {
        return Err(SlotError::Magic);
    }
    if u16::from_le_bytes([f0, f1]) != FORMAT {
        return Err(SlotError::Format);
    }
    let n = usize::from(u16::from_le_bytes([n0, n1]));
    let end = HEADER + n;
    let (Some(body), Some(&[c0, c1])) = (slot.get(..end), slot.get(end..end + CRC_LEN)) else {
        return Err(SlotError::Length);
    };
    if end + CRC_LEN > SLOT_LEN || dxl::crc::crc16(body) != u16::from_le_bytes([c0, c1]) {
        return Err(SlotError::Crc);
    }
    Ok(Saved {
        seq: u32::from_le_bytes([s0, s1, s2, s3]),
        text: body.get(HEADER..).unwrap_or(&[]),
    })
}

/// A byte writer into a slice (the tokens' text).
struct Cursor<'a> {
    buf: &'a mut [u8],
    at: usize,
}

impl core::fmt::Write for Cursor<'_> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let end = self.at + s.len();
        let dst = self.buf.get_mut(self.at..end).ok_or(core::fmt::Error)?;
        dst.copy_from_slice(s.as_bytes());
        self.at = end;
        Ok(())
    }
}

/// Writes `cfg`'s parameters as slot `seq` into `out` (at least [`SLOT_LEN`] bytes; the rest
/// of the slot is filled with `0xFF`, erased flash); the bytes to program, `None` if the
/// text does not fit.
pub fn encode(cfg: &Config, seq: u32, out: &mut [u8]) -> Option<usize> {
    use core::fmt::Write as _;
    let slot = out.get_mut(..SLOT_LEN)?;
    slot.fill(0xFF);
    let (head, rest) = slot.split_at_mut(HEADER);
    let text_max = rest.len().checked_sub(CRC_LEN)?;
    let mut w = Cursor {
        buf: rest.get_mut(..text_max)?,
        at: 0,
    };
    for p in PARAMS.iter().filter(|p| !TEST_ONLY.contains(&p.key)) {
        let Some(v) = p.value(cfg) else {
            continue;
        };
        if w.at > 0 {
            w.write_str(" ").ok()?;
        }
        w.write_str(p.key).ok()?;
        w.write_str("=").ok()?;
        p.write_value(v, &mut w).ok()?;
    }
    let n = w.at;
    let len = u16::try_from(n).ok()?;
    head.copy_from_slice(&[0; HEADER]);
    head.get_mut(..4)?.copy_from_slice(&MAGIC);
    head.get_mut(4..6)?.copy_from_slice(&FORMAT.to_le_bytes());
    head.get_mut(6..8)?.copy_from_slice(&len.to_le_bytes());
    head.get_mut(8..12)?.copy_from_slice(&seq.to_le_bytes());
    let end = HEADER + n;
    let crc = dxl::crc::crc16(slot.get(..end)?);
    slot.get_mut(end..end + CRC_LEN)?
        .copy_from_slice(&crc.to_le_bytes());
    Some(end + CRC_LEN)
}

/// What a load found (logged as the `ParamStore` fault record: `id` = [`StoreOutcome::code`],
/// `value` = [`StoreOutcome::value`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub enum StoreOutcome {
    /// 0: the parameters of slot `slot`, sequence `seq`, are in force.
    Loaded {
        /// The slot.
        slot: u8,
        /// Its sequence number.
        seq: u32,
    },
    /// 1: nothing saved: the defaults.
    Empty,
    /// 2: no slot decodes (damaged or torn): the defaults.
    Corrupt,
    /// 3: a slot decodes but the parser refuses its tokens (another firmware's keys or
    /// ranges): the defaults.
    Rejected,
    /// 4: the board has no parameter store: the defaults.
    NoStore,
}

impl StoreOutcome {
    /// The wire code (the record's `id`).
    pub const fn code(self) -> u8 {
        match self {
            StoreOutcome::Loaded { .. } => 0,
            StoreOutcome::Empty => 1,
            StoreOutcome::Corrupt => 2,
            StoreOutcome::Rejected => 3,
            StoreOutcome::NoStore => 4,
        }
    }

    /// The record's `value`: the loaded slot · 2²⁴ + its sequence number (low 24 bits); 0
    /// otherwise.
    pub fn value(self) -> i32 {
        match self {
            StoreOutcome::Loaded { slot, seq } => {
                (i32::from(slot) << 24) | (seq & 0x00FF_FFFF) as i32
            }
            _ => 0,
        }
    }
}

/// The newest slot of two decoded ones (`None`: neither decodes).
pub fn newest(slots: &[Result<Saved<'_>, SlotError>; 2]) -> Option<usize> {
    match slots {
        [Ok(a), Ok(b)] => Some(if b.seq > a.seq { 1 } else { 0 }),
        [Ok(_), Err(_)] => Some(0),
        [Err(_), Ok(_)] => Some(1),
        [Err(_), Err(_)] => None,
    }
}

/// Where the next save goes and its sequence number: the slot that does not hold the newest
/// copy, one more than the newest's (slot 0, sequence 1 when nothing decodes).
pub fn next_save(slots: [&[u8]; 2]) -> (usize, u32) {
    let d = [decode(slots[0]), decode(slots[1])];
    match newest(&d) {
        Some(i) => {
            let seq = d.get(i).and_then(|r| r.as_ref().ok()).map_or(0, |s| s.seq);
            (1 - i, seq.wrapping_add(1))
        }
        None => (0, 1),
    }
}

/// Loads the newest slot whose tokens the parser accepts into `cfg` (all or nothing; see the
/// module docs); `cfg` keeps its values otherwise.
pub fn load(cfg: &mut Config, slots: [&[u8]; 2]) -> StoreOutcome {
    let d = [decode(slots[0]), decode(slots[1])];
    let Some(first) = newest(&d) else {
        return if d.iter().all(|r| *r == Err(SlotError::Empty)) {
            StoreOutcome::Empty
        } else {
            StoreOutcome::Corrupt
        };
    };
    for i in [first, 1 - first] {
        let Some(Ok(saved)) = d.get(i) else {
            continue;
        };
        let mut c = *cfg;
        if apply(&mut c, saved.text).is_ok() {
            *cfg = c;
            return StoreOutcome::Loaded {
                slot: i as u8,
                seq: saved.seq,
            };
        }
    }
    StoreOutcome::Rejected
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn saved(cfg: &Config, seq: u32) -> Vec<u8> {
        let mut b = vec![0u8; SLOT_LEN];
        let n = encode(cfg, seq, &mut b).unwrap();
        assert!(n < SLOT_LEN / 2, "{n} bytes: the slot has room to grow");
        b
    }

    fn tuned() -> Config {
        let mut c = Config::default();
        apply(&mut c, b"elf catch_gain=0.5 gyro_ankle=0.04 wait_enable=1").unwrap();
        c
    }

    #[test]
    fn a_saved_configuration_loads_back_equal_and_the_newest_wins() {
        let old = saved(&Config::default(), 1);
        let new = saved(&tuned(), 2);
        let mut c = Config::default();
        assert_eq!(
            load(&mut c, [&old, &new]),
            StoreOutcome::Loaded { slot: 1, seq: 2 }
        );
        assert_eq!(format!("{c:?}"), format!("{:?}", tuned()));
        let mut c = Config::default();
        assert_eq!(
            load(&mut c, [&new, &old]),
            StoreOutcome::Loaded { slot: 0, seq: 2 }
        );
        assert_eq!(next_save([&old, &new]), (0, 3));
        assert_eq!(next_save([&new, &old]), (1, 3));
    }

    #[test]
    fn fault_injections_are_never_saved() {
        let mut c = tuned();
        apply(
            &mut c,
            b"elf stop_at=5 cut_save=100 fault_nan=3 fault_nan_com=4",
        )
        .unwrap();
        let slot = saved(&c, 1);
        let text = core::str::from_utf8(decode(&slot).unwrap().text).unwrap();
        for k in TEST_ONLY {
            assert!(!text.contains(&format!("{k}=")), "{k} saved: {text}");
            assert!(crate::params::find(k).is_some(), "{k} is a parameter");
        }
        let mut back = Config::default();
        assert!(matches!(
            load(&mut back, [&slot, &[]]),
            StoreOutcome::Loaded { .. }
        ));
        assert_eq!(format!("{back:?}"), format!("{:?}", tuned()));
    }

    #[test]
    fn empty_and_corrupt_stores_leave_the_defaults_and_say_so() {
        let erased = vec![0xFFu8; SLOT_LEN];
        let mut c = tuned();
        assert_eq!(load(&mut c, [&erased, &[]]), StoreOutcome::Empty);
        assert_eq!(format!("{c:?}"), format!("{:?}", tuned()));
        assert_eq!(next_save([&erased, &[]]), (0, 1));
        let mut bad = saved(&tuned(), 5);
        bad[40] ^= 0x01;
        assert_eq!(decode(&bad), Err(SlotError::Crc));
        let mut c = Config::default();
        assert_eq!(load(&mut c, [&bad, &erased]), StoreOutcome::Corrupt);
        assert_eq!(format!("{c:?}"), format!("{:?}", Config::default()));
        let mut other = saved(&tuned(), 5);
        other[4] = 9;
        assert_eq!(decode(&other), Err(SlotError::Format));
        assert_eq!(decode(b"not a slot at all"), Err(SlotError::Magic));
        // A slot that decodes but whose tokens the parser refuses: the other one, else none.
        let mut text = Vec::new();
        text.extend_from_slice(&MAGIC);
        text.extend_from_slice(&FORMAT.to_le_bytes());
        let body = b"no_such_key=1";
        text.extend_from_slice(&(body.len() as u16).to_le_bytes());
        text.extend_from_slice(&9u32.to_le_bytes());
        text.extend_from_slice(body);
        let crc = dxl::crc::crc16(&text);
        text.extend_from_slice(&crc.to_le_bytes());
        let mut c = Config::default();
        assert_eq!(load(&mut c, [&text, &erased]), StoreOutcome::Rejected);
        let good = saved(&tuned(), 3);
        assert_eq!(
            load(&mut c, [&text, &good]),
            StoreOutcome::Loaded { slot: 1, seq: 3 }
        );
    }

    proptest! {
        /// A power cut anywhere in a save (the new slot's first `cut` bytes programmed over
        /// erased or old flash) loses nothing: the previous copy loads.
        #[test]
        fn a_save_cut_anywhere_leaves_the_previous_copy(cut in 0usize..SLOT_LEN, erased_first: bool) {
            let a = saved(&tuned(), 7);
            let before = saved(&Config::default(), 6);
            let new = {
                let mut c = tuned();
                apply(&mut c, b"elf catch_gain=0.25").unwrap();
                saved(&c, 8)
            };
            let mut torn = if erased_first { vec![0xFFu8; SLOT_LEN] } else { before.clone() };
            torn[..cut].copy_from_slice(&new[..cut]);
            let mut c = Config::default();
            let out = load(&mut c, [&a, &torn]);
            if decode(&torn).map(|s| s.seq) == Ok(8) {
                // Cut after the CRC: the new copy is whole.
                prop_assert_eq!(out, StoreOutcome::Loaded { slot: 1, seq: 8 });
            } else {
                prop_assert_eq!(out, StoreOutcome::Loaded { slot: 0, seq: 7 });
                prop_assert_eq!(format!("{c:?}"), format!("{:?}", tuned()));
            }
        }
    }
}
