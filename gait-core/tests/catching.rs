//! The catching step (`gait_core::feedback::catch`, A1–A7): the capture-point error from the
//! trunk's attitude, the landing move beyond the deadband within reach and never inward, the
//! rate limit, the early touchdown, the body's offset, and the offsets on a sample; the swing
//! sole kept level (`feedback::level`, A10): its ramps, its bound and the joints it turns; the
//! clock hold (`feedback::hold`, A11); the levelling and the hold alone.

use gait_core::feedback::catch::{StepAdaptation, StepAdapter, MAX_OFFSET_M};
use gait_core::feedback::hold::HOLD_HEIGHT_M;
use gait_core::feedback::level::MAX_LEVEL_RAD;
use gait_core::trajectory::swing::FootSample;
use gait_core::{GaitSample, Robot, Side, SupportPhase};
use proptest::prelude::*;

const Z_C: f32 = 0.23;
const DT: f32 = 0.005;
const NO_LOAD: [f32; 2] = [0.0, 0.0];

/// A sample in `phase` with the feet at y = ±0.05 and the ZMP reference at `zmp`.
fn sample(phase: SupportPhase, support: Option<Side>, zmp: [f32; 2]) -> GaitSample<f32> {
    let mut s = GaitSample::zero();
    s.phase = phase;
    s.support_foot = support;
    s.zmp = zmp;
    s.com = [zmp[0], zmp[1], Z_C];
    s.feet = [
        FootSample {
            x: 0.0,
            y: 0.05,
            z: 0.0,
            yaw: 0.0,
        },
        FootSample {
            x: 0.0,
            y: -0.05,
            z: 0.0,
            yaw: 0.0,
        },
    ];
    s
}

/// The reference robot's weight, N.
fn weight_n() -> f32 {
    let r = Robot::reference();
    (r.masses.total() * r.gravity) as f32
}

fn single_left() -> GaitSample<f32> {
    sample(
        SupportPhase::Single(Side::Left),
        Some(Side::Left),
        [0.0, 0.05],
    )
}

/// The independent (A1): the capture-point error of a trunk at `pitch`, `pitch_rate` from an
/// upright baseline.
fn cp_error_x(pitch: f32, pitch_rate: f32) -> f32 {
    let omega = (9.81f32 / Z_C).sqrt();
    Z_C * (pitch + pitch_rate / omega)
}

/// One tick in left single support with the attitude `roll_pitch` and the rates `rates`, the
/// swing foot unloaded.
fn tilted(a: &mut StepAdapter, roll_pitch: [f32; 2], rates: [f32; 2]) -> [f32; 2] {
    a.update(&single_left(), Some(roll_pitch), Some(rates), NO_LOAD)
}

fn adapter(cfg: StepAdaptation) -> StepAdapter {
    let mut a = StepAdapter::new(&cfg, &Robot::reference(), Z_C, DT);
    // The baseline: upright.
    tilted(&mut a, [0.0, 0.0], [0.0, 0.0]);
    a
}

#[test]
fn off_moves_nothing() {
    let mut a = adapter(StepAdaptation::OFF);
    for _ in 0..100 {
        let asked = tilted(&mut a, [0.0, -0.3], [0.0, -2.0]);
        assert_eq!(asked, [0.0; 2]);
    }
    assert!(!a.is_shifting());
    let mut s = single_left();
    let before = s;
    a.apply(&mut s);
    assert_eq!(s, before);
}

#[test]
fn inside_the_deadband_there_is_no_catch() {
    let cfg = StepAdaptation::DEFAULT;
    let mut a = adapter(cfg);
    // A pitch rate whose capture-point error is 90 % of the deadband.
    let rate = 0.9 * cfg.deadband_m[0] / cp_error_x(0.0, 1.0);
    for _ in 0..50 {
        let asked = tilted(&mut a, [0.0, 0.0], [0.0, rate]);
        assert_eq!(asked, [0.0; 2]);
    }
    assert!(!a.is_shifting());
}

#[test]
fn a_backward_tip_moves_the_swing_foot_back_by_the_excess_at_the_rate_limit() {
    let cfg = StepAdaptation::DEFAULT;
    let mut a = adapter(cfg);
    let (pitch, rate) = (-0.05f32, -0.4f32);
    let e = cp_error_x(pitch, rate);
    let want = cfg.gain * (e + cfg.deadband_m[0]);
    assert!(
        want < 0.0 && want > -cfg.max_x_m,
        "the case must sit inside the reach: {want}"
    );
    let step = cfg.speed_m_s * DT;
    let mut last = 0.0f32;
    for k in 0..200 {
        let asked = tilted(&mut a, [0.0, pitch], [0.0, rate]);
        assert!(
            (asked[0] - want).abs() < 1e-5,
            "tick {k}: asked {asked:?}, want {want}"
        );
        assert_eq!(asked[1], 0.0);
        let [_, right] = a.foot_offsets();
        assert!(
            (right[0] - last).abs() <= step * 1.0001,
            "rate limit at tick {k}"
        );
        last = right[0];
        // The stance foot and the body stay where the stance foot is.
        assert_eq!(a.foot_offsets()[0], [0.0; 2]);
        assert_eq!(a.body_offset(), [0.0; 2]);
    }
    assert!((last - want).abs() < 1e-5, "reached {last}, want {want}");
    assert!((a.error()[0] - e).abs() < 1e-5);
}

#[test]
fn the_landing_move_stays_within_reach_and_never_inward() {
    // The lateral catch on (the default has it off).
    let cfg = StepAdaptation {
        max_out_m: 0.04,
        ..StepAdaptation::DEFAULT
    };
    let mut a = adapter(cfg);
    // Tipping hard forward and to the right (towards the right, swinging, foot: inward for
    // nothing, outward for the right foot is −y).
    for _ in 0..400 {
        let asked = tilted(&mut a, [0.5, 0.5], [3.0, 3.0]);
        assert!((asked[0] - cfg.max_x_m).abs() < 1e-6, "{asked:?}");
        assert!((asked[1] + cfg.max_out_m).abs() < 1e-6, "{asked:?}");
    }
    let mut a = adapter(cfg);
    // Tipping to the left while the right foot swings: the move would be inward.
    for _ in 0..400 {
        let asked = tilted(&mut a, [-0.5, 0.0], [-3.0, 0.0]);
        assert_eq!(asked[1], 0.0, "{asked:?}");
    }
    assert_eq!(a.foot_offsets()[1][1], 0.0);
}

#[test]
fn an_early_touchdown_holds_the_swing_foot() {
    let cfg = StepAdaptation::DEFAULT;
    let mut a = adapter(cfg);
    for _ in 0..10 {
        tilted(&mut a, [0.0, -0.1], [0.0, -1.0]);
    }
    let held = a.foot_offsets()[1];
    assert!(held[0] < 0.0);
    let loaded = [0.0, cfg.touchdown_share * weight_n() * 1.5];
    for _ in 0..10 {
        a.update(&single_left(), Some([0.0, -0.1]), Some([0.0, -1.0]), loaded);
    }
    assert_eq!(a.foot_offsets()[1], held);
}

#[test]
fn the_body_follows_the_reference_zmp_between_the_caught_feet() {
    let cfg = StepAdaptation {
        body_speed_m_s: 100.0,
        ..StepAdaptation::DEFAULT
    };
    let mut a = adapter(cfg);
    for _ in 0..100 {
        tilted(&mut a, [0.0, -0.1], [0.0, -1.0]);
    }
    let right = a.foot_offsets()[1];
    // Double support, the reference ZMP a quarter of the way from the right foot to the left.
    let ds = sample(SupportPhase::Double, Some(Side::Left), [0.0, -0.025]);
    a.update(&ds, Some([0.0, 0.0]), Some([0.0, 0.0]), [15.0, 15.0]);
    let body = a.body_offset();
    assert!(
        (body[0] - 0.75 * right[0]).abs() < 1e-6,
        "{body:?} {right:?}"
    );
    // The offsets on a sample: feet by theirs, CoM and ZMP by the body's.
    let mut s = ds;
    a.apply(&mut s);
    assert_eq!(s.feet[1].x, ds.feet[1].x + right[0]);
    assert_eq!(s.feet[0].x, ds.feet[0].x);
    assert_eq!(s.com[0], ds.com[0] + body[0]);
    assert_eq!(s.zmp[0], ds.zmp[0] + body[0]);
    assert_eq!(s.com[2], ds.com[2]);
}

#[test]
fn the_catch_turns_with_the_stance_foot() {
    let cfg = StepAdaptation::DEFAULT;
    let mut a = adapter(cfg);
    let mut s = single_left();
    let yaw = core::f32::consts::FRAC_PI_2;
    s.feet[0].yaw = yaw;
    for _ in 0..200 {
        a.update(&s, Some([0.0, -0.1]), Some([0.0, -1.0]), NO_LOAD);
    }
    // Backwards in a trunk facing +y is −y in the plan.
    let [dx, dy] = a.foot_offsets()[1];
    assert!(dx.abs() < 1e-6 && dy < -0.01, "{dx} {dy}");
}

proptest! {
    /// Any input, finite or not: the offsets stay finite, bounded and rate-limited.
    #[test]
    fn offsets_stay_finite_bounded_and_rate_limited(
        inputs in prop::collection::vec(
            (prop::array::uniform4(prop_oneof![-10.0f32..10.0, Just(f32::NAN), Just(f32::INFINITY)]),
             0u8..4, -0.2f32..0.2),
            1..200),
    ) {
        let cfg = StepAdaptation {
            max_out_m: 0.04,
            ..StepAdaptation::DEFAULT
        };
        let mut a = adapter(cfg);
        let lim = cfg.speed_m_s.max(cfg.body_speed_m_s) * DT * 1.0001;
        for ([r, p, rr, pr], phase, zy) in inputs {
            let s = match phase {
                0 => single_left(),
                1 => sample(SupportPhase::Single(Side::Right), Some(Side::Right), [0.0, -0.05]),
                2 => sample(SupportPhase::Double, Some(Side::Left), [0.0, zy]),
                _ => sample(SupportPhase::Standing, None, [0.0, zy]),
            };
            let before = (a.foot_offsets(), a.body_offset());
            let asked = a.update(&s, Some([r, p]), Some([rr, pr]), [f32::NAN, 3.0]);
            prop_assert!(asked.iter().all(|v| v.is_finite()));
            prop_assert!(asked[0].abs() <= cfg.max_x_m + 1e-6);
            let after = (a.foot_offsets(), a.body_offset());
            for (b, n) in before.0.iter().chain([&before.1]).zip(after.0.iter().chain([&after.1])) {
                for i in 0..2 {
                    prop_assert!(n[i].is_finite() && n[i].abs() <= MAX_OFFSET_M);
                    prop_assert!((n[i] - b[i]).abs() <= lim);
                }
            }
        }
    }
}

proptest! {
    /// Any configuration (negative, NaN, infinite limits) and any step: no panic, finite
    /// offsets.
    #[test]
    fn any_configuration_is_total(
        vals in prop::array::uniform12(prop_oneof![
            -1.0f32..1.0, Just(f32::NAN), Just(f32::INFINITY), Just(f32::NEG_INFINITY)
        ]),
        dt in prop_oneof![0.0f32..0.1, Just(f32::NAN), Just(-1.0f32)],
        z_c in prop_oneof![-1.0f32..1.0, Just(f32::NAN)],
    ) {
        let cfg = StepAdaptation {
            gain: vals[0],
            deadband_m: [vals[1], vals[2]],
            max_x_m: vals[3],
            max_out_m: vals[4],
            max_in_m: vals[5],
            speed_m_s: vals[6],
            body_speed_m_s: vals[7],
            baseline_s: vals[8],
            touchdown_share: vals[0],
            level_pitch: vals[9],
            level_roll: vals[10],
            level_ramp_s: vals[11],
            hold_max_s: vals[3],
            hold_settle_s: vals[6],
            level_joints: vals[1],
            hold_lag_m: vals[2],
            landing_gain: vals[9],
            landing_lateral: vals[5],
            landing_ramp_s: vals[10],
        };
        let mut a = StepAdapter::new(&cfg, &Robot::reference(), z_c, dt);
        for s in [single_left(), sample(SupportPhase::Double, Some(Side::Left), [0.0, 0.01])] {
            for _ in 0..5 {
                a.set_joint_lag([vals[4], vals[5]]);
                a.set_swing_lag_m(vals[7]);
                a.set_landing(Side::Left, [vals[8], vals[11]]);
                let asked = a.update(&s, Some([0.3, -0.4]), Some([2.0, -3.0]), NO_LOAD);
                prop_assert!(asked.iter().all(|v| v.is_finite()));
            }
        }
        for d in a.foot_offsets().iter().chain([&a.body_offset()]) {
            prop_assert!(d.iter().all(|v| v.is_finite() && v.abs() <= MAX_OFFSET_M));
        }
        prop_assert!(a.landing_body_shift().iter().all(|v| v.is_finite()));
        for c in a.sole_level() {
            prop_assert!(c.iter().all(|v| v.is_finite() && v.abs() <= MAX_LEVEL_RAD));
        }
    }
}

/// The levelling alone (the catching step's gain 0), gains k_θ, k_φ.
fn levelling(k_pitch: f32, k_roll: f32) -> StepAdaptation {
    StepAdaptation {
        gain: 0.0,
        level_pitch: k_pitch,
        level_roll: k_roll,
        ..StepAdaptation::DEFAULT
    }
}

fn close(a: [f32; 2], b: [f32; 2]) -> bool {
    (a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6
}

#[test]
fn the_swing_sole_turns_back_by_the_trunks_deviation_ramped_in_and_out() {
    let cfg = levelling(1.0, 0.5);
    // The adapter's first tick (upright, left single support) is the ramp's first.
    let mut a = adapter(cfg);
    let ramp_ticks = (cfg.level_ramp_s / DT).round() as usize;
    assert_eq!(ramp_ticks, 20);
    let (pitch, roll) = (-0.15f32, 0.08f32);
    // The baseline stays upright: the tip's capture-point error is beyond the deadband.
    assert!(cp_error_x(pitch, 0.0).abs() > cfg.deadband_m[0]);
    for i in 2..=30 {
        tilted(&mut a, [roll, pitch], [0.0, 0.0]);
        let w = (i as f32 / ramp_ticks as f32).min(1.0);
        let [left, right] = a.sole_level();
        // The right leg swings: Δq = −k·w·(deviation); the stance leg keeps the plan's ankle.
        assert!(
            close(right, [-w * pitch, -0.5 * w * roll]),
            "{i}: {right:?}"
        );
        assert_eq!(left, [0.0; 2]);
    }
    // Touchdown (double support): the correction ramps out over the same time.
    let ds = sample(SupportPhase::Double, Some(Side::Left), [0.0, 0.0]);
    for j in 1..=25 {
        a.update(&ds, Some([roll, pitch]), Some([0.0; 2]), NO_LOAD);
        let w = (1.0 - j as f32 / ramp_ticks as f32).max(0.0);
        assert!(
            close(a.sole_level()[1], [-w * pitch, -0.5 * w * roll]),
            "{j}"
        );
    }
    assert_eq!(a.sole_level(), [[0.0; 2]; 2]);
    // The catching step is off: nothing else moved.
    assert!(!a.is_shifting());
}

#[test]
fn the_levelling_turns_only_the_ankles_and_is_bounded() {
    let mut a = adapter(levelling(1.0, 1.0));
    // A trunk 0.5 rad back, 0.4 rad rolled: beyond the bound.
    for _ in 0..40 {
        tilted(&mut a, [0.4, -0.5], [0.0, 0.0]);
    }
    assert_eq!(a.sole_level()[1], [MAX_LEVEL_RAD, -MAX_LEVEL_RAD]);
    let mut q = [0.1f32; 12];
    a.apply_level(&mut q);
    for (j, v) in q.iter().enumerate() {
        let expected = match j {
            10 => 0.1 + MAX_LEVEL_RAD,
            11 => 0.1 - MAX_LEVEL_RAD,
            _ => 0.1,
        };
        assert!((v - expected).abs() < 1e-6, "joint {j}: {v}");
    }
}

#[test]
fn a_lost_attitude_holds_the_last_deviation_while_the_weight_ramps() {
    let mut a = adapter(levelling(1.0, 1.0));
    for _ in 0..40 {
        tilted(&mut a, [0.0, -0.1], [0.0, 0.0]);
    }
    let held = a.sole_level()[1];
    assert!(close(held, [0.1, 0.0]), "{held:?}");
    // The attitude is lost in the swing: the correction holds.
    a.update(&single_left(), None, None, NO_LOAD);
    assert_eq!(a.sole_level()[1], held);
    // Lost through the touchdown: it ramps out on the held deviation (one tick's step).
    let ds = sample(SupportPhase::Double, Some(Side::Left), [0.0, 0.0]);
    a.update(&ds, None, None, NO_LOAD);
    assert!(close(a.sole_level()[1], [0.1 * 19.0 / 20.0, 0.0]));
    // A non-finite attitude counts as lost.
    a.update(&ds, Some([f32::NAN, 0.3]), Some([0.0; 2]), NO_LOAD);
    assert!(close(a.sole_level()[1], [0.1 * 18.0 / 20.0, 0.0]));
}

#[test]
fn off_or_zero_gains_never_level() {
    for cfg in [StepAdaptation::OFF, levelling(0.0, 0.0)] {
        let mut a = adapter(cfg);
        for _ in 0..40 {
            tilted(&mut a, [0.2, -0.2], [1.0, -1.0]);
        }
        assert_eq!(a.sole_level(), [[0.0; 2]; 2]);
        let mut q = [0.2f32; 12];
        a.apply_level(&mut q);
        assert_eq!(q, [0.2f32; 12]);
    }
}

proptest! {
    /// Any attitude sequence, finite or not, in any phase: the corrections stay finite, within
    /// the bound, and only the leg that swings (or has just landed) is turned.
    #[test]
    fn the_levelling_is_finite_and_bounded(
        inputs in prop::collection::vec(
            (prop::array::uniform2(prop_oneof![-2.0f32..2.0, Just(f32::NAN), Just(f32::INFINITY)]),
             0u8..4),
            1..200),
    ) {
        let mut a = adapter(StepAdaptation::DEFAULT);
        let step = DT / StepAdaptation::DEFAULT.level_ramp_s;
        let mut w = [0.0f32, step];
        for ([r, p], phase) in inputs {
            let (s, swing) = match phase {
                0 => (single_left(), Some(1)),
                1 => (sample(SupportPhase::Single(Side::Right), Some(Side::Right), [0.0, -0.05]), Some(0)),
                2 => (sample(SupportPhase::Double, Some(Side::Left), [0.0, 0.0]), None),
                _ => (sample(SupportPhase::Standing, None, [0.0, 0.0]), None),
            };
            a.update(&s, Some([r, p]), Some([0.0, 0.0]), NO_LOAD);
            for (i, wi) in w.iter_mut().enumerate() {
                let target = if swing == Some(i) { 1.0 } else { 0.0 };
                *wi += (target - *wi).clamp(-step, step);
            }
            for (c, wi) in a.sole_level().iter().zip(w) {
                prop_assert!(c.iter().all(|v| v.is_finite() && v.abs() <= MAX_LEVEL_RAD));
                if wi < 1e-6 {
                    prop_assert_eq!(*c, [0.0; 2]);
                }
            }
        }
    }
}

/// Left single support with the right (swing) sole planned at `z`.
fn swing_at(z: f32) -> GaitSample<f32> {
    let mut s = single_left();
    s.feet[1].z = z;
    s
}

#[test]
fn the_clock_holds_while_a_late_caught_foot_travels_then_settles_within_the_budget() {
    let cfg = StepAdaptation {
        hold_max_s: 0.5,
        hold_settle_s: 0.05,
        ..StepAdaptation::DEFAULT
    };
    let mut a = adapter(cfg);
    let tip = ([0.0, -0.3], [0.0, -2.0]);
    // High in the swing: the foot moves but the clock runs.
    a.update(&swing_at(0.03), Some(tip.0), Some(tip.1), NO_LOAD);
    assert!(a.is_shifting());
    assert!(!a.wants_hold());
    // Descending below z_h while the offset still moves (5 cm at 0.5 m/s: 20 ticks): held.
    let low = swing_at(0.5 * HOLD_HEIGHT_M);
    let (mut held, mut ticks) = (0, 0);
    while ticks < 200 {
        a.update(&low, Some(tip.0), Some(tip.1), NO_LOAD);
        ticks += 1;
        if !a.wants_hold() {
            break;
        }
        held += 1;
    }
    // Travel (≤ 0.05 m at 0.5 m/s·dt a tick) plus the 0.05 s settling, within the budget.
    let travel = (cfg.max_x_m / (cfg.speed_m_s * DT)).ceil() as i32;
    let settle = (cfg.hold_settle_s / DT).round() as i32;
    assert!(
        held >= settle && held <= travel + settle + 1,
        "held {held} ticks"
    );
    // The budget: 0.02 s lets it hold 4 ticks at most.
    let mut b = adapter(StepAdaptation {
        hold_max_s: 0.02,
        ..cfg
    });
    b.update(&swing_at(0.03), Some(tip.0), Some(tip.1), NO_LOAD);
    let holds = (0..50)
        .filter(|_| {
            b.update(&low, Some(tip.0), Some(tip.1), NO_LOAD);
            b.wants_hold()
        })
        .count();
    assert_eq!(holds, 4);
}

#[test]
fn the_clock_never_holds_at_lift_off_without_a_budget_or_after_touchdown() {
    let tip = ([0.0, -0.3], [0.0, -2.0]);
    // Off with no budget; the default's 0.15 s holds the same caught foot on its way down.
    let off = StepAdaptation {
        hold_max_s: 0.0,
        ..StepAdaptation::DEFAULT
    };
    assert_eq!(StepAdaptation::DEFAULT.hold_max_s, 0.15);
    for (cfg, holds) in [(off, false), (StepAdaptation::DEFAULT, true)] {
        let mut a = adapter(cfg);
        let mut wants = Vec::new();
        for z in [0.03, 0.005, 0.004] {
            a.update(&swing_at(z), Some(tip.0), Some(tip.1), NO_LOAD);
            wants.push(a.wants_hold());
        }
        assert_eq!(wants, [false, holds, holds], "{cfg:?}");
    }
    let cfg = StepAdaptation {
        hold_max_s: 0.5,
        ..StepAdaptation::DEFAULT
    };
    // Rising from the ground (lift-off): no hold, though the foot travels.
    let mut b = adapter(cfg);
    for i in 0..10 {
        b.update(
            &swing_at(0.001 * i as f32),
            Some(tip.0),
            Some(tip.1),
            NO_LOAD,
        );
        assert!(!b.wants_hold(), "tick {i}");
    }
    // A swing foot that carries a fifth of the weight has landed: no hold.
    let mut c = adapter(cfg);
    c.update(&swing_at(0.03), Some(tip.0), Some(tip.1), NO_LOAD);
    let loaded = [0.0, 0.5 * weight_n()];
    c.update(&swing_at(0.002), Some(tip.0), Some(tip.1), loaded);
    assert!(!c.wants_hold());
    // Double support: no hold, and the budget refills.
    let ds = sample(SupportPhase::Double, Some(Side::Left), [0.0, 0.0]);
    c.update(&ds, Some(tip.0), Some(tip.1), NO_LOAD);
    assert!(!c.wants_hold());
}

// The parts alone: the levelling (A10) fed a deviation and a phase, the clock hold (A11) fed
// a swing foot.

#[test]
fn the_sole_level_alone_ramps_in_on_the_swing_leg_holds_a_lost_deviation_and_ramps_out() {
    use gait_core::feedback::level::SoleLevel;
    let cfg = StepAdaptation {
        level_pitch: 1.0,
        level_roll: 0.5,
        level_ramp_s: 4.0 * DT,
        ..StepAdaptation::DEFAULT
    };
    let mut l = SoleLevel::new(&cfg, DT);
    assert!(l.is_on());
    // Left stance: the right leg swings; w steps by 1/4 a tick.
    l.update(Some([0.1, 0.2]), SupportPhase::Single(Side::Left));
    let c = l.corrections();
    assert_eq!(c[0], [0.0, 0.0]);
    assert!(close(c[1], [-0.025, -0.025]), "{c:?}");
    for _ in 0..3 {
        l.update(None, SupportPhase::Single(Side::Left));
    }
    assert!(
        close(l.corrections()[1], [-0.1, -0.1]),
        "{:?}",
        l.corrections()
    );
    let mut q = [0.0f32; 12];
    l.apply(&mut q);
    for (j, v) in q.iter().enumerate() {
        let want = match j {
            10 => -0.1,
            11 => -0.1,
            _ => 0.0,
        };
        assert!((v - want).abs() < 1e-6, "{j}: {v}");
    }
    // Double support: out again in four ticks, and a large deviation is bounded.
    l.update(Some([2.0, -2.0]), SupportPhase::Double);
    assert_eq!(l.corrections()[1], [-MAX_LEVEL_RAD, MAX_LEVEL_RAD]);
    for _ in 0..3 {
        l.update(None, SupportPhase::Double);
    }
    assert_eq!(l.corrections(), [[0.0; 2]; 2]);
    // No tick, no levelling.
    assert!(!SoleLevel::new(&cfg, 0.0).is_on());
    assert!(!SoleLevel::new(&StepAdaptation::OFF, DT).is_on());
}

#[test]
fn the_clock_hold_alone_waits_for_a_travelling_foot_within_its_budget() {
    use gait_core::feedback::hold::{ClockHold, SwingFoot, HOLD_GAP_M};
    let cfg = StepAdaptation {
        hold_max_s: 3.0 * DT,
        hold_settle_s: 2.0 * DT,
        ..StepAdaptation::DEFAULT
    };
    let single = SupportPhase::Single(Side::Left);
    let low = 0.5 * HOLD_HEIGHT_M;
    let foot = |z_m: f32, gap_m: f32| {
        Some(SwingFoot {
            z_m,
            gap_m,
            lag_m: f32::NAN,
        })
    };
    let mut h = ClockHold::new(&cfg, DT);
    let held = |h: &mut ClockHold, phase, swing| {
        h.update(phase, swing);
        h.wants_hold()
    };
    // The first low sample has no height before it (not known to descend): no hold.
    assert!(!held(&mut h, single, foot(low, 0.01)));
    // Descending and on its way: held; arrived: held while it settles (two ticks).
    assert!(held(&mut h, single, foot(0.9 * low, 0.01)));
    assert!(held(&mut h, single, foot(0.9 * low, 0.0)));
    assert!(!held(&mut h, single, foot(0.9 * low, 0.0)));
    // On its way again: the third and last tick of the budget.
    assert!(held(&mut h, single, foot(0.9 * low, 2.0 * HOLD_GAP_M)));
    assert!(!held(&mut h, single, foot(0.9 * low, 2.0 * HOLD_GAP_M)));
    // No swing foot (landed): no hold; double support refills the budget.
    assert!(!held(&mut h, single, None));
    assert!(!held(&mut h, SupportPhase::Double, None));
    // Rising (lift-off) or high: no hold; then descending below z_h: held again.
    assert!(!held(&mut h, single, foot(0.5 * low, 0.01)));
    assert!(!held(&mut h, single, foot(low, 0.01)));
    assert!(!held(&mut h, single, foot(2.0 * HOLD_HEIGHT_M, 0.01)));
    assert!(held(&mut h, single, foot(low, 0.01)));
    assert!(held(&mut h, single, foot(0.5 * low, 0.01)));
    // No budget: never.
    let mut off = ClockHold::new(
        &StepAdaptation {
            hold_max_s: 0.0,
            ..cfg
        },
        DT,
    );
    off.update(single, foot(low, 0.01));
    off.update(single, foot(0.5 * low, 0.01));
    assert!(!off.wants_hold());
}

#[test]
fn the_swing_legs_measured_lag_turns_its_ankle_by_minus_k_times_the_lag() {
    // The levelling on the joints' lag alone (k_q = 0.5), the trunk upright.
    let cfg = StepAdaptation {
        level_joints: 0.5,
        ..levelling(0.0, 0.0)
    };
    let mut a = adapter(cfg);
    let ramp_ticks = (cfg.level_ramp_s / DT).round() as usize;
    let lag = 0.08f32;
    for i in 2..=30 {
        // The right leg swings; a NaN for the stance leg (not read) changes nothing.
        a.set_joint_lag([f32::NAN, lag]);
        tilted(&mut a, [0.0, 0.0], [0.0, 0.0]);
        let w = (i as f32 / ramp_ticks as f32).min(1.0);
        let [left, right] = a.sole_level();
        assert!(close(right, [-0.5 * w * lag, 0.0]), "{i}: {right:?}");
        assert_eq!(left, [0.0; 2]);
    }
    // An unread tick holds the last lag.
    a.set_joint_lag([f32::NAN; 2]);
    tilted(&mut a, [0.0, 0.0], [0.0, 0.0]);
    assert!(close(a.sole_level()[1], [-0.5 * lag, 0.0]));
    // A lag beyond the bound is clamped.
    a.set_joint_lag([0.0, 10.0]);
    tilted(&mut a, [0.0, 0.0], [0.0, 0.0]);
    assert_eq!(a.sole_level()[1], [-MAX_LEVEL_RAD, 0.0]);
    // Touchdown: ramped out, and the leg's lag forgotten once the weight is 0.
    let ds = sample(SupportPhase::Double, Some(Side::Left), [0.0, 0.0]);
    for _ in 0..=ramp_ticks {
        a.update(&ds, Some([0.0; 2]), Some([0.0; 2]), NO_LOAD);
    }
    assert_eq!(a.sole_level(), [[0.0; 2]; 2]);
    tilted(&mut a, [0.0, 0.0], [0.0, 0.0]);
    assert_eq!(a.sole_level()[1], [0.0; 2], "the old lag came back");
    // Off (k_q = 0, the default): the same lag leaves the ankles alone.
    let mut off = adapter(StepAdaptation {
        level_joints: 0.0,
        ..levelling(0.0, 0.0)
    });
    off.set_joint_lag([lag, lag]);
    tilted(&mut off, [0.0, 0.0], [0.0, 0.0]);
    assert_eq!(off.sole_level(), [[0.0; 2]; 2]);
}

#[test]
fn the_clock_holds_while_the_measured_swing_sole_lags_its_targets() {
    use gait_core::feedback::hold::{ClockHold, SwingFoot};
    let tol = 0.003f32;
    let cfg = StepAdaptation {
        hold_max_s: 3.0 * DT,
        hold_settle_s: 0.0,
        hold_lag_m: tol,
        ..StepAdaptation::DEFAULT
    };
    let single = SupportPhase::Single(Side::Left);
    let low = 0.5 * HOLD_HEIGHT_M;
    let foot = |z_m: f32, lag_m: f32| {
        Some(SwingFoot {
            z_m,
            gap_m: 0.0,
            lag_m,
        })
    };
    let mut h = ClockHold::new(&cfg, DT);
    let held = |h: &mut ClockHold, swing| {
        h.update(single, swing);
        h.wants_hold()
    };
    // High in the swing: no hold however far behind.
    assert!(!held(&mut h, foot(2.0 * HOLD_HEIGHT_M, 0.02)));
    // Descending below z_h: held while the lag is over the tolerance, not at or under it, not
    // when unmeasured; three ticks of budget.
    assert!(held(&mut h, foot(low, 2.0 * tol)));
    assert!(!held(&mut h, foot(low, tol)));
    assert!(!held(&mut h, foot(low, f32::NAN)));
    assert!(held(&mut h, foot(low, 2.0 * tol)));
    assert!(held(&mut h, foot(low, 2.0 * tol)));
    assert!(!held(&mut h, foot(low, 2.0 * tol)), "over the budget");
    // Off (tolerance 0): the same lag never holds.
    let mut off = ClockHold::new(
        &StepAdaptation {
            hold_lag_m: 0.0,
            ..cfg
        },
        DT,
    );
    off.update(single, foot(2.0 * low, 0.02));
    off.update(single, foot(low, 0.02));
    assert!(!off.wants_hold());
}

#[test]
fn the_adapter_holds_on_the_measured_lag_without_a_catch_until_the_foot_carries_load() {
    let cfg = StepAdaptation {
        gain: 0.0,
        hold_lag_m: 0.003,
        ..StepAdaptation::DEFAULT
    };
    let mut a = adapter(cfg);
    // single_left(): the right foot swings; its planned height set low and descending.
    let mut s = single_left();
    s.feet[1].z = 0.008;
    a.set_swing_lag_m(0.01);
    a.update(&s, Some([0.0; 2]), Some([0.0; 2]), NO_LOAD);
    s.feet[1].z = 0.006;
    a.update(&s, Some([0.0; 2]), Some([0.0; 2]), NO_LOAD);
    assert!(
        a.wants_hold(),
        "a lagging swing sole in the landing holds the clock"
    );
    // The swing foot carries half the weight: landed, no hold.
    let half = 0.5 * weight_n();
    a.update(&s, Some([0.0; 2]), Some([0.0; 2]), [half, half]);
    assert!(!a.wants_hold());
    // Not measured: no hold.
    s.feet[1].z = 0.004;
    a.set_swing_lag_m(f32::NAN);
    a.update(&s, Some([0.0; 2]), Some([0.0; 2]), NO_LOAD);
    assert!(!a.wants_hold());
}
