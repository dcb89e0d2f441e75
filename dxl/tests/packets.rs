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

/// Checks the packet `encode` produced against our own vector `body` (everything before the
/// CRC) and its CRC against `bitwise_crc`.
fn check_body(encoded: Result<usize, EncodeError>, buf: &[u8], body: &str) {
    let n = encoded.unwrap();
    let want = hex(body);
    assert_eq!(&buf[..n - 2], &want[..], "expected {body}");
    assert_eq!(
        bitwise_crc(&want).to_le_bytes(),
        buf[n - 2..n],
        "CRC of {body}"
    );
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
fn instruction_vectors() {
    let goal = 512i32.to_le_bytes();
    let emanual = [
        (Instruction::Ping, 1, "FF FF FD 00 01 03 00 01 19 4E"),
        (
            Instruction::Read { addr: 132, len: 4 },
            1,
            "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15",
        ),
        (
            Instruction::Write {
                addr: 116,
                data: &goal,
            },
            1,
            "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89",
        ),
        (Instruction::Reboot, 1, "FF FF FD 00 01 03 00 08 2F 4E"),
        (
            Instruction::SyncRead {
                addr: 132,
                len: 4,
                ids: &[1, 2],
            },
            0xFE,
            "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA",
        ),
    ];
    let mut b = [0u8; 64];
    for (instruction, id, expected) in emanual {
        check(instruction.encode(&mut b, id), &b, expected);
    }
    // Our own vectors (without their CRC, checked by `bitwise_crc`).
    let own = [
        (Instruction::Action, 0xFE, "FF FF FD 00 FE 03 00 05"),
        (
            Instruction::RegWrite {
                addr: 104,
                data: &[0xC8, 0, 0, 0],
            },
            1,
            "FF FF FD 00 01 09 00 04 68 00 C8 00 00 00",
        ),
        (
            Instruction::FastSyncRead {
                addr: 132,
                len: 4,
                ids: &[1, 2],
            },
            0xFE,
            "FF FF FD 00 FE 09 00 8A 84 00 04 00 01 02",
        ),
    ];
    for (instruction, id, body) in own {
        check_body(instruction.encode(&mut b, id), &b, body);
    }
}

#[test]
fn status_vectors() {
    let mut b = [0u8; 64];
    for (data, expected) in [
        (
            &[0x06, 0x04, 0x26][..],
            "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D",
        ),
        (
            &[0xA6, 0, 0, 0],
            "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0",
        ),
        (&[], "FF FF FD 00 01 04 00 55 00 A1 0C"),
    ] {
        check(
            encode_status(&mut b, 1, StatusError::OK, data),
            &b,
            expected,
        );
    }
}

#[test]
fn sync_write() {
    let mut b = [0u8; 64];
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
    let r = encode_bulk_write(&mut b, &entries);
    check_body(
        r,
        &b,
        "FF FF FD 00 FE 12 00 93 01 74 00 04 00 00 02 00 00 6F 09 00 01 00 00",
    );
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
    let bad_lengths: [(u8, &'static [u8]); 7] = [
        (0x01, &[0]),
        (0x02, &[0, 0, 4]),
        (0x03, &[0]),
        (0x82, &[0, 0, 4]),
        (0x83, &[0, 0, 2, 0, 1, 2]),
        (0x92, &[1, 2, 3, 4]),
        (0x93, &[1, 0, 0, 5, 0, 1]),
    ];
    for (instruction, params) in bad_lengths {
        let r = Instruction::parse(&p(instruction, params));
        assert_eq!(
            r,
            Err(ParseError::BadLength),
            "instruction {instruction:#04X}"
        );
    }
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

/// Checks that the WRITE parameters `params` go on the wire as `wire` (instruction byte and
/// stuffed parameters) and decode back.
fn check_stuffing(params: &str, wire: &str) {
    let mut b = [0u8; 64];
    let params = hex(params);
    let n = encode(&mut b, 1, 0x03, &params).unwrap();
    assert_eq!(&b[7..n - 2], &hex(wire)[..], "{wire}");
    assert_eq!(decode_one(&b[..n]).2, params);
}

#[test]
fn stuffing_cases() {
    let mut b = [0u8; 64];
    // In the middle; LEN counts the stuffed byte, CRC covers the stuffed stream.
    let r = encode(&mut b, 1, 0x03, &[0x10, 0xFF, 0xFF, 0xFD, 0x20]);
    check_body(r, &b, "FF FF FD 00 01 09 00 03 10 FF FF FD FD 20");
    check_stuffing("10 FF FF FD 20", "03 10 FF FF FD FD 20");
    // At the end of the parameters.
    check_stuffing("FF FF FD", "03 FF FF FD FD");
    // Repeated, back to back.
    check_stuffing(
        "FF FF FD FF FF FD FF FF FD",
        "03 FF FF FD FD FF FF FD FD FF FF FD FD",
    );
    // FD FD already in the data stays intact, and a lone FF FF FD followed by FD.
    check_stuffing("FF FF FD FD FD 00 FF FD", "03 FF FF FD FD FD FD 00 FF FD");
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
    for (bytes, error) in [
        ("FF FF FD 00 01 02 00", DecodeError::LenTooSmall),
        ("FF FF FD 00 01 14 00", DecodeError::LenTooLarge),
        ("FF FF FD 00 FF", DecodeError::BadId),
    ] {
        assert_eq!(dec.feed(&hex(bytes)).1, Some(Err(error)), "{bytes}");
    }
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

/// A decoder event: index of the byte that caused it; ID, instruction, parameters or error.
type Event = (usize, Result<(u8, u8, Vec<u8>), DecodeError>);

/// Feeds `stream` byte by byte: every event.
fn events<const N: usize>(dec: &mut Decoder<N>, stream: &[u8]) -> Vec<Event> {
    let mut got = Vec::new();
    for (i, &b) in stream.iter().enumerate() {
        if let Some(r) = dec.push(b) {
            got.push((i, r.map(|p| (p.id, p.instruction, p.params.to_vec()))));
        }
    }
    got
}

#[test]
fn decoder_finds_header_ending_in_crc_of_broken_packet() {
    // ID 1's packet is 5 bytes short, so ID 2's header ends on its first CRC byte
    // and ID 2's ID is its second CRC byte.
    let stream = hex("FF FF FD 00 01 06 00 55 FF FF FD 00 02 04 00 55 00 29 0C");
    let mut dec = Decoder::<32>::new();
    let got = events(&mut dec, &stream);
    let (last, rest) = got.split_last().unwrap();
    assert!(
        rest.iter()
            .all(|(i, e)| *i == 12 && *e == Err(DecodeError::Crc { id: 1 })),
        "{got:?}"
    );
    assert_eq!(*last, (18, Ok((2, opcode::STATUS, vec![0x00]))), "{got:?}");
    let p = Packet {
        id: 2,
        instruction: opcode::STATUS,
        params: &[0x00],
    };
    let st = Status::from_packet(&p).unwrap();
    assert_eq!((st.id, st.error, st.data), (2, StatusError::OK, &[][..]));
    assert_eq!(dec.stats().packets, 1);
    assert!(dec.is_idle());
    // The same packet alone, and through the one-shot decoder.
    assert_eq!(decode_one(&stream[8..]), (2, opcode::STATUS, vec![0x00]));
}

#[test]
fn decoder_keeps_packet_after_truncated_one() {
    let mut b = [0u8; 64];
    let mut p = [0u8; 64];
    for stuffing in [true, false] {
        let encode = |buf: &mut [u8], id, inst, params: &[u8]| {
            let mut w = PacketWriter::with_stuffing(buf, id, inst, stuffing)?;
            w.extend(params)?;
            w.finish()
        };
        // A packet with stuffing bytes, so that the cut can fall anywhere in its body.
        let n = encode(&mut b, 1, 0x03, &hex("10 FF FF FD 20 FF FD 00 30 31 32")).unwrap();
        let status = hex("00 FF FF FD 07");
        let pn = encode(&mut p, 2, opcode::STATUS, &status).unwrap();
        // Unstuffed, a header inside a body is data: only a packet that starts in the last
        // six bytes of the broken frame can be recovered (see the `packet` module docs).
        let cuts = if stuffing { 1..=n } else { 1..=6 };
        for k in cuts {
            let mut stream = b[..n - k].to_vec();
            stream.extend_from_slice(&p[..pn]);
            let mut dec = Decoder::<64>::new();
            dec.set_stuffing(stuffing);
            let got = events(&mut dec, &stream);
            let packets: Vec<_> = got
                .iter()
                .filter_map(|(i, e)| e.as_ref().ok().map(|p| (*i, p.clone())))
                .collect();
            let want = (stream.len() - 1, (2, opcode::STATUS, status.clone()));
            assert_eq!(packets, vec![want], "stuffing {stuffing}, cut {k}: {got:?}");
        }
    }
}

#[test]
fn decoder_refuses_len_ff00_and_more() {
    // A header can start inside such a LEN (here LEN_H), and the ping must not vanish into
    // the body, although the buffer could hold LEN = 0xFF05.
    let mut stream = hex("FF FF FD 00 01 05");
    let mut b = [0u8; 16];
    let n = Instruction::Ping.encode(&mut b, 9).unwrap();
    stream.extend_from_slice(&b[..n]);
    let mut dec = Decoder::<0xFF10>::new();
    let got = events(&mut dec, &stream);
    assert_eq!(
        got,
        vec![
            (6, Err(DecodeError::LenTooLarge)),
            (stream.len() - 1, Ok((9, opcode::PING, vec![])))
        ]
    );
    assert_eq!(
        decode(&hex("FF FF FD 00 01 00 FF"), &mut [0u8; 0xFF10]),
        Err(DecodeError::LenTooLarge)
    );
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
