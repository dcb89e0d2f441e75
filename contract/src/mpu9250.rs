//! The InvenSense MPU-9250 (the ROBOTIS OpenCR 1.0's on-board IMU, on SPI1) as the firmware's
//! driver configures and reads it and as a simulated one answers: register addresses, the
//! configuration written at start-up, the burst the driver reads each tick and its scale.
//! Source: InvenSense "MPU-9250 Register Map and Descriptions" RM-MPU-9250A-00 rev. 1.6.
//!
//! SPI (mode 0 or 3, ≤ 1 MHz for the registers, ≤ 20 MHz for the sensor registers): a
//! transaction's first byte is the register address, bit 7 set to read ([`READ`]); a read
//! returns consecutive registers for as long as the clock runs.
//!
//! The burst from [`ACCEL_XOUT_H`] is 14 bytes, big-endian i16: accelerometer x, y, z,
//! temperature, gyroscope x, y, z. With the configuration [`INIT`] (gyro ±2000 °/s, accelerometer
//! ±16 g, 41 Hz low-pass on both):
//!
//! ```text
//!   ω = raw / 16.4 °/s = raw · π / (180 · 16.4) rad/s          (M1)
//!   a = raw / 2048 g  = raw · 9.80665 / 2048 m/s²               (M2)
//! ```
//!
//! in the sensor's own axes; the chip's place and turn in the robot are the robot
//! description's, not the driver's.

/// Read flag of a transaction's address byte.
pub const READ: u8 = 0x80;
/// CONFIG: DLPF_CFG (bits 2:0) of the gyroscope and temperature low-pass.
pub const CONFIG: u8 = 0x1A;
/// GYRO_CONFIG: GYRO_FS_SEL (bits 4:3).
pub const GYRO_CONFIG: u8 = 0x1B;
/// ACCEL_CONFIG: ACCEL_FS_SEL (bits 4:3).
pub const ACCEL_CONFIG: u8 = 0x1C;
/// ACCEL_CONFIG 2: A_DLPFCFG (bits 2:0), ACCEL_FCHOICE_B (bit 3).
pub const ACCEL_CONFIG2: u8 = 0x1D;
/// First register of the sensor burst.
pub const ACCEL_XOUT_H: u8 = 0x3B;
/// USER_CTRL: I2C_IF_DIS (bit 4) keeps the chip on SPI.
pub const USER_CTRL: u8 = 0x6A;
/// PWR_MGMT_1: H_RESET (bit 7), CLKSEL (bits 2:0).
pub const PWR_MGMT_1: u8 = 0x6B;
/// PWR_MGMT_2: a set bit turns an accelerometer or gyroscope axis off.
pub const PWR_MGMT_2: u8 = 0x6C;
/// WHO_AM_I.
pub const WHO_AM_I: u8 = 0x75;
/// What WHO_AM_I reads on an MPU-9250.
pub const WHO_AM_I_VALUE: u8 = 0x71;

/// PWR_MGMT_1's H_RESET: every register to its reset value.
pub const H_RESET: u8 = 0x80;
/// Time the chip takes to come back from H_RESET before it is written again, µs (the
/// register map's start-up time for the register access: 100 ms).
pub const RESET_US: u32 = 100_000;

/// The configuration after the reset, in order (register, value): the PLL clock, SPI only, every
/// axis on, the 41 Hz low-pass (gyroscope: delay 5.9 ms; accelerometer: 11.8 ms), ±2000 °/s,
/// ±16 g.
pub const INIT: [(u8, u8); 7] = [
    (PWR_MGMT_1, 0x01),
    (USER_CTRL, 0x10),
    (PWR_MGMT_2, 0x00),
    (CONFIG, 0x03),
    (GYRO_CONFIG, 0x18),
    (ACCEL_CONFIG, 0x18),
    (ACCEL_CONFIG2, 0x03),
];

/// Bytes of the sensor burst from [`ACCEL_XOUT_H`].
pub const BURST_LEN: usize = 14;
/// Gyroscope LSB per °/s at ±2000 °/s.
pub const GYRO_LSB_PER_DPS: f64 = 16.4;
/// Accelerometer LSB per g at ±16 g.
pub const ACCEL_LSB_PER_G: f64 = 2048.0;
/// Standard gravity, m/s² (the accelerometer's g).
pub const G: f64 = 9.80665;

/// One burst in SI units, sensor axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reading {
    /// Angular rate x, y, z, rad/s (M1).
    pub gyro_rad_s: [f64; 3],
    /// Specific force x, y, z, m/s² (M2).
    pub accel_m_s2: [f64; 3],
}

/// The burst's seven big-endian words.
fn words(raw: &[u8; BURST_LEN]) -> [i16; 7] {
    core::array::from_fn(|i| {
        let hi = raw.get(2 * i).copied().unwrap_or(0);
        let lo = raw.get(2 * i + 1).copied().unwrap_or(0);
        i16::from_be_bytes([hi, lo])
    })
}

/// A burst in SI units: (M1), (M2).
pub fn decode(raw: &[u8; BURST_LEN]) -> Reading {
    let w = words(raw);
    let gyro = core::f64::consts::PI / (180.0 * GYRO_LSB_PER_DPS);
    let accel = G / ACCEL_LSB_PER_G;
    Reading {
        gyro_rad_s: [w[4], w[5], w[6]].map(|v| f64::from(v) * gyro),
        accel_m_s2: [w[0], w[1], w[2]].map(|v| f64::from(v) * accel),
    }
}

/// A burst in the firmware's integer units: angular rate in µrad/s, specific force in µm/s²
/// ((M1), (M2) × 10⁶, rounded to the nearest unit), in single precision (the controller's FPU
/// has no double): within half a unit and two parts in 10⁷ of [`decode`]'s (≤ 38 µm/s² at
/// full scale).
pub fn decode_micro(raw: &[u8; BURST_LEN]) -> ([i32; 3], [i32; 3]) {
    let w = words(raw);
    // (M1) and (M2) × 10⁶, once, in the compiler.
    const GYRO_URAD_S_PER_LSB: f32 =
        (1e6 * core::f64::consts::PI / (180.0 * GYRO_LSB_PER_DPS)) as f32;
    const ACCEL_UM_S2_PER_LSB: f32 = (1e6 * G / ACCEL_LSB_PER_G) as f32;
    // Rounded half away from zero; |v| ≤ 3.5·10⁷ and 1.6·10⁸: inside i32.
    let micro = |v: i16, per: f32| {
        let x = f32::from(v) * per;
        (x + if x < 0.0 { -0.5 } else { 0.5 }) as i32
    };
    (
        [w[4], w[5], w[6]].map(|v| micro(v, GYRO_URAD_S_PER_LSB)),
        [w[0], w[1], w[2]].map(|v| micro(v, ACCEL_UM_S2_PER_LSB)),
    )
}

/// The burst a chip reading `r` gives (each word rounded, saturated at the full scale; the
/// temperature word 0 = 21 °C): what a simulated chip answers.
pub fn encode(r: &Reading) -> [u8; BURST_LEN] {
    let gyro = 180.0 * GYRO_LSB_PER_DPS / core::f64::consts::PI;
    let accel = ACCEL_LSB_PER_G / G;
    // Rounded half away from zero; `as` saturates (NaN → 0).
    let word = |v: f64| {
        let half = if v < 0.0 { -0.5 } else { 0.5 };
        ((v + half) as i32).clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
    };
    let [ax, ay, az] = r.accel_m_s2.map(|v| word(v * accel));
    let [gx, gy, gz] = r.gyro_rad_s.map(|v| word(v * gyro));
    let mut out = [0u8; BURST_LEN];
    for (i, w) in [ax, ay, az, 0, gx, gy, gz].into_iter().enumerate() {
        let [hi, lo] = w.to_be_bytes();
        if let Some(b) = out.get_mut(2 * i..2 * i + 2) {
            b.copy_from_slice(&[hi, lo]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The integer units of any burst are (M1), (M2) in double precision times 10⁶, to
        /// within half a unit and single precision's rounding (2.4·10⁻⁷ of the value).
        #[test]
        fn micro_units_are_the_si_reading(raw in proptest::array::uniform14(any::<u8>())) {
            let (g, a) = decode_micro(&raw);
            let r = decode(&raw);
            let close = |got: i32, want: f64| (f64::from(got) - want).abs() <= 0.5 + 2.4e-7 * want.abs();
            for k in 0..3 {
                prop_assert!(close(g[k], r.gyro_rad_s[k] * 1e6), "{} {}", g[k], r.gyro_rad_s[k]);
                prop_assert!(close(a[k], r.accel_m_s2[k] * 1e6), "{} {}", a[k], r.accel_m_s2[k]);
            }
        }
    }

    #[test]
    fn a_burst_by_hand() {
        // accel z = +2048 (1 g), gyro x = +164 (10 °/s), gyro z = −16.4·90 ≈ −1476 (−90 °/s).
        let mut raw = [0u8; BURST_LEN];
        raw[4..6].copy_from_slice(&2048i16.to_be_bytes());
        raw[8..10].copy_from_slice(&164i16.to_be_bytes());
        raw[12..14].copy_from_slice(&(-1476i16).to_be_bytes());
        let r = decode(&raw);
        assert_eq!(r.accel_m_s2, [0.0, 0.0, 9.80665]);
        assert!((r.gyro_rad_s[0] - 10f64.to_radians()).abs() < 1e-12);
        assert!((r.gyro_rad_s[2] + 1476.0 / 16.4 * core::f64::consts::PI / 180.0).abs() < 1e-12);
        assert_eq!(encode(&r), raw);
    }

    #[test]
    fn full_scale_saturates_and_nan_reads_zero() {
        let r = Reading {
            gyro_rad_s: [100.0, -100.0, f64::NAN],
            accel_m_s2: [1e3, -1e3, 0.0],
        };
        let w = words(&encode(&r));
        assert_eq!(w, [i16::MAX, i16::MIN, 0, 0, i16::MAX, i16::MIN, 0]);
    }

    proptest! {
        /// Within the full scale a reading comes back to half an LSB.
        #[test]
        fn encode_then_decode_is_within_half_an_lsb(
            g in proptest::array::uniform3(-34.0f64..34.0),
            a in proptest::array::uniform3(-150.0f64..150.0),
        ) {
            let r = Reading { gyro_rad_s: g, accel_m_s2: a };
            let back = decode(&encode(&r));
            let g_lsb = core::f64::consts::PI / (180.0 * GYRO_LSB_PER_DPS);
            let a_lsb = G / ACCEL_LSB_PER_G;
            for i in 0..3 {
                prop_assert!((back.gyro_rad_s[i] - g[i]).abs() <= 0.5 * g_lsb + 1e-12);
                prop_assert!((back.accel_m_s2[i] - a[i]).abs() <= 0.5 * a_lsb + 1e-12);
            }
        }
    }
}
