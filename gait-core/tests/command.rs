//! Velocity commands → footsteps (`command.rs`): the footprints against hand-integrated
//! commands, the limits on random command sequences, stopping, and the footsteps walked by the
//! streaming sampler with steps appended while walking (continuity of the CoM).

use gait_core::trajectory::command::{CommandLimits, StepGenerator, WalkCommand, SOLE_GAP};
use gait_core::trajectory::plan::StepLimits;
use gait_core::{ForwardWalk, Place, Robot, Sampler, Side};

const T: f64 = 0.64;
const W: f64 = 0.045;

fn gen() -> StepGenerator<f64> {
    StepGenerator::new(
        &Robot::reference(),
        0.217,
        CommandLimits::DEFAULT,
        W,
        T,
        [Place::new(0.0, W, 0.0), Place::new(0.0, -W, 0.0)],
        Side::Left,
    )
    .unwrap()
}

fn cmd(vx: f64, vy: f64, yaw_rate: f64) -> WalkCommand<f64> {
    WalkCommand { vx, vy, yaw_rate }
}

/// Forward at 0.05 m/s: the velocity ramps by a·T = 0.064 m/s per step (reached in one step),
/// then consecutive footprints are v·T = 0.032 m apart, alternating at y = ±w.
#[test]
fn forward_command_advances_by_v_t_per_step() {
    let mut g = gen();
    let mut xs = Vec::new();
    for n in 0..10 {
        let s = g.next_step(&cmd(0.05, 0.0, 0.0));
        assert_eq!(s.side, if n % 2 == 0 { Side::Left } else { Side::Right });
        assert!((s.place.y - s.side.sign() * W).abs() < 1e-12, "{:?}", s);
        assert!(s.place.yaw.abs() < 1e-12);
        xs.push(s.place.x);
    }
    for (n, w) in xs.windows(2).enumerate() {
        assert!(
            (w[1] - w[0] - 0.05 * T).abs() < 1e-12,
            "step {n}: {}",
            w[1] - w[0]
        );
    }
    assert!((xs[0] - 0.05 * T).abs() < 1e-12);
    // Acceleration limit: a·T = 0.064 m/s per step; then the leg's reach caps the step at
    // max_length = 2·√(L² − h²) (L = 0.95·(thigh + calf), h = z_c − ankle height), i.e. the
    // speed at max_length / T, the same every step (no jitter).
    let robot = Robot::reference();
    let max_len = StepLimits::for_robot(&robot, 0.217).max_length;
    let mut g = gen();
    let v: Vec<f64> = (0..6)
        .map(|_| {
            g.next_step(&cmd(0.5, 0.0, 0.0));
            g.velocity()[0]
        })
        .collect();
    let a = CommandLimits::DEFAULT.acc * T;
    println!("forward speeds {v:?}; reach cap {:.4} m/s", max_len / T);
    assert!((v[0] - a).abs() < 1e-12, "{v:?}");
    for x in &v[2..] {
        assert!((x - max_len / T).abs() < 1e-6, "{v:?}");
    }
}

/// Turning in place at 0.3 rad/s: the heading integrates ω·T per step once the yaw rate is
/// reached, the feet stay 2w apart about their midpoint, and no sole corners overlap.
#[test]
fn turning_in_place_integrates_the_heading() {
    let mut g = gen();
    let mut yaw = Vec::new();
    for _ in 0..20 {
        yaw.push(g.next_step(&cmd(0.0, 0.0, 0.3)).place.yaw);
    }
    // ω ramps 0.32 rad/s² · ... : a·T = 0.32 ≥ 0.3, so every step turns 0.3·T = 0.192 rad.
    for w in yaw.windows(2) {
        assert!((w[1] - w[0] - 0.3 * T).abs() < 1e-12, "{}", w[1] - w[0]);
    }
    let [l, r] = g.feet();
    let mid = ((l.x + r.x) / 2.0, (l.y + r.y) / 2.0);
    assert!(mid.0.hypot(mid.1) < 0.03, "drifted to {mid:?}");
    assert!(((l.x - r.x).hypot(l.y - r.y) - 2.0 * W).abs() < 0.02);
}

/// Side-stepping left at 0.03 m/s: the feet move left by vy·T per step on average and their
/// inner gap never drops below the sole clearance.
#[test]
fn side_step_moves_left_and_keeps_the_gap() {
    let mut g = gen();
    let robot = Robot::reference();
    for _ in 0..10 {
        g.next_step(&cmd(0.0, 0.03, 0.0));
        let [l, r] = g.feet();
        let gap = (l.y - r.y) - robot.geometry.sole_width;
        assert!(gap >= SOLE_GAP - 1e-12, "gap {gap}");
    }
    let [l, r] = g.feet();
    let mid = (l.y + r.y) / 2.0;
    // 10 steps at 0.03·T = 0.0192 m each (reached in the first step).
    assert!(
        (mid - 10.0 * 0.03 * T + 0.03 * T / 2.0).abs() < 0.0192,
        "{mid}"
    );
}

/// A deterministic stream of random commands (outside the limits too, NaN included): every
/// footprint passes the plan's reach check against the support foot and the sole-corner check,
/// the velocity stays within the limits and changes at most a·T per step; after a zero command
/// the robot stands within the steps the deceleration needs plus one.
#[test]
fn random_commands_stay_within_the_limits_and_stop() {
    let robot = Robot::reference();
    let reach = StepLimits::for_robot(&robot, 0.217);
    let lim = CommandLimits::DEFAULT;
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for run in 0..200 {
        let mut g = gen();
        let mut prev = g.velocity();
        for k in 0..30 {
            let mut c = cmd(0.4 * rnd(), 0.2 * rnd(), 1.2 * rnd());
            if k % 11 == 5 {
                c.vy = f64::NAN;
            }
            let support = {
                let [l, r] = g.feet();
                if g.next_swing() == Side::Left {
                    r
                } else {
                    l
                }
            };
            let s = g.next_step(&c);
            reach
                .check(s.side, &support, &s.place)
                .unwrap_or_else(|e| panic!("run {run} step {k}: {e} {s:?} from {support:?}"));
            let gap = min_corner_gap(&robot, s.side, &support, &s.place);
            assert!(
                gap >= SOLE_GAP - 1e-9,
                "run {run} step {k}: soles {gap} m apart"
            );
            let v = g.velocity();
            assert!(v[0] <= lim.vx_forward + 1e-12 && v[0] >= -lim.vx_backward - 1e-12);
            assert!(v[1].abs() <= lim.vy + 1e-12 && v[2].abs() <= lim.yaw_rate + 1e-12);
            // Speeding up is limited by the acceleration; slowing down may be faster (the
            // reach limits scale a step back).
            for (i, (a, b)) in v.iter().zip(prev).enumerate() {
                let acc = if i == 2 { lim.yaw_acc } else { lim.acc };
                let faster = a.abs() - b.abs();
                assert!(
                    faster <= acc * T + 1e-12 && a * b >= -(acc * T).powi(2),
                    "run {run} step {k} axis {i}: {v:?} after {prev:?}"
                );
            }
            prev = v;
        }
        let need = (0.4f64 / (lim.acc * T))
            .ceil()
            .max((1.2 / (lim.yaw_acc * T)).ceil()) as usize;
        let mut steps = 0;
        while !g.is_standing() {
            g.next_step(&WalkCommand::zero());
            steps += 1;
            assert!(
                steps <= need + 2,
                "run {run}: not standing after {steps} steps"
            );
        }
    }
}

/// The footsteps of a command script walked by the sampler, appended one step ahead while it
/// walks (the way the firmware will): every step is accepted, and the CoM position and velocity
/// change per tick no more than in a pre-planned walk of the same steps (no jumps when a
/// command changes mid-walk).
#[test]
fn commanded_steps_walk_in_the_sampler_without_jumps() {
    let robot = Robot::reference();
    let walk = ForwardWalk {
        steps: 1,
        ..ForwardWalk::table2()
    };
    let script = [
        (6, cmd(0.05, 0.0, 0.0)),
        (6, cmd(0.0, 0.0, 0.35)),
        (5, cmd(0.0, 0.03, 0.0)),
        (5, cmd(0.04, 0.02, 0.0)),
        (6, cmd(0.0, 0.0, 0.0)),
    ];
    let steps: Vec<_> = {
        let mut g = gen();
        script
            .iter()
            .flat_map(|&(n, c)| (0..n).map(move |_| c))
            .map(|c| g.next_step(&c))
            .collect()
    };
    let empty = |r: &Robot| {
        let mut p = walk
            .model_plan::<f64, 64>(r, gait_core::ModelKind::Tlipfm)
            .unwrap();
        while p.pop_front().is_some() {}
        p
    };
    // Pre-planned: every step queued before the walk starts.
    let mut planned = empty(&robot);
    for s in &steps {
        planned.push(*s).unwrap();
    }
    let (dc_planned, dv_planned) = jumps(Sampler::new(planned, 0.005).unwrap(), &[]);
    // Online: the first two steps queued, the rest appended one step ahead.
    let mut online = empty(&robot);
    for s in &steps[..2] {
        online.push(*s).unwrap();
    }
    let (dc, dv) = jumps(Sampler::new(online, 0.005).unwrap(), &steps[2..]);
    println!(
        "max |Δc| per tick {dc:.2e} m (pre-planned {dc_planned:.2e}), max |Δv| {dv:.2e} m/s \
         (pre-planned {dv_planned:.2e})"
    );
    assert!(dc <= 1.2 * dc_planned + 1e-6, "{dc} vs {dc_planned}");
    assert!(dv <= 1.5 * dv_planned + 1e-4, "{dv} vs {dv_planned}");
}

/// Walks `s` to the end, appending `later` one at a time whenever fewer than two steps are
/// queued; the largest per-tick change of the CoM position and velocity.
fn jumps(mut s: Sampler<f64, 64>, later: &[gait_core::Footstep<f64>]) -> (f64, f64) {
    let mut next = later.iter();
    let mut prev: Option<gait_core::GaitSample<f64>> = None;
    let (mut dc, mut dv) = (0.0f64, 0.0f64);
    while !s.is_done() {
        if s.plan().len() < 2 {
            if let Some(st) = next.next() {
                s.push_step(*st).unwrap();
            }
        }
        let g = s.next(0.0);
        if let Some(p) = prev {
            for k in 0..2 {
                dc = dc.max((g.com[k] - p.com[k]).abs());
                dv = dv.max((g.com_vel[k] - p.com_vel[k]).abs());
            }
        }
        prev = Some(g);
    }
    assert!(next.next().is_none(), "every step was walked");
    (dc, dv)
}

/// The smallest distance (m) of the swing sole's corners beyond the support sole's inner edge,
/// measured across the support foot (negative: overlapping).
fn min_corner_gap(robot: &Robot, side: Side, support: &Place<f64>, to: &Place<f64>) -> f64 {
    let (l, w) = (robot.geometry.sole_length, robot.geometry.sole_width);
    let mut gap = f64::INFINITY;
    for (u, v) in [(0.5, 0.5), (0.5, -0.5), (-0.5, 0.5), (-0.5, -0.5)] {
        let (cx, cy) = (u * l, v * w);
        let wx = to.x + to.yaw.cos() * cx - to.yaw.sin() * cy;
        let wy = to.y + to.yaw.sin() * cx + to.yaw.cos() * cy;
        let (dx, dy) = (wx - support.x, wy - support.y);
        let across = -support.yaw.sin() * dx + support.yaw.cos() * dy;
        gap = gap.min(across * side.sign() - w / 2.0);
    }
    gap
}
