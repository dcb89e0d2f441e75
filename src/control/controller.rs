//! The control tick as a pipeline: [`Controller::tick`] reads as the data flow
//!
//! ```text
//!  sense ─▶ estimate ─▶ command ─▶ walk mode ─▶ sample corrections ─▶ IK ─▶ joint corrections ─▶ act ─▶ report
//!  (BULK READs,  (trunk, τ,    (command   (modes: ramp,  (TickPath:             (TickPath)            (safe targets,  (tick record,
//!   plausibility, measured ZMP, port)      online walk,   catching, stabilizer,                        SYNC WRITE,     command port
//!   supervisor)   loads)                   plan)          fdc)                                         servo monitor)  status)
//! ```
//!
//! The arithmetic of the estimate, the corrections and the IK is the [`TickPath`] the run chose
//! (f32 or fixed point); the supervisor's action decides whether the walk runs, holds the pose
//! or turns torque off.

use gait_core::feedback::{IkOffsets, Measured};
use gait_core::gait::Sample;
use gait_core::gait::Targets;
use gait_core::maths::fixed_point::Fx;
use gait_core::robot::LEG_JOINTS;
use gait_core::trajectory::command::WalkCommand;
use gait_core::trajectory::fixed_sampler::FixedFoot;
use gait_core::GaitSample;
#[cfg(not(feature = "board-opencm"))]
use walker_contract::command_port::ParamAccess;
use walker_contract::command_port::{Mode, PortState, PortStatus};

use crate::board::{Board, Stage};
use crate::bus::BoardMaster;
use crate::monitor::ServoMonitor;
use crate::record::{FaultKind, FaultState, LogWriter, LoggedPhase, Record, TickRecord};
use crate::startup::Ramp;
use crate::supervisor::{safe_targets, safe_targets_fx, Action, JointMap, StopReason, Supervisor};
use crate::Config;

use super::act::{fault, torque_off, write_goals, write_stop};
use super::commanded::{self, CommandLink};
use super::faults::FaultInjector;
use super::modes::{Motion, TakenStep, Tau, Walk};
use super::path::{Goal, IkRequest, MeasuredZmp, TickPath, Trunk};
use super::sense::Sense;
use super::RunEnd;

/// What the estimate stage made of this tick's sensors.
pub(super) struct Estimate {
    trunk: Trunk,
    tau: Tau,
    zmp: MeasuredZmp,
    loads: [f32; 2],
}

/// The walking controller between start-up and torque off: its state, in place.
pub(super) struct Controller<'a, P: TickPath> {
    pub cfg: &'a Config,
    pub targets: &'a Targets,
    pub map: &'a JointMap,
    pub walk: &'a mut Walk,
    pub path: P,
    pub sense: Sense,
    pub sup: Supervisor<3>,
    pub monitor: ServoMonitor,
    pub link: &'a mut CommandLink,
    pub log: LogWriter,
    pub faults: FaultInjector,
    /// The goal ticks last written.
    pub last_ticks: [i32; LEG_JOINTS],
    /// The last gait tick's present sample (corrected): the reference the measurements answer.
    pub prev: GaitSample<f32>,
    /// Its integer feet when the fixed-point sampler made it (no lead, no shift).
    pub prev_feet_fx: Option<[FixedFoot; 2]>,
    /// This tick's joint targets (written in place by the walk stage).
    pub goal: Goal,
    /// Joints whose clamping was logged.
    pub clamped_seen: u16,
    /// Ticks of the final hold after the plan.
    pub final_hold: u16,
    /// A graded stop's lowering from the last targets to the crouch (built at its first tick).
    pub lowering: Option<Ramp>,
    /// Whether the IK takes the present sample (no servo lead).
    pub no_lead: bool,
}

impl<P: TickPath> Controller<'_, P> {
    /// One control tick; the run's end once torque is off.
    // Out of line: its temporaries get a frame of their own, beside start-up's (stack:
    // scripts/stack-depth.py).
    #[inline(never)]
    pub fn tick<B: Board>(&mut self, bus: &mut BoardMaster<'_, B>) -> Option<RunEnd> {
        let tick = bus.board().wait_tick();
        bus.board().crash_cell().note_tick(tick.index);
        self.sup.tick_timing(tick.overrun);

        bus.board().stage(Stage::Sense);
        self.sense.read(bus);
        self.path.read_servos(bus, &self.prev, self.walk);
        let imu = self.sense.supervise(bus, &mut self.log, &mut self.sup);
        bus.board().stage(Stage::Estimate);
        let est = self.estimate(imu);
        bus.board().stage(Stage::Command);
        self.command(bus.board());

        bus.board().stage(Stage::Walk);
        let settling = self.sup.is_settling();
        let action = self.sup.step();
        let mut rec = TickRecord {
            time_us: tick.nominal_us as u32,
            overrun: tick.overrun,
            ..TickRecord::default()
        };
        match action {
            Action::Run => {
                let has_goal = self.walk_tick(bus.board(), &est, &mut rec);
                if self.sup.is_settling() && self.walk.at_standstill() {
                    self.sup.settled();
                }
                bus.board().stage(Stage::Act);
                self.act(bus, has_goal, &mut rec);
            }
            Action::Lower(k) => {
                bus.board().stage(Stage::Act);
                self.lower(bus, k, &mut rec);
            }
            Action::HoldPose | Action::Rest => write_goals(bus, &self.last_ticks),
            Action::SendTorqueOff => torque_off(bus, &mut self.log, self.cfg),
            Action::Idle => {}
        }
        bus.board().stage(Stage::Report);
        self.report(bus, action, settling, &est, &mut rec);
        self.end(bus, action)
    }

    /// Estimate: the trunk (the supervisor's tilt), τ, the measured ZMP and the loads; the leg
    /// odometry follows the executed phase and the loads (a robot without foot sensors: the
    /// loads' split its ZMP reference plans, which times each landing's survey).
    fn estimate(&mut self, imu: Option<dxl::table::imu::ImuSample>) -> Estimate {
        let trunk = self.path.trunk(imu.as_ref(), self.walk);
        self.sup.tilt(trunk.tilt);
        let tau = self.path.tau();
        let feet = self.sense.feet();
        let zmp = self.path.zmp(feet, &self.prev, self.prev_feet_fx);
        let loads = self.path.loads(feet);
        let split = if self.cfg.robot.bus.foot_boards.is_some() {
            loads
        } else {
            self.prev.planned_load_shares()
        };
        self.path.follow(self.prev.phase, split);
        Estimate {
            trunk,
            tau,
            zmp,
            loads,
        }
    }

    /// The command port: answered every tick; torque off on command; the command deadman; the
    /// online walk's command.
    fn command<B: Board>(&mut self, board: &mut B) {
        self.link.poll(board, &mut self.log);
        // A run is going: parameters read, never set (the OpenCM 9.04's build has no
        // parameter table: its flash).
        #[cfg(not(feature = "board-opencm"))]
        self.link
            .port
            .table
            .serve_param(ParamAccess::ReadOnly(self.cfg));
        #[cfg(feature = "board-opencm")]
        self.link
            .port
            .table
            .answer_param(walker_contract::command_port::ParamStatus::Unsupported);
        if self.link.mode() == Mode::TorqueOff {
            self.sup.stop(StopReason::Requested);
        }
        if let Some(o) = self.walk.gait.online_mut() {
            let limit_us = u64::from(self.cfg.deadman_ms).saturating_mul(1000);
            self.link.deadman(board, &mut self.log, o, limit_us);
        }
        if !self.walk.is_starting() {
            if let Some(o) = self.walk.gait.online_mut() {
                if self.sup.is_settling() {
                    // A graded stop walks to a standstill whatever the port commands.
                    o.clear_steps();
                    o.set_command(WalkCommand::default());
                } else {
                    o.set_command(self.link.velocity());
                    self.link.feed_steps(o);
                }
            }
        }
    }

    /// Tick `k` of a graded stop's lowering: the minimum-jerk ramp from the targets last sent
    /// to the crouch ([`crouch_joints`]), through [`Controller::act`] (limits, the SYNC WRITE,
    /// the servo monitor).
    fn lower<B: Board>(&mut self, bus: &mut BoardMaster<'_, B>, k: u16, rec: &mut TickRecord) {
        if k == 0 || self.lowering.is_none() {
            let mut from = [0.0f32; LEG_JOINTS];
            for (j, (f, &t)) in from.iter_mut().zip(self.last_ticks.iter()).enumerate() {
                *f = self.map.rad_of_tick(j, t);
            }
            let to = crouch_joints(self.targets, &self.prev, self.cfg.crouch_m).unwrap_or(from);
            let ticks = u32::from(self.sup.lower_ticks());
            self.lowering = Some(Ramp::new(from, to, ticks));
        }
        let has_goal = match &self.lowering {
            Some(r) => {
                self.goal = Goal::Rad(r.at(u32::from(k)));
                true
            }
            None => false,
        };
        self.act(bus, has_goal, rec);
    }

    /// The walk mode's motion, the sample corrections, the IK and the joint corrections: this
    /// tick's goal into [`Controller::goal`] (false: none, a non-finite sample, the stop has
    /// begun).
    fn walk_tick<B: Board>(&mut self, board: &mut B, est: &Estimate, rec: &mut TickRecord) -> bool {
        let hold = self.path.wants_hold();
        let (k, footstep) = match self.walk.tick(est.tau, hold) {
            Motion::Ramp(q) => {
                self.goal = Goal::Rad(q);
                return true;
            }
            Motion::Gait { k, footstep } => (k, footstep),
        };
        if let Some(f) = footstep {
            log_footstep(board, &mut self.log, &f);
        }
        // The walk's own samples, borrowed; copied only when a fault spoils them or a sample
        // correction moves them (copies: the walk hands out the plan's samples again on a held
        // tick).
        let mut own_present: Option<GaitSample<f32>> = None;
        let mut own_ahead: Option<Sample> = None;
        if self.faults.sample_at(k) {
            match self.walk.ahead() {
                Some(a) => self.faults.sample(k, &mut own_ahead.insert(*a).f32),
                None => self
                    .faults
                    .sample(k, own_present.insert(*self.walk.present())),
            }
        }
        let present = own_present.as_ref().unwrap_or(self.walk.present());
        let ahead = own_ahead.as_ref().or(self.walk.ahead());
        // Before the IK (which would clamp a NaN pelvis to finite, meaningless angles).
        if !(present.is_finite() && ahead.is_none_or(|a| a.f32.is_finite())) {
            crate::fw_log!(error, "non-finite gait sample at walk tick {}", k);
            self.sup.stop(StopReason::NonFiniteSample { tick: k });
            return false;
        }
        let measured = Measured {
            attitude: est.trunk.attitude,
            gyro: est.trunk.gyro,
            loads: est.loads,
            zmp: est.zmp.m,
            previous: &self.prev,
        };
        let mut offsets = IkOffsets::default();
        let moves =
            self.path
                .update_samples(board, &mut self.log, &measured, present, &mut offsets);
        if moves {
            let p = own_present.get_or_insert(*self.walk.present());
            self.path.apply_samples(p);
            if let Some(a) = self.walk.ahead() {
                let a = own_ahead.get_or_insert(*a);
                self.path.apply_samples(&mut a.f32);
                // The integer IK would not see the moves.
                a.fixed = None;
            }
        }
        let present = own_present.as_ref().unwrap_or(self.walk.present());
        let ahead = own_ahead.as_ref().or(self.walk.ahead());
        let IkOffsets { com_shift, sole_dz } = offsets;
        if !com_shift.iter().all(|v| v.is_finite()) {
            self.sup.stop(StopReason::NonFiniteSample { tick: k });
            return false;
        }
        let ik = IkRequest {
            plan: self.walk.gait.plan(),
            ahead,
            present,
            com_shift,
            sole_dz,
            walk_tick: k,
            gyro_raw: est.trunk.gyro_raw,
            f32_only: self.faults.targets_at(k),
        };
        self.path
            .joints(self.targets, &measured, &ik, &mut self.goal);
        if self.walk.gait.plan_done() {
            self.sup
                .stop_with_hold(StopReason::PlanDone, self.final_hold);
        }
        if self.faults.stop_at(k) {
            self.sup.stop(StopReason::Requested);
        }
        if let Goal::Rad(q) = &mut self.goal {
            self.faults.targets(k, q);
        }
        // The present sample in fixed point (the one the integer IK took: no lead, no shift)
        // goes to the log without float.
        let present_fx = ahead
            .and_then(|a| a.fixed.as_ref())
            .filter(|_| self.no_lead && !self.cfg.stabilizer_on);
        match present_fx {
            Some(f) => {
                rec.zmp_ref = f.zmp.map(pos_of_fx);
                rec.com = [pos_of_fx(f.com[0]), pos_of_fx(f.com[1])];
            }
            None => {
                let ([zx, zy], [cx, cy]) = self.logged_reference(present);
                rec.set_zmp_ref_m(zx, zy);
                rec.set_com_m(cx + com_shift[0], cy + com_shift[1]);
            }
        }
        rec.phase = phase_of(present);
        self.prev_feet_fx = present_fx.map(|f| f.feet);
        self.prev = *present;
        true
    }

    /// The ZMP reference and the CoM (x, y; m) of the moved sample `s` in the world the leg
    /// odometry estimates, as the log carries them (the landing hold's share taken out).
    fn logged_reference(&self, s: &GaitSample<f32>) -> ([f32; 2], [f32; 2]) {
        let [wx, wy] = self.path.reference_shift();
        let ([zx, zy], [cx, cy, _]) = (s.zmp, s.com);
        ([zx - wx, zy - wy], [cx - wx, cy - wy])
    }

    /// Act: the goal through the joint limits to servo ticks (a non-finite target holds the
    /// previous tick and stops; without a goal the last ticks again), ONE SYNC WRITE, the servo
    /// monitor.
    fn act<B: Board>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        has_goal: bool,
        rec: &mut TickRecord,
    ) {
        let checked = has_goal.then(|| match &self.goal {
            Goal::Rad(q) => safe_targets(q, self.map, &self.last_ticks),
            Goal::Fx(q) => Ok(safe_targets_fx(q, self.map)),
        });
        let ticks = match checked {
            None => {
                // The log shows the last finite sample.
                let ([zx, zy], [cx, cy]) = self.logged_reference(&self.prev);
                rec.set_zmp_ref_m(zx, zy);
                rec.set_com_m(cx, cy);
                rec.phase = LoggedPhase::Stopped;
                self.last_ticks
            }
            Some(Ok(t)) => {
                if t.clamped & !self.clamped_seen != 0 {
                    let first = t.clamped.trailing_zeros() as u8;
                    let now = bus.board().now_us();
                    let rec = fault(now, FaultKind::TargetClamped, first, i32::from(t.clamped));
                    self.log.write(bus.board(), rec);
                }
                self.clamped_seen |= t.clamped;
                t.ticks
            }
            Some(Err(e)) => {
                self.sup.stop(StopReason::NonFiniteTarget {
                    joint: e.first_joint(),
                });
                e.ticks
            }
        };
        write_goals(bus, &ticks);
        self.last_ticks = ticks;
        let limits = &self.cfg.servo_limits;
        let period = self.cfg.tick_period_us;
        if let Some(reason) =
            self.monitor
                .poll(bus, limits, period, &self.last_ticks, &self.map.ticks)
        {
            crate::fw_log!(error, "servo fault: {}", reason);
            let (_, id, _) = reason.code();
            let now = bus.board().now_us();
            let rec = fault(
                now,
                FaultKind::ServoProblem,
                id,
                reason.servo_problem_value(),
            );
            self.log.write(bus.board(), rec);
            self.sup.stop(reason);
        }
    }

    /// Report: the tick record (`settling`: the action came from a graded stop's walk to a
    /// standstill) and the command port's status.
    fn report<B: Board>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        action: Action,
        settling: bool,
        est: &Estimate,
        rec: &mut TickRecord,
    ) {
        if action != Action::Run {
            let ([zx, zy], [cx, cy]) = self.logged_reference(&self.prev);
            rec.set_zmp_ref_m(zx, zy);
            rec.set_com_m(cx, cy);
            rec.phase = match self.sup.stop_reason() {
                Some(StopReason::PlanDone) => LoggedPhase::Standing,
                _ => LoggedPhase::Stopped,
            };
        }
        if let Some(z) = est.zmp.fx {
            rec.zmp_meas = z.map(pos_of_fx);
            rec.zmp_valid = true;
        } else if let Some([zx, zy]) = est.zmp.m {
            rec.set_zmp_meas_m(zx, zy);
            rec.zmp_valid = true;
        }
        match est.tau {
            Tau::MilliNm(t) => rec.tau_mnm = t.clamp(-32_767, 32_767) as i16,
            Tau::Nm(t) => rec.set_tau_nm(t),
        }
        // The state that produced this tick's action.
        rec.fault = match action {
            Action::Run if settling => FaultState::Stopping,
            Action::Run if self.sup.any_holding() => FaultState::Holding,
            Action::Run => FaultState::Ok,
            Action::Lower(_) | Action::HoldPose | Action::Rest => FaultState::Stopping,
            Action::SendTorqueOff | Action::Idle => FaultState::TorqueOff,
        };
        let state = match action {
            Action::Run => self.walk.port_state(),
            Action::Lower(_) | Action::HoldPose => PortState::Stopping,
            Action::SendTorqueOff | Action::Idle => PortState::Stopped,
            Action::Rest => PortState::Resting,
        };
        let supply_dv = self.monitor.supply_dv();
        if supply_dv > 0 {
            self.path.supply(supply_dv);
        }
        let online = self.walk.gait.online();
        let steps = online.map_or(self.prev.steps_done, |o| o.steps_done());
        self.link.publish(&PortStatus {
            state,
            support: commanded::support_code(self.prev.phase),
            step_count: u16::try_from(steps).unwrap_or(u16::MAX),
            zmp_m: est.zmp.m,
            stop_code: self.sup.stop_reason().map_or(0, |r| r.kind().code()),
            fault_kind: self.log.last_fault(),
            walk_velocity: online.map_or([0.0; 3], |o| o.velocity()),
            queued: online.map_or(0, |o| o.queued()),
            servo_stiffness_cnm: self.path.servo_stiffness_cnm(),
            supply_dv,
        });
        rec.bus = bus.counters();
        rec.overruns = u16::try_from(bus.board().overruns()).unwrap_or(u16::MAX);
        self.log.write(bus.board(), Record::Tick(*rec));
        bus.board().feed();
    }

    /// After torque off (or at rest in the crouch): the stop record and the run's end.
    fn end<B: Board>(&mut self, bus: &mut BoardMaster<'_, B>, action: Action) -> Option<RunEnd> {
        if !matches!(action, Action::SendTorqueOff | Action::Idle | Action::Rest) {
            return None;
        }
        let reason = self.sup.stop_reason().unwrap_or(StopReason::Requested);
        write_stop(bus, &mut self.log, reason);
        crate::fw_log!(info, "stopped: {}", reason);
        if let Some((taken, refused)) = self.path.surveys() {
            crate::fw_log!(info, "odometry: {} surveys, {} refused", taken, refused);
        }
        if action == Action::Rest {
            crate::fw_log!(info, "resting in the crouch with torque on");
            return Some(RunEnd::Resting(reason));
        }
        Some(RunEnd::Stopped(reason))
    }
}

/// The crouch of a graded stop: `s` with both soles on the ground where they are, the pelvis
/// over their midpoint and `depth` (m) below the sample's height, through the IK (which clamps
/// to reach); `None` if the joints come out non-finite.
pub(super) fn crouch_joints(
    targets: &Targets,
    s: &GaitSample<f32>,
    depth: f32,
) -> Option<[f32; LEG_JOINTS]> {
    let mut c = *s;
    for f in c.feet.iter_mut() {
        f.z = 0.0;
    }
    let [l, r] = &c.feet;
    let mid = [0.5 * (l.x + r.x), 0.5 * (l.y + r.y)];
    c.com = [mid[0], mid[1], s.com[2] - depth];
    c.com_vel = [0.0; 2];
    c.zmp = mid;
    c.phase = gait_core::SupportPhase::Standing;
    c.support_foot = None;
    let q = targets.joints(&c, [0.0; 2]).0;
    q.iter().all(|v| v.is_finite()).then_some(q)
}

/// Logs a footstep the online walk committed.
fn log_footstep<B: Board>(board: &mut B, log: &mut LogWriter, f: &TakenStep) {
    commanded::log_footstep(
        board,
        log,
        f.step.side,
        &f.step.place,
        f.turn,
        f.shift,
        f.given,
    );
}

/// The logged support phase of a sample.
fn phase_of(s: &GaitSample<f32>) -> LoggedPhase {
    match s.phase {
        gait_core::SupportPhase::Standing => LoggedPhase::Standing,
        gait_core::SupportPhase::Double => LoggedPhase::Double,
        gait_core::SupportPhase::Single(gait_core::Side::Left) => LoggedPhase::SingleLeft,
        gait_core::SupportPhase::Single(gait_core::Side::Right) => LoggedPhase::SingleRight,
    }
}

/// An I16F16 position (m) in the log's unit ([`crate::record::POS_UNIT_M`] = 10 µm), rounded
/// half up: bits · 10⁵ / 2¹⁶ (integer only), saturating at the record's ±8,388,607 like
/// `pos_from_m`.
fn pos_of_fx(v: Fx) -> i32 {
    let p = (i64::from(v.to_bits()) * 100_000 + (1 << 15)) >> 16;
    p.clamp(-8_388_607, 8_388_607) as i32
}
