//! CRC-16 of Dynamixel Protocol 2.0.
//!
//! The checksum is CRC-16/BUYPASS (a.k.a. CRC-16/UMTS): polynomial `0x8005`, initial value
//! `0`, no reflection, no final XOR. It covers every byte of a packet from the first header
//! byte through the last (stuffed) parameter and is sent little-endian after it.
//! The 256-entry lookup tables are computed at compile time by `const fn`s.
//!
//! Byte-wise step (`T1` = [`TABLE`], the register after byte `x` from zero):
//! `c ← (c << 8) ^ T1[(c >> 8) ^ b]`. Four bytes at once (slicing by 4): the CRC is linear
//! over XOR, so with `Tk[x]` = the register after byte `x` and `k − 1` zero bytes,
//! `T(k+1)[x] = ((Tk[x] << 8) & 0xFFFF) ^ T1[Tk[x] >> 8]` ([`TABLE2`], [`TABLE3`], [`TABLE4`]),
//! feeding `b0 b1 b2 b3` gives
//! `c ← T4[(c >> 8) ^ b0] ^ T3[(c & 0xFF) ^ b1] ^ T2[b2] ^ T1[b3]`:
//! four independent lookups instead of four dependent steps (2 KiB of tables in flash).

/// CRC-16 polynomial used by Protocol 2.0.
pub const POLY: u16 = 0x8005;

/// `T1`: byte-wise lookup table, built at compile time.
pub const TABLE: [u16; 256] = msb_first_table(POLY);
/// `T2`: a byte followed by one zero byte (slicing by 4), built at compile time.
pub const TABLE2: [u16; 256] = shifted(&TABLE);
/// `T3`: a byte followed by two zero bytes.
pub const TABLE3: [u16; 256] = shifted(&TABLE2);
/// `T4`: a byte followed by three zero bytes.
pub const TABLE4: [u16; 256] = shifted(&TABLE3);

/// The byte-wise lookup table of any non-reflected CRC-16 with polynomial `poly`: entry `x`
/// is the register after shifting the byte `x` (in bits 15..8) through eight rounds (also the
/// log's CRC-16/CCITT-FALSE in `walker-contract`).
// Evaluated only at compile time: an out-of-range index here would be a build error.
#[allow(clippy::indexing_slicing)]
pub const fn msb_first_table(poly: u16) -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ poly
            } else {
                crc << 1
            };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
}

/// `T(k+1)` from `Tk`: one more zero byte fed after each entry's byte.
// Evaluated only at compile time: every index is below 256.
#[allow(clippy::indexing_slicing)]
const fn shifted(tk: &[u16; 256]) -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let t = tk[i];
        table[i] = (t << 8) ^ TABLE[(t >> 8) as usize];
        i += 1;
    }
    table
}

/// Entry `i` of a 256-entry table (a u8 index is never out of range).
#[inline(always)]
#[allow(clippy::indexing_slicing)]
const fn at(table: &[u16; 256], i: u8) -> u16 {
    table[i as usize]
}

/// Feeds four bytes into a running CRC (one slicing-by-4 step, see the module docs).
#[inline(always)]
const fn update4(crc: u16, b: [u8; 4]) -> u16 {
    let [hi, lo] = crc.to_be_bytes();
    at(&TABLE4, hi ^ b[0]) ^ at(&TABLE3, lo ^ b[1]) ^ at(&TABLE2, b[2]) ^ at(&TABLE, b[3])
}

/// Feeds one byte into a running CRC.
#[inline(always)]
pub const fn update_byte(crc: u16, byte: u8) -> u16 {
    (crc << 8) ^ at(&TABLE, ((crc >> 8) as u8) ^ byte)
}

/// Feeds a slice into a running CRC (four bytes per step, the rest byte by byte).
pub const fn update(crc: u16, data: &[u8]) -> u16 {
    let mut crc = crc;
    let mut rest = data;
    while let [b0, b1, b2, b3, tail @ ..] = rest {
        crc = update4(crc, [*b0, *b1, *b2, *b3]);
        rest = tail;
    }
    while let [b, tail @ ..] = rest {
        crc = update_byte(crc, *b);
        rest = tail;
    }
    crc
}

/// CRC-16 of `data` (initial value 0); `const`, so that fixed packets (the firmware's
/// broadcast torque-off) are built at compile time with the same tables.
pub const fn crc16(data: &[u8]) -> u16 {
    update(0, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bitwise(data: &[u8]) -> u16 {
        bitwise_from(0, data)
    }

    fn bitwise_from(init: u16, data: &[u8]) -> u16 {
        let mut crc = init;
        for &b in data {
            crc ^= u16::from(b) << 8;
            for _ in 0..8 {
                crc = if crc & 0x8000 != 0 {
                    (crc << 1) ^ POLY
                } else {
                    crc << 1
                };
            }
        }
        crc
    }

    #[test]
    fn check_value() {
        // CRC-16/BUYPASS check value of "123456789".
        assert_eq!(crc16(b"123456789"), 0xFEE8);
        assert_eq!(bitwise(b"123456789"), 0xFEE8);
    }

    #[test]
    fn ping_vector() {
        let crc = crc16(&[0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x01]);
        assert_eq!(crc.to_le_bytes(), [0x19, 0x4E]);
    }

    #[test]
    fn two_byte_steps_match_bitwise_at_every_length_and_start() {
        let data: [u8; 40] = core::array::from_fn(|k| (k as u8).wrapping_mul(73) ^ 0xA5);
        for start in 0..4 {
            for end in start..data.len() {
                let (a, b) = data[start..end].split_at((end - start) / 3);
                assert_eq!(
                    update(update(0x1D0F, a), b),
                    bitwise_from(0x1D0F, &data[start..end])
                );
            }
        }
        for x in 0..=255u8 {
            for y in [0u8, 1, 0x7F, 0xFD, 0xFF, x] {
                assert_eq!(update(0xBEEF, &[x, y]), bitwise_from(0xBEEF, &[x, y]));
            }
        }
    }

    #[test]
    fn table_matches_bitwise() {
        for i in 0..=255u8 {
            assert_eq!(
                crc16(&[i, 0x5A, i.wrapping_mul(7)]),
                bitwise(&[i, 0x5A, i.wrapping_mul(7)])
            );
        }
    }
}
