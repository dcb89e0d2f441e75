//! No robot's leg dimension, servo ID list or joint signs outside its description: the
//! workspace's product source (every crate's `src/`, less `#[cfg(test)]` code and comments)
//! is scanned for each described robot's numbers.
//!
//! What a literal scan can tell: a leg dimension written with three or more significant digits
//! (all of the OP3's: 0.11015, 0.0305, …) is that robot's and nothing else's; the reference
//! robot's round dimensions (0.1 m, 0.03 m, 0.045 m) also stand for gains, Table 2's S_W and
//! H_z and servo model constants, so they are checked by behaviour instead
//! (`host/tests/mujoco.rs`: a made-up robot's MuJoCo model puts its soles where its
//! description's FK does; gait-core `tests/robots.rs`: each robot's IK and reach check). The
//! leg ID list and the mounting signs are scanned as the sequences a copy would write.

use std::path::{Path, PathBuf};

/// The product source: every `.rs` file under the crates' `src/` folders, without the robot
/// descriptions themselves (gait-core `src/robot/`).
fn product_sources() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut out = Vec::new();
    let mut stack: Vec<PathBuf> = [
        "src",
        "gait-core/src",
        "contract/src",
        "dxl/src",
        "host/src",
    ]
    .iter()
    .map(|d| root.join(d))
    .collect();
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                if !p.ends_with("gait-core/src/robot") {
                    stack.push(p);
                }
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    assert!(out.len() > 50, "{} files", out.len());
    out
}

/// A file's code: `#[cfg(test)]` items and the test-only files cut, comments and string
/// literals blanked.
fn code_of(path: &Path) -> String {
    let name = path.file_name().unwrap().to_string_lossy();
    if name == "tests.rs" || name.ends_with("_tests.rs") {
        return String::new();
    }
    let text = std::fs::read_to_string(path).unwrap();
    let text = match text.find("#[cfg(test)]") {
        Some(i) => &text[..i],
        None => &text[..],
    };
    let mut out = String::new();
    for line in text.lines() {
        let code = line.split("//").next().unwrap_or("");
        let mut in_str = false;
        for c in code.chars() {
            if c == '"' {
                in_str = !in_str;
            }
            out.push(if in_str { ' ' } else { c });
        }
        out.push('\n');
    }
    out
}

/// The number literals of `code` (digits, a point, digits; an exponent), as written.
fn float_literals(code: &str) -> Vec<String> {
    let b = code.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts = b[i].is_ascii_digit()
            && (i == 0
                || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_' || b[i - 1] == b'.'));
        if !starts {
            i += 1;
            continue;
        }
        let s = i;
        while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'_') {
            i += 1;
        }
        if i + 1 < b.len() && b[i] == b'.' && b[i + 1].is_ascii_digit() {
            i += 1;
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'_') {
                i += 1;
            }
            out.push(code[s..i].replace('_', ""));
        }
    }
    out
}

/// Significant digits of a decimal literal ("0.0305" → 3, "0.100" → 1).
fn significant_digits(lit: &str) -> usize {
    let digits: String = lit.chars().filter(char::is_ascii_digit).collect();
    digits.trim_start_matches('0').trim_end_matches('0').len()
}

/// A robot's leg dimensions (m) from its description.
fn leg_dimensions(r: &gait_core::Robot) -> Vec<f64> {
    let g = &r.geometry;
    let mut v = vec![
        g.hip_offset_y,
        g.thigh,
        g.calf,
        g.ankle_height,
        g.sole_offset[0],
        g.sole_offset[1],
        g.hip_yaw_height,
        g.sole_length,
        g.sole_width,
    ];
    v.extend(g.force_sensors.iter().flatten());
    v.retain(|x| *x != 0.0);
    v.iter().map(|x| x.abs()).collect()
}

/// `seq` written as a Rust list would be (`a, b, c`), with any spacing.
fn contains_sequence(code: &str, seq: &[i64]) -> bool {
    let squeezed: String = code.chars().filter(|c| !c.is_whitespace()).collect();
    let want: Vec<String> = seq.iter().map(i64::to_string).collect();
    let want = want.join(",");
    squeezed.match_indices(&want).any(|(i, _)| {
        let before = squeezed[..i].chars().last();
        let after = squeezed[i + want.len()..].chars().next();
        !before.is_some_and(|c| c.is_ascii_digit() || c == '-')
            && !after.is_some_and(|c| c.is_ascii_digit())
    })
}

#[test]
fn no_leg_dimension_id_list_or_sign_outside_the_descriptions() {
    let files: Vec<(PathBuf, String)> = product_sources()
        .into_iter()
        .map(|p| {
            let c = code_of(&p);
            (p, c)
        })
        .collect();
    let mut found = Vec::new();
    for robot in gait_core::robot::ROBOTS.iter() {
        let dims: Vec<f64> = leg_dimensions(robot);
        let legs: Vec<i64> = robot.bus.legs.iter().map(|&i| i64::from(i)).collect();
        let signs: Vec<i64> = robot.mounting.iter().map(|&s| i64::from(s)).collect();
        let mixed_signs = signs.iter().any(|&s| s != signs[0]);
        for (path, code) in &files {
            for lit in float_literals(code) {
                let v: f64 = lit.parse().unwrap();
                if significant_digits(&lit) >= 3 && dims.contains(&v) {
                    found.push(format!(
                        "{}: {} leg dimension {lit}",
                        path.display(),
                        robot.name
                    ));
                }
            }
            if contains_sequence(code, &legs) {
                found.push(format!(
                    "{}: {} leg IDs {legs:?}",
                    path.display(),
                    robot.name
                ));
            }
            if mixed_signs && contains_sequence(code, &signs) {
                found.push(format!("{}: {} mounting signs", path.display(), robot.name));
            }
        }
    }
    assert!(
        found.is_empty(),
        "outside the descriptions:\n{}",
        found.join("\n")
    );
}

/// The scan finds what it looks for: each robot's own description file holds its distinctive
/// dimensions, its leg IDs and (where they differ) its signs, as the scan reads them.
#[test]
fn the_scan_finds_each_robots_numbers_in_its_own_description() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../gait-core/src/robot");
    for (robot, file) in [
        (gait_core::Robot::reference(), "tku_x.rs"),
        (gait_core::Robot::op3(), "op3.rs"),
    ] {
        let code = code_of(&dir.join(file));
        let lits: Vec<f64> = float_literals(&code)
            .iter()
            .filter(|l| significant_digits(l) >= 3)
            .map(|l| l.parse().unwrap())
            .collect();
        let distinctive: Vec<f64> = leg_dimensions(&robot)
            .into_iter()
            .filter(|v| significant_digits(&format!("{v}")) >= 3)
            .collect();
        for v in &distinctive {
            assert!(lits.contains(v), "{file}: {v} not found");
        }
        let legs: Vec<i64> = robot.bus.legs.iter().map(|&i| i64::from(i)).collect();
        assert!(contains_sequence(&code, &legs), "{file}: leg IDs");
        let signs: Vec<i64> = robot.mounting.iter().map(|&s| i64::from(s)).collect();
        if signs.iter().any(|&s| s != signs[0]) {
            assert!(contains_sequence(&code, &signs), "{file}: signs");
        }
        if robot.name == "op3" {
            assert!(distinctive.len() >= 5, "{distinctive:?}");
        }
    }
    // And a sequence inside a longer list of numbers is not taken for it.
    assert!(!contains_sequence("[17, 8, 10]", &[7, 8, 10]));
    assert!(contains_sequence("[8,\n 10, 12]", &[8, 10, 12]));
    assert_eq!(float_literals("a1.5 + 0.0305_f64 * x.0"), ["0.0305"]);
    assert_eq!(significant_digits("0.11015"), 5);
}
