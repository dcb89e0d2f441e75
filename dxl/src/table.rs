//! Control tables of the devices on the robot's bus, shared by firmware and simulator.
//!
//! Each field is a [`Field`] (address + size in bytes); multi-byte values are little-endian.
//! Besides the ROBOTIS X-series servo ([`x_series`]), the bus carries two devices of our own:
//! the foot force-sensor boards ([`foot`]) and the IMU board ([`imu`]). Both implement the
//! Protocol 2.0 subset PING / READ / WRITE / SYNC READ / BULK READ and share the common
//! header of the table (model number at 0, firmware version at 6, ID at 7, return delay at 9).
//! Bus IDs and the joint-angle ↔ tick map are the robot's, not the protocol's: they are in the
//! `walker-contract` crate (`bus_map`).

/// A control-table field: start address and size in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Field {
    /// Start address.
    pub addr: u16,
    /// Size in bytes.
    pub len: u16,
}

const fn f(addr: u16, len: u16) -> Field {
    Field { addr, len }
}

/// A device's answer to a READ of `len` bytes at `addr` from its control table `mem`: those
/// bytes, or Data Range where they run past the table's end (both bus ends' devices).
#[inline]
pub fn read(mem: &[u8], addr: u16, len: u16) -> Result<&[u8], crate::ErrorCode> {
    let start = usize::from(addr);
    mem.get(start..start + usize::from(len))
        .ok_or(crate::ErrorCode::DataRange)
}

fn i32_at(b: &[u8], i: usize) -> Option<i32> {
    let s = b.get(i..i.checked_add(4)?)?;
    Some(i32::from_le_bytes([
        *s.first()?,
        *s.get(1)?,
        *s.get(2)?,
        *s.get(3)?,
    ]))
}

fn u16_at(b: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_le_bytes([*b.get(i)?, *b.get(i.checked_add(1)?)?]))
}

/// The common header of our own boards' control tables ([`foot`], [`imu`]).
pub mod board_header {
    use super::{f, Field};

    /// Model Number (u16).
    pub const MODEL_NUMBER: Field = f(0, 2);
    /// Firmware Version (u8).
    pub const FIRMWARE_VERSION: Field = f(6, 1);
    /// ID (u8).
    pub const ID: Field = f(7, 1);
    /// Return Delay Time (u8, ×2 µs).
    pub const RETURN_DELAY_TIME: Field = f(9, 1);
}

/// A sample block of our boards: `words` as little-endian i32, then the u16 `counter`.
fn sample_bytes<const N: usize>(words: impl IntoIterator<Item = i32>, counter: u16) -> [u8; N] {
    let mut out = [0u8; N];
    let (body, tail) = out.split_at_mut(N.saturating_sub(2));
    for (chunk, v) in body.chunks_exact_mut(4).zip(words) {
        chunk.copy_from_slice(&v.to_le_bytes());
    }
    for (o, b) in tail.iter_mut().zip(counter.to_le_bytes()) {
        *o = b;
    }
    out
}

/// ROBOTIS X-series servo (XM430-W350 / XL430-W250), Protocol 2.0 control table.
pub mod x_series {
    use super::{f, Field};

    /// Model Number (u16, read-only).
    pub const MODEL_NUMBER: Field = f(0, 2);
    /// Firmware Version (u8, read-only).
    pub const FIRMWARE_VERSION: Field = f(6, 1);
    /// ID (u8, EEPROM).
    pub const ID: Field = f(7, 1);
    /// Baud Rate code (u8, EEPROM; 3 = 1 Mbps, 4 = 2 Mbps, 5 = 3 Mbps, 6 = 4 Mbps).
    pub const BAUD_RATE: Field = f(8, 1);
    /// Return Delay Time (u8, EEPROM, unit 2 µs, default 250 = 500 µs).
    pub const RETURN_DELAY_TIME: Field = f(9, 1);
    /// Operating Mode (u8, EEPROM; 3 = position, 4 = extended position).
    pub const OPERATING_MODE: Field = f(11, 1);
    /// PWM Limit (u16, EEPROM, 0..885 = 0..100 % duty; default 885).
    pub const PWM_LIMIT: Field = f(36, 2);
    /// Current Limit (u16, EEPROM, unit [`CURRENT_UNIT_MA`]; XM430-W350 default 1193).
    pub const CURRENT_LIMIT: Field = f(38, 2);
    /// Velocity Limit (u32, EEPROM, unit [`VELOCITY_UNIT_RPM`]; XM430-W350 default 200).
    pub const VELOCITY_LIMIT: Field = f(44, 4);
    /// Torque Enable (u8; 1 = on, locks the EEPROM area).
    pub const TORQUE_ENABLE: Field = f(64, 1);
    /// LED (u8).
    pub const LED: Field = f(65, 1);
    /// Status Return Level (u8; 0 = PING only, 1 = + READ, 2 = all).
    pub const STATUS_RETURN_LEVEL: Field = f(68, 1);
    /// Hardware Error Status (u8 bit field, read-only).
    pub const HARDWARE_ERROR_STATUS: Field = f(70, 1);
    /// Position D Gain (u16; K_PD = value / 16; default 0).
    pub const POSITION_D_GAIN: Field = f(80, 2);
    /// Position I Gain (u16; K_PI = value / 65536; default 0).
    pub const POSITION_I_GAIN: Field = f(82, 2);
    /// Position P Gain (u16; K_PP = value / 128; XM430-W350 default 800).
    pub const POSITION_P_GAIN: Field = f(84, 2);
    /// Feedforward 2nd Gain (u16; K_FF2 = value / 4; default 0).
    pub const FEEDFORWARD_2ND_GAIN: Field = f(88, 2);
    /// Feedforward 1st Gain (u16; K_FF1 = value / 4; default 0).
    pub const FEEDFORWARD_1ST_GAIN: Field = f(90, 2);
    /// Goal Velocity (i32, unit [`VELOCITY_UNIT_RPM`]).
    pub const GOAL_VELOCITY: Field = f(104, 4);
    /// Profile Acceleration (u32).
    pub const PROFILE_ACCELERATION: Field = f(108, 4);
    /// Profile Velocity (u32, 0 = unlimited).
    pub const PROFILE_VELOCITY: Field = f(112, 4);
    /// Goal Position (i32, ticks).
    pub const GOAL_POSITION: Field = f(116, 4);
    /// Moving (u8, read-only).
    pub const MOVING: Field = f(122, 1);
    /// Present PWM (i16, ±885 = ±100 % duty, read-only).
    pub const PRESENT_PWM: Field = f(124, 2);
    /// Present Current (i16, unit [`CURRENT_UNIT_MA`], read-only).
    pub const PRESENT_CURRENT: Field = f(126, 2);
    /// Present Velocity (i32, unit [`VELOCITY_UNIT_RPM`], read-only).
    pub const PRESENT_VELOCITY: Field = f(128, 4);
    /// Present Position (i32, ticks, read-only).
    pub const PRESENT_POSITION: Field = f(132, 4);
    /// Present Input Voltage (u16, unit 0.1 V, read-only).
    pub const PRESENT_INPUT_VOLTAGE: Field = f(144, 2);
    /// Present Temperature (u8, °C, read-only).
    pub const PRESENT_TEMPERATURE: Field = f(146, 1);

    /// Model number of the XM430-W350.
    pub const MODEL_XM430_W350: u16 = 1020;
    /// Model number of the XL430-W250.
    pub const MODEL_XL430_W250: u16 = 1060;
    /// Default Return Delay Time register value (×2 µs).
    pub const DEFAULT_RETURN_DELAY: u8 = 250;
    /// Operating Mode value for position control.
    pub const MODE_POSITION: u8 = 3;
    /// Operating Mode value for extended position control.
    pub const MODE_EXTENDED_POSITION: u8 = 4;
    /// Full-scale PWM value (100 % duty) of PWM Limit, Goal PWM and Present PWM.
    pub const PWM_FULL_SCALE: u16 = 885;
    /// Profile Acceleration unit in rev/min² per LSB.
    pub const ACCELERATION_UNIT_RPM2: f32 = 214.577;
    /// Velocity unit in rpm per LSB.
    pub const VELOCITY_UNIT_RPM: f32 = 0.229;
    /// Current unit in mA per LSB (XM430).
    pub const CURRENT_UNIT_MA: f32 = 2.69;

    /// Encoder ticks per revolution.
    pub const TICKS_PER_TURN: i32 = 4096;
    /// Tick value of the 0 rad joint position.
    pub const CENTER_TICK: i32 = 2048;
    /// Largest |Goal Position| in extended position mode.
    pub const MAX_EXTENDED_TICKS: i32 = 1_048_575;
}

/// Foot force-sensor board (our device): four load cells under each sole.
///
/// Sensor order: 0 front-left, 1 front-right, 2 rear-left, 3 rear-right; where the cells sit
/// under the sole is the robot's description (gait-core `Geometry::force_sensors`), not the
/// board's.
///
/// | addr | size | field |
/// |---|---|---|
/// | 0 | 2 | model number ([`foot::MODEL_NUMBER_VALUE`]) |
/// | 6 | 1 | firmware version |
/// | 7 | 1 | ID |
/// | 9 | 1 | return delay time (×2 µs) |
/// | 128 | 16 | force\[0..4\], i32 each, millinewtons, positive = load on the sole |
/// | 144 | 2 | sample counter (u16, wraps) |
pub mod foot {
    pub use super::board_header::{FIRMWARE_VERSION, ID, MODEL_NUMBER, RETURN_DELAY_TIME};
    use super::{f, i32_at, sample_bytes, u16_at, Field};

    /// Whole sample block: four forces and the counter (one READ).
    pub const SAMPLE: Field = f(128, 18);
    /// The four forces (4 × i32 mN).
    pub const FORCES: Field = f(128, 16);
    /// Sample counter (u16).
    pub const COUNTER: Field = f(144, 2);
    /// Model number reported by the foot board.
    pub const MODEL_NUMBER_VALUE: u16 = 0x5A11;

    /// One sample of a foot board.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct FootForces {
        /// Forces in mN: front-left, front-right, rear-left, rear-right.
        pub forces_mn: [i32; 4],
        /// Sample counter.
        pub counter: u16,
    }

    impl FootForces {
        /// Decodes the [`SAMPLE`] block (at least 18 bytes).
        pub fn from_bytes(b: &[u8]) -> Option<Self> {
            Some(FootForces {
                forces_mn: [i32_at(b, 0)?, i32_at(b, 4)?, i32_at(b, 8)?, i32_at(b, 12)?],
                counter: u16_at(b, 16)?,
            })
        }

        /// Encodes the [`SAMPLE`] block.
        pub fn to_bytes(&self) -> [u8; 18] {
            sample_bytes(self.forces_mn, self.counter)
        }

        /// Total vertical force in newtons.
        pub fn total_n(&self) -> f32 {
            self.forces_mn.iter().map(|&v| v as f32).sum::<f32>() * 1e-3
        }
    }
}

/// IMU board (our device): gyroscope and accelerometer in the torso frame (x forward,
/// y left, z up).
///
/// Units: angular rate in µrad/s (1e-6 rad/s, range ±2147 rad/s, far beyond the ±20 rad/s
/// a kid-size robot sees), acceleration in µm/s² (1e-6 m/s², range ±2147 m/s² ≈ ±219 g,
/// covering the sensor's ±16 g full scale with sub-µg resolution to spare).
///
/// | addr | size | field |
/// |---|---|---|
/// | 0 | 2 | model number ([`imu::MODEL_NUMBER_VALUE`]) |
/// | 6 | 1 | firmware version |
/// | 7 | 1 | ID |
/// | 9 | 1 | return delay time (×2 µs) |
/// | 128 | 12 | gyro x, y, z (i32, µrad/s) |
/// | 140 | 12 | accel x, y, z (i32, µm/s², includes gravity: +9.81 on z when upright) |
/// | 152 | 2 | sample counter (u16, wraps) |
pub mod imu {
    pub use super::board_header::{FIRMWARE_VERSION, ID, MODEL_NUMBER, RETURN_DELAY_TIME};
    use super::{f, i32_at, sample_bytes, u16_at, Field};

    /// Whole sample block: gyro, accel, counter (one READ).
    pub const SAMPLE: Field = f(128, 26);
    /// Gyroscope (3 × i32 µrad/s).
    pub const GYRO: Field = f(128, 12);
    /// Accelerometer (3 × i32 µm/s²).
    pub const ACCEL: Field = f(140, 12);
    /// Sample counter (u16).
    pub const COUNTER: Field = f(152, 2);
    /// Model number reported by the IMU board.
    pub const MODEL_NUMBER_VALUE: u16 = 0x5A20;
    /// Largest |angular rate| the board's gyro reports, µrad/s (its ±2000 °/s full scale):
    /// a larger value cannot come from the sensor (byte-shifted or corrupt data).
    pub const GYRO_FULL_SCALE_URAD_S: i32 = 34_906_586;
    /// Largest |specific force| per axis the board's accelerometer reports, µm/s² (its ±16 g
    /// full scale).
    pub const ACCEL_FULL_SCALE_UM_S2: i32 = 156_906_500;
    /// Scale from raw units to SI (rad/s or m/s²).
    pub const SCALE: f32 = 1e-6;

    /// One IMU sample in raw units.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct ImuSample {
        /// Angular rate x, y, z in µrad/s.
        pub gyro_urad_s: [i32; 3],
        /// Acceleration x, y, z in µm/s².
        pub accel_um_s2: [i32; 3],
        /// Sample counter.
        pub counter: u16,
    }

    impl ImuSample {
        /// Decodes the [`SAMPLE`] block (at least 26 bytes).
        pub fn from_bytes(b: &[u8]) -> Option<Self> {
            Some(ImuSample {
                gyro_urad_s: [i32_at(b, 0)?, i32_at(b, 4)?, i32_at(b, 8)?],
                accel_um_s2: [i32_at(b, 12)?, i32_at(b, 16)?, i32_at(b, 20)?],
                counter: u16_at(b, 24)?,
            })
        }

        /// Encodes the [`SAMPLE`] block.
        pub fn to_bytes(&self) -> [u8; 26] {
            let words = self.gyro_urad_s.into_iter().chain(self.accel_um_s2);
            sample_bytes(words, self.counter)
        }

        /// Angular rate in rad/s.
        pub fn gyro_rad_s(&self) -> [f32; 3] {
            self.gyro_urad_s.map(|v| v as f32 * SCALE)
        }

        /// Acceleration in m/s².
        pub fn accel_m_s2(&self) -> [f32; 3] {
            self.accel_um_s2.map(|v| v as f32 * SCALE)
        }

        /// Builds a sample from SI values, saturating out-of-range values (NaN maps to 0).
        pub fn from_si(gyro_rad_s: [f32; 3], accel_m_s2: [f32; 3], counter: u16) -> Self {
            ImuSample {
                gyro_urad_s: gyro_rad_s.map(|v| (v / SCALE) as i32),
                accel_um_s2: accel_m_s2.map(|v| (v / SCALE) as i32),
                counter,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::foot::FootForces;
    use super::imu::ImuSample;

    #[test]
    fn sensor_blocks() {
        let f = FootForces {
            forces_mn: [1000, 2000, -3, i32::MAX],
            counter: 0xBEEF,
        };
        assert_eq!(FootForces::from_bytes(&f.to_bytes()), Some(f));
        assert_eq!(FootForces::from_bytes(&[0; 17]), None);
        let s = ImuSample {
            gyro_urad_s: [1, -2, 3],
            accel_um_s2: [0, 0, 9_806_650],
            counter: 7,
        };
        assert_eq!(ImuSample::from_bytes(&s.to_bytes()), Some(s));
        assert_eq!(ImuSample::from_bytes(&[0; 25]), None);
        let even = FootForces {
            forces_mn: [10_000; 4],
            counter: 0,
        };
        assert!((even.total_n() - 40.0).abs() < 1e-4);
        assert_eq!(FootForces::from_bytes(&even.to_bytes()), Some(even));
    }
}
