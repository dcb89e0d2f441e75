//! A run as an MCAP file (the `mcap` crate) that Foxglove Studio opens: every channel is JSON
//! with a JSON Schema, times are the firmware's log clock (ns from its boot; the simulator's
//! truth is on the same clock), chunks are uncompressed.
//!
//! Channels (only those whose data the inputs hold are written):
//!
//! | topic | from | message |
//! | --- | --- | --- |
//! | `/zmp/reference` | log | `{x, y}` m |
//! | `/zmp/measured` | log (ticks with a valid measured ZMP) | `{x, y}` m |
//! | `/zmp/true` | truth | `{x, y}` m |
//! | `/com` | log (the model's CoM) | `{x, y}` m |
//! | `/com/true` | truth | `{x, y, z}` m |
//! | `/foot_forces` | truth | `{left: [f0..f3], right: [..], left_fz, right_fz}` N |
//! | `/imu` | truth | `{gyro: {x,y,z}` rad/s`, accel: {x,y,z}` m/s²`}` |
//! | `/torso_pose` | truth (pelvis) | `foxglove.PoseInFrame` (frame `world`) |
//! | `/joints` | truth | `{name[12], velocity[12]` rad/s`, effort[12]` N·m`}` by servo ID |
//! | `/joints/target` | the plan's IK, on the log clock | `{name[12], position[12]` rad`}` |
//! | `/events` | log (start-up, faults, stop) | `{kind, seq, detail}` |
//!
//! Joint positions are not in the log or the truth CSV, hence the targets from the plan.

use crate::report::{event_text, tick_rows, DecodedLog, TruthTable};
use gait_core::robot::{JOINT_NAMES, LEG_JOINTS};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::io::{Seek, Write};

/// The channels the exporter knows, with their JSON Schemas.
pub fn channel_schemas() -> Vec<(&'static str, &'static str, Value)> {
    let num = json!({"type": "number"});
    let xy = json!({"type": "object", "properties": {"x": num, "y": num}});
    let xyz = json!({"type": "object", "properties": {"x": num, "y": num, "z": num}});
    let arr = json!({"type": "array", "items": num});
    let names = json!({"type": "array", "items": {"type": "string"}});
    let time = json!({"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}});
    vec![
        ("/zmp/reference", "walker.Point2", xy.clone()),
        ("/zmp/measured", "walker.Point2", xy.clone()),
        ("/zmp/true", "walker.Point2", xy.clone()),
        ("/com", "walker.Point2", xy),
        ("/com/true", "walker.Point3", xyz.clone()),
        (
            "/foot_forces",
            "walker.FootForces",
            json!({"type": "object", "properties": {
                "left": arr, "right": arr, "left_fz": num, "right_fz": num}}),
        ),
        (
            "/imu",
            "walker.Imu",
            json!({"type": "object", "properties": {"gyro": xyz, "accel": xyz}}),
        ),
        (
            "/torso_pose",
            "foxglove.PoseInFrame",
            json!({"type": "object", "properties": {
                "timestamp": time,
                "frame_id": {"type": "string"},
                "pose": {"type": "object", "properties": {
                    "position": xyz,
                    "orientation": {"type": "object", "properties": {
                        "x": num, "y": num, "z": num, "w": num}}}}}}),
        ),
        (
            "/joints",
            "walker.JointState",
            json!({"type": "object", "properties": {
                "name": names, "velocity": arr, "effort": arr}}),
        ),
        (
            "/joints/target",
            "walker.JointTarget",
            json!({"type": "object", "properties": {"name": names, "position": arr}}),
        ),
        (
            "/events",
            "walker.Event",
            json!({"type": "object", "properties": {
                "kind": {"type": "string"}, "seq": {"type": "integer"},
                "detail": {"type": "string"}}}),
        ),
    ]
}

/// What was written: messages per topic.
pub type ChannelCounts = BTreeMap<String, u64>;

/// A finite number as JSON, else `null` (JSON has no NaN).
fn n(v: f64) -> Value {
    serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)
}

fn ns(t: f64) -> Option<u64> {
    (t.is_finite() && t >= 0.0).then(|| (t * 1e9).round() as u64)
}

/// Roll, pitch, yaw (rad, Z-Y-X) → quaternion (x, y, z, w).
fn quaternion(roll: f64, pitch: f64, yaw: f64) -> [f64; 4] {
    let (sr, cr) = (roll / 2.0).sin_cos();
    let (sp, cp) = (pitch / 2.0).sin_cos();
    let (sy, cy) = (yaw / 2.0).sin_cos();
    [
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ]
}

/// Writes the run as MCAP: the decoded log, the truth (optional) and the plan's joint targets
/// on the log clock (optional: times, angles by servo ID − 1).
pub fn write_mcap<W: Write + Seek>(
    log: &DecodedLog,
    truth: Option<&TruthTable>,
    targets: Option<(&[f64], &[[f64; LEG_JOINTS]])>,
    out: W,
) -> Result<ChannelCounts, String> {
    let e = |e: mcap::McapError| format!("mcap: {e}");
    let mut msgs: Vec<(u64, &'static str, Value)> = Vec::new();
    for r in tick_rows(&log.ticks) {
        let Some(t) = ns(r.t) else { continue };
        if r.zmp_ref.iter().all(|v| v.is_finite()) {
            msgs.push((
                t,
                "/zmp/reference",
                json!({"x": r.zmp_ref[0], "y": r.zmp_ref[1]}),
            ));
        }
        if let Some(m) = r.measured() {
            msgs.push((t, "/zmp/measured", json!({"x": m[0], "y": m[1]})));
        }
        if r.com.iter().all(|v| v.is_finite()) {
            msgs.push((t, "/com", json!({"x": r.com[0], "y": r.com[1]})));
        }
    }
    for ev in &log.events {
        let (seq, t_us, kind, detail) = event_text(ev);
        msgs.push((
            u64::from(t_us) * 1000,
            "/events",
            json!({"kind": kind, "seq": seq, "detail": detail}),
        ));
    }
    if let Some(tr) = truth {
        let col = |name: &str| tr.column(name);
        let cols3 = |a: &str, b: &str, c: &str| Some([col(a)?, col(b)?, col(c)?]);
        let com = cols3("com_x_m", "com_y_m", "com_z_m");
        let gyro = cols3("gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s");
        let acc = cols3("acc_x_m_s2", "acc_y_m_s2", "acc_z_m_s2");
        let pelvis = cols3("pelvis_x_m", "pelvis_y_m", "pelvis_z_m");
        let rpy = cols3("pelvis_roll_rad", "pelvis_pitch_rad", "pelvis_yaw_rad");
        let cells: Option<Vec<&[f64]>> = ["l", "r"]
            .iter()
            .flat_map(|s| (0..4).map(move |k| format!("{s}_f{k}_n")))
            .map(|c| col(&c))
            .collect();
        let (lfz, rfz) = (col("l_fz_n"), col("r_fz_n"));
        let qd: Option<Vec<&[f64]>> = (1..=LEG_JOINTS)
            .map(|i| col(&crate::sim::truth::joint_speed_column(i)))
            .collect();
        let tq: Option<Vec<&[f64]>> = (1..=LEG_JOINTS)
            .map(|i| col(&crate::sim::truth::joint_torque_column(i)))
            .collect();
        for (i, &t_s) in tr.t.iter().enumerate() {
            let Some(t) = ns(t_s) else { continue };
            let z = tr.zmp[i];
            msgs.push((t, "/zmp/true", json!({"x": n(z[0]), "y": n(z[1])})));
            if let Some(c) = com {
                msgs.push((
                    t,
                    "/com/true",
                    json!({"x": n(c[0][i]), "y": n(c[1][i]), "z": n(c[2][i])}),
                ));
            }
            if let Some(f) = &cells {
                let side =
                    |s: usize| -> Vec<Value> { (0..4).map(|k| n(f[4 * s + k][i])).collect() };
                msgs.push((
                    t,
                    "/foot_forces",
                    json!({"left": side(0), "right": side(1),
                           "left_fz": lfz.map_or(Value::Null, |v| n(v[i])),
                           "right_fz": rfz.map_or(Value::Null, |v| n(v[i]))}),
                ));
            }
            if let (Some(g), Some(a)) = (gyro, acc) {
                msgs.push((
                    t,
                    "/imu",
                    json!({"gyro": {"x": n(g[0][i]), "y": n(g[1][i]), "z": n(g[2][i])},
                           "accel": {"x": n(a[0][i]), "y": n(a[1][i]), "z": n(a[2][i])}}),
                ));
            }
            if let (Some(p), Some(r)) = (pelvis, rpy) {
                let q = quaternion(r[0][i], r[1][i], r[2][i]);
                msgs.push((
                    t,
                    "/torso_pose",
                    json!({"timestamp": {"sec": t / 1_000_000_000, "nsec": t % 1_000_000_000},
                           "frame_id": "world",
                           "pose": {"position": {"x": n(p[0][i]), "y": n(p[1][i]), "z": n(p[2][i])},
                                    "orientation": {"x": n(q[0]), "y": n(q[1]), "z": n(q[2]), "w": n(q[3])}}}),
                ));
            }
            if qd.is_some() || tq.is_some() {
                let pick = |c: &Option<Vec<&[f64]>>| -> Vec<Value> {
                    c.as_ref().map_or(vec![Value::Null; LEG_JOINTS], |c| {
                        c.iter().map(|v| n(v[i])).collect()
                    })
                };
                msgs.push((
                    t,
                    "/joints",
                    json!({"name": JOINT_NAMES, "velocity": pick(&qd), "effort": pick(&tq)}),
                ));
            }
        }
    }
    if let Some((tt, q)) = targets {
        for (&t_s, q) in tt.iter().zip(q) {
            let Some(t) = ns(t_s) else { continue };
            let pos: Vec<Value> = q.iter().map(|&v| n(v)).collect();
            msgs.push((
                t,
                "/joints/target",
                json!({"name": JOINT_NAMES, "position": pos}),
            ));
        }
    }
    msgs.sort_by_key(|m| m.0);

    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .profile("")
        .create(out)
        .map_err(e)?;
    let mut ids: BTreeMap<&str, u16> = BTreeMap::new();
    let mut counts = ChannelCounts::new();
    let used: std::collections::BTreeSet<&str> = msgs.iter().map(|m| m.1).collect();
    for (topic, name, schema) in channel_schemas() {
        if !used.contains(topic) {
            continue;
        }
        let sid = w
            .add_schema(name, "jsonschema", schema.to_string().as_bytes())
            .map_err(e)?;
        let cid = w
            .add_channel(sid, topic, "json", &BTreeMap::new())
            .map_err(e)?;
        ids.insert(topic, cid);
    }
    for (t, topic, v) in msgs {
        let c = counts.entry(topic.to_string()).or_insert(0);
        let header = mcap::records::MessageHeader {
            channel_id: ids[topic],
            sequence: *c as u32,
            log_time: t,
            publish_time: t,
        };
        w.write_to_known_channel(&header, v.to_string().as_bytes())
            .map_err(e)?;
        *c += 1;
    }
    w.finish().map_err(e)?;
    Ok(counts)
}

/// Writes the MCAP of a finished report's run to `path`: its log, its truth file (re-read) and
/// the plan's joint targets on the log clock.
pub fn export_run(
    opts: &crate::report::ReportOptions,
    summary: &crate::report::ReportSummary,
    robot: &gait_core::Robot,
    path: &std::path::Path,
) -> Result<ChannelCounts, String> {
    let truth = match &opts.truth {
        Some(p) => Some(crate::report::read_truth(p)?),
        None => None,
    };
    let dt = crate::report::tick_period(&summary.log).clamp(0.001, 0.02);
    let targets =
        crate::report::planned_joint_angles(&summary.spec, robot, dt, summary.alignment.offset);
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).map_err(|e| format!("cannot create {}: {e}", d.display()))?;
    }
    let f = std::fs::File::create(path)
        .map_err(|e| format!("cannot create {}: {e}", path.display()))?;
    write_mcap(
        &summary.log,
        truth.as_ref(),
        targets.as_ref().map(|(t, q)| (t.as_slice(), q.as_slice())),
        f,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_of_a_yaw() {
        let q = quaternion(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((q[2] - h).abs() < 1e-12 && (q[3] - h).abs() < 1e-12);
        assert!(q[0].abs() < 1e-12 && q[1].abs() < 1e-12);
        assert_eq!(n(f64::NAN), Value::Null);
    }
}
