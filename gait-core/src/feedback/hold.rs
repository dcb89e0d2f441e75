//! The clock hold: the landing waits for the caught foot and for the servos ([`ClockHold`];
//! part of the step adaptation, [`crate::feedback::catch::StepAdapter`], which feeds it the
//! swing foot of the catching step and the swing sole's measured lag).
//!
//! # Law
//! The servos lag ≈ 0.1 s, so a catch asked late in a swing is not where the plan sets the
//! foot down. With a hold budget H > 0 the plan's clock stands still (the firmware takes the
//! same sample again) for the next tick while
//!
//! ```text
//!   z_swing < z_h  and  ( |d*_swing − d_swing|∞ > ε  or  0 < t_arrived < T_s  or  ℓ > ℓ_max )
//!                  and  held < H                                                      (A11)
//!   ℓ = |FK(q̂_swing) − FK(q^s_swing)|∞       the swing sole's measured lag
//! ```
//!
//! (the planned swing sole below z_h = [`HOLD_HEIGHT_M`] and not rising — no hold at
//! lift-off —, the swing foot's offset more than ε = [`HOLD_GAP_M`] from (A5) of
//! [`crate::feedback::catch`] or, having moved in this single support, arrived less than the
//! settling time T_s ago) or the swing sole, by the forward kinematics of the servos' Present
//! Position q̂ against that of the targets q^s they were sent (pelvis frame), more than ℓ_max
//! from where its targets put it (`hold_lag_m`; 0 = off, and an unmeasured ℓ never holds): a
//! servo that lags sets the foot down short and late, so the plan waits for it. The budget is
//! per single support and refills outside single support. A swing that carries the touchdown
//! load never holds. The clock only stands still: a shorter swing would need the CoM
//! re-planned, which the precomputed TLIPFM segments cannot do mid-step.

use crate::feedback::catch::StepAdaptation;
use crate::trajectory::sampler::SupportPhase;

/// Planned swing sole height below which the clock holds for a foot still on its way (A11), m.
pub const HOLD_HEIGHT_M: f32 = 0.01;

/// Distance of the swing foot's offset from its target beyond which it is still on its way
/// (A11, ε), m.
pub const HOLD_GAP_M: f32 = 1e-4;

/// Whole ticks of `s` seconds at `dt_s` (0 when not `ok` or not finite).
fn ticks_of(s: f32, dt_s: f32, ok: bool) -> u32 {
    if !ok {
        return 0;
    }
    let n = s / dt_s;
    if n.is_finite() && n > 0.0 {
        // Saturating float-to-int cast (`as` saturates; no panic).
        (n + 0.5) as u32
    } else {
        0
    }
}

/// The swing foot as the clock hold sees it (A11), in single support before it has landed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SwingFoot {
    /// The swing sole's planned height z_swing, m.
    pub z_m: f32,
    /// The swing foot's offset's distance from its target |d*_swing − d_swing|∞, m.
    pub gap_m: f32,
    /// The swing sole's measured distance from where its targets put it (forward kinematics
    /// of the Present Position against that of the targets, |·|∞), m (NaN: not measured).
    pub lag_m: f32,
}

/// The clock hold's state (A11): the budget left in this single support and the swing foot's
/// progress.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockHold {
    /// Ticks the clock may still be held in this single support.
    left: u32,
    /// Largest hold per single support, ticks.
    max_ticks: u32,
    /// Settling time after the offset arrived, ticks.
    settle_ticks: u32,
    /// Ticks since the swing foot's offset arrived at its target.
    settled: u32,
    /// Whether the next tick holds the plan's clock.
    hold: bool,
    /// Whether the swing foot's offset moved in this single support.
    moving: bool,
    /// The swing sole's planned height at the last update, m (NaN outside single support).
    swing_z: f32,
    /// Measured lag beyond which the landing waits, m (0: off).
    lag_tol_m: f32,
}

impl ClockHold {
    /// The clock hold of `cfg` (`hold_max_s`, `hold_settle_s`) with ticks of `dt_s` seconds;
    /// a non-positive or non-finite tick gives no budget.
    pub fn new(cfg: &StepAdaptation, dt_s: f32) -> Self {
        let cfg = cfg.limited();
        let ok = dt_s.is_finite() && dt_s > 0.0;
        let max_ticks = ticks_of(cfg.hold_max_s, dt_s, ok);
        ClockHold {
            left: max_ticks,
            max_ticks,
            settle_ticks: ticks_of(cfg.hold_settle_s, dt_s, ok),
            settled: 0,
            hold: false,
            moving: false,
            swing_z: f32::NAN,
            lag_tol_m: if ok { cfg.hold_lag_m } else { 0.0 },
        }
    }

    /// Whether the plan's clock should stand still for the next tick: the caught swing foot is
    /// still on its way (or settling) as the plan would set it down.
    pub fn wants_hold(&self) -> bool {
        self.hold
    }

    /// One tick in the support `phase`, with the `swing` foot while it is in the air and
    /// tracked (`None` otherwise: no hold this tick). Outside single support the budget
    /// refills.
    pub fn update(&mut self, phase: SupportPhase, swing: Option<SwingFoot>) {
        self.hold = false;
        if !matches!(phase, SupportPhase::Single(_)) {
            self.left = self.max_ticks;
            self.settled = 0;
            self.moving = false;
            self.swing_z = f32::NAN;
        }
        let Some(SwingFoot {
            z_m: z,
            gap_m: gap,
            lag_m,
        }) = swing
        else {
            return;
        };
        // NaN compares false: an unmeasured lag never holds.
        let lagging = self.lag_tol_m > 0.0 && lag_m > self.lag_tol_m;
        if gap > HOLD_GAP_M {
            self.moving = true;
            self.settled = 0;
        } else {
            self.settled = self.settled.saturating_add(1);
        }
        let waiting =
            gap > HOLD_GAP_M || (self.moving && self.settled < self.settle_ticks) || lagging;
        // Descending or held (not rising: no hold at lift-off); NaN compares false.
        let landing = z < HOLD_HEIGHT_M && z <= self.swing_z;
        self.swing_z = z;
        if waiting && landing && self.left > 0 {
            self.hold = true;
            self.left -= 1;
        }
    }
}
