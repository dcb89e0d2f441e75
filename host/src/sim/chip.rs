//! The controller board's IMU chip as the simulator answers it on the lock-step pipes
//! ([`walker_contract::lockstep::SPI`]): an MPU-9250's registers over SPI
//! ([`walker_contract::mpu9250`]), its sensor burst the simulated trunk's rates and specific
//! force turned into the chip's axes ((I2) of [`gait_core::robot::ImuAxes`]).
//!
//! A transfer's first byte is the register address (bit 7: read); a read answers the
//! registers from there on, a write sets them (WHO_AM_I and the sensor registers are read
//! only). The registers reset to 0 but PWR_MGMT_1 (0x01) and WHO_AM_I (0x71); H_RESET resets
//! them. The burst follows the configured full scales (GYRO_FS_SEL, ACCEL_FS_SEL): a driver
//! that configured them otherwise than it decodes reads wrong values, as on the real chip;
//! an axis turned off in PWR_MGMT_2 reads 0.

use walker_contract::mpu9250 as reg;

/// Registers of the chip's map.
const REGISTERS: usize = 128;

/// The simulated chip.
#[derive(Clone, Debug)]
pub struct Mpu9250Chip {
    regs: [u8; REGISTERS],
    /// What the sensors measure now, chip axes.
    reading: reg::Reading,
}

impl Default for Mpu9250Chip {
    fn default() -> Self {
        Self::new()
    }
}

impl Mpu9250Chip {
    /// A chip after power-on, measuring nothing.
    pub fn new() -> Self {
        let mut c = Mpu9250Chip {
            regs: [0; REGISTERS],
            reading: reg::Reading {
                gyro_rad_s: [0.0; 3],
                accel_m_s2: [0.0; 3],
            },
        };
        c.reset();
        c
    }

    fn reset(&mut self) {
        self.regs = [0; REGISTERS];
        self.regs[usize::from(reg::PWR_MGMT_1)] = 0x01;
        self.regs[usize::from(reg::WHO_AM_I)] = reg::WHO_AM_I_VALUE;
    }

    /// What the sensors measure from now on (chip axes, rad/s and m/s²).
    pub fn measure(&mut self, reading: reg::Reading) {
        self.reading = reading;
    }

    /// The sensor burst as configured: each full scale 2^(3 − FS_SEL) times finer than
    /// ±2000 °/s and ±16 g; an axis turned off reads 0.
    fn burst(&self) -> [u8; reg::BURST_LEN] {
        let fine = |r: u8| f64::from(1u8 << (3 - ((self.regs[usize::from(r)] >> 3) & 3)));
        let off = self.regs[usize::from(reg::PWR_MGMT_2)];
        let (g, a) = (fine(reg::GYRO_CONFIG), fine(reg::ACCEL_CONFIG));
        // PWR_MGMT_2: bits 5:3 accelerometer x, y, z off; bits 2:0 gyroscope x, y, z off.
        let on = |bit: u8| if off & (1 << bit) == 0 { 1.0 } else { 0.0 };
        let r = &self.reading;
        reg::encode(&reg::Reading {
            gyro_rad_s: [0, 1, 2].map(|k| r.gyro_rad_s[k] * g * on(2 - k as u8)),
            accel_m_s2: [0, 1, 2].map(|k| r.accel_m_s2[k] * a * on(5 - k as u8)),
        })
    }

    /// One chip-select-low transfer: `mosi` in, one byte out for each.
    pub fn transfer(&mut self, mosi: &[u8]) -> Vec<u8> {
        let mut miso = vec![0u8; mosi.len()];
        let Some((&first, rest)) = mosi.split_first() else {
            return miso;
        };
        let start = usize::from(first & !reg::READ);
        if first & reg::READ != 0 {
            let burst = self.burst();
            let from = usize::from(reg::ACCEL_XOUT_H);
            for (k, out) in miso.iter_mut().skip(1).enumerate() {
                let a = (start + k) % REGISTERS;
                *out = match a.checked_sub(from) {
                    Some(i) if i < reg::BURST_LEN => burst[i],
                    _ => self.regs[a],
                };
            }
        } else {
            for (k, &v) in rest.iter().enumerate() {
                let a = (start + k) % REGISTERS;
                let sensor = (usize::from(reg::ACCEL_XOUT_H)..usize::from(reg::ACCEL_XOUT_H) + 14)
                    .contains(&a);
                if a == usize::from(reg::PWR_MGMT_1) && v & reg::H_RESET != 0 {
                    self.reset();
                } else if a != usize::from(reg::WHO_AM_I) && !sensor {
                    self.regs[a] = v;
                }
            }
        }
        miso
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(c: &mut Mpu9250Chip, r: u8, n: usize) -> Vec<u8> {
        let mut mosi = vec![0u8; n + 1];
        mosi[0] = r | reg::READ;
        c.transfer(&mosi)[1..].to_vec()
    }

    /// The start-up the firmware's driver makes (WHO_AM_I, H_RESET, the configuration read
    /// back), then a burst decoded as the driver decodes it: the reading back to within half
    /// a bit.
    #[test]
    fn the_chip_answers_the_drivers_start_and_burst() {
        let mut c = Mpu9250Chip::new();
        assert_eq!(read(&mut c, reg::WHO_AM_I, 1), [0x71]);
        c.transfer(&[reg::GYRO_CONFIG, 0x08]);
        c.transfer(&[reg::PWR_MGMT_1, reg::H_RESET]);
        assert_eq!(read(&mut c, reg::GYRO_CONFIG, 1), [0]);
        assert_eq!(read(&mut c, reg::PWR_MGMT_1, 1), [0x01]);
        for (r, v) in reg::INIT {
            c.transfer(&[r, v]);
            assert_eq!(read(&mut c, r, 1), [v]);
        }
        c.transfer(&[reg::WHO_AM_I, 0x00]);
        assert_eq!(read(&mut c, reg::WHO_AM_I, 1), [0x71]);
        let r = reg::Reading {
            gyro_rad_s: [0.3, -1.2, 0.05],
            accel_m_s2: [-1.0, 0.5, 9.7],
        };
        c.measure(r);
        let burst: [u8; reg::BURST_LEN] = read(&mut c, reg::ACCEL_XOUT_H, reg::BURST_LEN)
            .try_into()
            .unwrap();
        let back = reg::decode(&burst);
        let lsb_g = std::f64::consts::PI / (180.0 * reg::GYRO_LSB_PER_DPS);
        let lsb_a = reg::G / reg::ACCEL_LSB_PER_G;
        for k in 0..3 {
            assert!((back.gyro_rad_s[k] - r.gyro_rad_s[k]).abs() <= 0.5 * lsb_g + 1e-12);
            assert!((back.accel_m_s2[k] - r.accel_m_s2[k]).abs() <= 0.5 * lsb_a + 1e-12);
        }
        // A write to a sensor register changes nothing.
        c.transfer(&[reg::ACCEL_XOUT_H, 0x7F, 0x7F]);
        assert_eq!(read(&mut c, reg::ACCEL_XOUT_H, reg::BURST_LEN), burst);
    }

    /// Left at its reset scales (±250 °/s, ±2 g) the burst is 8 times finer than the driver
    /// decodes (a rate of 0.1 rad/s reads 0.8); an axis turned off reads 0.
    #[test]
    fn the_burst_follows_the_configured_scale_and_axes() {
        let mut c = Mpu9250Chip::new();
        c.measure(reg::Reading {
            gyro_rad_s: [0.1, 0.1, 0.1],
            accel_m_s2: [1.0, 1.0, 1.0],
        });
        let raw = |c: &mut Mpu9250Chip| -> reg::Reading {
            reg::decode(
                &read(c, reg::ACCEL_XOUT_H, reg::BURST_LEN)
                    .try_into()
                    .unwrap(),
            )
        };
        let r = raw(&mut c);
        assert!((r.gyro_rad_s[0] - 0.8).abs() < 0.002, "{r:?}");
        assert!((r.accel_m_s2[1] - 8.0).abs() < 0.01, "{r:?}");
        for (a, v) in reg::INIT {
            c.transfer(&[a, v]);
        }
        // Gyroscope y off (bit 1), accelerometer z off (bit 3).
        c.transfer(&[reg::PWR_MGMT_2, 0b0000_1010]);
        let r = raw(&mut c);
        assert!((r.gyro_rad_s[0] - 0.1).abs() < 0.002, "{r:?}");
        assert_eq!((r.gyro_rad_s[1], r.accel_m_s2[2]), (0.0, 0.0));
        assert!((r.accel_m_s2[0] - 1.0).abs() < 0.005, "{r:?}");
    }
}
