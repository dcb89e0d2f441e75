//! The lock-step protocol between the QEMU board's firmware and the simulator
//! (`docs/lockstep.md`): the frame markers and headers both ends write and read.
//!
//! Two transports carry it:
//! * **UARTs** (`scripts/qemu-run.sh --lockstep SPEC`, the simulator's TCP endpoints): the bus
//!   bytes on UART0, the time frames and reply announcements on UART2;
//! * **a pair of named pipes** (`walker fil`): the word `lockstep=PREFIX` on the firmware's
//!   command line ([`PIPE_WORD`]); the firmware writes its frames to `PREFIX` +
//!   [`TO_SIM_SUFFIX`] and reads the simulator's from `PREFIX` + [`TO_FIRMWARE_SUFFIX`], whole
//!   frames through semihosting SYS_WRITE and SYS_READ. The bus packets travel in the pipe too
//!   ([`packet_header`]), so that a packet or a reply costs QEMU one host call rather than a
//!   wake-up of its vCPU per byte (the CMSDK UART holds one received byte).
//!
//! Frames, firmware → simulator: [`time_frame`] (`0x5A` + u64 LE µs of virtual time); on the
//! pipes also [`packet_header`] (`0x50` + u16 LE length) followed by one instruction packet.
//! Simulator → firmware: [`reply_header`] (`0xA5` + u16 LE count of reply bytes for the last
//! instruction packet, 0 when none), after the reply bytes on UART0 or before them on the pipe.
//!
//! The board's IMU (the OpenCR's SPI chip, simulated; pipes only): firmware → simulator
//! [`spi_header`] (`0x53` + u16 LE length) followed by the bytes the board clocks out (MOSI)
//! in one chip-select-low transfer; simulator → firmware [`reply_header`] of the same count
//! followed by the bytes the chip clocked back (MISO), one for each byte out.

/// First byte of a time frame (firmware → simulator).
pub const TIME: u8 = 0x5A;
/// First byte of a reply announcement (simulator → firmware).
pub const REPLY: u8 = 0xA5;
/// First byte of a bus packet frame on the pipe transport (firmware → simulator).
pub const PACKET: u8 = 0x50;
/// First byte of a board IMU's SPI transfer frame on the pipe transport (firmware →
/// simulator).
pub const SPI: u8 = 0x53;
/// Longest SPI transfer a frame carries, bytes (the IMU's burst is 15).
pub const SPI_MAX: usize = 32;
/// The board's word `lockstep=PREFIX`: lock-step over the named pipes at `PREFIX` (the bare
/// word `lockstep`: over the UARTs). The parameter parser skips both.
pub const PIPE_WORD: &str = "lockstep";
/// Suffix of the pipe the firmware writes (time and packet frames).
pub const TO_SIM_SUFFIX: &str = "-to-sim";
/// Suffix of the pipe the firmware reads (reply announcements and replies).
pub const TO_FIRMWARE_SUFFIX: &str = "-to-fw";

// A frame's kind is its first byte: the four markers differ.
const _: () = assert!(
    TIME != REPLY
        && TIME != PACKET
        && REPLY != PACKET
        && SPI != TIME
        && SPI != REPLY
        && SPI != PACKET
);

/// Longest `PREFIX` of the pipes' paths, bytes (the firmware ignores a longer one).
pub const PREFIX_MAX: usize = 200;

/// Bytes of a time frame.
pub const TIME_FRAME_LEN: usize = 9;
/// Bytes of a packet or reply header.
pub const HEADER_LEN: usize = 3;

/// The time frame of virtual time `t_us`.
pub fn time_frame(t_us: u64) -> [u8; TIME_FRAME_LEN] {
    let t = t_us.to_le_bytes();
    [TIME, t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7]]
}

/// The header of a bus packet of `len` bytes on the pipe transport.
pub fn packet_header(len: u16) -> [u8; HEADER_LEN] {
    let [lo, hi] = len.to_le_bytes();
    [PACKET, lo, hi]
}

/// The header of an SPI transfer of `len` bytes on the pipe transport.
pub fn spi_header(len: u16) -> [u8; HEADER_LEN] {
    let [lo, hi] = len.to_le_bytes();
    [SPI, lo, hi]
}

/// The announcement of `n` reply bytes (a count over `u16::MAX` is announced as `u16::MAX`).
pub fn reply_header(n: usize) -> [u8; HEADER_LEN] {
    let [lo, hi] = u16::try_from(n).unwrap_or(u16::MAX).to_le_bytes();
    [REPLY, lo, hi]
}

/// The count of a header's two length bytes.
pub fn header_count(lo: u8, hi: u8) -> usize {
    usize::from(u16::from_le_bytes([lo, hi]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_have_their_marker_and_little_endian_fields() {
        assert_eq!(
            time_frame(0x0102_0304_0506_0708),
            [0x5A, 8, 7, 6, 5, 4, 3, 2, 1]
        );
        assert_eq!(packet_header(0x1234), [0x50, 0x34, 0x12]);
        assert_eq!(spi_header(15), [0x53, 15, 0]);
        assert_eq!(reply_header(180), [0xA5, 180, 0]);
        assert_eq!(reply_header(70_000), [0xA5, 0xFF, 0xFF]);
        assert_eq!(header_count(0x34, 0x12), 0x1234);
    }
}
