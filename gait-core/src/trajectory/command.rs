//! Walking on command: velocity commands (vx, vy, yaw rate) turned into omnidirectional
//! footsteps, one step at a time, within the leg's reach and without the feet colliding.
//!
//! **Velocity filter.** A command c = (vx, vy, ω) (m/s, m/s, rad/s, robot frame) is first
//! clamped to [`CommandLimits`] (|vx| ≤ `vx_forward` forward / `vx_backward` backward, |vy| ≤
//! `vy`, |ω| ≤ `yaw_rate`, each non-finite component counted as 0), then the walking velocity v
//! moves towards it by at most `acc·T` per step and axis (T = the step period):
//!
//! ```text
//!   v_{n+1} = v_n + clamp(c − v_n, −a·T, a·T)                                     (S1)
//! ```
//!
//! **Footprint.** Step n swings foot s (+1 left, −1 right) while the other foot supports at
//! S = (x_S, y_S, θ_S). With d = v_{n+1}·T (the torso's travel over one step period, robot frame),
//! the swing foot lands at
//!
//! ```text
//!   θ = θ_S + d_ω,   (x, y) = (x_S, y_S) + R(θ_S + d_ω/2)·(d_x, s·2w + d_y)             (S2)
//! ```
//!
//! (w = the nominal half width `step_width`): consecutive footprints advance by v·T, so the
//! robot moves at v; the offset turns by half the step's heading change so that a turn is
//! symmetric. Zero velocity gives a step in place beside the support foot, parallel to it.
//!
//! A heading correction δ (rad, [`StepGenerator::next_step_turned`]) is added to the step's
//! turn, d_ω ← d_ω + δ, without entering the velocity state v:
//!
//! ```text
//!   θ = θ_S + d_ω + δ                                                                   (S3)
//! ```
//!
//! A position correction c = (c_x, c_y) (m, in the support foot's frame,
//! [`StepGenerator::next_step_held`]) is added to the step's travel the same way, d_x ← d_x + c_x,
//! d_y ← d_y + c_y, outside the velocity state:
//!
//! ```text
//!   (x, y) = (x_S, y_S) + R(θ_S + d_ω/2)·(d_x + c_x, s·2w + d_y + c_y)                   (S4)
//! ```
//!
//! **Limits.** Each footprint must pass the plan's reach check ([`StepLimits::check`]: forward
//! distance, lateral distance ≥ sole width + 1 cm, heading change) and the sole-corner check: all
//! four corners of the swing sole lie at least [`SOLE_GAP`] beyond the support sole's inner edge
//! (lateral coordinate in the support frame, times s, ≥ sole_width/2 + gap) — turning feet do not
//! overlap at the toes or heels. A footprint that fails is moved back towards the in-place step:
//! d ← λ·d with λ ∈ [0, 1) found by [`SCALE_STEPS`] bisections (the largest passing λ to
//! 2⁻²⁴), and the walking velocity is set to the d actually stepped (v = λ·v), so the velocity
//! state is always what the feet did: at the reach limit the robot walks at the largest speed
//! the leg allows (Table 2's z_c and T = 0.64 s: 0.067 m per step, 0.105 m/s). λ = 0 (the
//! in-place step) always passes for a valid width (checked by [`StepGenerator::new`]).
//!
//! Everything is deterministic arithmetic in `R`: the host and the firmware integrate the same
//! commands to the same footprints.

use crate::error::GaitError;
use crate::maths::real::Real;
use crate::robot::{Robot, Side};
use crate::trajectory::plan::{Footstep, Place, StepLimits};

/// Clearance between the soles' facing edges, m.
pub const SOLE_GAP: f64 = 0.005;
/// Bisections of the footprint back-off λ.
pub const SCALE_STEPS: u32 = 24;

/// A walking velocity (robot frame).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WalkCommand<R> {
    /// Forward velocity, m/s.
    pub vx: R,
    /// Leftward velocity, m/s.
    pub vy: R,
    /// Yaw rate (counter-clockwise seen from above), rad/s.
    pub yaw_rate: R,
}

impl<R: Real> WalkCommand<R> {
    /// Standing still.
    pub fn zero() -> Self {
        WalkCommand {
            vx: R::zero(),
            vy: R::zero(),
            yaw_rate: R::zero(),
        }
    }

    /// True when every component is 0.
    pub fn is_zero(&self) -> bool {
        self.vx == R::zero() && self.vy == R::zero() && self.yaw_rate == R::zero()
    }
}

/// Velocity and acceleration limits of the command filter (S1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommandLimits {
    /// Largest forward velocity, m/s.
    pub vx_forward: f64,
    /// Largest backward velocity (positive), m/s.
    pub vx_backward: f64,
    /// Largest sideways velocity, m/s.
    pub vy: f64,
    /// Largest yaw rate, rad/s.
    pub yaw_rate: f64,
    /// Largest change of vx and vy per second, m/s².
    pub acc: f64,
    /// Largest change of the yaw rate per second, rad/s².
    pub yaw_acc: f64,
}

impl CommandLimits {
    /// Kid-size defaults: 0.2 m/s forward, 0.1 m/s back, 0.1 m/s sideways, 0.6 rad/s
    /// (34°/s); 0.1 m/s² and 0.5 rad/s² (a stop from full speed in two to three steps).
    pub const DEFAULT: CommandLimits = CommandLimits {
        vx_forward: 0.2,
        vx_backward: 0.1,
        vy: 0.1,
        yaw_rate: 0.6,
        acc: 0.1,
        yaw_acc: 0.5,
    };

    /// Every limit finite and positive.
    pub fn is_valid(&self) -> bool {
        [
            self.vx_forward,
            self.vx_backward,
            self.vy,
            self.yaw_rate,
            self.acc,
            self.yaw_acc,
        ]
        .iter()
        .all(|v| v.is_finite() && *v > 0.0)
    }
}

/// Footsteps from velocity commands, one per call of [`StepGenerator::next_step`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepGenerator<R> {
    /// The plan's reach limits.
    reach: StepLimits,
    /// Velocity and acceleration limits.
    limits: CommandLimits,
    /// Nominal half width w, m.
    half_width: R,
    /// Step period T, s.
    period: R,
    /// Sole length and width, m.
    sole: [R; 2],
    /// The walking velocity v (vx, vy, ω) after the last step.
    velocity: [R; 3],
    /// Where each foot is (left, right).
    feet: [Place<R>; 2],
    /// The foot that swings next.
    next_swing: Side,
}

fn clamp_r<R: Real>(v: R, lo: R, hi: R) -> R {
    if !v.is_finite() {
        R::zero()
    } else {
        v.clamp_to(lo, hi)
    }
}

impl<R: Real> StepGenerator<R> {
    /// A generator for `robot` standing with its feet at `feet` (left, right), walking with
    /// half width `half_width` (m) and step period `period` (s), `first` the foot that swings
    /// first; the reach limits are the plan's at CoM height `z_c`.
    pub fn new(
        robot: &Robot,
        z_c: f64,
        limits: CommandLimits,
        half_width: R,
        period: R,
        feet: [Place<R>; 2],
        first: Side,
    ) -> Result<Self, GaitError> {
        if !limits.is_valid() {
            return Err(GaitError::NonPositiveParameter);
        }
        if !(half_width.is_finite() && period.is_finite() && feet.iter().all(|f| f.is_finite())) {
            return Err(GaitError::NonFinite);
        }
        if period <= R::zero() {
            return Err(GaitError::NonPositivePeriod);
        }
        let reach = StepLimits::for_robot(robot, z_c);
        let g = &robot.geometry;
        let gen = StepGenerator {
            reach,
            limits,
            half_width,
            period,
            sole: [R::of(g.sole_length), R::of(g.sole_width)],
            velocity: [R::zero(); 3],
            feet,
            next_swing: first,
        };
        // The in-place step must be possible: it is the fallback of every footprint.
        let support = gen.support();
        let in_place = gen.footprint(&support, first, [R::zero(); 3]);
        if !gen.fits(first, &support, &in_place) {
            return Err(GaitError::StepOutOfReach);
        }
        Ok(gen)
    }

    /// The walking velocity (vx, vy, ω) of the last step.
    pub fn velocity(&self) -> [R; 3] {
        self.velocity
    }

    /// Where the feet are after the last step (left, right).
    pub fn feet(&self) -> [Place<R>; 2] {
        self.feet
    }

    /// The foot that swings next.
    pub fn next_swing(&self) -> Side {
        self.next_swing
    }

    /// True when the velocity is 0 and the feet stand parallel at the nominal width (the
    /// last step was an in-place step).
    pub fn is_standing(&self) -> bool {
        if self.velocity.iter().any(|v| *v != R::zero()) {
            return false;
        }
        let [l, r] = self.feet;
        let d = l.yaw - r.yaw;
        let (s, c) = (r.yaw.sin(), r.yaw.cos());
        let (dx, dy) = (l.x - r.x, l.y - r.y);
        let fwd = c * dx + s * dy;
        let lat = c * dy - s * dx;
        let eps = R::of(1e-6);
        d.abs() < eps && fwd.abs() < eps && (lat - (self.half_width + self.half_width)).abs() < eps
    }

    fn support(&self) -> Place<R> {
        let [l, r] = self.feet;
        match self.next_swing {
            Side::Left => r,
            Side::Right => l,
        }
    }

    /// (S2): the swing foot's place for the per-step travel `d` = (d_x, d_y, d_ω).
    fn footprint(&self, support: &Place<R>, side: Side, d: [R; 3]) -> Place<R> {
        let [dx, dy, dw] = d;
        let half = R::of(0.5);
        let a = support.yaw + dw * half;
        let (s, c) = (a.sin(), a.cos());
        let lat = R::of(side.sign()) * (self.half_width + self.half_width) + dy;
        Place {
            x: support.x + c * dx - s * lat,
            y: support.y + s * dx + c * lat,
            yaw: support.yaw + dw,
        }
    }

    /// The reach check and the sole-corner check of `to` (a `side` foot) against `support`.
    fn fits(&self, side: Side, support: &Place<R>, to: &Place<R>) -> bool {
        if self.reach.check(side, support, to).is_err() {
            return false;
        }
        let (ss, cs) = (support.yaw.sin(), support.yaw.cos());
        let (st, ct) = (to.yaw.sin(), to.yaw.cos());
        let half = R::of(0.5);
        let [len, wid] = self.sole;
        let edge = wid * half + R::of(SOLE_GAP);
        let sign = R::of(side.sign());
        for (u, v) in [(half, half), (half, -half), (-half, half), (-half, -half)] {
            // The corner in the world, then in the support sole's frame.
            let (cx, cy) = (u * len, v * wid);
            let wx = to.x + ct * cx - st * cy - support.x;
            let wy = to.y + st * cx + ct * cy - support.y;
            let lat = cs * wy - ss * wx;
            if lat * sign < edge {
                return false;
            }
        }
        true
    }

    /// The next footstep for the command `cmd` (S1, S2 and the limits; see the module doc).
    pub fn next_step(&mut self, cmd: &WalkCommand<R>) -> Footstep<R> {
        self.next_step_turned(cmd, R::zero()).0
    }

    /// [`Self::next_step`] with an extra heading change `turn` (rad) of the swing foot on top
    /// of the command's d_ω (S3): the heading hold's correction. The walking velocity stays the
    /// command's (the turn is not integrated into ω); the limits apply to the whole step.
    /// Returns the footstep and the correction stepped (λ·δ: less when the limits scaled the
    /// step back).
    pub fn next_step_turned(&mut self, cmd: &WalkCommand<R>, turn: R) -> (Footstep<R>, R) {
        let (step, turned, _) = self.next_step_held(cmd, turn, [R::zero(); 2]);
        (step, turned)
    }

    /// [`Self::next_step_turned`] with a position correction `shift` (m, support-foot frame) of
    /// the swing foot's travel (S4): the position hold's. Like the turn it is not integrated into
    /// the velocity and the limits apply to the whole step. Returns the footstep and the turn
    /// and shift stepped (λ·δ, λ·c). A non-finite correction counts as 0.
    pub fn next_step_held(
        &mut self,
        cmd: &WalkCommand<R>,
        turn: R,
        shift: [R; 2],
    ) -> (Footstep<R>, R, [R; 2]) {
        let turn = if turn.is_finite() { turn } else { R::zero() };
        let shift = shift.map(|v| if v.is_finite() { v } else { R::zero() });
        let l = &self.limits;
        let target = [
            clamp_r(cmd.vx, R::of(-l.vx_backward), R::of(l.vx_forward)),
            clamp_r(cmd.vy, R::of(-l.vy), R::of(l.vy)),
            clamp_r(cmd.yaw_rate, R::of(-l.yaw_rate), R::of(l.yaw_rate)),
        ];
        let t = self.period;
        let dv = [R::of(l.acc) * t, R::of(l.acc) * t, R::of(l.yaw_acc) * t];
        let mut v = self.velocity;
        for ((vi, ti), di) in v.iter_mut().zip(target).zip(dv) {
            *vi = *vi + clamp_r(ti - *vi, -di, di);
        }
        let [fx, fy, fw] = v.map(|vi| vi * t);
        let (step, scale) = self.step_by([fx + shift[0], fy + shift[1], fw + turn]);
        self.velocity = v.map(|vi| vi * scale);
        (step, turn * scale, shift.map(|c| c * scale))
    }

    /// An explicit step (a footstep list's entry): the next swing foot at the per-step travel
    /// `d` = (d_x, d_y, d_ω) of (S2) (m, m, rad, beyond the in-place step, in the support foot's
    /// frame), within the limits (scaled back like a commanded step); the walking velocity
    /// becomes the travel stepped over T, so the velocity filter (S1) continues from what the
    /// feet did. A non-finite component counts as 0.
    pub fn next_step_given(&mut self, d: [R; 3]) -> Footstep<R> {
        let d = d.map(|v| if v.is_finite() { v } else { R::zero() });
        let (step, scale) = self.step_by(d);
        let t = self.period;
        self.velocity = d.map(|di| di * scale / t);
        step
    }

    /// The next swing foot at travel `d` (S2), scaled back by λ until it fits; returns the
    /// step and λ.
    fn step_by(&mut self, full: [R; 3]) -> (Footstep<R>, R) {
        let side = self.next_swing;
        let support = self.support();
        let full_place = self.footprint(&support, side, full);
        let (place, scale) = if self.fits(side, &support, &full_place) {
            (full_place, R::one())
        } else {
            // Bisection on λ: `lo` always passes (λ = 0 is the in-place step), `hi` fails.
            let (mut lo, mut hi) = (R::zero(), R::one());
            let half = R::of(0.5);
            for _ in 0..SCALE_STEPS {
                let mid = (lo + hi) * half;
                let p = self.footprint(&support, side, full.map(|d| d * mid));
                if self.fits(side, &support, &p) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            (self.footprint(&support, side, full.map(|d| d * lo)), lo)
        };
        if let Some(f) = self.feet.get_mut(side.index()) {
            *f = place;
        }
        self.next_swing = side.other();
        (Footstep { side, place }, scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gen(limits: CommandLimits) -> StepGenerator<f64> {
        StepGenerator::new(
            &Robot::reference(),
            0.217,
            limits,
            0.045,
            0.64,
            [Place::new(0.0, 0.045, 0.0), Place::new(0.0, -0.045, 0.0)],
            Side::Left,
        )
        .unwrap()
    }

    #[test]
    fn a_turn_rotates_the_footprint_but_not_the_velocity() {
        let cmd = WalkCommand {
            vx: 0.05,
            vy: 0.0,
            yaw_rate: 0.0,
        };
        let (mut a, mut b) = (gen(CommandLimits::DEFAULT), gen(CommandLimits::DEFAULT));
        let plain = a.next_step(&cmd);
        let (turned, stepped) = b.next_step_turned(&cmd, 0.04);
        assert_eq!(stepped, 0.04, "within the limits: all of it");
        // (S1): 0.1 m/s² · 0.64 s = 0.064 m/s ≥ 0.05: v reaches the command in one step.
        assert_eq!(a.velocity(), [0.05, 0.0, 0.0]);
        assert_eq!(
            b.velocity(),
            a.velocity(),
            "the turn is not integrated into ω"
        );
        assert!((turned.place.yaw - plain.place.yaw - 0.04).abs() < 1e-12);
        // (S2) with d_ω = 0.04 around the support foot (0, −0.045): offset (0.032, 0.09)
        // rotated by 0.02 rad.
        let (s, c) = 0.02f64.sin_cos();
        assert!((turned.place.x - (c * 0.032 - s * 0.09)).abs() < 1e-12);
        assert!((turned.place.y - (-0.045 + s * 0.032 + c * 0.09)).abs() < 1e-12);
        // A non-finite turn counts as none.
        let mut n = gen(CommandLimits::DEFAULT);
        assert_eq!(n.next_step_turned(&cmd, f64::NAN), (plain, 0.0));
        // Beyond the reach's heading limit the step is scaled back, and so is the turn.
        let mut big = gen(CommandLimits::DEFAULT);
        let (f, stepped) = big.next_step_turned(&cmd, 3.0);
        assert!(stepped > 0.0 && stepped < 3.0, "{stepped}");
        // (S2–S3) scaled by λ with d_ω = 0: θ = λ·δ, exactly the turn stepped.
        assert!(
            (f.place.yaw - stepped).abs() < 1e-12,
            "{} {stepped}",
            f.place.yaw
        );
    }

    #[test]
    fn a_given_step_lands_where_its_entry_says_and_sets_the_velocity() {
        let mut g = gen(CommandLimits::DEFAULT);
        // Left foot, 4 cm forward, 1 cm out, 0.2 rad: (S2) around the support (0, −0.045).
        let f = g.next_step_given([0.04, 0.01, 0.2]);
        assert_eq!(f.side, Side::Left);
        let (s, c) = 0.1f64.sin_cos();
        assert!((f.place.x - (c * 0.04 - s * 0.1)).abs() < 1e-12);
        assert!((f.place.y - (-0.045 + s * 0.04 + c * 0.1)).abs() < 1e-12);
        assert!((f.place.yaw - 0.2).abs() < 1e-12);
        let v = g.velocity();
        assert!((v[0] - 0.04 / 0.64).abs() < 1e-12 && (v[2] - 0.2 / 0.64).abs() < 1e-12);
        assert_eq!(g.next_swing(), Side::Right);
        // Beyond the reach (0.5 m forward) it is scaled back to the largest step that fits,
        // and the velocity with it.
        let mut h = gen(CommandLimits::DEFAULT);
        let far = h.next_step_given([0.5, 0.0, 0.0]);
        assert!(far.place.x > 0.0 && far.place.x < 0.5, "{}", far.place.x);
        assert!((h.velocity()[0] - far.place.x / 0.64).abs() < 1e-9);
        // Non-finite components count as 0: the in-place step.
        let mut n = gen(CommandLimits::DEFAULT);
        let z = n.next_step_given([f64::NAN, 0.0, f64::INFINITY]);
        assert_eq!(z.place, Place::new(0.0, 0.045, 0.0));
    }

    #[test]
    fn zero_command_steps_in_place_and_stands() {
        let mut g = gen(CommandLimits::DEFAULT);
        let s = g.next_step(&WalkCommand::zero());
        assert_eq!(s.side, Side::Left);
        assert_eq!(s.place, Place::new(0.0, 0.045, 0.0));
        assert!(g.is_standing());
    }
}
