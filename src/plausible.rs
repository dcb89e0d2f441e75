//! Plausibility of the sensor boards' replies: a reply whose CRC is right can still carry
//! wrong data (a dropped byte plus a CRC-16 collision shifts it, about once in 1.35·10⁵ faulty
//! replies; a board can freeze and repeat its last sample). Every reply is checked before its
//! values are used; a rejected reply counts as missing (the supervisor holds the last good
//! value, see [`crate::supervisor`]), and a board without an accepted sample for longer than
//! [`Config::sensor_stale_ms`] stops the robot (`SensorStale`).
//!
//! Checks ([`SensorRejection`] codes):
//! * **counter** (both boards): the board's u16 sample counter differs from the one of its last
//!   accepted sample (a frozen board repeats it);
//! * **range**: IMU |ω| per axis ≤ [`imu::GYRO_FULL_SCALE_URAD_S`] (±2000 °/s) and |a| per axis
//!   ≤ [`imu::ACCEL_FULL_SCALE_UM_S2`] (±16 g); each load cell within ±f·W (a cell reads
//!   negative when the centre of pressure is beyond the opposite edge: −1.2·W in the MuJoCo
//!   robot's Table 2 walk);
//! * **weight**: one foot's total in [−0.1·W, f·W], and both feet's total ≤ f·W when both
//!   replied this tick, where W = m·g is the robot's weight (reference robot: m·g from
//!   `Robot::masses.total()` and `gravity`, 48.5 N) and f = [`Config::force_factor`] (default
//!   6: the feet carry W standing and a few times W at touch-down; a shifted byte is off by a
//!   factor 2⁸ or more).

use dxl::table::foot::FootForces;
use dxl::table::imu::{self, ImuSample};
use walker_contract::codes::SensorRejection;

use crate::Config;

/// Fraction of the weight a foot's total may read below zero (noise, zero offset).
pub const NEGATIVE_LOAD_FRACTION: f32 = 0.1;

/// The per-board state of the checks for `N` sensor boards.
#[derive(Clone, Debug)]
pub struct Plausibility<const N: usize> {
    /// f·W, mN, rounded down: the bound of a cell, of a foot's total and of both feet's total.
    max_mn: i64,
    /// −0.1·W, mN, rounded up: the lower bound of a foot's total.
    min_total_mn: i64,
    stale_us: u64,
    counters: [Option<u16>; N],
    last_ok_us: [u64; N],
}

impl<const N: usize> Plausibility<N> {
    /// Checks for a robot of weight `weight_n` (N) with `cfg`'s force factor and staleness
    /// bound; every board counts as fresh at `now_us`.
    pub fn new(cfg: &Config, weight_n: f32, now_us: u64) -> Self {
        // The bounds in whole mN, once: the per-tick checks are integer compares (no soft
        // float on the FPU-less boards). `as` rounds toward zero — down for the positive bound,
        // up for the negative one, as an integer reading compares — saturates, and makes NaN 0.
        let weight_mn = weight_n * 1000.0;
        Plausibility {
            max_mn: (cfg.force_factor * weight_mn) as i64,
            min_total_mn: (-NEGATIVE_LOAD_FRACTION * weight_mn) as i64,
            stale_us: u64::from(cfg.sensor_stale_ms).saturating_mul(1000),
            counters: [None; N],
            last_ok_us: [now_us; N],
        }
    }

    fn counter_advanced(&self, k: usize, counter: u16) -> Result<(), SensorRejection> {
        match self.counters.get(k) {
            Some(Some(c)) if *c == counter => Err(SensorRejection::FrozenCounter),
            _ => Ok(()),
        }
    }

    /// A foot's total load is plausible.
    fn total_ok(&self, mn: i64) -> bool {
        mn >= self.min_total_mn && mn <= self.max_mn
    }

    /// Checks a foot board's sample (board index `k`).
    pub fn foot(&self, k: usize, f: &FootForces) -> Result<(), SensorRejection> {
        self.counter_advanced(k, f.counter)?;
        if !f
            .forces_mn
            .iter()
            .all(|&v| i64::from(v).abs() <= self.max_mn)
        {
            return Err(SensorRejection::OutOfRange);
        }
        let total: i64 = f.forces_mn.iter().map(|&v| i64::from(v)).sum();
        if !self.total_ok(total) {
            return Err(SensorRejection::Weight);
        }
        Ok(())
    }

    /// Checks the two feet together (both accepted this tick): their total ≤ f·W.
    pub fn feet_together(&self, a: &FootForces, b: &FootForces) -> Result<(), SensorRejection> {
        let total: i64 = a
            .forces_mn
            .iter()
            .chain(b.forces_mn.iter())
            .map(|&v| i64::from(v))
            .sum();
        if total <= self.max_mn {
            Ok(())
        } else {
            Err(SensorRejection::Weight)
        }
    }

    /// Checks the IMU board's sample (board index `k`).
    pub fn imu(&self, k: usize, s: &ImuSample) -> Result<(), SensorRejection> {
        self.counter_advanced(k, s.counter)?;
        let gyro_ok = s
            .gyro_urad_s
            .iter()
            .all(|v| v.unsigned_abs() <= imu::GYRO_FULL_SCALE_URAD_S.unsigned_abs());
        let accel_ok = s
            .accel_um_s2
            .iter()
            .all(|v| v.unsigned_abs() <= imu::ACCEL_FULL_SCALE_UM_S2.unsigned_abs());
        if gyro_ok && accel_ok {
            Ok(())
        } else {
            Err(SensorRejection::OutOfRange)
        }
    }

    /// Records board `k`'s accepted sample (its counter) at `now_us`.
    pub fn accept(&mut self, k: usize, counter: u16, now_us: u64) {
        if let (Some(c), Some(t)) = (self.counters.get_mut(k), self.last_ok_us.get_mut(k)) {
            *c = Some(counter);
            *t = now_us;
        }
    }

    /// Age of board `k`'s last accepted sample, ms (saturating), when it exceeds the bound.
    pub fn stale(&self, k: usize, now_us: u64) -> Option<u16> {
        let age = now_us.saturating_sub(*self.last_ok_us.get(k)?);
        (age > self.stale_us).then(|| u16::try_from(age / 1000).unwrap_or(u16::MAX))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: f32 = 40.0;

    fn p() -> Plausibility<3> {
        Plausibility::new(&Config::default(), W, 0)
    }

    fn foot(mn: [i32; 4], counter: u16) -> FootForces {
        FootForces {
            forces_mn: mn,
            counter,
        }
    }

    #[test]
    fn foot_range_weight_and_counter() {
        let mut c = p();
        // The robot's weight on one foot, evenly: fine.
        let ok = foot([10_000; 4], 1);
        assert_eq!(c.foot(0, &ok), Ok(()));
        c.accept(0, 1, 5_000);
        // The same counter again: frozen.
        assert_eq!(c.foot(0, &ok), Err(SensorRejection::FrozenCounter));
        // Another board's counter is its own.
        assert_eq!(c.foot(1, &ok), Ok(()));
        // One cell beyond ±6·W = ±240 N (a byte shift multiplies by 256): out of range.
        assert_eq!(
            c.foot(0, &foot([10_000 * 256, 0, 0, 0], 2)),
            Err(SensorRejection::OutOfRange)
        );
        assert_eq!(
            c.foot(0, &foot([-240_001, 240_000, 8_000, 0], 2)),
            Err(SensorRejection::OutOfRange)
        );
        assert_eq!(c.foot(0, &foot([-240_000, 240_000, 8_000, 0], 2)), Ok(()));
        // The extremes of the wire's i32 (integer bounds, no overflow).
        for v in [i32::MIN, i32::MAX] {
            assert_eq!(
                c.foot(0, &foot([v; 4], 2)),
                Err(SensorRejection::OutOfRange)
            );
            assert_eq!(
                c.feet_together(&foot([v; 4], 3), &foot([v; 4], 3)),
                if v < 0 {
                    Ok(())
                } else {
                    Err(SensorRejection::Weight)
                }
            );
        }
        // Cells in range but the foot's total below −0.1·W = −4 N or above 6·W = 240 N.
        assert_eq!(
            c.foot(0, &foot([-4_001, 0, 0, 0], 2)),
            Err(SensorRejection::Weight)
        );
        assert_eq!(c.foot(0, &foot([-4_000, 0, 0, 0], 2)), Ok(()));
        assert_eq!(
            c.foot(0, &foot([60_001, 60_000, 60_000, 60_000], 2)),
            Err(SensorRejection::Weight)
        );
        assert_eq!(c.foot(0, &foot([60_000; 4], 2)), Ok(()));
        // Both feet together above 240 N.
        let a = foot([35_000; 4], 3);
        let b = foot([25_001; 4], 3);
        assert_eq!(c.feet_together(&a, &b), Err(SensorRejection::Weight));
        assert_eq!(c.feet_together(&a, &foot([25_000; 4], 3)), Ok(()));
    }

    #[test]
    fn imu_range_and_counter() {
        let mut c = p();
        let ok = ImuSample::from_si([0.1, -0.3, 0.0], [0.0, 0.0, 9.81], 7);
        assert_eq!(c.imu(2, &ok), Ok(()));
        c.accept(2, 7, 0);
        assert_eq!(c.imu(2, &ok), Err(SensorRejection::FrozenCounter));
        // 2000 °/s = 34.9 rad/s is the gyro's full scale, 16 g the accelerometer's.
        let fast = ImuSample::from_si([35.0, 0.0, 0.0], [0.0, 0.0, 9.81], 8);
        assert_eq!(c.imu(2, &fast), Err(SensorRejection::OutOfRange));
        let edge = ImuSample::from_si([34.9, 0.0, 0.0], [0.0, 0.0, 15.9 * 9.80665], 8);
        assert_eq!(c.imu(2, &edge), Ok(()));
        let hard = ImuSample::from_si([0.0; 3], [0.0, 0.0, 16.1 * 9.80665], 8);
        assert_eq!(c.imu(2, &hard), Err(SensorRejection::OutOfRange));
    }

    #[test]
    fn staleness_bound() {
        // Default 100 ms: 100 ms old is still fine, 100.001 ms is stale (age in whole ms).
        let mut c = p();
        c.accept(1, 3, 1_000);
        assert_eq!(c.stale(1, 101_000), None);
        assert_eq!(c.stale(1, 101_001), Some(100));
        assert_eq!(c.stale(0, 250_000), Some(250));
        assert_eq!(c.stale(9, 250_000), None);
    }
}
