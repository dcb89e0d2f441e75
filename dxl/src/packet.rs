//! Protocol 2.0 packet framing: encoder, byte stuffing and a streaming decoder.
//!
//! Wire format of every packet (instruction and status alike):
//!
//! ```text
//! FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM ... | CRC_L CRC_H
//! ```
//!
//! * `LEN` counts `INST`, the parameters **after stuffing** and the two CRC bytes.
//! * The CRC ([`crate::crc`]) covers everything from the first header byte through the last
//!   stuffed parameter.
//! * Byte stuffing: inside the `INST`+`PARAM` region every `FF FF FD` is followed by an
//!   extra `FD`, so the header pattern `FF FF FD 00` can never appear inside a packet. The
//!   decoder removes the extra byte again.
//!
//! [`PacketWriter`] encodes into a caller-supplied `&mut [u8]`; [`Decoder`] is fed one byte
//! at a time, skips garbage, resynchronises on the next header and reports typed errors.
//!
//! Resynchronisation: when a candidate frame fails, decoding goes on as if the input were
//! scanned again from the byte after the failed frame's first byte, its body and CRC
//! included, without keeping that input:
//! * while looking for a packet the decoder keeps the longest suffix of the input that can
//!   still start one, so a false header with an impossible ID or LEN never hides a real
//!   packet behind it;
//! * a header appearing inside a (stuffed) packet body aborts that packet
//!   ([`DecodeError::Interrupted`]) and decoding restarts from it;
//! * so after a CRC failure a packet can only start in the rejected frame's last five bytes
//!   (a header that ends on a CRC byte, or a prefix of one; none starts in the header, ID or
//!   LEN), and decoding resumes from there — e.g. after a packet cut short by five bytes,
//!   whose CRC bytes are the next packet's `00` and ID.
//!
//! Hence a valid packet after arbitrary garbage or after broken (truncated, corrupted)
//! packets is always found, when its last byte arrives, unless the garbage and the packet's
//! first bytes happen to form a frame with a valid CRC (a 2⁻¹⁶ coincidence the protocol
//! cannot rule out). Every accepted packet is a CRC-valid frame.
//!
//! Without stuffing ([`Decoder::set_stuffing`]`(false)`, FAST SYNC READ replies) a header
//! inside a body is legal data and cannot abort the frame, so this guarantee does not hold:
//! a packet that starts inside a rejected frame is found only if it starts in its last six
//! bytes (a reply after an echo cut short by up to six bytes, but not by more).

use crate::crc;

/// The four header bytes that start every packet.
pub const HEADER: [u8; 4] = [0xFF, 0xFF, 0xFD, 0x00];
/// Broadcast ID: every device executes the instruction (and only some reply).
pub const BROADCAST_ID: u8 = 0xFE;
/// Largest ID a single device may have.
pub const MAX_DEVICE_ID: u8 = 0xFC;
/// Bytes before the instruction: header, ID, LEN.
pub const PREAMBLE_LEN: usize = 7;
/// Packet overhead: preamble, instruction and CRC.
pub const OVERHEAD: usize = PREAMBLE_LEN + 1 + 2;

/// Encoding failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The output buffer cannot hold the packet.
    BufferTooSmall,
    /// The packet would exceed the 16-bit LEN field.
    TooLong,
    /// An argument is inconsistent (e.g. sync-write data of the wrong length, bad ID).
    InvalidArgument,
}

/// Writes one packet into a byte buffer, stuffing the instruction/parameter region.
///
/// The bytes are copied as given; [`finish`](Self::finish) stuffs the region in one pass (a
/// word-at-a-time scan for `FD`..`FF` finds that nothing is due in the common case; an `FD`
/// is inserted after each `FF FF FD` otherwise), then fills in LEN and the CRC.
#[derive(Debug)]
pub struct PacketWriter<'a> {
    buf: &'a mut [u8],
    pos: usize,
    stuffing: bool,
}

impl<'a> PacketWriter<'a> {
    /// Starts a packet (header, ID, LEN placeholder, instruction) with byte stuffing.
    pub fn new(buf: &'a mut [u8], id: u8, instruction: u8) -> Result<Self, EncodeError> {
        Self::with_stuffing(buf, id, instruction, true)
    }

    /// Starts a packet, choosing whether the parameter region is byte-stuffed.
    ///
    /// Only the FAST SYNC READ combined reply is sent unstuffed.
    pub fn with_stuffing(
        buf: &'a mut [u8],
        id: u8,
        instruction: u8,
        stuffing: bool,
    ) -> Result<Self, EncodeError> {
        let [h0, h1, h2, h3] = HEADER;
        // The preamble with a LEN placeholder, and the instruction.
        let start = [h0, h1, h2, h3, id, 0, 0, instruction];
        buf.get_mut(..start.len())
            .ok_or(EncodeError::BufferTooSmall)?
            .copy_from_slice(&start);
        Ok(PacketWriter {
            buf,
            pos: start.len(),
            stuffing,
        })
    }

    /// Appends one parameter byte.
    #[inline(always)]
    pub fn push(&mut self, b: u8) -> Result<(), EncodeError> {
        let slot = self
            .buf
            .get_mut(self.pos)
            .ok_or(EncodeError::BufferTooSmall)?;
        *slot = b;
        self.pos += 1;
        Ok(())
    }

    /// Appends parameter bytes.
    #[inline(always)]
    pub fn extend(&mut self, data: &[u8]) -> Result<(), EncodeError> {
        let end = self.pos + data.len();
        let dst = self
            .buf
            .get_mut(self.pos..end)
            .ok_or(EncodeError::BufferTooSmall)?;
        copy_bytes(dst, data);
        self.pos = end;
        Ok(())
    }

    /// Appends a little-endian `u16` parameter.
    pub fn push_u16(&mut self, v: u16) -> Result<(), EncodeError> {
        self.extend(&v.to_le_bytes())
    }

    /// Writes a LEN value now (normally [`finish`](Self::finish) fills it in).
    ///
    /// Needed when a running CRC must cover LEN before the packet ends (FAST SYNC READ).
    pub fn preset_len(&mut self, len: u16) {
        let [lo, hi] = len.to_le_bytes();
        if let Some(s) = self.buf.get_mut(5) {
            *s = lo;
        }
        if let Some(s) = self.buf.get_mut(6) {
            *s = hi;
        }
    }

    /// Bytes written so far: as they will appear on the wire for an unstuffed packet; a
    /// stuffed one gets its stuffing bytes in [`finish`](Self::finish).
    pub fn written(&self) -> &[u8] {
        self.buf.get(..self.pos).unwrap_or(&[])
    }

    /// Inserts the stuffing bytes into the instruction/parameter region: an `FD` after each
    /// `FF FF FD` (matching restarts after an inserted `FD`).
    fn stuff(&mut self) -> Result<(), EncodeError> {
        let region = self.buf.get(PREAMBLE_LEN..self.pos).unwrap_or(&[]);
        // The first FF FF FD ends at `i`: match again from its first FF.
        let mut at = match first_stuffing(region) {
            Some(i) => PREAMBLE_LEN + i - 3,
            None => return Ok(()),
        };
        // Rare: make room for each stuffing byte, from the first one on.
        let mut matched = 0;
        while at < self.pos {
            let b = self.buf.get(at).copied().unwrap_or(0);
            matched = match (matched, b) {
                (2, 0xFD) => 3,
                (1 | 2, 0xFF) => 2,
                (_, 0xFF) => 1,
                _ => 0,
            };
            at += 1;
            if matched == 3 {
                if self.pos >= self.buf.len() {
                    return Err(EncodeError::BufferTooSmall);
                }
                // Shift the rest up by one, the FD going in at `at`: each byte takes the one
                // before it (a carried byte, not `copy_within`: this rare path would otherwise
                // link `memmove`, 1.6 KB of the OpenCM's flash).
                let mut carry = 0xFD;
                for slot in self.buf.get_mut(at..=self.pos).unwrap_or(&mut []) {
                    core::mem::swap(slot, &mut carry);
                }
                self.pos += 1;
                at += 1;
                matched = 0;
            }
        }
        Ok(())
    }

    /// Stuffs the region, fills in LEN and the CRC; returns the total packet length.
    pub fn finish(mut self) -> Result<usize, EncodeError> {
        if self.stuffing {
            self.stuff()?;
        }
        let len = self
            .pos
            .checked_sub(PREAMBLE_LEN - 2)
            .and_then(|l| u16::try_from(l).ok())
            .ok_or(EncodeError::TooLong)?;
        self.preset_len(len);
        let crc = crc::crc16(self.written());
        let end = self.pos + 2;
        self.buf
            .get_mut(self.pos..end)
            .ok_or(EncodeError::BufferTooSmall)?
            .copy_from_slice(&crc.to_le_bytes());
        Ok(end)
    }
}

/// The index just after the first `FF FF FD` in `region`, if any (where the first stuffing
/// byte goes). Words without `FD`..`FF` are skipped four bytes at a time; such a byte ends
/// any partial match.
fn first_stuffing(region: &[u8]) -> Option<usize> {
    let mut matched = 0;
    let mut i = 0;
    while i < region.len() {
        if let Some(s) = region.get(i..i + 4) {
            if !has_fd_or_above(word(s)) {
                matched = 0;
                i += 4;
                continue;
            }
        }
        let stop = (i + 4).min(region.len());
        while i < stop {
            let b = region.get(i).copied().unwrap_or(0);
            matched = match (matched, b) {
                (2, 0xFD) => return Some(i + 1),
                (1 | 2, 0xFF) => 2,
                (_, 0xFF) => 1,
                _ => 0,
            };
            i += 1;
        }
    }
    None
}

/// Encodes a complete packet with the given parameters; returns its length.
pub fn encode(
    buf: &mut [u8],
    id: u8,
    instruction: u8,
    params: &[u8],
) -> Result<usize, EncodeError> {
    let mut w = PacketWriter::new(buf, id, instruction)?;
    w.extend(params)?;
    w.finish()
}

/// A decoded packet; `params` are already unstuffed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Packet<'a> {
    /// Device ID (or [`BROADCAST_ID`]).
    pub id: u8,
    /// Instruction byte (`0x55` for status packets).
    pub instruction: u8,
    /// Parameters without stuffing and without CRC.
    pub params: &'a [u8],
}

/// Decoding failure reported by [`Decoder::push`]; the decoder is ready for the next byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// The received CRC does not match; `id` is the (untrusted) ID field.
    Crc {
        /// ID field of the rejected packet.
        id: u8,
    },
    /// The ID field is 0xFD or 0xFF (reserved / impossible).
    BadId,
    /// LEN is smaller than 3 (instruction + CRC).
    LenTooSmall,
    /// LEN announces more parameter bytes than the decoder buffer holds (or is 0xFF00 or
    /// more, whatever the buffer).
    LenTooLarge,
    /// A new header appeared inside a packet body; decoding restarted from it.
    Interrupted,
    /// The input ended before a complete packet (one-shot [`decode`] only).
    Incomplete,
}

/// Receive counters of a [`Decoder`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecoderStats {
    /// Packets accepted.
    pub packets: u32,
    /// Packets rejected for a bad CRC.
    pub crc_errors: u32,
    /// Headers rejected for a bad ID or LEN, or interrupted by a new header.
    pub framing_errors: u32,
    /// Bytes skipped while searching for a header.
    pub skipped_bytes: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Preamble,
    Body,
    CrcLow,
    CrcHigh,
}

/// Buffer-independent decoder state (shared by [`Decoder`] and [`decode`]).
#[derive(Debug, Clone)]
struct Core {
    state: State,
    /// The preamble received so far; the frame's whole preamble in the other states.
    pre: [u8; PREAMBLE_LEN],
    pre_len: usize,
    id: u8,
    instruction: u8,
    have_instruction: bool,
    /// Raw region bytes (instruction + stuffed params) still expected.
    remaining: usize,
    params_len: usize,
    crc: u16,
    crc_low: u8,
    /// Progress of a header match inside the body (see [`header_step`]; for
    /// resynchronisation), also the unstuffing state: 3 = the last raw bytes were FF FF FD (an
    /// FD now is the stuffing byte). A dropped stuffing byte leaves it at 0, so FF FF FD FD FD
    /// keeps the second FD.
    nested: usize,
    stuffing: bool,
    complete: bool,
    stats: DecoderStats,
}

/// Returns whether `p` can still be the beginning of a valid packet preamble, given that
/// `p[..from]` already passed this check.
fn check_preamble(p: &[u8], from: usize, capacity: usize) -> Result<(), Option<DecodeError>> {
    for (i, &b) in p.iter().enumerate().skip(from) {
        match i {
            0..=3 if HEADER.get(i) != Some(&b) => return Err(None),
            4 if b == 0xFD || b == 0xFF => return Err(Some(DecodeError::BadId)),
            6 => {
                let len = usize::from(u16::from_le_bytes([p.get(5).copied().unwrap_or(0), b]));
                if len < 3 {
                    return Err(Some(DecodeError::LenTooSmall));
                }
                // LEN_H = FF is refused too: a header could then start inside LEN, where the
                // body's header check does not see it.
                if len - 3 > capacity.min(0xFEFC) {
                    return Err(Some(DecodeError::LenTooLarge));
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// The little-endian word of a 4-byte chunk (0 for a shorter slice, never given here).
#[inline(always)]
fn word(s: &[u8]) -> u32 {
    match s {
        &[a, b, c, d] => u32::from_le_bytes([a, b, c, d]),
        _ => 0,
    }
}

/// Whether any byte of `w` is `FD`, `FE` or `FF` (the bytes that can need stuffing or
/// advance a header match). Per byte: `(b & 7F) + 3` sets bit 7 exactly when
/// `b & 7F ≥ 7D` (and never carries into the next byte), so with bit 7 of `b` itself it
/// flags `b ≥ FD`.
#[inline(always)]
fn has_fd_or_above(w: u32) -> bool {
    ((w & 0x7F7F_7F7F).wrapping_add(0x0303_0303) & w & 0x8080_8080) != 0
}

/// Copies `src` into the start of `dst` (the shorter length), a word at a time: packets'
/// pieces are short, and a `memcpy` call costs more than the copy.
#[inline(always)]
fn copy_bytes(dst: &mut [u8], src: &[u8]) {
    let mut d = dst.chunks_exact_mut(4);
    let mut s = src.chunks_exact(4);
    for (dw, sw) in (&mut d).zip(&mut s) {
        if let (Ok(dw), Ok(sw)) = (<&mut [u8; 4]>::try_from(dw), <&[u8; 4]>::try_from(sw)) {
            *dw = *sw;
        }
    }
    for (db, sb) in d.into_remainder().iter_mut().zip(s.remainder()) {
        *db = *sb;
    }
}

/// One step of matching [`HEADER`] in a byte stream: `state` = header bytes matched so far.
#[inline(always)]
fn header_step(state: usize, byte: u8) -> usize {
    match (state, byte) {
        (1 | 2, 0xFF) => 2,
        (_, 0xFF) => 1,
        (2, 0xFD) => 3,
        (3, 0x00) => 4,
        _ => 0,
    }
}

impl Core {
    const fn new() -> Self {
        Core {
            state: State::Preamble,
            pre: [0; PREAMBLE_LEN],
            pre_len: 0,
            id: 0,
            instruction: 0,
            have_instruction: false,
            remaining: 0,
            params_len: 0,
            crc: 0,
            crc_low: 0,
            nested: 0,
            stuffing: true,
            complete: false,
            stats: DecoderStats {
                packets: 0,
                crc_errors: 0,
                framing_errors: 0,
                skipped_bytes: 0,
            },
        }
    }

    fn reset(&mut self) {
        self.state = State::Preamble;
        self.pre_len = 0;
        self.complete = false;
    }

    fn packet<'b>(&self, buf: &'b [u8]) -> Option<Packet<'b>> {
        if !self.complete {
            return None;
        }
        Some(Packet {
            id: self.id,
            instruction: self.instruction,
            params: buf.get(..self.params_len)?,
        })
    }

    fn push(&mut self, buf: &mut [u8], byte: u8) -> Option<Result<(), DecodeError>> {
        self.complete = false;
        if self.state == State::Preamble {
            return self.push_preamble(buf.len(), byte);
        }
        match self.state {
            State::Preamble => None, // returned above; here only for exhaustiveness
            State::Body => {
                // Track a header starting inside the frame (one call site, inlined).
                let before = self.nested;
                self.nested = header_step(before, byte);
                self.push_body(buf, byte, before == 3)
            }
            State::CrcLow => {
                self.crc_low = byte;
                self.state = State::CrcHigh;
                None
            }
            State::CrcHigh => {
                self.reset();
                if u16::from_le_bytes([self.crc_low, byte]) == self.crc {
                    self.complete = true;
                    self.stats.packets = self.stats.packets.wrapping_add(1);
                    Some(Ok(()))
                } else {
                    self.crc_failed(buf.len(), byte)
                }
            }
        }
    }

    /// Rejects the frame whose last byte, `byte`, did not match the CRC.
    #[cold]
    #[inline(never)]
    fn crc_failed(&mut self, capacity: usize, byte: u8) -> Option<Result<(), DecodeError>> {
        self.stats.crc_errors = self.stats.crc_errors.wrapping_add(1);
        let id = self.id;
        // Scan the rejected frame again from its second byte. No packet starts in its header
        // or ID (FF FD 00 and the ID are not FF FF), nor in LEN (`check_preamble` refuses
        // LEN_H = FF), nor wholly inside a stuffed body (that is `Interrupted`): only in the
        // last bytes, as the header prefix that ended on the last body byte (`nested` bytes of
        // it) followed by the two CRC bytes. `pre` still starts with the rejected header.
        self.pre_len = self.nested;
        // A bad ID found here is counted; the CRC error is what is reported.
        let _ = self.push_preamble(capacity, self.crc_low);
        let _ = self.push_preamble(capacity, byte);
        Some(Err(DecodeError::Crc { id }))
    }

    // Out of line: the body bytes, the common case, then need fewer registers saved per byte.
    #[inline(never)]
    fn push_preamble(&mut self, capacity: usize, byte: u8) -> Option<Result<(), DecodeError>> {
        if let Some(slot) = self.pre.get_mut(self.pre_len) {
            *slot = byte;
            self.pre_len += 1;
        }
        let mut first_error = None;
        // Keep the longest suffix of the received bytes that can still start a packet. The
        // bytes before the new one passed already; after a shift, all are checked again.
        let mut from = self.pre_len.saturating_sub(1);
        while self.pre_len > 0 {
            let p = self.pre.get(..self.pre_len).unwrap_or(&[]);
            match check_preamble(p, from, capacity) {
                Ok(()) => break,
                Err(e) => {
                    if let Some(e) = e {
                        self.stats.framing_errors = self.stats.framing_errors.wrapping_add(1);
                        first_error = first_error.or(Some(e));
                    } else {
                        self.stats.skipped_bytes = self.stats.skipped_bytes.wrapping_add(1);
                    }
                    self.pre.copy_within(1.., 0);
                    self.pre_len -= 1;
                    from = 0;
                }
            }
        }
        if self.pre_len == PREAMBLE_LEN {
            self.start_body();
        }
        first_error.map(Err)
    }

    /// The whole preamble (checked) is in `pre`: the frame's body comes next.
    fn start_body(&mut self) {
        let [.., id, lo, hi] = self.pre;
        self.id = id;
        // `check_preamble` guaranteed LEN >= 3.
        self.remaining = usize::from(u16::from_le_bytes([lo, hi])).saturating_sub(2);
        self.crc = crc::crc16(&self.pre);
        self.params_len = 0;
        self.have_instruction = false;
        self.nested = 0;
        self.state = State::Body;
    }

    /// Block decoding: bytes until an event (how many were used, and the event).
    ///
    /// Equivalent to [`push`](Self::push) on each byte in turn (same events, same state
    /// after, same counters), with fast paths for a whole valid frame without `FF FF FD` in
    /// its body, a whole clean preamble at the start of a search, the instruction byte, both CRC bytes when they match, and runs of body bytes
    /// up to a completed `FF FF FD` (only the byte after one can be stuffing or end a
    /// header; every other body byte only feeds the CRC, the buffer and the header match).
    fn feed(&mut self, buf: &mut [u8], bytes: &[u8]) -> (usize, Option<Result<(), DecodeError>>) {
        let mut used = 0;
        if !bytes.is_empty() {
            // As `push` does for every byte: the last packet is no longer current.
            self.complete = false;
        }
        while let Some(rest) = bytes.get(used..) {
            let Some(&first) = rest.first() else { break };
            match self.state {
                State::Body if self.nested != 3 && (self.have_instruction || first < 0xFD) => {
                    if !self.have_instruction {
                        // The instruction byte, as `push_body` takes it.
                        self.instruction = first;
                        self.have_instruction = true;
                        self.crc = crc::update_byte(self.crc, first);
                        self.remaining = self.remaining.saturating_sub(1);
                        if self.remaining == 0 {
                            self.state = State::CrcLow;
                        }
                        used += 1;
                        continue;
                    }
                    let n = self.body_run(buf, rest);
                    if n > 0 {
                        used += n;
                        continue;
                    }
                }
                State::CrcLow => {
                    if let Some(&[lo, hi]) = rest.get(..2) {
                        if u16::from_le_bytes([lo, hi]) == self.crc {
                            // Both CRC bytes at once: the packet is complete.
                            self.reset();
                            self.complete = true;
                            self.stats.packets = self.stats.packets.wrapping_add(1);
                            return (used + 2, Some(Ok(())));
                        }
                    }
                }
                State::Preamble if self.pre_len == 0 => {
                    if let Some(n) = self.whole_frame(buf, rest) {
                        return (used + n, Some(Ok(())));
                    }
                    if let Some(pre) = rest.get(..PREAMBLE_LEN) {
                        if check_preamble(pre, 0, buf.len()).is_ok() {
                            self.pre.copy_from_slice(pre);
                            self.pre_len = PREAMBLE_LEN;
                            self.start_body();
                            used += PREAMBLE_LEN;
                            continue;
                        }
                    }
                }
                _ => {}
            }
            used += 1;
            if let Some(ev) = self.push(buf, first) {
                return (used, Some(ev));
            }
        }
        (bytes.len(), None)
    }

    /// A whole valid frame at the start of `bytes` (searching, nothing buffered) with no
    /// `FF FF FD` in its body, so without stuffing bytes or a header inside: accepted in one
    /// go (preamble check, one CRC pass over the frame, one copy of the parameters) with the
    /// outcome `push` would reach on its last byte; its length. `None` (nothing changed)
    /// for anything else, which then takes the byte-wise paths.
    fn whole_frame(&mut self, buf: &mut [u8], bytes: &[u8]) -> Option<usize> {
        let pre = bytes.get(..PREAMBLE_LEN)?;
        check_preamble(pre, 0, buf.len()).ok()?;
        let len = usize::from(u16::from_le_bytes([*pre.get(5)?, *pre.get(6)?]));
        let end = PREAMBLE_LEN + len;
        let frame = bytes.get(..end)?;
        let (covered, [lo, hi]) = frame.split_last_chunk::<2>()?;
        let body = covered.get(PREAMBLE_LEN..)?;
        if first_stuffing(body).is_some() || crc::crc16(covered) != u16::from_le_bytes([*lo, *hi]) {
            return None;
        }
        let (&instruction, params) = body.split_first()?;
        copy_bytes(buf.get_mut(..params.len())?, params);
        self.id = *pre.get(4)?;
        self.instruction = instruction;
        self.params_len = params.len();
        self.reset();
        self.complete = true;
        self.stats.packets = self.stats.packets.wrapping_add(1);
        Some(end)
    }

    /// The leading parameter bytes of `bytes` within the frame's body, up to and including
    /// one that completes `FF FF FD` (the state is `Body` after the instruction, `nested` is
    /// not 3): CRC'd, stored and matched as [`push_body`](Self::push_body) would; how many (0
    /// only if the buffer is full).
    #[inline(always)]
    fn body_run(&mut self, buf: &mut [u8], bytes: &[u8]) -> usize {
        let Some(dst) = buf.get_mut(self.params_len..) else {
            return 0;
        };
        let src = bytes.get(..self.remaining).unwrap_or(bytes);
        let len = dst.len().min(src.len());
        let mut nested = self.nested;
        let mut n = 0;
        'run: while n < len {
            // Whole words without FD..FF: copied; each such byte ends any header match (a
            // `00` continues one only after FF FF FD, and `nested` is not 3 here).
            while let (Some(d), Some(s)) = (dst.get_mut(n..n + 4), src.get(n..n + 4)) {
                if has_fd_or_above(word(s)) {
                    break;
                }
                d.copy_from_slice(s);
                n += 4;
                nested = 0;
            }
            // Then up to four bytes one at a time.
            let stop = (n + 4).min(len);
            while n < stop {
                let (Some(d), Some(&b)) = (dst.get_mut(n), src.get(n)) else {
                    break 'run;
                };
                *d = b;
                n += 1;
                if b >= 0xFD {
                    nested = header_step(nested, b);
                    if nested == 3 {
                        // After FF FF FD the next byte may be stuffing or start the `00` of
                        // a header: `push` decides.
                        break 'run;
                    }
                } else {
                    nested = 0;
                }
            }
        }
        // The run is stored unchanged (nothing dropped): its CRC in one pass.
        self.crc = crc::update(self.crc, dst.get(..n).unwrap_or(&[]));
        self.nested = nested;
        self.params_len += n;
        self.remaining -= n;
        if self.remaining == 0 {
            self.state = State::CrcLow;
        }
        n
    }

    /// How many more bytes the current frame needs (at least 1; see [`Decoder::wanted`]).
    fn wanted(&self) -> usize {
        match self.state {
            // A packet starting at the earliest possible byte has 3 more after its preamble.
            State::Preamble => PREAMBLE_LEN - self.pre_len.min(PREAMBLE_LEN - 1),
            // The rest of the body and the CRC.
            State::Body => (self.remaining + 2).max(1),
            State::CrcLow => 2,
            State::CrcHigh => 1,
        }
    }

    /// One body byte (`nested` already advanced past it; `after_ff_ff_fd`: the raw bytes
    /// before it were FF FF FD).
    fn push_body(
        &mut self,
        buf: &mut [u8],
        byte: u8,
        after_ff_ff_fd: bool,
    ) -> Option<Result<(), DecodeError>> {
        self.crc = crc::update_byte(self.crc, byte);
        self.remaining = self.remaining.saturating_sub(1);
        if self.remaining == 0 {
            self.state = State::CrcLow;
        }
        if self.stuffing {
            // A correctly stuffed region never contains FF FF FD 00: it is a new packet.
            if self.nested == 4 {
                self.stats.framing_errors = self.stats.framing_errors.wrapping_add(1);
                self.state = State::Preamble;
                // `pre` still starts with this frame's header, the same bytes.
                self.pre_len = 4;
                return Some(Err(DecodeError::Interrupted));
            }
            // FF FF FD FD: drop the stuffing FD (`header_step` left `nested` at 0).
            if after_ff_ff_fd && byte == 0xFD {
                return None;
            }
        }
        if !self.have_instruction {
            self.instruction = byte;
            self.have_instruction = true;
        } else if let Some(slot) = buf.get_mut(self.params_len) {
            *slot = byte;
            self.params_len += 1;
        }
        // (A full buffer cannot happen: the preamble check bounds LEN by the capacity.)
        None
    }
}

/// Streaming packet decoder holding at most `N` parameter bytes.
///
/// Feed it bytes with [`push`](Self::push). `N` bounds the *raw* (stuffed) parameter length
/// (`LEN - 3`); longer packets, and any with LEN ≥ 0xFF00, are rejected with
/// [`DecodeError::LenTooLarge`] as soon as their LEN field arrives.
#[derive(Debug, Clone)]
pub struct Decoder<const N: usize> {
    core: Core,
    buf: [u8; N],
}

impl<const N: usize> Default for Decoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Decoder<N> {
    /// Creates an empty decoder.
    pub const fn new() -> Self {
        Decoder {
            core: Core::new(),
            buf: [0; N],
        }
    }

    /// Feeds one byte; returns a packet or an error when one is complete.
    pub fn push(&mut self, byte: u8) -> Option<Result<Packet<'_>, DecodeError>> {
        match self.core.push(&mut self.buf, byte)? {
            Ok(()) => self.core.packet(&self.buf).map(Ok),
            Err(e) => Some(Err(e)),
        }
    }

    /// Feeds bytes until a packet or error completes; returns the bytes consumed and the event.
    ///
    /// The same events and state as [`push`](Self::push) on each byte in turn, faster: a
    /// clean preamble and the runs of parameter bytes below `FD` take a tight loop (the
    /// block-read path of the bus master).
    pub fn feed(&mut self, bytes: &[u8]) -> (usize, Option<Result<Packet<'_>, DecodeError>>) {
        match self.core.feed(&mut self.buf, bytes) {
            (n, None) => (n, None),
            (n, Some(Ok(()))) => (n, self.core.packet(&self.buf).map(Ok)),
            (n, Some(Err(e))) => (n, Some(Err(e))),
        }
    }

    /// How many more bytes the frame being received needs (≥ 1): the rest of the preamble,
    /// or of the body and CRC. A reader asking the line for this many never reads past the
    /// end of the packet being received, nor of one starting after it; only a packet starting
    /// inside a broken frame's body (which interrupts it) can end earlier, so a reader keeps
    /// what [`feed`](Self::feed) did not use for its next call.
    pub fn wanted(&self) -> usize {
        self.core.wanted()
    }

    /// The packet completed by the last [`push`](Self::push), if it completed one.
    pub fn packet(&self) -> Option<Packet<'_>> {
        self.core.packet(&self.buf)
    }

    /// Drops any partial packet and starts searching for a header again.
    pub fn reset(&mut self) {
        self.core.reset();
    }

    /// Enables or disables unstuffing (disable only to receive a FAST SYNC READ reply).
    pub fn set_stuffing(&mut self, enabled: bool) {
        self.core.stuffing = enabled;
    }

    /// Whether the decoder is between packets (no partial packet buffered).
    pub fn is_idle(&self) -> bool {
        self.core.state == State::Preamble && self.core.pre_len == 0
    }

    /// Receive counters.
    pub fn stats(&self) -> DecoderStats {
        self.core.stats
    }
}

/// One-shot decode of the first packet in `bytes`, unstuffing the parameters into `buf`.
///
/// Leading garbage is skipped; the first complete packet or the first error is returned.
pub fn decode<'b>(bytes: &[u8], buf: &'b mut [u8]) -> Result<Packet<'b>, DecodeError> {
    let mut core = Core::new();
    for &b in bytes {
        match core.push(buf, b) {
            None => {}
            Some(Err(e)) => return Err(e),
            Some(Ok(())) => return core.packet(buf).ok_or(DecodeError::Incomplete),
        }
    }
    Err(DecodeError::Incomplete)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ping_roundtrip() {
        let mut buf = [0u8; 16];
        let n = encode(&mut buf, 1, 0x01, &[]).unwrap();
        assert_eq!(
            &buf[..n],
            &[0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x01, 0x19, 0x4E]
        );
        let mut out = [0u8; 4];
        let p = decode(&buf[..n], &mut out).unwrap();
        assert_eq!((p.id, p.instruction, p.params), (1, 1, &[][..]));
    }

    #[test]
    fn stuffing_inserts_fd() {
        let mut buf = [0u8; 32];
        let n = encode(&mut buf, 1, 0x03, &[0xFF, 0xFF, 0xFD, 0x01]).unwrap();
        assert_eq!(&buf[7..n - 2], &[0x03, 0xFF, 0xFF, 0xFD, 0xFD, 0x01]);
        assert_eq!(u16::from_le_bytes([buf[5], buf[6]]), 8);
    }

    #[test]
    fn buffer_too_small() {
        let mut buf = [0u8; 9];
        assert_eq!(
            encode(&mut buf, 1, 1, &[]),
            Err(EncodeError::BufferTooSmall)
        );
    }
}
