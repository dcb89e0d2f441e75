//! Byte-exact packets, byte stuffing and decoder behaviour.

use dxl::instruction::{BulkRead, SyncWrite};
use dxl::*;

mod common;
use common::bitwise_crc;

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|h| u8::from_str_radix(h, 16).unwrap())
        .collect()
}

/// Checks that `bytes` is what `encode` produced and that its CRC is right.
fn check(encoded: Result<usize, EncodeError>, buf: &[u8], expected: &str) {
    let n = encoded.unwrap();
    let want = hex(expected);
    assert_eq!(&buf[..n], &want[..], "expected {expected}");
    let crc = bitwise_crc(&want[..n - 2]).to_le_bytes();
    assert_eq!(&want[n - 2..], &crc, "CRC of the vector itself");
}

fn decode_one(bytes: &[u8]) -> (u8, u8, Vec<u8>) {
    let mut out = [0u8; 512];
    let p = decode(bytes, &mut out).unwrap();
    (p.id, p.instruction, p.params.to_vec())
}

// The vectors below are the ROBOTIS e-manual Protocol 2.0 examples (PING, READ, WRITE,
// REBOOT, SYNC READ, SYNC WRITE and the status replies); the BULK/FAST/REG-WRITE vectors are
// our own, with their CRC verified by `bitwise_crc`.

#[test]
fn ping() {
    let mut b = [0u8; 64];
    check(
        Instruction::Ping.encode(&mut b, 1),
        &b,
        "FF FF FD 00 01 03 00 01 19 4E",
    );
    let r = encode_status(&mut b, 1, StatusError::OK, &[0x06, 0x04, 0x26]);
    check(r, &b, "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D");
}

#[test]
fn read() {
    let mut b = [0u8; 64];
    let r = Instruction::Read { addr: 132, len: 4 }.encode(&mut b, 1);
    check(r, &b, "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15");
    let r = encode_status(&mut b, 1, StatusError::OK, &[0xA6, 0, 0, 0]);
    check(r, &b, "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0");
}

#[test]
fn write() {
    let mut b = [0u8; 64];
    let r = Instruction::Write {
        addr: 116,
        data: &512i32.to_le_bytes(),
    }
    .encode(&mut b, 1);
    check(r, &b, "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89");
    let r = encode_status(&mut b, 1, StatusError::OK, &[]);
    check(r, &b, "FF FF FD 00 01 04 00 55 00 A1 0C");
}

#[test]
fn reboot_action_reg_write() {
    let mut b = [0u8; 64];
    check(
        Instruction::Reboot.encode(&mut b, 1),
        &b,
        "FF FF FD 00 01 03 00 08 2F 4E",
    );
    let n = Instruction::Action.encode(&mut b, 0xFE).unwrap();
    assert_eq!(&b[..8], &hex("FF FF FD 00 FE 03 00 05")[..]);
    assert_eq!(bitwise_crc(&b[..8]).to_le_bytes(), [b[8], b[9]]);
    assert_eq!(n, 10);
    let n = Instruction::RegWrite {
        addr: 104,
        data: &[0xC8, 0, 0, 0],
    }
    .encode(&mut b, 1)
    .unwrap();
    assert_eq!(
        &b[..n - 2],
        &hex("FF FF FD 00 01 09 00 04 68 00 C8 00 00 00")[..]
    );
    assert_eq!(bitwise_crc(&b[..n - 2]).to_le_bytes(), [b[n - 2], b[n - 1]]);
}

#[test]
fn sync_read_and_write() {
    let mut b = [0u8; 64];
    let r = Instruction::SyncRead {
        addr: 132,
        len: 4,
        ids: &[1, 2],
    }
    .encode(&mut b, 0xFE);
    check(r, &b, "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA");
    let d1 = 150i32.to_le_bytes();
    let d2 = 170i32.to_le_bytes();
    let r = encode_sync_write(&mut b, 116, 4, &[(1, &d1), (2, &d2)]);
    check(
        r,
        &b,
        "FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87",
    );
    assert_eq!(
        encode_sync_write(&mut b, 116, 4, &[(1, &[1, 2, 3])]),
        Err(EncodeError::InvalidArgument)
    );
    let r = Instruction::FastSyncRead {
        addr: 132,
        len: 4,
        ids: &[1, 2],
    }
    .encode(&mut b, 0xFE);
    let n = r.unwrap();
    assert_eq!(
        &b[..n - 2],
        &hex("FF FF FD 00 FE 09 00 8A 84 00 04 00 01 02")[..]
    );
    assert_eq!(bitwise_crc(&b[..n - 2]).to_le_bytes(), [b[n - 2], b[n - 1]]);
}

#[test]
fn bulk_read_and_write() {
    let mut b = [0u8; 64];
    let reqs = [
        BulkReadRequest {
            id: 1,
            addr: 132,
            len: 4,
        },
        BulkReadRequest {
            id: 2,
            addr: 132,
            len: 4,
        },
    ];
    check(
        encode_bulk_read(&mut b, &reqs),
        &b,
        "FF FF FD 00 FE 0D 00 92 01 84 00 04 00 02 84 00 04 00 FC 5A",
    );
    let entries = [
        BulkWriteEntry {
            id: 1,
            addr: 116,
            data: &[0, 2, 0, 0],
        },
        BulkWriteEntry {
            id: 111,
            addr: 9,
            data: &[0],
        },
    ];
    let n = encode_bulk_write(&mut b, &entries).unwrap();
    let want = hex("FF FF FD 00 FE 12 00 93 01 74 00 04 00 00 02 00 00 6F 09 00 01 00 00");
    assert_eq!(&b[..n - 2], &want[..]);
    assert_eq!(bitwise_crc(&want).to_le_bytes(), [b[n - 2], b[n - 1]]);
}

#[test]
fn every_instruction_parses_back() {
    let sw = [1u8, 10, 20, 2, 30, 40];
    let br = [1u8, 132, 0, 4, 0, 111, 128, 0, 18, 0];
    let bw = [1u8, 116, 0, 2, 0, 5, 6, 200, 9, 0, 0, 0];
    let all = [
        Instruction::Ping,
        Instruction::Read { addr: 132, len: 4 },
        Instruction::Write {
            addr: 116,
            data: &[1, 2, 3, 4],
        },
        Instruction::RegWrite {
            addr: 116,
            data: &[],
        },
        Instruction::Action,
        Instruction::Reboot,
        Instruction::SyncRead {
            addr: 132,
            len: 4,
            ids: &[1, 2, 3],
        },
        Instruction::FastSyncRead {
            addr: 132,
            len: 4,
            ids: &[7],
        },
        Instruction::SyncWrite(SyncWrite::from_raw(116, 2, &sw).unwrap()),
        Instruction::BulkRead(BulkRead::from_raw(&br).unwrap()),
        Instruction::BulkWrite(dxl::BulkWrite::from_raw(&bw).unwrap()),
    ];
    let mut b = [0u8; 128];
    let mut out = [0u8; 128];
    for inst in all {
        let n = inst.encode(&mut b, 5).unwrap();
        let p = decode(&b[..n], &mut out).unwrap();
        assert_eq!(p.id, 5);
        assert_eq!(Instruction::parse(&p).unwrap(), inst);
    }
    // Iterators over the group payloads.
    let Instruction::SyncWrite(s) = all[8] else {
        panic!()
    };
    assert_eq!(
        s.entries().collect::<Vec<_>>(),
        vec![(1, &[10u8, 20][..]), (2, &[30, 40][..])]
    );
    assert_eq!(s.data_for(2), Some(&[30u8, 40][..]));
    assert_eq!(s.data_for(3), None);
    let Instruction::BulkRead(r) = all[9] else {
        panic!()
    };
    assert_eq!(
        r.entries().collect::<Vec<_>>(),
        vec![
            BulkReadRequest {
                id: 1,
                addr: 132,
                len: 4
            },
            BulkReadRequest {
                id: 111,
                addr: 128,
                len: 18
            }
        ]
    );
    let Instruction::BulkWrite(w) = all[10] else {
        panic!()
    };
    let e: Vec<_> = w.entries().collect();
    assert_eq!(e.len(), 2);
    assert_eq!(
        e[1],
        BulkWriteEntry {
            id: 200,
            addr: 9,
            data: &[]
        }
    );
}

#[test]
fn parse_rejects_bad_layouts() {
    let p = |instruction, params: &'static [u8]| Packet {
        id: 1,
        instruction,
        params,
    };
    assert_eq!(
        Instruction::parse(&p(0x01, &[0])),
        Err(ParseError::BadLength)
    );
    assert_eq!(
        Instruction::parse(&p(0x02, &[0, 0, 4])),
        Err(ParseError::BadLength)
    );
    assert_eq!(
        Instruction::parse(&p(0x03, &[0])),
        Err(ParseError::BadLength)
    );
    assert_eq!(
        Instruction::parse(&p(0x82, &[0, 0, 4])),
        Err(ParseError::BadLength)
    );
    assert_eq!(
        Instruction::parse(&p(0x83, &[0, 0, 2, 0, 1, 2])),
        Err(ParseError::BadLength)
    );
    assert_eq!(
        Instruction::parse(&p(0x92, &[1, 2, 3, 4])),
        Err(ParseError::BadLength)
    );
    assert_eq!(
        Instruction::parse(&p(0x93, &[1, 0, 0, 5, 0, 1])),
        Err(ParseError::BadLength)
    );
    assert_eq!(
        Instruction::parse(&p(0x77, &[])),
        Err(ParseError::UnknownInstruction(0x77))
    );
    assert_eq!(
        Status::from_packet(&p(0x55, &[])),
        Err(ParseError::BadLength)
    );
    assert_eq!(
        Status::from_packet(&p(0x02, &[0])),
        Err(ParseError::NotStatus)
    );
    let st = Status::from_packet(&p(0x55, &[0x87, 9])).unwrap();
    assert!(st.error.alert);
    assert_eq!(st.error.code, Some(ErrorCode::Access));
    assert_eq!(st.data, &[9]);
}

#[test]
fn stuffing_cases() {
    let mut b = [0u8; 64];
    // In the middle.
    let n = encode(&mut b, 1, 0x03, &[0x10, 0xFF, 0xFF, 0xFD, 0x20]).unwrap();
    assert_eq!(
        &b[..n - 2],
        &hex("FF FF FD 00 01 09 00 03 10 FF FF FD FD 20")[..]
    );
    // LEN counts the stuffed byte; CRC covers the stuffed stream.
    assert_eq!(bitwise_crc(&b[..n - 2]).to_le_bytes(), [b[n - 2], b[n - 1]]);
    assert_eq!(decode_one(&b[..n]).2, vec![0x10, 0xFF, 0xFF, 0xFD, 0x20]);
    // At the end of the parameters.
    let n = encode(&mut b, 1, 0x03, &[0xFF, 0xFF, 0xFD]).unwrap();
    assert_eq!(&b[7..n - 2], &hex("03 FF FF FD FD")[..]);
    assert_eq!(decode_one(&b[..n]).2, vec![0xFF, 0xFF, 0xFD]);
    // Repeated, back to back.
    let params = hex("FF FF FD FF FF FD FF FF FD");
    let n = encode(&mut b, 1, 0x03, &params).unwrap();
    assert_eq!(
        &b[7..n - 2],
        &hex("03 FF FF FD FD FF FF FD FD FF FF FD FD")[..]
    );
    assert_eq!(decode_one(&b[..n]).2, params);
    // FD FD already in the data stays intact, and a lone FF FF FD followed by FD.
    let params = hex("FF FF FD FD FD 00 FF FD");
    let n = encode(&mut b, 1, 0x03, &params).unwrap();
    assert_eq!(&b[7..n - 2], &hex("03 FF FF FD FD FD FD 00 FF FD")[..]);
    assert_eq!(decode_one(&b[..n]).2, params);
    // A header pattern in the data cannot leak onto the wire.
    let params = hex("FF FF FD 00 01 02");
    let n = encode(&mut b, 1, 0x03, &params).unwrap();
    assert!(!b[7..n].windows(4).any(|w| w == HEADER));
    assert_eq!(decode_one(&b[..n]).2, params);
    // Status packets are stuffed too (error byte + data).
    let n = encode_status(&mut b, 3, StatusError::OK, &[0xFF, 0xFD]).unwrap();
    assert_eq!(&b[7..n - 2], &hex("55 00 FF FD")[..]);
    let n = encode_status(&mut b, 3, StatusError::OK, &[0xFF, 0xFF, 0xFD]).unwrap();
    assert_eq!(&b[7..n - 2], &hex("55 00 FF FF FD FD")[..]);
}

#[test]
fn decoder_resynchronises() {
    let mut b = [0u8; 32];
    let n = Instruction::Ping.encode(&mut b, 7).unwrap();
    let mut stream = hex("00 13 FF FF 55 FF FF FD FF FD 00");
    stream.extend_from_slice(&b[..n]);
    let mut dec = Decoder::<32>::new();
    let mut got = Vec::new();
    for &x in &stream {
        if let Some(r) = dec.push(x) {
            got.push(r.map(|p| (p.id, p.instruction)));
        }
    }
    assert_eq!(got, vec![Ok((7, 1))]);
    assert_eq!(dec.stats().packets, 1);
    assert!(dec.stats().skipped_bytes >= 11);
}

#[test]
fn decoder_errors() {
    let mut b = [0u8; 32];
    let n = Instruction::Read { addr: 132, len: 4 }
        .encode(&mut b, 1)
        .unwrap();
    let mut dec = Decoder::<16>::new();
    // Bad CRC.
    let mut bad = b[..n].to_vec();
    bad[n - 1] ^= 1;
    assert_eq!(dec.feed(&bad).1, Some(Err(DecodeError::Crc { id: 1 })));
    assert_eq!(dec.stats().crc_errors, 1);
    // A good packet right after.
    assert!(matches!(dec.feed(&b[..n]).1, Some(Ok(p)) if p.id == 1 && p.instruction == 2));
    // LEN too small / too large / bad ID.
    assert_eq!(
        dec.feed(&hex("FF FF FD 00 01 02 00")).1,
        Some(Err(DecodeError::LenTooSmall))
    );
    assert_eq!(
        dec.feed(&hex("FF FF FD 00 01 14 00")).1,
        Some(Err(DecodeError::LenTooLarge))
    );
    assert_eq!(
        dec.feed(&hex("FF FF FD 00 FF")).1,
        Some(Err(DecodeError::BadId))
    );
    assert_eq!(dec.stats().framing_errors, 3);
    // A header that interrupts a packet body restarts decoding from that header.
    let mut s = hex("FF FF FD 00 01 0C 00 02 01");
    s.extend_from_slice(&b[..n]);
    let (used, ev) = dec.feed(&s);
    assert_eq!(ev, Some(Err(DecodeError::Interrupted)));
    assert!(matches!(dec.feed(&s[used..]).1, Some(Ok(p)) if p.id == 1));
    // One-shot decode of truncated input.
    let mut out = [0u8; 8];
    assert_eq!(decode(&b[..n - 1], &mut out), Err(DecodeError::Incomplete));
    assert_eq!(decode(&[], &mut out), Err(DecodeError::Incomplete));
    // A packet whose LEN exceeds the one-shot buffer.
    assert_eq!(
        decode(&b[..n], &mut [0u8; 3]),
        Err(DecodeError::LenTooLarge)
    );
    // `packet()` is only available right after completion.
    assert!(dec.packet().is_none() || dec.is_idle());
}

#[test]
fn decoder_reset_and_idle() {
    let mut dec = Decoder::<8>::new();
    assert!(dec.is_idle());
    dec.feed(&hex("FF FF FD 00 01"));
    assert!(!dec.is_idle());
    dec.reset();
    assert!(dec.is_idle());
    let mut b = [0u8; 16];
    let n = Instruction::Ping.encode(&mut b, 2).unwrap();
    assert!(matches!(dec.feed(&b[..n]), (10, Some(Ok(_)))));
    assert_eq!(dec.packet().map(|p| p.id), Some(2));
}

#[test]
fn encoder_limits() {
    let mut b = [0u8; 12];
    assert_eq!(
        encode(&mut b, 1, 3, &[1, 2, 3]),
        Err(EncodeError::BufferTooSmall)
    );
    assert_eq!(encode(&mut b, 1, 3, &[1, 2]), Ok(12));
    // Stuffing needs room for the extra byte.
    assert_eq!(encode(&mut b, 1, 3, &[0xFF, 0xFD]), Ok(12));
    assert_eq!(
        encode(&mut b, 1, 0xFF, &[0xFF, 0xFD]),
        Err(EncodeError::BufferTooSmall)
    );
    assert_eq!(encode(&mut [], 1, 1, &[]), Err(EncodeError::BufferTooSmall));
}
