//! The compliance feed-forward's load model against independently derived numbers: a hand
//! computed single-support case, and the principle of virtual work over the whole Table 2 walk
//! (τ_j = −F·∂x_cop/∂q_j plus the links' m·g·∂z/∂q_j, by central differences of the forward
//! kinematics).

use gait_core::feedback::compliance::{Compliance, LoadModel, XM430_STIFFNESS};
use gait_core::kinematics::leg::{LegKinematics, Pose};
use gait_core::kinematics::pipeline::{joint_targets, pelvis_pose};
use gait_core::trajectory::swing::FootSample;
use gait_core::{ForwardWalk, GaitSample, Model, ModelKind, Robot, Sampler, Side, SupportPhase};

fn foot(x: f32, y: f32) -> FootSample<f32> {
    FootSample {
        x,
        y,
        z: 0.0,
        yaw: 0.0,
    }
}

/// Left single support, pelvis point at y = 0 and z_c = 0.23 m (straight legs), ZMP under the
/// left ankle: the ground force runs from (0, 0.045, 0) to the CoM (0, 0, 0.23), whose moment
/// about the left hip (0, 0.045, 0.23) is M·g·0.045 about +x and about the left ankle
/// (0, 0.045, 0.03) its lateral part F_y = −M·g·0.045/0.23 times the ankle's height 0.03 m; the
/// hanging right leg loads nothing; no other joint carries a torque.
#[test]
fn single_support_hip_roll_carries_the_body_beside_it() {
    let robot = Robot::reference();
    let model = LoadModel::new(&robot);
    let s = GaitSample {
        time_ns: 0,
        zmp: [0.0, 0.045],
        com: [0.0, 0.0, 0.23],
        com_vel: [0.0; 2],
        feet: [foot(0.0, 0.045), foot(0.0, -0.045)],
        phase: SupportPhase::Single(Side::Left),
        support_foot: Some(Side::Left),
        steps_done: 0,
    };
    let tau = model.joint_torques(&s, [0.0; 2], &[0.0; 12]);
    let expect = 4.95 * 9.80665 * 0.045;
    assert!((tau[1] - expect).abs() < 1e-4, "{tau:?}");
    let ankle = expect * 0.03 / 0.23;
    assert!((tau[5] - ankle).abs() < 1e-4, "{tau:?}");
    for (j, t) in tau.iter().enumerate() {
        if j != 1 && j != 5 {
            assert!(t.abs() < 1e-5, "joint {j}: {t}");
        }
    }
    // The feed-forward adds k·τ/K, saturated.
    let c = Compliance {
        roll: 1.0,
        pitch: 1.0,
        stiffness: XM430_STIFFNESS,
        max_rad: 0.5,
    };
    let mut q = [0.0f32; 12];
    let largest = model.apply(&c, &mut q, &s, [0.0; 2]);
    assert!((q[1] - expect / XM430_STIFFNESS).abs() < 1e-5, "{q:?}");
    assert!((largest - q[1]).abs() < 1e-7);
    let mut q = [0.0f32; 12];
    let sat = Compliance { max_rad: 0.05, ..c };
    model.apply(&sat, &mut q, &s, [0.0; 2]);
    assert_eq!(q[1], 0.05);
    let mut q = [0.0f32; 12];
    model.apply(&Compliance::OFF, &mut q, &s, [0.0; 2]);
    assert!(q.iter().all(|v| *v == 0.0));
}

/// Double support: the load splits along the line between the soles.
#[test]
fn double_support_splits_the_load_along_the_feet() {
    let robot = Robot::reference();
    let model = LoadModel::new(&robot);
    let mut s = GaitSample {
        time_ns: 0,
        zmp: [0.0, 0.0225],
        com: [0.0, 0.0, 0.23],
        com_vel: [0.0; 2],
        feet: [foot(0.0, 0.045), foot(0.0, -0.045)],
        phase: SupportPhase::Double,
        support_foot: None,
        steps_done: 0,
    };
    let [l, r] = model.load_split(&s);
    assert!(
        (l - 0.75).abs() < 1e-6 && (r - 0.25).abs() < 1e-6,
        "{l} {r}"
    );
    s.zmp = [0.0, 0.2];
    assert_eq!(model.load_split(&s), [1.0, 0.0]);
    s.feet = [foot(0.0, 0.0), foot(0.0, 0.0)];
    assert_eq!(model.load_split(&s), [0.5, 0.5]);
}

/// τ_j by virtual work: with the pelvis fixed, turning joint j by δ moves the foot (and its
/// centre of pressure, rigidly) and the mass points below j; the torque that holds the static
/// loads is τ_j = −Σ F·∂x/∂q_j. Checked on every 10th sample of the Table 2 walk, both legs.
#[test]
fn torques_match_virtual_work_over_the_table2_walk() {
    let robot = Robot::reference();
    let model = LoadModel::new(&robot);
    let kin = LegKinematics::<f64>::new(&robot);
    let walk = ForwardWalk::table2();
    let m = Model::<f32>::new(ModelKind::Tlipfm, &robot, walk.z_c).unwrap();
    let plan = walk.plan::<f32, 32>(&robot, walk.params(m)).unwrap();
    let mut sampler = Sampler::new(plan, 0.005).unwrap();
    let kin32 = LegKinematics::<f32>::new(&robot);
    let (g, mass) = (robot.gravity, robot.masses.total());
    let links = [robot.masses.thigh, robot.masses.calf, robot.masses.sole];
    let (mut n, mut worst) = (0usize, 0.0f64);
    let mut k = 0usize;
    while !sampler.is_done() {
        let s = sampler.next(0.0);
        k += 1;
        if !k.is_multiple_of(10) {
            continue;
        }
        let (q, _) = joint_targets(&kin32, &s);
        let tau = model.joint_torques(&s, [0.0; 2], &q);
        let split = model.load_split(&s);
        let p32 = pelvis_pose(&s);
        let pelvis = Pose::new(
            f64::from(p32.x),
            f64::from(p32.y),
            f64::from(p32.z),
            0.0,
            0.0,
            f64::from(p32.yaw),
        );
        let w2 = g / f64::from(s.com[2]);
        let f = [
            mass * w2 * f64::from(s.com[0] - s.zmp[0]),
            mass * w2 * f64::from(s.com[1] - s.zmp[1]),
            mass * g,
        ];
        let mix = [
            f64::from(split[0] * s.feet[0].x + split[1] * s.feet[1].x),
            f64::from(split[0] * s.feet[0].y + split[1] * s.feet[1].y),
        ];
        for (i, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let ft = s.feet[i];
            let cop = [
                f64::from(ft.x) + f64::from(s.zmp[0]) - mix[0],
                f64::from(ft.y) + f64::from(s.zmp[1]) - mix[1],
                f64::from(ft.z),
            ];
            let q64: [f64; 6] = core::array::from_fn(|j| f64::from(q[6 * i + j]));
            // The centre of pressure in the foot's frame, carried rigidly.
            let foot0 = kin.fk(side, &pelvis, &q64);
            let r0 = foot0.rotation();
            let d = [cop[0] - foot0.x, cop[1] - foot0.y, cop[2] - foot0.z];
            let local: [f64; 3] =
                core::array::from_fn(|a| r0[0][a] * d[0] + r0[1][a] * d[1] + r0[2][a] * d[2]);
            let place = |qq: &[f64; 6]| -> ([f64; 3], [f64; 3]) {
                let fp = kin.fk(side, &pelvis, qq);
                let r = fp.rotation();
                let c: [f64; 3] = core::array::from_fn(|a| {
                    [fp.x, fp.y, fp.z][a]
                        + r[a][0] * local[0]
                        + r[a][1] * local[1]
                        + r[a][2] * local[2]
                });
                let pts = kin.points(side, &pelvis, qq);
                (c, [pts.thigh_mass[2], pts.calf_mass[2], pts.sole_mass[2]])
            };
            for j in 0..6 {
                let h = 1e-6;
                let (mut qp, mut qm) = (q64, q64);
                qp[j] += h;
                qm[j] -= h;
                let ((cp, zp), (cm, zm)) = (place(&qp), place(&qm));
                let share = f64::from(split[i]);
                let mut expect = 0.0;
                for a in 0..3 {
                    expect -= share * f[a] * (cp[a] - cm[a]) / (2.0 * h);
                }
                for l in 0..3 {
                    expect += links[l] * g * (zp[l] - zm[l]) / (2.0 * h);
                }
                let got = f64::from(tau[6 * i + j]);
                let err = (got - expect).abs();
                worst = worst.max(err);
                assert!(
                    err < 2e-3 + 1e-3 * expect.abs(),
                    "sample {} ns, leg {i}, joint {j}: model {got} N·m, virtual work {expect} N·m",
                    s.time_ns
                );
                n += 1;
            }
        }
    }
    assert!(n > 1000, "{n} torques checked");
    println!("{n} joint torques within {worst:.2e} N·m of virtual work");
}
