//! `dxl`: a `no_std`, allocation-free Dynamixel Protocol 2.0 stack for the walking robot.
//!
//! * [`crc`] – the protocol's CRC-16 (compile-time table).
//! * [`packet`] – packet framing, byte stuffing, streaming [`Decoder`].
//! * [`instruction`] – instruction builders/parsers and status packets (both bus ends).
//! * [`table`] – control tables of the X-series servos and of our foot and IMU boards.
//! * [`master`] – the hardware-independent bus master driver.
//!
//! No function panics on any input: all indexing is checked and errors are typed.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![cfg_attr(
    not(test),
    deny(
        clippy::indexing_slicing,
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic
    )
)]

#[cfg(test)]
extern crate std;

pub mod crc;
pub mod instruction;
pub mod master;
pub mod packet;
pub mod table;

pub use instruction::{
    encode_bulk_read, encode_bulk_write, encode_fast_sync_status, encode_status, encode_sync_write,
    opcode, BulkRead, BulkReadRequest, BulkWrite, BulkWriteEntry, ErrorCode, FastSyncPart,
    FastSyncParts, Instruction, ParseError, Status, StatusError, SyncWrite,
};
pub use master::{BusStats, Clock, DeviceResult, Error, IoTransport, Master, PingInfo, Transport};
pub use packet::{
    decode, encode, DecodeError, Decoder, DecoderStats, EncodeError, Packet, PacketWriter,
    BROADCAST_ID, HEADER,
};
