//! Supervisor: device freshness, fall and overrun detection, the stop sequence, and the target
//! filter that keeps non-finite or out-of-limit values away from the servos.
//!
//! # The stop sequence (docs/stops.md has the whole table)
//! Each stop reason has a grade ([`StopGrade`], defined with the reasons in the contract):
//!
//! ```text
//!  Running ─Settle─▶ Settling ─standstill or settle_ticks─▶ Lowering ─lower_ticks─▶ Stopping ─stopping_ticks─▶ TorqueOff
//!     │                 (the walk runs,                        (the ramp to            (hold the
//!     ├─Lower──────────▶ stopped by the controller) ──────────▶ the crouch)  ─────────▶ crouch)
//!     └─Limp (fall, hardware error) ──────────────────────────────────────────────────────────────▶ TorqueOff
//!                                                                            (an operator's stop with rest: ▶ Resting)
//! ```
//!
//! An operator's stop ([`StopReason::rests`]) with [`Supervisor::with_rest`] ends in `Resting`
//! instead of `TorqueOff`: the crouch held with torque on, the run over (a limp robot does not
//! keep a crouch; the operator's second torque off is the control loop's, after the run).
//! The finished plan (grade `Hold`) holds its final pose, then turns torque off. With
//! `lower_ticks` = 0 the lowering is skipped (the pose is held, then torque off); with
//! `settle_ticks` = 0 a `Settle` reason lowers at once. The first stop reason wins and is
//! reported (log stop record), with one exception: a `Limp` reason while a graded stop runs
//! (the robot fell while lowering) goes limp at once and is the one reported. A `Lower`
//! reason while settling begins the lowering (the first reason stays). A device missing at
//! start-up goes straight to `TorqueOff` (torque was never enabled).
//!
//! Per device, a missed reply is bridged by holding its last good value for at most
//! [`SupervisorConfig::hold_ticks`] consecutive ticks; one more miss is `DeviceLost`.

use gait_core::robot::{Robot, Side, JOINTS_PER_LEG, LEG_JOINTS};
use walker_contract::bus_map::TickMap;

pub use walker_contract::codes::{StopGrade, StopReason};
pub use walker_contract::config::SupervisorConfig;

/// Supervisor state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub enum State {
    /// Walking or standing under control.
    Running,
    /// Walking to a standstill: the walk runs, told to stop (graded stop, `Settle`).
    Settling {
        /// Why.
        reason: StopReason,
        /// Ticks left before the lowering begins anyway.
        ticks_left: u16,
    },
    /// Lowering to the crouch.
    Lowering {
        /// Why.
        reason: StopReason,
        /// Tick of the lowering (0 ..= `lower_ticks` − 1).
        k: u16,
    },
    /// Holding the pose before torque off (or before the lowering, after the plan's final
    /// hold).
    Stopping {
        /// Why.
        reason: StopReason,
        /// Ticks left before torque off (or the lowering).
        ticks_left: u16,
        /// The lowering follows the hold (the finished plan's final hold).
        lower_next: bool,
    },
    /// Torque off (final).
    TorqueOff {
        /// Why.
        reason: StopReason,
    },
    /// Resting in the crouch with torque on (final; an operator's stop with `rest`).
    Resting {
        /// Why.
        reason: StopReason,
    },
}

/// What the control loop must do this tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub enum Action {
    /// Compute and send new targets.
    Run,
    /// Send tick `k` of the lowering to the crouch (of [`Supervisor::lower_ticks`]).
    Lower(u16),
    /// Send the last targets again (hold the pose).
    HoldPose,
    /// Send the broadcast torque-off now (returned once).
    SendTorqueOff,
    /// Send the last targets again and end the run with torque on (resting in the crouch).
    Rest,
    /// Nothing to send.
    Idle,
}

/// Freshness of one device's data this tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(all(target_arch = "arm", target_os = "none"), derive(defmt::Format))]
pub enum Freshness {
    /// Fresh data.
    Fresh,
    /// Missed; use the last good value (held for this many consecutive ticks).
    Held(u16),
    /// Missed more than `hold_ticks` times: lost (the supervisor is stopping).
    Lost,
    /// Not a supervised device id.
    Unknown,
}

/// The supervisor for `N` devices.
#[derive(Clone, Debug)]
pub struct Supervisor<const N: usize> {
    cfg: SupervisorConfig,
    ids: [u8; N],
    misses: [u16; N],
    state: State,
    overrun_run: u16,
    torque_off_sent: bool,
    settle_ticks: u16,
    lower_ticks: u16,
    rest: bool,
}

impl<const N: usize> Supervisor<N> {
    /// A running supervisor watching the devices `ids`; graded stops neither settle nor lower
    /// until [`Supervisor::with_grades`].
    pub fn new(cfg: SupervisorConfig, ids: [u8; N]) -> Self {
        Supervisor {
            cfg,
            ids,
            misses: [0; N],
            state: State::Running,
            overrun_run: 0,
            torque_off_sent: false,
            settle_ticks: 0,
            lower_ticks: 0,
            rest: false,
        }
    }

    /// An operator's stop ends resting in the crouch with torque on (`true`) instead of
    /// torque off.
    pub fn with_rest(mut self, rest: bool) -> Self {
        self.rest = rest;
        self
    }

    /// The graded stops' longest walk to a standstill and their lowering, ticks.
    pub fn with_grades(mut self, settle_ticks: u16, lower_ticks: u16) -> Self {
        self.settle_ticks = settle_ticks;
        self.lower_ticks = lower_ticks;
        self
    }

    /// Current state.
    pub fn state(&self) -> State {
        self.state
    }

    /// The configuration.
    pub fn config(&self) -> &SupervisorConfig {
        &self.cfg
    }

    /// Ticks of the lowering to the crouch (0: none).
    pub fn lower_ticks(&self) -> u16 {
        self.lower_ticks
    }

    /// The stop reason, once stopping.
    pub fn stop_reason(&self) -> Option<StopReason> {
        match self.state {
            State::Running => None,
            State::Settling { reason, .. }
            | State::Lowering { reason, .. }
            | State::Stopping { reason, .. }
            | State::TorqueOff { reason }
            | State::Resting { reason } => Some(reason),
        }
    }

    /// True while a graded stop walks to a standstill.
    pub fn is_settling(&self) -> bool {
        matches!(self.state, State::Settling { .. })
    }

    /// True while at least one device is on last-good hold.
    pub fn any_holding(&self) -> bool {
        self.misses.iter().any(|&m| m > 0)
    }

    /// State for the log's status byte.
    pub fn fault_state(&self) -> crate::record::FaultState {
        match self.state {
            State::Running if self.any_holding() => crate::record::FaultState::Holding,
            State::Running => crate::record::FaultState::Ok,
            State::Settling { .. }
            | State::Lowering { .. }
            | State::Stopping { .. }
            | State::Resting { .. } => crate::record::FaultState::Stopping,
            State::TorqueOff { .. } => crate::record::FaultState::TorqueOff,
        }
    }

    /// Start-up probe result: every id in `missing` did not answer. Any missing device goes
    /// straight to `TorqueOff` with `DeviceMissing` (the first missing id).
    pub fn startup(&mut self, missing: &[u8]) -> Result<(), StopReason> {
        match missing.first() {
            None => Ok(()),
            Some(&id) => {
                let reason = StopReason::DeviceMissing { id };
                if self.state == State::Running {
                    self.state = State::TorqueOff { reason };
                }
                Err(reason)
            }
        }
    }

    /// Starts the stop sequence of `reason`'s grade (see the module docs: the first reason
    /// wins; a limp reason cuts a graded stop short).
    pub fn stop(&mut self, reason: StopReason) {
        let grade = reason.grade();
        match self.state {
            State::Running => match grade {
                StopGrade::Limp => self.state = State::TorqueOff { reason },
                StopGrade::Settle if self.settle_ticks > 0 => {
                    self.state = State::Settling {
                        reason,
                        ticks_left: self.settle_ticks,
                    }
                }
                StopGrade::Settle | StopGrade::Lower => self.lower(reason),
                StopGrade::Hold => self.state = self.hold(reason, self.cfg.stopping_ticks, false),
            },
            State::Settling { reason: first, .. } if grade == StopGrade::Lower => self.lower(first),
            State::Settling { .. } | State::Lowering { .. } | State::Stopping { .. }
                if grade == StopGrade::Limp =>
            {
                self.state = State::TorqueOff { reason }
            }
            _ => {}
        }
    }

    /// The lowering (or, without one, the hold before torque off).
    fn lower(&mut self, reason: StopReason) {
        self.state = if self.lower_ticks > 0 {
            State::Lowering { reason, k: 0 }
        } else {
            self.hold(reason, self.cfg.stopping_ticks, false)
        };
    }

    /// Holding the pose for `ticks` (none: torque off — resting for an operator's stop with
    /// `rest` — or the lowering when `lower_next`).
    fn hold(&self, reason: StopReason, ticks: u16, lower_next: bool) -> State {
        match (ticks, lower_next && self.lower_ticks > 0) {
            (0, false) if self.rest && reason.rests() => State::Resting { reason },
            (0, false) => State::TorqueOff { reason },
            (0, true) => State::Lowering { reason, k: 0 },
            (t, l) => State::Stopping {
                reason,
                ticks_left: t,
                lower_next: l,
            },
        }
    }

    /// Starts the stop sequence holding the pose for `hold_ticks` ticks first (e.g. the final
    /// hold after the plan), then lowering the robot if `reason`'s grade lowers it. The first
    /// reason wins.
    pub fn stop_with_hold(&mut self, reason: StopReason, hold_ticks: u16) {
        if self.state == State::Running {
            self.state = match reason.grade() {
                StopGrade::Limp => State::TorqueOff { reason },
                StopGrade::Hold => self.hold(reason, hold_ticks, false),
                StopGrade::Settle | StopGrade::Lower => self.hold(reason, hold_ticks, true),
            };
        }
    }

    /// The walk stands (or cannot walk to a standstill): a settling stop begins its lowering.
    pub fn settled(&mut self) {
        if let State::Settling { reason, .. } = self.state {
            self.lower(reason);
        }
    }

    /// Reports whether device `id` answered this tick.
    pub fn report(&mut self, id: u8, answered: bool) -> Freshness {
        let Some(pos) = self.ids.iter().position(|&d| d == id) else {
            return Freshness::Unknown;
        };
        let Some(m) = self.misses.get_mut(pos) else {
            return Freshness::Unknown;
        };
        if answered {
            *m = 0;
            return Freshness::Fresh;
        }
        *m = m.saturating_add(1);
        if *m > self.cfg.hold_ticks {
            self.stop(StopReason::DeviceLost { id });
            Freshness::Lost
        } else {
            Freshness::Held(*m)
        }
    }

    /// Reports the trunk tilt from vertical, rad (non-finite values are ignored: the IMU
    /// filter already holds its last good value). Beyond the limit the robot is falling: the
    /// servos go limp at once (no pose hold: stiff legs would only lever the fall).
    pub fn tilt(&mut self, tilt_rad: f32) {
        if tilt_rad.is_finite() && libm::fabsf(tilt_rad) > self.cfg.tilt_limit_rad {
            let mrad = libm::fminf(libm::fabsf(tilt_rad) * 1000.0, 65535.0) as u16;
            self.stop(StopReason::Fall { tilt_mrad: mrad });
        }
    }

    /// Reports whether this tick overran.
    pub fn tick_timing(&mut self, overrun: bool) {
        if overrun {
            self.overrun_run = self.overrun_run.saturating_add(1);
            if self.overrun_run >= self.cfg.overrun_burst.max(1) {
                self.stop(StopReason::OverrunBurst {
                    count: self.overrun_run,
                });
            }
        } else {
            self.overrun_run = 0;
        }
    }

    /// Reports that the walking plan is finished.
    pub fn plan_done(&mut self) {
        self.stop(StopReason::PlanDone);
    }

    /// Advances one tick after all reports; tells the loop what to send.
    pub fn step(&mut self) -> Action {
        match self.state {
            State::Running => Action::Run,
            State::Settling { reason, ticks_left } => {
                let left = ticks_left.saturating_sub(1);
                if left == 0 {
                    self.lower(reason);
                } else {
                    self.state = State::Settling {
                        reason,
                        ticks_left: left,
                    };
                }
                Action::Run
            }
            State::Lowering { reason, k } => {
                let next = k.saturating_add(1);
                self.state = if next >= self.lower_ticks {
                    self.hold(reason, self.cfg.stopping_ticks, false)
                } else {
                    State::Lowering { reason, k: next }
                };
                Action::Lower(k)
            }
            State::Stopping {
                reason,
                ticks_left,
                lower_next,
            } => {
                let left = ticks_left.saturating_sub(1);
                self.state = self.hold(reason, left, lower_next);
                Action::HoldPose
            }
            State::Resting { .. } => Action::Rest,
            State::TorqueOff { .. } => {
                if self.torque_off_sent {
                    Action::Idle
                } else {
                    self.torque_off_sent = true;
                    Action::SendTorqueOff
                }
            }
        }
    }
}

/// Joint limits of the 12 leg joints and the servos' tick range around the contract's
/// rad ↔ tick map ([`TickMap`], the one definition of the conversion).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointMap {
    /// The rad ↔ tick map (zero tick, ticks per turn, mounting signs).
    pub ticks: TickMap,
    /// Lower joint limits, rad.
    pub min_rad: [f32; LEG_JOINTS],
    /// Upper joint limits, rad.
    pub max_rad: [f32; LEG_JOINTS],
    /// Lowest tick the servo accepts.
    pub tick_min: i32,
    /// Highest tick the servo accepts.
    pub tick_max: i32,
    /// The joint limits in I16F16 rad bits (lower, upper; the fixed-point path).
    pub limits_fx: [[i32; 2]; LEG_JOINTS],
    /// [`TickMap::ticks_per_fx_rad_32`], computed once.
    pub fx_k: i64,
}

impl JointMap {
    /// From the robot description (all signs +1: the mounting is not described yet).
    pub fn from_robot(robot: &Robot) -> Self {
        let mut min_rad = [0.0f32; LEG_JOINTS];
        let mut max_rad = [0.0f32; LEG_JOINTS];
        for (i, (lo, hi)) in min_rad.iter_mut().zip(max_rad.iter_mut()).enumerate() {
            let side = if i < JOINTS_PER_LEG {
                Side::Left
            } else {
                Side::Right
            };
            let l = robot.joint_limit(side, i % JOINTS_PER_LEG);
            *lo = l.min as f32;
            *hi = l.max as f32;
        }
        let ticks = TickMap::from_robot(robot);
        let bits = |v: f32| gait_core::maths::fixed_point::fx_sat(v).to_bits();
        let mut limits_fx = [[0i32; 2]; LEG_JOINTS];
        for (l, (&lo, &hi)) in limits_fx.iter_mut().zip(min_rad.iter().zip(max_rad.iter())) {
            *l = [bits(lo), bits(hi)];
        }
        JointMap {
            ticks,
            min_rad,
            max_rad,
            tick_min: 0,
            tick_max: ticks.ticks_per_turn - 1,
            limits_fx,
            fx_k: ticks.ticks_per_fx_rad_32(),
        }
    }

    /// Joint angle (rad) of joint `j` at servo tick `tick` (inverse of the tick mapping,
    /// without clamping).
    pub fn rad_of_tick(&self, j: usize, tick: i32) -> f32 {
        self.ticks.rad_f32(j, tick)
    }

    /// Tick of joint `j` at `rad` (clamped to the joint and servo limits; `rad` must be finite).
    fn tick(&self, j: usize, rad: f32) -> (i32, bool) {
        let lo = self.min_rad.get(j).copied().map_or(0.0, |v| v);
        let hi = self.max_rad.get(j).copied().map_or(0.0, |v| v);
        let c = if rad < lo {
            lo
        } else if rad > hi {
            hi
        } else {
            rad
        };
        let t = self.ticks.tick_f32(j, c);
        let tc = t.max(self.tick_min).min(self.tick_max);
        (tc, c != rad || tc != t)
    }
}

/// Targets that passed the filter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SafeTargets {
    /// Servo ticks to send.
    pub ticks: [i32; LEG_JOINTS],
    /// Bit j set: joint j was clamped to its limit.
    pub clamped: u16,
}

/// Some targets were non-finite; `ticks` still holds safe values to send (previous target for
/// the rejected joints).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TargetError {
    /// Safe servo ticks (non-finite joints hold their previous target).
    pub ticks: [i32; LEG_JOINTS],
    /// Bit j set: joint j was NaN or infinite.
    pub non_finite: u16,
    /// Bit j set: joint j was clamped.
    pub clamped: u16,
}

impl TargetError {
    /// Index of the first non-finite joint.
    pub fn first_joint(&self) -> u8 {
        self.non_finite.trailing_zeros().min(15) as u8
    }
}

/// Converts joint targets (rad) to servo ticks so that nothing non-finite or out of limit
/// reaches a servo: finite values are clamped to the joint limits (and the servo's tick range);
/// a non-finite value holds `prev` (itself clamped to the tick range) and makes the result
/// `Err` — whose `ticks` are still safe to send.
pub fn safe_targets(
    targets: &[f32; LEG_JOINTS],
    map: &JointMap,
    prev: &[i32; LEG_JOINTS],
) -> Result<SafeTargets, TargetError> {
    let mut ticks = [0i32; LEG_JOINTS];
    let mut clamped = 0u16;
    let mut non_finite = 0u16;
    for (j, ((out, &rad), &p)) in ticks
        .iter_mut()
        .zip(targets.iter())
        .zip(prev.iter())
        .enumerate()
    {
        if rad.is_finite() {
            let (t, c) = map.tick(j, rad);
            *out = t;
            if c {
                clamped |= 1 << j;
            }
        } else {
            non_finite |= 1 << j;
            *out = p.max(map.tick_min).min(map.tick_max);
        }
    }
    if non_finite == 0 {
        Ok(SafeTargets { ticks, clamped })
    } else {
        Err(TargetError {
            ticks,
            non_finite,
            clamped,
        })
    }
}

/// [`safe_targets`] for joint targets in I16F16 rad (the fixed-point path: integer only,
/// [`TickMap::tick_fx_k`]); fixed-point angles are always finite, so it cannot fail.
pub fn safe_targets_fx(
    targets: &[gait_core::maths::fixed_point::Fx; LEG_JOINTS],
    map: &JointMap,
) -> SafeTargets {
    let mut ticks = [0i32; LEG_JOINTS];
    let mut clamped = 0u16;
    for (j, ((out, q), l)) in ticks
        .iter_mut()
        .zip(targets.iter())
        .zip(map.limits_fx.iter())
        .enumerate()
    {
        let b = q.to_bits();
        let c = b.max(l[0]).min(l[1]);
        let t = map.ticks.tick_fx_k(j, c, map.fx_k);
        *out = t.max(map.tick_min).min(map.tick_max);
        if c != b || *out != t {
            clamped |= 1 << j;
        }
    }
    SafeTargets { ticks, clamped }
}

#[cfg(test)]
mod tests {
    use super::*;

    const IDS: [u8; 15] = walker_contract::bus_map::DEVICE_IDS;

    fn sup() -> Supervisor<15> {
        Supervisor::new(
            SupervisorConfig {
                stopping_ticks: 3,
                ..SupervisorConfig::default()
            },
            IDS,
        )
    }

    fn run_to_off(s: &mut Supervisor<15>) -> [Action; 5] {
        [s.step(), s.step(), s.step(), s.step(), s.step()]
    }

    #[test]
    fn running_runs() {
        let mut s = sup();
        assert_eq!(s.startup(&[]), Ok(()));
        for _ in 0..100 {
            for id in IDS {
                assert_eq!(s.report(id, true), Freshness::Fresh);
            }
            s.tilt(0.1);
            s.tick_timing(false);
            assert_eq!(s.step(), Action::Run);
        }
        assert_eq!(s.fault_state(), crate::record::FaultState::Ok);
    }

    #[test]
    fn missing_at_startup_goes_to_torque_off() {
        let mut s = sup();
        let r = s.startup(&[111, 7]);
        assert_eq!(r, Err(StopReason::DeviceMissing { id: 111 }));
        assert_eq!(
            s.state(),
            State::TorqueOff {
                reason: StopReason::DeviceMissing { id: 111 }
            }
        );
        assert_eq!(s.step(), Action::SendTorqueOff);
        assert_eq!(s.step(), Action::Idle);
    }

    #[test]
    fn hold_then_lost() {
        let mut s = sup();
        for k in 1..=10u16 {
            assert_eq!(s.report(200, false), Freshness::Held(k));
            assert_eq!(s.fault_state(), crate::record::FaultState::Holding);
            assert_eq!(s.step(), Action::Run);
        }
        // A fresh reply resets the count.
        assert_eq!(s.report(200, true), Freshness::Fresh);
        for _ in 0..10 {
            s.report(200, false);
        }
        assert_eq!(s.report(200, false), Freshness::Lost);
        assert_eq!(s.stop_reason(), Some(StopReason::DeviceLost { id: 200 }));
        assert_eq!(
            run_to_off(&mut s),
            [
                Action::HoldPose,
                Action::HoldPose,
                Action::HoldPose,
                Action::SendTorqueOff,
                Action::Idle
            ]
        );
        assert_eq!(s.report(99, true), Freshness::Unknown);
    }

    #[test]
    fn fall() {
        let mut s = sup();
        s.tilt(f32::NAN);
        s.tilt(-0.59);
        assert_eq!(s.state(), State::Running);
        s.tilt(-0.75);
        assert_eq!(s.stop_reason(), Some(StopReason::Fall { tilt_mrad: 750 }));
        // The first reason wins.
        s.plan_done();
        assert_eq!(s.stop_reason(), Some(StopReason::Fall { tilt_mrad: 750 }));
        // Limp at once: the very next action is torque off, no pose hold.
        assert_eq!(s.step(), Action::SendTorqueOff);
        run_to_off(&mut s);
        assert_eq!(s.fault_state(), crate::record::FaultState::TorqueOff);
    }

    #[test]
    fn overrun_burst() {
        let mut s = sup();
        for _ in 0..4 {
            s.tick_timing(true);
        }
        s.tick_timing(false);
        for _ in 0..4 {
            s.tick_timing(true);
        }
        assert_eq!(s.state(), State::Running);
        s.tick_timing(true);
        assert_eq!(s.stop_reason(), Some(StopReason::OverrunBurst { count: 5 }));
    }

    #[test]
    fn plan_done_and_zero_stopping_ticks() {
        let mut s: Supervisor<1> = Supervisor::new(
            SupervisorConfig {
                stopping_ticks: 0,
                ..SupervisorConfig::default()
            },
            [1],
        );
        s.plan_done();
        assert_eq!(
            s.state(),
            State::TorqueOff {
                reason: StopReason::PlanDone
            }
        );
        assert_eq!(s.step(), Action::SendTorqueOff);
    }

    #[test]
    fn stop_with_hold_uses_its_own_hold() {
        let mut s = sup();
        s.stop_with_hold(StopReason::PlanDone, 2);
        assert_eq!(s.step(), Action::HoldPose);
        assert_eq!(s.step(), Action::HoldPose);
        assert_eq!(s.step(), Action::SendTorqueOff);
        // The first reason wins.
        s.stop(StopReason::Requested);
        assert_eq!(s.stop_reason(), Some(StopReason::PlanDone));
        let mut z = sup();
        z.stop_with_hold(StopReason::PlanDone, 0);
        assert_eq!(z.step(), Action::SendTorqueOff);
    }

    /// The graded supervisor's actions from the lowering on: lower 3 ticks, hold 3, torque off.
    const LOWER_HOLD_OFF: [Action; 7] = [
        Action::Lower(0),
        Action::Lower(1),
        Action::Lower(2),
        Action::HoldPose,
        Action::HoldPose,
        Action::HoldPose,
        Action::SendTorqueOff,
    ];

    /// The graded supervisor: settle ≤ 4 ticks, lower 3 ticks, hold 3 ticks.
    fn graded() -> Supervisor<15> {
        sup().with_grades(4, 3)
    }

    #[test]
    fn an_operator_stop_settles_lowers_holds_then_turns_torque_off() {
        let mut s = graded();
        s.stop(StopReason::Requested);
        assert!(s.is_settling());
        assert_eq!(s.fault_state(), crate::record::FaultState::Stopping);
        // The walk runs while it settles; the standstill begins the lowering.
        assert_eq!(s.step(), Action::Run);
        s.settled();
        assert!(!s.is_settling());
        let seq: Vec<Action> = (0..7).map(|_| s.step()).collect();
        assert_eq!(seq, LOWER_HOLD_OFF);
        assert_eq!(s.step(), Action::Idle);
        assert_eq!(s.stop_reason(), Some(StopReason::Requested));
    }

    #[test]
    fn with_rest_an_operator_stop_ends_resting_in_the_crouch_and_a_fault_stop_does_not() {
        let mut s = graded().with_rest(true);
        s.stop(StopReason::Requested);
        assert_eq!(s.step(), Action::Run);
        s.settled();
        let seq: Vec<Action> = (0..7).map(|_| s.step()).collect();
        let mut rest = LOWER_HOLD_OFF;
        rest[6] = Action::Rest;
        assert_eq!(seq, rest);
        // Final: resting (torque on) whatever comes after.
        s.tilt(0.8);
        assert_eq!(s.step(), Action::Rest);
        assert_eq!(
            s.state(),
            State::Resting {
                reason: StopReason::Requested
            }
        );
        assert_eq!(s.fault_state(), crate::record::FaultState::Stopping);
        // A held operator stop rests too; a minor fault and the finished plan turn torque off.
        let mut h = graded().with_rest(true);
        h.stop_with_hold(StopReason::Requested, 1);
        let seq: Vec<Action> = (0..8).map(|_| h.step()).collect();
        assert_eq!(seq[7], Action::Rest);
        let stale = StopReason::SensorStale {
            id: 200,
            age_ms: 101,
        };
        for (reason, settled) in [(stale, true), (StopReason::PlanDone, false)] {
            let mut f = graded().with_rest(true);
            if settled {
                f.stop(reason);
                f.settled();
            } else {
                f.stop_with_hold(reason, 1);
            }
            let seq: Vec<Action> = (0..10).map(|_| f.step()).collect();
            assert!(seq.contains(&Action::SendTorqueOff), "{reason:?}: {seq:?}");
            assert!(!seq.contains(&Action::Rest), "{reason:?}");
        }
    }

    #[test]
    fn a_walk_that_does_not_stand_in_time_is_lowered_anyway() {
        let mut s = graded();
        s.stop(StopReason::SensorStale {
            id: 200,
            age_ms: 101,
        });
        let seq: Vec<Action> = (0..6).map(|_| s.step()).collect();
        assert_eq!(
            seq,
            [
                Action::Run,
                Action::Run,
                Action::Run,
                Action::Run,
                Action::Lower(0),
                Action::Lower(1)
            ]
        );
    }

    #[test]
    fn each_grade_has_its_own_first_action() {
        // (reason, first action of the sequence)
        let cases = [
            (StopReason::Fall { tilt_mrad: 700 }, Action::SendTorqueOff),
            (
                StopReason::ServoFault {
                    id: 3,
                    check: walker_contract::codes::ServoCheck::HardwareError,
                    reading: 0x20,
                },
                Action::SendTorqueOff,
            ),
            (StopReason::ServoLost { id: 4 }, Action::Lower(0)),
            (
                StopReason::ServoFault {
                    id: 4,
                    check: walker_contract::codes::ServoCheck::TorqueOff,
                    reading: 0,
                },
                Action::Lower(0),
            ),
            (StopReason::NonFiniteSample { tick: 9 }, Action::Lower(0)),
            (StopReason::NonFiniteTarget { joint: 2 }, Action::Lower(0)),
            (StopReason::Requested, Action::Run),
            (StopReason::OverrunBurst { count: 5 }, Action::Run),
            (StopReason::DeviceLost { id: 111 }, Action::Run),
            (
                StopReason::ServoFault {
                    id: 5,
                    check: walker_contract::codes::ServoCheck::Temperature,
                    reading: 71,
                },
                Action::Run,
            ),
        ];
        for (reason, first) in cases {
            let mut s = graded();
            s.stop(reason);
            assert_eq!(s.step(), first, "{reason:?}");
            assert_eq!(s.stop_reason(), Some(reason));
        }
    }

    #[test]
    fn a_fall_cuts_a_graded_stop_short_and_a_lower_reason_ends_the_settling() {
        let mut s = graded();
        s.stop(StopReason::Requested);
        s.stop(StopReason::ServoLost { id: 2 });
        // Lowering now, the first reason kept.
        assert_eq!(s.step(), Action::Lower(0));
        assert_eq!(s.stop_reason(), Some(StopReason::Requested));
        // Another graded reason changes nothing; a fall goes limp and is reported.
        s.stop(StopReason::OverrunBurst { count: 5 });
        assert_eq!(s.step(), Action::Lower(1));
        s.tilt(0.8);
        assert_eq!(s.stop_reason(), Some(StopReason::Fall { tilt_mrad: 800 }));
        assert_eq!(s.step(), Action::SendTorqueOff);
    }

    #[test]
    fn a_held_stop_lowers_after_its_hold_and_the_finished_plan_does_not() {
        let mut s = graded();
        s.stop_with_hold(StopReason::Requested, 2);
        assert_eq!([s.step(), s.step()], [Action::HoldPose; 2]);
        let seq: Vec<Action> = (0..7).map(|_| s.step()).collect();
        assert_eq!(seq, LOWER_HOLD_OFF);
        let mut p = graded();
        p.stop_with_hold(StopReason::PlanDone, 2);
        let seq: Vec<Action> = (0..3).map(|_| p.step()).collect();
        assert_eq!(
            seq,
            [Action::HoldPose, Action::HoldPose, Action::SendTorqueOff]
        );
        let mut q = graded();
        q.plan_done();
        assert_eq!(q.step(), Action::HoldPose);
    }

    fn map() -> JointMap {
        JointMap::from_robot(&Robot::reference())
    }

    #[test]
    fn rad_of_tick_inverts_tick() {
        let mut m = map();
        m.ticks.sign[4] = -1;
        for j in 0..12 {
            let (t, _) = m.tick(j, 0.3);
            assert!((m.rad_of_tick(j, t) - 0.3).abs() < 1e-3, "{j}");
        }
    }

    #[test]
    fn map_from_reference_robot() {
        let m = map();
        assert_eq!(m.ticks.zero_tick, 2048);
        assert!((m.ticks.ticks_per_rad_f32() - 651.8986).abs() < 1e-3);
        // Knee 0..2.5 on both legs; right hip roll mirrored.
        assert_eq!((m.min_rad[3], m.max_rad[3]), (0.0, 2.5));
        assert_eq!((m.min_rad[9], m.max_rad[9]), (0.0, 2.5));
        assert_eq!((m.min_rad[7], m.max_rad[7]), (-0.7, 0.5));
    }

    #[test]
    fn finite_targets_pass_and_clamp() {
        let m = map();
        let prev = [2048; 12];
        let mut t = [0.0f32; 12];
        t[3] = 0.5;
        let ok = safe_targets(&t, &m, &prev).unwrap();
        assert_eq!(ok.ticks[0], 2048);
        assert_eq!(ok.ticks[3], 2048 + 326);
        assert_eq!(ok.clamped, 0);
        t[3] = -1.0; // knee below 0 → 0
        t[2] = 10.0; // hip pitch above 0.9 → 0.9
        let ok = safe_targets(&t, &m, &prev).unwrap();
        assert_eq!(ok.ticks[3], 2048);
        assert_eq!(
            ok.ticks[2],
            2048 + libm::roundf(0.9 * m.ticks.ticks_per_rad_f32()) as i32
        );
        assert_eq!(ok.clamped, (1 << 3) | (1 << 2));
    }

    #[test]
    fn fixed_point_targets_match_the_f32_conversion() {
        use gait_core::maths::fixed_point::Fx;
        let m = map();
        let prev = [2048; 12];
        // In range, below and above the limits (knee 0..2.5, hip pitch ..0.9).
        for (j, rad) in [
            (3, 0.5f32),
            (3, -1.0),
            (2, 10.0),
            (0, -0.123),
            (9, 1.7),
            (7, -0.69),
        ] {
            let mut t = [0.0f32; 12];
            t[j] = rad;
            let want = safe_targets(&t, &m, &prev).unwrap();
            let got = safe_targets_fx(&t.map(Fx::from_num), &m);
            assert!(
                (got.ticks[j] - want.ticks[j]).abs() <= 1,
                "{j} {rad}: {got:?} vs {want:?}"
            );
            assert_eq!(got.clamped, want.clamped, "{j} {rad}");
        }
    }

    #[test]
    fn non_finite_targets_hold_previous() {
        let m = map();
        let mut prev = [2048; 12];
        prev[5] = 2100;
        prev[6] = 99_999; // garbage previous value is clamped to the servo range
        let mut t = [0.1f32; 12];
        t[5] = f32::NAN;
        t[6] = f32::NEG_INFINITY;
        let e = safe_targets(&t, &m, &prev).unwrap_err();
        assert_eq!(e.non_finite, (1 << 5) | (1 << 6));
        assert_eq!(e.first_joint(), 5);
        assert_eq!(e.ticks[5], 2100);
        assert_eq!(e.ticks[6], 4095);
        assert_eq!(e.ticks[0], 2048 + 65);
        assert!(e.ticks.iter().all(|&x| (0..=4095).contains(&x)));
    }

    #[test]
    fn tick_range_clamp_with_wide_limits() {
        let mut m = map();
        m.min_rad = [-100.0; 12];
        m.max_rad = [100.0; 12];
        m.ticks.sign[0] = -1;
        let mut t = [0.0f32; 12];
        t[0] = 50.0;
        t[1] = 50.0;
        let ok = safe_targets(&t, &m, &[2048; 12]).unwrap();
        assert_eq!(ok.ticks[0], 0);
        assert_eq!(ok.ticks[1], 4095);
        assert_eq!(ok.clamped & 3, 3);
    }
}
