//! The simulated bus: instruction dispatch to the devices, status packets and fault injection.
//!
//! Replies follow Protocol 2.0: a unicast PING/READ/WRITE/REG WRITE/ACTION/REBOOT gets one
//! status packet (subject to the servo's Status Return Level); a broadcast PING is answered by
//! every device in ID order; SYNC READ / BULK READ are answered by each listed device in list
//! order; FAST SYNC READ by one combined packet (missing devices are left out of it); broadcast
//! WRITE, SYNC WRITE and BULK WRITE get no reply. An unknown instruction or a malformed one
//! addressed to a device is answered with the Instruction / Data Length error; an instruction
//! packet with a bad CRC is not answered (its ID cannot be trusted; `docs/lockstep.md`).
//!
//! Faults (deterministic from the seed, one random draw per status packet): the packet is
//! dropped with probability `p_drop`, else one of its bytes is XOR-ed with a random non-zero
//! mask with probability `p_corrupt`. Dead devices never answer nor execute.
//! Every SYNC READ / BULK READ reply is independent: a silent device does not stop the later ones.

use dxl::instruction::{encode_fast_sync_status, encode_status, opcode, FastSyncPart};
use dxl::{ErrorCode, Instruction, Packet, ParseError, StatusError, BROADCAST_ID};

use dxl::table::x_series;

use super::device::{Device, DeviceKind};
use super::rng::Rng;

/// Fault injection on the bus.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BusFaults {
    /// Probability that a status packet is not sent.
    pub p_drop: f64,
    /// Probability that one byte of a status packet is corrupted.
    pub p_corrupt: f64,
    /// IDs of devices that never answer (nor execute).
    pub dead_ids: Vec<u8>,
    /// Devices that die for a while and come back (a servo browning out).
    pub outages: Vec<Outage>,
}

/// A device dead (no answer, no motion: a servo goes limp) from `from_us` until `until_us`
/// of simulated time; a servo comes back as after a power-on, with its torque off.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outage {
    /// Bus id.
    pub id: u8,
    /// Start, µs.
    pub from_us: u64,
    /// End, µs (`None`: never comes back).
    pub until_us: Option<u64>,
}

impl Outage {
    /// Parses `ID:FROM_S[:FOR_S]` (e.g. `4:6` dead from 6 s on, `4:6:0.2` back at 6.2 s).
    pub fn parse(s: &str) -> Result<Self, String> {
        let bad = || format!("{s}: expected ID:FROM_S[:FOR_S], e.g. 4:6:0.2");
        let parts: Vec<&str> = s.split(':').collect();
        let secs = |t: &str| -> Result<u64, String> {
            let v: f64 = t.parse().map_err(|_| bad())?;
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad());
            }
            Ok((v * 1e6).round() as u64)
        };
        match parts.as_slice() {
            [id, from] | [id, from, _] => {
                let id: u8 = id.parse().map_err(|_| bad())?;
                let from_us = secs(from)?;
                let until_us = match parts.get(2) {
                    Some(d) => Some(from_us + secs(d)?),
                    None => None,
                };
                Ok(Outage {
                    id,
                    from_us,
                    until_us,
                })
            }
            _ => Err(bad()),
        }
    }

    /// Dead at `t_us`.
    pub fn dead_at(&self, t_us: u64) -> bool {
        t_us >= self.from_us && self.until_us.is_none_or(|u| t_us < u)
    }
}

/// Bus counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BusCounters {
    /// Instruction packets handled (including ones with a bad CRC).
    pub instructions: u64,
    /// Status packets sent (corrupted ones included, dropped ones not).
    pub status_sent: u64,
    /// Status packets dropped by fault injection.
    pub dropped: u64,
    /// Status packets corrupted by fault injection.
    pub corrupted: u64,
    /// Instruction packets received with a bad CRC.
    pub crc_errors: u64,
    /// Packets that could not be parsed as instructions.
    pub malformed: u64,
    /// Bytes written on the bus.
    pub bytes_out: u64,
}

/// An instruction packet copied out of the decoder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OwnedPacket {
    /// Packet ID.
    pub id: u8,
    /// Instruction byte.
    pub instruction: u8,
    /// Unstuffed parameters.
    pub params: Vec<u8>,
}

impl OwnedPacket {
    /// Copies a decoded packet.
    pub fn from_packet(p: &Packet<'_>) -> Self {
        OwnedPacket {
            id: p.id,
            instruction: p.instruction,
            params: p.params.to_vec(),
        }
    }

    /// Borrows it as a `dxl` packet.
    pub fn packet(&self) -> Packet<'_> {
        Packet {
            id: self.id,
            instruction: self.instruction,
            params: &self.params,
        }
    }
}

/// The devices on the bus plus the fault injector.
#[derive(Clone, Debug)]
pub struct DeviceBus {
    /// Devices, in ascending ID order at construction.
    pub devices: Vec<Device>,
    faults: BusFaults,
    rng: Rng,
    /// Counters.
    pub counters: BusCounters,
}

fn err(code: ErrorCode) -> StatusError {
    StatusError {
        alert: false,
        code: Some(code),
    }
}

impl DeviceBus {
    /// A bus with these devices; `rng` drives the fault injection.
    pub fn new(devices: Vec<Device>, faults: BusFaults, rng: Rng) -> Self {
        let mut bus = DeviceBus {
            devices,
            faults,
            rng,
            counters: BusCounters::default(),
        };
        for d in &mut bus.devices {
            d.dead = bus.faults.dead_ids.contains(&d.id);
        }
        bus
    }

    /// The outages at simulated time `t_us`: a device dies at its outage's start; a servo that
    /// comes back has its Torque Enable at 0 (its RAM area after a power-on).
    pub fn apply_outages(&mut self, t_us: u64) {
        for o in &self.faults.outages {
            let dead = o.dead_at(t_us) || self.faults.dead_ids.contains(&o.id);
            if let Some(d) = self.devices.iter_mut().find(|d| d.id == o.id) {
                if d.dead && !dead && matches!(d.kind, DeviceKind::Servo { .. }) {
                    d.set(x_series::TORQUE_ENABLE, &[0]);
                }
                d.dead = dead;
            }
        }
    }

    /// Index of the live device with `id`.
    pub fn find(&self, id: u8) -> Option<usize> {
        self.devices.iter().position(|d| d.id == id && !d.dead)
    }

    /// Device with `id` (dead or alive).
    pub fn device(&self, id: u8) -> Option<&Device> {
        self.devices.iter().find(|d| d.id == id)
    }

    /// Appends one status packet to `out`, through the fault injector.
    fn emit(&mut self, out: &mut Vec<u8>, id: u8, error: StatusError, data: &[u8]) {
        let mut buf = vec![0u8; data.len() * 2 + 16];
        if let Ok(n) = encode_status(&mut buf, id, error, data) {
            buf.truncate(n);
            self.emit_raw(out, buf);
        }
    }

    fn emit_raw(&mut self, out: &mut Vec<u8>, mut pkt: Vec<u8>) {
        let u = self.rng.uniform();
        if u < self.faults.p_drop {
            self.counters.dropped += 1;
            return;
        }
        if u < self.faults.p_drop + self.faults.p_corrupt && !pkt.is_empty() {
            let i = self.rng.below(pkt.len() as u64) as usize;
            let mask = 1 + self.rng.below(255) as u8;
            pkt[i] ^= mask;
            self.counters.corrupted += 1;
        }
        self.counters.status_sent += 1;
        out.extend_from_slice(&pkt);
    }

    /// Whether device `i` answers an instruction of this class.
    fn replies(&self, i: usize, is_read: bool, is_ping: bool) -> bool {
        let srl = self.devices[i].status_return_level();
        is_ping || srl >= 2 || (srl >= 1 && is_read)
    }

    /// An instruction packet with a bad CRC, with the (untrusted) ID field `id`: counted, not
    /// answered (the lock-step acknowledgement announces 0 bytes).
    pub fn handle_crc_error(&mut self, id: u8) -> Vec<u8> {
        self.counters.instructions += 1;
        self.counters.crc_errors += 1;
        let _ = id;
        Vec::new()
    }

    /// Executes one packet; returns the reply bytes, or `None` for a non-instruction packet
    /// (a status packet on the bus).
    pub fn handle(&mut self, p: &Packet<'_>) -> Option<Vec<u8>> {
        if p.instruction == opcode::STATUS {
            return None;
        }
        self.counters.instructions += 1;
        let mut out = Vec::new();
        match Instruction::parse(p) {
            Ok(inst) => self.execute(p.id, &inst, &mut out),
            Err(e) => {
                self.counters.malformed += 1;
                if let Some(i) = self.find(p.id) {
                    let code = match e {
                        ParseError::UnknownInstruction(_) | ParseError::NotStatus => {
                            ErrorCode::Instruction
                        }
                        ParseError::BadLength => ErrorCode::DataLength,
                    };
                    if self.replies(i, false, false) {
                        self.emit(&mut out, p.id, err(code), &[]);
                    }
                }
            }
        }
        self.counters.bytes_out += out.len() as u64;
        Some(out)
    }

    fn read_reply(&mut self, out: &mut Vec<u8>, i: usize, addr: u16, len: u16) {
        let id = self.devices[i].id;
        if !self.replies(i, true, false) {
            return;
        }
        match self.devices[i].read(addr, len) {
            Ok(data) => {
                let data = data.to_vec();
                self.emit(out, id, StatusError::OK, &data);
            }
            Err(code) => self.emit(out, id, err(code), &[]),
        }
    }

    fn execute(&mut self, pid: u8, inst: &Instruction<'_>, out: &mut Vec<u8>) {
        let unicast = self.find(pid);
        let targets: Vec<usize> = if pid == BROADCAST_ID {
            (0..self.devices.len())
                .filter(|&i| !self.devices[i].dead)
                .collect()
        } else {
            unicast.into_iter().collect()
        };
        match *inst {
            Instruction::Ping => {
                for i in targets {
                    let (id, data) = (self.devices[i].id, self.devices[i].ping_data());
                    self.emit(out, id, StatusError::OK, &data);
                }
            }
            Instruction::Read { addr, len } => {
                if let Some(i) = unicast {
                    self.read_reply(out, i, addr, len);
                }
            }
            Instruction::Write { addr, data } | Instruction::RegWrite { addr, data } => {
                let reg = matches!(inst, Instruction::RegWrite { .. });
                for i in targets {
                    let r = if reg {
                        self.devices[i].pending = Some((addr, data.to_vec()));
                        Ok(())
                    } else {
                        self.devices[i].write(addr, data)
                    };
                    if pid != BROADCAST_ID && self.replies(i, false, false) {
                        let id = self.devices[i].id;
                        let e = r.err().map_or(StatusError::OK, err);
                        self.emit(out, id, e, &[]);
                    }
                }
            }
            Instruction::Action => {
                for i in targets {
                    let r = match self.devices[i].pending.take() {
                        Some((addr, data)) => self.devices[i].write(addr, &data),
                        None => Err(ErrorCode::Instruction),
                    };
                    if pid != BROADCAST_ID && self.replies(i, false, false) {
                        let id = self.devices[i].id;
                        self.emit(out, id, r.err().map_or(StatusError::OK, err), &[]);
                    }
                }
            }
            Instruction::Reboot => {
                for i in targets {
                    self.devices[i].reboot();
                    if pid != BROADCAST_ID && self.replies(i, false, false) {
                        let id = self.devices[i].id;
                        self.emit(out, id, StatusError::OK, &[]);
                    }
                }
            }
            Instruction::SyncRead { addr, len, ids } => {
                if pid == BROADCAST_ID {
                    for &id in ids {
                        if let Some(i) = self.find(id) {
                            self.read_reply(out, i, addr, len);
                        }
                    }
                }
            }
            Instruction::FastSyncRead { addr, len, ids } => {
                if pid == BROADCAST_ID {
                    self.fast_sync_read(out, addr, len, ids);
                }
            }
            Instruction::SyncWrite(sw) => {
                if pid == BROADCAST_ID {
                    for (id, data) in sw.entries() {
                        if let Some(i) = self.find(id) {
                            let _ = self.devices[i].write(sw.addr, data);
                        }
                    }
                }
            }
            Instruction::BulkRead(br) => {
                if pid == BROADCAST_ID {
                    for r in br.entries() {
                        if let Some(i) = self.find(r.id) {
                            self.read_reply(out, i, r.addr, r.len);
                        }
                    }
                }
            }
            Instruction::BulkWrite(bw) => {
                if pid == BROADCAST_ID {
                    for e in bw.entries() {
                        if let Some(i) = self.find(e.id) {
                            let _ = self.devices[i].write(e.addr, e.data);
                        }
                    }
                }
            }
        }
    }

    fn fast_sync_read(&mut self, out: &mut Vec<u8>, addr: u16, len: u16, ids: &[u8]) {
        let zeros = vec![0u8; usize::from(len)];
        let mut owned: Vec<(u8, StatusError, Vec<u8>)> = Vec::new();
        for &id in ids {
            let Some(i) = self.find(id) else { continue };
            if !self.replies(i, true, false) {
                continue;
            }
            match self.devices[i].read(addr, len) {
                Ok(d) => owned.push((id, StatusError::OK, d.to_vec())),
                Err(c) => owned.push((id, err(c), zeros.clone())),
            }
        }
        if owned.is_empty() {
            return;
        }
        let parts: Vec<FastSyncPart<'_>> = owned
            .iter()
            .map(|(id, e, d)| FastSyncPart {
                id: *id,
                error: *e,
                data: d,
                crc_ok: true,
            })
            .collect();
        let mut buf = vec![0u8; parts.len() * (usize::from(len) + 4) + 16];
        if let Ok(n) = encode_fast_sync_status(&mut buf, len, &parts) {
            buf.truncate(n);
            self.emit_raw(out, buf);
        }
    }
}
