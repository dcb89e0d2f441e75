//! The driver of the OpenCR 1.0's on-board IMU, an InvenSense MPU-9250 on SPI (registers and
//! scale: [`walker_contract::mpu9250`], one place for this driver and a simulated chip). Over
//! any `embedded-hal` [`SpiDevice`] (the board owns the bus and the chip select), so the same
//! code runs against a register model in the host tests. Hand-written: the maintained MPU-9250
//! crates are I²C-first, allocate, or pull in the magnetometer, which the walk does not read.
//!
//! Start-up ([`Mpu9250::start`]): WHO_AM_I must read 0x71; H_RESET, a 100 ms wait, then the
//! configuration [`walker_contract::mpu9250::INIT`], each register read back. Each tick
//! ([`Mpu9250::sample`]): one 15-byte transaction (the address and the 14-byte burst) into an
//! [`ImuSample`] (µrad/s, µm/s², the driver's own sample counter), the sensor's axes.
//!
//! The driver keeps no port: the board lends it its SPI device (and, to start, its way of
//! waiting) for each call, so that a board whose SPI and clock are one value (QEMU's, whose
//! transfers and waits both move its virtual clock) can lend it.

use dxl::table::imu::ImuSample;
use embedded_hal::delay::DelayNs;
use embedded_hal::spi::{Operation, SpiDevice};
use walker_contract::mpu9250 as reg;

/// Why the IMU did not start or give a sample ([`ImuError::code`]: its code in the log).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImuError {
    /// The SPI transfer failed.
    Bus,
    /// WHO_AM_I read this instead of an MPU-9250's 0x71 (an ICM-20648, the later OpenCR
    /// boards' chip, reads 0x00 there).
    NotMpu9250(u8),
    /// A configuration register read back this other value: (register, value).
    ConfigMismatch(u8, u8),
}

impl ImuError {
    /// The error's code (1 the SPI, 2 another chip, 3 a register that did not take) and its
    /// byte (what WHO_AM_I read; the register that did not take; 0).
    pub fn code(&self) -> (u8, u8) {
        match *self {
            ImuError::Bus => (1, 0),
            ImuError::NotMpu9250(who) => (2, who),
            ImuError::ConfigMismatch(r, _) => (3, r),
        }
    }
}

/// A started MPU-9250: its sample counter.
#[derive(Debug)]
pub struct Mpu9250 {
    counter: u16,
}

impl Mpu9250 {
    /// Checks the chip on `port`, resets and configures it (about 100 ms of `port`'s wait).
    pub fn start<P: SpiDevice + DelayNs>(port: &mut P) -> Result<Self, ImuError> {
        let who = read_register(port, reg::WHO_AM_I)?;
        if who != reg::WHO_AM_I_VALUE {
            return Err(ImuError::NotMpu9250(who));
        }
        write_register(port, reg::PWR_MGMT_1, reg::H_RESET)?;
        port.delay_us(reg::RESET_US);
        for (r, v) in reg::INIT {
            write_register(port, r, v)?;
            let back = read_register(port, r)?;
            if back != v {
                return Err(ImuError::ConfigMismatch(r, back));
            }
        }
        Ok(Mpu9250 { counter: 0 })
    }

    /// One burst over `spi` as an [`ImuSample`] (its counter counts the driver's good
    /// samples).
    pub fn sample<S: SpiDevice>(&mut self, spi: &mut S) -> Result<ImuSample, ImuError> {
        let mut raw = [0u8; reg::BURST_LEN];
        spi.transaction(&mut [
            Operation::Write(&[reg::ACCEL_XOUT_H | reg::READ]),
            Operation::Read(&mut raw),
        ])
        .map_err(|_| ImuError::Bus)?;
        let (gyro_urad_s, accel_um_s2) = reg::decode_micro(&raw);
        self.counter = self.counter.wrapping_add(1);
        Ok(ImuSample {
            gyro_urad_s,
            accel_um_s2,
            counter: self.counter,
        })
    }
}

fn read_register<S: SpiDevice>(spi: &mut S, r: u8) -> Result<u8, ImuError> {
    let mut v = [0u8; 1];
    spi.transaction(&mut [Operation::Write(&[r | reg::READ]), Operation::Read(&mut v)])
        .map_err(|_| ImuError::Bus)?;
    Ok(v[0])
}

fn write_register<S: SpiDevice>(spi: &mut S, r: u8, v: u8) -> Result<(), ImuError> {
    spi.write(&[r & !reg::READ, v]).map_err(|_| ImuError::Bus)
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::spi::{ErrorKind, ErrorType};
    use std::vec::Vec;

    /// A register model of the chip: 128 registers, reset values 0 but WHO_AM_I; a write
    /// transaction sets consecutive registers, a read returns them; H_RESET clears them.
    struct Chip {
        regs: [u8; 128],
        who: u8,
        writes: Vec<(u8, u8)>,
        reset_seen: bool,
        fail: bool,
        /// A register that ignores writes (a broken chip).
        stuck: Option<u8>,
        /// Time waited on the port, µs.
        waited_us: u32,
    }

    impl Chip {
        fn new() -> Self {
            let mut regs = [0u8; 128];
            regs[usize::from(reg::WHO_AM_I)] = reg::WHO_AM_I_VALUE;
            Chip {
                regs,
                who: reg::WHO_AM_I_VALUE,
                writes: Vec::new(),
                reset_seen: false,
                fail: false,
                stuck: None,
                waited_us: 0,
            }
        }
    }

    impl ErrorType for Chip {
        type Error = ErrorKind;
    }

    impl SpiDevice for Chip {
        fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
            if self.fail {
                return Err(ErrorKind::Other);
            }
            let mut addr: Option<(u8, bool)> = None;
            for op in ops.iter_mut() {
                match op {
                    Operation::Write(bytes) => {
                        for &b in bytes.iter() {
                            match addr {
                                None => addr = Some((b & 0x7F, b & reg::READ != 0)),
                                Some((a, false)) => {
                                    self.writes.push((a, b));
                                    if a == reg::PWR_MGMT_1 && b & reg::H_RESET != 0 {
                                        self.regs = [0; 128];
                                        self.regs[usize::from(reg::WHO_AM_I)] = self.who;
                                        self.reset_seen = true;
                                    } else if self.stuck != Some(a) {
                                        self.regs[usize::from(a)] = b;
                                    }
                                    addr = Some((a + 1, false));
                                }
                                Some((_, true)) => {}
                            }
                        }
                    }
                    Operation::Read(buf) => {
                        let (a, _) = addr.unwrap_or((0, true));
                        for (i, b) in buf.iter_mut().enumerate() {
                            *b = self.regs[(usize::from(a) + i) % 128];
                        }
                    }
                    _ => return Err(ErrorKind::Other),
                }
            }
            self.regs[usize::from(reg::WHO_AM_I)] = self.who;
            Ok(())
        }
    }

    impl DelayNs for Chip {
        fn delay_ns(&mut self, ns: u32) {
            self.waited_us = self.waited_us.saturating_add(ns / 1000);
        }
    }

    #[test]
    fn start_checks_the_chip_resets_it_and_writes_the_configuration() {
        let mut chip = Chip::new();
        Mpu9250::start(&mut chip).unwrap();
        assert!(chip.reset_seen);
        assert!(
            chip.waited_us >= reg::RESET_US,
            "waited {} µs after the reset",
            chip.waited_us
        );
        // The reset first, then the configuration in order.
        let mut want = vec![(reg::PWR_MGMT_1, reg::H_RESET)];
        want.extend(reg::INIT);
        assert_eq!(chip.writes, want);
        assert_eq!(chip.regs[usize::from(reg::GYRO_CONFIG)], 0x18);
        assert_eq!(chip.regs[usize::from(reg::ACCEL_CONFIG)], 0x18);
    }

    #[test]
    fn each_error_has_its_code() {
        assert_eq!(ImuError::Bus.code(), (1, 0));
        assert_eq!(ImuError::NotMpu9250(0xE0).code(), (2, 0xE0));
        assert_eq!(ImuError::ConfigMismatch(0x1B, 0).code(), (3, 0x1B));
    }

    #[test]
    fn another_chip_a_dead_bus_or_a_register_that_does_not_take_stop_the_start() {
        let mut other = Chip {
            who: 0x70,
            ..Chip::new()
        };
        other.regs[usize::from(reg::WHO_AM_I)] = 0x70;
        assert_eq!(
            Mpu9250::start(&mut other).err(),
            Some(ImuError::NotMpu9250(0x70))
        );
        let mut dead = Chip {
            fail: true,
            ..Chip::new()
        };
        assert_eq!(Mpu9250::start(&mut dead).err(), Some(ImuError::Bus));
        let mut stuck = Chip {
            stuck: Some(reg::GYRO_CONFIG),
            ..Chip::new()
        };
        assert_eq!(
            Mpu9250::start(&mut stuck).err(),
            Some(ImuError::ConfigMismatch(reg::GYRO_CONFIG, 0))
        );
    }

    #[test]
    fn a_sample_is_the_burst_in_micro_units_with_a_counter() {
        let mut chip = Chip::new();
        let mut imu = Mpu9250::start(&mut chip).unwrap();
        // Upright, turning: 1 g on z; 0.5 rad/s about y (pitching), −0.2 about z.
        let burst = reg::encode(&reg::Reading {
            gyro_rad_s: [0.0, 0.5, -0.2],
            accel_m_s2: [0.0, 0.0, reg::G],
        });
        chip.regs[usize::from(reg::ACCEL_XOUT_H)..][..reg::BURST_LEN].copy_from_slice(&burst);
        let s = imu.sample(&mut chip).unwrap();
        let lsb_urad = 1e6 * core::f64::consts::PI / (180.0 * 16.4);
        assert!((f64::from(s.gyro_urad_s[1]) - 5e5).abs() <= 0.5 * lsb_urad + 1.0);
        assert!((f64::from(s.gyro_urad_s[2]) + 2e5).abs() <= 0.5 * lsb_urad + 1.0);
        assert_eq!(s.gyro_urad_s[0], 0);
        assert!((f64::from(s.accel_um_s2[2]) - 9_806_650.0).abs() <= 1.0);
        assert_eq!(s.counter, 1);
        assert_eq!(imu.sample(&mut chip).unwrap().counter, 2);
        chip.fail = true;
        assert_eq!(imu.sample(&mut chip), Err(ImuError::Bus));
    }
}
