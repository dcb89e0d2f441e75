//! The servos' Present Position and what the f32 path makes of it: the servo deflection
//! feedback ([`gait_core::feedback::deflection`]), the leg odometry
//! ([`gait_core::measure::odometry`]), the swing leg's pitch lag for the sole's levelling
//! ([`gait_core::feedback::level`], e_q of (A10)) and the swing sole's lag for the clock hold's
//! landing condition ([`gait_core::feedback::hold`], ℓ of (A11)).

use dxl::table::x_series;
use dxl::{BulkReadRequest, DeviceResult};
use gait_core::feedback::{JointCorrection, JointInput, Measured};
use gait_core::measure::odometry::SurveyedSole;
use gait_core::robot::{ANKLE_PITCH, HIP_PITCH, JOINTS_PER_LEG, KNEE, LEG_JOINTS};
use gait_core::{Robot, Side};
use walker_contract::bus_map as ids;

use crate::board::Board;
use crate::bus::BoardMaster;
use crate::supervisor::JointMap;

/// The servos' Present Position and what the firmware makes of it (f32 path only): the servo
/// deflection feedback ([`gait_core::feedback::deflection`], `deflection_ki`: its joints read in one BULK
/// READ every tick, the targets of the last walking tick before the correction (D1)) and the leg
/// odometry ([`gait_core::measure::odometry`], `sole_poses=measured`: once a step, the stance leg's six
/// on the tick after a survey falls due, the new leg's six on the next, O3′), the swing leg's
/// pitch lag (`catch_level_joints`: its three pitch servos every tick of a single support) and
/// the swing sole's lag (`catch_hold_lag`: its six servos every tick of a single support).
/// Built only while one of them acts.
pub(super) struct ServoSense {
    deflection: Option<gait_core::feedback::deflection::DeflectionFeedback>,
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
    /// The deflection feedback of `cfg` at tick period `dt_s`, the odometry when `odometry`,
    /// the swing leg's pitch lag when `swing_lag` and the swing sole's measured lag when
    /// `landing`; `None` while none acts.
    pub(super) fn new(
        cfg: &gait_core::feedback::deflection::DeflectionConfig,
        odometry: bool,
        swing_lag: bool,
        landing: bool,
        robot: &Robot,
        dt_s: f32,
    ) -> Option<Self> {
        let feedback = gait_core::feedback::deflection::DeflectionFeedback::new(cfg, dt_s);
        let deflection = feedback.is_on().then_some(feedback);
        let odometry = odometry.then(|| Odometry {
            legs: gait_core::measure::odometry::LegOdometry::new(
                &gait_core::measure::odometry::OdometryLimits::DEFAULT,
            ),
            kin: gait_core::kinematics::leg::LegKinematics::new(robot),
            stage: Survey::Idle,
            ik: [f32::NAN; LEG_JOINTS],
        });
        if deflection.is_none() && odometry.is_none() && !swing_lag && !landing {
            return None;
        }
        Some(ServoSense {
            deflection,
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
        })
    }

    /// ONE BULK READ of the Present Positions this tick needs (rad; NaN for a reply that
    /// failed) — the deflection feedback's joints, a survey's leg (odometry O3′: the stance
    /// leg, then the new one on the next tick, which takes the survey against the plan's places
    /// of the feet `planned`) and the `swing` leg's pitch servos (its pitch lag; all six for the
    /// swing sole's lag). Returns a survey taken: the new foot and its surveyed place minus the
    /// planned one (m, x and y; for the online walk's position hold).
    pub(super) fn read<B: Board>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        map: &JointMap,
        planned: &[gait_core::Place<f32>; 2],
        swing: Option<Side>,
    ) -> Option<(Side, [f32; 2])> {
        self.present = [f32::NAN; LEG_JOINTS];
        self.lag = [f32::NAN; 2];
        self.sole_lag_m = f32::NAN;
        let leg = match self.odometry.as_ref().map(|o| o.stage) {
            Some(Survey::Stance(s)) => Some(s),
            Some(Survey::New { stance, .. }) => Some(stance.other()),
            _ => None,
        };
        let deflection = self.deflection.is_some();
        let whole_swing = self.landing.is_some();
        let swing = swing.filter(|_| self.swing_lag || whole_swing);
        if leg.is_none() && !deflection && swing.is_none() {
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
        let in_swing = |j: usize| {
            swing == Some(side_of(j))
                && (whole_swing || matches!(j % JOINTS_PER_LEG, HIP_PITCH | KNEE | ANKLE_PITCH))
        };
        self.reqs.clear();
        self.joints.clear();
        let f = x_series::PRESENT_POSITION;
        for j in (0..LEG_JOINTS)
            .filter(|&j| in_leg(j) || in_swing(j) || (deflection && self.mask.contains(j)))
        {
            if let Some(id) = ids::servo_id(j) {
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

    /// Odometry surveys taken and refused.
    pub(super) fn surveys(&self) -> (u16, u16) {
        self.odometry.as_ref().map_or((0, 0), |o| o.legs.counts())
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
        self.apply(input.walk_tick, input.phase, q);
        if self.swing_lag || self.landing.is_some() {
            self.last_goal = *q;
        }
    }
}
