//! The Table 2 walk through the leg IK: 12 joint trajectories, limits, continuity, feasibility.

use gait_core::kinematics::leg::{check, leg_fk, JointSpeedMonitor, LegKinematics};
use gait_core::kinematics::pipeline::{foot_pose, joint_targets, pelvis_pose};
use gait_core::robot::JOINT_NAMES;
use gait_core::{ForwardWalk, Model, ModelKind, Robot, Sampler, Side};

fn walk_joints<R: gait_core::Real>(kind: ModelKind) -> (Vec<[f64; 12]>, f64) {
    let robot = Robot::reference();
    let walk = ForwardWalk::table2();
    let model = Model::<R>::new(kind, &robot, walk.z_c).unwrap();
    let plan = walk.plan::<R, 32>(&robot, walk.params(model)).unwrap();
    let mut s = Sampler::new(plan, 0.005).unwrap();
    let kin = LegKinematics::<R>::new(&robot);
    let mut out = Vec::new();
    let mut worst_fk: f64 = 0.0;
    while !s.is_done() {
        let sample = s.next(R::zero());
        let (q, report) = joint_targets(&kin, &sample);
        assert!(
            !report.clamped(),
            "IK clamped at t = {} ns: {report:?}",
            sample.time_ns
        );
        let q64: [f64; 12] = core::array::from_fn(|i| q[i].to_f64());
        assert!(q64.iter().all(|v| v.is_finite()));
        // FK closes the loop: both feet are where the gait put them.
        let pelvis = pelvis_pose(&sample);
        for side in [Side::Left, Side::Right] {
            let i = side.index();
            let leg: [R; 6] = core::array::from_fn(|j| q[6 * i + j]);
            let f = leg_fk(&robot, side, &pelvis, &leg);
            let want = foot_pose(&sample.feet[i]);
            worst_fk = worst_fk
                .max((f.x - want.x).abs().to_f64())
                .max((f.y - want.y).abs().to_f64())
                .max((f.z - want.z).abs().to_f64());
        }
        out.push(q64);
    }
    (out, worst_fk)
}

#[test]
fn table2_joint_trajectories_are_finite_within_limits_continuous_and_feasible() {
    let robot = Robot::reference();
    for kind in ModelKind::ALL {
        let (traj, fk_err) = walk_joints::<f32>(kind);
        assert!(fk_err < 1e-5, "{kind:?}: FK(IK) off by {fk_err} m");
        let dt = 0.005;
        let mut mon = JointSpeedMonitor::new(&robot, dt).unwrap();
        for (k, q) in traj.iter().enumerate() {
            for (j, v) in q.iter().enumerate() {
                let side = if j < 6 { Side::Left } else { Side::Right };
                let lim = robot.joint_limit(side, j % 6);
                assert!(
                    *v >= lim.min && *v <= lim.max,
                    "{} = {v} outside limits",
                    JOINT_NAMES[j]
                );
            }
            mon.push(k as f64 * dt, q);
        }
        // Continuity: no jumps (an IK branch flip would move a joint by ~π in one tick). The
        // bound, 8 rad/s, is far above the walk's fastest joint and far below a flip.
        for w in traj.windows(2) {
            for j in 0..12 {
                let step = (w[1][j] - w[0][j]).abs();
                assert!(step <= 8.0 * dt, "{} jumps {step} rad", JOINT_NAMES[j]);
            }
        }
        let report = mon.report();
        println!(
            "{kind:?} peak joint speeds (rad/s, limit {}):",
            report.limit
        );
        for (j, name) in JOINT_NAMES.iter().enumerate() {
            println!(
                "  {:>14} {:6.3} at t = {:.3} s",
                name, report.peak_speed[j], report.peak_time[j]
            );
            assert!(report.peak_speed[j].is_finite());
        }
        // Feasibility as it comes out: the Table 2 swing (3 cm in 0.17 s) asks the swing knee
        // for slightly more than an XM430's 4.8 rad/s. The check must name that joint.
        match check(&report) {
            Ok(()) => println!("  feasible"),
            Err(e) => {
                println!("  INFEASIBLE: {e}");
                assert!(e.speed > e.limit && e.joint == report.worst_joint);
                assert!(
                    JOINT_NAMES[e.joint].ends_with("knee")
                        || JOINT_NAMES[e.joint].ends_with("pitch")
                );
            }
        }
        // The knees bend (z_c < straight-leg height) and the hips/knees actually move.
        assert!(traj.iter().all(|q| q[3] > 0.1 && q[9] > 0.1));
        assert!(report.peak_speed[2] > 0.05 && report.peak_speed[3] > 0.05);
    }
}

#[test]
fn f64_pipeline_matches_f32_pipeline() {
    let (a, _) = walk_joints::<f32>(ModelKind::Tlipfm);
    let (b, fk) = walk_joints::<f64>(ModelKind::Tlipfm);
    assert!(fk < 1e-9);
    let worst = a
        .iter()
        .zip(&b)
        .flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p - q).abs()))
        .fold(0.0, f64::max);
    println!("f32 vs f64 joint angles: {worst:.2e} rad");
    assert!(worst < 1e-4, "{worst}");
}
