//! The one fake robot (feature `fake-robot`, always in the host unit tests): a [`Board`] whose
//! Dynamixel bus is a set of emulated devices, for the host unit tests, the on-target
//! benchmark (`src/bin/bench.rs`) and any on-target test. `no_std`, heapless, no allocation.
//!
//! * A virtual clock: the line time of every byte at the bus baud rate, a modelled compute
//!   time per tick ([`FakeRobot::compute_ns`]), and the tick deadlines of a [`TickSchedule`].
//! * The reference robot's bus ([`FakeRobot::reference`]): 12 servos that store their registers
//!   (Return Delay Time 9, Torque Enable 64, Hardware Error Status 70, Position I Gain 82, Goal
//!   Position 116, Present Position 132, the monitor block 126..146) and reach a goal at once
//!   while torque is on; two foot boards and an IMU whose sample counters advance on every read.
//! * Sensor models: [`Feet::Standing`] puts the robot's weight under the sole of every foot on
//!   the ground (the lowest soles from the servos' present positions through the leg FK), equal
//!   on the four cells; [`Feet::Constant`] reports fixed forces. [`ImuMotion::Sinusoid`] is a
//!   1.5 Hz pitch-rate sinusoid `ω_y = A sin(2π·1.5·t)` with gravity on z;
//!   [`ImuMotion::Alternating`] a pitch rate that alternates between two values, read by read.
//! * Fault options: missing devices ([`FakeRobot::remove`], [`FakeRobot::unconnected`]), a device
//!   register that ignores writes ([`FakeDevice::rdt_stuck`], [`FakeDevice::torque_stuck`]), and
//!   scripts keyed on the number of SYNC WRITEs seen: a device dies or answers again, the trunk
//!   tilts by 1 rad, a tick is slow, a sensor's counter freezes, a sample spikes.
//!
//! What surrounds the robot is an [`Observer`]: it sees every packet, SYNC WRITE, tick, log
//! write and servo-power switch, is told when the board's own code starts and ends (the bench
//! meters the firmware's work between them), and ends the run ([`Board::exit`]). The host tests'
//! observer keeps everything in vectors ([`trace::Trace`], test builds only); the robot's
//! fields and the observer's read alike (`b.packets`, `b.goals`) through `Deref`.

use core::ops::{Deref, DerefMut};

use dxl::table::{foot, foot::FootForces, imu, imu::ImuSample, x_series};
use dxl::{encode_status, Instruction, StatusError};
use gait_core::kinematics::leg::{leg_fk, Pose};
use gait_core::robot::ImuAxes;
use gait_core::{Robot, Side};
use walker_contract::bus_map::{self, TickMap};

use crate::board::{
    Board, BusError, Clock, CrashCell, LineTime, LogSink, ResetCause, ServoBus, Tick, TickSchedule,
    TickTimer, Watchdog,
};
use crate::record::BoardId;

/// Devices on the fake bus at most.
pub const MAX_DEVICES: usize = 16;
/// Bytes of replies queued for one instruction at most (a SYNC READ of 12 monitor blocks).
pub const RX_CAPACITY: usize = 1024;
/// Slow-tick scripts at most.
pub const MAX_SLOW: usize = 8;
/// Bytes of one device's reply data at most.
const MAX_REPLY_DATA: usize = 32;

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
    /// Present Current READs still to answer `current_spike_raw` instead of `current_raw`.
    pub current_spikes: u8,
    /// Present Current of a spike, units of 2.69 mA.
    pub current_spike_raw: i16,
    /// Deflection under load, ticks: with torque on the servo stands at goal − `sag`.
    pub sag: i32,
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
            current_spikes: 0,
            current_spike_raw: 0,
            sag: 0,
        }
    }
}

/// What the foot boards report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Feet {
    /// The robot's weight shared by the feet on the ground (see the module doc).
    Standing,
    /// Fixed forces, mN: `[left, right]`, four cells each.
    Constant([[i32; 4]; 2]),
}

/// What the IMU reports as the trunk's pitch rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ImuMotion {
    /// `amp · sin(2π·1.5 Hz·t)`, rad/s (0: a still trunk, so τ = J·φ̈ = 0).
    Sinusoid {
        /// Amplitude, rad/s.
        amp: f32,
    },
    /// A push: `rate` rad/s from `from_us` until `until_us` (robot clock), 0 otherwise.
    Tip {
        /// Pitch rate while tipping, rad/s.
        rate: f32,
        /// Start, µs.
        from_us: u64,
        /// End, µs.
        until_us: u64,
    },
    /// `even` on reads with an even sample counter, `odd` on the others, rad/s.
    Alternating {
        /// Rate at even counters, rad/s.
        even: f32,
        /// Rate at odd counters, rad/s.
        odd: f32,
    },
}

/// One instruction packet as the fake bus saw it.
#[derive(Clone, Copy, Debug)]
pub struct PacketSeen<'a> {
    /// Board time when it was sent, µs.
    pub t_us: u64,
    /// Packet id.
    pub id: u8,
    /// Instruction.
    pub op: u8,
    /// Address (READ, WRITE, SYNC READ/WRITE), else 0.
    pub addr: u16,
    /// Data of a WRITE, else empty.
    pub data: &'a [u8],
    /// Bytes of the instruction packet.
    pub tx_bytes: usize,
    /// Bytes of the replies it got.
    pub rx_bytes: usize,
}

/// What surrounds the fake robot: it sees what happens on the board and ends the run.
pub trait Observer {
    /// An instruction packet was handled.
    fn packet(&mut self, _seen: &PacketSeen<'_>) {}
    /// A SYNC WRITE was handled; the 12 servos' goal positions after it (-1: no such servo).
    fn sync_write(&mut self, _goals: &[i32; 12]) {}
    /// `wait_tick` was entered (the firmware's work of the tick is over).
    fn tick_start(&mut self) {}
    /// `wait_tick` returns `tick`.
    fn tick(&mut self, _tick: Tick) {}
    /// Log bytes were written.
    fn log(&mut self, _bytes: &[u8]) {}
    /// `servo_power(on)` was called.
    fn power(&mut self, _on: bool) {}
    /// The board's own code (bus emulation, log sink) starts.
    fn enter(&mut self) {}
    /// The board's own code ends.
    fn leave(&mut self) {}
    /// The control tick enters `stage`.
    fn stage(&mut self, _stage: crate::board::Stage) {}
    /// The firmware exits with `code`.
    fn exit(&mut self, code: i32) -> !;
}

/// The fake robot: board, bus and devices (module doc); `O` observes it.
pub struct FakeRobot<O> {
    now_ns: u64,
    /// `now_ns / 1000`, kept so that reading the clock costs no division.
    now_us: u64,
    line: LineTime,
    rx: heapless::Deque<u8, RX_CAPACITY>,
    sched: TickSchedule,
    /// Modelled compute time per tick, ns.
    pub compute_ns: u64,
    /// Devices on the bus.
    pub devices: heapless::Vec<FakeDevice, MAX_DEVICES>,
    /// What the foot boards report.
    pub feet: Feet,
    /// What the IMU reports.
    pub imu_motion: ImuMotion,
    /// Instruction packets seen.
    pub packets_seen: usize,
    /// SYNC WRITEs seen.
    pub sync_writes: usize,
    /// Watchdog timeout once started.
    pub watchdog: Option<u32>,
    /// Packets seen when the watchdog was started.
    pub watchdog_at: Option<usize>,
    /// Watchdog feeds.
    pub feeds: u32,
    /// Calls of `torque_off_best_effort`.
    pub best_effort: u32,
    /// What `reset_cause` reports (power-on by default).
    pub reset: (ResetCause, u32),
    /// The no-init crash record.
    pub crash: CrashCell,
    /// Script: device `id` dies once `n` SYNC WRITEs were seen.
    pub kill_at: Option<(u8, usize)>,
    /// Script: device `id` answers again once `n` SYNC WRITEs were seen (a servo with its
    /// torque off, as after a brown-out).
    pub revive_at: Option<(u8, usize)>,
    /// Script: the IMU tilts by 1 rad once `n` SYNC WRITEs were seen.
    pub fall_at: Option<usize>,
    /// Script: the operator button reads high during these spans of board time, µs (from,
    /// until; low otherwise); `None`: no button.
    pub button_us: Option<[(u64, u64); 2]>,
    /// Script: the tick that made the `n`-th SYNC WRITE takes this much longer, µs.
    pub slow: heapless::Vec<(usize, u64), MAX_SLOW>,
    /// Script: board `id`'s sample counter stops advancing once `n` SYNC WRITEs were seen.
    pub freeze_at: Option<(u8, usize)>,
    /// Script: board `id` reports an out-of-range value (a byte-shifted sample) at the
    /// `n`-th SYNC WRITE only.
    pub spike_at: Option<(u8, usize)>,
    /// The controller board's IMU, for a robot whose IMU is on the board: the same motion as
    /// the bus IMU's, in the chip's axes turned so in the trunk ((I2) of [`ImuAxes`]), and
    /// whether its start fails. `None`: the board has none.
    pub board_imu: Option<(ImuAxes, bool)>,
    imu_counter: u16,
    foot_counters: [u16; 2],
    /// The observer.
    pub observer: O,
}

/// Joint angles (rad) → ticks of the fake's initial pose: knees bent, hips and ankles pitched.
const INITIAL_RAD: [f32; 6] = [0.0, 0.01, -0.35, 0.7, -0.35, -0.01];

impl<O: Observer> FakeRobot<O> {
    /// The reference robot's bus (servos 1–12 at the initial pose, feet 111/112, IMU 200) at
    /// 1 Mbps, the default tick period, 150 µs of compute per tick, standing feet and a
    /// 0.3 rad/s pitch-rate sinusoid.
    pub fn reference(observer: O) -> Self {
        let mut devices = heapless::Vec::new();
        let init = Self::initial_ticks();
        for (&id, j) in bus_map::DEVICE_IDS.iter().zip(0usize..) {
            let kind = match id {
                bus_map::FOOT_LEFT => Kind::Foot(0),
                bus_map::FOOT_RIGHT => Kind::Foot(1),
                bus_map::IMU => Kind::Imu,
                _ => Kind::Servo(j),
            };
            let ticks = init.get(j).copied().unwrap_or(0);
            // Cannot fail: the bus map has fewer than MAX_DEVICES devices.
            let _ = devices.push(FakeDevice::new(id, kind, ticks));
        }
        FakeRobot {
            now_ns: 0,
            now_us: 0,
            line: LineTime { baud: 1_000_000 },
            rx: heapless::Deque::new(),
            sched: TickSchedule::new(crate::Config::default_config().tick_period_us),
            compute_ns: 150_000,
            devices,
            feet: Feet::Standing,
            imu_motion: ImuMotion::Sinusoid { amp: 0.3 },
            packets_seen: 0,
            sync_writes: 0,
            watchdog: None,
            watchdog_at: None,
            feeds: 0,
            best_effort: 0,
            reset: (ResetCause::PowerOn, 0),
            crash: CrashCell::new(),
            kill_at: None,
            revive_at: None,
            fall_at: None,
            button_us: None,
            slow: heapless::Vec::new(),
            freeze_at: None,
            spike_at: None,
            board_imu: None,
            imu_counter: 0,
            foot_counters: [0; 2],
            observer,
        }
    }

    /// A bus with nothing connected.
    pub fn unconnected(observer: O) -> Self {
        let mut b = Self::reference(observer);
        b.devices.clear();
        b
    }

    /// The same with tick period `period_us`.
    pub fn with_period(mut self, period_us: u32) -> Self {
        self.sched = TickSchedule::new(period_us);
        self
    }

    /// The same with the IMU's pitch-rate sinusoid of amplitude `amp` rad/s (0: a still
    /// trunk, so τ = J·φ̈ = 0).
    pub fn with_imu_rate(mut self, amp: f32) -> Self {
        self.imu_motion = ImuMotion::Sinusoid { amp };
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

    /// The same with the IMU on the board instead of the bus: the bus IMU gone, the board's
    /// chip turned in the trunk as `axes` say.
    pub fn with_board_imu(mut self, axes: ImuAxes) -> Self {
        self.remove(bus_map::IMU);
        self.board_imu = Some((axes, false));
        self
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

    /// The foot forces (mN) the boards report now (see [`Feet`]).
    pub fn foot_forces(&self) -> [[i32; 4]; 2] {
        match self.feet {
            Feet::Constant(f) => f,
            Feet::Standing => self.standing_forces(),
        }
    }

    /// [`Feet::Standing`]: the robot's weight shared by the feet on the ground, centre of
    /// pressure at each loaded sole's centre.
    fn standing_forces(&self) -> [[i32; 4]; 2] {
        let robot = Robot::reference();
        let pelvis = Pose::level(0.0f64, 0.0, 0.0, 0.0);
        let mut z = [0.0f64; 2];
        for (s, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let mut q = [0.0f64; 6];
            for (j, v) in q.iter_mut().enumerate() {
                let t = self
                    .device(1 + (6 * s + j) as u8)
                    .map_or(x_series::CENTER_TICK, |d| d.present);
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

    fn advance(&mut self, ns: u64) {
        self.now_ns = self.now_ns.saturating_add(ns);
        self.now_us = self.now_ns / 1000;
    }

    /// True when script `s` (device, SYNC WRITE count) applies to `id` now: from then on
    /// (`once` false) or at that count only.
    fn scripted(&self, s: Option<(u8, usize)>, id: u8, once: bool) -> bool {
        s.is_some_and(|(d, n)| {
            d == id
                && if once {
                    self.sync_writes == n
                } else {
                    self.sync_writes >= n
                }
        })
    }

    fn imu_bytes(&mut self) -> [u8; 26] {
        if !self.scripted(self.freeze_at, bus_map::IMU, false) {
            self.imu_counter = self.imu_counter.wrapping_add(1);
        }
        let spike = self.scripted(self.spike_at, bus_map::IMU, true);
        let rate = match self.imu_motion {
            ImuMotion::Sinusoid { amp } => {
                let t = self.now_ns as f32 * 1e-9;
                amp * libm::sinf(core::f32::consts::TAU * 1.5 * t)
            }
            ImuMotion::Tip {
                rate,
                from_us,
                until_us,
            } => {
                if (from_us..until_us).contains(&self.now_us) {
                    rate
                } else {
                    0.0
                }
            }
            ImuMotion::Alternating { even, odd } => {
                if self.imu_counter.is_multiple_of(2) {
                    even
                } else {
                    odd
                }
            }
        };
        let g = 9.80665f32;
        let fallen = self.fall_at.is_some_and(|n| self.sync_writes >= n);
        let accel = if fallen {
            [-g * libm::sinf(1.0), 0.0, g * libm::cosf(1.0)]
        } else {
            [0.0, 0.0, g]
        };
        let mut s = ImuSample::from_si([0.0, rate, 0.0], accel, self.imu_counter);
        if spike {
            s.gyro_urad_s[1] = i32::MAX / 2;
        }
        s.to_bytes()
    }

    fn foot_sample(&mut self, side: usize, id: u8) -> Option<[u8; 18]> {
        let frozen = self.scripted(self.freeze_at, id, false);
        let spike = self.scripted(self.spike_at, id, true);
        let mut forces_mn = *self.foot_forces().get(side)?;
        let counter = self.foot_counters.get_mut(side)?;
        if !frozen {
            *counter = counter.wrapping_add(1);
        }
        if spike {
            forces_mn[0] = forces_mn[0].wrapping_mul(256).wrapping_add(1_000_000);
        }
        let counter = *counter;
        Some(FootForces { forces_mn, counter }.to_bytes())
    }

    /// Reads `len` bytes at `addr` of device `i` into `out`; their number, None when the
    /// device has no such register block.
    fn read_mem(
        &mut self,
        i: usize,
        addr: u16,
        len: u16,
        out: &mut [u8; MAX_REPLY_DATA],
    ) -> Option<usize> {
        let d = self.devices.get(i)?.clone();
        let mut put = |b: &[u8]| {
            out.get_mut(..b.len())?.copy_from_slice(b);
            Some(b.len())
        };
        match (d.kind, addr, len) {
            (_, 9, 1) => put(&[d.rdt]),
            (Kind::Servo(_), 132, 4) => put(&d.present.to_le_bytes()),
            (Kind::Servo(_), 116, 4) => put(&d.goal.to_le_bytes()),
            (Kind::Servo(_), 64, 1) => put(&[u8::from(d.torque)]),
            // The servo monitor's status READ: Torque Enable .. Hardware Error Status (LED 0,
            // Status Return Level 2).
            (Kind::Servo(_), 64, 7) => put(&[u8::from(d.torque), 0, 0, 0, 2, 0, d.hw_error]),
            (Kind::Servo(_), 82, 2) => put(&d.i_gain.to_le_bytes()),
            (Kind::Servo(_), 70, 1) => put(&[d.hw_error]),
            (Kind::Servo(_), 126, 2) if d.current_spikes > 0 => {
                let dev = self.devices.get_mut(i)?;
                dev.current_spikes -= 1;
                put(&d.current_spike_raw.to_le_bytes())
            }
            (Kind::Servo(_), 126, 2) => put(&d.current_raw.to_le_bytes()),
            (Kind::Servo(_), 144, 3) => {
                let [lo, hi] = d.voltage_dv.to_le_bytes();
                put(&[lo, hi, d.temperature])
            }
            (Kind::Foot(s), 128, 18) => {
                let b = self.foot_sample(s, d.id)?;
                out.get_mut(..b.len())?.copy_from_slice(&b);
                Some(b.len())
            }
            (Kind::Imu, 128, 26) => {
                let b = self.imu_bytes();
                out.get_mut(..b.len())?.copy_from_slice(&b);
                Some(b.len())
            }
            _ => None,
        }
    }

    /// Writes `data` at `addr` of device `i`; false when it has no such register.
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
            // Profile Velocity: accepted; the fake's servos reach their goal at once.
            (Kind::Servo(_), 112, [_, _, _, _]) => true,
            (Kind::Servo(_), 116, [a, b, c, e]) => {
                d.goal = i32::from_le_bytes([*a, *b, *c, *e]);
                if d.torque {
                    d.present = d.goal.saturating_sub(d.sag);
                }
                true
            }
            _ => false,
        }
    }

    fn alive(&self, id: u8) -> Option<usize> {
        self.devices.iter().position(|d| d.id == id && !d.dead)
    }

    /// Queues device `id`'s status packet with `data`; its alert bit set while the device has
    /// a hardware error latched (as X-series servos do).
    fn status(&mut self, id: u8, data: &[u8]) {
        let mut buf = [0u8; MAX_REPLY_DATA + 16];
        let alert = self.devices.iter().any(|d| d.id == id && d.hw_error != 0);
        let error = StatusError {
            alert,
            ..StatusError::OK
        };
        if let Ok(n) = encode_status(&mut buf, id, error, data) {
            for &b in buf.get(..n).unwrap_or(&[]) {
                let _ = self.rx.push_back(b);
            }
        }
    }

    /// Device `i`'s reply to a read of `len` bytes at `addr`, when it has that block.
    fn reply_read(&mut self, i: usize, id: u8, addr: u16, len: u16) {
        let mut data = [0u8; MAX_REPLY_DATA];
        if let Some(n) = self.read_mem(i, addr, len, &mut data) {
            self.status(id, data.get(..n).unwrap_or(&[]));
        }
    }

    /// Answers one instruction packet (malformed packets and other instructions: no reply).
    fn handle(&mut self, packet: &[u8]) {
        let mut buf = [0u8; 512];
        let Ok(p) = dxl::decode(packet, &mut buf) else {
            return;
        };
        let Ok(inst) = Instruction::parse(&p) else {
            return;
        };
        let mut addr = 0;
        let mut data: &[u8] = &[];
        match inst {
            Instruction::Ping => {
                if let Some(kind) = self.alive(p.id).and_then(|i| self.devices.get(i)) {
                    let model = match kind.kind {
                        Kind::Servo(_) => x_series::MODEL_XM430_W350,
                        Kind::Foot(_) => foot::MODEL_NUMBER_VALUE,
                        Kind::Imu => imu::MODEL_NUMBER_VALUE,
                    };
                    let [lo, hi] = model.to_le_bytes();
                    self.status(p.id, &[lo, hi, 48]);
                }
            }
            Instruction::Read { addr: a, len } => {
                addr = a;
                if let Some(i) = self.alive(p.id) {
                    self.reply_read(i, p.id, a, len);
                }
            }
            Instruction::Write { addr: a, data: w } => {
                (addr, data) = (a, w);
                if p.id == dxl::BROADCAST_ID {
                    for i in 0..self.devices.len() {
                        if self.devices.get(i).is_some_and(|d| !d.dead) {
                            self.write_mem(i, a, w);
                        }
                    }
                } else if let Some(i) = self.alive(p.id) {
                    if self.write_mem(i, a, w) {
                        self.status(p.id, &[]);
                    }
                }
            }
            Instruction::SyncRead { addr: a, len, ids } => {
                addr = a;
                for &id in ids {
                    if let Some(i) = self.alive(id) {
                        self.reply_read(i, id, a, len);
                    }
                }
            }
            Instruction::SyncWrite(sw) => {
                addr = sw.addr;
                for (id, d) in sw.entries() {
                    if let Some(i) = self.alive(id) {
                        self.write_mem(i, sw.addr, d);
                    }
                }
                self.after_sync_write();
            }
            Instruction::BulkRead(br) => {
                for r in br.entries() {
                    if let Some(i) = self.alive(r.id) {
                        self.reply_read(i, r.id, r.addr, r.len);
                    }
                }
            }
            _ => {}
        }
        let seen = PacketSeen {
            t_us: self.now_us,
            id: p.id,
            op: p.instruction,
            addr,
            data,
            tx_bytes: packet.len(),
            rx_bytes: self.rx.len(),
        };
        self.observer.packet(&seen);
    }

    /// Counts a SYNC WRITE, tells the observer the goals, runs the kill/revive scripts.
    fn after_sync_write(&mut self) {
        self.sync_writes += 1;
        let mut g = [0i32; 12];
        for (j, v) in g.iter_mut().enumerate() {
            *v = self.device(j as u8 + 1).map_or(-1, |d| d.goal);
        }
        self.observer.sync_write(&g);
        for (script, dead) in [(self.kill_at, true), (self.revive_at, false)] {
            if let Some((id, n)) = script {
                if self.sync_writes == n {
                    if let Some(d) = self.device_mut(id) {
                        d.dead = dead;
                        // A servo that comes back has been through a power-on: torque off.
                        if !dead && matches!(d.kind, Kind::Servo(_)) {
                            d.torque = false;
                        }
                    }
                }
            }
        }
    }
}

impl<O> Deref for FakeRobot<O> {
    type Target = O;
    fn deref(&self) -> &O {
        &self.observer
    }
}

impl<O> DerefMut for FakeRobot<O> {
    fn deref_mut(&mut self) -> &mut O {
        &mut self.observer
    }
}

impl<O: Observer> ServoBus for FakeRobot<O> {
    fn send(&mut self, packet: &[u8]) -> Result<(), BusError> {
        self.observer.enter();
        self.rx.clear();
        self.advance(self.line.bytes_ns(packet.len()));
        self.handle(packet);
        self.packets_seen += 1;
        self.observer.leave();
        Ok(())
    }

    fn recv(&mut self, buf: &mut [u8], timeout_us: u32) -> Result<usize, BusError> {
        self.observer.enter();
        let start = self.now_ns;
        let mut n = 0;
        for slot in buf.iter_mut() {
            let Some(b) = self.rx.pop_front() else { break };
            *slot = b;
            n += 1;
        }
        if n > 0 {
            self.advance(self.line.bytes_ns(n));
        }
        if n < buf.len() {
            let t = self
                .now_ns
                .max(start.saturating_add(u64::from(timeout_us) * 1000));
            self.advance(t - self.now_ns);
        }
        self.observer.leave();
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

impl<O> Clock for FakeRobot<O> {
    fn now_us(&self) -> u64 {
        self.now_us
    }
}

impl<O: Observer> TickTimer for FakeRobot<O> {
    fn period_us(&self) -> u32 {
        self.sched.period_us()
    }

    fn wait_tick(&mut self) -> Tick {
        self.observer.tick_start();
        let mut compute = self.compute_ns;
        for &(n, extra_us) in &self.slow {
            if n == self.sync_writes {
                compute = compute.saturating_add(extra_us * 1000);
            }
        }
        self.advance(compute);
        let plan = self.sched.plan(self.now_us);
        if let Some(w) = plan.wait_until_us {
            let target = self.now_ns.max(w * 1000);
            self.advance(target - self.now_ns);
        }
        self.observer.tick(plan.tick);
        plan.tick
    }

    fn overruns(&self) -> u32 {
        self.sched.overruns()
    }
}

impl<O: Observer> LogSink for FakeRobot<O> {
    fn write_log(&mut self, bytes: &[u8]) {
        self.observer.enter();
        self.observer.log(bytes);
        self.observer.leave();
    }
}

impl<O: Observer> Watchdog for FakeRobot<O> {
    fn start(&mut self, timeout_ms: u32) {
        self.watchdog = Some(timeout_ms);
        self.watchdog_at = Some(self.packets_seen);
    }
    fn feed(&mut self) {
        self.feeds += 1;
    }
}

impl<O: Observer> Board for FakeRobot<O> {
    const NAME: &'static str = "fake";
    const ID: BoardId = BoardId::Unknown;

    fn torque_off_best_effort(&mut self) {
        self.best_effort += 1;
        for d in self.devices.iter_mut() {
            d.torque = false;
        }
    }

    fn servo_power(&mut self, on: bool) {
        self.observer.power(on);
    }

    fn reset_cause(&self) -> (ResetCause, u32) {
        self.reset
    }

    fn crash_cell(&mut self) -> &mut CrashCell {
        &mut self.crash
    }

    fn exit(&mut self, code: i32) -> ! {
        self.observer.exit(code)
    }

    fn stage(&mut self, stage: crate::board::Stage) {
        self.observer.stage(stage);
    }

    fn enable_button(&mut self) -> Option<bool> {
        let now = self.now_us;
        self.button_us
            .map(|spans| spans.iter().any(|&(a, b)| now >= a && now < b))
    }

    fn imu_start(&mut self) -> Option<Result<(), crate::mpu9250::ImuError>> {
        let (_, fails) = self.board_imu?;
        Some(if fails {
            Err(crate::mpu9250::ImuError::NotMpu9250(0))
        } else {
            Ok(())
        })
    }

    fn imu_sample(&mut self) -> Option<Result<ImuSample, crate::mpu9250::ImuError>> {
        let (axes, _) = self.board_imu?;
        let s = ImuSample::from_bytes(&self.imu_bytes())?;
        // i32 → f64 → i32 is exact; the turn only moves and negates the values.
        let chip = |v: [i32; 3]| axes.to_chip_f64(v.map(f64::from)).map(|x| x as i32);
        Some(Ok(ImuSample {
            gyro_urad_s: chip(s.gyro_urad_s),
            accel_um_s2: chip(s.accel_um_s2),
            counter: s.counter,
        }))
    }
}

/// The host tests' observer: every packet, SYNC WRITE, tick, log byte and power switch in
/// vectors (test builds only).
#[cfg(test)]
pub mod trace {
    use std::vec::Vec;

    use super::{FakeRobot, Observer, PacketSeen};
    use crate::board::Tick;
    use crate::record::{Record, RecordDecoder};

    /// The fake robot of the host tests.
    pub type FakeBoard = FakeRobot<Trace>;

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

    /// Per `wait_tick`: the tick and the number of packets sent before it.
    #[derive(Clone, Copy, Debug)]
    pub struct TickMark {
        /// The tick returned.
        pub tick: Tick,
        /// `packets.len()` when it was returned.
        pub packets_before: usize,
    }

    /// Everything the fake robot saw.
    #[derive(Default)]
    pub struct Trace {
        /// Every instruction packet.
        pub packets: Vec<Pkt>,
        /// Log bytes.
        pub log: Vec<u8>,
        /// Every tick.
        pub ticks: Vec<TickMark>,
        /// Every `servo_power` call: (on, `packets.len()` at the call).
        pub power: Vec<(bool, usize)>,
        /// Goal positions of every SYNC WRITE.
        pub goals: Vec<[i32; 12]>,
    }

    impl Trace {
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
    }

    impl Observer for Trace {
        fn packet(&mut self, s: &PacketSeen<'_>) {
            self.packets.push(Pkt {
                t_us: s.t_us,
                id: s.id,
                op: s.op,
                addr: s.addr,
                data: s.data.to_vec(),
                tx_bytes: s.tx_bytes,
                rx_bytes: s.rx_bytes,
            });
        }
        fn sync_write(&mut self, goals: &[i32; 12]) {
            self.goals.push(*goals);
        }
        fn tick(&mut self, tick: Tick) {
            self.ticks.push(TickMark {
                tick,
                packets_before: self.packets.len(),
            });
        }
        fn log(&mut self, bytes: &[u8]) {
            self.log.extend_from_slice(bytes);
        }
        fn power(&mut self, on: bool) {
            self.power.push((on, self.packets.len()));
        }
        fn exit(&mut self, code: i32) -> ! {
            panic!("exit({code}) called in a host test")
        }
    }

    impl FakeBoard {
        /// The reference robot ([`FakeRobot::reference`]) recording into a [`Trace`].
        pub fn robot() -> Self {
            FakeRobot::reference(Trace::default())
        }

        /// A bus with nothing connected, recording into a [`Trace`].
        pub fn empty() -> Self {
            FakeRobot::unconnected(Trace::default())
        }
    }
}
