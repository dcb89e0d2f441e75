//! The servos' Present Position and what the f32 path makes of it: the servo deflection
//! feedback ([`gait_core::feedback::deflection`]), the leg odometry
//! ([`gait_core::measure::odometry`]), the swing leg's pitch lag for the sole's levelling
//! ([`gait_core::feedback::level`], e_q of (A10)) and the swing sole's lag for the clock hold's
//! landing condition ([`gait_core::feedback::hold`], ℓ of (A11)); the servo survey of the leg
//! servos' stiffness while the robot stands ([`gait_core::measure::stiffness`]), which sets the
//! deflection feedback's gain (D6).

use dxl::table::x_series;
use dxl::{BulkReadRequest, DeviceResult};
use gait_core::feedback::compliance::LoadModel;
use gait_core::feedback::deflection::{DeflectionConfig, DeflectionFeedback};
use gait_core::feedback::{JointCorrection, JointInput, Measured};
use gait_core::measure::odometry::SurveyedSole;
use gait_core::measure::stiffness::{Stiffness, StiffnessSurvey};
use gait_core::robot::{ANKLE_PITCH, HIP_PITCH, JOINTS_PER_LEG, KNEE, LEG_JOINTS};
use gait_core::{Robot, Side};

use crate::board::Board;
use crate::bus::BoardMaster;
use crate::supervisor::JointMap;

/// The servos' Present Position and what the firmware makes of it (f32 path only): the servo
/// deflection feedback ([`gait_core::feedback::deflection`], `deflection_ki`: its joints read in one BULK
/// READ every tick, the targets of the last walking tick before the correction (D1)) and the leg
/// odometry ([`gait_core::measure::odometry`], `sole_poses=measured`: once a step, the stance leg's six
/// on the tick after a survey falls due, the new leg's six on the next, O3′), the swing leg's
/// pitch lag (`catch_level_joints`: its three pitch servos every tick of a single support) and
/// the swing sole's lag (`catch_hold_lag`: its six servos every tick of a single support), and
/// the servo survey (the six pitch servos every standing tick until its window closes).
pub(super) struct ServoSense {
    /// The deflection feedback, while it acts or the survey may turn it on.
    deflection: Option<DeflectionFeedback>,
    /// Its configuration (the survey's gain rule D6).
    deflection_cfg: DeflectionConfig,
    /// The servo survey and the load model its torques come from.
    survey: StiffnessSurvey,
    load: LoadModel,
    /// The datasheet stiffness K_n the survey's softness is taken against, N·m/rad.
    k_nominal: f32,
    /// The survey's result, once its window closed, for the log (taken once).
    survey_note: Option<SurveyNote>,
    /// The tick period, s.
    dt_s: f32,
    /// The walking tick whose goals `last_goal` holds.
    goal_tick: Option<u32>,
    /// The leg servos' supply last read, V (NaN: none yet).
    supply_v: f32,
    /// The survey's stiffness and the supply it was measured at (V; NaN: unknown), once taken.
    surveyed: Option<(Stiffness, f32)>,
    /// The supply the deflection gain was last set for, V.
    gain_v: f32,
    /// The deflection feedback's joints.
    mask: gait_core::feedback::deflection::JointSet,
    odometry: Option<Odometry>,
    reqs: heapless::Vec<BulkReadRequest, LEG_JOINTS>,
    /// Per request: the joint index.
    joints: heapless::Vec<usize, LEG_JOINTS>,
    buf: [u8; 4 * LEG_JOINTS],
    results: [DeviceResult; LEG_JOINTS],
    /// This tick's Present Positions, rad (NaN where not read).
    present: [f32; LEG_JOINTS],
    /// The targets q* of the last walking tick before the correction, and that tick.
    sent: Option<(u32, [f32; LEG_JOINTS])>,
    /// The swing leg's pitch lag is measured (the levelling's e_q).
    swing_lag: bool,
    /// The IK's joint targets of the last walking tick, rad (NaN before the first).
    last_ik: [f32; LEG_JOINTS],
    /// The joint targets sent on the last walking tick (every correction), rad.
    last_goal: [f32; LEG_JOINTS],
    /// This tick's pitch lag e_q per leg (left, right), rad (NaN where not measured).
    lag: [f32; 2],
    /// The legs' kinematics for the swing sole's measured lag (the clock hold's landing
    /// condition), while it acts.
    landing: Option<gait_core::kinematics::leg::LegKinematics<f32>>,
    /// This tick's swing sole distance from where its targets put it, m (NaN: not measured).
    sole_lag_m: f32,
}

/// The supply change that sets the deflection gain again after the survey, V (the servos'
/// Present Input Voltage is in 0.1 V).
const SUPPLY_STEP_V: f32 = 0.099;

/// What the servo survey found and what it set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct SurveyNote {
    /// The measured stiffness (None: too little load to tell, or no standing).
    pub stiffness: Option<Stiffness>,
    /// The deflection feedback's gain k_i it gives (D6), 1/s.
    pub ki: f32,
    /// The supply it was measured at, V (NaN: none read yet).
    pub volts: f32,
}

/// The leg odometry's firmware side: its state, the legs' FK and the survey's two reads.
struct Odometry {
    legs: gait_core::measure::odometry::LegOdometry<f32>,
    kin: gait_core::kinematics::leg::LegKinematics<f32>,
    stage: Survey,
    /// The IK's joint targets of the last walking tick (before the feed-forwards and the
    /// feedback: the gait's planned motion, which the loaded leg follows), rad.
    ik: [f32; LEG_JOINTS],
}

/// Where the survey's reads stand (odometry O3′: the stance leg on one tick, the new leg on the
/// next).
#[derive(Clone, Copy)]
enum Survey {
    /// None due.
    Idle,
    /// Due since last tick: this tick reads the stance leg.
    Stance(Side),
    /// This tick reads the new leg and takes the survey, with the stance leg's read and the
    /// IK's targets sent before it.
    New {
        stance: Side,
        first: [f32; LEG_JOINTS],
        ik: [f32; LEG_JOINTS],
    },
}

impl ServoSense {
    /// The deflection feedback of `cfg` at tick period `dt_s` (its gain raised by the servo
    /// survey's softness against the datasheet stiffness `k_nominal`, N·m/rad), the servo
    /// survey when `survey` (one of its uses is on), the odometry when `odometry`, the swing
    /// leg's pitch lag when `swing_lag` and the swing sole's measured lag when `landing`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        cfg: &DeflectionConfig,
        k_nominal: f32,
        survey: bool,
        odometry: bool,
        swing_lag: bool,
        landing: bool,
        robot: &Robot,
        dt_s: f32,
    ) -> Self {
        let feedback = DeflectionFeedback::new(cfg, dt_s);
        let may_act = cfg.is_on() || (survey && cfg.ki_for(1.0) > 0.0);
        let deflection = may_act.then_some(feedback);
        let odometry = odometry.then(|| Odometry {
            legs: gait_core::measure::odometry::LegOdometry::new(
                &gait_core::measure::odometry::OdometryLimits::DEFAULT,
            ),
            kin: gait_core::kinematics::leg::LegKinematics::new(robot),
            stage: Survey::Idle,
            ik: [f32::NAN; LEG_JOINTS],
        });
        ServoSense {
            deflection,
            deflection_cfg: *cfg,
            survey: if survey {
                StiffnessSurvey::new(
                    gait_core::measure::stiffness::SETTLE_S,
                    gait_core::measure::stiffness::SPAN_S,
                    dt_s,
                )
            } else {
                StiffnessSurvey::off()
            },
            load: LoadModel::new(robot),
            k_nominal,
            survey_note: None,
            dt_s,
            goal_tick: None,
            supply_v: f32::NAN,
            surveyed: None,
            gain_v: f32::NAN,
            mask: cfg.joints,
            odometry,
            reqs: heapless::Vec::new(),
            joints: heapless::Vec::new(),
            buf: [0; 4 * LEG_JOINTS],
            results: [Ok(()); LEG_JOINTS],
            present: [f32::NAN; LEG_JOINTS],
            sent: None,
            swing_lag,
            last_ik: [f32::NAN; LEG_JOINTS],
            last_goal: [f32::NAN; LEG_JOINTS],
            lag: [f32::NAN; 2],
            landing: landing.then(|| gait_core::kinematics::leg::LegKinematics::new(robot)),
            sole_lag_m: f32::NAN,
        }
    }

    /// ONE BULK READ of the Present Positions this tick needs (rad; NaN for a reply that
    /// failed) — the deflection feedback's joints, a survey's leg (odometry O3′: the stance
    /// leg, then the new one on the next tick, which takes the survey against the plan's places
    /// of the feet `planned`), the `swing` leg's pitch servos (its pitch lag; all six for the
    /// swing sole's lag) and, while the servo survey's window is open and the last sample's
    /// `phase` stands, the pitch servos. Returns a survey taken: the new foot and its surveyed
    /// place minus the planned one (m, x and y; for the online walk's position hold).
    pub(super) fn read<B: Board>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        map: &JointMap,
        planned: &[gait_core::Place<f32>; 2],
        phase: gait_core::SupportPhase,
    ) -> Option<(Side, [f32; 2])> {
        let swing = phase.swing();
        self.present = [f32::NAN; LEG_JOINTS];
        self.lag = [f32::NAN; 2];
        self.sole_lag_m = f32::NAN;
        let leg = match self.odometry.as_ref().map(|o| o.stage) {
            Some(Survey::Stance(s)) => Some(s),
            Some(Survey::New { stance, .. }) => Some(stance.other()),
            _ => None,
        };
        let deflection = self.deflection.as_ref().is_some_and(|d| d.is_on());
        // Not on the ramp's ticks (no walking tick's goals to compare with yet).
        let surveying = self.goal_tick.is_some() && self.survey.wants(phase);
        let whole_swing = self.landing.is_some();
        let swing = swing.filter(|_| self.swing_lag || whole_swing);
        if leg.is_none() && !deflection && !surveying && swing.is_none() {
            return None;
        }
        let side_of = |j: usize| {
            if j < JOINTS_PER_LEG {
                Side::Left
            } else {
                Side::Right
            }
        };
        let in_leg = |j: usize| leg == Some(side_of(j));
        let pitch = |j: usize| matches!(j % JOINTS_PER_LEG, HIP_PITCH | KNEE | ANKLE_PITCH);
        let in_swing = |j: usize| swing == Some(side_of(j)) && (whole_swing || pitch(j));
        self.reqs.clear();
        self.joints.clear();
        let f = x_series::PRESENT_POSITION;
        for j in (0..LEG_JOINTS).filter(|&j| {
            in_leg(j)
                || in_swing(j)
                || (deflection && self.mask.contains(j))
                || (surveying && pitch(j))
        }) {
            if let Some(&id) = bus.devices().legs.get(j) {
                // At most LEG_JOINTS entries: cannot fail.
                let _ = self.reqs.push(BulkReadRequest {
                    id,
                    addr: f.addr,
                    len: f.len,
                });
                let _ = self.joints.push(j);
            }
        }
        let n = self.reqs.len();
        if let (Some(results), Some(buf)) = (self.results.get_mut(..n), self.buf.get_mut(..4 * n)) {
            if n > 0 && bus.master().bulk_read(&self.reqs, buf, results).is_ok() {
                for ((&j, r), b) in self
                    .joints
                    .iter()
                    .zip(results.iter())
                    .zip(buf.chunks_exact(4))
                {
                    if let (Ok(()), Some(v), [b0, b1, b2, b3]) = (r, self.present.get_mut(j), b) {
                        *v = map
                            .ticks
                            .rad_f32(j, i32::from_le_bytes([*b0, *b1, *b2, *b3]));
                    }
                }
            }
        }
        if let Some(side) = swing {
            let base = if side == Side::Left {
                0
            } else {
                JOINTS_PER_LEG
            };
            let off = |j: usize, of: &[f32; LEG_JOINTS]| {
                let (p, t) = (self.present.get(base + j), of.get(base + j));
                p.zip(t).map_or(f32::NAN, |(p, t)| p - t)
            };
            if let Some(l) = self
                .lag
                .get_mut(usize::from(side == Side::Right))
                .filter(|_| self.swing_lag)
            {
                *l = off(HIP_PITCH, &self.last_ik)
                    + off(KNEE, &self.last_ik)
                    + off(ANKLE_PITCH, &self.last_goal);
            }
            let leg = |of: &[f32; LEG_JOINTS]| -> Option<[f32; JOINTS_PER_LEG]> {
                of.get(base..base + JOINTS_PER_LEG)?.try_into().ok()
            };
            if let (Some(kin), Some(q), Some(goal)) = (
                self.landing.as_ref(),
                leg(&self.present),
                leg(&self.last_goal),
            ) {
                let pelvis = gait_core::kinematics::leg::Pose::level(0.0, 0.0, 0.0, 0.0);
                let at = kin.fk(side, &pelvis, &q).position();
                let to = kin.fk(side, &pelvis, &goal).position();
                // NaN (a joint unread) propagates: no hold on it.
                self.sole_lag_m = at
                    .iter()
                    .zip(to)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, |m: f32, d| if d > m || d.is_nan() { d } else { m });
            }
        }
        let o = self.odometry.as_mut()?;
        let mut taken = None;
        o.stage = match o.stage {
            Survey::Idle => Survey::Idle,
            Survey::Stance(stance) => Survey::New {
                stance,
                first: self.present,
                ik: o.ik,
            },
            Survey::New { stance, first, ik } => {
                let q = gait_core::measure::odometry::legs_at_first_read(
                    stance,
                    &first,
                    &self.present,
                    &ik,
                    &o.ik,
                );
                // A refused survey (a failed read: NaN) keeps the landing where the plan puts it.
                let new = stance.other();
                if let Ok(p) = o.legs.survey(&o.kin, &q, planned) {
                    let [l, r] = planned;
                    let plan = if new == Side::Left { l } else { r };
                    taken = Some((new, [p.x - plan.x, p.y - plan.y]));
                }
                Survey::Idle
            }
        };
        taken
    }

    /// The IK's joint targets of this walking tick (rad), for the survey's reads (O3′): kept
    /// only while a survey is under way (the next tick reads a leg).
    pub(super) fn note_ik(&mut self, q: &[f32; LEG_JOINTS]) {
        if self.swing_lag {
            self.last_ik = *q;
        }
        if let Some(o) = self
            .odometry
            .as_mut()
            .filter(|o| !matches!(o.stage, Survey::Idle))
        {
            o.ik = *q;
        }
    }

    /// Walking tick `k` of phase `phase` with the targets `q` (rad, before the correction):
    /// (D1)-(D4) against the last tick's targets if that was tick k − 1, then (D5) on `q`.
    fn apply(&mut self, k: u32, phase: gait_core::SupportPhase, q: &mut [f32; LEG_JOINTS]) {
        let Some(feedback) = self.deflection.as_mut() else {
            return;
        };
        if let Some((_, sent)) = self.sent.filter(|(at, _)| at.wrapping_add(1) == k) {
            feedback.update(phase, &sent, &self.present);
        }
        self.sent = Some((k, *q));
        feedback.apply(q);
    }

    /// The servo survey (K1)-(K2) on walking tick `k` in `phase`, the sample `input`: the goals
    /// of tick k − 1 against this tick's Present Positions, the torques the load model gives
    /// for the targets `q`; when its window closes, the deflection feedback's gain (D6).
    fn survey(&mut self, input: &JointInput<'_>, q: &[f32; LEG_JOINTS]) {
        if self.survey.is_done()
            || self.goal_tick.map(|t| t.wrapping_add(1)) != Some(input.walk_tick)
        {
            return;
        }
        // The torques only on the window's ticks (the settling and a step only count).
        let tau = if self.survey.wants(input.phase) {
            self.load.joint_torques(input.loaded, input.com_shift, q)
        } else {
            [0.0; LEG_JOINTS]
        };
        let Some(found) = self
            .survey
            .add(input.phase, &self.last_goal, &self.present, &tau)
        else {
            return;
        };
        self.surveyed = found.map(|k| (k, self.supply_v));
        let (_, ki) = self.set_gain();
        self.survey_note = Some(SurveyNote {
            stiffness: found,
            ki,
            volts: self.supply_v,
        });
    }

    /// (K3) and (D6) for the survey's stiffness at the present supply: the softness and the
    /// deflection feedback's gain set (0 when the feedback cannot act).
    fn set_gain(&mut self) -> (f32, f32) {
        let softness = self
            .surveyed_now()
            .map_or(0.0, |s| s.softness(self.k_nominal));
        let ki = self.deflection_cfg.ki_for(softness);
        self.gain_v = self.supply_v;
        match self.deflection.as_mut() {
            Some(d) => {
                d.set_gain(ki, self.dt_s);
                (softness, ki)
            }
            None => (softness, 0.0),
        }
    }

    /// The survey's result at the present supply (the drive's torque, so its K, follows the
    /// supply); None before the survey or without its result.
    fn surveyed_now(&self) -> Option<Stiffness> {
        self.surveyed
            .map(|(k, at_v)| k.at_supply(self.supply_v, at_v))
    }

    /// The survey's stiffness at the present supply, N·m/rad; None before the survey or without
    /// its result.
    pub(super) fn stiffness(&self) -> Option<f32> {
        self.surveyed_now().map(|s| s.k)
    }

    /// The leg servos' supply last read (V): after the survey a change of 0.1 V or more sets
    /// the deflection feedback's gain again for the stiffness at that supply (battery sag);
    /// returns whether it did (what follows the stiffness follows it then).
    pub(super) fn supply(&mut self, volts: f32) -> bool {
        if !(volts.is_finite() && volts > 0.0) {
            return false;
        }
        self.supply_v = volts;
        // A survey taken before any reading: measured at the first supply read.
        if let Some((_, at_v)) = self.surveyed.as_mut().filter(|(_, v)| v.is_nan()) {
            *at_v = volts;
        }
        // A NaN `gain_v` (the survey before any reading) counts as changed.
        let unchanged = (volts - self.gain_v).abs() < SUPPLY_STEP_V;
        let again = self.surveyed.is_some() && !unchanged;
        if again {
            self.set_gain();
        }
        again
    }

    /// The servo survey's result, once, when its window has closed.
    pub(super) fn take_survey_note(&mut self) -> Option<SurveyNote> {
        self.survey_note.take()
    }

    /// The soles' places for the measured ZMP when the plan puts the feet at `planned`
    /// (odometry O2; the plan's own with `sole_poses=planned`).
    pub(super) fn feet(&self, planned: [gait_core::Place<f32>; 2]) -> [SurveyedSole<f32>; 2] {
        let [l, r] = planned;
        match &self.odometry {
            Some(o) => [o.legs.sole(Side::Left, &l), o.legs.sole(Side::Right, &r)],
            None => [SurveyedSole::planned(l), SurveyedSole::planned(r)],
        }
    }

    /// Follows the support phase of the sample the servos execute and the feet's loads (N,
    /// left and right): a survey due reads the stance leg next tick, the new leg the tick after
    /// (odometry O6, the due rule and O3′).
    pub(super) fn follow(&mut self, phase: gait_core::SupportPhase, loads: [f32; 2]) {
        if let Some(o) = self.odometry.as_mut() {
            o.legs.phase(phase);
            if let (Survey::Idle, Some((stance, _))) = (o.stage, o.legs.survey_due(loads)) {
                o.stage = Survey::Stance(stance);
            }
        }
    }

    /// This tick's swing pitch lag e_q per leg (left, right; the levelling's (A10)), rad: NaN
    /// where not measured.
    pub(super) fn swing_lag(&self) -> [f32; 2] {
        self.lag
    }

    /// This tick's swing sole distance from where its targets put it (the clock hold's
    /// landing condition, A11), m: NaN when not measured.
    pub(super) fn sole_lag_m(&self) -> f32 {
        self.sole_lag_m
    }

    /// Odometry surveys taken and refused, while the odometry runs.
    pub(super) fn surveys(&self) -> Option<(u16, u16)> {
        self.odometry.as_ref().map(|o| o.legs.counts())
    }
}

/// The servo deflection feedback (D5) as the last joint correction.
impl JointCorrection for ServoSense {
    fn correct_joints(
        &mut self,
        _: &Measured<'_>,
        input: &JointInput<'_>,
        q: &mut [f32; LEG_JOINTS],
    ) {
        self.survey(input, q);
        self.apply(input.walk_tick, input.phase, q);
        if self.swing_lag || self.landing.is_some() || !self.survey.is_done() {
            self.last_goal = *q;
            self.goal_tick = Some(input.walk_tick);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The servo sense of the deflection configuration `cfg` against the XM430's datasheet
    /// stiffness, with the survey when `survey` and nothing else, at 200 Hz.
    fn build(cfg: &DeflectionConfig, survey: bool) -> ServoSense {
        ServoSense::new(
            cfg,
            18.875,
            survey,
            false,
            false,
            false,
            &Robot::reference(),
            0.005,
        )
    }

    /// A survey at 12 V that found the servos at their datasheet stiffness (σ = 0: the
    /// deflection feedback off); then the battery sags.
    fn surveyed_at_12_v(k: f32) -> ServoSense {
        let mut s = build(&DeflectionConfig::DEFAULT, true);
        s.supply(12.0);
        s.surveyed = Some((Stiffness { k, samples: 60 }, 12.0));
        s.set_gain();
        s
    }

    #[test]
    fn the_stiffness_and_the_deflection_gain_follow_the_supply() {
        let mut s = surveyed_at_12_v(18.875);
        assert_eq!(s.stiffness(), Some(18.875));
        assert!(!s.deflection.as_ref().is_some_and(|d| d.is_on()));
        // 10.5 V: K = 18.875·10.5/12 = 16.52, σ = 12/10.5 − 1 = 1/7, k_i = 4/7 per s.
        assert!(s.supply(10.5), "a 1.5 V sag sets the gain again");
        let k = s.stiffness().unwrap();
        assert!((k - 16.515_625).abs() < 1e-3, "{k}");
        let d = s.deflection.as_ref().unwrap();
        assert!(d.is_on());
        let (softness, ki) = s.set_gain();
        assert!((softness - 1.0 / 7.0).abs() < 1e-4, "{softness}");
        assert!((ki - 4.0 / 7.0).abs() < 1e-4, "{ki}");
        // Back to 12 V: off again; readings that are no voltage change nothing.
        s.supply(12.0);
        assert!(!s.deflection.as_ref().unwrap().is_on());
        for bad in [f32::NAN, 0.0, -3.0, f32::INFINITY] {
            assert!(!s.supply(bad));
            assert_eq!(s.stiffness(), Some(18.875));
        }
        // A change below 0.1 V keeps the gain set for the last one.
        assert!(!s.supply(11.95));
        assert_eq!(s.gain_v, 12.0);
    }

    #[test]
    fn without_a_survey_result_the_supply_sets_nothing() {
        let cfg = DeflectionConfig::DEFAULT;
        let mut s = build(&cfg, true);
        assert!(!s.supply(10.0), "no survey result: nothing to set");
        assert_eq!(s.stiffness(), None);
        assert!(!s.deflection.as_ref().unwrap().is_on());
        // The deflection feedback is not even built when neither k_i nor soft_ki can act, nor
        // when no survey runs; no survey, no reads for it.
        assert!(build(&DeflectionConfig::OFF, true).deflection.is_none());
        let unsurveyed = build(&cfg, false);
        assert!(unsurveyed.deflection.is_none());
        assert!(!unsurveyed.survey.wants(gait_core::SupportPhase::Standing));
        assert!(unsurveyed.survey.is_done());
        // A survey taken before the first supply reading counts as measured at that reading.
        let mut early = build(&cfg, true);
        early.surveyed = Some((
            Stiffness {
                k: 18.875,
                samples: 60,
            },
            f32::NAN,
        ));
        early.supply(11.0);
        assert_eq!(early.stiffness(), Some(18.875));
        early.supply(9.625);
        assert!((early.stiffness().unwrap() - 16.515_625).abs() < 1e-3);
    }
}
