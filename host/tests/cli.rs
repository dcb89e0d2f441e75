//! End-to-end tests of the `walker` CLI: export round trip, report on a synthetic log with
//! garbage, plan-file errors, hand-computed statistics, compare and capture --from-file.

use gait_core::kinematics::leg::{leg_fk, Pose};
use gait_core::{Robot, Side};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use walker_contract::record::{
    encode, BoardId, LoggedPhase, Record, StartupRecord, StopRecord, TickRecord, MAX_FRAME,
};
use walker_contract::StopReason;
use walker_host::export;
use walker_host::planfile::{self, WalkSpec};
use walker_host::report;

fn walker(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_walker"))
        .args(args)
        .current_dir(workspace())
        .output()
        .expect("run walker")
}

/// `walker report --log LOG --truth TRUTH --out OUT EXTRA…`, which must succeed; its stdout.
fn report_ok(log: &Path, truth: &Path, out: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "report",
        "--log",
        s(log),
        "--truth",
        s(truth),
        "--out",
        s(out),
    ];
    args.extend_from_slice(extra);
    let o = walker(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("walker-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (header, rows)
}

/// Every column of a CSV the host writes names its unit as a suffix, or is a count, flag, code
/// or name (listed here).
fn assert_units(header: &str) {
    const UNITS: [&str; 11] = [
        "_s", "_us", "_m", "_rad", "_rad_s", "_m_s2", "_n", "_nm", "_frac", "_deg", "_v",
    ];
    const UNITLESS: [&str; 22] = [
        "seq",
        "kind",
        "detail",
        "zmp_valid",
        "phase",
        "fault",
        "overrun",
        "bus_timeouts",
        "bus_crc_errors",
        "bus_status_errors",
        "tick_overruns",
        "support",
        "stance",
        "falling",
        "tq_limited",
        "l_contact",
        "r_contact",
        "other_contact",
        "run",
        "exit_code",
        "timing_factor",
        "walking_ticks",
    ];
    for c in header.split(',') {
        assert!(
            UNITS.iter().any(|u| c.ends_with(u)) || UNITLESS.contains(&c) || c == "ref_mismatch",
            "column {c:?} has no unit in {header}"
        );
    }
}

/// No `NaN` (or `inf`) text in a CSV: an absent value is an empty field.
fn assert_no_nan_text(path: &Path) {
    let text = std::fs::read_to_string(path).unwrap();
    for word in ["NaN", "nan", "inf"] {
        assert!(
            !text
                .split([',', '\n'])
                .any(|f| f.trim().trim_start_matches('-') == word),
            "{}: {word} field",
            path.display()
        );
    }
}

#[test]
fn every_csv_header_carries_units() {
    assert_units(report::RESPONSE_HEADER);
    assert_units(walker_host::sim::truth::HEADER);
    assert_units(walker_host::beyond::CSV_HEADER);
    assert_units(&walker_host::export::header());
    // The events CSV: seq, time_us, kind, detail.
    let mut buf = Vec::new();
    report::write_events_csv(&[], &mut buf).unwrap();
    assert_units(String::from_utf8(buf).unwrap().trim());
}

fn frame(rec: &Record) -> Vec<u8> {
    let mut b = [0u8; MAX_FRAME];
    let n = encode(rec, &mut b);
    assert!(n > 0);
    b[..n].to_vec()
}

fn tick(seq: u16, zmp_ref: [f32; 2], meas: Option<[f32; 2]>, phase: LoggedPhase) -> Record {
    let mut r = TickRecord {
        seq,
        time_us: 1_000_000 + u32::from(seq) * 1000,
        phase,
        zmp_valid: meas.is_some(),
        ..TickRecord::default()
    };
    r.set_zmp_ref_m(zmp_ref[0], zmp_ref[1]);
    if let Some(m) = meas {
        r.set_zmp_meas_m(m[0], m[1]);
    }
    r.set_com_m(zmp_ref[0], zmp_ref[1]);
    r.set_tau_nm(0.01);
    r.bus.timeouts = seq / 10;
    Record::Tick(r)
}

#[test]
fn export_round_trips_through_forward_kinematics() {
    let dir = tmp("export");
    let out = dir.join("plan.csv");
    let o = walker(&[
        "export",
        "--plan",
        "plans/table2.toml",
        "--out",
        s(&out),
        "--dt",
        "0.005",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (header, rows) = read_csv(&out);
    let mut expect: Vec<String> = export::LEAD_COLUMNS.map(String::from).to_vec();
    expect.extend(gait_core::robot::JOINT_NAMES.map(|n| format!("{n}_rad")));
    assert_eq!(header, expect);
    assert_units(&header.join(","));
    // 1.6 + 14·0.64 + 1.6 s at 5 ms.
    assert_eq!(rows.len(), 12160 / 5 + 1);
    let robot = Robot::reference();
    let mut worst = 0.0f64;
    for row in &rows {
        let v: Vec<f64> = row.iter().map(|x| x.parse().unwrap()).collect();
        assert_eq!(v.len(), 24);
        // Table 2 walks straight: every heading is 0, so the pelvis is level with yaw 0.
        let pelvis = Pose::level(v[3], v[4], v[5], 0.0);
        assert!((v[5] - 0.217).abs() < 1e-12);
        for (side, feet, q) in [(Side::Left, 6, 12), (Side::Right, 9, 18)] {
            let angles: [f64; 6] = v[q..q + 6].try_into().unwrap();
            let foot = leg_fk(&robot, side, &pelvis, &angles);
            for (k, got) in [foot.x, foot.y, foot.z].into_iter().enumerate() {
                worst = worst.max((got - v[feet + k]).abs());
            }
            assert!(foot.roll.abs() < 1e-6 && foot.pitch.abs() < 1e-6 && foot.yaw.abs() < 1e-6);
        }
    }
    assert!(
        worst < 1e-6,
        "FK of the exported angles misses the feet by {worst} m"
    );
}

#[test]
fn turning_export_round_trips_in_memory() {
    let spec = planfile::load(&workspace().join("plans/turn.toml")).unwrap();
    let robot = Robot::reference();
    let (rows, summary) = export::export_rows(&spec, &robot, 0.005).unwrap();
    assert_eq!(summary.clamped_rows, 0);
    let last = rows.last().unwrap();
    assert!((last.feet_yaw[0] - 0.4).abs() < 1e-9 && (last.feet_yaw[1] - 0.4).abs() < 1e-9);
    for r in &rows {
        let pelvis = r.pelvis();
        assert_eq!([pelvis.x, pelvis.y, pelvis.z], r.com);
        for (i, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let q: [f64; 6] = r.q[6 * i..6 * i + 6].try_into().unwrap();
            let f = leg_fk(&robot, side, &pelvis, &q);
            let e = (f.x - r.feet[i][0])
                .abs()
                .max((f.y - r.feet[i][1]).abs())
                .max((f.z - r.feet[i][2]).abs());
            assert!(e < 1e-6, "t = {}: foot {i} off by {e}", r.t);
            let dyaw = (f.yaw - r.feet_yaw[i] + std::f64::consts::PI)
                .rem_euclid(2.0 * std::f64::consts::PI)
                - std::f64::consts::PI;
            assert!(dyaw.abs() < 1e-6);
        }
    }
}

/// The start-up record of a QEMU run at `time_us` with tick period `tick_period_us`, the bus
/// probed or not.
fn startup(time_us: u32, tick_period_us: u32, probed: bool) -> Record {
    Record::Startup(StartupRecord {
        seq: 0,
        time_us,
        board: BoardId::QemuMps2,
        fw: [0, 1, 0],
        tick_period_us,
        bus_baud: 1_000_000,
        device_count: 15,
        probed,
        missing: Default::default(),
    })
}

/// A log with every kind of damage: starts mid-frame, garbage, a truncated frame, a corrupted
/// frame and an unterminated frame at the end.
fn damaged_log() -> (Vec<u8>, Vec<u16>) {
    let mut bytes = Vec::new();
    // Mid-stream start: the tail of a frame.
    let prev = frame(&tick(999, [0.0, 0.0], None, LoggedPhase::Standing));
    bytes.extend_from_slice(&prev[prev.len() - 17..]);
    bytes.extend(frame(&startup(999_000, 1000, false)));
    let mut kept = Vec::new();
    for seq in 1..=100u16 {
        let phase = if seq <= 20 {
            LoggedPhase::Standing
        } else {
            LoggedPhase::Double
        };
        let x = f32::from(seq) * 1e-4;
        let mut f = frame(&tick(seq, [x, 0.01], Some([x + 0.001, 0.01]), phase));
        match seq {
            // Garbage after this frame, terminated by a delimiter.
            30 => {
                bytes.extend(&f);
                bytes.extend([0x11, 0x22, 0x33, 0x00]);
                kept.push(seq);
                continue;
            }
            // Truncated: only its first 20 bytes arrive; it swallows frame 61.
            60 => f.truncate(20),
            61 => {}
            // One flipped bit: CRC error.
            80 => f[12] ^= 0x04,
            _ => kept.push(seq),
        }
        bytes.extend(f);
    }
    bytes.extend(frame(&Record::Stop(StopRecord {
        seq: 101,
        time_us: 1_200_000,
        reason: StopReason::PlanDone,
    })));
    // Unterminated frame at the end.
    let last = frame(&tick(102, [0.0, 0.0], None, LoggedPhase::Standing));
    bytes.extend_from_slice(&last[..10]);
    (bytes, kept)
}

#[test]
fn report_on_damaged_log_counts_exactly() {
    let (bytes, kept) = damaged_log();
    assert_eq!(kept.len(), 97);
    let log = report::decode_bytes(&bytes);
    assert_eq!(log.ticks.len(), 97);
    assert_eq!(log.events.len(), 2);
    assert_eq!(log.good(), 99);
    // mid-stream start, garbage, truncated 60 + 61, CRC of 80, unterminated end.
    assert_eq!(log.bad(), 5);
    assert_eq!(log.decoder.rejected, 4);
    // The flipped bit is a CRC error; the mid-stream tail fails COBS or CRC; garbage fails COBS.
    let r = log.rejects;
    assert!(r.crc >= 1);
    assert_eq!(r.overlong, 1);
    assert_eq!(
        r.cobs + r.crc + r.unknown_type + r.length + r.field + r.overlong,
        4
    );
    assert!(log.trailing_bytes == 10);

    let dir = tmp("report");
    let path = dir.join("walk.log");
    std::fs::write(&path, &bytes).unwrap();
    let out = dir.join("report");
    let o = walker(&["report", "--log", s(&path), "--out", s(&out)]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        stdout.contains("99 good records (97 ticks, 2 events), 5 bad"),
        "{stdout}"
    );
    let (header, rows) = read_csv(&out.join("zmp_response.csv"));
    assert_eq!(header.join(","), report::RESPONSE_HEADER);
    assert_eq!(rows.len(), 97);
    assert_no_nan_text(&out.join("zmp_response.csv"));
    let seqs: Vec<u16> = rows.iter().map(|r| r[1].parse().unwrap()).collect();
    assert_eq!(seqs, kept);
    // Row of seq 30: t, reference, measured, phase, bus timeouts.
    let r = &rows[kept.iter().position(|&k| k == 30).unwrap()];
    assert_eq!(r[0], "1.030000");
    assert_eq!(r[2], "0.00300");
    assert_eq!(r[3], "0.01000");
    assert_eq!(r[4], "0.00400");
    assert_eq!(r[6], "1");
    assert_eq!(r[10], "double");
    assert_eq!(r[13], "3");
    for f in [
        "report.md",
        "stats.json",
        "zmp_response.svg",
        "zmp_response.png",
        "events.csv",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).unwrap()).unwrap();
    let rec = &json["records"];
    assert_eq!(
        [&rec["good"], &rec["bad"], &rec["ticks"], &rec["events"]],
        [99, 5, 97, 2],
        "{json}"
    );
    assert_eq!(json["zmp_error"]["x"]["count"], 97);
    assert!((json["zmp_error"]["x"]["mean_abs"].as_f64().unwrap() - 0.001).abs() < 1e-9);
    assert_eq!(json["truth_error"], serde_json::Value::Null);
    let png = std::fs::read(out.join("zmp_response.png")).unwrap();
    assert_eq!(&png[..8], &[0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A]);
    let svg = std::fs::read_to_string(out.join("zmp_response.svg")).unwrap();
    assert!(svg.contains("ZMP reference") && svg.contains("support polygon min/max"));
    assert!(svg.contains("t (s)") && svg.contains("ZMP x (m)"), "{svg}");
    // Every measured x is 1 mm ahead of the reference.
    assert!(
        stdout.contains("| x (sagittal) | 97 | 0.097000 | 0.001000 | 0.001000 | 0.001000 |"),
        "{stdout}"
    );
}

#[test]
fn bad_plan_file_names_the_field() {
    let dir = tmp("badplan");
    let cases = [
        ("t2 = 0.1\n", "field `t2`"),
        ("a = 0.06\n", "field `a`"),
        ("z_c = -1.0\n", "field `z_c`"),
        ("model = \"lip\"\n", "field `model`"),
        ("step_lenght = 0.02\n", "field `step_lenght`"),
        ("s_first = 0\n", "field `s_first`"),
        ("steps = 0\n", "field `steps`"),
        (
            "[[footsteps]]\nside = \"left\"\nx = 0.02\ny = 0.045\n[[footsteps]]\nside = \"right\"\nx = 0.9\ny = -0.045\n",
            "field `footsteps[1]`",
        ),
        ("[[footsteps]]\nside = \"left\"\nx = 0.02\ny = 0.045\n[[footsteps]]\nside = \"right\"\ny = -0.045\n", "footsteps[1].x"),
        ("dt = 0.3\n", "field `dt`"),
    ];
    for (i, (text, want)) in cases.iter().enumerate() {
        let p = dir.join(format!("bad{i}.toml"));
        std::fs::write(&p, text).unwrap();
        let o = walker(&["export", "--plan", s(&p), "--out", s(&dir.join("x.csv"))]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{text}: {err}");
        assert!(err.contains(want), "{text:?}: want {want:?} in {err:?}");
        assert!(err.contains(&format!("bad{i}.toml")), "{err}");
    }
    // The library gives the field separately.
    let e = planfile::parse("t1 = 0.2\nt2 = 0.1\n")
        .unwrap()
        .check(&Robot::reference())
        .unwrap_err();
    assert_eq!(e.field, "t2");
    assert!(e.reason.contains("0 < t1 < t2 < T"));
    // Defaults are Table 2.
    assert_eq!(planfile::parse("").unwrap(), WalkSpec::default());
    assert_eq!(
        planfile::load(&workspace().join("plans/table2.toml")).unwrap(),
        WalkSpec::default()
    );
}

#[test]
fn usage_errors_exit_2() {
    assert_eq!(walker(&["frobnicate"]).status.code(), Some(2));
    assert_eq!(walker(&["report"]).status.code(), Some(2));
    assert_eq!(walker(&["export", "--dt", "abc"]).status.code(), Some(2));
    assert_eq!(
        walker(&["compare", "--runs", "lipm"]).status.code(),
        Some(2)
    );
    for bad in ["-1", "abc", "NaN", "inf"] {
        for cmd in ["simulate", "fil", "beyond"] {
            let out = walker(&[cmd, "--stall-torque", bad]);
            assert_eq!(out.status.code(), Some(2), "{cmd} --stall-torque {bad}");
        }
    }
    // Every duration is checked before anything starts (NaN, negative and huge values would
    // abort with SIGABRT in Duration::from_secs_f64).
    for bad in ["nan", "-5", "1e300", "0", "inf"] {
        for (cmd, opt) in [
            ("fil", "--timeout"),
            ("beyond", "--timeout"),
            ("simulate", "--timeout"),
            ("capture", "--seconds"),
        ] {
            let out = walker(&[cmd, opt, bad]);
            assert_eq!(out.status.code(), Some(2), "{cmd} {opt} {bad}");
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(err.contains(opt), "{cmd} {opt} {bad}: {err}");
        }
    }
    // The physics options are checked too.
    for (opt, bad) in [
        ("--physics", "bullet"),
        ("--push", "1:2"),
        ("--floor-friction", "-1"),
        ("--floor-steps", "500"),
        ("--payload", "nan"),
    ] {
        let out = walker(&["fil", opt, bad]);
        assert_eq!(out.status.code(), Some(2), "fil {opt} {bad}");
    }
    // A firmware command line over the firmware's 1024-byte semihosting buffer: refused
    // before QEMU starts (QEMU would hand the firmware no parameter at all).
    // (One token with a long value: repeats of one key would be merged into one token.)
    let long = format!("t1=0.15{}", "0".repeat(1100));
    assert!(long.len() > 1024);
    let out = walker(&["fil", "--firmware-args", &long]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("1024-byte semihosting buffer"), "{err}");
    assert!(walker(&["--help"]).status.success());
    assert!(walker(&["report", "--help"]).status.success());
}

/// clap's conveniences: version, help with a line per option, suggestions, repeats and
/// conflicts refused, non-UTF-8 paths.
#[test]
fn command_line_is_standard() {
    let o = walker(&["--version"]);
    assert!(o.status.success());
    assert_eq!(
        String::from_utf8_lossy(&o.stdout).trim(),
        format!("walker {}", env!("CARGO_PKG_VERSION"))
    );
    for cmd in [
        "export", "report", "compare", "capture", "simulate", "fil", "beyond",
    ] {
        let o = walker(&[cmd, "--help"]);
        assert!(o.status.success(), "{cmd}");
        let help = String::from_utf8_lossy(&o.stdout);
        assert!(help.contains(&format!("Usage: walker {cmd}")), "{help}");
    }
    let help = String::from_utf8_lossy(&walker(&["fil", "--help"]).stdout).into_owned();
    assert!(help.contains("--firmware-args") && help.contains("Sole–floor friction coefficient"));
    // A misspelt flag: exit 2 and the right spelling suggested.
    let o = walker(&["fil", "--timout", "5"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("'--timout'") && err.contains("'--timeout'"),
        "{err}"
    );
    // Repeats and conflicts.
    for args in [
        &[
            "fil",
            "--plan",
            "plans/table2.toml",
            "--plan",
            "plans/turn.toml",
        ][..],
        &["report", "--log", "a", "--log", "b"],
        &[
            "capture",
            "--port",
            "/dev/null",
            "--from-file",
            "x",
            "--out",
            "y",
        ],
        &["capture", "--list", "--port", "/dev/null"],
        &["capture", "--port", "/dev/null"],
        &["capture"],
        &["fil", "--machine", "mps2-an385"],
        &["fil", "--p-drop", "1.5"],
        &["fil", "--dead", "111,x"],
        &["simulate", "--port", "70000"],
    ] {
        let o = walker(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.starts_with("error: "), "{args:?}: {err}");
    }
    // A path that is not UTF-8 is carried as it is: a clean "not found", no panic.
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt as _;
        let bad = std::ffi::OsStr::from_bytes(b"/tmp/walker-\xff\xfe.log");
        let o = Command::new(env!("CARGO_BIN_EXE_walker"))
            .arg("report")
            .arg("--log")
            .arg(bad)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.contains("not found") && !err.contains("panicked"),
            "{err}"
        );
    }
}

/// `--firmware-args` goes through the firmware's own parser on the host, before QEMU (or even
/// the ELF) is looked for: a misspelt key lists the valid keys, a value out of range gives the
/// range.
#[test]
fn firmware_args_are_checked_before_qemu_starts() {
    let cases = [
        ("stab_kk=1", "unknown firmware parameter `stab_kk`"),
        (
            "stab_kp=1e9",
            "`stab_kp=1e9`: out of range (expected 0 ..= 10",
        ),
        ("feasibility=maybe", "`feasibility=maybe`: bad value"),
        ("lockstep oops", "`oops`: not a key=value pair"),
    ];
    for (args, want) in cases {
        for cmd in [
            &["fil", "--elf", "/nonexistent", "--firmware-args", args][..],
            &["beyond", "--elf", "/nonexistent", "--feedback-args", args],
            &["sweep", "--elf", "/nonexistent", "--firmware-args", args],
        ] {
            let o = walker(cmd);
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(2), "{cmd:?}: {err}");
            assert!(err.contains(want), "{cmd:?}: want {want:?} in {err}");
            assert!(
                !err.contains("ELF"),
                "{cmd:?}: checked after the ELF: {err}"
            );
        }
    }
    let o = walker(&["fil", "--firmware-args", "stab_kk=1"]);
    let err = String::from_utf8_lossy(&o.stderr);
    for key in walker_contract::params::KEYS {
        assert!(err.contains(key), "valid key {key} not listed: {err}");
    }
}

/// A start-up record, three ticks with hand-picked errors (and one without a measured ZMP),
/// a stop record.
fn hand_log(scale: f32) -> Vec<u8> {
    let errs = [[0.001, 0.0], [-0.002, 0.004], [0.003, -0.004]];
    let mut bytes = vec![0u8];
    bytes.extend(frame(&startup(999_000, 1000, true)));
    for (i, e) in errs.iter().enumerate() {
        let r = [0.01, -0.02];
        let m = [r[0] + e[0] * scale, r[1] + e[1] * scale];
        bytes.extend(frame(&tick(i as u16, r, Some(m), LoggedPhase::Double)));
    }
    bytes.extend(frame(&tick(3, [0.0, 0.0], None, LoggedPhase::Double)));
    bytes.extend(frame(&Record::Stop(StopRecord {
        seq: 4,
        time_us: 1_004_000,
        reason: StopReason::PlanDone,
    })));
    bytes
}

#[test]
fn statistics_match_a_hand_computed_case() {
    let log = report::decode_bytes(&hand_log(1.0));
    assert_eq!((log.good(), log.bad()), (6, 0));
    let st = report::error_stats(&report::tick_rows(&log.ticks));
    assert_eq!((st.ticks, st.skipped), (4, 1));
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
    // x errors 1, −2, 3 mm: Σ 6 mm, mean 2 mm, RMS √(14/3) mm, max 3 mm.
    assert_eq!(st.x.count, 3);
    assert!(close(st.x.sum_abs, 0.006) && close(st.x.mean_abs, 0.002));
    assert!(close(st.x.rms, (14.0f64 / 3.0).sqrt() * 1e-3) && close(st.x.max_abs, 0.003));
    // y errors 0, 4, −4 mm: Σ 8 mm, mean 8/3 mm, RMS √(32/3) mm, max 4 mm.
    assert!(close(st.y.sum_abs, 0.008) && close(st.y.mean_abs, 0.008 / 3.0));
    assert!(close(st.y.rms, (32.0f64 / 3.0).sqrt() * 1e-3) && close(st.y.max_abs, 0.004));
}

#[test]
fn compare_prints_runs_side_by_side() {
    let dir = tmp("compare");
    let mut runs = Vec::new();
    for (name, scale) in [("lipm", 3.0), ("dlipm", 2.0), ("tlipfm", 1.0)] {
        let p = dir.join(format!("{name}.log"));
        std::fs::write(&p, hand_log(scale)).unwrap();
        runs.push(format!("{name}={}", s(&p)));
    }
    let out = dir.join("compare.md");
    let o = walker(&["compare", "--runs", &runs.join(","), "--out", s(&out)]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        stdout.contains("| statistic | lipm | dlipm | tlipfm |"),
        "{stdout}"
    );
    assert!(
        stdout.contains("| Σ\\|e_x\\| (m) | 0.018000 | 0.012000 | 0.006000 |"),
        "{stdout}"
    );
    assert!(
        stdout.contains("Σ|e_x| smallest first: tlipfm < dlipm < lipm"),
        "{stdout}"
    );
    let md = std::fs::read_to_string(&out).unwrap();
    assert!(
        md.contains("| max \\|e_y\\| (m) | 0.012000 | 0.008000 | 0.004000 |"),
        "{md}"
    );
    let o = walker(&[
        "compare",
        "--runs",
        &format!("x={}", s(&dir.join("missing.log"))),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not found"));
}

#[test]
fn capture_from_file_and_missing_port() {
    let dir = tmp("capture");
    let (bytes, kept) = damaged_log();
    let saved = dir.join("saved.bin");
    std::fs::write(&saved, &bytes).unwrap();
    let out = dir.join("walk.log");
    let o = walker(&["capture", "--from-file", s(&saved), "--out", s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(&out).unwrap(), bytes);
    let (_, rows) = read_csv(&dir.join("walk.csv"));
    assert_eq!(rows.len(), kept.len());
    let (_, events) = read_csv(&dir.join("walk.events.csv"));
    assert_eq!(events.len(), 2);

    // `walker capture` from a serial port that does not exist, into x.log.
    let capture_missing = |extra: &[&str]| {
        let x = dir.join("x.log");
        let mut args = vec!["capture", "--port", "/dev/ttyDOESNOTEXIST", "--out", s(&x)];
        args.extend_from_slice(extra);
        walker(&args)
    };
    let o = capture_missing(&["--seconds", "1"]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("serial port /dev/ttyDOESNOTEXIST not found"),
        "{err}"
    );
    // Not a serial port.
    let o = walker(&[
        "capture",
        "--port",
        "/dev/null",
        "--baud",
        "12345",
        "--out",
        s(&dir.join("x.log")),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("cannot open serial port /dev/null"), "{err}");
    // Bad --seconds / --baud: usage errors before any port is opened.
    for (flag, bad) in [
        ("--seconds", "NaN"),
        ("--seconds", "-1"),
        ("--seconds", "0"),
        ("--seconds", "1e300"),
        ("--seconds", "inf"),
        ("--baud", "0"),
        ("--baud", "-5"),
    ] {
        let o = capture_missing(&[flag, bad]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{flag} {bad}: {err}");
        assert!(err.contains(flag), "{flag} {bad}: {err}");
    }
    // --defmt needs --elf (and the other way round); a missing ELF is a failure, not a panic.
    for args in [
        &["capture", "--defmt", "x.defmt"][..],
        &["capture", "--elf", "x.elf", "--list"],
        &["capture", "--list", "--defmt", "x", "--elf", "y"],
    ] {
        assert_eq!(walker(args).status.code(), Some(2), "{args:?}");
    }
    let o = walker(&["capture", "--defmt", s(&saved), "--elf", "/nonexistent.elf"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("cannot read the ELF /nonexistent.elf"));
    // The port listing runs (whatever the machine has).
    let o = walker(&["capture", "--list"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// How a pseudo-terminal capture is ended.
#[cfg(unix)]
#[derive(Clone, Copy, Debug)]
enum PtyEnd {
    /// `--seconds 2`.
    Seconds,
    /// The other end closes (a hang-up).
    HangUp,
    /// SIGINT (Ctrl-C).
    CtrlC,
}

/// Captures the damaged log through a pseudo-terminal (from `serialport`) at `baud`, ended as
/// `how`: the raw bytes and the CSVs must be there whichever way it ends.
#[cfg(unix)]
fn pty_capture(name: &str, baud: &str, how: PtyEnd) {
    use serialport::SerialPort as _;
    use std::io::{BufRead, Read, Write};
    let (master, slave) = serialport::TTYPort::pair().expect("a pseudo-terminal");
    let path = slave.name().expect("the pty's name");
    // The pair's descriptors are inheritable: keep close-on-exec copies only, so that no child
    // (the capture or another test's) holds the master open and hides the hang-up.
    let cloexec = |fd: std::os::fd::RawFd| {
        // SAFETY: `fd` was just released by its TTYPort (`into_raw_fd`): we own it.
        let owned = unsafe { <std::os::fd::OwnedFd as std::os::fd::FromRawFd>::from_raw_fd(fd) };
        std::fs::File::from(owned.try_clone().expect("F_DUPFD_CLOEXEC"))
    };
    use std::os::fd::IntoRawFd as _;
    let mut master = cloexec(master.into_raw_fd());
    let slave = cloexec(slave.into_raw_fd());
    let dir = tmp(name);
    let out = dir.join("walk.log");
    let mut args = vec!["capture", "--port", &path, "--baud", baud, "--out", s(&out)];
    if let PtyEnd::Seconds = how {
        args.extend(["--seconds", "2"]);
    }
    let mut child = Command::new(env!("CARGO_BIN_EXE_walker"))
        .args(&args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The capture prints "capturing …" once the port is open: send after that.
    let mut err = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    err.read_line(&mut line).unwrap();
    assert!(line.starts_with("capturing"), "{line}");
    let (bytes, kept) = damaged_log();
    for chunk in bytes.chunks(333) {
        master.write_all(chunk).unwrap();
    }
    // Wait until the capture has everything on disk, then end it.
    let t0 = std::time::Instant::now();
    while std::fs::metadata(&out).map_or(0, |m| m.len()) < bytes.len() as u64 {
        assert!(
            t0.elapsed().as_secs() < 20,
            "the capture did not read the bytes"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    match how {
        PtyEnd::Seconds => {}
        PtyEnd::HangUp => {
            drop(master);
            drop(slave);
        }
        PtyEnd::CtrlC => {
            let st = Command::new("kill")
                .args(["-INT", &child.id().to_string()])
                .status()
                .unwrap();
            assert!(st.success());
        }
    }
    let t0 = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed().as_secs() > 30 {
            let _ = child.kill();
            panic!("{how:?}: the capture did not end");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let o = child.wait_with_output().unwrap();
    let mut rest = String::new();
    err.read_to_string(&mut rest).unwrap();
    assert!(o.status.success(), "{how:?}: {rest}");
    let want = match how {
        PtyEnd::Seconds => "time is up",
        PtyEnd::HangUp => "hung up",
        PtyEnd::CtrlC => "Ctrl-C",
    };
    assert!(rest.contains(want), "{how:?}: {rest}");
    assert_eq!(std::fs::read(&out).unwrap(), bytes);
    let (_, rows) = read_csv(&dir.join("walk.csv"));
    assert_eq!(rows.len(), kept.len());
    let (_, events) = read_csv(&dir.join("walk.events.csv"));
    assert_eq!(events.len(), 2);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("99 good records (97 ticks, 2 events), 5 bad"),
        "{stdout}"
    );
}

/// One test, run in turn: each capture's pseudo-terminal must not leak into another's child.
#[cfg(unix)]
#[test]
fn capture_from_a_pseudo_terminal() {
    pty_capture("pty", "921600", PtyEnd::Seconds);
    // 250 000 and 1 234 567 baud are no standard termios rates.
    pty_capture("pty-hangup", "250000", PtyEnd::HangUp);
    pty_capture("pty-ctrlc", "1234567", PtyEnd::CtrlC);
}

#[test]
fn report_with_truth_file() {
    let dir = tmp("truth");
    let log = dir.join("walk.log");
    std::fs::write(&log, hand_log(1.0)).unwrap();
    // The sim's truth CSV: t_s plus more columns; the true ZMP equals the reference here.
    let truth = dir.join("truth.csv");
    let mut t = String::from(
        "t_s,zmp_x_m,zmp_y_m,fz_n,support,l_f0_n,l_f1_n,l_f2_n,l_f3_n,r_f0_n,r_f1_n,r_f2_n,r_f3_n\n",
    );
    for k in 0..4 {
        t.push_str(&format!(
            "{:.6},0.010000,-0.020000,48.5,D,1,2,3,4,5,6,7,{k}\n",
            1.0 + k as f64 * 1e-3
        ));
    }
    std::fs::write(&truth, t).unwrap();
    let out = dir.join("report");
    let stdout = report_ok(&log, &truth, &out, &["--model", "lipm"]);
    let x_row = "| x (sagittal) | 3 | 0.006000 | 0.002000 | 0.002160 | 0.003000 |";
    assert_eq!(stdout.matches(x_row).count(), 2, "{stdout}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("Measured − true ZMP") && md.contains("LIPM"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).unwrap()).unwrap();
    assert_eq!(json["truth_error"]["x"]["count"], 3);
    assert_eq!(json["model"], "lipm");
    // Load cells in the truth: the foot-force figure; no joint columns: no joint figures.
    assert!(out.join("foot_forces.png").is_file() && out.join("foot_forces.svg").is_file());
    assert!(!out.join("joint_speeds.png").exists());
    let tr = report::read_truth(&truth).unwrap();
    assert_eq!(tr.column("r_f3_n"), Some(&[0.0, 1.0, 2.0, 3.0][..]));
    assert!(tr.column("support").unwrap().iter().all(|v| v.is_nan()));
    assert!(report::foot_force_figure("f", &tr).is_some());
    let speed = walker_host::sim::truth::joint_speed_column;
    assert!(report::joint_figure("j", &tr, speed, "rad/s", None).is_none());
}

/// 5 KB of random bytes (xorshift, fixed seed): nothing decodes.
fn random_bytes() -> Vec<u8> {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    (0..5 * 1024)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

/// Logs no reader may accept, each with the words its refusal must contain.
fn unusable_logs() -> Vec<(&'static str, Vec<u8>, &'static str)> {
    // Only standing ticks: decodable, but the firmware never walked.
    let mut standing = vec![0u8];
    standing.extend(frame(&startup(0, 1000, true)));
    for seq in 1..50u16 {
        standing.extend(frame(&tick(seq, [0.0, 0.0], None, LoggedPhase::Standing)));
    }
    // Walking ticks, but no start-up record (not the firmware's whole run).
    let mut headless = vec![0u8];
    for seq in 1..50u16 {
        headless.extend(frame(&tick(
            seq,
            [0.0, 0.0],
            Some([0.001, 0.0]),
            LoggedPhase::Double,
        )));
    }
    // A start-up record and nothing else.
    let mut startup_only = vec![0u8];
    startup_only.extend(frame(&startup(0, 1000, true)));
    vec![
        ("random.log", random_bytes(), "no firmware log record"),
        ("empty.log", Vec::new(), "is empty"),
        ("standing.log", standing, "no walking record"),
        ("headless.log", headless, "no start-up record"),
        ("startup-only.log", startup_only, "no tick record"),
    ]
}

#[test]
fn report_refuses_logs_without_a_walk() {
    let dir = tmp("refuse");
    for (name, bytes, want) in unusable_logs() {
        let path = dir.join(name);
        std::fs::write(&path, &bytes).unwrap();
        let out = dir.join(format!("{name}.report"));
        let o = walker(&["report", "--log", s(&path), "--out", s(&out)]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains(want) && err.contains(name), "{name}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{name}: one line: {err}");
        assert!(
            !out.join("zmp_response.png").exists(),
            "{name}: plots written"
        );
    }
}

#[test]
fn compare_refuses_what_report_refuses() {
    let dir = tmp("compare-refuse");
    let good = dir.join("good.log");
    std::fs::write(&good, hand_log(1.0)).unwrap();
    let mut cases = unusable_logs();
    // Decodable and walking, but never a valid measured ZMP: it would rank best at 0.000.
    let mut blind = vec![0u8];
    blind.extend(frame(&startup(0, 1000, true)));
    for seq in 1..20u16 {
        blind.extend(frame(&tick(seq, [0.01, 0.0], None, LoggedPhase::Double)));
    }
    cases.push(("blind.log", blind, "no tick with a valid measured ZMP"));
    for (name, bytes, want) in cases {
        let path = dir.join(name);
        std::fs::write(&path, &bytes).unwrap();
        let out = dir.join(format!("{name}.md"));
        let runs = format!("good={},bad={}", s(&good), s(&path));
        let o = walker(&["compare", "--runs", &runs, "--out", s(&out)]);
        let err = String::from_utf8_lossy(&o.stderr);
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert_eq!(o.status.code(), Some(1), "{name}: {err}");
        assert!(
            err.contains(want) && err.contains("run bad"),
            "{name}: {err}"
        );
        assert!(
            !stdout.contains("smallest first"),
            "{name} ranked: {stdout}"
        );
        assert!(!out.exists(), "{name}: {} written", out.display());
    }
}

#[test]
fn capture_refuses_garbage_and_empty_captures() {
    let dir = tmp("capture-refuse");
    for (name, bytes, want) in unusable_logs() {
        // capture decodes any log, walking or not: only the non-walking one passes.
        if name == "standing.log" {
            continue;
        }
        let path = dir.join(name);
        std::fs::write(&path, &bytes).unwrap();
        let out = dir.join(format!("out-{name}"));
        let o = walker(&["capture", "--from-file", s(&path), "--out", s(&out)]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains(want), "{name}: {err}");
        assert!(
            !dir.join(format!("out-{name}"))
                .with_extension("csv")
                .exists(),
            "{name}"
        );
    }
    // --defmt on random bytes and on an empty file: refused whatever ELF (here the firmware's
    // own table is not needed: an ELF with no defmt table is refused too, so build the check
    // on a real ELF only when there is one).
    let elf = workspace().join("target/thumbv7em-none-eabihf/release/qemu");
    if elf.is_file() {
        for (name, bytes) in [
            ("random.defmt", random_bytes()),
            ("empty.defmt", Vec::new()),
        ] {
            let path = dir.join(name);
            std::fs::write(&path, &bytes).unwrap();
            let o = walker(&["capture", "--defmt", s(&path), "--elf", s(&elf)]);
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(1), "{name}: {err}");
            assert!(err.contains(name), "{name}: {err}");
        }
    }
}

/// The synthetic walk's log cut at half its bytes: every reader warns where it ends (no stop
/// record) and goes on.
#[test]
fn readers_warn_of_a_log_cut_at_half() {
    let dir = tmp("cut");
    let (log, truth, _) = synthetic_walk(&dir);
    let bytes = std::fs::read(&log).unwrap();
    let cut = dir.join("cut.log");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let whole = report::decode_bytes(&bytes);
    let half = report::decode_bytes(&bytes[..bytes.len() / 2]);
    let end = report::tick_rows(&half.ticks).last().unwrap().t;
    assert!(half.ticks.len() * 2 <= whole.ticks.len() + 2);
    let want = format!("ends at t = {end:.3} s");
    let check = |o: &Output, what: &str| {
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{what}: {err}");
        assert!(
            err.contains("warning:") && err.contains("no stop record") && err.contains(&want),
            "{what}: {err}"
        );
    };
    // report (with the whole truth: it covers the cut log, no truth warning).
    let out = dir.join("report");
    let o = walker(&[
        "report",
        "--log",
        s(&cut),
        "--truth",
        s(&truth),
        "--out",
        s(&out),
    ]);
    check(&o, "report");
    assert!(!String::from_utf8_lossy(&o.stderr).contains("truth file"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).unwrap()).unwrap();
    assert!(
        json["warnings"][0].as_str().unwrap().contains(&want),
        "{json}"
    );
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("**warning**") && md.contains(&want), "{md}");
    // compare, against the whole log.
    let runs = format!("whole={},cut={}", s(&log), s(&cut));
    let o = walker(&["compare", "--runs", &runs, "--out", s(&dir.join("c.md"))]);
    check(&o, "compare");
    assert!(String::from_utf8_lossy(&o.stderr).contains("run cut"));
    assert!(!String::from_utf8_lossy(&o.stderr).contains("run whole"));
    // capture --from-file.
    let o = walker(&[
        "capture",
        "--from-file",
        s(&cut),
        "--out",
        s(&dir.join("cap.log")),
    ]);
    check(&o, "capture");
    // The whole log: no warning at all.
    let o = walker(&[
        "report",
        "--log",
        s(&log),
        "--truth",
        s(&truth),
        "--out",
        s(&out),
    ]);
    assert!(o.status.success());
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("warning"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// A truth file that covers a fifth of the log: the report says how much.
#[test]
fn report_warns_of_a_partial_truth() {
    let dir = tmp("partial-truth");
    let (log, truth, _) = synthetic_walk(&dir);
    let text = std::fs::read_to_string(&truth).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let keep = 1 + (lines.len() - 1) / 5;
    let part = dir.join("part.csv");
    std::fs::write(&part, lines[..keep].join("\n") + "\n").unwrap();
    let o = walker(&[
        "report",
        "--log",
        s(&log),
        "--truth",
        s(&part),
        "--out",
        s(&dir.join("report")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("warning: the truth file") && err.contains("covers 20 % of the log"),
        "{err}"
    );
}

/// A start-up `TimingStretched` record: the plan drawn (support bounds, MCAP joint targets) is
/// the stretched one, and the report says so.
#[test]
fn report_draws_the_stretched_plan() {
    let dir = tmp("stretch");
    let (log, truth, _) = synthetic_walk(&dir);
    let bytes = std::fs::read(&log).unwrap();
    let head = 1 + frame(&startup(0, 5000, true)).len();
    let mut stretched = bytes[..head].to_vec();
    stretched.extend(frame(&Record::Fault(
        walker_contract::record::FaultRecord {
            seq: 0,
            time_us: 0,
            kind: walker_contract::FaultKind::TimingStretched,
            id: 9,
            value: 1264,
        },
    )));
    stretched.extend(&bytes[head..]);
    let slog = dir.join("stretched.log");
    std::fs::write(&slog, &stretched).unwrap();
    let targets = |log: &Path, name: &str| {
        let mcap_path = dir.join(format!("{name}.mcap"));
        let out = dir.join(name);
        report_ok(log, &truth, &out, &["--mcap", s(&mcap_path)]);
        let bytes = std::fs::read(&mcap_path).unwrap();
        let n = mcap::MessageStream::new(&bytes)
            .unwrap()
            .filter(|m| m.as_ref().unwrap().channel.topic == "/joints/target")
            .count();
        (n, out)
    };
    let (plain, plain_out) = targets(&log, "plain");
    let (longer, out) = targets(&slog, "stretched");
    // The walk part of the plan is 1.264 times longer; the lead-in and the hold are not.
    assert!(longer as f64 > plain as f64 * 1.15, "{plain} → {longer}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("step timing stretched ×1.264"), "{md}");
    assert!(md.contains("right knee") || md.contains("r_knee"), "{md}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).unwrap()).unwrap();
    assert!(json["plan_adjustments"][0]
        .as_str()
        .unwrap()
        .contains("×1.264"));
    let plain_md = std::fs::read_to_string(plain_out.join("report.md")).unwrap();
    assert!(plain_md.contains("plan adjustments at start-up: none logged"));
}

/// A synthetic 14-step walk (Table 2 through the plan's own trajectory): the firmware log
/// (standing lead-in, then walking ticks; measured ZMP 1 mm ahead) and a truth CSV with every
/// column of the simulator's header.
fn synthetic_walk(dir: &Path) -> (PathBuf, PathBuf, usize) {
    let spec = planfile::load(&workspace().join("plans/table2.toml")).unwrap();
    let (rows, _) = export::export_rows(&spec, &Robot::reference(), 0.005).unwrap();
    let mut log = vec![0u8];
    log.extend(frame(&startup(0, 5000, true)));
    let header: Vec<&str> = walker_host::sim::truth::HEADER.split(',').collect();
    let mut truth = format!("{}\n", header.join(","));
    for (i, r) in rows.iter().enumerate() {
        let phase = if r.t < 1.6 {
            LoggedPhase::Standing
        } else {
            LoggedPhase::Double
        };
        let mut t = TickRecord {
            seq: (i + 1) as u16,
            time_us: (r.t * 1e6).round() as u32 + 5000,
            phase,
            zmp_valid: true,
            ..TickRecord::default()
        };
        t.set_zmp_ref_m(r.zmp[0] as f32, r.zmp[1] as f32);
        t.set_zmp_meas_m(r.zmp[0] as f32 + 0.001, r.zmp[1] as f32);
        t.set_com_m(r.com[0] as f32, r.com[1] as f32);
        log.extend(frame(&Record::Tick(t)));
        let vals: Vec<String> = header
            .iter()
            .map(|h| match *h {
                "t_s" => format!("{:.6}", r.t + 0.005),
                "zmp_x_m" => format!("{:.6}", r.zmp[0]),
                "zmp_y_m" => format!("{:.6}", r.zmp[1]),
                "support" => "D".into(),
                "stance" => "L".into(),
                "pelvis_z_m" => "0.217".into(),
                h if h.starts_with("l_f") || h.starts_with("r_f") => "12.5".into(),
                _ => format!("{:.4}", (i as f64 * 0.01).sin()),
            })
            .collect();
        truth.push_str(&vals.join(","));
        truth.push('\n');
    }
    log.extend(frame(&Record::Stop(StopRecord {
        seq: rows.len() as u16 + 1,
        time_us: 13_000_000,
        reason: StopReason::PlanDone,
    })));
    let (lp, tp) = (dir.join("walk.log"), dir.join("truth.csv"));
    std::fs::write(&lp, log).unwrap();
    std::fs::write(&tp, truth).unwrap();
    (lp, tp, rows.len())
}

#[test]
fn mcap_of_a_14_step_walk_holds_every_channel() {
    let dir = tmp("mcap");
    let (log, truth, ticks) = synthetic_walk(&dir);
    let mcap_path = dir.join("run.mcap");
    let stdout = report_ok(
        &log,
        &truth,
        &dir.join("report"),
        &["--mcap", s(&mcap_path)],
    );
    assert!(stdout.contains("run.mcap: 15 channels"), "{stdout}");
    // The report's joint and foot figures come from the same truth.
    for f in ["joint_speeds.png", "joint_torques.svg", "foot_forces.png"] {
        assert!(dir.join("report").join(f).is_file(), "{f}");
    }
    let bytes = std::fs::read(&mcap_path).unwrap();
    let mut count: std::collections::BTreeMap<String, usize> = Default::default();
    let mut last_time = 0u64;
    let mut pose = None;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.channel.message_encoding, "json");
        let schema = m.channel.schema.as_ref().expect("a schema");
        assert_eq!(schema.encoding, "jsonschema");
        assert!(m.log_time >= last_time, "messages in time order");
        last_time = m.log_time;
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        if m.channel.topic == "/torso_pose" && pose.is_none() {
            pose = Some(v);
        }
        *count.entry(m.channel.topic.clone()).or_default() += 1;
    }
    for topic in [
        "/zmp/reference",
        "/zmp/measured",
        "/zmp/true",
        "/com",
        "/com/true",
        "/foot_forces",
        "/imu",
        "/torso_pose",
        "/joints",
        "/joints/target",
        "/events",
    ] {
        assert!(
            count.get(topic).copied().unwrap_or(0) > 0,
            "{topic}: {count:?}"
        );
    }
    assert_eq!(count["/zmp/reference"], ticks);
    assert_eq!(count["/zmp/measured"], ticks);
    assert_eq!(count["/events"], 2);
    let pose = pose.unwrap();
    assert_eq!(pose["frame_id"], "world");
    assert_eq!(pose["pose"]["position"]["z"], 0.217);
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    assert_eq!(summary.channels.len(), 15);
    assert_foxglove_ready(&bytes);
    // The transforms follow the plan's joint targets at ≤ 50 Hz over the whole walk.
    let tf = count["/tf"];
    assert!(
        tf * 4 <= ticks + 4 && tf * 4 + 8 >= ticks,
        "{tf} transforms for {ticks} ticks at 200 Hz"
    );
}

/// The Foxglove-ready parts of an MCAP of a run (`walker report --mcap`, `walker fil --mcap`):
/// zstd chunks, `foxglove.FrameTransforms` from the world through the pelvis to both soles,
/// the URDF as an attachment and on `/robot_description`, events as `foxglove.Log`, the
/// `foxglove.SceneUpdate` scene and footsteps, and the `robot`, `plan`, `firmware` metadata.
fn assert_foxglove_ready(bytes: &[u8]) {
    let summary = mcap::Summary::read(bytes).unwrap().expect("a summary");
    assert!(!summary.chunk_indexes.is_empty(), "chunked");
    for c in &summary.chunk_indexes {
        assert_eq!(c.compression, "zstd", "chunk at {}", c.chunk_start_offset);
        assert!(c.compressed_size < c.uncompressed_size, "{c:?}");
    }
    let schema_of = |topic: &str| -> String {
        let ch = summary
            .channels
            .values()
            .find(|c| c.topic == topic)
            .unwrap_or_else(|| panic!("no channel {topic}"));
        ch.schema.as_ref().expect("a schema").name.clone()
    };
    assert_eq!(schema_of("/tf"), "foxglove.FrameTransforms");
    assert_eq!(schema_of("/events"), "foxglove.Log");
    assert_eq!(schema_of("/scene"), "foxglove.SceneUpdate");
    assert_eq!(schema_of("/footsteps"), "foxglove.SceneUpdate");
    assert_eq!(schema_of("/robot_description"), "std_msgs/String");
    // The URDF attachment.
    let urdf_index = summary
        .attachment_indexes
        .iter()
        .find(|a| a.name == "robot.urdf")
        .expect("a robot.urdf attachment");
    let urdf = mcap::read::attachment(bytes, urdf_index).unwrap();
    let urdf = std::str::from_utf8(&urdf.data).unwrap().to_string();
    for j in walker_host::sim::urdf::tree(&Robot::reference()) {
        assert!(
            urdf.contains(&format!("<joint name=\"{}\"", j.name)),
            "{}",
            j.name
        );
    }
    let names: Vec<&str> = summary
        .metadata_indexes
        .iter()
        .map(|m| m.name.as_str())
        .collect();
    for m in ["robot", "plan", "firmware"] {
        assert!(names.contains(&m), "metadata {m}: {names:?}");
    }
    let mut logs = 0;
    let mut tf_frames = None;
    let mut description = None;
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        match m.channel.topic.as_str() {
            "/events" => {
                logs += 1;
                assert!(
                    v["level"].as_u64().is_some_and(|l| (1..=5).contains(&l)),
                    "{v}"
                );
                assert!(!v["message"].as_str().unwrap().is_empty(), "{v}");
                assert!(v["timestamp"]["sec"].is_u64(), "{v}");
            }
            "/tf" if tf_frames.is_none() => {
                let list = v["transforms"].as_array().unwrap();
                let pairs: Vec<(String, String)> = list
                    .iter()
                    .map(|t| {
                        let f = |k: &str| t[k].as_str().unwrap().to_string();
                        (f("parent_frame_id"), f("child_frame_id"))
                    })
                    .collect();
                tf_frames = Some(pairs);
            }
            "/robot_description" => description = v["data"].as_str().map(str::to_string),
            _ => {}
        }
    }
    assert!(logs > 0, "foxglove.Log messages");
    assert_eq!(description.as_deref(), Some(urdf.as_str()));
    // Every link of the URDF is reached from `world` by the transforms.
    let pairs = tf_frames.expect("a /tf message");
    let mut reached = vec!["world".to_string()];
    for (parent, child) in &pairs {
        assert!(reached.contains(parent), "{parent} → {child}: {pairs:?}");
        reached.push(child.clone());
    }
    for s in ["l_sole", "r_sole", "pelvis"] {
        assert!(reached.iter().any(|r| r == s), "{s}: {pairs:?}");
    }
}

/// `--config`: one file per run; a typo is refused with the field's path before anything starts.
#[test]
fn run_configuration_file_errors_name_the_field() {
    let dir = tmp("runconfig");
    let bad = dir.join("run.toml");
    std::fs::write(&bad, "[sim]\nfloor_frction = 0.5\n").unwrap();
    for cmd in ["fil", "beyond", "sweep"] {
        let o = walker(&[cmd, "--config", s(&bad), "--elf", "/nonexistent"]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{cmd}: {err}");
        assert!(
            err.contains("run.toml: field `sim.floor_frction`: unknown field")
                && err.contains("`floor_friction`"),
            "{cmd}: {err}"
        );
        // --config and --plan exclude each other.
        let o = walker(&[cmd, "--config", s(&bad), "--plan", "plans/table2.toml"]);
        assert_eq!(o.status.code(), Some(2));
    }
    // The example is valid; a bad --firmware-args on top of it is still caught before QEMU.
    let o = walker(&[
        "fil",
        "--config",
        "plans/run-example.toml",
        "--elf",
        "/nonexistent",
        "--firmware-args",
        "stab_kp=20",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("`stab_kp=20`: out of range"), "{err}");
}

/// `NAME = value` (an integer, decimal or hex) from a Python file's top level.
fn python_constant(text: &str, name: &str) -> i64 {
    let line = text
        .lines()
        .find(|l| l.starts_with(&format!("{name} = ")))
        .unwrap_or_else(|| panic!("{name} not in the Python test"));
    let v = line[name.len() + 3..]
        .split('#')
        .next()
        .unwrap_or_default()
        .trim();
    match v.strip_prefix("0x") {
        Some(h) => i64::from_str_radix(h, 16).unwrap(),
        None => v.parse().unwrap_or_else(|e| panic!("{name} = {v}: {e}")),
    }
}

#[test]
fn sdk_example_uses_the_contract_registers() {
    use walker_contract::command_port::{self as port, Mode, PortState};
    // The example's register map (the SDK test imports it) and the test's own codes.
    let read = |p: &str| std::fs::read_to_string(workspace().join(p)).unwrap();
    let example = read("host/examples/sdk_drive.py");
    let test = read("host/tests/sdk/test_sdk_command_port.py");
    let c = |n: &str| python_constant(&example, n);
    let t = |n: &str| python_constant(&test, n);
    let regs = [
        ("ADDR_MODEL", port::MODEL_NUMBER.addr),
        ("ADDR_FIRMWARE_VERSION", port::FIRMWARE_VERSION.addr),
        ("ADDR_ID", port::ID.addr),
        ("ADDR_MODE", port::MODE.addr),
        ("ADDR_VELOCITY_X", port::VELOCITY_X.addr),
        ("ADDR_HEARTBEAT", port::HEARTBEAT.addr),
        ("ADDR_STATUS", port::STATE.addr),
        ("ADDR_STEP_COUNT", port::STEP_COUNT.addr),
        ("ADDR_COMMAND_COUNT", port::COMMAND_COUNT.addr),
    ];
    for (name, addr) in regs {
        assert_eq!(c(name), i64::from(addr), "{name}");
    }
    // The status block: State to the end of Supply Voltage, the registers in the order decoded.
    let end = port::SUPPLY_VOLTAGE.addr + port::SUPPLY_VOLTAGE.len;
    assert_eq!(c("STATUS_LEN"), i64::from(end - port::STATE.addr));
    assert_eq!(
        (port::STATUS_BLOCK.addr, port::STATUS_BLOCK.len),
        (port::STATE.addr, end - port::STATE.addr)
    );
    let decoded = [
        (port::STATE, 0),
        (port::SUPPORT_FOOT, 1),
        (port::STEP_COUNT, 2),
        (port::ZMP_X, 4),
        (port::ZMP_Y, 6),
        (port::ZMP_VALID, 8),
        (port::STOP_CODE, 9),
        (port::FAULT_KIND, 10),
        (port::STEP_LIST, 11),
        (port::WALK_VX, 12),
        (port::WALK_VY, 14),
        (port::WALK_YAW, 16),
        (port::COMMAND_COUNT, 18),
        (port::SERVO_STIFFNESS, 20),
        (port::SUPPLY_VOLTAGE, 22),
    ];
    for (r, off) in decoded {
        assert_eq!(
            r.addr - port::STATE.addr,
            off,
            "status block offset of {}",
            r.addr
        );
    }
    assert_eq!(c("PORT_ID"), i64::from(port::PORT_ID));
    assert_eq!(c("PORT_MODEL"), i64::from(port::MODEL_NUMBER_VALUE));
    assert_eq!(c("VELOCITY_X_MAX"), i64::from(port::VELOCITY_RANGE[0].1));
    assert_eq!(
        c("STOP_CODE_DEADMAN"),
        i64::from(walker_contract::StopCode::Deadman.code())
    );
    for (name, m) in [
        ("MODE_TORQUE_OFF", Mode::TorqueOff),
        ("MODE_STAND", Mode::Stand),
        ("MODE_WALK", Mode::Walk),
        ("MODE_STOP", Mode::Stop),
    ] {
        assert_eq!(c(name), i64::from(m.code()), "{name}");
    }
    assert_eq!(c("STATE_STANDING"), i64::from(PortState::Standing.code()));
    assert_eq!(c("STATE_WALKING"), i64::from(PortState::Walking.code()));
    for (name, e) in [
        ("ERR_DATA_RANGE", dxl::ErrorCode::DataRange),
        ("ERR_DATA_LENGTH", dxl::ErrorCode::DataLength),
        ("ERR_ACCESS", dxl::ErrorCode::Access),
    ] {
        let byte = dxl::StatusError {
            alert: false,
            code: Some(e),
        }
        .to_byte();
        assert_eq!(t(name), i64::from(byte), "{name}");
    }
    // The bad velocity the test sends is out of range.
    assert!(300 > port::VELOCITY_RANGE[0].1 && -300 < port::VELOCITY_RANGE[0].0);
}

/// `walker flash` refuses what it can before it touches the port: a missing image, one over
/// the limit, one not linked for 0x0804_0000, bad option values.
#[test]
fn flash_refuses_before_touching_the_port() {
    let dir = tmp("flash");
    let port = "/dev/ttyDOESNOTEXIST";
    let err = |o: &Output| String::from_utf8_lossy(&o.stderr).into_owned();
    let o = walker(&["flash", "--serial", port, "/nonexistent/opencr.bin"]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(
        err(&o).contains("/nonexistent/opencr.bin not found"),
        "{}",
        err(&o)
    );
    // A vector table for 0x0804_0000, then filler up to 256 KiB + 1.
    let mut image = [0x2005_0000u32.to_le_bytes(), 0x0804_0101u32.to_le_bytes()].concat();
    image.resize(256 * 1024 + 1, 0x5A);
    let big = dir.join("big.bin");
    std::fs::write(&big, &image).unwrap();
    let o = walker(&["flash", "--serial", port, s(&big)]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(
        err(&o).contains("over --limit-kib 256 (nothing was sent)") && !err(&o).contains(port),
        "{}",
        err(&o)
    );
    // Within a larger limit it goes as far as the port (the 1200-baud touch opens it).
    let o = walker(&["flash", "--serial", port, "--limit-kib", "512", s(&big)]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(
        err(&o).contains(&format!("serial port {port} not found")),
        "{}",
        err(&o)
    );
    // An image linked for 0x0800_0000 (reset vector 0x080001C9).
    image[4..8].copy_from_slice(&0x0800_01C9u32.to_le_bytes());
    image.truncate(4096);
    let wrong = dir.join("wrong.bin");
    std::fs::write(&wrong, &image).unwrap();
    let o = walker(&["flash", "--serial", port, s(&wrong)]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(err(&o).contains("reset vector 0x080001C9"), "{}", err(&o));
    // Usage errors.
    for args in [
        &["flash", s(&big)][..],
        &["flash", "--serial", port],
        &["flash", "--serial", port, "--limit-kib", "0", s(&big)],
        &["flash", "--serial", port, "--limit-kib", "769", s(&big)],
        &["flash", "--serial", port, "--block-kib", "17", s(&big)],
        &["flash", "--serial", port, "--baud", "0", s(&big)],
    ] {
        let o = walker(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", err(&o));
    }
    let o = walker(&["flash", "--help"]);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("Usage: walker flash"));
}

/// `walker flash --board opencm` refuses what it can before it touches the port: a missing
/// image, one over the 114 KiB the bootloader erases, one not linked for 0x0800_3000, the
/// OpenCR-only options.
#[test]
fn flash_opencm_refuses_before_touching_the_port() {
    let dir = tmp("flash-opencm");
    let port = "/dev/ttyDOESNOTEXIST";
    let err = |o: &Output| String::from_utf8_lossy(&o.stderr).into_owned();
    let cm = |rest: &[&str]| {
        let mut args = vec!["flash", "--board", "opencm", "--serial", port];
        args.extend_from_slice(rest);
        walker(&args)
    };
    let o = cm(&["/nonexistent/opencm"]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(
        err(&o).contains("/nonexistent/opencm not found"),
        "{}",
        err(&o)
    );
    // A vector table for 0x0800_3000, then filler up to 114 KiB + 1.
    let mut image = [0x2000_5000u32.to_le_bytes(), 0x0800_3101u32.to_le_bytes()].concat();
    image.resize(114 * 1024 + 1, 0x5A);
    let big = dir.join("big.bin");
    std::fs::write(&big, &image).unwrap();
    let o = cm(&[s(&big)]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(
        err(&o).contains("over --limit-kib 114 (nothing was sent)") && !err(&o).contains(port),
        "{}",
        err(&o)
    );
    // Within the limit it goes as far as the port (the reset request opens it).
    image.truncate(100 * 1024);
    let fits = dir.join("fits.bin");
    std::fs::write(&fits, &image).unwrap();
    let o = cm(&[s(&fits)]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(
        err(&o).contains(&format!("serial port {port} not found")),
        "{}",
        err(&o)
    );
    let o = cm(&["--limit-kib", "64", s(&fits)]);
    assert!(err(&o).contains("over --limit-kib 64"), "{}", err(&o));
    // An OpenCR image (reset vector in sector 5) and an ELF linked for 0x0800_0000.
    image[4..8].copy_from_slice(&0x0804_0101u32.to_le_bytes());
    let opencr = dir.join("opencr.bin");
    std::fs::write(&opencr, &image).unwrap();
    let o = cm(&[s(&opencr)]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(
        err(&o).contains("reset vector 0x08040101") && err(&o).contains("board-opencm"),
        "{}",
        err(&o)
    );
    // Usage errors: the OpenCR-only options, a limit over the erased region.
    for (args, says) in [
        (
            &["--no-read-back", s(&fits)][..],
            "--no-read-back is an OpenCR option",
        ),
        (
            &["--block-kib", "8", s(&fits)][..],
            "--block-kib is an OpenCR option",
        ),
        (&["--limit-kib", "115", s(&fits)][..], "over the 114 KiB"),
    ] {
        let o = cm(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", err(&o));
        assert!(err(&o).contains(says), "{args:?}: {}", err(&o));
    }
    let o = walker(&["flash", "--board", "opencx", "--serial", port, s(&fits)]);
    assert_eq!(o.status.code(), Some(2), "{}", err(&o));
    let o = walker(&["flash", "--help"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("opencm"));
}
