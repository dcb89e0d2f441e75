//! Tests of the simulated robot: ground-truth ZMP, force distribution, the bus over TCP with
//! lock-step, fault injection and determinism.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::Duration;

use dxl::instruction::{encode_bulk_read, encode_sync_write, opcode, BulkReadRequest};
use dxl::table::{foot, foot::FootForces, imu, imu::ImuSample, x_series};
use dxl::{Decoder, Instruction, Status, BROADCAST_ID};
use gait_core::kinematics::leg::{leg_points, Pose};
use gait_core::{Robot, Side};
use walker_contract::bus_map::TickMap;
use walker_host::sim::forces::{center_of_pressure, distribute, FootContact};
use walker_host::sim::zmp::{whole_body_zmp, MassPoint};
use walker_host::sim::{
    spawn, FaultConfig, PhysicsModel, ServoTorque, SimConfig, Simulator, Support, TruthSample,
};

const G: f64 = 9.80665;

/// These tests check the idealised kinematic model (exact, hand-checkable numbers) and the bus;
/// the MuJoCo robot's physics is tested in `tests/mujoco.rs`.
fn kin() -> SimConfig {
    SimConfig {
        physics: PhysicsModel::Kinematic,
        ..SimConfig::default()
    }
}
const TOTAL_MASS: f64 = 4.95;
/// Σ mᵢ zᵢ at the zero pose, by hand: upper body 3.05 kg at 0.23 + 0.09 = 0.32 m; per leg
/// thigh 0.20 kg at 0.18 m, calf 0.50 kg at 0.08 m, sole 0.25 kg at 0.015 m.
const SUM_MZ: f64 = 3.05 * 0.32 + 2.0 * (0.20 * 0.18 + 0.50 * 0.08 + 0.25 * 0.015);

/// The seven mass points of the reference robot at the zero pose, pelvis at (0, 0, 0.23).
fn zero_pose_points(acc: [f64; 3]) -> Vec<MassPoint> {
    let robot = Robot::reference();
    let pelvis = Pose::new(0.0, 0.0, 0.23, 0.0, 0.0, 0.0);
    let mut pts = vec![MassPoint {
        mass: 3.05,
        pos: [0.0, 0.0, 0.32],
        acc,
    }];
    for side in [Side::Left, Side::Right] {
        let lp = leg_points(&robot, side, &pelvis, &[0.0; 6]);
        for (m, p) in [
            (0.20, lp.thigh_mass),
            (0.50, lp.calf_mass),
            (0.25, lp.sole_mass),
        ] {
            pts.push(MassPoint {
                mass: m,
                pos: p,
                acc,
            });
        }
    }
    pts
}

#[test]
fn zero_pose_mass_points_match_hand_values() {
    let pts = zero_pose_points([0.0; 3]);
    let m: f64 = pts.iter().map(|p| p.mass).sum();
    let mz: f64 = pts.iter().map(|p| p.mass * p.pos[2]).sum();
    assert!((m - TOTAL_MASS).abs() < 1e-12);
    assert!((mz - SUM_MZ).abs() < 1e-12, "{mz} vs {SUM_MZ}");
}

#[test]
fn static_zmp_is_com_projection() {
    let z = whole_body_zmp(&zero_pose_points([0.0; 3]), G, [0.0; 2]).unwrap();
    // Symmetric straight legs: the CoM is under P = (0, 0).
    assert!(z.xy[0].abs() < 1e-12 && z.xy[1].abs() < 1e-12);
    assert!((z.fz - TOTAL_MASS * G).abs() < 1e-9);
}

#[test]
fn horizontal_acceleration_shifts_zmp() {
    for a in [1.0, -2.5] {
        let z = whole_body_zmp(&zero_pose_points([a, 0.5 * a, 0.0]), G, [0.0; 2]).unwrap();
        let expect = -a * SUM_MZ / (TOTAL_MASS * G);
        assert!((z.xy[0] - expect).abs() < 1e-12, "{} vs {expect}", z.xy[0]);
        assert!((z.xy[1] - 0.5 * expect).abs() < 1e-12);
        // e.g. a = 1 m/s² → −0.023393 m.
    }
    let z = whole_body_zmp(&zero_pose_points([1.0, 0.0, 0.0]), G, [0.0; 2]).unwrap();
    assert!((z.xy[0] + 0.023393).abs() < 1e-5);
}

#[test]
fn simulated_static_robot_zmp_and_forces() {
    let mut sim = Simulator::new(&kin()).unwrap();
    sim.advance_to(100_000).unwrap();
    let t = *sim.physics.truth();
    assert_eq!(t.support, Support::Double);
    assert!(
        t.zmp[0].abs() < 1e-9 && t.zmp[1].abs() < 1e-9,
        "{:?}",
        t.zmp
    );
    assert!((t.fz - TOTAL_MASS * G).abs() < 1e-6);
    let com_z = SUM_MZ / TOTAL_MASS;
    assert!((t.com[2] - com_z).abs() < 1e-9);
    assert!((t.pelvis[2] - 0.23).abs() < 1e-12);
    // The foot boards' tables: forces sum to the weight, centre of pressure under P.
    let mut total = 0.0;
    for id in [111, 112] {
        let d = sim.bus.device(id).unwrap();
        let s =
            FootForces::from_bytes(d.read(foot::SAMPLE.addr, foot::SAMPLE.len).unwrap()).unwrap();
        total += f64::from(s.total_n());
        // The cells' places are the robot description's (the board does not know them).
        let cells = gait_core::Robot::reference().geometry.force_sensors;
        let cop = [0, 1].map(|a| {
            s.forces_mn
                .iter()
                .zip(cells)
                .map(|(&f, c)| f64::from(f) * 1e-3 * c[a])
                .sum::<f64>()
                / f64::from(s.total_n())
        });
        assert!(cop[0].abs() < 1e-4 && cop[1].abs() < 1e-4, "{cop:?}");
        assert!((f64::from(s.total_n()) - TOTAL_MASS * G / 2.0).abs() < 0.01);
    }
    assert!((total - TOTAL_MASS * G).abs() < 0.01);
    // The IMU: no rotation, +g on z.
    let d = sim.bus.device(200).unwrap();
    let s = ImuSample::from_bytes(d.read(imu::SAMPLE.addr, imu::SAMPLE.len).unwrap()).unwrap();
    assert_eq!(s.gyro_urad_s, [0, 0, 0]);
    assert!((s.accel_m_s2()[2] as f64 - G).abs() < 1e-4);
}

#[test]
fn static_crouch_zmp_equals_com_projection() {
    // Crouched, asymmetric static pose: no accelerations → ZMP = CoM ground projection.
    let mut q = [0.0; 12];
    q[2] = -0.3;
    q[3] = 0.6;
    q[4] = -0.3;
    q[8] = -0.2;
    q[9] = 0.4;
    q[10] = -0.2;
    let cfg = SimConfig {
        initial_q: q,
        ..kin()
    };
    let mut sim = Simulator::new(&cfg).unwrap();
    sim.advance_to(50_000).unwrap();
    let t = *sim.physics.truth();
    assert!((t.zmp[0] - t.com[0]).abs() < 1e-9 && (t.zmp[1] - t.com[1]).abs() < 1e-9);
    // Stance = the lower (longer, right) leg; the bent left leg is in the air.
    assert_eq!(t.support, Support::Right);
}

#[test]
fn force_distribution_matches_zmp_and_weight() {
    let s = Robot::reference().geometry.force_sensors;
    let w = TOTAL_MASS * G;
    let l = FootContact {
        xy: [0.0, 0.045],
        yaw: 0.0,
    };
    let r = FootContact {
        xy: [0.02, -0.045],
        yaw: 0.1,
    };
    for zmp in [
        [0.0, 0.0],
        [0.01, 0.02],
        [0.015, -0.04],
        [-0.02, 0.05],
        [0.03, 0.0],
    ] {
        let f = distribute(w, zmp, Some(l), Some(r), &s);
        assert!(f.iter().flatten().all(|v| *v >= 0.0));
        let (cop, total) = center_of_pressure(&f, [Some(l), Some(r)], &s).unwrap();
        assert!((total - w).abs() < 1e-9);
        assert!(
            (cop[0] - zmp[0]).abs() < 1e-9 && (cop[1] - zmp[1]).abs() < 1e-9,
            "{zmp:?} {cop:?}"
        );
    }
    // Single support.
    let f = distribute(w, [0.03, 0.05], Some(l), None, &s);
    let (cop, total) = center_of_pressure(&f, [Some(l), None], &s).unwrap();
    assert!(
        (total - w).abs() < 1e-9 && (cop[0] - 0.03).abs() < 1e-9 && (cop[1] - 0.05).abs() < 1e-9
    );
    assert_eq!(f[1], [0.0; 4]);
}

#[test]
fn disturbance_torque_shifts_zmp() {
    let mut cfg = kin();
    cfg.disturbance.constant_nm = 0.5;
    cfg.fall.enabled = false;
    let mut sim = Simulator::new(&cfg).unwrap();
    sim.advance_to(2_000_000).unwrap();
    let t = *sim.physics.truth();
    // Steady state: φ_d = τ/k, ZMP_x = τ/(Mg) + M_u·l_u·sin φ_d / M.
    let k = 0.026 * (std::f64::consts::TAU * 8.0).powi(2);
    let phi = 0.5 / k;
    let expect = 0.5 / (TOTAL_MASS * G) + 3.05 * 0.09 * phi.sin() / TOTAL_MASS;
    assert!((t.zmp[0] - expect).abs() < 1e-4, "{} vs {expect}", t.zmp[0]);
}

#[test]
fn forced_fall_tilts_imu_and_unloads_feet() {
    let mut cfg = kin();
    cfg.fall.forced_at_s = Some(0.1);
    let mut sim = Simulator::new(&cfg).unwrap();
    sim.advance_to(3_000_000).unwrap();
    let s = sim.summary();
    assert!(s.fall_started_us.is_some() && s.fallen_at_us.is_some());
    let d = sim.bus.device(200).unwrap();
    let imu_s = ImuSample::from_bytes(d.read(imu::SAMPLE.addr, imu::SAMPLE.len).unwrap()).unwrap();
    let a = imu_s.accel_m_s2();
    // Lying on its front: gravity mostly along body x.
    assert!(a[0].abs() > 8.0 && a[2].abs() < 2.0, "{a:?}");
    let t = sim.physics.truth();
    assert!(t.falling && t.forces.iter().flatten().all(|v| *v == 0.0));
}

#[test]
fn truth_csv_is_written() {
    let path = std::env::temp_dir().join(format!("walker-sim-truth-{}.csv", std::process::id()));
    let cfg = SimConfig {
        log_truth: Some(path.clone()),
        log_every_us: 10_000,
        // No torque model: the motor torques are not available (empty fields).
        servo_torque: None,
        ..kin()
    };
    let mut sim = Simulator::new(&cfg).unwrap();
    sim.advance_to(1_000_000).unwrap();
    let s = sim.summary();
    let text = std::fs::read_to_string(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].starts_with("t_s,zmp_x_m,zmp_y_m,fz_n,"));
    assert_eq!(lines.len() as u64, s.truth_rows + 1);
    assert!((95..=101).contains(&s.truth_rows), "{}", s.truth_rows);
    let cols = lines[0].split(',').count();
    assert!(lines[1..].iter().all(|l| l.split(',').count() == cols));
    // An absent value is an empty field, never NaN text.
    assert!(!text.contains("NaN") && !text.to_lowercase().contains(",nan"));
    // The one reader reads it back: the ZMP under the feet while standing, and every torque
    // column either all numbers or all empty (no torque model in the kinematic robot: empty).
    let tr = walker_host::report::read_truth(&path_copy(&text)).unwrap();
    assert_eq!(tr.t.len() as u64, s.truth_rows);
    assert!(
        tr.zmp.iter().all(|z| z[1].abs() < 0.05),
        "{:?}",
        tr.zmp.first()
    );
    let header: Vec<&str> = lines[0].split(',').collect();
    let tq = header.iter().position(|c| *c == "tq_1_nm").unwrap();
    let first: Vec<&str> = lines[1].split(',').collect();
    let torque_model = cfg.servo_torque.is_some();
    assert_eq!(first[tq].is_empty(), !torque_model, "{}", lines[1]);
}

/// `text` in a fresh temporary file.
fn path_copy(text: &str) -> std::path::PathBuf {
    let p = std::env::temp_dir().join(format!("walker-sim-truth-copy-{}.csv", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p
}

/// BULK READ request of foot board `id`'s sensor block.
fn foot_request(id: u8) -> BulkReadRequest {
    BulkReadRequest {
        id,
        addr: foot::SAMPLE.addr,
        len: foot::SAMPLE.len,
    }
}

/// BULK READ request of the IMU's sensor block.
fn imu_request() -> BulkReadRequest {
    BulkReadRequest {
        id: 200,
        addr: imu::SAMPLE.addr,
        len: imu::SAMPLE.len,
    }
}

/// The instruction packet of `inst` to device `id`.
fn packet(id: u8, inst: Instruction<'_>) -> Vec<u8> {
    let mut buf = [0u8; 64];
    let n = inst.encode(&mut buf, id).unwrap();
    buf[..n].to_vec()
}

/// The pelvis pose of a truth sample (position, roll-pitch-yaw).
fn pelvis_pose(tr: &TruthSample) -> Pose<f64> {
    let ([x, y, z], [roll, pitch, yaw]) = (tr.pelvis, tr.pelvis_rpy);
    Pose::new(x, y, z, roll, pitch, yaw)
}

fn ping(id: u8) -> Vec<u8> {
    packet(id, Instruction::Ping)
}

fn statuses(bytes: &[u8]) -> Vec<(u8, u8, Vec<u8>)> {
    let mut dec = Decoder::<1024>::new();
    let mut out = Vec::new();
    for &b in bytes {
        if let Some(Ok(p)) = dec.push(b) {
            let s = Status::from_packet(&p).unwrap();
            out.push((s.id, s.error.to_byte(), s.data.to_vec()));
        }
    }
    out
}

#[test]
fn fault_rates_and_dead_device() {
    let cfg = SimConfig {
        seed: 1234,
        faults: FaultConfig {
            p_drop: 0.1,
            p_corrupt: 0.05,
            dead_ids: vec![111],
            ..FaultConfig::default()
        },
        ..kin()
    };
    let mut sim = Simulator::new(&cfg).unwrap();
    let clean = {
        let mut s = Simulator::new(&kin()).unwrap();
        s.feed(&ping(1)).remove(0)
    };
    let (mut dropped, mut corrupted) = (0, 0);
    let n = 10_000;
    let p = ping(1);
    for _ in 0..n {
        let r = sim.feed(&p);
        assert_eq!(r.len(), 1);
        if r[0].is_empty() {
            dropped += 1;
        } else if r[0] != clean {
            corrupted += 1;
            assert_eq!(r[0].len(), clean.len());
            assert_eq!(r[0].iter().zip(&clean).filter(|(a, b)| a != b).count(), 1);
        }
    }
    // Binomial: 4 standard deviations.
    let sd = |p: f64| 4.0 * (n as f64 * p * (1.0 - p)).sqrt();
    assert!(
        (dropped as f64 - 1000.0).abs() < sd(0.1),
        "dropped {dropped}"
    );
    assert!(
        (corrupted as f64 - 500.0).abs() < sd(0.05),
        "corrupted {corrupted}"
    );
    assert_eq!(sim.bus.counters.dropped, dropped);
    assert_eq!(sim.bus.counters.corrupted, corrupted);
    // Dead left foot board.
    let mut sim = Simulator::new(&SimConfig {
        faults: FaultConfig {
            dead_ids: vec![111],
            ..FaultConfig::default()
        },
        ..kin()
    })
    .unwrap();
    assert_eq!(sim.feed(&ping(111)), vec![Vec::<u8>::new()]);
    let mut buf = [0u8; 32];
    let k = Instruction::SyncRead {
        addr: foot::SAMPLE.addr,
        len: foot::SAMPLE.len,
        ids: &[111, 112],
    }
    .encode(&mut buf, BROADCAST_ID)
    .unwrap();
    let r = sim.feed(&buf[..k]);
    let st = statuses(&r[0]);
    assert_eq!(st.len(), 1);
    assert_eq!(st[0].0, 112);
}

#[test]
fn in_process_determinism() {
    let run = |seed: u64| {
        let mut cfg = SimConfig { seed, ..kin() };
        cfg.faults.p_drop = 0.2;
        cfg.faults.p_corrupt = 0.2;
        cfg.noise.force_std_n = 0.5;
        cfg.noise.gyro_std_rad_s = 0.01;
        let mut sim = Simulator::new(&cfg).unwrap();
        let mut out = Vec::new();
        let mut buf = [0u8; 64];
        for k in 0..200u64 {
            sim.advance_to(k * 10_000).unwrap();
            let n = encode_bulk_read(&mut buf, &[foot_request(111), imu_request()]).unwrap();
            for r in sim.feed(&buf[..n]) {
                out.extend(r);
            }
        }
        out
    };
    assert_eq!(run(5), run(5));
    assert_ne!(run(5), run(6));
}

/// A master on the TCP bus plus the lock-step channel.
struct Client {
    bus: TcpStream,
    ls: TcpStream,
    log: Vec<u8>,
}

impl Client {
    fn connect(cfg: SimConfig) -> (Client, walker_host::sim::SimHandle) {
        let h = spawn(SimConfig {
            port: 0,
            lockstep_port: Some(0),
            ..cfg
        })
        .unwrap();
        let bus = TcpStream::connect(h.bus_addr().unwrap()).unwrap();
        let ls = TcpStream::connect(h.lockstep_addr().unwrap()).unwrap();
        for s in [&bus, &ls] {
            s.set_nodelay(true).unwrap();
            s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        }
        (
            Client {
                bus,
                ls,
                log: Vec::new(),
            },
            h,
        )
    }

    fn time(&mut self, t_us: u64) {
        let mut m = vec![0x5A];
        m.extend_from_slice(&t_us.to_le_bytes());
        self.ls.write_all(&m).unwrap();
    }

    /// Sends one instruction; returns the reply bytes announced on the lock-step channel.
    fn send(&mut self, pkt: &[u8]) -> Vec<u8> {
        self.bus.write_all(pkt).unwrap();
        announced_reply(&mut self.ls, &mut self.bus, &mut self.log)
    }

    fn read(&mut self, id: u8, addr: u16, len: u16) -> Vec<u8> {
        let st = statuses(&self.send(&packet(id, Instruction::Read { addr, len })));
        assert_eq!(st.len(), 1);
        assert_eq!((st[0].0, st[0].1), (id, 0));
        st[0].2.clone()
    }
}

fn i32_of(b: &[u8]) -> i32 {
    i32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

#[test]
fn tcp_bus_conversation_with_lockstep() {
    let (mut c, h) = Client::connect(kin());
    c.time(0);
    // PING every device.
    let expect: Vec<(u8, u16)> = (1..=12)
        .map(|id| (id, x_series::MODEL_XM430_W350))
        .chain([
            (111, foot::MODEL_NUMBER_VALUE),
            (112, foot::MODEL_NUMBER_VALUE),
            (200, imu::MODEL_NUMBER_VALUE),
        ])
        .collect();
    for &(id, model) in &expect {
        let st = statuses(&c.send(&ping(id)));
        assert_eq!(st.len(), 1);
        assert_eq!(st[0].0, id);
        assert_eq!(u16::from_le_bytes([st[0].2[0], st[0].2[1]]), model);
    }
    // Nobody at ID 50: zero bytes.
    assert!(c.send(&ping(50)).is_empty());
    // Broadcast PING: everyone, in ID order.
    let st = statuses(&c.send(&ping(BROADCAST_ID)));
    assert_eq!(
        st.iter().map(|s| s.0).collect::<Vec<_>>(),
        expect.iter().map(|e| e.0).collect::<Vec<_>>()
    );
    // WRITE Return Delay Time, READ it back.
    let rdt = Instruction::Write {
        addr: x_series::RETURN_DELAY_TIME.addr,
        data: &[5],
    };
    let st = statuses(&c.send(&packet(3, rdt)));
    let mut buf = [0u8; 256];
    assert_eq!((st[0].0, st[0].1), (3, 0));
    assert_eq!(c.read(3, x_series::RETURN_DELAY_TIME.addr, 1), vec![5]);
    // Torque on for every servo (broadcast SYNC WRITE: no reply, ack 0).
    let on: Vec<(u8, &[u8])> = (1..=12u8).map(|id| (id, &[1u8][..])).collect();
    let n = encode_sync_write(&mut buf, x_series::TORQUE_ENABLE.addr, 1, &on).unwrap();
    assert!(c.send(&buf[..n]).is_empty());
    // Goal: left hip yaw (ID 1) +100 ticks.
    let goal = (2048 + 100i32).to_le_bytes();
    let n =
        encode_sync_write(&mut buf, x_series::GOAL_POSITION.addr, 4, &[(1, &goal[..])]).unwrap();
    assert!(c.send(&buf[..n]).is_empty());
    // 10 ms later: moved, by at most 4.8 rad/s · 10 ms = 31.3 ticks.
    c.time(10_000);
    let p = i32_of(&c.read(1, x_series::PRESENT_POSITION.addr, 4));
    assert!(p > 2048 && p <= 2048 + 32, "present {p}");
    let v = i32_of(&c.read(1, x_series::PRESENT_VELOCITY.addr, 4));
    assert!(
        v > 0 && f64::from(v) * 0.229 * std::f64::consts::TAU / 60.0 <= 4.8 + 0.03,
        "velocity {v}"
    );
    // Time does not run without the lock-step channel saying so.
    assert_eq!(i32_of(&c.read(1, x_series::PRESENT_POSITION.addr, 4)), p);
    c.time(300_000);
    let p = i32_of(&c.read(1, x_series::PRESENT_POSITION.addr, 4));
    assert!((p - 2148).abs() <= 1, "present {p}");
    // SYNC READ of all twelve present positions: 12 status packets, counted exactly.
    let ids: Vec<u8> = (1..=12).collect();
    let n = Instruction::SyncRead {
        addr: x_series::PRESENT_POSITION.addr,
        len: 4,
        ids: &ids,
    }
    .encode(&mut buf, BROADCAST_ID)
    .unwrap();
    let r = c.send(&buf[..n]);
    let st = statuses(&r);
    assert_eq!(st.len(), 12);
    assert_eq!(r.len(), 12 * 15);
    // BULK READ the sensors.
    let n = encode_bulk_read(
        &mut buf,
        &[foot_request(111), foot_request(112), imu_request()],
    )
    .unwrap();
    let st = statuses(&c.send(&buf[..n]));
    assert_eq!(
        st.iter().map(|s| s.0).collect::<Vec<_>>(),
        vec![111, 112, 200]
    );
    let total: f32 = st[..2]
        .iter()
        .map(|s| FootForces::from_bytes(&s.2).unwrap().total_n())
        .sum();
    assert!(
        (f64::from(total) - TOTAL_MASS * G).abs() < 0.05,
        "total {total}"
    );
    // FAST SYNC READ: one combined packet.
    let n = Instruction::FastSyncRead {
        addr: x_series::PRESENT_POSITION.addr,
        len: 4,
        ids: &[1, 2, 3],
    }
    .encode(&mut buf, BROADCAST_ID)
    .unwrap();
    let r = c.send(&buf[..n]);
    let mut dec = Decoder::<256>::new();
    dec.set_stuffing(false);
    let (_, ev) = dec.feed(&r);
    let pkt = ev.unwrap().unwrap();
    let parts: Vec<_> = dxl::FastSyncParts::parse(&pkt, 4).unwrap().collect();
    assert_eq!(
        parts.iter().map(|p| p.id).collect::<Vec<_>>(),
        vec![1, 2, 3]
    );
    assert!((i32_of(parts[0].data) - 2148).abs() <= 1);
    // An unknown instruction gets the Instruction error.
    let n = dxl::encode(&mut buf, 2, 0x40, &[]).unwrap();
    let st = statuses(&c.send(&buf[..n]));
    assert_eq!(st[0].1, 2);
    // A status packet on the bus is not an instruction: no ack; the next PING is acked normally.
    let n = dxl::instruction::encode_status(&mut buf, 1, dxl::StatusError::OK, &[]).unwrap();
    assert_eq!(buf[7], opcode::STATUS);
    c.bus.write_all(&buf[..n]).unwrap();
    assert_eq!(statuses(&c.send(&ping(7))).len(), 1);
    // A bad CRC: no reply, announced as 0 bytes.
    let mut bad = ping(7);
    let last = bad.len() - 1;
    bad[last] ^= 0x55;
    assert!(c.send(&bad).is_empty());
    // Nothing beyond the announced bytes was written.
    c.bus
        .set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let mut extra = [0u8; 1];
    assert!(c.bus.read(&mut extra).is_err());
    drop(c);
    let s = h.join().unwrap();
    assert_eq!(s.sim_time_us, 300_000);
    assert_eq!(s.lockstep_messages, 3);
    assert_eq!(s.lockstep_errors, 0);
}

/// A lock-step master on the simulator's pipes (`SimConfig::lockstep_pipe`), as the QEMU board
/// with `lockstep=PREFIX` is.
struct PipeClient {
    to_sim: std::fs::File,
    to_fw: std::fs::File,
    log: Vec<u8>,
}

impl PipeClient {
    fn connect(cfg: SimConfig, name: &str) -> (PipeClient, walker_host::sim::SimHandle) {
        let prefix =
            std::env::temp_dir().join(format!("walker-sim-test-{}-{name}", std::process::id()));
        let h = spawn(SimConfig {
            lockstep_pipe: Some(prefix.clone()),
            ..cfg
        })
        .unwrap();
        assert!(h.bus_addr().is_none());
        let path = |s: &str| {
            let mut p = prefix.as_os_str().to_owned();
            p.push(s);
            std::path::PathBuf::from(p)
        };
        // The board's order: its write end, then its read end.
        let to_sim = std::fs::OpenOptions::new()
            .write(true)
            .open(path("-to-sim"))
            .unwrap();
        let to_fw = std::fs::File::open(path("-to-fw")).unwrap();
        (
            PipeClient {
                to_sim,
                to_fw,
                log: Vec::new(),
            },
            h,
        )
    }
}

/// What a lock-step session needs of its master.
trait LockstepMaster {
    /// Sends a time frame.
    fn time(&mut self, t_us: u64);
    /// Sends one instruction; returns its announced reply bytes, logging announcement and reply.
    fn send(&mut self, pkt: &[u8]) -> Vec<u8>;
    /// The announcements and replies so far.
    fn take_log(&mut self) -> Vec<u8>;
}

impl LockstepMaster for Client {
    fn time(&mut self, t_us: u64) {
        Client::time(self, t_us)
    }
    fn send(&mut self, pkt: &[u8]) -> Vec<u8> {
        Client::send(self, pkt)
    }
    fn take_log(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.log)
    }
}

impl LockstepMaster for PipeClient {
    fn time(&mut self, t_us: u64) {
        let mut m = vec![0x5A];
        m.extend_from_slice(&t_us.to_le_bytes());
        self.to_sim.write_all(&m).unwrap();
    }
    fn send(&mut self, pkt: &[u8]) -> Vec<u8> {
        let mut m = vec![0x50];
        m.extend_from_slice(&(pkt.len() as u16).to_le_bytes());
        m.extend_from_slice(pkt);
        self.to_sim.write_all(&m).unwrap();
        // Announcement and reply on the one pipe (`Read` for `&File`).
        let (mut ann, mut data) = (&self.to_fw, &self.to_fw);
        announced_reply(&mut ann, &mut data, &mut self.log)
    }
    fn take_log(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.log)
    }
}

fn session_config(seed: u64) -> SimConfig {
    let mut cfg = SimConfig { seed, ..kin() };
    cfg.faults.p_drop = 0.1;
    cfg.faults.p_corrupt = 0.1;
    cfg.noise.force_std_n = 0.2;
    cfg.noise.accel_std_m_s2 = 0.05;
    cfg
}

fn tcp_session(seed: u64) -> Vec<u8> {
    let (c, h) = Client::connect(session_config(seed));
    let log = session(c);
    let s = h.join().unwrap();
    assert_eq!(s.lockstep_messages, 201);
    log
}

/// The session of [`tcp_session`] on the pipes: (announcements and replies, the summary).
fn pipe_session(seed: u64, name: &str) -> (Vec<u8>, walker_host::sim::SimSummary) {
    let (c, h) = PipeClient::connect(session_config(seed), name);
    let log = session(c);
    (log, h.join().unwrap())
}

/// Torque on, then 100 rounds of a goal SYNC WRITE and a BULK READ 10 ms apart; the master is
/// dropped at the end (its end of the connection closed).
fn session(mut c: impl LockstepMaster) -> Vec<u8> {
    let mut buf = [0u8; 128];
    let on: Vec<(u8, &[u8])> = (1..=12u8).map(|id| (id, &[1u8][..])).collect();
    c.time(0);
    let n = encode_sync_write(&mut buf, x_series::TORQUE_ENABLE.addr, 1, &on).unwrap();
    c.send(&buf[..n]);
    for k in 1..=100u64 {
        c.time(k * 10_000);
        let g = (2048 + (k as i32 % 20) * 5).to_le_bytes();
        let n = encode_sync_write(
            &mut buf,
            x_series::GOAL_POSITION.addr,
            4,
            &[(3, &g[..]), (9, &g[..])],
        )
        .unwrap();
        c.send(&buf[..n]);
        c.time(k * 10_000 + 300);
        let n = encode_bulk_read(
            &mut buf,
            &[
                BulkReadRequest {
                    id: 3,
                    addr: x_series::PRESENT_POSITION.addr,
                    len: 4,
                },
                foot_request(111),
                imu_request(),
            ],
        )
        .unwrap();
        c.send(&buf[..n]);
    }
    c.take_log()
}

#[test]
fn pipe_runs_answer_as_tcp_runs_do() {
    let tcp = tcp_session(99);
    let (pipes, summary) = pipe_session(99, "a");
    assert!(pipes.len() > 1000);
    assert_eq!(pipes, tcp);
    assert!(summary.lockstep);
    assert_eq!(summary.lockstep_messages, 201);
    assert_eq!(summary.lockstep_errors, 0);
    // The last time frame is 1.0003 s: whole 1 ms physics steps up to it.
    assert_eq!(summary.sim_time_us, 1_000_000);
    // The simulator removed the pipes' names once the master had opened them.
    let left = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with(&format!("walker-sim-test-{}-a", std::process::id()))
        })
        .count();
    assert_eq!(left, 0);
    assert_ne!(pipe_session(100, "b").0, pipes);
}

#[test]
fn tcp_runs_are_deterministic() {
    let a = tcp_session(99);
    let b = tcp_session(99);
    assert!(a.len() > 1000);
    assert_eq!(a, b);
    assert_ne!(a, tcp_session(100));
}

/// Writes goal angles (rad) of all 12 joints with one SYNC WRITE (torque assumed on).
fn set_goals(sim: &mut Simulator, q: &[f64; 12]) {
    let data: Vec<[u8; 4]> = q
        .iter()
        .map(|&a| TickMap::reference().tick_f64(0, a).to_le_bytes())
        .collect();
    let entries: Vec<(u8, &[u8])> = (0..12).map(|j| (j as u8 + 1, &data[j][..])).collect();
    let mut buf = [0u8; 128];
    let n = encode_sync_write(&mut buf, x_series::GOAL_POSITION.addr, 4, &entries).unwrap();
    assert_eq!(sim.feed(&buf[..n]), vec![Vec::<u8>::new()]);
}

fn torque_on(sim: &mut Simulator) {
    let on: Vec<(u8, &[u8])> = (1..=12u8).map(|id| (id, &[1u8][..])).collect();
    let mut buf = [0u8; 64];
    let n = encode_sync_write(&mut buf, x_series::TORQUE_ENABLE.addr, 1, &on).unwrap();
    sim.feed(&buf[..n]);
}

#[test]
fn lateral_sway_zmp_follows_cart_table() {
    // Parallelogram sway: hip roll θ, ankle roll −θ on both legs: the pelvis stays upright and
    // moves sideways by ≈ 0.2·sin θ. Cart-table check: ZMP_y ≈ y_com − (z/g)·ÿ_com.
    // Goals every 10 ms.
    let mut sim = Simulator::new(&kin()).unwrap();
    torque_on(&mut sim);
    let mut rows = Vec::new();
    for k in 0..2000u64 {
        let t = k as f64 * 1e-3;
        if k % 10 == 0 {
            let th = 0.1 * (std::f64::consts::TAU * 1.5 * t).sin();
            let mut q = [0.0; 12];
            q[1] = th;
            q[5] = -th;
            q[7] = th;
            q[11] = -th;
            set_goals(&mut sim, &q);
        }
        sim.advance_to((k + 1) * 1000).unwrap();
        let tr = *sim.physics.truth();
        rows.push((tr.zmp[1], tr.com[1], tr.com[2], tr.support, tr.pelvis_rpy));
        if (560..600).contains(&k) {
            eprintln!(
                "k {k} t {} py {:.6} pz {:.6} stance {} zmp {:.4} fz {:.3}",
                tr.t_us, tr.pelvis[1], tr.pelvis[2], tr.stance_left, tr.zmp[1], tr.fz
            );
        }
    }
    assert!(rows.iter().all(|r| r.3 == Support::Double));
    assert!(rows.iter().all(|r| r.4[0].abs() < 1e-6));
    let amp = rows.iter().map(|r| r.1.abs()).fold(0.0, f64::max);
    assert!(amp > 0.012 && amp < 0.025, "CoM sway amplitude {amp}");
    // Compare over the steady part with 10 ms central differences of the CoM. Such a difference
    // is the CoM acceleration averaged with the triangular kernel (11 − |k|)/121 over ±10 ms, and
    // the ZMP is linear in the accelerations: average the (instantaneous) true ZMP alike. Unaveraged
    // it also holds the servos' response to every 10 ms goal step, which the difference cannot see.
    let (mut err2, mut dev2) = (0.0, 0.0);
    for i in 500..1990 {
        let acc = (rows[i + 10].1 - 2.0 * rows[i].1 + rows[i - 10].1) / 1e-4;
        let pred = rows[i].1 - rows[i].2 / G * acc;
        let zmp: f64 = (0..21)
            .map(|k| (11.0 - (k as f64 - 10.0).abs()) / 121.0 * rows[i + k - 10].0)
            .sum();
        err2 += (zmp - pred).powi(2);
        dev2 += (rows[i].0 - rows[i].1).powi(2);
    }
    let rel = (err2 / dev2).sqrt();
    assert!(rel < 0.35, "relative error {rel}");
    assert!(
        dev2.sqrt() / 1490f64.sqrt() > 0.002,
        "the dynamics must matter"
    );
}

#[test]
fn stepping_switches_support_without_jumps() {
    // Shift the weight over the right foot, lift the left foot, put it down, shift back.
    let mut cfg = kin();
    cfg.fall.enabled = false;
    let mut sim = Simulator::new(&cfg).unwrap();
    torque_on(&mut sim);
    let mut supports = Vec::new();
    let mut last_pelvis: Option<[f64; 3]> = None;
    let mut max_jump: f64 = 0.0;
    for k in 0..3000u64 {
        let t = k as f64 * 1e-3;
        if k % 10 == 0 {
            // Sway right (positive hip roll shifts the pelvis right), then lift the left leg.
            let th = 0.2 * (std::f64::consts::PI * (t / 3.0)).sin().powi(2);
            let lift = 0.3 * (std::f64::consts::PI * ((t - 1.0) / 1.0).clamp(0.0, 1.0)).sin();
            set_goals(&mut sim, &sway_and_lift_by(th, lift));
        }
        sim.advance_to((k + 1) * 1000).unwrap();
        let tr = *sim.physics.truth();
        if let Some(p) = last_pelvis {
            let d = ((tr.pelvis[0] - p[0]).powi(2)
                + (tr.pelvis[1] - p[1]).powi(2)
                + (tr.pelvis[2] - p[2]).powi(2))
            .sqrt();
            max_jump = max_jump.max(d);
        }
        last_pelvis = Some(tr.pelvis);
        if supports.last() != Some(&tr.support) {
            supports.push(tr.support);
        }
    }
    assert_eq!(
        supports,
        vec![Support::Double, Support::Right, Support::Double],
        "{supports:?}"
    );
    // 1 ms steps, speeds below 1 m/s: no teleporting at the switches.
    assert!(max_jump < 1e-3, "pelvis jump {max_jump}");
}

#[test]
fn zmp_outside_support_starts_a_fall() {
    // Lift the left leg without shifting the weight: the CoM is outside the right sole.
    let mut sim = Simulator::new(&kin()).unwrap();
    torque_on(&mut sim);
    // Ramp the goals so that the three pitch joints move together (the foot stays flat).
    for k in 1..=20u64 {
        let a = 0.4 * k as f64 / 20.0;
        let mut q = [0.0; 12];
        q[2] = -a;
        q[3] = 2.0 * a;
        q[4] = -a;
        set_goals(&mut sim, &q);
        sim.advance_to(k * 10_000).unwrap();
        if sim.summary().fall_started_us.is_some() {
            break;
        }
    }
    let t = *sim.physics.truth();
    assert_eq!(t.support, Support::Right);
    assert!(t.pelvis_rpy[1].abs() < 0.05);
    sim.advance_to(2_000_000).unwrap();
    let s = sim.summary();
    let start = s.fall_started_us.expect("a fall");
    assert!(start < 300_000, "fall at {start}");
    assert!(s.fallen_at_us.is_some());
    // Falls to the left (the unsupported side): body y axis tips toward gravity.
    let d = sim.bus.device(200).unwrap();
    let imu_s = ImuSample::from_bytes(d.read(imu::SAMPLE.addr, imu::SAMPLE.len).unwrap()).unwrap();
    let t = *sim.physics.truth();
    assert!(
        imu_s.accel_m_s2()[1] < -8.0,
        "{:?} {:?} {:?} {:?}",
        imu_s.accel_m_s2(),
        t.pelvis,
        t.com,
        t.pelvis_rpy
    );
}

/// Reads one reply announcement (`0xA5`, u16 LE count) from `ann` and the reply's bytes from
/// `data`, both noted in `log`; the reply.
fn announced_reply(ann: &mut impl Read, data: &mut impl Read, log: &mut Vec<u8>) -> Vec<u8> {
    let mut ack = [0u8; 3];
    ann.read_exact(&mut ack).unwrap();
    assert_eq!(ack[0], 0xA5);
    let n = usize::from(u16::from_le_bytes([ack[1], ack[2]]));
    let mut reply = vec![0u8; n];
    data.read_exact(&mut reply).unwrap();
    log.extend_from_slice(&ack);
    log.extend_from_slice(&reply);
    reply
}

fn read_statuses(bus: &mut TcpStream, count: usize) -> Vec<(u8, u8, Vec<u8>)> {
    let mut dec = Decoder::<1024>::new();
    let mut out = Vec::new();
    let mut b = [0u8; 1];
    while out.len() < count {
        bus.read_exact(&mut b).unwrap();
        if let Some(Ok(p)) = dec.push(b[0]) {
            let s = Status::from_packet(&p).unwrap();
            out.push((s.id, s.error.to_byte(), s.data.to_vec()));
        }
    }
    out
}

#[test]
fn free_running_follows_wall_clock() {
    let h = spawn(SimConfig { port: 0, ..kin() }).unwrap();
    let mut bus = TcpStream::connect(h.bus_addr().unwrap()).unwrap();
    bus.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    bus.write_all(&ping(12)).unwrap();
    assert_eq!(read_statuses(&mut bus, 1)[0].0, 12);
    let torque_on = Instruction::Write {
        addr: x_series::TORQUE_ENABLE.addr,
        data: &[1],
    };
    bus.write_all(&packet(5, torque_on)).unwrap();
    read_statuses(&mut bus, 1);
    let goal = Instruction::Write {
        addr: x_series::GOAL_POSITION.addr,
        data: &2100i32.to_le_bytes(),
    };
    bus.write_all(&packet(5, goal)).unwrap();
    read_statuses(&mut bus, 1);
    std::thread::sleep(Duration::from_millis(200));
    let present = Instruction::Read {
        addr: x_series::PRESENT_POSITION.addr,
        len: 4,
    };
    bus.write_all(&packet(5, present)).unwrap();
    let st = read_statuses(&mut bus, 1);
    assert!((i32_of(&st[0].2) - 2100).abs() <= 1);
    let progress = h.progress();
    drop(bus);
    let s = h.join().unwrap();
    assert!(s.sim_time_us >= 200_000 && !s.lockstep);
    assert_eq!(
        progress
            .instructions
            .load(std::sync::atomic::Ordering::Relaxed),
        4
    );
}

#[test]
fn connect_mode_reaches_a_listening_master() {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    let h = spawn(SimConfig {
        port,
        connect: true,
        ..kin()
    })
    .unwrap();
    let (mut bus, _) = l.accept().unwrap();
    bus.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    bus.write_all(&ping(200)).unwrap();
    let st = read_statuses(&mut bus, 1);
    assert_eq!(
        u16::from_le_bytes([st[0].2[0], st[0].2[1]]),
        imu::MODEL_NUMBER_VALUE
    );
    drop(bus);
    h.join().unwrap();
}

#[test]
fn stop_while_waiting_for_a_connection() {
    let h = spawn(SimConfig { port: 0, ..kin() }).unwrap();
    h.stop();
    assert!(matches!(
        h.join(),
        Err(walker_host::sim::SimError::Timeout(_))
    ));
}

/// Minimum-jerk blend (the firmware's start-up ramp profile).
fn min_jerk(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
}

#[test]
fn servo_follows_a_goal_step_smoothly() {
    // A 100-tick step on the left hip yaw: the critically damped second-order response
    // Δ·(1 − (1 + ωt)·e^(−ωt)), starting from rest (no velocity jump), |q̈| ≤ ω²·Δ.
    let cfg = kin();
    let w = std::f64::consts::TAU * cfg.servo_frequency_hz;
    let mut sim = Simulator::new(&cfg).unwrap();
    torque_on(&mut sim);
    let mut q = [0.0; 12];
    q[0] = TickMap::reference().rad_f64(0, 2148);
    set_goals(&mut sim, &q);
    let d = q[0];
    let mut prev_v = 0.0;
    for k in 1..=300u64 {
        sim.advance_to(k * 1000).unwrap();
        let t = k as f64 * 1e-3;
        let expect = d * (1.0 - (1.0 + w * t) * (-w * t).exp());
        let (qj, vj, aj) = (
            sim.physics.q()[0],
            sim.physics.qd()[0],
            sim.physics.kinematic().unwrap().qdd[0],
        );
        assert!((qj - expect).abs() < 0.01 * d, "t {t}: {qj} vs {expect}");
        assert!(vj.abs() <= cfg.servo_speed_limit + 1e-12);
        assert!(aj.abs() <= w * w * d * 1.0001, "t {t}: q̈ {aj}");
        // Velocity changes by at most the largest acceleration times the step.
        assert!(
            (vj - prev_v).abs() <= w * w * d * 1e-3 * 1.0001,
            "t {t}: velocity jump"
        );
        prev_v = vj;
    }
    assert!((sim.physics.q()[0] - d).abs() < 1e-3 * d);
}

#[test]
fn tick_staircase_crouch_keeps_zmp_near_com() {
    // The firmware's start-up: a 1.5 s minimum-jerk crouch written every 5 ms as whole servo
    // ticks. Hip and ankle pitch round together, the knee (twice the angle) on other ticks, so
    // the pelvis pitch follows a ±1-tick (1.5 mrad) staircase of rounding errors. A first-order
    // servo lag turns every goal change into a velocity jump and the true ZMP swings at the tick
    // rate; a continuous-velocity servo leaves only a small ripple.
    let cfg = kin();
    let mut sim = Simulator::new(&cfg).unwrap();
    torque_on(&mut sim);
    let knee = TickMap::reference().rad_f64(0, 2521);
    let mut rows = Vec::new();
    for k in 0..1600u64 {
        if k % 5 == 0 {
            let s = min_jerk((k / 5 + 1) as f64 / 300.0);
            let mut q = [0.0; 12];
            for o in [0, 6] {
                q[o + 2] = -0.5 * knee * s;
                q[o + 3] = knee * s;
                q[o + 4] = -0.5 * knee * s;
            }
            set_goals(&mut sim, &q);
        }
        sim.advance_to((k + 1) * 1000).unwrap();
        let tr = *sim.physics.truth();
        // The truth describes the present instant (no finite-difference lag).
        assert_eq!(tr.t_us, (k + 1) * 1000);
        assert_eq!(tr.support, Support::Double);
        rows.push(tr);
    }
    let (mut max_d, mut sum2) = (0.0f64, 0.0);
    for tr in &rows[100..1450] {
        let d = tr.zmp[0] - tr.com[0];
        max_d = max_d.max(d.abs());
        sum2 += d * d;
        // At most the one-tick rounding error (1.53 mrad) of the pitch-joint sum.
        assert!(
            tr.pelvis_rpy[1].abs() < 1.6e-3,
            "pitch {}",
            tr.pelvis_rpy[1]
        );
    }
    let rms = (sum2 / 1350.0).sqrt();
    eprintln!("ZMP − CoM max {max_d} RMS {rms}");
    assert!(
        max_d < 0.025 && rms < 0.01,
        "ZMP − CoM max {max_d} RMS {rms}"
    );
    // The crouch happened (the CoM went down by 9.5 mm), and at rest the ZMP is the CoM.
    let drop = rows[0].com[2] - rows[1599].com[2];
    assert!(drop > 0.009, "CoM drop {drop}");
    let last = rows[1599];
    assert!((last.zmp[0] - last.com[0]).abs() < 1e-4);
    // The analytic accelerations agree with differences of the positions: the IMU's specific
    // force (upper-body frame, pitch p, no roll or yaw) against 1 ms second differences of P,
    // away from the goal changes (where the servo acceleration steps).
    let mut worst = 0.0f64;
    for i in 100..1450 {
        if i % 5 == 4 || i % 5 == 0 {
            continue;
        }
        let (a, b, c) = (&rows[i - 1], &rows[i], &rows[i + 1]);
        let fd = [0, 2].map(|k| (c.pelvis[k] - 2.0 * b.pelvis[k] + a.pelvis[k]) / 1e-6);
        let (s, co) = b.pelvis_rpy[1].sin_cos();
        let ax = co * b.accel[0] + s * b.accel[2];
        let az = -s * b.accel[0] + co * b.accel[2] - G;
        worst = worst.max((ax - fd[0]).abs()).max((az - fd[1]).abs());
    }
    eprintln!("IMU vs differences {worst} m/s²");
    assert!(worst < 2e-3, "IMU vs differences {worst} m/s²");
}

/// Drives the simulator at 1 ms steps through `secs` seconds of goals `goal(t)` (sent every 10 ms).
fn drive(sim: &mut Simulator, from_s: f64, secs: f64, goal: impl Fn(f64) -> [f64; 12]) {
    let k0 = (from_s * 1000.0).round() as u64;
    for k in k0..k0 + (secs * 1000.0).round() as u64 {
        if k % 10 == 0 {
            set_goals(sim, &goal(k as f64 * 1e-3));
        }
        sim.advance_to((k + 1) * 1000).unwrap();
    }
}

/// Sway the pelvis over the right foot (parallel legs: hip roll θ, ankle roll −θ), then lift the
/// left foot by bending its knee: the goals at time `t` (s).
fn sway_and_lift(t: f64) -> [f64; 12] {
    sway_and_lift_by(0.2 * min_jerk(t), 0.3 * min_jerk(t - 1.0))
}

/// The goals of a sway by hip/ankle roll `th` (rad) with the left knee lifted by `lift` (rad).
fn sway_and_lift_by(th: f64, lift: f64) -> [f64; 12] {
    let mut q = [0.0; 12];
    q[1] = th;
    q[5] = -th;
    q[7] = th;
    q[11] = -th;
    q[2] = -lift;
    q[3] = 2.0 * lift;
    q[4] = -lift;
    q
}

/// The robot standing still on its right foot, left foot lifted (`sway_and_lift` held).
fn standing_on_right_foot(cfg: &SimConfig) -> Simulator {
    let mut sim = Simulator::new(cfg).unwrap();
    torque_on(&mut sim);
    drive(&mut sim, 0.0, 3.5, sway_and_lift);
    sim
}

#[test]
fn static_torques_match_moment_balance() {
    // Standing still on the right foot, each motor carries the gravity moment of the links on
    // the far side of its joint from the ground, summed here by hand from the mass points:
    // |τ| = |Σ mᵢ·g·(lever arm of mᵢ about the joint axis)|.
    let mut cfg = kin();
    cfg.fall.enabled = false;
    let sim = standing_on_right_foot(&cfg);
    let tr = *sim.physics.truth();
    assert_eq!(tr.support, Support::Right);
    assert!(
        tr.margin > 0.005,
        "the ZMP is inside the right sole: {}",
        tr.margin
    );
    assert!(tr.joint_speed.iter().all(|v| v.abs() < 1e-3), "at rest");
    let robot = Robot::reference();
    let m = robot.masses;
    let pelvis = pelvis_pose(&tr);
    assert!(tr.pelvis_rpy[0].abs() < 0.01 && tr.pelvis_rpy[1].abs() < 0.01);
    let q = sim.physics.q();
    let left = leg_points(&robot, Side::Left, &pelvis, &q[..6].try_into().unwrap());
    let right = leg_points(&robot, Side::Right, &pelvis, &q[6..].try_into().unwrap());
    let upper = [
        tr.pelvis[0],
        tr.pelvis[1],
        tr.pelvis[2] + m.upper_body_height,
    ];
    let swing = [
        (m.thigh, left.thigh_mass),
        (m.calf, left.calf_mass),
        (m.sole, left.sole_mass),
    ];
    let mut above_stance_hip = swing.to_vec();
    above_stance_hip.push((m.upper_body, upper));
    let mut above_stance_ankle = above_stance_hip.clone();
    above_stance_ankle.push((m.thigh, right.thigh_mass));
    above_stance_ankle.push((m.calf, right.calf_mass));
    // Moment of gravity about an axis along x (roll) or y (pitch) through `p`.
    let g = robot.gravity;
    let roll = |pts: &[(f64, [f64; 3])], p: [f64; 3]| -> f64 {
        pts.iter().map(|(mi, r)| mi * g * (r[1] - p[1])).sum()
    };
    let pitch = |pts: &[(f64, [f64; 3])], p: [f64; 3]| -> f64 {
        pts.iter().map(|(mi, r)| mi * g * (r[0] - p[0])).sum()
    };
    let cases = [
        (
            "right ankle roll",
            11,
            roll(&above_stance_ankle, right.ankle),
        ),
        (
            "right ankle pitch",
            10,
            pitch(&above_stance_ankle, right.ankle),
        ),
        ("right hip roll", 7, roll(&above_stance_hip, right.hip)),
        ("left hip roll", 1, roll(&swing, left.hip)),
    ];
    for (name, j, expect) in cases {
        let got = tr.joint_torque[j];
        assert!(
            (got.abs() - expect.abs()).abs() < 0.01 * expect.abs() + 0.01,
            "{name}: simulator {got:.4} N·m, moment balance {expect:.4} N·m"
        );
    }
    // The stance hip roll carries the upper body and the swing leg: a real load, not ≈ 0.
    assert!(tr.joint_torque[7].abs() > 1.5);
    assert_eq!(tr.torque_limited, 0, "an XM430 holds this pose");
}

#[test]
fn weak_servos_sag_under_load() {
    // The same motion with 1 N·m servos: the stance hip roll needs ≈ 2.4 N·m once the left foot
    // is off the ground, so it sits at its bound and the joint sags away from its goal until the
    // pelvis has rolled far enough for the lifted foot to land again; XM430-class servos hold
    // the one-foot stance.
    let mut cfg = kin();
    cfg.fall.enabled = false;
    let strong = standing_on_right_foot(&cfg);
    let goal = sway_and_lift(3.5);
    assert!((strong.physics.q()[7] - goal[7]).abs() < 0.01);
    assert_eq!(strong.physics.truth().support, Support::Right);
    let weak_servo = ServoTorque {
        stall_torque: 1.0,
        ..ServoTorque::XM430
    };
    cfg.servo_torque = Some(weak_servo);
    let mut weak = Simulator::new(&cfg).unwrap();
    torque_on(&mut weak);
    let mut worst: f64 = 0.0;
    let mut hip_at_bound = false;
    for k in 0..3500u64 {
        if k % 10 == 0 {
            set_goals(&mut weak, &sway_and_lift(k as f64 * 1e-3));
        }
        weak.advance_to((k + 1) * 1000).unwrap();
        let tr = weak.physics.truth();
        for (j, t) in tr.joint_torque.iter().enumerate() {
            let (lo, hi) = weak_servo.range(tr.joint_speed[j]);
            // The torque line is frozen within a step: allow what one step's speed change moves.
            assert!(
                *t >= lo - 0.05 && *t <= hi + 0.05,
                "joint {j}: {t} not in [{lo}, {hi}]"
            );
        }
        worst = worst.max((weak.physics.q()[7] - sway_and_lift(k as f64 * 1e-3)[7]).abs());
        hip_at_bound |= tr.torque_limited & (1 << 7) != 0;
    }
    assert!(hip_at_bound, "the stance hip roll never reached its bound");
    assert_eq!(
        weak.physics.truth().support,
        Support::Double,
        "the lifted foot came down"
    );
    assert!(worst > 0.05, "the hip roll sagged only {worst} rad");
}

#[test]
fn slack_torque_limits_change_nothing() {
    // Servos far stronger than any load, and no rotor inertia: the motion is the servo loop's
    // own, step for step, as without the torque model.
    let a_cfg = SimConfig {
        servo_torque: None,
        ..kin()
    };
    let mut b_cfg = a_cfg.clone();
    b_cfg.servo_torque = Some(ServoTorque {
        stall_torque: 1e6,
        no_load_speed: 1e6,
        armature: 0.0,
    });
    let (mut a, mut b) = (
        Simulator::new(&a_cfg).unwrap(),
        Simulator::new(&b_cfg).unwrap(),
    );
    torque_on(&mut a);
    torque_on(&mut b);
    drive(&mut a, 0.0, 2.5, sway_and_lift);
    drive(&mut b, 0.0, 2.5, sway_and_lift);
    for j in 0..12 {
        assert!((a.physics.q()[j] - b.physics.q()[j]).abs() < 1e-9);
    }
    assert!(a.physics.truth().joint_torque.iter().all(|t| t.is_nan()));
    assert!(b.physics.truth().joint_torque.iter().all(|t| t.is_finite()));
}

#[test]
fn a_fast_swing_is_torque_limited_and_keeps_to_the_motor_line() {
    // Standing on the right foot, the left knee is asked to jump 0.6 rad: the loop's wish needs
    // more than the motor gives, so the knee follows slower than without the limit, and the
    // applied torque stays inside the torque–speed range.
    let mut cfg = kin();
    cfg.fall.enabled = false;
    let mut limited = standing_on_right_foot(&cfg);
    cfg.servo_torque = None;
    let mut free = standing_on_right_foot(&cfg);
    let mut goal = sway_and_lift(3.5);
    goal[3] += 0.6;
    set_goals(&mut limited, &goal);
    set_goals(&mut free, &goal);
    let model = ServoTorque::XM430;
    let mut saw_limit = false;
    let mut lag: f64 = 0.0;
    for k in 3500..3800u64 {
        limited.advance_to((k + 1) * 1000).unwrap();
        free.advance_to((k + 1) * 1000).unwrap();
        let tr = limited.physics.truth();
        let (lo, hi) = model.range(tr.joint_speed[3]);
        let t = tr.joint_torque[3];
        assert!(
            t >= lo - 0.05 && t <= hi + 0.05,
            "knee torque {t} not in [{lo}, {hi}]"
        );
        assert!(tr.joint_speed[3].abs() <= model.no_load_speed + 1e-9);
        saw_limit |= tr.torque_limited & (1 << 3) != 0;
        lag = lag.max(free.physics.q()[3] - limited.physics.q()[3]);
    }
    assert!(saw_limit, "the knee never reached its torque bound");
    assert!(
        lag > 0.01,
        "the torque limit slowed the knee by only {lag} rad"
    );
}

#[test]
fn swinging_knee_torque_is_inertia_times_acceleration_plus_gravity() {
    // Standing on the right foot, only the lifted left knee moves (0.1 rad at 1 Hz): its motor
    // torque must be a rigid pendulum's about the knee axis, derived here from the link points
    // alone: τ = (Σ m·|a × (r − p)|² + I_a)·q̈ + a·Σ (r − p) × m·g·ẑ over the calf and sole
    // masses (p the knee, a its axis oriented so that +q̈ turns the calf about +a).
    let mut cfg = kin();
    cfg.fall.enabled = false;
    let mut sim = standing_on_right_foot(&cfg);
    let robot = Robot::reference();
    let m = robot.masses;
    let g = robot.gravity;
    let base = sway_and_lift(3.5);
    let cross = |u: [f64; 3], v: [f64; 3]| {
        [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ]
    };
    let sub = |u: [f64; 3], v: [f64; 3]| [u[0] - v[0], u[1] - v[1], u[2] - v[2]];
    let dot = |u: [f64; 3], v: [f64; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    let mut checked = 0;
    let mut inertial: f64 = 0.0;
    for k in 3500..5500u64 {
        if k % 10 == 0 {
            let mut q = base;
            q[3] += 0.1 * (std::f64::consts::TAU * (k - 3500) as f64 * 1e-3).sin();
            set_goals(&mut sim, &q);
        }
        sim.advance_to((k + 1) * 1000).unwrap();
        if k < 4000 || k % 50 != 0 {
            continue;
        }
        let tr = *sim.physics.truth();
        assert_eq!(tr.support, Support::Right);
        let pelvis = pelvis_pose(&tr);
        let mut ql: [f64; 6] = sim.physics.q()[..6].try_into().unwrap();
        let lp = leg_points(&robot, Side::Left, &pelvis, &ql);
        let p = lp.knee;
        let mut a = cross(sub(lp.hip, p), sub(lp.ankle, p));
        let n = dot(a, a).sqrt();
        a = a.map(|v| v / n);
        ql[3] += 1e-6;
        let moved = leg_points(&robot, Side::Left, &pelvis, &ql).calf_mass;
        if dot(sub(moved, lp.calf_mass), cross(a, sub(lp.calf_mass, p))) < 0.0 {
            a = a.map(|v| -v);
        }
        let links = [(m.calf, lp.calf_mass), (m.sole, lp.sole_mass)];
        let inertia: f64 = links
            .iter()
            .map(|(mi, r)| {
                let c = cross(a, sub(*r, p));
                mi * dot(c, c)
            })
            .sum::<f64>()
            + ServoTorque::XM430.armature;
        let gravity: f64 = links
            .iter()
            .map(|(mi, r)| dot(a, cross(sub(*r, p), [0.0, 0.0, mi * g])))
            .sum();
        let expect = inertia * sim.physics.kinematic().unwrap().qdd[3] + gravity;
        inertial = inertial.max((inertia * sim.physics.kinematic().unwrap().qdd[3]).abs());
        let got = tr.joint_torque[3];
        assert!(
            (got - expect).abs() < 0.02 * expect.abs() + 0.005,
            "t {:.3}: simulator {got:.4} N·m, pendulum {expect:.4} N·m",
            tr.t_us as f64 * 1e-6
        );
        checked += 1;
    }
    assert!(checked >= 30);
    // The inertia term is well above the tolerance: leaving it out would fail.
    assert!(inertial > 0.025, "inertia term only {inertial} N·m");
}

/// Present Position of joint 1 over 300 ms of a swinging goal, with the true joint angle.
fn present_positions(position_latency_us: u64) -> Vec<(i32, f64)> {
    let mut cfg = kin();
    cfg.fall.enabled = false;
    cfg.noise.position_latency_us = position_latency_us;
    let mut sim = Simulator::new(&cfg).unwrap();
    torque_on(&mut sim);
    let mut rows = Vec::new();
    for k in 0..300u64 {
        let mut q = [0.0; 12];
        q[0] = 0.3 * (std::f64::consts::TAU * 2.0 * k as f64 * 1e-3).sin();
        set_goals(&mut sim, &q);
        sim.advance_to((k + 1) * 1000).unwrap();
        let reported = sim.bus.devices[0].get_i32(x_series::PRESENT_POSITION);
        rows.push((reported, sim.physics.q()[0]));
    }
    rows
}

#[test]
fn present_position_latency_delays_the_reported_angle() {
    let ticks = |q: f64| TickMap::reference().tick_f64(0, q);
    let now = present_positions(0);
    assert!(now.iter().all(|&(r, q)| r == ticks(q)));
    let moved = now.iter().map(|r| r.0).max().unwrap() - now.iter().map(|r| r.0).min().unwrap();
    assert!(moved > 100, "the joint must move: {moved} ticks");
    let late = present_positions(10_000);
    // Same motion (the servo loop sees the joint without delay), reported 10 physics steps late.
    assert_eq!(
        late.iter().map(|r| r.1).collect::<Vec<_>>(),
        now.iter().map(|r| r.1).collect::<Vec<_>>()
    );
    for k in 10..late.len() {
        assert_eq!(late[k].0, ticks(now[k - 10].1), "step {k}");
    }
    assert_eq!(late[0].0, ticks(now[0].1));
}

/// An outage `4:0.05:0.05`: servo 4 answers until 50 ms, not from 50 to 100 ms (nor moves),
/// and after 100 ms again with its torque off (as after a power-on); the other servos as
/// before. The parser takes `ID:FROM_S[:FOR_S]` and refuses anything else.
#[test]
fn a_servo_outage_silences_it_then_brings_it_back_with_torque_off() {
    use walker_host::sim::Outage;
    assert_eq!(
        Outage::parse("4:0.05:0.05"),
        Ok(Outage {
            id: 4,
            from_us: 50_000,
            until_us: Some(100_000)
        })
    );
    assert_eq!(Outage::parse("4:6").map(|o| o.until_us), Ok(None));
    for bad in ["4", "x:1", "4:-1", "4:1:2:3", "4:nan"] {
        assert!(Outage::parse(bad).is_err(), "{bad}");
    }
    let mut cfg = kin();
    cfg.faults.outages = vec![Outage::parse("4:0.05:0.05").unwrap()];
    let mut sim = Simulator::new(&cfg).unwrap();
    let torque_on = Instruction::Write {
        addr: x_series::TORQUE_ENABLE.addr,
        data: &[1],
    };
    let torque = Instruction::Read {
        addr: x_series::TORQUE_ENABLE.addr,
        len: 1,
    };
    for id in [4, 5] {
        assert!(!sim.feed(&packet(id, torque_on))[0].is_empty());
    }
    let answers = |sim: &mut Simulator, id: u8| -> Option<u8> {
        let r = sim.feed(&packet(id, torque));
        let mut d = Decoder::<64>::new();
        let mut data = None;
        for &b in &r[0] {
            if let Some(Ok(p)) = d.push(b) {
                data = Some(Status::from_packet(&p).unwrap().data[0]);
            }
        }
        data
    };
    sim.advance_to(49_000).unwrap();
    assert_eq!(
        (answers(&mut sim, 4), answers(&mut sim, 5)),
        (Some(1), Some(1))
    );
    sim.advance_to(50_000).unwrap();
    assert_eq!(
        (answers(&mut sim, 4), answers(&mut sim, 5)),
        (None, Some(1))
    );
    sim.advance_to(99_000).unwrap();
    assert_eq!(answers(&mut sim, 4), None);
    sim.advance_to(100_000).unwrap();
    assert_eq!(
        (answers(&mut sim, 4), answers(&mut sim, 5)),
        (Some(0), Some(1))
    );
}
