//! Fault injection for tests (as smoltcp's `FaultInjector` wraps a device): a non-finite CoM in
//! the sample the IK takes (`fault_nan_com`), a non-finite joint target (`fault_nan`) and an
//! operator stop (`stop_at`), each at a given walk tick. Compiled into host tests and the QEMU
//! board only; the robot boards get [`FaultInjector`] as a zero-sized type that never injects
//! (their parameters are accepted and ignored).

use gait_core::robot::LEG_JOINTS;
use gait_core::GaitSample;

use crate::Config;

/// The faults a test run injects (walk ticks).
#[cfg(any(test, feature = "board-qemu"))]
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct FaultInjector {
    nan_com: Option<u32>,
    nan_target: Option<u32>,
    stop: Option<u32>,
}

/// The robot boards' injector: never injects.
#[cfg(not(any(test, feature = "board-qemu")))]
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct FaultInjector;

impl FaultInjector {
    /// The faults `cfg` asks for.
    #[cfg(any(test, feature = "board-qemu"))]
    pub(crate) fn new(cfg: &Config) -> Self {
        FaultInjector {
            nan_com: cfg.fault_nan_com_tick,
            nan_target: cfg.fault_nan_tick,
            stop: cfg.stop_at_tick,
        }
    }

    /// None on a robot board.
    #[cfg(not(any(test, feature = "board-qemu")))]
    pub(crate) fn new(_: &Config) -> Self {
        FaultInjector
    }

    /// Whether walk tick `k`'s sample is spoiled ([`FaultInjector::sample`]).
    #[inline]
    pub(crate) fn sample_at(&self, k: u32) -> bool {
        #[cfg(any(test, feature = "board-qemu"))]
        if self.nan_com == Some(k) {
            return true;
        }
        let _ = k;
        false
    }

    /// At walk tick `k`, spoils the CoM of `sample` (a copy of the one the IK takes).
    #[inline]
    pub(crate) fn sample(&self, k: u32, sample: &mut GaitSample<f32>) {
        if self.sample_at(k) {
            sample.com[0] = f32::NAN;
        }
    }

    /// Whether walk tick `k`'s joint targets are spoiled (they must come from the f32 IK).
    #[inline]
    pub(crate) fn targets_at(&self, k: u32) -> bool {
        #[cfg(any(test, feature = "board-qemu"))]
        if self.nan_target == Some(k) {
            return true;
        }
        let _ = k;
        false
    }

    /// At walk tick `k`, spoils the first joint target of `q`.
    #[inline]
    pub(crate) fn targets(&self, k: u32, q: &mut [f32; LEG_JOINTS]) {
        if self.targets_at(k) {
            if let Some(v) = q.first_mut() {
                *v = f32::NAN;
            }
        }
    }

    /// Whether the operator's stop comes at walk tick `k`.
    #[inline]
    pub(crate) fn stop_at(&self, k: u32) -> bool {
        #[cfg(any(test, feature = "board-qemu"))]
        if self.stop == Some(k) {
            return true;
        }
        let _ = k;
        false
    }
}
