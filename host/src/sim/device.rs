//! Simulated bus devices: their control-table memory and the access rules of WRITE and READ.
//!
//! The tables are byte arrays laid out by `dxl::table` (X-series servo, foot board, IMU
//! board). Servos: the EEPROM area (addresses below Torque Enable, 64) is locked while the
//! torque is on; the model/firmware bytes, Hardware Error Status and the block from 120 to 147
//! (Moving … Present Temperature) are read-only. Foot and IMU boards: only ID and Return Delay
//! Time are writable. Violations answer the protocol's Access / Data Range / Data Limit errors.

use dxl::table::{foot, imu, x_series, Field};
use dxl::ErrorCode;

/// Size of a servo's control table (the X-series table ends with the indirect data at 661).
pub const SERVO_TABLE_LEN: usize = 662;
/// Size of a sensor board's control table.
pub const BOARD_TABLE_LEN: usize = 256;
/// Firmware version reported by every simulated device.
pub const FIRMWARE_VERSION: u8 = 48;

/// What a device is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeviceKind {
    /// Leg servo driving joint `joint` (0..12: left leg then right leg, joint order).
    Servo {
        /// Joint index.
        joint: usize,
    },
    /// Foot force-sensor board of foot `side` (0 left, 1 right).
    Foot {
        /// Foot index.
        side: usize,
    },
    /// IMU board.
    Imu,
}

/// One simulated device.
#[derive(Clone, Debug)]
pub struct Device {
    /// Current bus ID (mirrors the ID byte of the table).
    pub id: u8,
    /// Kind.
    pub kind: DeviceKind,
    /// Control-table memory.
    pub mem: Vec<u8>,
    /// A dead device neither answers nor executes anything (fault injection).
    pub dead: bool,
    /// Registered write (REG WRITE), executed by ACTION.
    pub pending: Option<(u16, Vec<u8>)>,
}

fn range(field: Field) -> std::ops::Range<usize> {
    usize::from(field.addr)..usize::from(field.addr) + usize::from(field.len)
}

impl Device {
    fn with(id: u8, kind: DeviceKind, len: usize, model: u16) -> Self {
        let mut d = Device {
            id,
            kind,
            mem: vec![0; len],
            dead: false,
            pending: None,
        };
        d.set(x_series::MODEL_NUMBER, &model.to_le_bytes());
        d.set(x_series::FIRMWARE_VERSION, &[FIRMWARE_VERSION]);
        d.set(x_series::ID, &[id]);
        d.set(
            x_series::RETURN_DELAY_TIME,
            &[x_series::DEFAULT_RETURN_DELAY],
        );
        d
    }

    /// An XM430-W350 servo in position mode, torque off, holding `ticks`.
    pub fn servo(id: u8, joint: usize, ticks: i32) -> Self {
        let mut d = Self::with(
            id,
            DeviceKind::Servo { joint },
            SERVO_TABLE_LEN,
            x_series::MODEL_XM430_W350,
        );
        d.set(x_series::BAUD_RATE, &[3]);
        d.set(x_series::OPERATING_MODE, &[x_series::MODE_POSITION]);
        d.set(x_series::STATUS_RETURN_LEVEL, &[2]);
        d.set(x_series::PRESENT_TEMPERATURE, &[36]);
        // Factory defaults of the XM430-W350 control table (ROBOTIS e-manual).
        d.set(x_series::PWM_LIMIT, &x_series::PWM_FULL_SCALE.to_le_bytes());
        d.set(x_series::CURRENT_LIMIT, &1193u16.to_le_bytes());
        d.set_i32(x_series::VELOCITY_LIMIT, 200);
        d.set(x_series::POSITION_P_GAIN, &800u16.to_le_bytes());
        d.set(x_series::PRESENT_INPUT_VOLTAGE, &120u16.to_le_bytes());
        d.set_i32(x_series::GOAL_POSITION, ticks);
        d.set_i32(x_series::PRESENT_POSITION, ticks);
        d
    }

    /// A foot board (`side` 0 left, 1 right).
    pub fn foot(id: u8, side: usize) -> Self {
        Self::with(
            id,
            DeviceKind::Foot { side },
            BOARD_TABLE_LEN,
            foot::MODEL_NUMBER_VALUE,
        )
    }

    /// The IMU board.
    pub fn imu(id: u8) -> Self {
        Self::with(
            id,
            DeviceKind::Imu,
            BOARD_TABLE_LEN,
            imu::MODEL_NUMBER_VALUE,
        )
    }

    /// Model number (PING).
    pub fn model(&self) -> u16 {
        u16::from_le_bytes([self.mem[0], self.mem[1]])
    }

    /// PING reply data: model number and firmware version.
    pub fn ping_data(&self) -> [u8; 3] {
        let [lo, hi] = self.model().to_le_bytes();
        [
            lo,
            hi,
            self.mem[usize::from(x_series::FIRMWARE_VERSION.addr)],
        ]
    }

    /// Writes raw bytes of a field (no access check; for the simulator itself).
    pub fn set(&mut self, field: Field, data: &[u8]) {
        if let Some(s) = self.mem.get_mut(range(field)) {
            let n = s.len().min(data.len());
            s[..n].copy_from_slice(&data[..n]);
        }
    }

    /// Writes an i32 field.
    pub fn set_i32(&mut self, field: Field, v: i32) {
        self.set(field, &v.to_le_bytes());
    }

    /// Reads a u8 field.
    pub fn get_u8(&self, field: Field) -> u8 {
        self.mem.get(usize::from(field.addr)).copied().unwrap_or(0)
    }

    /// Reads an i32 field.
    pub fn get_i32(&self, field: Field) -> i32 {
        match self.mem.get(range(field)) {
            Some(&[a, b, c, d]) => i32::from_le_bytes([a, b, c, d]),
            _ => 0,
        }
    }

    /// Reads a u16 field (0 if the field is not 2 bytes long).
    pub fn get_u16(&self, field: Field) -> u16 {
        match self.mem.get(range(field)) {
            Some(&[a, b]) => u16::from_le_bytes([a, b]),
            _ => 0,
        }
    }

    /// Whether a servo's torque is on.
    pub fn torque_on(&self) -> bool {
        matches!(self.kind, DeviceKind::Servo { .. }) && self.get_u8(x_series::TORQUE_ENABLE) != 0
    }

    /// Status Return Level (2 = reply to everything; the boards always reply).
    pub fn status_return_level(&self) -> u8 {
        match self.kind {
            DeviceKind::Servo { .. } => self.get_u8(x_series::STATUS_RETURN_LEVEL),
            _ => 2,
        }
    }

    /// READ access: the bytes `addr..addr+len`.
    pub fn read(&self, addr: u16, len: u16) -> Result<&[u8], ErrorCode> {
        dxl::table::read(&self.mem, addr, len)
    }

    fn writable(&self, a: usize) -> bool {
        match self.kind {
            DeviceKind::Servo { .. } => {
                let ro = a <= 6 || a == 70 || (120..=147).contains(&a);
                let locked = a < usize::from(x_series::TORQUE_ENABLE.addr) && self.torque_on();
                !ro && !locked
            }
            _ => a == usize::from(foot::ID.addr) || a == usize::from(foot::RETURN_DELAY_TIME.addr),
        }
    }

    /// The value `data` (written at `addr`) gives to the byte at `field.addr`, if it covers it.
    fn covered_u8(addr: usize, data: &[u8], field: Field) -> Option<u8> {
        data.get(usize::from(field.addr).checked_sub(addr)?)
            .copied()
    }

    /// WRITE access with the protocol's checks; on success the bytes are stored.
    pub fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), ErrorCode> {
        let start = usize::from(addr);
        let end = start + data.len();
        if end > self.mem.len() {
            return Err(ErrorCode::DataRange);
        }
        if !(start..end).all(|a| self.writable(a)) {
            return Err(ErrorCode::Access);
        }
        if let Some(id) = Self::covered_u8(start, data, x_series::ID) {
            if id > dxl::packet::MAX_DEVICE_ID {
                return Err(ErrorCode::DataRange);
            }
        }
        if matches!(self.kind, DeviceKind::Servo { .. }) {
            if let Some(t) = Self::covered_u8(start, data, x_series::TORQUE_ENABLE) {
                if t > 1 {
                    return Err(ErrorCode::DataRange);
                }
            }
            if let Some(m) = Self::covered_u8(start, data, x_series::OPERATING_MODE) {
                if m != x_series::MODE_POSITION && m != x_series::MODE_EXTENDED_POSITION {
                    return Err(ErrorCode::DataRange);
                }
            }
            if let Some(s) = Self::covered_u8(start, data, x_series::STATUS_RETURN_LEVEL) {
                if s > 2 {
                    return Err(ErrorCode::DataRange);
                }
            }
            let g = range(x_series::GOAL_POSITION);
            if start <= g.start && end >= g.end {
                let o = g.start - start;
                let v = i32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]]);
                let extended = Self::covered_u8(start, data, x_series::OPERATING_MODE)
                    .unwrap_or(self.get_u8(x_series::OPERATING_MODE))
                    == x_series::MODE_EXTENDED_POSITION;
                let ok = if extended {
                    v.abs() <= x_series::MAX_EXTENDED_TICKS
                } else {
                    (0..x_series::TICKS_PER_TURN).contains(&v)
                };
                if !ok {
                    return Err(ErrorCode::DataLimit);
                }
            }
        }
        self.mem[start..end].copy_from_slice(data);
        self.id = self.mem[usize::from(x_series::ID.addr)];
        Ok(())
    }

    /// REBOOT: torque off, registered write dropped.
    pub fn reboot(&mut self) {
        if matches!(self.kind, DeviceKind::Servo { .. }) {
            self.set(x_series::TORQUE_ENABLE, &[0]);
        }
        self.pending = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn servo_access_rules() {
        let mut d = Device::servo(3, 2, 2048);
        assert_eq!(d.model(), x_series::MODEL_XM430_W350);
        assert_eq!(d.write(9, &[10]), Ok(()));
        assert_eq!(d.read(9, 1), Ok(&[10u8][..]));
        assert_eq!(d.write(132, &[0; 4]), Err(ErrorCode::Access));
        assert_eq!(d.write(64, &[2]), Err(ErrorCode::DataRange));
        assert_eq!(d.write(64, &[1]), Ok(()));
        assert_eq!(d.write(9, &[0]), Err(ErrorCode::Access));
        assert_eq!(
            d.write(116, &5000i32.to_le_bytes()),
            Err(ErrorCode::DataLimit)
        );
        assert_eq!(d.write(116, &3000i32.to_le_bytes()), Ok(()));
        assert_eq!(d.get_i32(x_series::GOAL_POSITION), 3000);
        assert_eq!(d.read(660, 4), Err(ErrorCode::DataRange));
    }

    #[test]
    fn servo_answers_the_monitor_registers() {
        // The firmware's servo monitor reads Hardware Error Status (70) and 126 ..= 146
        // (Present Current, Input Voltage, Temperature) from every servo while walking.
        let d = Device::servo(3, 2, 2048);
        assert_eq!(d.read(70, 1), Ok(&[0u8][..]));
        let b = d.read(126, 21).unwrap();
        assert_eq!(i16::from_le_bytes([b[0], b[1]]), 0);
        assert_eq!(u16::from_le_bytes([b[18], b[19]]), 120, "12.0 V");
        assert_eq!(b[20], 36, "36 °C");
    }

    #[test]
    fn board_access_rules() {
        let mut d = Device::foot(111, 0);
        assert_eq!(d.model(), foot::MODEL_NUMBER_VALUE);
        assert_eq!(d.write(128, &[1]), Err(ErrorCode::Access));
        assert_eq!(d.write(9, &[0]), Ok(()));
        assert_eq!(d.write(7, &[113]), Ok(()));
        assert_eq!(d.id, 113);
    }
}
