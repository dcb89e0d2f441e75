//! The MuJoCo robot against hand-checkable physics: standing still, tipping over, a servo's
//! step response on its torque–speed line, a push of known impulse, determinism.

use dxl::instruction::encode_sync_write;
use dxl::table::x_series;
use walker_contract::bus_map::TickMap;
use walker_host::sim::{Push, SimConfig, Simulator, XServoParams};

fn ticks_of(q: f64) -> i32 {
    TickMap::reference().tick_f64(0, q)
}

const G: f64 = 9.80665;

/// Writes one register of servos `ids` with one SYNC WRITE.
fn write_all(sim: &mut Simulator, field: dxl::table::Field, ids: &[u8], values: &[Vec<u8>]) {
    let entries: Vec<(u8, &[u8])> = ids.iter().zip(values).map(|(&i, v)| (i, &v[..])).collect();
    let mut buf = [0u8; 256];
    let n = encode_sync_write(&mut buf, field.addr, field.len, &entries).unwrap();
    sim.feed(&buf[..n]);
}

/// Goals = `q`, torque on, on all 12 servos.
fn hold_pose(sim: &mut Simulator, q: &[f64; 12]) {
    let ids: Vec<u8> = (1..=12).collect();
    let goals: Vec<Vec<u8>> = q
        .iter()
        .map(|&a| ticks_of(a).to_le_bytes().to_vec())
        .collect();
    write_all(sim, x_series::GOAL_POSITION, &ids, &goals);
    write_all(sim, x_series::TORQUE_ENABLE, &ids, &vec![vec![1u8]; 12]);
}

/// Legs tilted by `a` (hip pitch a, ankle pitch −a), knees slightly bent: feet flat, pelvis
/// upright, P moved forward of the soles by ≈ 0.2·sin a.
fn lean(a: f64) -> [f64; 12] {
    let leg = [0.0, 0.0, a - 0.1, 0.2, -a - 0.1, 0.0];
    let mut q = [0.0; 12];
    q[..6].copy_from_slice(&leg);
    q[6..].copy_from_slice(&leg);
    q
}

/// x of the soles (both at the same x) from P, by the leg's forward kinematics.
fn sole_x(q: &[f64; 12]) -> f64 {
    let pelvis = gait_core::kinematics::leg::Pose::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let ql: [f64; 6] = q[..6].try_into().unwrap();
    gait_core::kinematics::leg::leg_fk(
        &gait_core::Robot::reference(),
        gait_core::Side::Left,
        &pelvis,
        &ql,
    )
    .x
}

fn standing(q: [f64; 12]) -> Simulator {
    let cfg = SimConfig {
        initial_q: q,
        ..SimConfig::default()
    };
    let mut sim = Simulator::new(&cfg).unwrap();
    hold_pose(&mut sim, &q);
    sim
}

/// The firmware's measurement: the load cells' centre of pressure placed at the true sole poses.
fn measured_zmp(sim: &Simulator) -> ([f64; 2], f64) {
    let t = sim.physics.truth();
    let cells = gait_core::Robot::reference().geometry.force_sensors;
    let mut sum = 0.0;
    let mut m = [0.0; 2];
    for s in 0..2 {
        // Sole point and yaw from the wrench's reference point: the truth's CoP per foot is
        // not published, so rebuild the sole pose from the feet's contact wrench instead:
        // the cells sum to F_z and their moments are the sole's, so Σ Fᵢ·cᵢ / Σ Fᵢ is the
        // sole's CoP in its frame; world position = sole point + R·(that).
        let f = t.forces[s];
        let fz: f64 = f.iter().sum();
        if fz <= 0.0 {
            continue;
        }
        let w = t.sole_wrench[s];
        // Sole point in the world from the wrench: M = (cop − s) × F ⇒ for a flat sole
        // cop_x − s_x = −M_y/F_z, cop_y − s_y = M_x/F_z (independent check of the cells).
        let local: [f64; 2] =
            [0, 1].map(|k| f.iter().zip(cells).map(|(fi, c)| fi * c[k]).sum::<f64>() / fz);
        let from_wrench = [-w[4] / w[2], w[3] / w[2]];
        for k in 0..2 {
            assert!(
                (local[k] - from_wrench[k]).abs() < 1e-6,
                "cells {local:?} vs wrench {from_wrench:?}"
            );
        }
        let _ = local;
        sum += fz;
        m[0] += fz * from_wrench[0];
        m[1] += fz * from_wrench[1];
    }
    (m, sum)
}

#[test]
fn standing_still_zmp_is_com_projection_and_weight_is_carried() {
    let q = lean(0.0);
    let mut sim = standing(q);
    sim.advance_to(3_000_000).unwrap();
    let t = *sim.physics.truth();
    assert!(!t.falling && sim.physics.fall_started_us().is_none());
    let mass = 4.95;
    let cells: f64 = t.forces.iter().flatten().sum();
    assert!(
        (cells - mass * G).abs() < 0.005 * mass * G,
        "load cells {cells} N vs m·g {} N",
        mass * G
    );
    assert!(t.sole_contact == [true, true]);
    // True centre of pressure vs the CoM's ground projection.
    let d = (t.zmp[0] - t.com[0]).hypot(t.zmp[1] - t.com[1]);
    eprintln!(
        "standing: load cells {cells:.4} N = {:.5} m·g; CoP − CoM projection {:.4} mm",
        cells / (mass * G),
        d * 1e3
    );
    assert!(d < 0.001, "CoP {:?} vs CoM {:?}: {d} m", t.zmp, t.com);
    let _ = measured_zmp(&sim);
}

#[test]
fn load_cells_reproduce_the_sole_wrench() {
    let mut sim = standing(lean(0.15));
    sim.advance_to(1_000_000).unwrap();
    let (_, fz) = measured_zmp(&sim);
    assert!(fz > 40.0);
}

#[test]
fn com_outside_the_soles_falls_inside_stands() {
    // Inside: lean 0.1 rad (P ≈ 2 cm ahead of the ankles).
    let mut sim = standing(lean(0.1));
    sim.advance_to(10_000).unwrap();
    let inside = sim.physics.truth().margin;
    let com_x = sim.physics.truth().com[0] - sole_x(&lean(0.1));
    assert!(
        com_x > 0.01 && com_x < 0.04,
        "CoM x {com_x} from the ankles"
    );
    sim.advance_to(2_000_000).unwrap();
    assert!(
        sim.physics.fall_started_us().is_none(),
        "fell with CoM x {com_x}"
    );
    assert!(inside > 0.01, "margin {inside}");
    // Outside: lean 0.5 rad: the CoM is ahead of the toes (sole half-length 5 cm).
    let mut sim = standing(lean(0.5));
    sim.advance_to(10_000).unwrap();
    let com_x = sim.physics.truth().com[0] - sole_x(&lean(0.5));
    assert!(
        com_x > 0.05 + 0.005,
        "CoM x {com_x} (from the ankles) is not beyond the toes"
    );
    sim.advance_to(2_000_000).unwrap();
    assert!(sim.physics.fall_started_us().is_some());
    assert!(sim.physics.fallen_at_us().is_some(), "did not come to lie");
    assert!(
        sim.physics.truth().pelvis_rpy[1] > 0.8,
        "did not fall forward"
    );
}

#[test]
fn servo_step_follows_the_torque_speed_line() {
    // Held in the air, only the left hip yaw powered, P gain 3200 (the PWM saturates until
    // the error is below 885/25 = 35 ticks = 0.054 rad): a 0.8 rad step runs on the
    // torque–speed line, J·ω̇ = τ_s − f_c − (τ_s/ω₀ + b_g)·ω, so
    // θ(t) = ω_ss·(t − T·(1 − e^(−t/T))), ω_ss = (τ_s − f_c)/b, T = J/b.
    let cfg = SimConfig {
        env: walker_host::sim::EnvConfig {
            start_lift_m: 0.3,
            ..Default::default()
        },
        ..SimConfig::default()
    };
    let mut sim = Simulator::new(&cfg).unwrap();
    write_all(
        &mut sim,
        x_series::POSITION_P_GAIN,
        &[1],
        &[3200u16.to_le_bytes().to_vec()],
    );
    write_all(&mut sim, x_series::TORQUE_ENABLE, &[1], &[vec![1u8]]);
    sim.advance_to(200_000).unwrap();
    assert!(sim.physics.q()[0].abs() < 2e-3);
    let step = 0.8;
    let t0 = sim.time_us();
    write_all(
        &mut sim,
        x_series::GOAL_POSITION,
        &[1],
        &[ticks_of(step).to_le_bytes().to_vec()],
    );
    let mut t90 = None;
    while sim.time_us() < t0 + 1_000_000 {
        sim.advance_to(sim.time_us() + 1000).unwrap();
        if t90.is_none() && sim.physics.q()[0] >= 0.9 * step {
            t90 = Some((sim.time_us() - t0) as f64 * 1e-6);
        }
    }
    let t90 = t90.expect("never reached 90 %");
    let p = XServoParams::XM430_W350;
    // Joint inertia about the vertical hip axis of a hanging straight leg: the armature plus
    // the links' own inertia about their long axis (rods r = 2 cm, the sole box's yaw inertia).
    let links = 0.5 * 0.2 * 0.02f64.powi(2)
        + 0.5 * 0.5 * 0.02f64.powi(2)
        + 0.25 * (0.1f64.powi(2) + 0.06f64.powi(2)) / 12.0;
    let j = p.armature + links;
    let b = p.back_emf_damping() + p.gear_damping;
    let w_ss = (p.stall_torque - p.friction_loss) / b;
    let tc = j / b;
    let theta = |t: f64| w_ss * (t - tc * (1.0 - (-t / tc).exp()));
    // Solve θ(t) = 0.9·step by bisection.
    let (mut lo, mut hi) = (0.0, 2.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if theta(mid) < 0.9 * step {
            lo = mid
        } else {
            hi = mid
        }
    }
    let expect = 0.5 * (lo + hi);
    eprintln!("servo step: time to 90 % {t90:.4} s, torque–speed line {expect:.4} s");
    assert!(
        (t90 - expect).abs() < 0.1 * expect,
        "time to 90 %: {t90} s, torque–speed line {expect} s"
    );
    // Settles on the goal within the encoder's resolution plus the friction dead band.
    assert!((sim.physics.q()[0] - step).abs() < 0.01);
}

#[test]
fn a_push_changes_the_com_velocity_by_impulse_over_mass() {
    // In free flight (no hold, no floor contact yet), a 1.2 N·s push along 30°.
    let push = Push {
        at_s: 0.05,
        impulse_ns: 1.2,
        direction_rad: 30f64.to_radians(),
        duration_s: 0.01,
    };
    let cfg = SimConfig {
        env: walker_host::sim::EnvConfig {
            start_lift_m: 0.6,
            ..Default::default()
        },
        hold_until_torque: false,
        pushes: vec![push],
        ..SimConfig::default()
    };
    let mut sim = Simulator::new(&cfg).unwrap();
    let mass = sim.physics.mujoco().unwrap().total_mass();
    assert!((mass - 4.95).abs() < 1e-9, "model mass {mass}");
    let vel = |sim: &mut Simulator, t_us: u64| {
        sim.advance_to(t_us).unwrap();
        let a = sim.physics.truth().com;
        sim.advance_to(t_us + 10_000).unwrap();
        let b = sim.physics.truth().com;
        [(b[0] - a[0]) / 0.01, (b[1] - a[1]) / 0.01]
    };
    let before = vel(&mut sim, 20_000);
    let after = vel(&mut sim, 80_000);
    assert!(sim.physics.truth().fz == 0.0, "touched the floor");
    let dv = [after[0] - before[0], after[1] - before[1]];
    let expect = [
        1.2 / mass * 30f64.to_radians().cos(),
        1.2 / mass * 30f64.to_radians().sin(),
    ];
    eprintln!("push: Δv {dv:?} m/s, J/m {expect:?} m/s");
    for k in 0..2 {
        assert!(
            (dv[k] - expect[k]).abs() < 0.05 * expect[k].abs(),
            "Δv {dv:?} vs J/m {expect:?}"
        );
    }
}

#[test]
fn same_seed_same_truth() {
    let run = || {
        let dir = std::env::temp_dir().join(format!("walker-mj-det-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(format!("truth-{}.csv", rand_suffix()));
        let cfg = SimConfig {
            initial_q: lean(0.05),
            log_truth: Some(path.clone()),
            noise: walker_host::sim::NoiseConfig {
                force_std_n: 0.2,
                gyro_std_rad_s: 0.01,
                ..Default::default()
            },
            seed: 5,
            ..SimConfig::default()
        };
        let mut sim = Simulator::new(&cfg).unwrap();
        hold_pose(&mut sim, &lean(0.05));
        sim.advance_to(300_000).unwrap();
        hold_pose(&mut sim, &lean(0.15));
        sim.advance_to(600_000).unwrap();
        sim.summary();
        drop(sim);
        std::fs::read(&path).unwrap()
    };
    let a = run();
    let b = run();
    assert!(a.len() > 10_000);
    assert_eq!(a, b);
}

fn rand_suffix() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    N.fetch_add(1, Ordering::Relaxed)
}

#[test]
fn the_mujoco_model_is_the_robot_description() {
    // One source: MuJoCo's kinematics of the generated model put each sole exactly where
    // gait-core's forward kinematics does, for joint angles across the limits, on every
    // described robot (the OP3's FK is checked against Menagerie's op3.xml in gait-core's
    // tests/robots.rs, so its MuJoCo model is too).
    for robot in gait_core::robot::ROBOTS {
        model_is_the_description(robot);
    }
    // And a made-up robot whose every leg dimension, sign and ID differs from both: a number of
    // either robot left in the generator would put its soles elsewhere (the reference robot's
    // round dimensions cannot be told from other constants by a literal scan:
    // host/tests/descriptions.rs).
    model_is_the_description(made_up_robot());
}

/// The reference robot with other legs: every dimension changed, the sole off the ankle, the
/// hip's roll and pitch axes below the pelvis point, mixed mounting signs, zero offsets and
/// other IDs.
fn made_up_robot() -> gait_core::Robot {
    let r = gait_core::Robot::reference();
    let g = gait_core::robot::Geometry {
        hip_offset_y: 0.052,
        thigh: 0.107,
        calf: 0.093,
        ankle_height: 0.027,
        sole_offset: [0.004, 0.006],
        hip_yaw_height: 0.013,
        sole_length: 0.097,
        sole_width: 0.063,
        ..r.geometry
    };
    let made = gait_core::Robot {
        name: "made-up",
        geometry: g,
        mounting: [1, -1, 1, -1, -1, 1, -1, 1, 1, -1, 1, -1],
        zero_offsets: [5, -12, 30, 0, -7, 3, 9, 0, -25, 14, 2, -4],
        bus: gait_core::robot::BusDescription {
            legs: [21, 22, 23, 24, 25, 26, 31, 32, 33, 34, 35, 36],
            ..r.bus
        },
        ..r
    };
    made.validate().unwrap();
    made.validate_bus().unwrap();
    made
}

fn model_is_the_description(robot: gait_core::Robot) {
    use gait_core::kinematics::leg::{leg_fk, Pose};
    use gait_core::Side;
    let mut rng = 12345u64;
    let mut uniform = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..20 {
        let q: [f64; 12] = std::array::from_fn(|j| {
            let side = if j < 6 { Side::Left } else { Side::Right };
            let l = robot.joint_limit(side, j % 6);
            l.min + (l.max - l.min) * uniform()
        });
        let cfg = SimConfig {
            initial_q: q,
            env: walker_host::sim::EnvConfig {
                start_lift_m: 1.0,
                ..Default::default()
            },
            robot,
            ..SimConfig::default()
        };
        let mut sim = Simulator::new(&cfg).unwrap();
        let body = sim.physics.mujoco().unwrap();
        let (p, r) = body.torso();
        let pelvis = Pose::new(p[0], p[1], p[2], 0.0, 0.0, 0.0);
        assert!((r[0] - 1.0).abs() < 1e-12 && (r[8] - 1.0).abs() < 1e-12);
        for (k, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let ql: [f64; 6] = q[6 * k..6 * k + 6].try_into().unwrap();
            let fk = leg_fk(&robot, side, &pelvis, &ql);
            let (sp, sr) = body.sole_sites()[k];
            let d =
                ((sp[0] - fk.x).powi(2) + (sp[1] - fk.y).powi(2) + (sp[2] - fk.z).powi(2)).sqrt();
            assert!(
                d < 1e-9,
                "{}: {side:?} sole {sp:?} vs FK {fk:?}",
                robot.name
            );
            let rf = fk.rotation();
            for i in 0..3 {
                for j in 0..3 {
                    assert!((sr[3 * i + j] - rf[i][j]).abs() < 1e-9, "{side:?} rotation");
                }
            }
        }
    }
}

#[test]
fn the_trunk_com_offset_moves_the_whole_body_com_by_its_mass_share() {
    let com_x = |dx: f64| {
        let q = lean(0.0);
        let mut cfg = SimConfig {
            initial_q: q,
            ..SimConfig::default()
        };
        cfg.env.trunk_com_dx_m = dx;
        let mut sim = Simulator::new(&cfg).unwrap();
        hold_pose(&mut sim, &q);
        sim.advance_to(2_000).unwrap();
        sim.physics.truth().com[0]
    };
    // Upper body 3.05 kg of 4.95 kg (reference-robot.md): 1 cm moves the CoM 6.16 mm.
    let shift = com_x(0.01) - com_x(0.0);
    assert!((shift - 0.01 * 3.05 / 4.95).abs() < 2e-4, "shift {shift} m");
    let back = com_x(-0.01) - com_x(0.0);
    assert!((back + 0.01 * 3.05 / 4.95).abs() < 2e-4, "shift {back} m");
    let mut cfg = SimConfig::default();
    cfg.env.trunk_com_dx_m = 0.06;
    assert!(cfg.validate().is_err());
}

#[test]
fn the_op3_stands_on_its_own_bus_map_and_mounting_signs() {
    // The OP3 in MuJoCo: its servos are found at OP3.robot's IDs (legs 7–18, arms 1–6, head
    // 19–20), no foot boards and no bus IMU; goals written through its tick map (several
    // mounting signs −1) hold a crouch: it stands, its weight on its soles, its torso upright,
    // and every joint at its goal within the servos' steady sag.
    use gait_core::robot::LEG_JOINTS;
    use gait_core::Robot;
    let robot = Robot::op3();
    let leg = [0.0, 0.0, -0.35, 0.7, -0.35, 0.0];
    let mut q = [0.0; LEG_JOINTS];
    q[..6].copy_from_slice(&leg);
    q[6..].copy_from_slice(&leg);
    let cfg = SimConfig {
        robot,
        initial_q: q,
        ..SimConfig::default()
    };
    let mut sim = Simulator::new(&cfg).unwrap();
    let ids: Vec<u8> = sim.bus.devices.iter().map(|d| d.id).collect();
    assert_eq!(
        ids,
        [8, 10, 12, 14, 16, 18, 7, 9, 11, 13, 15, 17, 1, 2, 3, 4, 5, 6, 19, 20]
    );
    let map = TickMap::from_robot(&robot);
    let goals: Vec<Vec<u8>> = (0..LEG_JOINTS)
        .map(|j| map.tick_f64(j, q[j]).to_le_bytes().to_vec())
        .collect();
    let legs = robot.bus.legs;
    write_all(&mut sim, x_series::GOAL_POSITION, &legs, &goals);
    write_all(
        &mut sim,
        x_series::TORQUE_ENABLE,
        &legs,
        &vec![vec![1u8]; 12],
    );
    let held: Vec<u8> = robot.bus.held.iter().map(|h| h.id).collect();
    let held_goals: Vec<Vec<u8>> = robot
        .bus
        .held
        .iter()
        .map(|h| {
            TickMap::reference()
                .tick_f64(0, h.angle)
                .to_le_bytes()
                .to_vec()
        })
        .collect();
    write_all(&mut sim, x_series::GOAL_POSITION, &held, &held_goals);
    write_all(
        &mut sim,
        x_series::TORQUE_ENABLE,
        &held,
        &vec![vec![1u8]; held.len()],
    );
    sim.advance_to(2_000_000).unwrap();
    let t = *sim.physics.truth();
    assert!(
        !t.falling && sim.physics.fall_started_us().is_none(),
        "{t:?}"
    );
    assert_eq!(t.sole_contact, [true, true]);
    let mass = robot.masses.total();
    assert!(
        (t.fz - mass * G).abs() < 0.01 * mass * G,
        "soles carry {} N of {} N",
        t.fz,
        mass * G
    );
    let body = sim.physics.mujoco().unwrap();
    let (_, r) = body.torso();
    assert!(r[8] > 0.99, "torso tilted: R_zz = {}", r[8]);
    // Each joint near its goal: a sign error would drive it the other way, to a limit.
    for (j, (got, want)) in body.q().iter().zip(q).enumerate() {
        assert!((got - want).abs() < 0.05, "joint {j}: {got} vs goal {want}");
    }
    // The held servos stand at their goals, read back through the bus tables.
    for (d, h) in sim.bus.devices[12..].iter().zip(robot.bus.held) {
        let tick = d.get_i32(x_series::PRESENT_POSITION);
        assert_eq!(
            tick,
            TickMap::reference().servo_tick_f64(h.angle),
            "{}",
            h.name
        );
    }
}
