//! Test-only (`lib.rs` declares it under #[cfg(test)]) fake board: a virtual clock (1 Mbps byte times, a modelled compute time per tick),
//! and a scripted in-memory Dynamixel bus of fake devices built with `dxl`'s device-side
//! helpers: 12 servos that store goal positions (and reach them at once while torque is on),
//! two foot boards whose forces put the centre of pressure under the sole of every foot that
//! is on the ground (from the servos' goal positions through the leg FK), and an IMU that
//! reports a pitch rate and gravity. Faults are scripted by the number of SYNC WRITEs seen.

use std::collections::VecDeque;
use std::vec::Vec;

use dxl::table::{foot::FootForces, imu::ImuSample, x_series};
use dxl::{encode_status, Instruction, StatusError};
use gait_core::kinematics::{leg_fk, Pose};
use gait_core::{Robot, Side};

use crate::board::{
    Board, BusError, Clock, LineTime, LogSink, ServoBus, Tick, TickSchedule, TickTimer, Watchdog,
};
use crate::record::{BoardId, Record, RecordDecoder};
use walker_contract::bus_map::TickMap;

/// One instruction packet seen on the bus.
#[derive(Clone, Debug, PartialEq)]
pub struct Pkt {
    /// Board time when it was sent, µs.
    pub t_us: u64,
    /// Packet id.
    pub id: u8,
    /// Instruction.
    pub op: u8,
    /// Address (READ, WRITE, SYNC READ/WRITE), else 0.
    pub addr: u16,
    /// Data of a WRITE.
    pub data: Vec<u8>,
    /// Bytes of the instruction packet.
    pub tx_bytes: usize,
    /// Bytes of the replies it got.
    pub rx_bytes: usize,
}

/// What a fake device is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Servo of joint j.
    Servo(usize),
    /// Foot board of side 0 (left) / 1 (right).
    Foot(usize),
    /// IMU board.
    Imu,
}

/// A fake device.
#[derive(Clone, Debug)]
pub struct FakeDevice {
    /// Bus id.
    pub id: u8,
    /// Kind.
    pub kind: Kind,
    /// Return Delay Time register.
    pub rdt: u8,
    /// The RDT register ignores writes (verification test).
    pub rdt_stuck: bool,
    /// Torque Enable.
    pub torque: bool,
    /// Goal position, ticks.
    pub goal: i32,
    /// Present position, ticks.
    pub present: i32,
    /// Dead: answers nothing.
    pub dead: bool,
    /// Position I Gain register.
    pub i_gain: u16,
    /// Torque Enable ignores writes of 0 (a servo that does not let go).
    pub torque_stuck: bool,
    /// Hardware Error Status.
    pub hw_error: u8,
    /// Present Temperature, °C.
    pub temperature: u8,
    /// Present Input Voltage, 0.1 V.
    pub voltage_dv: u16,
    /// Present Current, units of 2.69 mA.
    pub current_raw: i16,
}

impl FakeDevice {
    /// A healthy device `id` of `kind` at factory settings, holding position `ticks` (servos).
    pub fn new(id: u8, kind: Kind, ticks: i32) -> Self {
        FakeDevice {
            id,
            kind,
            rdt: x_series::DEFAULT_RETURN_DELAY,
            rdt_stuck: false,
            torque: false,
            goal: ticks,
            present: ticks,
            dead: false,
            i_gain: 0,
            torque_stuck: false,
            hw_error: 0,
            temperature: 40,
            voltage_dv: 120,
            current_raw: 300,
        }
    }
}

/// Per `wait_tick`: the tick and the number of packets sent before it.
#[derive(Clone, Copy, Debug)]
pub struct TickMark {
    /// The tick returned.
    pub tick: Tick,
    /// `packets.len()` when it was returned.
    pub packets_before: usize,
}

/// The fake board.
pub struct FakeBoard {
    now_ns: u64,
    line: LineTime,
    rx: VecDeque<u8>,
    sched: TickSchedule,
    /// Modelled compute time per tick, µs.
    pub compute_us: u64,
    /// Devices on the bus.
    pub devices: Vec<FakeDevice>,
    /// Every instruction packet.
    pub packets: Vec<Pkt>,
    /// Log bytes.
    pub log: Vec<u8>,
    /// Every tick.
    pub ticks: Vec<TickMark>,
    /// Watchdog timeout once started.
    pub watchdog: Option<u32>,
    /// `packets.len()` when the watchdog was started.
    pub watchdog_at: Option<usize>,
    /// Watchdog feeds.
    pub feeds: u32,
    /// Calls of `torque_off_best_effort`.
    pub best_effort: u32,
    /// Every `servo_power` call: (on, `packets.len()` at the call).
    pub power: Vec<(bool, usize)>,
    /// What `reset_cause` reports (power-on by default).
    pub reset: (crate::board::ResetCause, u32),
    /// The no-init crash record.
    pub crash: crate::board::CrashCell,
    /// Goal positions of every SYNC WRITE.
    pub goals: Vec<[i32; 12]>,
    /// Script: device `id` dies once `n` SYNC WRITEs were seen.
    pub kill_at: Option<(u8, usize)>,
    /// Script: device `id` answers again once `n` SYNC WRITEs were seen.
    pub revive_at: Option<(u8, usize)>,
    /// Script: the IMU tilts by 1 rad once `n` SYNC WRITEs were seen.
    pub fall_at: Option<usize>,
    /// Script: the tick that made the `n`-th SYNC WRITE takes this much longer, µs.
    pub slow: Vec<(usize, u64)>,
    /// Script: board `id`'s sample counter stops advancing once `n` SYNC WRITEs were seen.
    pub freeze_at: Option<(u8, usize)>,
    /// Script: board `id` reports an out-of-range value (a byte-shifted sample) at the
    /// `n`-th SYNC WRITE only.
    pub spike_at: Option<(u8, usize)>,
    imu_counter: u16,
    foot_counters: [u16; 2],
    /// Amplitude of the IMU's 1.5 Hz pitch-rate sinusoid, rad/s.
    imu_rate_amp: f32,
}

/// Joint angles (rad) → ticks of the fake's initial pose: knees bent, hips and ankles pitched.
const INITIAL_RAD: [f32; 6] = [0.0, 0.01, -0.35, 0.7, -0.35, -0.01];

impl FakeBoard {
    /// The reference robot's bus: servos 1–12, feet 111/112, IMU 200.
    pub fn robot() -> Self {
        let mut devices = Vec::new();
        let init = Self::initial_ticks();
        for (j, &t) in init.iter().enumerate() {
            devices.push(FakeDevice::new(j as u8 + 1, Kind::Servo(j), t));
        }
        for (id, kind) in [(111, Kind::Foot(0)), (112, Kind::Foot(1)), (200, Kind::Imu)] {
            devices.push(FakeDevice::new(id, kind, 0));
        }
        FakeBoard {
            now_ns: 0,
            line: LineTime { baud: 1_000_000 },
            rx: VecDeque::new(),
            sched: TickSchedule::new(crate::Config::default().tick_period_us),
            compute_us: 150,
            devices,
            packets: Vec::new(),
            log: Vec::new(),
            ticks: Vec::new(),
            watchdog: None,
            watchdog_at: None,
            feeds: 0,
            best_effort: 0,
            power: Vec::new(),
            reset: (crate::board::ResetCause::PowerOn, 0),
            crash: crate::board::CrashCell::new(),
            goals: Vec::new(),
            kill_at: None,
            revive_at: None,
            fall_at: None,
            slow: Vec::new(),
            freeze_at: None,
            spike_at: None,
            imu_counter: 0,
            foot_counters: [0; 2],
            imu_rate_amp: 0.3,
        }
    }

    /// A bus with nothing connected.
    pub fn empty() -> Self {
        let mut b = Self::robot();
        b.devices.clear();
        b
    }

    /// Uses the tick period of `cfg`.
    pub fn with_period(mut self, period_us: u32) -> Self {
        self.sched = TickSchedule::new(period_us);
        self
    }

    /// The same with the IMU's pitch-rate sinusoid of amplitude `amp` rad/s (0: a still
    /// trunk, so τ = J·φ̈ = 0).
    pub fn with_imu_rate(mut self, amp: f32) -> Self {
        self.imu_rate_amp = amp;
        self
    }

    /// Initial present positions of the 12 servos.
    pub fn initial_ticks() -> [i32; 12] {
        let mut t = [0i32; 12];
        for (j, v) in t.iter_mut().enumerate() {
            let mirror = j >= 6 && matches!(j % 6, 0 | 1 | 5);
            let r = INITIAL_RAD[j % 6] * if mirror { -1.0 } else { 1.0 };
            *v = TickMap::reference().tick_f32(j, r);
        }
        t
    }

    /// Removes device `id` from the bus.
    pub fn remove(&mut self, id: u8) {
        self.devices.retain(|d| d.id != id);
    }

    /// Device `id`.
    pub fn device(&self, id: u8) -> Option<&FakeDevice> {
        self.devices.iter().find(|d| d.id == id)
    }

    /// Device `id`, mutable.
    pub fn device_mut(&mut self, id: u8) -> Option<&mut FakeDevice> {
        self.devices.iter_mut().find(|d| d.id == id)
    }

    /// The servos.
    pub fn servos(&self) -> impl Iterator<Item = &FakeDevice> {
        self.devices
            .iter()
            .filter(|d| matches!(d.kind, Kind::Servo(_)))
    }

    /// Every record of the log.
    pub fn records(&self) -> Vec<Record> {
        let mut d = RecordDecoder::new();
        let mut out = Vec::new();
        d.feed(&self.log, |r| out.push(r.expect("log frame")));
        out
    }

    /// Packets of opcode `op`.
    pub fn count(&self, op: u8) -> usize {
        self.packets.iter().filter(|p| p.op == op).count()
    }

    fn sync_writes(&self) -> usize {
        self.goals.len()
    }

    /// The foot forces (mN) the boards report now: the robot's weight shared by the feet on
    /// the ground, centre of pressure at each loaded sole's centre.
    pub fn foot_forces(&self) -> [[i32; 4]; 2] {
        let robot = Robot::reference();
        let pelvis = Pose::level(0.0f64, 0.0, 0.0, 0.0);
        let mut z = [0.0f64; 2];
        for (s, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let mut q = [0.0f64; 6];
            for (j, v) in q.iter_mut().enumerate() {
                let t = self
                    .device(1 + (6 * s + j) as u8)
                    .map_or(2048, |d| d.present);
                *v = TickMap::reference().rad_f64(6 * s + j, t);
            }
            z[s] = leg_fk(&robot, side, &pelvis, &q).z;
        }
        let low = z[0].min(z[1]);
        let loaded = z.map(|v| v - low < 0.002);
        let n = loaded.iter().filter(|&&l| l).count().max(1) as f64;
        let weight_mn = robot.masses.total() * robot.gravity * 1000.0;
        loaded.map(|l| {
            if l {
                [(weight_mn / n / 4.0) as i32; 4]
            } else {
                [0; 4]
            }
        })
    }

    /// True when script `s` (device, SYNC WRITE count) applies to `id` now: from then on
    /// (`once` false) or at that count only.
    fn scripted(&self, s: Option<(u8, usize)>, id: u8, once: bool) -> bool {
        s.is_some_and(|(d, n)| {
            d == id
                && if once {
                    self.sync_writes() == n
                } else {
                    self.sync_writes() >= n
                }
        })
    }

    fn imu_sample(&mut self) -> [u8; 26] {
        if !self.scripted(self.freeze_at, walker_contract::bus_map::IMU, false) {
            self.imu_counter = self.imu_counter.wrapping_add(1);
        }
        let spike = self.scripted(self.spike_at, walker_contract::bus_map::IMU, true);
        let t = self.now_ns as f32 * 1e-9;
        let rate = self.imu_rate_amp * (core::f32::consts::TAU * 1.5 * t).sin();
        let g = 9.80665f32;
        let fallen = self.fall_at.is_some_and(|n| self.sync_writes() >= n);
        let accel = if fallen {
            [-g * 1.0f32.sin(), 0.0, g * 1.0f32.cos()]
        } else {
            [0.0, 0.0, g]
        };
        let mut s = ImuSample::from_si([0.0, rate, 0.0], accel, self.imu_counter);
        if spike {
            s.gyro_urad_s[1] = i32::MAX / 2;
        }
        s.to_bytes()
    }

    fn read_mem(&mut self, i: usize, addr: u16, len: u16) -> Option<Vec<u8>> {
        let d = self.devices.get(i)?.clone();
        match (d.kind, addr, len) {
            (_, 9, 1) => Some(vec![d.rdt]),
            (Kind::Servo(_), 132, 4) => Some(d.present.to_le_bytes().to_vec()),
            (Kind::Servo(_), 116, 4) => Some(d.goal.to_le_bytes().to_vec()),
            (Kind::Servo(_), 64, 1) => Some(vec![u8::from(d.torque)]),
            (Kind::Servo(_), 82, 2) => Some(d.i_gain.to_le_bytes().to_vec()),
            (Kind::Servo(_), 70, 1) => Some(vec![d.hw_error]),
            (Kind::Servo(_), 126, 21) => {
                let mut b = vec![0u8; 21];
                b[0..2].copy_from_slice(&d.current_raw.to_le_bytes());
                b[6..10].copy_from_slice(&d.present.to_le_bytes());
                b[18..20].copy_from_slice(&d.voltage_dv.to_le_bytes());
                b[20] = d.temperature;
                Some(b)
            }
            (Kind::Foot(s), 128, 18) => {
                let counter = self.foot_counters.get_mut(s)?;
                let frozen = self
                    .freeze_at
                    .is_some_and(|(id, n)| id == d.id && self.goals.len() >= n);
                if !frozen {
                    *counter = counter.wrapping_add(1);
                }
                let counter = *counter;
                let mut forces_mn = self.foot_forces()[s];
                if self.scripted(self.spike_at, d.id, true) {
                    forces_mn[0] = forces_mn[0].wrapping_mul(256).wrapping_add(1_000_000);
                }
                let f = FootForces { forces_mn, counter };
                Some(f.to_bytes().to_vec())
            }
            (Kind::Imu, 128, 26) => Some(self.imu_sample().to_vec()),
            _ => None,
        }
    }

    fn write_mem(&mut self, i: usize, addr: u16, data: &[u8]) -> bool {
        let Some(d) = self.devices.get_mut(i) else {
            return false;
        };
        match (d.kind, addr, data) {
            (_, 9, [v]) => {
                if !d.rdt_stuck {
                    d.rdt = *v;
                }
                true
            }
            (Kind::Servo(_), 64, [v]) => {
                d.torque = *v != 0 || (d.torque && d.torque_stuck);
                if d.torque {
                    d.goal = d.present;
                }
                true
            }
            (Kind::Servo(_), 82, [a, b]) => {
                d.i_gain = u16::from_le_bytes([*a, *b]);
                true
            }
            (Kind::Servo(_), 116, [a, b, c, e]) => {
                d.goal = i32::from_le_bytes([*a, *b, *c, *e]);
                if d.torque {
                    d.present = d.goal;
                }
                true
            }
            _ => false,
        }
    }

    fn alive(&self, id: u8) -> Option<usize> {
        self.devices.iter().position(|d| d.id == id && !d.dead)
    }

    fn status(&mut self, id: u8, data: &[u8]) {
        let mut buf = [0u8; 300];
        let n = encode_status(&mut buf, id, StatusError::OK, data).unwrap();
        self.rx.extend(&buf[..n]);
    }

    fn handle(&mut self, packet: &[u8]) -> Pkt {
        let mut buf = [0u8; 512];
        let p = dxl::decode(packet, &mut buf).expect("instruction packet");
        let inst = Instruction::parse(&p).expect("instruction");
        let mut rec = Pkt {
            t_us: self.now_us(),
            id: p.id,
            op: p.instruction,
            addr: 0,
            data: Vec::new(),
            tx_bytes: packet.len(),
            rx_bytes: 0,
        };
        let bcast = p.id == dxl::BROADCAST_ID;
        match inst {
            Instruction::Ping => {
                if let Some(i) = self.alive(p.id) {
                    let model = match self.devices[i].kind {
                        Kind::Servo(_) => x_series::MODEL_XM430_W350,
                        Kind::Foot(_) => dxl::table::foot::MODEL_NUMBER_VALUE,
                        Kind::Imu => dxl::table::imu::MODEL_NUMBER_VALUE,
                    };
                    let [lo, hi] = model.to_le_bytes();
                    self.status(p.id, &[lo, hi, 48]);
                }
            }
            Instruction::Read { addr, len } => {
                rec.addr = addr;
                if let Some(i) = self.alive(p.id) {
                    if let Some(d) = self.read_mem(i, addr, len) {
                        self.status(p.id, &d);
                    }
                }
            }
            Instruction::Write { addr, data } => {
                rec.addr = addr;
                rec.data = data.to_vec();
                if bcast {
                    for i in 0..self.devices.len() {
                        if !self.devices[i].dead {
                            self.write_mem(i, addr, data);
                        }
                    }
                } else if let Some(i) = self.alive(p.id) {
                    if self.write_mem(i, addr, data) {
                        self.status(p.id, &[]);
                    }
                }
            }
            Instruction::SyncRead { addr, len, ids } => {
                rec.addr = addr;
                for &id in ids {
                    if let Some(i) = self.alive(id) {
                        if let Some(d) = self.read_mem(i, addr, len) {
                            self.status(id, &d);
                        }
                    }
                }
            }
            Instruction::SyncWrite(sw) => {
                rec.addr = sw.addr;
                let entries: Vec<(u8, Vec<u8>)> =
                    sw.entries().map(|(id, d)| (id, d.to_vec())).collect();
                for (id, d) in entries {
                    if let Some(i) = self.alive(id) {
                        self.write_mem(i, sw.addr, &d);
                    }
                }
                let mut g = [0i32; 12];
                for (j, v) in g.iter_mut().enumerate() {
                    *v = self.device(j as u8 + 1).map_or(-1, |d| d.goal);
                }
                self.goals.push(g);
                for (script, dead) in [(self.kill_at, true), (self.revive_at, false)] {
                    if let Some((id, n)) = script {
                        if self.goals.len() == n {
                            if let Some(d) = self.device_mut(id) {
                                d.dead = dead;
                            }
                        }
                    }
                }
            }
            Instruction::BulkRead(br) => {
                let reqs: Vec<_> = br.entries().collect();
                for r in reqs {
                    if let Some(i) = self.alive(r.id) {
                        if let Some(d) = self.read_mem(i, r.addr, r.len) {
                            self.status(r.id, &d);
                        }
                    }
                }
            }
            other => panic!("unexpected instruction {other:?}"),
        }
        rec.rx_bytes = self.rx.len();
        rec
    }
}

impl ServoBus for FakeBoard {
    fn send(&mut self, packet: &[u8]) -> Result<(), BusError> {
        self.rx.clear();
        self.now_ns += self.line.bytes_ns(packet.len());
        let rec = self.handle(packet);
        self.packets.push(rec);
        Ok(())
    }

    fn recv(&mut self, buf: &mut [u8], timeout_us: u32) -> Result<usize, BusError> {
        let start = self.now_ns;
        let mut n = 0;
        while n < buf.len() {
            let Some(b) = self.rx.pop_front() else { break };
            buf[n] = b;
            n += 1;
            self.now_ns += self.line.bytes_ns(1);
        }
        if n < buf.len() {
            self.now_ns = self.now_ns.max(start + u64::from(timeout_us) * 1000);
        }
        Ok(n)
    }

    fn baud(&self) -> u32 {
        self.line.baud
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), BusError> {
        self.line = LineTime { baud };
        Ok(())
    }
}

impl Clock for FakeBoard {
    fn now_us(&self) -> u64 {
        self.now_ns / 1000
    }
}

impl TickTimer for FakeBoard {
    fn period_us(&self) -> u32 {
        self.sched.period_us()
    }

    fn wait_tick(&mut self) -> Tick {
        self.now_ns += self.compute_us * 1000;
        for &(n, extra) in &self.slow {
            if n == self.goals.len() {
                self.now_ns += extra * 1000;
            }
        }
        let plan = self.sched.plan(self.now_us());
        if let Some(t) = plan.wait_until_us {
            self.now_ns = self.now_ns.max(t * 1000);
        }
        self.ticks.push(TickMark {
            tick: plan.tick,
            packets_before: self.packets.len(),
        });
        plan.tick
    }

    fn overruns(&self) -> u32 {
        self.sched.overruns()
    }
}

impl LogSink for FakeBoard {
    fn write_log(&mut self, bytes: &[u8]) {
        self.log.extend_from_slice(bytes);
    }
}

impl Watchdog for FakeBoard {
    fn start(&mut self, timeout_ms: u32) {
        self.watchdog = Some(timeout_ms);
        self.watchdog_at = Some(self.packets.len());
    }
    fn feed(&mut self) {
        self.feeds += 1;
    }
}

impl Board for FakeBoard {
    const NAME: &'static str = "fake";
    const ID: BoardId = BoardId::Unknown;

    fn torque_off_best_effort(&mut self) {
        self.best_effort += 1;
        for d in &mut self.devices {
            d.torque = false;
        }
    }

    fn servo_power(&mut self, on: bool) {
        self.power.push((on, self.packets.len()));
    }

    fn reset_cause(&self) -> (crate::board::ResetCause, u32) {
        self.reset
    }

    fn crash_cell(&mut self) -> &mut crate::board::CrashCell {
        &mut self.crash
    }

    fn exit(&mut self, code: i32) -> ! {
        panic!("exit({code}) called in a host test")
    }
}
