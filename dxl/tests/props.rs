//! Property tests and the long-running fuzz loop.
//!
//! The proptest cases honour `PROPTEST_CASES` (default 256). `fuzz_streams` runs
//! `DXL_FUZZ_CASES` random/mutated streams (default 20 000); CI runs it with 1 000 000 in
//! release mode: `DXL_FUZZ_CASES=1000000 cargo test --release --target host-tuple -p dxl
//! --test props fuzz_streams`.

use dxl::instruction::SyncWrite;
use dxl::*;
use proptest::prelude::*;

const CAP: usize = 64;

mod common;
use common::bitwise_crc;

/// An accepted packet: index of its last byte, ID, instruction, parameters.
type Accepted = (usize, u8, u8, Vec<u8>);

/// Whether a CRC-valid frame for `id` ends at `end` in `stream` (independent check).
fn frame_ok(stream: &[u8], end: usize, id: u8) -> bool {
    (0..end.saturating_sub(8)).any(|s| {
        stream[s..s + 4] == HEADER
            && stream[s + 4] == id
            && s + 7 + usize::from(u16::from_le_bytes([stream[s + 5], stream[s + 6]])) == end + 1
            && bitwise_crc(&stream[s..end - 1]).to_le_bytes() == [stream[end - 1], stream[end]]
    })
}

/// Feeds `stream` byte by byte; checks that every accepted packet is a CRC-valid frame.
fn run<const N: usize>(dec: &mut Decoder<N>, stream: &[u8]) -> Vec<Accepted> {
    let mut out = Vec::new();
    for (i, &b) in stream.iter().enumerate() {
        if let Some(Ok(p)) = dec.push(b) {
            assert!(
                frame_ok(stream, i, p.id),
                "accepted a frame without a valid CRC at {i}"
            );
            assert!(p.params.len() <= N);
            out.push((i, p.id, p.instruction, p.params.to_vec()));
        }
    }
    out
}

/// Checks the decoder on `stream` = garbage + packet (`start..=end`) + garbage, where byte
/// `mutated` (if any) was altered.
fn check_case(
    dec: &mut Decoder<CAP>,
    stream: &[u8],
    start: usize,
    end: usize,
    mutated: Option<usize>,
    original: (u8, u8, &[u8]),
) {
    dec.reset();
    let got = run(dec, stream);
    let is_original =
        |a: &Accepted| a.0 == end && a.1 == original.0 && a.2 == original.1 && a.3 == original.2;
    let found = got.iter().any(is_original);
    match mutated {
        Some(m) if (start..=end).contains(&m) => {
            assert!(
                !found,
                "a corrupted packet was accepted (byte {m} of {stream:02X?})"
            );
        }
        _ => {
            // Only a (CRC-valid, already checked) frame formed by the garbage may hide it.
            let other = got.iter().any(|a| !is_original(a));
            assert!(found || other, "valid packet lost in {stream:02X?}");
        }
    }
}

fn byte() -> impl Strategy<Value = u8> {
    prop_oneof![any::<u8>(), Just(0xFF), Just(0xFD), Just(0x00)]
}

fn id() -> impl Strategy<Value = u8> {
    prop_oneof![0u8..=0xFC, Just(0xFE)]
}

proptest! {
    #[test]
    fn roundtrip_any_packet(
        id in id(),
        inst in any::<u8>(),
        params in prop::collection::vec(byte(), 0..48),
        pre in prop::collection::vec(byte(), 0..24),
        post in prop::collection::vec(byte(), 0..8),
    ) {
        let mut buf = [0u8; 2 * CAP + 16];
        let n = encode(&mut buf, id, inst, &params).unwrap();
        let mut stream = pre.clone();
        stream.extend_from_slice(&buf[..n]);
        stream.extend_from_slice(&post);
        // One-shot decode of the clean packet.
        let mut out = [0u8; 2 * CAP];
        let p = decode(&buf[..n], &mut out).unwrap();
        prop_assert_eq!((p.id, p.instruction, p.params), (id, inst, &params[..]));
        // Streaming decode after arbitrary garbage.
        let mut dec = Decoder::<CAP>::new();
        check_case(&mut dec, &stream, pre.len(), pre.len() + n - 1, None, (id, inst, &params));
    }

    #[test]
    fn mutated_packets_are_rejected(
        id in id(),
        inst in any::<u8>(),
        params in prop::collection::vec(byte(), 0..48),
        pre in prop::collection::vec(byte(), 0..8),
        pos in any::<prop::sample::Index>(),
        flip in 1u8..=255,
    ) {
        let mut buf = [0u8; 2 * CAP + 16];
        let n = encode(&mut buf, id, inst, &params).unwrap();
        let mut stream = pre.clone();
        stream.extend_from_slice(&buf[..n]);
        let m = pos.index(stream.len());
        stream[m] ^= flip;
        let mut dec = Decoder::<CAP>::new();
        check_case(&mut dec, &stream, pre.len(), pre.len() + n - 1, Some(m), (id, inst, &params));
    }

    #[test]
    fn random_streams_never_panic(stream in prop::collection::vec(byte(), 0..400)) {
        let mut dec = Decoder::<CAP>::new();
        run(&mut dec, &stream);
        let mut raw = Decoder::<CAP>::new();
        raw.set_stuffing(false);
        run(&mut raw, &stream);
        let mut out = [0u8; 16];
        let _ = decode(&stream, &mut out);
        let mut small = Decoder::<0>::new();
        run(&mut small, &stream);
    }

    #[test]
    fn instructions_roundtrip(
        id in id(),
        addr in any::<u16>(),
        len in 0u16..6,
        ids in prop::collection::vec(0u8..=0xFC, 0..8),
        data in prop::collection::vec(byte(), 0..24),
        which in 0u8..5,
    ) {
        let per = usize::from(len) + 1;
        let raw_len = data.len() / per * per;
        let sw = SyncWrite::from_raw(addr, len, &data[..raw_len]).unwrap();
        let inst = match which {
            0 => Instruction::Read { addr, len },
            1 => Instruction::Write { addr, data: &data },
            2 => Instruction::SyncRead { addr, len, ids: &ids },
            3 => Instruction::SyncWrite(sw),
            _ => Instruction::FastSyncRead { addr, len, ids: &ids },
        };
        let mut buf = [0u8; 128];
        let n = inst.encode(&mut buf, id).unwrap();
        let mut out = [0u8; 128];
        let p = decode(&buf[..n], &mut out).unwrap();
        prop_assert_eq!(p.id, id);
        prop_assert_eq!(Instruction::parse(&p).unwrap(), inst);
    }

    #[test]
    fn status_roundtrip(id in 0u8..=0xFC, err in any::<u8>(), data in prop::collection::vec(byte(), 0..40)) {
        let mut buf = [0u8; 128];
        let n = encode_status(&mut buf, id, StatusError::from_byte(err), &data).unwrap();
        let mut out = [0u8; 128];
        let p = decode(&buf[..n], &mut out).unwrap();
        let st = Status::from_packet(&p).unwrap();
        prop_assert_eq!((st.id, st.error.to_byte(), st.data), (id, err, &data[..]));
    }
}

/// Small xorshift64 generator (deterministic, fast).
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }

    /// A byte biased towards the protocol's special values.
    fn byte(&mut self) -> u8 {
        match self.next() % 8 {
            0 => 0xFF,
            1 => 0xFD,
            2 => 0x00,
            _ => self.next() as u8,
        }
    }
}

#[test]
fn fuzz_streams() {
    let cases: u64 = std::env::var("DXL_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20_000);
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    let mut dec = Decoder::<CAP>::new();
    let mut raw_dec = Decoder::<CAP>::new();
    raw_dec.set_stuffing(false);
    let mut buf = [0u8; 2 * CAP + 16];
    let mut params = Vec::with_capacity(CAP);
    let mut stream = Vec::with_capacity(4 * CAP);
    for case in 0..cases {
        stream.clear();
        if case % 10 == 0 {
            // Pure random stream: must not panic; anything accepted must be a valid frame.
            let len = rng.below(300);
            stream.extend((0..len).map(|_| rng.byte()));
            dec.reset();
            run(&mut dec, &stream);
            raw_dec.reset();
            run(&mut raw_dec, &stream);
            continue;
        }
        let id = if rng.below(16) == 0 {
            0xFE
        } else {
            rng.below(0xFD) as u8
        };
        let inst = rng.byte();
        params.clear();
        let plen = rng.below(40);
        params.extend((0..plen).map(|_| rng.byte()));
        let n = encode(&mut buf, id, inst, &params).unwrap();
        let pre = rng.below(12);
        stream.extend((0..pre).map(|_| rng.byte()));
        stream.extend_from_slice(&buf[..n]);
        let post = rng.below(4);
        stream.extend((0..post).map(|_| rng.byte()));
        let mutated = if case % 2 == 0 {
            let m = rng.below(stream.len());
            stream[m] ^= (rng.below(255) + 1) as u8;
            Some(m)
        } else {
            None
        };
        check_case(
            &mut dec,
            &stream,
            pre,
            pre + n - 1,
            mutated,
            (id, inst, &params),
        );
    }
}
