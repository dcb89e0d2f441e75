//! A run as an MCAP file (the `mcap` crate) that Foxglove opens as is: every channel is JSON
//! with a JSON Schema, chunks are zstd-compressed, times are the firmware's log clock (ns from
//! its boot; the simulator's truth is on the same clock).
//!
//! Channels (only those whose data the inputs hold are written; the truth's are thinned to
//! [`TRUTH_PERIOD_S`], `/tf` and `/scene` to [`SCENE_PERIOD_S`], numbers rounded to
//! 1/[`PER_UNIT`] of their unit, so that the Table 2 walk fits in ≈ 2 MB):
//!
//! | topic | from | schema: message |
//! | --- | --- | --- |
//! | `/zmp/reference` | log | `walker.Point2`: `{x, y}` m |
//! | `/zmp/measured` | log (ticks with a valid measured ZMP) | `walker.Point2` |
//! | `/zmp/true` | truth | `walker.Point2` |
//! | `/com` | log (the model's CoM) | `walker.Point2` |
//! | `/com/true` | truth | `walker.Point3`: `{x, y, z}` m |
//! | `/foot_forces` | truth | `walker.FootForces`: `{left: [f0..f3], right: [..], left_fz, right_fz}` N |
//! | `/imu` | truth | `walker.Imu`: `{gyro: {x,y,z}` rad/s`, accel: {x,y,z}` m/s²`}` |
//! | `/torso_pose` | truth (pelvis) | `foxglove.PoseInFrame` (frame `world`) |
//! | `/joints` | truth | `walker.JointState`: `{name[12], velocity[12]` rad/s`, effort[12]` N·m`}` by servo ID |
//! | `/joints/target` | the plan's IK, on the log clock | `walker.JointTarget`: `{name[12], position[12]` rad`}` |
//! | `/tf` | `world → pelvis` (truth, else the plan) and every joint of the URDF by forward kinematics of the joint targets, ≤ 50 Hz | `foxglove.FrameTransforms` |
//! | `/robot_description` | the URDF ([`crate::sim::urdf`]), once | `std_msgs/String`: `{data}` |
//! | `/scene` | ZMP reference (green), measured (red), true (orange) on the floor; CoM of the log (blue, on the floor) and of the truth (purple); the support polygon (the soles in contact: truth, else the plan's feet and the logged phase), ≤ 50 Hz | `foxglove.SceneUpdate` |
//! | `/footsteps` | the plan's footsteps (start feet and landings), once | `foxglove.SceneUpdate` |
//! | `/events` | log (start-up, faults, stop) in words | `foxglove.Log` |
//!
//! Attachment `robot.urdf` (`application/xml`); metadata records `robot`, `plan` and
//! `firmware` (all values strings). Joint positions are neither in the log nor in the truth
//! CSV, hence the joint targets of the plan for the transforms.

use crate::export::ExportRow;
use crate::report::{event_text, tick_rows, DecodedLog, TruthTable};
use crate::sim::urdf::{self, LinkTransform, TreeJoint};
use gait_core::robot::{JOINT_NAMES, LEG_JOINTS};
use gait_core::Robot;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::io::{Seek, Write};
use walker_contract::record::Record;
use walker_contract::StopReason;

/// Period of the `/tf` and `/scene` messages, s (50 Hz: the 3D panel's frame rate, a fraction
/// of the file).
pub const SCENE_PERIOD_S: f64 = 0.02;

/// Period of the truth's channels, s (200 Hz, the firmware's tick; the truth CSV has 1 kHz).
pub const TRUTH_PERIOD_S: f64 = 0.005;

/// The frame of the world (x forward, y left, z up; origin midway between the feet at the start).
pub const WORLD: &str = "world";

fn time_schema() -> Value {
    json!({"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}})
}

fn vec3_schema() -> Value {
    let num = json!({"type": "number"});
    json!({"type": "object", "properties": {"x": num, "y": num, "z": num}})
}

fn quat_schema() -> Value {
    let num = json!({"type": "number"});
    json!({"type": "object", "properties": {"x": num, "y": num, "z": num, "w": num}})
}

fn pose_schema() -> Value {
    json!({"type": "object", "properties": {"position": vec3_schema(), "orientation": quat_schema()}})
}

fn color_schema() -> Value {
    let num = json!({"type": "number"});
    json!({"type": "object", "properties": {"r": num, "g": num, "b": num, "a": num}})
}

/// Foxglove's `foxglove.SceneUpdate` JSON Schema (the primitives written here: spheres, cubes,
/// lines, texts).
fn scene_update_schema() -> Value {
    let (pose, vec3, color) = (pose_schema(), vec3_schema(), color_schema());
    let prim = |extra: Value| {
        let mut p = json!({"pose": pose, "color": color});
        if let (Some(p), Value::Object(e)) = (p.as_object_mut(), extra) {
            p.extend(e);
        }
        json!({"type": "array", "items": {"type": "object", "properties": p}})
    };
    let entity = json!({"type": "object", "properties": {
        "timestamp": time_schema(),
        "frame_id": {"type": "string"},
        "id": {"type": "string"},
        "lifetime": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
        "frame_locked": {"type": "boolean"},
        "metadata": {"type": "array", "items": {"type": "object", "properties": {
            "key": {"type": "string"}, "value": {"type": "string"}}}},
        "spheres": prim(json!({"size": vec3})),
        "cubes": prim(json!({"size": vec3})),
        "lines": prim(json!({
            "type": {"type": "integer", "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
            "thickness": {"type": "number"},
            "scale_invariant": {"type": "boolean"},
            "points": {"type": "array", "items": vec3},
            "colors": {"type": "array", "items": color},
            "indices": {"type": "array", "items": {"type": "integer"}}})),
        "texts": prim(json!({
            "billboard": {"type": "boolean"}, "font_size": {"type": "number"},
            "scale_invariant": {"type": "boolean"}, "text": {"type": "string"}})),
        "arrows": {"type": "array"}, "cylinders": {"type": "array"},
        "triangles": {"type": "array"}, "models": {"type": "array"}}});
    json!({"title": "foxglove.SceneUpdate", "type": "object", "properties": {
        "deletions": {"type": "array", "items": {"type": "object", "properties": {
            "timestamp": time_schema(), "type": {"type": "integer"}, "id": {"type": "string"}}}},
        "entities": {"type": "array", "items": entity}}})
}

/// The channels the exporter knows: topic, schema name, JSON Schema.
pub fn channel_schemas() -> Vec<(&'static str, &'static str, Value)> {
    let num = json!({"type": "number"});
    let xy = json!({"type": "object", "properties": {"x": num, "y": num}});
    let xyz = vec3_schema();
    let arr = json!({"type": "array", "items": num});
    let names = json!({"type": "array", "items": {"type": "string"}});
    let time = time_schema();
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
                "pose": pose_schema()}}),
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
            "/tf",
            "foxglove.FrameTransforms",
            json!({"title": "foxglove.FrameTransforms", "type": "object", "properties": {
                "transforms": {"type": "array", "items": {"type": "object", "properties": {
                    "timestamp": time,
                    "parent_frame_id": {"type": "string"},
                    "child_frame_id": {"type": "string"},
                    "translation": xyz,
                    "rotation": quat_schema()}}}}}),
        ),
        (
            "/robot_description",
            "std_msgs/String",
            json!({"type": "object", "properties": {"data": {"type": "string"}}}),
        ),
        ("/scene", "foxglove.SceneUpdate", scene_update_schema()),
        ("/footsteps", "foxglove.SceneUpdate", scene_update_schema()),
        (
            "/events",
            "foxglove.Log",
            json!({"title": "foxglove.Log", "type": "object", "properties": {
                "timestamp": time,
                "level": {"type": "integer", "description": "0 UNKNOWN, 1 DEBUG, 2 INFO, 3 WARNING, 4 ERROR, 5 FATAL"},
                "message": {"type": "string"},
                "name": {"type": "string"},
                "file": {"type": "string"},
                "line": {"type": "integer"}}}),
        ),
    ]
}

/// What was written: messages per topic.
pub type ChannelCounts = BTreeMap<String, u64>;

/// The numbers written are rounded to 1/`PER_UNIT` of their unit (µm, µrad, µN, …; far below
/// any sensor's resolution), so that the JSON text is short and compresses well.
pub const PER_UNIT: f64 = 1e6;

/// A finite number as JSON rounded to 1/[`PER_UNIT`], else `null` (JSON has no NaN).
fn n(v: f64) -> Value {
    let r = (v * PER_UNIT).round() / PER_UNIT;
    serde_json::Number::from_f64(if r == 0.0 { 0.0 } else { r }).map_or(Value::Null, Value::Number)
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

/// Everything an MCAP of a run is made of besides the log.
#[derive(Clone, Debug, Default)]
pub struct RunExtras<'a> {
    /// The simulator's truth, on the log clock.
    pub truth: Option<&'a TruthTable>,
    /// The plan's trajectory (joint targets, pelvis, feet) with times on the log clock.
    pub plan: Option<&'a [ExportRow]>,
    /// The plan's footsteps: (side index 0 left / 1 right, x m, y m, yaw rad), start feet first.
    pub footsteps: Vec<(usize, [f64; 3])>,
    /// The robot's URDF ([`crate::sim::urdf::urdf`]) and link tree; `None`: no `/tf`, no model.
    pub robot: Option<(String, Vec<TreeJoint>)>,
    /// Sole length and width, m (the support polygon and the footsteps).
    pub sole: [f64; 2],
    /// Metadata records: name, key → value.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
}

fn stamp(t: u64) -> Value {
    json!({"sec": t / 1_000_000_000, "nsec": t % 1_000_000_000})
}

fn p3(p: [f64; 3]) -> Value {
    json!({"x": n(p[0]), "y": n(p[1]), "z": n(p[2])})
}

fn rgba(c: [f64; 4]) -> Value {
    json!({"r": c[0], "g": c[1], "b": c[2], "a": c[3]})
}

fn pose_at(p: [f64; 3], q: [f64; 4]) -> Value {
    json!({"position": p3(p), "orientation": {"x": n(q[0]), "y": n(q[1]), "z": n(q[2]), "w": n(q[3])}})
}

fn sphere(p: [f64; 3], d: f64, c: [f64; 4]) -> Value {
    json!({"pose": pose_at(p, [0.0, 0.0, 0.0, 1.0]), "size": {"x": d, "y": d, "z": d}, "color": rgba(c)})
}

fn entity(t: u64, id: &str, fields: Value) -> Value {
    let mut e = json!({"timestamp": stamp(t), "frame_id": WORLD, "id": id,
        "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": false, "metadata": [],
        "arrows": [], "cubes": [], "spheres": [], "cylinders": [], "lines": [],
        "triangles": [], "texts": [], "models": []});
    if let (Some(e), Value::Object(f)) = (e.as_object_mut(), fields) {
        e.extend(f);
    }
    e
}

/// The corners of a sole (length `l`, width `w`) at `(x, y)` with heading `yaw`.
fn sole_corners(x: f64, y: f64, yaw: f64, [l, w]: [f64; 2]) -> [[f64; 2]; 4] {
    let (s, c) = yaw.sin_cos();
    [[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]].map(|[a, b]| {
        let (u, v) = (a * l / 2.0, b * w / 2.0);
        [x + c * u - s * v, y + s * u + c * v]
    })
}

/// Convex hull (counter-clockwise, Andrew's monotone chain) of `pts`.
pub fn convex_hull(mut pts: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    pts.retain(|p| p.iter().all(|v| v.is_finite()));
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = hull.len();
        let it: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in it {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// The `foxglove.Log` level of an event: start-up and a planned or requested stop are INFO,
/// faults WARNING, any other stop ERROR.
fn log_level(r: &Record) -> u8 {
    match r {
        Record::Startup(_) | Record::Tick(_) => 2,
        Record::Stop(s) if matches!(s.reason, StopReason::PlanDone | StopReason::Requested) => 2,
        Record::Stop(_) => 4,
        Record::Fault(_) => 3,
    }
}

/// Times (s) from `times` at most one per `period`, with their indices.
fn thinned(times: impl Iterator<Item = f64>, period: f64) -> Vec<(usize, f64)> {
    let mut next = f64::NEG_INFINITY;
    let mut out = Vec::new();
    for (i, t) in times.enumerate() {
        if t.is_finite() && t >= 0.0 && t >= next - 1e-9 {
            out.push((i, t));
            next = t + period;
        }
    }
    out
}

/// Writes the run as MCAP: the decoded log and `extra` (the truth, the plan's trajectory on the
/// log clock, the robot model, metadata), zstd-compressed chunks.
pub fn write_mcap<W: Write + Seek>(
    log: &DecodedLog,
    extra: &RunExtras<'_>,
    out: W,
) -> Result<ChannelCounts, String> {
    let e = |e: mcap::McapError| format!("mcap: {e}");
    let truth = extra.truth;
    let plan = extra.plan.unwrap_or(&[]);
    let mut msgs: Vec<(u64, &'static str, Value)> = Vec::new();
    let rows = tick_rows(&log.ticks);
    for r in &rows {
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
        let t = u64::from(t_us) * 1000;
        msgs.push((
            t,
            "/events",
            json!({"timestamp": stamp(t), "level": log_level(ev),
                   "message": format!("{kind} #{seq}: {detail}"),
                   "name": kind, "file": "", "line": 0}),
        ));
    }
    let col = |name: &str| truth.and_then(|tr| tr.column(name));
    let cols3 = |a: &str, b: &str, c: &str| Some([col(a)?, col(b)?, col(c)?]);
    let pelvis = cols3("pelvis_x_m", "pelvis_y_m", "pelvis_z_m");
    let rpy = cols3("pelvis_roll_rad", "pelvis_pitch_rad", "pelvis_yaw_rad");
    let com = cols3("com_x_m", "com_y_m", "com_z_m");
    if let Some(tr) = truth {
        let gyro = cols3("gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s");
        let acc = cols3("acc_x_m_s2", "acc_y_m_s2", "acc_z_m_s2");
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
        for (i, t_s) in thinned(tr.t.iter().copied(), TRUTH_PERIOD_S) {
            let Some(t) = ns(t_s) else { continue };
            let z = tr.zmp[i];
            msgs.push((t, "/zmp/true", json!({"x": n(z[0]), "y": n(z[1])})));
            if let Some(c) = com {
                msgs.push((t, "/com/true", p3([c[0][i], c[1][i], c[2][i]])));
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
                    json!({"gyro": p3([g[0][i], g[1][i], g[2][i]]),
                           "accel": p3([a[0][i], a[1][i], a[2][i]])}),
                ));
            }
            if let (Some(p), Some(r)) = (pelvis, rpy) {
                let q = quaternion(r[0][i], r[1][i], r[2][i]);
                msgs.push((
                    t,
                    "/torso_pose",
                    json!({"timestamp": stamp(t), "frame_id": WORLD,
                           "pose": pose_at([p[0][i], p[1][i], p[2][i]], q)}),
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
    for row in plan {
        let Some(t) = ns(row.t) else { continue };
        let pos: Vec<Value> = row.q.iter().map(|&v| n(v)).collect();
        msgs.push((
            t,
            "/joints/target",
            json!({"name": JOINT_NAMES, "position": pos}),
        ));
    }
    // The plan row at or before `t`.
    let plan_at = |t: f64| -> Option<&ExportRow> {
        let i = plan.partition_point(|r| r.t <= t + 1e-9);
        (i > 0).then(|| &plan[i - 1])
    };
    // The truth row at `t` with a finite pelvis pose: position and quaternion.
    let truth_base = |t: f64| -> Option<([f64; 3], [f64; 4])> {
        let i = truth?.index_at(t)?;
        let (p, r) = (pelvis?, rpy?);
        let pos = [p[0][i], p[1][i], p[2][i]];
        let ang = [r[0][i], r[1][i], r[2][i]];
        pos.iter()
            .chain(&ang)
            .all(|v| v.is_finite())
            .then(|| (pos, quaternion(ang[0], ang[1], ang[2])))
    };
    if let Some((urdf_text, tree)) = &extra.robot {
        // Transforms: at the plan's samples (joint targets), else the truth's (base only).
        let times: Vec<f64> = if plan.is_empty() {
            truth.map_or(Vec::new(), |tr| tr.t.clone())
        } else {
            plan.iter().map(|r| r.t).collect()
        };
        for (_, t_s) in thinned(times.into_iter(), SCENE_PERIOD_S) {
            let Some(t) = ns(t_s) else { continue };
            let row = plan_at(t_s);
            let base = truth_base(t_s).or_else(|| {
                let p = row?.pelvis();
                Some(([p.x, p.y, p.z], quaternion(p.roll, p.pitch, p.yaw)))
            });
            let mut tfs: Vec<LinkTransform> = Vec::new();
            if let Some((pos, rot)) = base {
                tfs.push(LinkTransform {
                    parent: WORLD.into(),
                    child: urdf::ROOT.into(),
                    translation: pos,
                    rotation: rot,
                });
            }
            if let Some(r) = row {
                tfs.extend(urdf::transforms(tree, &r.q));
            }
            if tfs.is_empty() {
                continue;
            }
            let list: Vec<Value> = tfs
                .iter()
                .map(|f| {
                    json!({"timestamp": stamp(t), "parent_frame_id": f.parent,
                           "child_frame_id": f.child, "translation": p3(f.translation),
                           "rotation": {"x": n(f.rotation[0]), "y": n(f.rotation[1]),
                                        "z": n(f.rotation[2]), "w": n(f.rotation[3])}})
                })
                .collect();
            msgs.push((t, "/tf", json!({ "transforms": list })));
        }
        let first = msgs.iter().map(|m| m.0).min().unwrap_or(0);
        msgs.push((first, "/robot_description", json!({ "data": urdf_text })));
    }
    // The scene: ZMPs, CoMs and the support polygon at the log's ticks, ≤ 50 Hz.
    let soles_truth = cols3("l_x_m", "l_y_m", "l_yaw_rad")
        .zip(cols3("r_x_m", "r_y_m", "r_yaw_rad"))
        .zip(col("l_contact").zip(col("r_contact")));
    for (k, t_s) in thinned(rows.iter().map(|r| r.t), SCENE_PERIOD_S) {
        let Some(t) = ns(t_s) else { continue };
        let r = &rows[k];
        let floor = 0.002;
        let mut zmp = Vec::new();
        if r.zmp_ref.iter().all(|v| v.is_finite()) {
            zmp.push(sphere(
                [r.zmp_ref[0], r.zmp_ref[1], floor],
                0.012,
                [0.1, 0.75, 0.2, 1.0],
            ));
        }
        if let Some(m) = r.measured() {
            zmp.push(sphere([m[0], m[1], floor], 0.012, [0.9, 0.15, 0.1, 1.0]));
        }
        let ti = truth.and_then(|tr| tr.index_at(t_s));
        if let Some(z) = ti.and_then(|i| truth.map(|tr| tr.zmp[i])) {
            if z.iter().all(|v| v.is_finite()) {
                zmp.push(sphere([z[0], z[1], floor], 0.01, [1.0, 0.6, 0.0, 1.0]));
            }
        }
        let mut coms = Vec::new();
        if r.com.iter().all(|v| v.is_finite()) {
            coms.push(sphere(
                [r.com[0], r.com[1], floor],
                0.012,
                [0.15, 0.35, 0.95, 1.0],
            ));
        }
        if let (Some(i), Some(c)) = (ti, com) {
            let p = [c[0][i], c[1][i], c[2][i]];
            if p.iter().all(|v| v.is_finite()) {
                coms.push(sphere(p, 0.02, [0.6, 0.2, 0.8, 1.0]));
            }
        }
        // The soles in contact: the truth's, else the plan's feet in the logged phase.
        let mut corners = Vec::new();
        if let (Some(i), Some(((l, rr), (lc, rc)))) = (ti, soles_truth) {
            for (s, c) in [(l, lc), (rr, rc)] {
                if c[i] > 0.5 {
                    corners.extend(sole_corners(s[0][i], s[1][i], s[2][i], extra.sole));
                }
            }
        } else if let Some(row) = plan_at(t_s) {
            use walker_contract::record::LoggedPhase as P;
            let on = match r.rec.phase {
                P::SingleLeft => [true, false],
                P::SingleRight => [false, true],
                _ => [true, true],
            };
            for ((f, yaw), _) in row.feet.iter().zip(row.feet_yaw).zip(on).filter(|x| x.1) {
                corners.extend(sole_corners(f[0], f[1], yaw, extra.sole));
            }
        }
        let hull = convex_hull(corners);
        let lines: Vec<Value> = if hull.len() >= 3 {
            let pts: Vec<Value> = hull.iter().map(|p| p3([p[0], p[1], 0.001])).collect();
            vec![
                json!({"type": 1, "pose": pose_at([0.0; 3], [0.0, 0.0, 0.0, 1.0]),
                        "thickness": 0.004, "scale_invariant": false, "points": pts,
                        "color": rgba([0.1, 0.1, 0.1, 1.0]), "colors": [], "indices": []}),
            ]
        } else {
            Vec::new()
        };
        msgs.push((
            t,
            "/scene",
            json!({"deletions": [], "entities": [
                entity(t, "zmp", json!({"spheres": zmp})),
                entity(t, "com", json!({"spheres": coms})),
                entity(t, "support_polygon", json!({"lines": lines}))]}),
        ));
    }
    if !extra.footsteps.is_empty() {
        let t = msgs.iter().map(|m| m.0).min().unwrap_or(0);
        let [l, w] = extra.sole;
        let cubes: Vec<Value> = extra
            .footsteps
            .iter()
            .map(|(side, [x, y, yaw])| {
                let c = if *side == 0 {
                    [0.2, 0.5, 1.0, 0.35]
                } else {
                    [1.0, 0.35, 0.2, 0.35]
                };
                json!({"pose": pose_at([*x, *y, 0.0005], quaternion(0.0, 0.0, *yaw)),
                       "size": {"x": l, "y": w, "z": 0.001}, "color": rgba(c)})
            })
            .collect();
        msgs.push((
            t,
            "/footsteps",
            json!({"deletions": [], "entities": [entity(t, "footsteps", json!({"cubes": cubes}))]}),
        ));
    }
    msgs.sort_by_key(|m| m.0);

    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .profile("")
        .create(out)
        .map_err(e)?;
    let mut ids: BTreeMap<&str, u16> = BTreeMap::new();
    let mut counts = ChannelCounts::new();
    let used: std::collections::BTreeSet<&str> = msgs.iter().map(|m| m.1).collect();
    let mut schema_ids: BTreeMap<&str, u16> = BTreeMap::new();
    for (topic, name, schema) in channel_schemas() {
        if !used.contains(topic) {
            continue;
        }
        let sid = match schema_ids.get(name) {
            Some(&id) => id,
            None => {
                let id = w
                    .add_schema(name, "jsonschema", schema.to_string().as_bytes())
                    .map_err(e)?;
                schema_ids.insert(name, id);
                id
            }
        };
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
    if let Some((urdf_text, _)) = &extra.robot {
        w.attach(&mcap::Attachment {
            log_time: 0,
            create_time: 0,
            name: "robot.urdf".into(),
            media_type: "application/xml".into(),
            data: std::borrow::Cow::Borrowed(urdf_text.as_bytes()),
        })
        .map_err(e)?;
    }
    for (name, kv) in &extra.metadata {
        w.write_metadata(&mcap::records::Metadata {
            name: name.clone(),
            metadata: kv.clone(),
        })
        .map_err(e)?;
    }
    w.finish().map_err(e)?;
    Ok(counts)
}

/// `key=value` tokens as a map (a bare word maps to an empty value).
fn token_map(tokens: &[String]) -> BTreeMap<String, String> {
    tokens
        .iter()
        .map(|t| match t.split_once('=') {
            Some((k, v)) => (k.to_string(), v.to_string()),
            None => (t.clone(), String::new()),
        })
        .collect()
}

/// Writes the MCAP of a finished report's run to `path`: its log, its truth file (re-read), the
/// plan's trajectory on the log clock, the robot's URDF and the metadata `robot`, `plan` and
/// `firmware`. `firmware_tokens`: the firmware's command line of the run (`walker fil`); `None`
/// (a report of a captured log): the plan's firmware parameters.
pub fn export_run(
    opts: &crate::report::ReportOptions,
    summary: &crate::report::ReportSummary,
    robot: &Robot,
    firmware_tokens: Option<&[String]>,
    path: &std::path::Path,
) -> Result<ChannelCounts, String> {
    let truth = match &opts.truth {
        Some(p) => Some(crate::report::read_truth(p)?),
        None => None,
    };
    let spec = &summary.spec;
    let dt = crate::report::tick_period(&summary.log).clamp(0.001, 0.02);
    let offset = summary.alignment.offset;
    let plan: Option<Vec<ExportRow>> =
        crate::export::export_rows(spec, robot, dt)
            .ok()
            .map(|(rows, _)| {
                rows.into_iter()
                    .map(|mut r| {
                        r.t -= offset;
                        r
                    })
                    .collect()
            });
    let mut footsteps = Vec::new();
    if let Ok(p) = spec.plan(robot) {
        for (k, f) in p.start_feet().iter().enumerate() {
            footsteps.push((k, [f.x, f.y, f.yaw]));
        }
        for e in (0..p.len()).filter_map(|i| p.step(i)) {
            let f = e.step.place;
            footsteps.push((e.step.side.index(), [f.x, f.y, f.yaw]));
        }
    }
    let servo = crate::sim::dynamixel::XServoParams::XM430_W350;
    let urdf_text = urdf::urdf(robot, servo.stall_torque);
    let mut plan_md = BTreeMap::from([
        ("name".to_string(), opts.plan_name.clone()),
        ("model".to_string(), spec.model_kind().name().to_string()),
        ("spec".to_string(), format!("{spec:?}")),
    ]);
    if let Ok(fields) = spec.firmware_fields() {
        for (field, token) in fields {
            let v = token.split_once('=').map_or("", |(_, v)| v);
            plan_md.insert(field, v.to_string());
        }
    }
    let (source, tokens) = match firmware_tokens {
        Some(t) => ("the firmware's command line", t.to_vec()),
        None => (
            "the plan's firmware parameters (the robot's own configuration is not in its log)",
            spec.firmware_tokens().unwrap_or_default(),
        ),
    };
    let mut fw_md = token_map(&tokens);
    fw_md.insert("_source".into(), source.into());
    fw_md.insert("_command_line".into(), tokens.join(" "));
    let robot_md = BTreeMap::from([
        ("urdf_attachment".to_string(), "robot.urdf".to_string()),
        ("urdf_topic".to_string(), "/robot_description".to_string()),
        ("root_frame".to_string(), urdf::ROOT.to_string()),
        ("world_frame".to_string(), WORLD.to_string()),
        ("joint_names".to_string(), JOINT_NAMES.join(",")),
        (
            "transforms_hz".to_string(),
            format!("{}", 1.0 / SCENE_PERIOD_S),
        ),
    ]);
    let g = robot.geometry;
    let extra = RunExtras {
        truth: truth.as_ref(),
        plan: plan.as_deref(),
        footsteps,
        robot: Some((urdf_text, urdf::tree(robot))),
        sole: [g.sole_length, g.sole_width],
        metadata: vec![
            ("robot".into(), robot_md),
            ("plan".into(), plan_md),
            ("firmware".into(), fw_md),
        ],
    };
    if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).map_err(|e| format!("cannot create {}: {e}", d.display()))?;
    }
    let f = std::fs::File::create(path)
        .map_err(|e| format!("cannot create {}: {e}", path.display()))?;
    write_mcap(&summary.log, &extra, std::io::BufWriter::new(f))
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

    #[test]
    fn hull_of_two_soles_in_double_support() {
        let mut pts = sole_corners(0.0, 0.045, 0.0, [0.1, 0.06]).to_vec();
        pts.extend(sole_corners(0.02, -0.045, 0.0, [0.1, 0.06]));
        let h = convex_hull(pts);
        assert_eq!(h.len(), 6, "{h:?}");
        let area: f64 = (0..h.len())
            .map(|i| {
                let (a, b) = (h[i], h[(i + 1) % h.len()]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum::<f64>()
            / 2.0;
        // The 0.12 × 0.15 m bounding box less two corner triangles of 0.02 × 0.09 m / 2.
        assert!((area - 0.0162).abs() < 1e-12, "{area}");
    }
}
