//! The online walk (`online.rs`): modes and transitions, the DCM preview's CoM continuity when
//! the command changes mid-step, reverses or stops at any phase, and the joint targets of the
//! IK continuous and unclamped throughout.

use gait_core::kinematics::leg::LegKinematics;
use gait_core::kinematics::pipeline::joint_targets;
use gait_core::trajectory::command::{CommandLimits, StepGenerator, WalkCommand};
use gait_core::trajectory::online::{
    ListedStep, OnlineParams, OnlineWalk, WalkMode, DEFAULT_ZMP_INSET, MAX_HEADING_TURN,
    MAX_POSITION_SHIFT, STEP_QUEUE_LEN, ZMP_MARGIN,
};
use gait_core::trajectory::plan::SwingShape;
use gait_core::{GaitSample, Place, Robot, Side};

const W: f64 = 0.045;
const DT: f64 = 0.005;

fn params() -> OnlineParams {
    OnlineParams {
        z_c: 0.217,
        period: 0.64,
        // Table 2's T with a longer single support and a 2.5 cm swing: the swing knee stays
        // within the servo speed (Table 2's 0.34 s, 3 cm swing needs ≈ 6 rad/s, which the
        // firmware's feasibility check stretches).
        t1: 0.1,
        t2: 0.54,
        half_width: W,
        swing: SwingShape::Cycloid {
            height: 0.025,
            width: 0.0,
        },
        limits: CommandLimits::DEFAULT,
        dt: DT,
        zmp_inset: DEFAULT_ZMP_INSET,
        heading_gain: 0.0,
        position_gain: 0.0,
    }
}

fn feet() -> [Place<f64>; 2] {
    [Place::new(0.0, W, 0.0), Place::new(0.0, -W, 0.0)]
}

/// The generator alone from the walk's standing feet, `first` swinging first.
fn generator(first: Side) -> StepGenerator<f64> {
    StepGenerator::new(
        &Robot::reference(),
        0.217,
        CommandLimits::DEFAULT,
        W,
        0.64,
        feet(),
        first,
    )
    .unwrap()
}

fn walk() -> OnlineWalk<f64> {
    OnlineWalk::new(&Robot::reference(), params(), feet()).unwrap()
}

fn cmd(vx: f64, vy: f64, yaw_rate: f64) -> WalkCommand<f64> {
    WalkCommand { vx, vy, yaw_rate }
}

fn omega() -> f64 {
    (Robot::reference().gravity / 0.217).sqrt()
}

/// Runs `script` (tick → command) for `ticks` ticks; returns the samples.
fn run(
    w: &mut OnlineWalk<f64>,
    ticks: usize,
    script: impl Fn(usize) -> Option<WalkCommand<f64>>,
) -> Vec<GaitSample<f64>> {
    (0..ticks)
        .map(|k| {
            if let Some(c) = script(k) {
                w.set_command(c);
            }
            w.tick()
        })
        .collect()
}

/// The continuity checks over consecutive samples: CoM velocity change per tick within the
/// exact bound of (D4), |Δẋ| ≤ ω·sinh(ωdt)·|x − p| + (cosh ωdt − 1)·|ẋ| (+ rounding), and the
/// ZMP within the feedback's margin of a foot on the ground; joint targets from the IK never
/// clamped and changing per tick by at most the servo speed × dt.
fn assert_continuous(s: &[GaitSample<f64>]) -> f64 {
    let robot = Robot::reference();
    let kin = LegKinematics::new(&robot);
    let w = omega();
    let (sh, ch) = ((w * DT).sinh(), (w * DT).cosh());
    let qmax = robot.servo.max_speed * DT;
    let mut worst_dq: f64 = 0.0;
    let mut prev_q: Option<[f64; 12]> = None;
    for (k, pair) in s.windows(2).enumerate() {
        let (a, b) = (&pair[0], &pair[1]);
        for i in 0..2 {
            let bound = w * sh * (a.com[i] - b.zmp[i]).abs() + (ch - 1.0) * a.com_vel[i].abs();
            let dv = (b.com_vel[i] - a.com_vel[i]).abs();
            assert!(dv <= bound + 1e-9, "tick {k} axis {i}: Δv {dv} > {bound}");
            let dx = (b.com[i] - a.com[i]).abs();
            assert!(
                dx <= (a.com_vel[i].abs() + dv) * DT + 1e-9,
                "tick {k}: Δx {dx}"
            );
        }
        let near = b.feet.iter().any(|f| {
            f.z == 0.0
                && (b.zmp[0] - f.x).abs() <= ZMP_MARGIN + W + 1e-9
                && (b.zmp[1] - f.y).abs() <= ZMP_MARGIN + W + 1e-9
        });
        assert!(near, "tick {k}: ZMP {:?} off the feet", b.zmp);
        let (q, rep) = joint_targets(&kin, b);
        assert!(!rep.clamped(), "tick {k}: IK clamped {rep:?}");
        if let Some(p) = prev_q {
            for j in 0..12 {
                let d = (q[j] - p[j]).abs();
                worst_dq = worst_dq.max(d);
                assert!(d <= qmax, "tick {k} joint {j}: Δq {d} > {qmax}");
            }
        }
        prev_q = Some(q);
    }
    worst_dq
}

#[test]
fn standing_stays_still_on_the_feet_midpoint() {
    let mut w = walk();
    let s = run(&mut w, 200, |_| None);
    for x in &s {
        assert!(x.com[0].abs() < 1e-12 && x.com[1].abs() < 1e-12);
        assert_eq!(x.com_vel, [0.0, 0.0]);
    }
    assert!(matches!(w.mode(), WalkMode::Standing(_)));
}

/// Forward 0.05 m/s for 6 s then stop: the modes run standing → starting → walking →
/// stopping → standing; the CoM ends at rest on the midpoint of the feet, which are where the
/// generator alone puts them for the same commands.
#[test]
fn forward_then_stop_ends_standing_where_the_steps_went() {
    let mut w = walk();
    let mut modes = Vec::new();
    let mut steps = Vec::new();
    let s: Vec<_> = (0..3000)
        .map(|k| {
            if k == 10 {
                w.set_command(cmd(0.05, 0.0, 0.0));
            }
            if k == 1210 {
                w.set_command(cmd(0.0, 0.0, 0.0));
            }
            let x = w.tick();
            let m = std::mem::discriminant(w.mode());
            if modes.last() != Some(&m) {
                modes.push(m);
            }
            if let Some(f) = w.take_footstep() {
                steps.push(f);
            }
            x
        })
        .collect();
    assert!(matches!(w.mode(), WalkMode::Standing(_)));
    assert_eq!(
        modes.len(),
        5,
        "standing, starting, walking, stopping, standing"
    );
    // The generator alone, stepped by the same commands at the same step boundaries.
    let mut g = generator(Side::Left);
    // Starting takes one period from tick 10; step n starts at tick 10 + 128 (n + 1).
    for (n, f) in steps.iter().enumerate() {
        let start = 10 + 128 * (n + 1);
        let c = if start < 1210 {
            cmd(0.05, 0.0, 0.0)
        } else {
            cmd(0.0, 0.0, 0.0)
        };
        assert_eq!(g.next_step(&c), *f, "step {n}");
    }
    assert!(g.is_standing());
    let last = s.last().unwrap();
    let [l, r] = g.feet();
    assert!(
        (last.com[0] - 0.5 * (l.x + r.x)).abs() < 2e-3,
        "{:?}",
        last.com
    );
    assert!(
        (last.com[1] - 0.5 * (l.y + r.y)).abs() < 2e-3,
        "{:?} {l:?} {r:?}",
        last.com
    );
    assert!(last.com_vel[0].abs() < 1e-3 && last.com_vel[1].abs() < 1e-3);
    // 6 s at 0.05 m/s less the ramps: about 0.25 m.
    assert!(l.x > 0.2 && l.x < 0.32, "walked {}", l.x);
    let dq = assert_continuous(&s);
    eprintln!("forward/stop: worst Δq per tick {dq:.4} rad");
}

/// A command arriving at each of 16 phases of a step (forward → diagonal with a turn), a
/// reversal (forward → backward) and a stop at each phase: continuous CoM velocity, ZMP on
/// the feet, joint targets continuous and unclamped.
#[test]
fn commands_mid_step_reversal_and_stop_at_any_phase_are_continuous() {
    let mut worst: f64 = 0.0;
    for phase in 0..16 {
        let change = 10 + 128 * 4 + phase * 8;
        for second in [
            cmd(0.04, 0.03, 0.2),
            cmd(-0.08, 0.0, 0.0),
            cmd(0.0, 0.0, 0.0),
            cmd(0.0, -0.05, -0.3),
        ] {
            let mut w = walk();
            let s = run(&mut w, change + 2500, |k| {
                if k == 10 {
                    Some(cmd(0.08, 0.0, 0.0))
                } else if k == change {
                    Some(second)
                } else if k == change + 1200 {
                    Some(cmd(0.0, 0.0, 0.0))
                } else {
                    None
                }
            });
            worst = worst.max(assert_continuous(&s));
            assert!(
                matches!(w.mode(), WalkMode::Standing(_)),
                "phase {phase} {second:?}: ends standing"
            );
        }
    }
    eprintln!("worst Δq per tick {worst:.4} rad");
}

/// Non-finite command components count as 0 (a stop), never reaching the CoM.
#[test]
fn non_finite_commands_never_reach_the_com() {
    let mut w = walk();
    let s = run(&mut w, 1500, |k| match k {
        10 => Some(cmd(0.05, 0.0, 0.0)),
        400 => Some(cmd(f64::NAN, f64::INFINITY, 0.0)),
        _ => None,
    });
    assert!(s.iter().all(|x| x.is_finite()));
    assert!(matches!(w.mode(), WalkMode::Standing(_)));
}

/// The heading hold (H1–H2) against a world whose soles slipped 0.1 rad to the left: the
/// measured heading is the feet's mean yaw (what the pelvis follows) plus the slip. Each walking
/// step turns back k = 0.5 of the error within ±δ_max, the corrections sum to −slip, and the
/// robot's world heading comes back to the commanded 0 (straight walk). With k = 0 the feet are
/// the generator's exactly.
#[test]
fn heading_hold_turns_a_slip_back_within_its_bound() {
    let slip = 0.1;
    let mut p = params();
    p.heading_gain = 0.5;
    let mut w = OnlineWalk::new(&Robot::reference(), p, feet()).unwrap();
    let mut plain = walk();
    let mut feet_now = feet();
    let mut turns = Vec::new();
    let mut world = Vec::new();
    for k in 0..3000 {
        if k == 10 {
            w.set_command(cmd(0.05, 0.0, 0.0));
            plain.set_command(cmd(0.05, 0.0, 0.0));
        }
        let [l, r] = feet_now;
        let mean = 0.5 * (l.yaw + r.yaw);
        w.set_heading(mean + slip);
        w.tick();
        plain.tick();
        if let Some(f) = w.take_footstep() {
            turns.push(w.last_turn());
            feet_now[f.side.index()] = f.place;
            let [l, r] = feet_now;
            world.push(0.5 * (l.yaw + r.yaw) + slip);
        }
        assert!(plain.last_turn() == 0.0, "no heading, no turn");
    }
    // 3000 ticks = 15 s: the start phase, then ≈ 21 steps of 0.64 s.
    assert!(turns.len() > 15, "{} steps", turns.len());
    assert_eq!(turns[0], 0.0, "the start phase's step does not turn");
    assert!(
        (turns[1] + MAX_HEADING_TURN).abs() < 1e-12,
        "0.5 · 0.1 = the bound 0.05: {}",
        turns[1]
    );
    assert!(turns.iter().all(|t| t.abs() <= MAX_HEADING_TURN + 1e-12));
    let total: f64 = turns.iter().sum();
    assert!((total + slip).abs() < 2e-3, "Σδ = {total}");
    let last = *world.last().unwrap();
    assert!(last.abs() < 2e-3, "world heading {last}");
    // Off: the same walk steps as the generator alone.
    let mut q = params();
    q.heading_gain = 0.0;
    let mut off = OnlineWalk::new(&Robot::reference(), q, feet()).unwrap();
    let mut on_plain = walk();
    for k in 0..1500 {
        if k == 10 {
            off.set_command(cmd(0.05, 0.0, 0.0));
            on_plain.set_command(cmd(0.05, 0.0, 0.0));
        }
        off.set_heading(1.0);
        off.tick();
        on_plain.tick();
        assert_eq!(off.take_footstep(), on_plain.take_footstep(), "tick {k}");
    }
}

/// The position hold (P1–P2) against a world where every landing lands 1 cm further forward
/// and 2 mm further left than the plan puts it from the support foot (a stance leg that yields):
/// the surveyed place minus the planned one is fed after each landing. Without the hold the
/// feet drift from the commanded track by 1 cm a step; with k = 0.5 the drift settles at
/// Δ/k = 2 cm × (1, 0.2) and the feet keep the commanded velocity; every correction is within
/// ±c_max and a whole number of µm (as logged; the firmware's test replays the logged shifts
/// through the generator). With k = 0 the feet are the generator's exactly.
#[test]
fn position_hold_keeps_the_surveyed_feet_on_the_commanded_track() {
    let delta = [0.010, 0.002];
    let run = |k: f64| {
        let mut p = params();
        p.position_gain = k;
        let mut w = OnlineWalk::new(&Robot::reference(), p, feet()).unwrap();
        let mut nominal = walk();
        // The world: where each foot really is (planned + offset), and the last support.
        let mut real = feet();
        let mut planned = feet();
        let mut drift = Vec::new();
        for t in 0..3000 {
            if t == 10 {
                w.set_command(cmd(0.05, 0.0, 0.0));
                nominal.set_command(cmd(0.05, 0.0, 0.0));
            }
            w.tick();
            nominal.tick();
            let n = nominal.take_footstep();
            if let Some(f) = w.take_footstep() {
                let (i, j) = (f.side.index(), f.side.other().index());
                // The landing relative to the support foot as planned, then Δ off (support
                // frame; the walk is straight).
                let rel = [f.place.x - planned[j].x, f.place.y - planned[j].y];
                real[i] = Place {
                    x: real[j].x + rel[0] + delta[0],
                    y: real[j].y + rel[1] + delta[1],
                    yaw: f.place.yaw,
                };
                planned[i] = f.place;
                w.set_landing_offset(f.side, [real[i].x - f.place.x, real[i].y - f.place.y]);
                let c = w.last_shift();
                for v in c {
                    assert!(v.abs() <= MAX_POSITION_SHIFT + 1e-12, "{c:?}");
                    assert_eq!((v * 1e6).round() * 1e-6, v, "whole µm: {c:?}");
                }
                let nf = n.expect("the nominal walk steps in step");
                assert_eq!(nf.side, f.side);
                if k == 0.0 {
                    assert_eq!(nf.place, f.place, "off: the generator's footprints");
                }
                drift.push([real[i].x - nf.place.x, real[i].y - nf.place.y]);
            } else {
                assert!(n.is_none());
            }
        }
        drift
    };
    let off = run(0.0);
    let on = run(0.5);
    assert!(on.len() > 15 && on.len() == off.len(), "{} steps", on.len());
    // Off: the drift grows by Δ a step (the first, start-phase step too).
    let last_off = off.last().unwrap();
    assert!(
        last_off[0] > 0.01 * (off.len() as f64 - 3.0),
        "{last_off:?}"
    );
    // On: it settles at Δ/k.
    for d in &on[on.len() - 5..] {
        assert!(
            (d[0] - 0.02).abs() < 1e-3 && (d[1] - 0.004).abs() < 1e-3,
            "{on:?}"
        );
    }
}

/// A footstep list walked from standing: four explicit steps (forward, a turn, a side step,
/// right foot first) land where the generator's explicit steps put them, in order; the walk
/// stops by itself after them (stopping steps of the generator closing the feet) and stands;
/// CoM and joint targets continuous throughout. A step for the foot that does not swing next
/// gets an in-place step first; a full queue refuses more; non-finite entries are refused.
#[test]
fn a_footstep_list_is_walked_in_order_and_the_walk_stops_after_it() {
    let list = [
        ListedStep {
            side: Side::Right,
            d: [0.03, 0.0, 0.0],
        },
        ListedStep {
            side: Side::Left,
            d: [0.03, 0.0, 0.1],
        },
        ListedStep {
            side: Side::Right,
            d: [0.0, -0.02, 0.1],
        },
        ListedStep {
            side: Side::Left,
            d: [0.02, 0.0, 0.0],
        },
    ];
    let mut w = walk();
    let mut steps = Vec::new();
    let mut modes = Vec::new();
    let mut samples = Vec::new();
    for k in 0..2400 {
        if k == 10 {
            for l in list {
                assert!(w.push_step(l));
            }
            assert_eq!(w.queued(), 4);
        }
        samples.push(w.tick());
        let m = std::mem::discriminant(w.mode());
        if modes.last() != Some(&m) {
            modes.push(m);
        }
        if let Some(f) = w.take_footstep() {
            steps.push((f, w.last_given()));
        }
    }
    assert!(matches!(w.mode(), WalkMode::Standing(_)), "stands again");
    assert_eq!(w.queued(), 0);
    assert_eq!(
        modes.len(),
        5,
        "standing, starting, walking, stopping, standing"
    );
    // The generator alone: the four listed steps, then zero-command steps until it stands.
    let mut g = generator(Side::Right);
    for (n, (f, given)) in steps.iter().enumerate() {
        match list.get(n) {
            Some(l) => {
                assert_eq!(f.side, l.side, "step {n}");
                assert_eq!(*given, Some(l.d), "step {n}");
                assert_eq!(g.next_step_given(l.d), *f, "step {n}");
            }
            None => {
                assert_eq!(*given, None, "step {n}: the stop's");
                assert_eq!(g.next_step(&cmd(0.0, 0.0, 0.0)), *f, "step {n}");
            }
        }
    }
    assert!(steps.len() > list.len(), "stopping steps after the list");
    assert!(g.is_standing());
    // Independently: the first (right) step lands 3 cm ahead of the left support at (0, W),
    // 2W to its right.
    let first = steps[0].0.place;
    assert!((first.x - 0.03).abs() < 1e-12 && (first.y + W).abs() < 1e-12);
    // The turns add up: 0.2 rad on both feet at the end.
    let [l, r] = g.feet();
    assert!(
        (l.yaw - 0.2).abs() < 1e-9 && (r.yaw - 0.2).abs() < 1e-9,
        "{l:?} {r:?}"
    );
    assert_continuous(&samples);

    // Walking under a command, a step queued for the foot that does not swing next: one
    // in-place step first, then the listed one.
    let mut v = walk();
    v.set_command(cmd(0.03, 0.0, 0.0));
    let mut seen = Vec::new();
    let mut pushed = None;
    for _ in 0..1500 {
        v.tick();
        if let Some(f) = v.take_footstep() {
            seen.push((f, v.last_given()));
            if seen.len() == 3 && pushed.is_none() {
                // The step just committed swings f.side; the next swings the other: ask for
                // f.side again.
                let l = ListedStep {
                    side: f.side,
                    d: [0.01, 0.0, 0.0],
                };
                assert!(v.push_step(l));
                pushed = Some(l);
            }
        }
    }
    let l = pushed.unwrap();
    assert_eq!(seen[3].1, Some([0.0; 3]), "an in-place step to change feet");
    assert_eq!(seen[4].0.side, l.side);
    assert_eq!(seen[4].1, Some(l.d));
    assert_eq!(seen[5].1, None, "then the command's steps again");

    // Bounded and checked.
    let mut q = walk();
    for _ in 0..STEP_QUEUE_LEN {
        assert!(q.push_step(ListedStep {
            side: Side::Left,
            d: [0.0; 3]
        }));
    }
    assert!(
        !q.push_step(ListedStep {
            side: Side::Left,
            d: [0.0; 3]
        }),
        "full"
    );
    let mut n = walk();
    assert!(!n.push_step(ListedStep {
        side: Side::Left,
        d: [f64::NAN, 0.0, 0.0]
    }));
    assert_eq!(n.queued(), 0);
    assert!(matches!(n.mode(), WalkMode::Standing(_)));
}

/// `clear_steps` (the firmware's command deadman) while a footstep list walks under the zero
/// command: the listed step under way lands where it was committed, no listed step after it
/// is walked, the generator's stop steps close the feet and the walk stands; the CoM stays
/// continuous through it. Without the clear the rest of the list is walked.
#[test]
fn clearing_the_steps_mid_list_lands_the_step_under_way_then_stops() {
    let list: Vec<ListedStep<f64>> = (0..6)
        .map(|i| ListedStep {
            side: if i % 2 == 0 { Side::Left } else { Side::Right },
            d: [0.03, 0.0, 0.0],
        })
        .collect();
    let run = |clear: bool| {
        let mut w = walk();
        let mut steps = Vec::new();
        let mut samples = Vec::new();
        let mut cleared_at = None;
        for k in 0..2400 {
            if k == 10 {
                for l in &list {
                    assert!(w.push_step(*l));
                }
            }
            samples.push(w.tick());
            if let Some(f) = w.take_footstep() {
                steps.push((f, w.last_given()));
                if clear && steps.len() == 2 {
                    w.clear_steps();
                    assert_eq!(w.queued(), 0);
                    cleared_at = Some(steps.len());
                }
            }
        }
        assert!(matches!(w.mode(), WalkMode::Standing(_)), "stands again");
        assert_continuous(&samples);
        (steps, cleared_at)
    };
    let (all, _) = run(false);
    assert!(all.iter().filter(|(_, g)| g.is_some()).count() == list.len());
    let (steps, cleared_at) = run(true);
    assert_eq!(cleared_at, Some(2));
    // The two listed steps committed before the clear, then only the stop's (unlisted) steps.
    assert!(steps[..2].iter().all(|(_, g)| g.is_some()));
    assert!(steps[2..].iter().all(|(_, g)| g.is_none()), "{steps:?}");
    assert!(steps.len() <= 4, "{} steps", steps.len());
    // The same first two steps as the uncleared walk's.
    assert_eq!(steps[0].0, all[0].0);
    assert_eq!(steps[1].0, all[1].0);
}
