//! The servo monitor: while the robot walks, the leg servos' health, one servo after the other
//! (round-robin over the 12), with two small READs a servo: Present Input Voltage and Present
//! Temperature (144 ..= 146, 3 bytes: 14 + 14 bytes on the bus) and Present Current (126 ..= 127,
//! 2 bytes: 14 + 13). A servo that has latched a hardware error sets the alert bit (bit 7 of
//! the error byte) of every status packet it sends: a reply with it is followed by a READ of
//! Hardware Error Status (70, 1 byte) for its value, so a healthy bus never pays for that one.
//!
//! The READs are spread in time, not in ticks: one every [`READ_EVERY_US`] (2.5 ms), so every
//! servo is checked every 60 ms at any tick period up to 5 ms — two READs a tick at the 200 Hz
//! default (≈ 0.55 ms of bus at 1 Mbps), at most one a tick at 1 kHz (≈ 62 µs at 4.5 Mbps: what
//! lets the Cortex-M3's 1 kHz tick fit its period, BENCHMARKS.md "The Cortex-M3 board at 1 kHz"). Longer ticks read
//! [`MAX_READS_PER_TICK`] a tick (every servo every 12 ticks), so the monitor never takes more
//! of a tick's bus time than at 200 Hz.
//!
//! Checks ([`ServoCheck`], limits [`ServoLimits`] from the parameter table):
//! Hardware Error Status ≠ 0; temperature > `servo_temp_max` °C; voltage (0.1 V units) outside
//! [`servo_volt_min`, `servo_volt_max`]; |current| (2.69 mA units) > `servo_current_max`. Any
//! of them stops the robot (`ServoFault`, exit 21). A READ that fails (lost reply) is only
//! counted by the bus statistics: that check of that servo waits for its next turn.

use dxl::table::x_series;
use gait_core::robot::LEG_JOINTS;
use walker_contract::bus_map as ids;
use walker_contract::codes::ServoCheck;
use walker_contract::config::ServoLimits;

use crate::board::{Clock, ServoBus};
use crate::bus::BoardMaster;
use crate::supervisor::StopReason;

/// Time between two of the monitor's READs, µs: 24 READs (two for each of the 12 servos) make
/// a 60 ms round.
pub const READ_EVERY_US: u32 = 2_500;
/// Most READs in one tick (a tick longer than 5 ms does not make the monitor's bus time grow).
pub const MAX_READS_PER_TICK: u32 = 2;

/// First address of the voltage and temperature READ (Present Input Voltage).
pub const SUPPLY_ADDR: u16 = x_series::PRESENT_INPUT_VOLTAGE.addr;
/// Length of that READ: Present Input Voltage (144, 2 bytes) and Present Temperature (146).
pub const SUPPLY_LEN: usize =
    (x_series::PRESENT_TEMPERATURE.addr + x_series::PRESENT_TEMPERATURE.len - SUPPLY_ADDR) as usize;

/// Round-robin state: the next READ (servo `next / 2`, voltage and temperature when `next` is
/// even, current when odd) and the time owed to the READs, µs.
#[derive(Clone, Debug, Default)]
pub struct ServoMonitor {
    next: usize,
    credit_us: u32,
}

/// What one READ of a servo answered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ServoHealth {
    /// Hardware Error Status (read after a reply with the alert bit).
    HardwareError(u8),
    /// Present Input Voltage (0.1 V) and Present Temperature (°C).
    Supply {
        /// Present Input Voltage, 0.1 V units.
        voltage_dv: u16,
        /// Present Temperature, °C.
        temperature_c: u8,
    },
    /// Present Current, raw (2.69 mA units).
    Current(i16),
}

/// The limit that servo `id`'s reading breaks, as a stop reason.
pub fn check(id: u8, h: &ServoHealth, lim: &ServoLimits) -> Option<StopReason> {
    let fault = |check, reading: u16| Some(StopReason::ServoFault { id, check, reading });
    match *h {
        ServoHealth::HardwareError(e) if e != 0 => fault(ServoCheck::HardwareError, u16::from(e)),
        ServoHealth::HardwareError(_) => None,
        ServoHealth::Supply {
            voltage_dv,
            temperature_c,
        } => {
            if temperature_c > lim.temperature_max_c {
                return fault(ServoCheck::Temperature, u16::from(temperature_c));
            }
            let v = f32::from(voltage_dv) * 0.1;
            if v < lim.voltage_min_v {
                return fault(ServoCheck::VoltageLow, voltage_dv);
            }
            if v > lim.voltage_max_v {
                return fault(ServoCheck::VoltageHigh, voltage_dv);
            }
            None
        }
        ServoHealth::Current(raw) => {
            let ma = libm::fabsf(f32::from(raw) * x_series::CURRENT_UNIT_MA);
            if ma > lim.current_max_a * 1000.0 {
                return fault(ServoCheck::Current, libm::fminf(ma, 65_535.0) as u16);
            }
            None
        }
    }
}

impl ServoMonitor {
    /// Starts with the first leg servo.
    pub const fn new() -> Self {
        ServoMonitor {
            next: 0,
            credit_us: 0,
        }
    }

    /// One tick of `period_us`: the READs that fell due (one every [`READ_EVERY_US`], at most
    /// [`MAX_READS_PER_TICK`]), each checked; the first fault found.
    pub fn poll<B: ServoBus + Clock>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        lim: &ServoLimits,
        period_us: u32,
    ) -> Option<StopReason> {
        let cap = READ_EVERY_US * MAX_READS_PER_TICK;
        self.credit_us = self.credit_us.saturating_add(period_us).min(cap);
        while self.credit_us >= READ_EVERY_US {
            self.credit_us -= READ_EVERY_US;
            if let Some(fault) = self.read_next(bus, lim) {
                return Some(fault);
            }
        }
        None
    }

    /// The next READ of the round and its checks (and Hardware Error Status after an alert).
    fn read_next<B: ServoBus + Clock>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        lim: &ServoLimits,
    ) -> Option<StopReason> {
        let k = self.next % (2 * LEG_JOINTS);
        self.next = (k + 1) % (2 * LEG_JOINTS);
        let id = *ids::LEGS.get(k / 2)?;
        let alerts = bus.master().stats().hardware_alerts;
        let health = if k.is_multiple_of(2) {
            let mut b = [0u8; SUPPLY_LEN];
            bus.master().read(id, SUPPLY_ADDR, &mut b).ok().map(|()| {
                let [lo, hi, temperature_c] = b;
                ServoHealth::Supply {
                    voltage_dv: u16::from_le_bytes([lo, hi]),
                    temperature_c,
                }
            })
        } else {
            let mut b = [0u8; 2];
            bus.master()
                .read(id, x_series::PRESENT_CURRENT.addr, &mut b)
                .ok()
                .map(|()| ServoHealth::Current(i16::from_le_bytes(b)))
        };
        // The alert bit of this reply (counted by the master): the error's value.
        if bus.master().stats().hardware_alerts != alerts {
            let mut e = [0u8; 1];
            let read = bus
                .master()
                .read(id, x_series::HARDWARE_ERROR_STATUS.addr, &mut e);
            if read.is_ok() {
                if let Some(fault) = check(id, &ServoHealth::HardwareError(e[0]), lim) {
                    return Some(fault);
                }
            }
        }
        check(id, &health?, lim)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_limit() {
        let lim = ServoLimits::xm430();
        assert_eq!(SUPPLY_LEN, 3);
        let supply = |voltage_dv, temperature_c| ServoHealth::Supply {
            voltage_dv,
            temperature_c,
        };
        let f = |check, reading| {
            Some(StopReason::ServoFault {
                id: 3,
                check,
                reading,
            })
        };
        assert_eq!(check(3, &supply(120, 40), &lim), None);
        assert_eq!(check(3, &ServoHealth::Current(500), &lim), None);
        assert_eq!(check(3, &ServoHealth::HardwareError(0), &lim), None);
        // Overload bit (5) of Hardware Error Status.
        assert_eq!(
            check(3, &ServoHealth::HardwareError(0x20), &lim),
            f(ServoCheck::HardwareError, 0x20)
        );
        assert_eq!(check(3, &supply(120, 70), &lim), None);
        assert_eq!(
            check(3, &supply(120, 71), &lim),
            f(ServoCheck::Temperature, 71)
        );
        assert_eq!(check(3, &supply(100, 40), &lim), None);
        assert_eq!(
            check(3, &supply(99, 40), &lim),
            f(ServoCheck::VoltageLow, 99)
        );
        assert_eq!(
            check(3, &supply(149, 40), &lim),
            f(ServoCheck::VoltageHigh, 149)
        );
        // 2.5 A = 929.4 units of 2.69 mA: 929 passes, −930 (2.5017 A) does not.
        assert_eq!(check(3, &ServoHealth::Current(929), &lim), None);
        assert_eq!(
            check(3, &ServoHealth::Current(-930), &lim),
            f(ServoCheck::Current, 2501)
        );
    }
}
