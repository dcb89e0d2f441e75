//! The landing hold (`gait_core::feedback::catch`, A8–A9): a walk whose every landing is δ off
//! its targets ends δ/k_l off its plan instead of N·δ; the move follows the feet's midpoint
//! (an error alternating between the feet moves nothing), along the stance foot's heading,
//! bounded, ramped in after lift-off, taken only when both feet were surveyed since they
//! landed; the references' shift is the hold's share of the body's offset; gain 0 is the
//! catching step alone.

use gait_core::feedback::catch::{StepAdaptation, StepAdapter, MAX_LANDING_SHIFT_M};
use gait_core::trajectory::swing::FootSample;
use gait_core::{GaitSample, Robot, Side, SupportPhase};
use proptest::prelude::*;

const Z_C: f32 = 0.23;
const DT: f32 = 0.005;
/// Ticks of one single support (long enough for the ramp and the offset's rate limit).
const SINGLE: usize = 80;
/// Ticks of one double support.
const DOUBLE: usize = 20;
/// The plan's step length, m.
const STEP: f32 = 0.02;

/// The plan's place (x, y) of foot `side` after `steps` steps (left first, each foot moving
/// 2·STEP per stride from x = 0).
fn plan(side: Side, steps: usize) -> [f32; 2] {
    // Steps 1, 3, 5, … move the left foot; 2, 4, … the right one.
    let moved = match side {
        Side::Left => steps.div_ceil(2),
        Side::Right => steps / 2,
    };
    let first = if side == Side::Left { STEP } else { 2.0 * STEP };
    let x = if moved == 0 {
        0.0
    } else {
        first + 2.0 * STEP * (moved - 1) as f32
    };
    [x, if side == Side::Left { 0.05 } else { -0.05 }]
}

/// A gait sample in `phase` with the feet at the plan's places after `steps` steps, heading
/// `yaw`.
fn sample(phase: SupportPhase, support: Option<Side>, steps: usize, yaw: f32) -> GaitSample<f32> {
    let foot = |side| {
        let [x, y] = plan(side, steps);
        FootSample { x, y, z: 0.0, yaw }
    };
    let mut s = GaitSample::zero();
    s.phase = phase;
    s.support_foot = support;
    s.feet = [foot(Side::Left), foot(Side::Right)];
    s.zmp = [(s.feet[0].x + s.feet[1].x) / 2.0, 0.0];
    s.com = [s.zmp[0], 0.0, Z_C];
    s
}

fn adapter(landing_gain: f32, landing_ramp_s: f32) -> StepAdapter {
    let cfg = StepAdaptation {
        landing_gain,
        landing_ramp_s,
        ..StepAdaptation::DEFAULT
    };
    StepAdapter::new(&cfg, &Robot::reference(), Z_C, DT)
}

/// One tick upright (no catch) with the swing foot unloaded.
fn tick(a: &mut StepAdapter, s: &GaitSample<f32>) {
    a.update(s, Some([0.0, 0.0]), Some([0.0, 0.0]), [0.0, 0.0]);
}

/// Walks `steps` steps where every landing is `delta` (x, m) off the place its targets put it
/// relative to the stance foot, surveying each landing (the odometry's ε: true place minus
/// commanded place). Returns each foot's true place minus the plan's after the walk (x, m).
fn walk(a: &mut StepAdapter, steps: usize, delta: f32) -> [f32; 2] {
    // True x of each foot; the commanded place is plan + offset.
    let mut truth = [plan(Side::Left, 0)[0], plan(Side::Right, 0)[0]];
    for n in 1..=steps {
        let swing = if n % 2 == 1 { Side::Left } else { Side::Right };
        let stance = swing.other();
        let single = sample(SupportPhase::Single(stance), Some(stance), n, 0.0);
        for _ in 0..SINGLE {
            tick(a, &single);
        }
        let (i, j) = (swing as usize, stance as usize);
        let d = a.foot_offsets();
        // The leg sets the foot down δ off where its targets put it from the stance foot.
        let commanded_rel = (plan(swing, n)[0] + d[i][0]) - (plan(stance, n)[0] + d[j][0]);
        truth[i] = truth[j] + commanded_rel + delta;
        let double = sample(SupportPhase::Double, Some(stance), n, 0.0);
        tick(a, &double);
        // The survey: the odometry's world is the truth here (no reading error).
        let d = a.foot_offsets();
        a.set_landing(swing, [truth[i] - (plan(swing, n)[0] + d[i][0]), 0.0]);
        for _ in 1..DOUBLE {
            tick(a, &double);
        }
    }
    [
        truth[0] - plan(Side::Left, steps)[0],
        truth[1] - plan(Side::Right, steps)[0],
    ]
}

#[test]
fn the_plan_helper_walks_the_plan() {
    assert_eq!(plan(Side::Left, 0), [0.0, 0.05]);
    assert_eq!(plan(Side::Left, 1)[0], STEP);
    assert_eq!(plan(Side::Right, 2)[0], 2.0 * STEP);
    assert_eq!(plan(Side::Left, 3)[0], 3.0 * STEP);
    assert_eq!(plan(Side::Right, 3)[0], 2.0 * STEP);
}

#[test]
fn without_the_hold_the_landing_errors_add_up() {
    let delta = 0.004;
    let mut a = adapter(0.0, 0.2);
    let [l, r] = walk(&mut a, 12, delta);
    // The left foot landed 6 times, the right 6: each landing adds δ to the chain.
    assert!((l - 11.0 * delta).abs() < 1e-5, "left {l}");
    assert!((r - 12.0 * delta).abs() < 1e-5, "right {r}");
    assert_eq!(a.foot_offsets(), [[0.0; 2]; 2]);
}

#[test]
fn a_repeated_landing_error_leaves_delta_over_k() {
    let delta = 0.004;
    for k in [1.0f32, 0.5, 0.25] {
        let mut a = adapter(k, 0.2);
        let [l, r] = walk(&mut a, 24, delta);
        // e_n = (1 − k)·e_s + δ → δ/k (the steady state, reached to (1 − k)^23 of δ).
        let want = delta / k;
        for (side, e) in [("left", l), ("right", r)] {
            assert!(
                (e - want).abs() < 0.02 * want + 1e-6,
                "k {k}, {side}: {e} m off the plan, want {want}"
            );
        }
        // The offsets took back what the legs added: the commanded places stand ≈ n·δ behind.
        let d = a.foot_offsets();
        assert!(d[1][0] < -20.0 * delta + want, "k {k}: {d:?}");
        assert_eq!(d[0][1], 0.0);
        assert_eq!(d[1][1], 0.0);
    }
}

#[test]
fn the_references_shift_is_the_holds_share_of_the_body() {
    let mut a = adapter(1.0, 0.2);
    walk(&mut a, 9, 0.005);
    // No catch: the whole body offset is the hold's.
    assert_eq!(a.landing_body_shift(), a.body_offset());
    assert!(a.body_offset()[0] < -0.02, "{:?}", a.body_offset());
    // Gain 0: no shift at all.
    let mut off = adapter(0.0, 0.2);
    walk(&mut off, 9, 0.005);
    assert_eq!(off.landing_body_shift(), [0.0; 2]);
    assert_eq!(off.body_offset(), [0.0; 2]);
}

/// One double-support tick (heading `yaw`) with the left foot surveyed `e_left` off and the
/// right one `e_right`; the sample of the single support on the left foot that follows.
fn surveyed_then_left_stance(
    a: &mut StepAdapter,
    e_left: [f32; 2],
    e_right: [f32; 2],
    yaw: f32,
) -> GaitSample<f32> {
    tick(a, &sample(SupportPhase::Double, Some(Side::Right), 1, yaw));
    a.set_landing(Side::Right, e_right);
    a.set_landing(Side::Left, e_left);
    sample(SupportPhase::Single(Side::Left), Some(Side::Left), 2, yaw)
}

/// Single support on the left foot (heading `yaw`) after both feet were surveyed `e` off: the
/// right foot's offset after `ticks` ticks.
fn swing_offset_after(a: &mut StepAdapter, e: [f32; 2], yaw: f32, ticks: usize) -> [f32; 2] {
    let single = surveyed_then_left_stance(a, e, e, yaw);
    for _ in 0..ticks {
        tick(a, &single);
    }
    a.foot_offsets()[1]
}

/// A distance that alternates between the feet (one foot long, the other short) is the
/// midpoint's: no move; one foot alone off moves by half of it.
#[test]
fn the_move_follows_the_feet_midpoint() {
    let mut a = adapter(1.0, 0.0);
    let single = surveyed_then_left_stance(&mut a, [0.006, 0.0], [-0.006, 0.0], 0.0);
    for _ in 0..20 {
        tick(&mut a, &single);
    }
    assert_eq!(a.foot_offsets(), [[0.0; 2]; 2]);
    let mut a = adapter(1.0, 0.0);
    let single = surveyed_then_left_stance(&mut a, [0.006, 0.0], [0.0, 0.0], 0.0);
    for _ in 0..20 {
        tick(&mut a, &single);
    }
    assert!((a.foot_offsets()[1][0] + 0.003).abs() < 1e-6);
}

#[test]
fn the_move_is_along_the_stance_heading_within_its_bound() {
    // Heading 0: the sideways part of e is left alone.
    let mut a = adapter(1.0, 0.0);
    let d = swing_offset_after(&mut a, [0.006, 0.004], 0.0, 20);
    assert!((d[0] + 0.006).abs() < 1e-6 && d[1] == 0.0, "{d:?}");
    // Heading 90°: forward is +y; e·h = 0.004.
    let mut a = adapter(1.0, 0.0);
    let d = swing_offset_after(&mut a, [0.006, 0.004], core::f32::consts::FRAC_PI_2, 20);
    assert!(d[0].abs() < 1e-5 && (d[1] + 0.004).abs() < 1e-5, "{d:?}");
    // A large distance: at most MAX_LANDING_SHIFT_M.
    let mut a = adapter(1.0, 0.0);
    let d = swing_offset_after(&mut a, [-0.5, 0.0], 0.0, 40);
    assert!((d[0] - MAX_LANDING_SHIFT_M).abs() < 1e-6, "{d:?}");
}

/// `landing_lateral`: the midpoint's sideways distance (across the stance heading) corrected
/// by its own gain, within the same bound; the forward part as without it.
#[test]
fn the_lateral_move_corrects_the_midpoint_across_the_heading() {
    let lateral = |k_lat: f32| {
        let cfg = StepAdaptation {
            landing_gain: 1.0,
            landing_lateral: k_lat,
            landing_ramp_s: 0.0,
            ..StepAdaptation::DEFAULT
        };
        StepAdapter::new(&cfg, &Robot::reference(), Z_C, DT)
    };
    // Heading 0: 6 mm long, 4 mm to the left; half the sideways part back.
    let d = swing_offset_after(&mut lateral(0.5), [0.006, 0.004], 0.0, 20);
    assert!(
        (d[0] + 0.006).abs() < 1e-6 && (d[1] + 0.002).abs() < 1e-6,
        "{d:?}"
    );
    // Heading 90°: sideways is −x; e across it is −0.006, e along it 0.004.
    let d = swing_offset_after(
        &mut lateral(1.0),
        [0.006, 0.004],
        core::f32::consts::FRAC_PI_2,
        20,
    );
    assert!(
        (d[0] + 0.006).abs() < 1e-5 && (d[1] + 0.004).abs() < 1e-5,
        "{d:?}"
    );
    // Bounded like the forward move.
    let d = swing_offset_after(&mut lateral(1.0), [0.0, 0.5], 0.0, 40);
    assert!((d[1] + MAX_LANDING_SHIFT_M).abs() < 1e-6, "{d:?}");
}

#[test]
fn the_move_enters_over_the_ramp() {
    let ramp_s = 0.2;
    let e = 0.004;
    let ramp_ticks = (ramp_s / DT) as usize;
    let mut a = adapter(1.0, ramp_s);
    let mut last = 0.0f32;
    let single = surveyed_then_left_stance(&mut a, [e, 0.0], [e, 0.0], 0.0);
    for k in 1..=ramp_ticks + 10 {
        tick(&mut a, &single);
        let x = a.foot_offsets()[1][0];
        // Tick k has k/N of u (the rate limit is far above e/N per tick).
        let want = -e * (k as f32 / ramp_ticks as f32).min(1.0);
        assert!((x - want).abs() < 1e-6, "tick {k}: {x}, want {want}");
        assert!(x <= last + 1e-9);
        last = x;
    }
}

#[test]
fn only_both_feet_surveyed_since_they_landed_move_the_landing() {
    // Never surveyed, or the stance foot alone: nothing moves.
    for surveyed in [false, true] {
        let mut a = adapter(1.0, 0.0);
        if surveyed {
            a.set_landing(Side::Left, [0.01, 0.0]);
        }
        let single = sample(SupportPhase::Single(Side::Left), Some(Side::Left), 2, 0.0);
        for _ in 0..40 {
            tick(&mut a, &single);
        }
        assert_eq!(a.foot_offsets(), [[0.0; 2]; 2]);
    }
    // Surveyed, then it lifted (single support on the right): its distance is dropped, and its
    // next stance without a survey moves nothing.
    let mut a = adapter(1.0, 0.0);
    a.set_landing(Side::Left, [0.01, 0.0]);
    assert_eq!(a.landing_errors()[0], Some([0.01, 0.0]));
    let right = sample(SupportPhase::Single(Side::Right), Some(Side::Right), 3, 0.0);
    tick(&mut a, &right);
    assert_eq!(a.landing_errors()[0], None);
    for _ in 0..40 {
        tick(&mut a, &right);
    }
    assert_eq!(a.foot_offsets(), [[0.0; 2]; 2]);
    // A non-finite survey is no survey.
    let mut a = adapter(1.0, 0.0);
    a.set_landing(Side::Left, [f32::NAN, 0.0]);
    a.set_landing(Side::Right, [0.0, f32::INFINITY]);
    assert_eq!(a.landing_errors(), [None, None]);
}

proptest! {
    /// Gain 0 is the catching step alone: under any attitude and any surveys the offsets equal
    /// those of an adapter that never hears of a survey.
    #[test]
    fn gain_zero_ignores_the_surveys(
        pitches in prop::collection::vec(-0.3f32..0.3, 1..60),
        survey in prop::array::uniform2(-0.05f32..0.05),
    ) {
        let mut with = adapter(0.0, 0.2);
        let mut without = adapter(0.0, 0.2);
        for (k, p) in pitches.iter().enumerate() {
            let phase = if k % 20 < 15 {
                (SupportPhase::Single(Side::Left), 2)
            } else {
                (SupportPhase::Double, 2)
            };
            let s = sample(phase.0, Some(Side::Left), phase.1, 0.0);
            with.set_landing(Side::Left, survey);
            for a in [&mut with, &mut without] {
                a.update(&s, Some([0.0, *p]), Some([0.0, 3.0 * p]), [0.0, 0.0]);
            }
            prop_assert_eq!(with.foot_offsets(), without.foot_offsets());
            prop_assert_eq!(with.body_offset(), without.body_offset());
            prop_assert_eq!(with.landing_body_shift(), [0.0; 2]);
        }
    }
}
