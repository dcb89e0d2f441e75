//! CRC-16 of Dynamixel Protocol 2.0.
//!
//! The checksum is CRC-16/BUYPASS (a.k.a. CRC-16/UMTS): polynomial `0x8005`, initial value
//! `0`, no reflection, no final XOR. It covers every byte of a packet from the first header
//! byte through the last (stuffed) parameter and is sent little-endian after it.
//! The 256-entry lookup table is computed at compile time by a `const fn`.

/// CRC-16 polynomial used by Protocol 2.0.
pub const POLY: u16 = 0x8005;

/// Byte-wise lookup table, built at compile time.
pub const TABLE: [u16; 256] = make_table();

// Evaluated only at compile time: an out-of-range index here would be a build error.
#[allow(clippy::indexing_slicing)]
const fn make_table() -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ POLY
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

/// Feeds one byte into a running CRC.
#[inline]
pub fn update_byte(crc: u16, byte: u8) -> u16 {
    let idx = usize::from(((crc >> 8) as u8) ^ byte);
    // `idx` is a u8, so the lookup never fails; `unwrap_or` keeps the code panic-free.
    (crc << 8) ^ TABLE.get(idx).copied().unwrap_or(0)
}

/// Feeds a slice into a running CRC.
pub fn update(crc: u16, data: &[u8]) -> u16 {
    data.iter().fold(crc, |c, &b| update_byte(c, b))
}

/// CRC-16 of `data` (initial value 0); `const`, so that fixed packets (the firmware's
/// broadcast torque-off) are built at compile time with the same table.
pub const fn crc16(data: &[u8]) -> u16 {
    let mut crc = 0u16;
    let mut i = 0;
    while i < data.len() {
        // `i < len` and a u8 index into a 256-entry table: neither can be out of range.
        #[allow(clippy::indexing_slicing)]
        let idx = (((crc >> 8) as u8) ^ data[i]) as usize;
        #[allow(clippy::indexing_slicing)]
        let t = TABLE[idx];
        crc = (crc << 8) ^ t;
        i += 1;
    }
    crc
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bitwise(data: &[u8]) -> u16 {
        let mut crc = 0u16;
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
    fn table_matches_bitwise() {
        for i in 0..=255u8 {
            assert_eq!(
                crc16(&[i, 0x5A, i.wrapping_mul(7)]),
                bitwise(&[i, 0x5A, i.wrapping_mul(7)])
            );
        }
    }
}
