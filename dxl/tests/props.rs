//! Property tests and the long-running fuzz loop.
//!
//! The proptest cases honour `PROPTEST_CASES` (default 256). `fuzz_streams` runs
//! `DXL_FUZZ_CASES` random, mutated and junk-between-packets streams (default 20 000), one shard
//! per core; `scripts/test.sh` runs 10 000 000: `DXL_FUZZ_CASES=10000000 cargo test --target
//! host-tuple -p dxl --test props fuzz_streams`.
//!
//! The central property: in a stream of intact packets with junk between them (random bytes,
//! header fragments, corrupted packets, packets cut short by any number of bytes), every
//! intact packet is decoded when its last byte arrives — unless other bytes happen to form a
//! CRC-valid frame overlapping it (a 2⁻¹⁶ coincidence the protocol cannot rule out).

use dxl::instruction::SyncWrite;
use dxl::*;
use proptest::prelude::*;

const CAP: usize = 64;

mod common;
use common::bitwise_crc;

/// A packet: ID, instruction, parameters (unstuffed).
#[derive(Debug, Clone, PartialEq, Eq)]
struct Pkt {
    id: u8,
    inst: u8,
    params: Vec<u8>,
}

/// A packet found in (accepted) or put into (intact) a stream: its first and last byte.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Placed {
    start: usize,
    end: usize,
    pkt: Pkt,
}

/// Removes the stuffing bytes from an instruction + parameter region, written from the
/// protocol's rule independently of the decoder: an FD right after FF FF FD is dropped, and
/// the bytes before a dropped FD do not count for the next match.
fn unstuff(raw: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut last = [0u8; 3];
    for &b in raw {
        if last == [0xFF, 0xFF, 0xFD] && b == 0xFD {
            last = [0; 3];
            continue;
        }
        out.push(b);
        last = [last[1], last[2], b];
    }
    out
}

/// The start of a CRC-valid frame that ends at `end` in `stream` and carries `pkt` (with or
/// without unstuffing), checked independently of the decoder.
fn frame_start(stream: &[u8], end: usize, pkt: &Pkt, stuffed: bool) -> Option<usize> {
    (0..end.saturating_sub(8)).find(|&s| {
        let ok = stream[s..s + 4] == HEADER
            && stream[s + 4] == pkt.id
            && s + 7 + usize::from(u16::from_le_bytes([stream[s + 5], stream[s + 6]])) == end + 1
            && bitwise_crc(&stream[s..end - 1]).to_le_bytes() == [stream[end - 1], stream[end]];
        ok && {
            let raw = &stream[s + 7..end - 1];
            let region = if stuffed { unstuff(raw) } else { raw.to_vec() };
            region[0] == pkt.inst && region[1..] == pkt.params[..]
        }
    })
}

/// Feeds `stream` byte by byte; checks that every accepted packet is a CRC-valid frame that
/// ends with the byte that completed it and decodes to what the decoder returned.
///
/// It also feeds a clone of the decoder the same stream in blocks of pseudo-random sizes
/// (`Decoder::feed`, the fast path) and checks that it reports exactly the same events at the
/// same bytes, and ends with the same counters and state.
fn run<const N: usize>(dec: &mut Decoder<N>, stream: &[u8], stuffed: bool) -> Vec<Placed> {
    let mut blocks = dec.clone();
    let mut out = Vec::new();
    let mut events = Vec::new();
    for (i, &b) in stream.iter().enumerate() {
        let ev = dec.push(b);
        if let Some(ev) = &ev {
            events.push((i, ev.map(|p| (p.id, p.instruction, p.params.to_vec()))));
        }
        if let Some(Ok(p)) = ev {
            let pkt = Pkt {
                id: p.id,
                inst: p.instruction,
                params: p.params.to_vec(),
            };
            assert!(p.params.len() <= N);
            let Some(start) = frame_start(stream, i, &pkt, stuffed) else {
                panic!("accepted {pkt:02X?} at {i}, not a CRC-valid frame of {stream:02X?}");
            };
            out.push(Placed { start, end: i, pkt });
        }
    }
    assert_eq!(
        feed_events(&mut blocks, stream),
        events,
        "feed vs push on {stream:02X?}"
    );
    assert_eq!(blocks.stats(), dec.stats());
    assert_eq!(blocks.is_idle(), dec.is_idle());
    assert_eq!(blocks.wanted(), dec.wanted());
    assert_eq!(blocks.packet(), dec.packet());
    out
}

/// An event of the decoder at a byte index: the packet (ID, instruction, params) or the error.
type Event = (usize, Result<(u8, u8, Vec<u8>), DecodeError>);

/// Feeds `stream` with `Decoder::feed` in blocks of 1 to 40 bytes (sizes from a generator
/// seeded by the stream); the events with the index of the byte that completed each.
fn feed_events<const N: usize>(dec: &mut Decoder<N>, stream: &[u8]) -> Vec<Event> {
    let mut rng = XorShift(0x2545_F491_4F6C_DD1D ^ stream.len() as u64);
    let mut events = Vec::new();
    let mut at = 0;
    while at < stream.len() {
        let end = (at + 1 + rng.below(40)).min(stream.len());
        let mut pos = at;
        while pos < end {
            let (used, ev) = dec.feed(&stream[pos..end]);
            assert!(used >= 1 && pos + used <= end);
            if let Some(ev) = ev {
                events.push((
                    pos + used - 1,
                    ev.map(|p| (p.id, p.instruction, p.params.to_vec())),
                ));
            } else {
                assert_eq!(pos + used, end, "feed stops early only on an event");
            }
            pos += used;
        }
        at = end;
    }
    events
}

/// Whether `a` overlaps the bytes `p.start..=p.end`.
fn overlaps(a: &Placed, p: &Placed) -> bool {
    a.start <= p.end && a.end >= p.start
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
    let got = run(dec, stream, true);
    let is_original =
        |a: &Placed| a.end == end && (a.pkt.id, a.pkt.inst, &a.pkt.params[..]) == original;
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

/// Checks the decoder on a stream of intact packets (`placed`) with junk between them: each
/// is decoded exactly when its last byte arrives, unless an accepted frame made of other bytes
/// (a CRC-valid coincidence, checked by `run`) overlaps it.
fn check_stream(dec: &mut Decoder<CAP>, stream: &[u8], placed: &[Placed]) {
    dec.reset();
    let got = run(dec, stream, true);
    for p in placed {
        if got.contains(p) {
            continue;
        }
        let hidden = got.iter().any(|a| !placed.contains(a) && overlaps(a, p));
        assert!(
            hidden,
            "intact packet {p:02X?} lost in {stream:02X?}; decoded {got:02X?}"
        );
    }
    let stray = got.iter().filter(|a| !placed.contains(a)).count();
    let expected = placed.iter().filter(|p| got.contains(p)).count();
    assert_eq!(got.len(), stray + expected, "a packet was decoded twice");
}

/// Junk between intact packets.
#[derive(Debug, Clone)]
enum Junk {
    /// Arbitrary bytes.
    Bytes(Vec<u8>),
    /// The first `len` (1..=7) bytes of a preamble: header, ID, LEN.
    Preamble { len: usize, id: u8, plen: u16 },
    /// A valid packet without its last `1 + cut % length` bytes.
    Truncated { pkt: Pkt, cut: usize },
    /// A valid packet with byte `pos % length` XORed with `flip` (non-zero).
    Corrupted { pkt: Pkt, pos: usize, flip: u8 },
}

fn encode_pkt(pkt: &Pkt) -> Vec<u8> {
    let mut buf = [0u8; 2 * CAP + 16];
    let n = encode(&mut buf, pkt.id, pkt.inst, &pkt.params).unwrap();
    buf[..n].to_vec()
}

fn push_junk(stream: &mut Vec<u8>, junk: &Junk) {
    match junk {
        Junk::Bytes(b) => stream.extend_from_slice(b),
        Junk::Preamble { len, id, plen } => {
            let [lo, hi] = plen.to_le_bytes();
            let pre = [0xFF, 0xFF, 0xFD, 0x00, *id, lo, hi];
            stream.extend_from_slice(&pre[..(*len).clamp(1, 7)]);
        }
        Junk::Truncated { pkt, cut } => {
            let bytes = encode_pkt(pkt);
            let n = bytes.len();
            stream.extend_from_slice(&bytes[..n - 1 - cut % n]);
        }
        Junk::Corrupted { pkt, pos, flip } => {
            let mut bytes = encode_pkt(pkt);
            let n = bytes.len();
            bytes[pos % n] ^= flip;
            stream.extend_from_slice(&bytes);
        }
    }
}

/// Builds `junk packet junk packet ... junk`: the stream and where its intact packets are.
fn build_stream(parts: &[(Vec<Junk>, Pkt)], trailer: &[Junk]) -> (Vec<u8>, Vec<Placed>) {
    let mut stream = Vec::new();
    let mut placed = Vec::new();
    for (junk, pkt) in parts {
        junk.iter().for_each(|j| push_junk(&mut stream, j));
        let start = stream.len();
        stream.extend_from_slice(&encode_pkt(pkt));
        placed.push(Placed {
            start,
            end: stream.len() - 1,
            pkt: pkt.clone(),
        });
    }
    trailer.iter().for_each(|j| push_junk(&mut stream, j));
    (stream, placed)
}

fn byte() -> impl Strategy<Value = u8> {
    prop_oneof![any::<u8>(), Just(0xFF), Just(0xFD), Just(0x00)]
}

fn id() -> impl Strategy<Value = u8> {
    prop_oneof![0u8..=0xFC, Just(0xFE)]
}

fn pkt() -> impl Strategy<Value = Pkt> {
    pkt_of(byte(), 40)
}

/// A packet with its instruction from `inst` and fewer than `max_params` parameters.
fn pkt_of(inst: impl Strategy<Value = u8>, max_params: usize) -> impl Strategy<Value = Pkt> {
    let params = prop::collection::vec(byte(), 0..max_params);
    (id(), inst, params).prop_map(|(id, inst, params)| Pkt { id, inst, params })
}

fn junk() -> impl Strategy<Value = Junk> {
    prop_oneof![
        prop::collection::vec(byte(), 1..12).prop_map(Junk::Bytes),
        (1usize..=7, byte(), prop_oneof![0u16..80, any::<u16>()])
            .prop_map(|(len, id, plen)| Junk::Preamble { len, id, plen }),
        (pkt(), any::<usize>()).prop_map(|(pkt, cut)| Junk::Truncated { pkt, cut }),
        (pkt(), any::<usize>(), 1u8..=255).prop_map(|(pkt, pos, flip)| Junk::Corrupted {
            pkt,
            pos,
            flip
        }),
    ]
}

/// Junk before a packet; half the time it ends with a truncated packet (a LEN that swallows the next packet).
fn junk_before() -> impl Strategy<Value = Vec<Junk>> {
    (
        prop::collection::vec(junk(), 0..3),
        prop::option::of((pkt(), any::<usize>())),
    )
        .prop_map(|(mut junk, cut)| {
            junk.extend(cut.map(|(pkt, cut)| Junk::Truncated { pkt, cut }));
            junk
        })
}

/// A packet's bytes built from the protocol's rules, independently of `PacketWriter`: an
/// `FD` after `FF FF FD` in the instruction + parameter region gets an extra `FD`.
fn reference_encoding(id: u8, inst: u8, params: &[u8]) -> Vec<u8> {
    let mut region = Vec::new();
    for &b in std::iter::once(&inst).chain(params) {
        region.push(b);
        if region.ends_with(&[0xFF, 0xFF, 0xFD]) {
            region.push(0xFD);
        }
    }
    let mut out = HEADER.to_vec();
    out.push(id);
    out.extend_from_slice(&(region.len() as u16 + 2).to_le_bytes());
    out.extend_from_slice(&region);
    let crc = bitwise_crc(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

proptest! {
    #[test]
    fn encoder_matches_the_reference_in_any_split(
        id in id(),
        inst in any::<u8>(),
        params in prop::collection::vec(byte(), 0..48),
        cut in any::<prop::sample::Index>(),
    ) {
        let want = reference_encoding(id, inst, &params);
        // `extend` (runs of plain bytes, `push` for FD..FF) in two parts, and byte-wise `push`.
        let (a, b) = params.split_at(cut.index(params.len() + 1));
        let mut buf = [0u8; 2 * CAP + 16];
        let mut w = PacketWriter::new(&mut buf, id, inst).unwrap();
        w.extend(a).unwrap();
        w.extend(b).unwrap();
        let n = w.finish().unwrap();
        prop_assert_eq!(&buf[..n], &want[..]);
        let mut buf2 = [0u8; 2 * CAP + 16];
        let mut w = PacketWriter::new(&mut buf2, id, inst).unwrap();
        for &x in &params {
            w.push(x).unwrap();
        }
        let n = w.finish().unwrap();
        prop_assert_eq!(&buf2[..n], &want[..]);
        // Too small a buffer fails at every length short of the packet.
        for short in 0..want.len() {
            let mut small = vec![0u8; short];
            let r = PacketWriter::new(&mut small, id, inst)
                .and_then(|mut w| w.extend(&params).and_then(|()| w.finish()));
            prop_assert_eq!(r, Err(EncodeError::BufferTooSmall));
        }
    }

    #[test]
    fn roundtrip_any_packet(
        pkt in pkt_of(any::<u8>(), 48),
        pre in prop::collection::vec(byte(), 0..24),
        post in prop::collection::vec(byte(), 0..8),
    ) {
        let packet = encode_pkt(&pkt);
        let n = packet.len();
        let stream = [&pre[..], &packet, &post].concat();
        let original = (pkt.id, pkt.inst, &pkt.params[..]);
        // One-shot decode of the clean packet.
        let mut out = [0u8; 2 * CAP];
        let p = decode(&packet, &mut out).unwrap();
        prop_assert_eq!((p.id, p.instruction, p.params), original);
        // Streaming decode after arbitrary garbage.
        let mut dec = Decoder::<CAP>::new();
        check_case(&mut dec, &stream, pre.len(), pre.len() + n - 1, None, original);
    }

    #[test]
    fn intact_packets_survive_junk(
        parts in prop::collection::vec((junk_before(), pkt()), 1..4),
        trailer in prop::collection::vec(junk(), 0..2),
    ) {
        let (stream, placed) = build_stream(&parts, &trailer);
        let mut dec = Decoder::<CAP>::new();
        check_stream(&mut dec, &stream, &placed);
        // Without unstuffing nothing is guaranteed here, but all it accepts must be frames.
        dec.reset();
        dec.set_stuffing(false);
        run(&mut dec, &stream, false);
    }

    #[test]
    fn mutated_packets_are_rejected(
        pkt in pkt_of(any::<u8>(), 48),
        pre in prop::collection::vec(byte(), 0..8),
        pos in any::<prop::sample::Index>(),
        flip in 1u8..=255,
    ) {
        let packet = encode_pkt(&pkt);
        let n = packet.len();
        let mut stream = [&pre[..], &packet].concat();
        let m = pos.index(stream.len());
        stream[m] ^= flip;
        let original = (pkt.id, pkt.inst, &pkt.params[..]);
        let mut dec = Decoder::<CAP>::new();
        check_case(&mut dec, &stream, pre.len(), pre.len() + n - 1, Some(m), original);
    }

    #[test]
    fn random_streams_never_panic(stream in prop::collection::vec(byte(), 0..400)) {
        let mut dec = Decoder::<CAP>::new();
        run(&mut dec, &stream, true);
        let mut raw = Decoder::<CAP>::new();
        raw.set_stuffing(false);
        run(&mut raw, &stream, false);
        let mut out = [0u8; 16];
        let _ = decode(&stream, &mut out);
        let mut small = Decoder::<0>::new();
        run(&mut small, &stream, true);
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

    fn pkt(&mut self) -> Pkt {
        let id = if self.below(16) == 0 {
            0xFE
        } else {
            self.below(0xFD) as u8
        };
        let inst = self.byte();
        let plen = self.below(40);
        let params = (0..plen).map(|_| self.byte()).collect();
        Pkt { id, inst, params }
    }

    fn junk(&mut self) -> Junk {
        match self.below(4) {
            0 => Junk::Bytes((0..1 + self.below(11)).map(|_| self.byte()).collect()),
            1 => Junk::Preamble {
                len: 1 + self.below(7),
                id: self.byte(),
                plen: if self.below(2) == 0 {
                    self.below(80) as u16
                } else {
                    self.next() as u16
                },
            },
            2 => self.truncated(),
            _ => Junk::Corrupted {
                pkt: self.pkt(),
                pos: self.next() as usize,
                flip: (self.below(255) + 1) as u8,
            },
        }
    }

    /// A packet cut short by 1 ..= its length bytes, uniformly.
    fn truncated(&mut self) -> Junk {
        Junk::Truncated {
            pkt: self.pkt(),
            cut: self.next() as usize,
        }
    }
}

#[test]
fn fuzz_streams() {
    let cases: u64 = std::env::var("DXL_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20_000);
    // One shard per core, each its own random sequence; shard k runs cases k, k + n, k + 2n, …
    // so that the mix of stream kinds (by case number) is the same whatever the core count.
    let shards = std::thread::available_parallelism().map_or(1, |n| n.get().min(8)) as u64;
    std::thread::scope(|scope| {
        for k in 0..shards {
            scope.spawn(move || fuzz_shard(k, shards, cases));
        }
    });
}

/// The cases `first, first + step, …` below `cases` of [`fuzz_streams`], on the random sequence
/// of shard `first`.
fn fuzz_shard(first: u64, step: u64, cases: u64) {
    // A zero state would freeze XorShift: any seed, never zero.
    let mut rng =
        XorShift((0x9E37_79B9_7F4A_7C15 ^ first.wrapping_mul(0xD1B5_4A32_D192_ED03)).max(1));
    let mut dec = Decoder::<CAP>::new();
    let mut raw_dec = Decoder::<CAP>::new();
    raw_dec.set_stuffing(false);
    let mut buf = [0u8; 2 * CAP + 16];
    let mut params = Vec::with_capacity(CAP);
    let mut stream = Vec::with_capacity(4 * CAP);
    for case in (first..cases).step_by(step.max(1) as usize) {
        stream.clear();
        match case % 10 {
            0 => {
                // Pure random stream: must not panic; anything accepted must be a valid frame.
                let len = rng.below(300);
                stream.extend((0..len).map(|_| rng.byte()));
                dec.reset();
                run(&mut dec, &stream, true);
                raw_dec.reset();
                run(&mut raw_dec, &stream, false);
                continue;
            }
            1..=4 => {} // one packet between random bytes, below
            _ => {
                // Intact packets with junk between them; before a packet, half the time a
                // truncated one (its LEN swallows the intact packet's first bytes).
                let parts: Vec<_> = (0..1 + rng.below(3))
                    .map(|_| {
                        let mut junk: Vec<_> = (0..rng.below(3)).map(|_| rng.junk()).collect();
                        if rng.below(2) == 0 {
                            junk.push(rng.truncated());
                        }
                        (junk, rng.pkt())
                    })
                    .collect();
                let trailer: Vec<_> = (0..rng.below(2)).map(|_| rng.junk()).collect();
                let (stream, placed) = build_stream(&parts, &trailer);
                check_stream(&mut dec, &stream, &placed);
                raw_dec.reset();
                run(&mut raw_dec, &stream, false);
                continue;
            }
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
