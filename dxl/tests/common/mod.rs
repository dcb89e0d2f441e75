//! Helpers shared by the integration tests.

/// Independent bitwise CRC-16/BUYPASS (poly 0x8005, init 0), to cross-check the table CRC.
pub fn bitwise_crc(data: &[u8]) -> u16 {
    let mut crc = 0u16;
    for &b in data {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x8005
            } else {
                crc << 1
            };
        }
    }
    crc
}
