//! The servo monitor: while the robot walks, one leg servo per tick (round-robin over the 12,
//! so each is read every 12 ticks, 60 ms at 5 ms) is asked for its health with two READs:
//! Hardware Error Status (70, 1 byte) and the block 126 ..= 146 (21 bytes: Present Current at
//! 126, Present Input Voltage at 144, Present Temperature at 146). Bus cost per tick: 14 + 12
//! and 14 + 32 bytes, ≈ 0.72 ms at 1 Mbps.
//!
//! Checks ([`ServoCheck`], limits [`ServoLimits`] from the parameter table):
//! Hardware Error Status ≠ 0; temperature > `servo_temp_max` °C; voltage (0.1 V units) outside
//! [`servo_volt_min`, `servo_volt_max`]; |current| (2.69 mA units) > `servo_current_max`. Any
//! of them stops the robot (`ServoFault`, exit 21). A READ that fails (lost reply) is only
//! counted by the bus statistics: the check of that servo waits for its next turn.

use dxl::table::x_series;
use gait_core::robot::LEG_JOINTS;
use walker_contract::bus_map as ids;
use walker_contract::codes::ServoCheck;
use walker_contract::config::ServoLimits;

use crate::board::{Clock, ServoBus};
use crate::bus::BoardMaster;
use crate::supervisor::StopReason;

/// First address of the block read with the present values.
pub const BLOCK_ADDR: u16 = x_series::PRESENT_CURRENT.addr;
/// Length of the block: Present Current (126) through Present Temperature (146).
pub const BLOCK_LEN: usize = (x_series::PRESENT_TEMPERATURE.addr - BLOCK_ADDR + 1) as usize;

/// Round-robin state.
#[derive(Clone, Debug, Default)]
pub struct ServoMonitor {
    next: usize,
}

/// What one servo answered (`None`: that READ failed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServoHealth {
    /// Hardware Error Status.
    pub hardware_error: Option<u8>,
    /// The block 126 ..= 146.
    pub block: Option<[u8; BLOCK_LEN]>,
}

fn field(block: &[u8; BLOCK_LEN], f: dxl::table::Field) -> Option<&[u8]> {
    let start = usize::from(f.addr.checked_sub(BLOCK_ADDR)?);
    block.get(start..start + usize::from(f.len))
}

/// The first limit servo `id`'s health breaks, as a stop reason.
pub fn check(id: u8, h: &ServoHealth, lim: &ServoLimits) -> Option<StopReason> {
    let fault = |check, reading: u16| Some(StopReason::ServoFault { id, check, reading });
    if let Some(e) = h.hardware_error.filter(|&e| e != 0) {
        return fault(ServoCheck::HardwareError, u16::from(e));
    }
    let b = h.block.as_ref()?;
    if let Some(&[t]) = field(b, x_series::PRESENT_TEMPERATURE) {
        if t > lim.temperature_max_c {
            return fault(ServoCheck::Temperature, u16::from(t));
        }
    }
    if let Some(&[lo, hi]) = field(b, x_series::PRESENT_INPUT_VOLTAGE) {
        let dv = u16::from_le_bytes([lo, hi]);
        let v = f32::from(dv) * 0.1;
        if v < lim.voltage_min_v {
            return fault(ServoCheck::VoltageLow, dv);
        }
        if v > lim.voltage_max_v {
            return fault(ServoCheck::VoltageHigh, dv);
        }
    }
    if let Some(&[lo, hi]) = field(b, x_series::PRESENT_CURRENT) {
        let ma = f32::from(i16::from_le_bytes([lo, hi])) * x_series::CURRENT_UNIT_MA;
        let ma = libm::fabsf(ma);
        if ma > lim.current_max_a * 1000.0 {
            return fault(ServoCheck::Current, libm::fminf(ma, 65_535.0) as u16);
        }
    }
    None
}

impl ServoMonitor {
    /// Starts with the first leg servo.
    pub const fn new() -> Self {
        ServoMonitor { next: 0 }
    }

    /// Reads the next servo's health (two READs) and checks it.
    pub fn poll<B: ServoBus + Clock>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        lim: &ServoLimits,
    ) -> Option<StopReason> {
        let j = self.next % LEG_JOINTS;
        self.next = (j + 1) % LEG_JOINTS;
        let id = *ids::LEGS.get(j)?;
        let mut e = [0u8; 1];
        let hardware_error = bus
            .master()
            .read(id, x_series::HARDWARE_ERROR_STATUS.addr, &mut e)
            .ok()
            .map(|()| e[0]);
        let mut b = [0u8; BLOCK_LEN];
        let block = bus.master().read(id, BLOCK_ADDR, &mut b).ok().map(|()| b);
        check(
            id,
            &ServoHealth {
                hardware_error,
                block,
            },
            lim,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(current_raw: i16, dv: u16, t: u8) -> [u8; BLOCK_LEN] {
        let mut b = [0u8; BLOCK_LEN];
        b[0..2].copy_from_slice(&current_raw.to_le_bytes());
        b[18..20].copy_from_slice(&dv.to_le_bytes());
        b[20] = t;
        b
    }

    fn h(e: u8, b: [u8; BLOCK_LEN]) -> ServoHealth {
        ServoHealth {
            hardware_error: Some(e),
            block: Some(b),
        }
    }

    #[test]
    fn each_limit() {
        let lim = ServoLimits::xm430();
        assert_eq!(BLOCK_LEN, 21);
        let ok = block(500, 120, 40);
        assert_eq!(check(3, &h(0, ok), &lim), None);
        let f = |check, reading| {
            Some(StopReason::ServoFault {
                id: 3,
                check,
                reading,
            })
        };
        // Overload bit (5) of Hardware Error Status.
        assert_eq!(
            check(3, &h(0x20, ok), &lim),
            f(ServoCheck::HardwareError, 0x20)
        );
        assert_eq!(check(3, &h(0, block(500, 120, 70)), &lim), None);
        assert_eq!(
            check(3, &h(0, block(500, 120, 71)), &lim),
            f(ServoCheck::Temperature, 71)
        );
        assert_eq!(check(3, &h(0, block(0, 100, 40)), &lim), None);
        assert_eq!(
            check(3, &h(0, block(0, 99, 40)), &lim),
            f(ServoCheck::VoltageLow, 99)
        );
        assert_eq!(
            check(3, &h(0, block(0, 149, 40)), &lim),
            f(ServoCheck::VoltageHigh, 149)
        );
        // 2.5 A = 929.4 units of 2.69 mA: 929 passes, −930 (2.5017 A) does not.
        assert_eq!(check(3, &h(0, block(929, 120, 40)), &lim), None);
        assert_eq!(
            check(3, &h(0, block(-930, 120, 40)), &lim),
            f(ServoCheck::Current, 2501)
        );
        // A failed READ checks nothing.
        let none = ServoHealth {
            hardware_error: None,
            block: None,
        };
        assert_eq!(check(3, &none, &lim), None);
    }
}
