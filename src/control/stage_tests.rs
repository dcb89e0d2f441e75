//! Host tests of the tick's stages one at a time (no walk): the fault injector, the f32 and the
//! fixed-point paths' corrections and IK against the gait-core pieces they chain. Host tests
//! only (`#[cfg(test)]`): a test that cannot set up returns its reason as an error.

use gait_core::feedback::catch::StepAdaptation;
use gait_core::feedback::compliance::{Compliance, LoadModel};
use gait_core::feedback::{IkOffsets, Measured};
use gait_core::gait::{Arithmetic, Engine, Targets};
use gait_core::robot::LEG_JOINTS;
use gait_core::{GaitSample, Robot, SupportPhase};

use super::f32_path::F32Path;
use super::faults::FaultInjector;
use super::path::{Goal, IkRequest, TickPath};
use crate::fake_robot::trace::FakeBoard;
use crate::record::LogWriter;
use crate::supervisor::JointMap;
use crate::Config;
use walker_contract::config::MAX_STEPS;

/// The first sample of the plan of `cfg` in single support.
fn single_support_sample(cfg: &Config) -> Result<GaitSample<f32>, String> {
    let robot = Robot::reference();
    let mut e = Engine::<MAX_STEPS>::new(&cfg.walk_config(), Arithmetic::F32, &robot)
        .map_err(|e| format!("engine: {e:?}"))?;
    loop {
        let s = e.next(0.0).f32;
        if matches!(s.phase, SupportPhase::Single(_)) {
            return Ok(s);
        }
        if e.is_done() {
            return Err("the plan has no single support".into());
        }
    }
}

fn measured(previous: &GaitSample<f32>, gyro: Option<[f32; 2]>) -> Measured<'_> {
    Measured {
        attitude: Some([0.0; 2]),
        gyro,
        loads: [f32::NAN; 2],
        zmp: None,
        previous,
    }
}

/// The goal's f32 targets (`None`: an integer goal).
fn rad(goal: &Goal) -> Option<[f32; LEG_JOINTS]> {
    match goal {
        Goal::Rad(q) => Some(*q),
        Goal::Fx(_) => None,
    }
}

#[test]
fn the_fault_injector_spoils_only_its_ticks() -> Result<(), String> {
    let cfg = Config {
        fault_nan_com_tick: Some(7),
        fault_nan_tick: Some(9),
        stop_at_tick: Some(11),
        ..Config::default()
    };
    let f = FaultInjector::new(&cfg);
    let s = single_support_sample(&Config::default())?;
    for k in 0..20 {
        let mut spoiled = s;
        f.sample(k, &mut spoiled);
        assert_eq!(f.sample_at(k), k == 7);
        assert_eq!(spoiled.com[0].is_nan(), k == 7, "tick {k}");
        assert_eq!(spoiled.is_finite(), k != 7, "tick {k}");
        let mut q = [0.1f32; LEG_JOINTS];
        f.targets(k, &mut q);
        assert_eq!(q[0].is_nan(), k == 9, "tick {k}");
        assert!(q[1..].iter().all(|v| *v == 0.1));
        assert_eq!(f.stop_at(k), k == 11);
    }
    let none = FaultInjector::new(&Config::default());
    assert!((0..10_000).all(|k| !none.sample_at(k) && !none.targets_at(k) && !none.stop_at(k)));
    Ok(())
}

/// The f32 path's joint corrections in their stated order on the IK's targets: the compliance
/// feed-forward on the IK's angles (its load model depends on them), then the gyro damping; the
/// levelling adds nothing without a swing deviation and the deflection feedback is off.
#[test]
fn the_f32_joint_chain_is_the_ik_then_compliance_then_gyro_damping() -> Result<(), String> {
    let cfg = Config {
        compliance: Compliance::DEFAULT,
        step_adaptation: StepAdaptation::OFF,
        sole_poses_measured: false,
        ..Config::default()
    };
    assert!(cfg.compliance.is_on() && !cfg.deflection.is_on());
    let robot = Robot::reference();
    let map = JointMap::from_robot(&robot);
    let targets = Targets::new(&robot, cfg.compensation);
    let present = single_support_sample(&cfg)?;
    let gyro = Some([0.3f32, -0.2]);
    let mut path = F32Path::new(&cfg, &robot, &map, present.com[2]);
    let ik = IkRequest {
        plan: None,
        ahead: None,
        present: &present,
        com_shift: [0.0; 2],
        sole_dz: [0.0; 2],
        walk_tick: 0,
        gyro_raw: None,
        f32_only: false,
    };
    let m = measured(&present, gyro);
    let mut goal = Goal::Rad([0.0; LEG_JOINTS]);
    path.joints(&targets, &m, &ik, &mut goal);

    let load = LoadModel::new(&robot);
    let ik_q = targets.joints(&present, [0.0; 2]).0;
    let mut expected = ik_q;
    let sag = load.apply(&cfg.compliance, &mut expected, &present, [0.0; 2]);
    cfg.gyro_feedback.apply(&mut expected, present.phase, gyro);
    assert!(sag > 1e-4, "the feed-forward acts: {sag}");
    assert_ne!(expected, ik_q);
    assert_eq!(rad(&goal), Some(expected));
    // Not the other order: the gyro damping first would change what the sag model loads.
    let mut reversed = ik_q;
    cfg.gyro_feedback.apply(&mut reversed, present.phase, gyro);
    load.apply(&cfg.compliance, &mut reversed, &present, [0.0; 2]);
    assert_ne!(rad(&goal), Some(reversed));
    Ok(())
}

/// Without a push the sample corrections of the f32 path add nothing (the stabilizer off, the
/// force difference control off) and never move the samples: the walk's samples are borrowed.
#[test]
fn the_f32_sample_chain_moves_nothing_without_a_catch() -> Result<(), String> {
    let cfg = Config::default();
    let robot = Robot::reference();
    let map = JointMap::from_robot(&robot);
    let present = single_support_sample(&cfg)?;
    let mut path = F32Path::new(&cfg, &robot, &map, present.com[2]);
    let mut board = FakeBoard::robot();
    let mut log = LogWriter::new();
    let mut offsets = IkOffsets::default();
    for _ in 0..50 {
        let moves = path.update_samples(
            &mut board,
            &mut log,
            &measured(&present, Some([0.0; 2])),
            &present,
            &mut offsets,
        );
        assert!(!moves);
    }
    assert_eq!(offsets, IkOffsets::default());
    Ok(())
}

/// A trunk tipped back beyond the ankles' deadband in single support: the catching step moves
/// the samples (on copies), the swing foot's landing place back; the stabilizer's shift stays 0
/// (off).
#[test]
fn a_tipped_trunk_makes_the_f32_sample_chain_move_the_swing_foot_back() -> Result<(), String> {
    let cfg = Config::default();
    let robot = Robot::reference();
    let map = JointMap::from_robot(&robot);
    let present = single_support_sample(&cfg)?;
    let SupportPhase::Single(stance) = present.phase else {
        return Err("the sample is not in single support".into());
    };
    let swing = stance.other().index();
    let mut path = F32Path::new(&cfg, &robot, &map, present.com[2]);
    let mut board = FakeBoard::robot();
    let mut log = LogWriter::new();
    let mut offsets = IkOffsets::default();
    let upright = measured(&present, Some([0.0; 2]));
    assert!(!path.update_samples(&mut board, &mut log, &upright, &present, &mut offsets));
    let tipped = Measured {
        attitude: Some([0.0, -0.2]),
        gyro: Some([0.0, -1.0]),
        ..upright
    };
    let moves = path.update_samples(&mut board, &mut log, &tipped, &present, &mut offsets);
    assert!(moves);
    let mut copy = present;
    path.apply_samples(&mut copy);
    assert!(
        copy.feet[swing].x < present.feet[swing].x,
        "the landing moves back"
    );
    assert_eq!(
        copy.feet[1 - swing],
        present.feet[1 - swing],
        "the stance foot stays"
    );
    assert_eq!(offsets.com_shift, [0.0; 2]);
    Ok(())
}

/// The fixed-point path takes the integer IK for the plan's integer sample (its goal in I16F16
/// straight to the ticks) and the f32 IK when told to (the fault injection's f32 targets).
#[cfg(feature = "fixed-gait")]
#[test]
fn the_fixed_path_takes_the_integer_ik_unless_f32_only() -> Result<(), String> {
    use super::fixed_path::FixedPath;
    use super::modes::Plan;
    let cfg = Config {
        arithmetic: Arithmetic::Fixed,
        autostart: true,
        ..Config::default()
    };
    let robot = Robot::reference();
    let targets = Targets::new(&robot, cfg.compensation);
    let engine = Engine::<MAX_STEPS>::new(&cfg.walk_config(), Arithmetic::Fixed, &robot)
        .map_err(|e| format!("engine: {e:?}"))?;
    let plan = Plan::new(engine, 0);
    let sample = *plan.ahead();
    assert!(sample.fixed.is_some());
    let mut path = FixedPath::new(&cfg, &robot);
    let mut ik = IkRequest {
        plan: Some(&plan),
        ahead: Some(&sample),
        present: &sample.f32,
        com_shift: [0.0; 2],
        sole_dz: [0.0; 2],
        walk_tick: 0,
        gyro_raw: None,
        f32_only: false,
    };
    let m = measured(&sample.f32, None);
    let mut goal = Goal::Rad([0.0; LEG_JOINTS]);
    path.joints(&targets, &m, &ik, &mut goal);
    let fx = plan
        .engine()
        .joints_fx(&targets, &sample, [0.0; 2])
        .ok_or("no integer IK for an integer sample")?;
    assert!(matches!(goal, Goal::Fx(q) if q == fx));
    ik.f32_only = true;
    path.joints(&targets, &m, &ik, &mut goal);
    assert_eq!(
        rad(&goal),
        Some(plan.engine().joints(&targets, &sample, [0.0; 2]))
    );
    Ok(())
}
