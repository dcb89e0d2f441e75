//! The servo monitor: while the robot walks (and while a graded stop lowers it), every leg
//! servo and every held servo (a robot's arms and head: the bus description's `held`) is
//! watched, one small READ at a time, round-robin:
//!
//! | READ | addresses | bytes on the bus | checks |
//! | --- | --- | --- | --- |
//! | status | Torque Enable .. Hardware Error Status (64 ..= 70, 7 bytes) | 14 + 18 | torque found off, Hardware Error Status ≠ 0 |
//! | supply | Present Input Voltage, Present Temperature (144 ..= 146, 3 bytes) | 14 + 14 | voltage, temperature |
//! | current | Present Current (126 ..= 127, 2 bytes) | 14 + 13 | current |
//!
//! The round is four passes over the n servos (12 legs and the held ones), status, supply,
//! status, current: 48 READs for a robot without held servos, every servo READ every 12 READs and
//! its status every 24 (the OP3's 20 servos: every 20 and 40, 50 ms and 100 ms).
//!
//! The READs are spread in time, not in ticks: one every [`READ_EVERY_US`] (2.5 ms), so every
//! servo answers (or not) every 30 ms and reports its torque and hardware error every 60 ms at
//! any tick period up to 5 ms — two READs a tick at the 200 Hz default (≈ 0.55 ms of bus at 1
//! Mbps), at most one a tick at 1 kHz (≈ 62 µs at 4.5 Mbps: what lets the Cortex-M3's 1 kHz
//! tick fit its period, BENCHMARKS.md "The Cortex-M3 board at 1 kHz"). Longer ticks read
//! [`MAX_READS_PER_TICK`] a tick, so the monitor never takes more of a tick's bus time than at
//! 200 Hz.
//!
//! Checks ([`ServoCheck`], limits [`ServoLimits`] from the parameter table):
//! * A READ left unanswered is READ again at the next turn (2.5 ms later) instead of moving on;
//!   [`ServoLimits::miss_limit`] misses of one servo in a row make it lost: `ServoLost` (exit
//!   24). With the default 8 a dead servo is found within 30 + 7 · 2.5 = 47.5 ms of its death,
//!   and a bus that loses one reply in five stops a walk for nothing once in about 400,000
//!   misses (0.2⁸).
//!   A lost servo is still READ at its turns (once each), to see it come back.
//! * Torque Enable read 0 (a servo that browned out comes back limp): its Goal Position is
//!   written again (the last target sent) and its torque turned on again, and the robot stops
//!   (`ServoFault` `TorqueOff`).
//! * Hardware Error Status ≠ 0, temperature > `servo_temp_max` °C, voltage (0.1 V units)
//!   outside [`servo_volt_min`, `servo_volt_max`]: `ServoFault` (exit 21).
//! * |current| (2.69 mA units) > `servo_current_max` in two current READs of one servo
//!   in a row (one round apart: 120 ms with 12 servos, 200 ms with 20): `ServoFault` (exit
//!   21). A shorted or blocked motor draws it all along (and the servo flags its own Overload
//!   and Electrical Shock in Hardware Error Status); a knee back-driven at a landing draws it
//!   for tens of milliseconds, and a motor heats over seconds: one reading over the limit is
//!   not a finding.
//!
//! What each stop does (a hardware error goes limp at once; the others are graded stops) is the
//! supervisor's ([`crate::supervisor`], docs/stops.md).

use dxl::table::x_series;
use gait_core::robot::LEG_JOINTS;
use walker_contract::bus_map::{servo_slot_id, servo_slots, TickMap, MAX_HELD};
use walker_contract::codes::ServoCheck;
use walker_contract::config::ServoLimits;

use crate::board::{Clock, ServoBus};
use crate::bus::BoardMaster;
use crate::startup::held_goal;
use crate::supervisor::StopReason;

/// Time between two of the monitor's READs, µs: 12 READs (one for each servo) make 30 ms.
pub const READ_EVERY_US: u32 = 2_500;
/// Most READs in one tick (a tick longer than 5 ms does not make the monitor's bus time grow).
pub const MAX_READS_PER_TICK: u32 = 2;
/// READs a round makes per servo: status, supply, status, current.
pub const PASSES: usize = 4;

/// First address of the status READ (Torque Enable).
pub const STATUS_ADDR: u16 = x_series::TORQUE_ENABLE.addr;
/// Length of the status READ: Torque Enable (64) ..= Hardware Error Status (70).
pub const STATUS_LEN: usize = (x_series::HARDWARE_ERROR_STATUS.addr
    + x_series::HARDWARE_ERROR_STATUS.len
    - STATUS_ADDR) as usize;
/// First address of the voltage and temperature READ (Present Input Voltage).
pub const SUPPLY_ADDR: u16 = x_series::PRESENT_INPUT_VOLTAGE.addr;
/// Length of that READ: Present Input Voltage (144, 2 bytes) and Present Temperature (146).
pub const SUPPLY_LEN: usize =
    (x_series::PRESENT_TEMPERATURE.addr + x_series::PRESENT_TEMPERATURE.len - SUPPLY_ADDR) as usize;

/// Round-robin state: the next READ of the round, the time owed to the READs (µs) and each
/// servo's unanswered READs in a row.
#[derive(Clone, Debug, Default)]
pub struct ServoMonitor {
    next: usize,
    credit_us: u32,
    misses: [u8; LEG_JOINTS + MAX_HELD],
    /// Bit j: servo j's last Present Current READ was over the limit.
    current_over: u32,
    /// The last Present Input Voltage read, 0.1 V (0: none yet).
    supply_dv: u16,
}

/// What one READ of a servo answered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ServoHealth {
    /// Torque Enable and Hardware Error Status.
    Status {
        /// Torque Enable (0 off, 1 on).
        torque: u8,
        /// Hardware Error Status.
        error: u8,
    },
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
        ServoHealth::Status { error, .. } if error != 0 => {
            fault(ServoCheck::HardwareError, u16::from(error))
        }
        ServoHealth::Status { torque: 0, .. } => fault(ServoCheck::TorqueOff, 0),
        ServoHealth::Status { .. } => None,
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
    /// Starts with the first leg servo's status.
    pub const fn new() -> Self {
        ServoMonitor {
            next: 0,
            credit_us: 0,
            misses: [0; LEG_JOINTS + MAX_HELD],
            current_over: 0,
            supply_dv: 0,
        }
    }

    /// The leg servos' supply: the last Present Input Voltage read (0.1 V; 0 before the first).
    pub fn supply_dv(&self) -> u16 {
        self.supply_dv
    }

    /// One tick of `period_us`: the READs that fell due (one every [`READ_EVERY_US`], at most
    /// [`MAX_READS_PER_TICK`]), each checked; the first stop reason found. `goals` are the
    /// leg servos' Goal Positions last sent (ticks): a leg servo found limp gets its own back
    /// before its torque, a held servo its pose (through the rad → tick map `ticks`).
    pub fn poll<B: ServoBus + Clock>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        lim: &ServoLimits,
        period_us: u32,
        goals: &[i32; LEG_JOINTS],
        ticks: &TickMap,
    ) -> Option<StopReason> {
        let cap = READ_EVERY_US * MAX_READS_PER_TICK;
        self.credit_us = self.credit_us.saturating_add(period_us).min(cap);
        while self.credit_us >= READ_EVERY_US {
            self.credit_us -= READ_EVERY_US;
            if let Some(fault) = self.read_next(bus, lim, goals, ticks) {
                return Some(fault);
            }
        }
        None
    }

    /// A current reading over the limit counts only as the second in a row of servo `j` (its
    /// slot in the round); any other finding passes as it is.
    fn debounce(
        &mut self,
        j: usize,
        health: &ServoHealth,
        found: Option<StopReason>,
    ) -> Option<StopReason> {
        if !matches!(health, ServoHealth::Current(_)) {
            return found;
        }
        let bit = 1u32.checked_shl(j as u32).unwrap_or(0);
        if found.is_none() {
            self.current_over &= !bit;
            return None;
        }
        let before = self.current_over & bit != 0;
        self.current_over |= bit;
        if before {
            found
        } else {
            None
        }
    }

    /// The next READ of the round and its checks.
    fn read_next<B: ServoBus + Clock>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        lim: &ServoLimits,
        goals: &[i32; LEG_JOINTS],
        ticks: &TickMap,
    ) -> Option<StopReason> {
        let devices = bus.devices();
        let n = servo_slots(devices);
        let round = PASSES * n;
        let k = self.next % round;
        let j = k % n;
        let id = servo_slot_id(devices, j)?;
        let health = match k / n {
            1 => {
                let mut b = [0u8; SUPPLY_LEN];
                bus.master().read(id, SUPPLY_ADDR, &mut b).ok().map(|()| {
                    let [lo, hi, temperature_c] = b;
                    ServoHealth::Supply {
                        voltage_dv: u16::from_le_bytes([lo, hi]),
                        temperature_c,
                    }
                })
            }
            3 => {
                let mut b = [0u8; 2];
                bus.master()
                    .read(id, x_series::PRESENT_CURRENT.addr, &mut b)
                    .ok()
                    .map(|()| ServoHealth::Current(i16::from_le_bytes(b)))
            }
            _ => {
                let mut b = [0u8; STATUS_LEN];
                bus.master().read(id, STATUS_ADDR, &mut b).ok().map(|()| {
                    let [torque, .., error] = b;
                    ServoHealth::Status { torque, error }
                })
            }
        };
        let misses = self.misses.get_mut(j)?;
        let Some(health) = health else {
            // Unanswered: READ again at the next turn, until the servo counts as lost (then
            // once a turn, to see it come back).
            let lost_before = *misses >= lim.miss_limit;
            *misses = misses.saturating_add(1);
            if lost_before {
                self.next = (k + 1) % round;
            }
            // Reported once, when the count reaches the limit.
            return (*misses == lim.miss_limit).then_some(StopReason::ServoLost { id });
        };
        *misses = 0;
        self.next = (k + 1) % round;
        if let ServoHealth::Supply { voltage_dv, .. } = health {
            self.supply_dv = voltage_dv;
        }
        let found = self.debounce(j, &health, check(id, &health, lim));
        if let Some(StopReason::ServoFault {
            check: ServoCheck::TorqueOff,
            ..
        }) = found
        {
            // Limp after a brown-out: its last goal back, then its torque (best effort: the
            // stop is on its way whatever the bus says).
            let goal = match j.checked_sub(LEG_JOINTS) {
                None => goals.get(j).copied(),
                Some(h) => devices.held.get(h).map(|h| held_goal(ticks, h)),
            };
            let goal = goal.unwrap_or(0);
            let _ = bus
                .master()
                .write(id, x_series::GOAL_POSITION.addr, &goal.to_le_bytes());
            let _ = bus.master().write(id, x_series::TORQUE_ENABLE.addr, &[1]);
        }
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_limit() {
        let lim = ServoLimits::xm430();
        assert_eq!((SUPPLY_LEN, STATUS_LEN), (3, 7));
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
        // Overload bit (5) of Hardware Error Status, whatever Torque Enable reads (the servo
        // cut its own torque); torque found off.
        let status = |torque, error| ServoHealth::Status { torque, error };
        assert_eq!(
            check(3, &status(0, 0x20), &lim),
            f(ServoCheck::HardwareError, 0x20)
        );
        assert_eq!(check(3, &status(0, 0), &lim), f(ServoCheck::TorqueOff, 0));
        assert_eq!(check(3, &status(1, 0), &lim), None);
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

    #[test]
    fn a_current_over_the_limit_counts_at_the_second_reading_in_a_row() {
        let lim = ServoLimits::xm430();
        let mut m = ServoMonitor::new();
        let over = ServoHealth::Current(1000);
        let under = ServoHealth::Current(-900);
        let read = |m: &mut ServoMonitor, j: usize, id: u8, h: ServoHealth| {
            m.debounce(j, &h, check(id, &h, &lim))
        };
        let fault = Some(StopReason::ServoFault {
            id: 19,
            check: ServoCheck::Current,
            reading: 2690,
        });
        // Servo slot 19 (the OP3's last held servo): over, under, over, over.
        assert_eq!(read(&mut m, 19, 19, over), None);
        assert_eq!(read(&mut m, 19, 19, under), None);
        assert_eq!(read(&mut m, 19, 19, over), None);
        // Another servo's reading in between does not clear slot 19's.
        assert_eq!(read(&mut m, 3, 4, under), None);
        assert_eq!(read(&mut m, 3, 4, over), None);
        assert_eq!(read(&mut m, 19, 19, over), fault);
        // The other checks are not held back: one hot reading stops.
        let hot = ServoHealth::Supply {
            voltage_dv: 120,
            temperature_c: 71,
        };
        assert!(read(&mut ServoMonitor::new(), 0, 1, hot).is_some());
        // Every slot has its bit.
        const { assert!(LEG_JOINTS + MAX_HELD <= 32) };
    }
}
