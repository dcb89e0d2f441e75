//! The robot's servo bus as both ends see it: device IDs, joint order and names, and the ONE
//! joint-angle ↔ servo-tick map.
//!
//! # IDs
//! The robot description's bus ([`gait_core::robot::BusDescription`]) is the one place the IDs
//! are written; the constants here are the reference robot's (`shared/reference-robot.md`):
//! left leg 1–6, right leg 7–12, each in the joint order `hip_yaw`, `hip_roll`, `hip_pitch`,
//! `knee`, `ankle_pitch`, `ankle_roll` ([`JOINT_NAMES`]); foot sensor boards 111 (left) and 112
//! (right); the waist IMU board 200.
//!
//! # rad ↔ tick ([`TickMap`])
//! `tick = zero_tick + o_j + round(sign_j · q · ticks_per_rad)` and
//! `q = sign_j · (tick − zero_tick − o_j) / ticks_per_rad`, with `ticks_per_rad = ticks_per_turn / 2π`
//! (4096 / 2π ≈ 651.9 on X-series servos, `zero_tick` = 2048 = 0 rad), `sign_j` = ±1 the
//! mounting of joint j (the description's `mounting`: all +1 on the reference robot) and `o_j`
//! its servo's zero offset in ticks (the description's `zero_offsets`: 0 on both robots). The firmware works in f32
//! ([`TickMap::tick_f32`], [`TickMap::rad_f32`]), the simulator in f64 ([`TickMap::tick_f64`],
//! [`TickMap::rad_f64`]), the fixed-point pipeline in I16F16 bits ([`TickMap::tick_fx`]); the
//! four are the same map in three number types.

use gait_core::robot::{BusDescription, ImuPlace};
pub use gait_core::robot::{JOINTS_PER_LEG, JOINT_NAMES, LEG_JOINTS};
use gait_core::Robot;

/// The reference robot's bus.
const BUS: BusDescription = Robot::reference().bus;

/// All twelve leg servos, left then right (joint index j ↔ `LEGS[j]`).
pub const LEGS: [u8; LEG_JOINTS] = BUS.legs;
/// Left-leg servos in joint order (see [`JOINT_NAMES`]).
pub const LEFT_LEG: [u8; JOINTS_PER_LEG] = [LEGS[0], LEGS[1], LEGS[2], LEGS[3], LEGS[4], LEGS[5]];
/// Right-leg servos in joint order.
pub const RIGHT_LEG: [u8; JOINTS_PER_LEG] =
    [LEGS[6], LEGS[7], LEGS[8], LEGS[9], LEGS[10], LEGS[11]];
/// The foot sensor boards (left, right).
const FEET: [u8; 2] = match BUS.foot_boards {
    Some(f) => f,
    None => [0, 0],
};
/// Left foot sensor board.
pub const FOOT_LEFT: u8 = FEET[0];
/// Right foot sensor board.
pub const FOOT_RIGHT: u8 = FEET[1];
/// Waist IMU board.
pub const IMU: u8 = match BUS.imu {
    ImuPlace::Bus(id) => id,
    ImuPlace::Board(_) => 0,
};
/// Devices read every control tick, in bulk-read order.
pub const SENSOR_IDS: [u8; 3] = [FOOT_LEFT, FOOT_RIGHT, IMU];
/// Every device on the bus: the legs, the foot boards, the IMU.
pub const DEVICE_IDS: [u8; 15] = [
    LEGS[0], LEGS[1], LEGS[2], LEGS[3], LEGS[4], LEGS[5], LEGS[6], LEGS[7], LEGS[8], LEGS[9],
    LEGS[10], LEGS[11], FOOT_LEFT, FOOT_RIGHT, IMU,
];

/// The servos' encoder facts (X-series control table): ticks per turn, 0 rad tick, extended
/// position range.
pub use dxl::table::x_series::{CENTER_TICK as ZERO_TICK, MAX_EXTENDED_TICKS, TICKS_PER_TURN};

/// An ID no device answers to (255: not a Dynamixel device ID): a sensor slot the robot does
/// not have, for tables indexed by slot.
pub const NOT_ON_BUS: u8 = 0xFF;
/// Most held servos (arms, head) the firmware drives (every description has at most these: a
/// test checks).
pub const MAX_HELD: usize = 8;
/// Sensor slots of the tick's BULK READ: the left and right foot boards and a bus IMU.
pub const SENSOR_SLOTS: usize = 3;
/// Most devices on a described bus: the legs, the sensor slots, the held servos.
pub const MAX_DEVICES: usize = LEG_JOINTS + SENSOR_SLOTS + MAX_HELD;

/// The controller board's own IMU ([`ImuPlace::Board`]) where the supervisor, the start-up
/// record and the fault records name a device: an ID no Dynamixel device has (they stop at
/// 252; 254 is the broadcast ID).
pub const BOARD_IMU: u8 = 253;

/// The sensor slots of `bus` on the bus: left foot board, right foot board, bus IMU; `None`
/// where the robot has none there (no foot boards; the IMU on the controller board).
pub fn sensor_slots(bus: &BusDescription) -> [Option<u8>; SENSOR_SLOTS] {
    let [l, r, imu] = sensor_ids(bus);
    [l, r, imu.filter(|&id| id != BOARD_IMU)]
}

/// The sensors of the robot, slot by slot (left foot board, right foot board, IMU): the
/// device each slot's samples come from, [`BOARD_IMU`] for the controller board's IMU, `None`
/// where the robot has none.
pub fn sensor_ids(bus: &BusDescription) -> [Option<u8>; SENSOR_SLOTS] {
    let [l, r] = match bus.foot_boards {
        Some([l, r]) => [Some(l), Some(r)],
        None => [None, None],
    };
    let imu = match bus.imu {
        ImuPlace::Bus(id) => id,
        ImuPlace::Board(_) => BOARD_IMU,
    };
    [l, r, Some(imu)]
}

/// The servos of `bus`, legs (joint order) then held ones (at most [`MAX_HELD`]): how many,
/// and the ID of servo slot `k` (`None` past them). The servo monitor's round and the stop's
/// torque-off read-back go through these slots.
pub fn servo_slots(bus: &BusDescription) -> usize {
    LEG_JOINTS + bus.held.len().min(MAX_HELD)
}

/// [`servo_slots`]' slot `k`: its servo's ID.
pub fn servo_slot_id(bus: &BusDescription, k: usize) -> Option<u8> {
    match k.checked_sub(LEG_JOINTS) {
        None => bus.legs.get(k).copied(),
        Some(h) if h < MAX_HELD => bus.held.get(h).map(|h| h.id),
        Some(_) => None,
    }
}

/// Every device of `bus` in probe order: the legs (joint order), the sensors, the held servos
/// (at most [`MAX_HELD`]).
pub fn device_ids(bus: &BusDescription) -> heapless::Vec<u8, MAX_DEVICES> {
    let mut out = heapless::Vec::new();
    let sensors = sensor_slots(bus);
    let held = bus.held.iter().take(MAX_HELD).map(|h| h.id);
    for id in bus
        .legs
        .iter()
        .copied()
        .chain(sensors.into_iter().flatten())
        .chain(held)
    {
        // At most MAX_DEVICES by construction.
        let _ = out.push(id);
    }
    out
}

/// True when `id` is one of `bus`'s foot boards.
pub fn is_foot(bus: &BusDescription, id: u8) -> bool {
    bus.foot_boards.is_some_and(|f| f.contains(&id))
}

/// The servo ID of joint `j` (0..12), `None` beyond.
pub fn servo_id(j: usize) -> Option<u8> {
    LEGS.get(j).copied()
}

/// The joint index (0..12) of servo `id`, `None` for a non-leg device.
pub fn joint_of(id: u8) -> Option<usize> {
    LEGS.iter().position(|&x| x == id)
}

/// The name of joint `j` (`l_hip_yaw` … `r_ankle_roll`), `"?"` beyond.
pub fn joint_name(j: usize) -> &'static str {
    JOINT_NAMES.get(j).copied().unwrap_or("?")
}

/// The joint-angle ↔ servo-tick map of the 12 leg servos (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickMap {
    /// Tick that stands for 0 rad.
    pub zero_tick: i32,
    /// Ticks per turn.
    pub ticks_per_turn: i32,
    /// +1 when joint-positive is servo-positive, −1 otherwise (mounting), per joint.
    pub sign: [i8; LEG_JOINTS],
    /// Each leg servo's zero offset, ticks (the tick of its joint's 0 rad minus `zero_tick`).
    pub offset: [i8; LEG_JOINTS],
}

impl Default for TickMap {
    fn default() -> Self {
        Self::reference()
    }
}

impl TickMap {
    /// The reference robot's map: 4096 ticks per turn, 2048 = 0 rad, its mounting signs.
    pub const fn reference() -> Self {
        TickMap {
            zero_tick: ZERO_TICK,
            ticks_per_turn: TICKS_PER_TURN,
            sign: Robot::reference().mounting,
            offset: Robot::reference().zero_offsets,
        }
    }

    /// From a robot description's servo data and mounting signs.
    pub fn from_robot(robot: &Robot) -> Self {
        TickMap {
            zero_tick: robot.servo.zero_tick,
            ticks_per_turn: i32::try_from(robot.servo.ticks_per_turn).unwrap_or(TICKS_PER_TURN),
            sign: robot.mounting,
            offset: robot.zero_offsets,
        }
    }

    /// The zero tick of joint `j`: `zero_tick` + its offset (`zero_tick` beyond the 12).
    fn zero_of(&self, j: usize) -> i32 {
        self.zero_tick
            .saturating_add(self.offset.get(j).map_or(0, |&o| i32::from(o)))
    }

    /// The mounting sign of joint `j` as ±1.0 (+1 beyond the 12 joints).
    fn sign_of(&self, j: usize) -> f32 {
        match self.sign.get(j) {
            Some(&s) if s < 0 => -1.0,
            _ => 1.0,
        }
    }

    /// Ticks per radian, f32 (1.0 for a degenerate map, so that nothing divides by 0).
    pub fn ticks_per_rad_f32(&self) -> f32 {
        let t = self.ticks_per_turn as f32 / core::f32::consts::TAU;
        if t.is_finite() && t != 0.0 {
            t
        } else {
            1.0
        }
    }

    /// The tick of joint `j` at `rad` (f32; `rad` finite, the caller clamps the result).
    pub fn tick_f32(&self, j: usize, rad: f32) -> i32 {
        self.servo_tick_f32(self.sign_of(j) * rad)
            .saturating_add(self.zero_of(j) - self.zero_tick)
    }

    /// The tick at `rad` in the servo's own direction (no mounting sign: a held servo, or a
    /// leg joint's angle already signed), f32, `rad` finite.
    pub fn servo_tick_f32(&self, rad: f32) -> i32 {
        self.zero_tick
            .saturating_add(gait_core::maths::fastmath::round_i32(
                rad * self.ticks_per_rad_f32(),
            ))
    }

    /// The joint angle (rad, f32) of joint `j` at `tick`.
    pub fn rad_f32(&self, j: usize, tick: i32) -> f32 {
        self.sign_of(j) * (tick.saturating_sub(self.zero_of(j))) as f32 / self.ticks_per_rad_f32()
    }

    /// The tick of joint `j` at `q` (f64, nearest, half away from zero), saturating at
    /// ±[`MAX_EXTENDED_TICKS`]; a non-finite `q` gives its zero tick.
    pub fn tick_f64(&self, j: usize, q: f64) -> i32 {
        let lim = MAX_EXTENDED_TICKS;
        (self.servo_tick_f64(f64::from(self.sign_of(j)) * q) + (self.zero_of(j) - self.zero_tick))
            .clamp(-lim, lim)
    }

    /// [`TickMap::tick_f64`] in the servo's own direction (no mounting sign: a held servo, the
    /// simulated servo's encoder).
    pub fn servo_tick_f64(&self, q: f64) -> i32 {
        let t =
            q * f64::from(self.ticks_per_turn) / core::f64::consts::TAU + f64::from(self.zero_tick);
        let lim = f64::from(MAX_EXTENDED_TICKS);
        if t.is_finite() {
            libm::round(t).clamp(-lim, lim) as i32
        } else {
            self.zero_tick
        }
    }

    /// The joint angle (rad, f64) of joint `j` at `tick`.
    pub fn rad_f64(&self, j: usize, tick: i32) -> f64 {
        f64::from(self.sign_of(j))
            * (f64::from(tick) - f64::from(self.zero_of(j)))
            * core::f64::consts::TAU
            / f64::from(self.ticks_per_turn)
    }

    /// The tick of joint `j` at a fixed-point angle given as its I16F16 bits (integer only,
    /// round half up): `tick = zero + (bits · K + 2³¹) >> 32` with
    /// K = round(ticks_per_turn · 2¹⁶ · 2³² / (2π · 2³²)) = ticks per rad · 2⁻¹⁶ · 2³².
    pub fn tick_fx(&self, j: usize, bits: i32) -> i32 {
        self.tick_fx_k(j, bits, self.ticks_per_fx_rad_32())
    }

    /// [`TickMap::tick_fx`] with its factor `k` = [`TickMap::ticks_per_fx_rad_32`] computed
    /// once by the caller (it takes an f64 rounding: soft float on FPU-less cores).
    pub fn tick_fx_k(&self, j: usize, bits: i32, k: i64) -> i32 {
        let s = i64::from(bits) * i64::from(self.sign_of(j) as i8);
        let t = (s * k + (1 << 31)) >> 32;
        (t as i32).saturating_add(self.zero_of(j))
    }

    /// Ticks per rad × 2⁻¹⁶ × 2³² (42 722 830 for 4096 ticks per turn).
    pub fn ticks_per_fx_rad_32(&self) -> i64 {
        libm::round(f64::from(self.ticks_per_turn) * 65536.0 / core::f64::consts::TAU) as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_and_names_agree() {
        assert_eq!(DEVICE_IDS[..12], LEGS);
        assert_eq!(&DEVICE_IDS[12..], &SENSOR_IDS);
        assert_eq!([LEFT_LEG, RIGHT_LEG].concat(), LEGS);
        for (j, &id) in LEGS.iter().enumerate() {
            assert_eq!(servo_id(j), Some(id));
            assert_eq!(joint_of(id), Some(j));
        }
        assert_eq!(joint_of(IMU), None);
        assert_eq!(joint_name(3), "l_knee");
        assert_eq!(joint_name(12), "?");
    }

    #[test]
    fn each_robots_devices_from_its_description() {
        let t = Robot::reference();
        assert_eq!(device_ids(&t.bus), DEVICE_IDS);
        assert_eq!(sensor_slots(&t.bus), SENSOR_IDS.map(Some));
        assert!(is_foot(&t.bus, 111) && is_foot(&t.bus, 112) && !is_foot(&t.bus, 200));
        let o = Robot::op3();
        assert_eq!(sensor_slots(&o.bus), [None; 3]);
        assert_eq!(sensor_ids(&o.bus), [None, None, Some(BOARD_IMU)]);
        assert_eq!(sensor_ids(&t.bus), SENSOR_IDS.map(Some));
        // No robot's bus can hold the board IMU's ID.
        let mut on_bus = vec![];
        for r in gait_core::robot::ROBOTS.iter() {
            r.for_each_bus_id(|id| on_bus.push(id));
        }
        assert!(!on_bus.contains(&BOARD_IMU) && BOARD_IMU > 252 && BOARD_IMU != 254);
        assert_eq!(
            device_ids(&o.bus),
            [8, 10, 12, 14, 16, 18, 7, 9, 11, 13, 15, 17, 1, 2, 3, 4, 5, 6, 19, 20]
        );
        assert!(!is_foot(&o.bus, 19));
        for r in gait_core::robot::ROBOTS.iter() {
            assert!(r.bus.held.len() <= MAX_HELD, "{}", r.name);
        }
    }

    #[test]
    fn the_map_in_three_number_types() {
        let m = TickMap::reference();
        assert_eq!(m, TickMap::from_robot(&Robot::reference()));
        assert_eq!(m.tick_f32(0, 0.0), 2048);
        assert_eq!(m.tick_f32(3, 0.5), 2048 + 326);
        assert_eq!(m.tick_f64(0, core::f64::consts::PI), 4096);
        assert_eq!(m.tick_f64(0, -core::f64::consts::FRAC_PI_2), 1024);
        assert_eq!(m.tick_f64(0, f64::NAN), 2048);
        assert_eq!(m.tick_f64(0, 1e12), MAX_EXTENDED_TICKS);
        assert!((m.rad_f64(0, 3072) - core::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert!((m.rad_f32(0, 3072) - core::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert_eq!(m.ticks_per_fx_rad_32(), 42_722_830);
        for t in [0, 1, 2047, 2048, 2049, 3000, 4095] {
            assert_eq!(m.tick_f64(0, m.rad_f64(0, t)), t);
            assert_eq!(m.tick_f32(0, m.rad_f32(0, t)), t);
            let q = m.rad_f64(0, t);
            let bits = libm::round(q * 65536.0) as i32;
            assert_eq!(m.tick_fx(0, bits), t, "{t}");
        }
        let mut flipped = m;
        flipped.sign[4] = -1;
        assert_eq!(flipped.tick_f32(4, 0.5), 2048 - 326);
        assert_eq!(flipped.tick_fx(4, 32768), 2048 - 326);
        assert!((flipped.rad_f32(4, 2048 - 326) - 0.5).abs() < 1e-3);
        assert!((flipped.rad_f64(4, 2048 + 326) + 0.5).abs() < 1e-3);
    }

    /// The servo slots: the legs in joint order, then the held servos; nothing past them.
    #[test]
    fn servo_slots_are_the_legs_then_the_held_servos() {
        let o = Robot::op3();
        assert_eq!(servo_slots(&o.bus), 20);
        assert_eq!(servo_slot_id(&o.bus, 0), Some(8));
        assert_eq!(servo_slot_id(&o.bus, 11), Some(17));
        assert_eq!(servo_slot_id(&o.bus, 12), Some(1));
        assert_eq!(servo_slot_id(&o.bus, 19), Some(20));
        assert_eq!(servo_slot_id(&o.bus, 20), None);
        let t = Robot::reference();
        assert_eq!(servo_slots(&t.bus), 12);
        assert_eq!(servo_slot_id(&t.bus, 11), Some(12));
        assert_eq!(servo_slot_id(&t.bus, 12), None);
    }

    /// A servo whose horn sits 37 ticks off (joint 2) and one 15 ticks the other way on a
    /// servo mounted reversed (joint 8): the joint's 0 rad is the servo's zero tick plus the
    /// offset in every number type, the mounting sign applies to the angle only, and the
    /// joints without an offset read as before.
    #[test]
    fn a_zero_offset_moves_the_joints_zero_tick() {
        let mut m = TickMap::reference();
        m.offset[2] = 37;
        m.offset[8] = -15;
        m.sign[8] = -1;
        assert_eq!(m.tick_f32(2, 0.0), 2048 + 37);
        assert_eq!(m.tick_f64(2, 0.0), 2048 + 37);
        assert_eq!(m.tick_fx(2, 0), 2048 + 37);
        assert_eq!(m.tick_f64(2, f64::NAN), 2048 + 37);
        assert_eq!(m.tick_f32(2, 0.5), 2048 + 37 + 326);
        assert_eq!(m.tick_f64(8, 0.5), 2048 - 15 - 326);
        assert_eq!(m.tick_fx(8, 32768), 2048 - 15 - 326);
        assert_eq!(m.tick_f32(3, 0.5), 2048 + 326);
        assert_eq!(m.rad_f64(2, 2048 + 37), 0.0);
        assert_eq!(m.rad_f32(8, 2048 - 15), 0.0);
        for (j, t) in [
            (2, 0),
            (2, 2085),
            (2, 4095),
            (8, 1000),
            (8, 2033),
            (8, 3900),
        ] {
            assert_eq!(m.tick_f64(j, m.rad_f64(j, t)), t);
            assert_eq!(m.tick_f32(j, m.rad_f32(j, t)), t);
            let bits = libm::round(m.rad_f64(j, t) * 65536.0) as i32;
            assert_eq!(m.tick_fx(j, bits), t, "{j} {t}");
        }
        // The description's offsets are the map's.
        let r = Robot {
            zero_offsets: [0, 0, 37, 0, 0, 0, 0, 0, -15, 0, 0, 0],
            ..Robot::reference()
        };
        assert_eq!(TickMap::from_robot(&r).offset, r.zero_offsets);
        assert!(r.validate_bus().is_ok());
    }
}
