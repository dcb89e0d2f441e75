//! The `walker` command line: a small hand parser (no clap: compile time) and a table of
//! subcommands. Adding a subcommand = one [`Subcommand`] entry in [`SUBCOMMANDS`] with a
//! handler `fn(&mut Args) -> Result<(), CliError>` that takes its options from [`Args`] and
//! calls [`Args::finish`] before doing any work (so unknown options are refused early).
//!
//! Exit codes: 0 success, 1 failure (bad plan file, unreadable log, serial port not found, …),
//! 2 usage error (unknown subcommand or option, missing or malformed value).

use crate::planfile::{self, WalkSpec};
use crate::{capture, export, report};
use gait_core::Robot;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// A command-line error with its exit code.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CliError {
    /// What went wrong.
    pub message: String,
    /// Exit code (1 failure, 2 usage).
    pub code: i32,
}

impl CliError {
    /// A usage error (exit code 2).
    pub fn usage(msg: impl Into<String>) -> Self {
        CliError {
            message: msg.into(),
            code: 2,
        }
    }
    /// A failure (exit code 1).
    pub fn failed(msg: impl Into<String>) -> Self {
        CliError {
            message: msg.into(),
            code: 1,
        }
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for CliError {}

impl From<String> for CliError {
    fn from(s: String) -> Self {
        CliError::failed(s)
    }
}

impl From<planfile::PlanError> for CliError {
    fn from(e: planfile::PlanError) -> Self {
        CliError::failed(e.to_string())
    }
}

/// The options of one subcommand, consumed by name.
#[derive(Debug)]
pub struct Args {
    cmd: &'static str,
    items: Vec<String>,
    used: Vec<bool>,
}

impl Args {
    /// The arguments after the subcommand name.
    pub fn new(cmd: &'static str, items: &[String]) -> Self {
        Args {
            cmd,
            items: items.to_vec(),
            used: vec![false; items.len()],
        }
    }

    /// True when `--help` / `-h` was given.
    pub fn wants_help(&self) -> bool {
        self.items.iter().any(|a| a == "--help" || a == "-h")
    }

    /// The value of `--name VALUE` or `--name=VALUE` (the last one wins).
    pub fn value(&mut self, name: &str) -> Result<Option<String>, CliError> {
        let mut found = None;
        let prefix = format!("{name}=");
        let mut i = 0;
        while i < self.items.len() {
            if self.items[i] == name {
                self.used[i] = true;
                match self.items.get(i + 1) {
                    Some(v) if !v.starts_with("--") => {
                        self.used[i + 1] = true;
                        found = Some(v.clone());
                        i += 1;
                    }
                    _ => {
                        return Err(CliError::usage(format!(
                            "walker {}: {name} needs a value",
                            self.cmd
                        )))
                    }
                }
            } else if let Some(v) = self.items[i].strip_prefix(&prefix) {
                self.used[i] = true;
                found = Some(v.to_string());
            }
            i += 1;
        }
        Ok(found)
    }

    /// A required value.
    pub fn required(&mut self, name: &str) -> Result<String, CliError> {
        self.value(name)?
            .ok_or_else(|| CliError::usage(format!("walker {}: {name} is required", self.cmd)))
    }

    /// A value parsed as `T`.
    pub fn parsed<T: FromStr>(&mut self, name: &str) -> Result<Option<T>, CliError>
    where
        T::Err: fmt::Display,
    {
        match self.value(name)? {
            None => Ok(None),
            Some(v) => v
                .parse::<T>()
                .map(Some)
                .map_err(|e| CliError::usage(format!("walker {}: {name} {v:?}: {e}", self.cmd))),
        }
    }

    /// A flag without a value.
    pub fn flag(&mut self, name: &str) -> bool {
        let mut hit = false;
        for (a, u) in self.items.iter().zip(self.used.iter_mut()) {
            if a == name {
                *u = true;
                hit = true;
            }
        }
        hit
    }

    /// Refuses anything not consumed.
    pub fn finish(&self) -> Result<(), CliError> {
        match self.items.iter().zip(&self.used).find(|(_, u)| !**u) {
            Some((a, _)) => Err(CliError::usage(format!(
                "walker {}: unexpected argument {a:?} (see `walker {} --help`)",
                self.cmd, self.cmd
            ))),
            None => Ok(()),
        }
    }

    /// The arguments not consumed yet (for pass-through subcommands).
    pub fn rest(&mut self) -> Vec<String> {
        let out = self
            .items
            .iter()
            .zip(&self.used)
            .filter(|(_, u)| !**u)
            .map(|(a, _)| a.clone())
            .collect();
        self.used.iter_mut().for_each(|u| *u = true);
        out
    }
}

/// One subcommand.
pub struct Subcommand {
    /// Its name.
    pub name: &'static str,
    /// One line for the overview.
    pub summary: &'static str,
    /// Its usage text.
    pub usage: &'static str,
    /// The handler.
    pub run: fn(&mut Args) -> Result<(), CliError>,
}

/// The simulated robot's physics options shared by `simulate`, `fil` and `beyond` (usage text).
macro_rules! physics_options {
    () => {
        "\n  --physics        mujoco (default: full dynamics) | kinematic (idealised: stance sole bolted down)\
\n  --push LIST      pushes on the torso, T:IMPULSE_NS:DIRECTION_DEG[,…] (0° forward, 90° left), e.g. 3.2:1.5:0\
\n  --floor-friction sole–floor friction coefficient (default 1.0)\
\n  --floor-steps MM floor of square 5 cm tiles with random heights within ±MM (seeded; level under the start)\
\n  --slope DEG      floor slope, uphill forward\
\n  --payload KG     extra mass on the torso, 15 cm above the pelvis\
\n  --sensor-latency-ms MS  latency of the foot boards' and the IMU's samples\
\n  --servo-voltage V       servo supply voltage (default 12; XM430-W350 datasheet at 12 V)"
    };
}

/// Every subcommand, in the order of the help text.
pub const SUBCOMMANDS: &[Subcommand] = &[
    Subcommand {
        name: "export",
        summary: "sample a plan and write ZMP, CoM, feet and the 12 joint angles as CSV",
        usage: "walker export [--plan plans/table2.toml] [--out out/plan.csv] [--dt 0.005]\n\
                \n  --plan  plan/parameter file (TOML; default: the built-in Table 2 walk)\
                \n  --out   CSV to write (default out/plan.csv)\
                \n  --dt    sample time, s (default: the plan's dt)",
        run: run_export,
    },
    Subcommand {
        name: "report",
        summary: "decode a firmware log: ZMP CSV, plots (SVG/PNG), Table 3 statistics",
        usage: "walker report --log out/walk.log [--out out/report] [--truth out/truth.csv] [--plan plans/table2.toml] [--model tlipfm] [--mcap run.mcap]\n\
                \n  --log    captured firmware log (binary COBS frames)\
                \n  --out    folder for zmp_response.csv, events.csv, zmp_response.svg/.png, report.md, stats.json\
                \n           (with a truth file also joint_speeds, joint_torques, foot_forces .svg/.png)\
                \n  --mcap   also write the run as MCAP for Foxglove (README: \"Opening a run in Foxglove\")\
                \n  --truth  CSV with t, zmp_x, zmp_y (e.g. the simulator's true ZMP), same clock as the log\
                \n  --plan   the plan the firmware walked (support-polygon bounds; default Table 2)\
                \n  --model  lipm | dlipm | tlipfm: the model the firmware ran (report title; default: the plan's)",
        run: run_report,
    },
    Subcommand {
        name: "compare",
        summary: "Table 3 statistics of several runs side by side",
        usage: "walker compare --runs lipm=out/lipm.log,dlipm=out/dlipm.log,tlipfm=out/tlipfm.log [--out out/compare.md]",
        run: run_compare,
    },
    Subcommand {
        name: "capture",
        summary: "record the firmware log from a serial port (or decode a saved capture)",
        usage: "walker capture --port /dev/ttyUSB0 [--baud 921600] --out out/walk.log [--seconds N]\n\
                walker capture --from-file saved.log [--out out/walk.log]\n\
                walker capture --list    (the serial ports found)\n\
                \n  writes the raw stream to --out, the decoded ticks to <out>.csv and events to <out>.events.csv\
                \n  any baud rate the port accepts; without --seconds, capture runs until Ctrl-C or the\
                \n  port hangs up; the CSVs are written however it ends",
        run: run_capture,
    },
    Subcommand {
        name: "simulate",
        summary: "serve the simulated robot on the servo bus (TCP) for the firmware",
        usage: concat!("walker simulate [--port 5760] [--lockstep-port 5761] [--connect] [--seed N] [--stall-torque NM] [--truth out/truth.csv] [--timeout S]\n\
                \n  --port           bus TCP port on 127.0.0.1 (QEMU -serial tcp:127.0.0.1:PORT)\
                \n  --lockstep-port  lock-step time channel (default: free-running)\
                \n  --connect        connect to a listening QEMU instead of listening\
                \n  --seed           seed of the noise and fault streams\
                \n  --stall-torque   servo stall torque, N·m (MuJoCo: XM430-W350 4.1 by default; kinematic: 3.5, 0 = unlimited)\
                \n  --truth          write the ground truth (true ZMP, …) to this CSV (for `walker report --truth`)\
                \n  --timeout        seconds to wait for the firmware (default 30)\
                \n  physics options:", physics_options!()),
        run: run_simulate,
    },
    Subcommand {
        name: "fil",
        summary: "firmware-in-the-loop: the firmware in QEMU against the simulated robot",
        usage: concat!("walker fil [--plan plans/table2.toml] [--model lipm|dlipm|tlipfm] [--out out/fil]\n\
                [--elf target/thumbv7em-none-eabihf/release/qemu] [--machine mps2-an500|mps2-an386]\n\
                [--seed N] [--stall-torque NM] [--p-drop P] [--p-corrupt P] [--dead ID,ID] [--fall-at S]\n\
                [--tau-constant NM] [--tau-random NM] [--firmware-args 'k=v ...'] [--timeout S]\n\
                [--video OUT/walk.mp4] [physics options]\n\
         Runs the firmware ELF in QEMU in lock-step with the simulated robot, captures its log\n\
         to OUT/walk.log and writes the report to OUT/report. Exit code 3: the firmware failed.\n\
         --video renders the walk (MuJoCo, headless; needs `bash scripts/render-setup.sh`).\n\
         physics options:", physics_options!()),
        run: run_fil,
    },
    Subcommand {
        name: "beyond",
        summary: "LIPM, DLIPM, TLIPFM, TLIPFM with the Fourier CoM, + whole-body compensation, + feedback: side by side in the FIL walk",
        usage: concat!("walker beyond [--plan plans/table2.toml] [--out out/beyond] [--elf target/thumbv7em-none-eabihf/release/qemu]\n\
                [--machine mps2-an500] [--seed N] [--stall-torque NM] [--firmware-args 'k=v ...'] [--feedback-args 'stab_ki=2 ...'] [--timeout S]\n\
         Walks the plan six times in the firmware-in-the-loop setup (the MuJoCo robot with\n\
         XM430-W350 servo models; --stall-torque changes their stall torque) and prints per\n\
         run the true and measured ZMP errors, the time the true ZMP is inside the support polygon\n\
         (5 mm margin), distance walked vs planned, peak joint speeds and motor torques; writes\n\
         OUT/beyond.md, OUT/beyond.csv and OUT/<run>/.\n\
         --firmware-args go to every run (e.g. feasibility=off), --feedback-args to the feedback run.\n\
         physics options:", physics_options!()),
        run: run_beyond,
    },
];

/// The overview help text.
pub fn usage() -> String {
    let mut s = String::from("walker: host tools of the walking controller\n\nusage: walker <command> [options]\n\ncommands:\n");
    for c in SUBCOMMANDS {
        s.push_str(&format!("  {:<9} {}\n", c.name, c.summary));
    }
    s.push_str("\n`walker <command> --help` shows a command's options.\n");
    s
}

/// Runs the command line `args` (without the program name); returns the exit code.
pub fn main_with(args: &[String]) -> i32 {
    match dispatch(args) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {e}");
            e.code
        }
    }
}

/// Finds and runs the subcommand.
pub fn dispatch(args: &[String]) -> Result<(), CliError> {
    let Some(name) = args.first() else {
        print!("{}", usage());
        return Err(CliError::usage("no command given"));
    };
    if name == "help" || name == "--help" || name == "-h" {
        match args
            .get(1)
            .and_then(|n| SUBCOMMANDS.iter().find(|c| c.name == n))
        {
            Some(c) => println!("{}", c.usage),
            None => print!("{}", usage()),
        }
        return Ok(());
    }
    let Some(cmd) = SUBCOMMANDS.iter().find(|c| c.name == name) else {
        return Err(CliError::usage(format!(
            "unknown command {name:?}\n\n{}",
            usage()
        )));
    };
    let mut a = Args::new(cmd.name, &args[1..]);
    if a.wants_help() {
        println!("{}", cmd.usage);
        return Ok(());
    }
    (cmd.run)(&mut a)
}

/// Loads `--plan` (or the built-in Table 2 walk).
fn plan_arg(a: &mut Args) -> Result<(WalkSpec, String), CliError> {
    match a.value("--plan")? {
        Some(p) => Ok((planfile::load(Path::new(&p))?, p)),
        None => Ok((WalkSpec::default(), "built-in Table 2 walk".to_string())),
    }
}

/// The `--model` value of subcommand `cmd`.
fn model_name(cmd: &str, m: &str) -> Result<planfile::ModelName, CliError> {
    match m {
        "lipm" => Ok(planfile::ModelName::Lipm),
        "dlipm" => Ok(planfile::ModelName::Dlipm),
        "tlipfm" => Ok(planfile::ModelName::Tlipfm),
        other => Err(CliError::usage(format!(
            "walker {cmd}: --model {other:?}: expected lipm, dlipm or tlipfm"
        ))),
    }
}

fn create_parent(p: &Path) -> Result<(), CliError> {
    if let Some(d) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)
            .map_err(|e| CliError::failed(format!("cannot create {}: {e}", d.display())))?;
    }
    Ok(())
}

fn run_export(a: &mut Args) -> Result<(), CliError> {
    let plan = a.value("--plan")?;
    let out = PathBuf::from(a.value("--out")?.unwrap_or_else(|| "out/plan.csv".into()));
    let dt: Option<f64> = a.parsed("--dt")?;
    a.finish()?;
    let (spec, name) = match plan {
        Some(p) => (planfile::load(Path::new(&p))?, p),
        None => (WalkSpec::default(), "built-in Table 2 walk".to_string()),
    };
    let robot = Robot::reference();
    let dt = dt.unwrap_or(spec.dt);
    let (rows, summary) = export::export_rows(&spec, &robot, dt).map_err(|e| {
        let e = if e.field == "dt" {
            planfile::PlanError {
                field: "--dt / dt".into(),
                ..e
            }
        } else {
            e
        };
        CliError::failed(format!("{name}: {e}"))
    })?;
    create_parent(&out)?;
    let file = std::fs::File::create(&out)
        .map_err(|e| CliError::failed(format!("cannot create {}: {e}", out.display())))?;
    export::write_csv(&rows, std::io::BufWriter::new(file))
        .map_err(|e| CliError::failed(format!("cannot write {}: {e}", out.display())))?;
    println!(
        "{}: {} rows at dt = {dt} s ({:.3} s, model {}) → {}",
        name,
        summary.rows,
        rows.last().map_or(0.0, |r| r.t),
        spec.model_kind().name(),
        out.display()
    );
    if summary.clamped_rows > 0 {
        eprintln!(
            "warning: the leg IK could not meet the feet exactly in {} rows (worst reach deficit {:.6} m)",
            summary.clamped_rows, summary.worst_reach_deficit
        );
    }
    Ok(())
}

fn run_report(a: &mut Args) -> Result<(), CliError> {
    let log = PathBuf::from(a.required("--log")?);
    let out = PathBuf::from(a.value("--out")?.unwrap_or_else(|| "out/report".into()));
    let truth = a.value("--truth")?.map(PathBuf::from);
    let model = a.value("--model")?;
    let mcap = a.value("--mcap")?.map(PathBuf::from);
    let (mut spec, plan_name) = plan_arg(a)?;
    a.finish()?;
    if let Some(m) = model {
        spec.model = model_name("report", &m)?;
    }
    if !log.exists() {
        return Err(CliError::failed(format!(
            "log file {} not found",
            log.display()
        )));
    }
    let opts = report::ReportOptions {
        log,
        out_dir: out.clone(),
        truth,
        spec,
        plan_name,
    };
    let r = report::run(&opts, &Robot::reference())?;
    if let Some(m) = &mcap {
        let counts = crate::mcap_export::export_run(&opts, &r, &Robot::reference(), m)?;
        println!(
            "{}: {} channels, {} messages (Foxglove: open the file)",
            m.display(),
            counts.len(),
            counts.values().sum::<u64>()
        );
    }
    println!(
        "{}: {} good records ({} ticks, {} events), {} bad, {} sequence gaps",
        opts.log.display(),
        r.log.good(),
        r.log.ticks.len(),
        r.log.events.len(),
        r.log.bad(),
        r.log.decoder.seq_gaps
    );
    println!("\nZMP tracking error, measured − reference (seed 000 Table 3):\n");
    print!("{}", report::stats_table(&r.stats));
    if let Some(ts) = &r.truth_stats {
        println!("\nmeasured − true ZMP:\n");
        print!("{}", report::stats_table(ts));
    }
    println!(
        "\nwrote {}",
        r.files
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

/// Parses `name=path,name=path`.
pub fn parse_runs(s: &str) -> Result<Vec<(String, PathBuf)>, CliError> {
    let mut out = Vec::new();
    for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        let (name, path) = item.split_once('=').ok_or_else(|| {
            CliError::usage(format!(
                "walker compare: --runs item {item:?} is not name=path"
            ))
        })?;
        if name.is_empty() || path.is_empty() {
            return Err(CliError::usage(format!(
                "walker compare: --runs item {item:?} is not name=path"
            )));
        }
        out.push((name.to_string(), PathBuf::from(path)));
    }
    if out.is_empty() {
        return Err(CliError::usage("walker compare: --runs lists no run"));
    }
    Ok(out)
}

fn run_compare(a: &mut Args) -> Result<(), CliError> {
    let runs = parse_runs(&a.required("--runs")?)?;
    let out = PathBuf::from(a.value("--out")?.unwrap_or_else(|| "out/compare.md".into()));
    a.finish()?;
    let mut results = Vec::new();
    for (name, path) in &runs {
        if !path.exists() {
            return Err(CliError::failed(format!(
                "log file {} (run {name}) not found",
                path.display()
            )));
        }
        let log = report::decode_file(path)?;
        let stats = report::error_stats(&report::tick_rows(&log.ticks));
        results.push((name.clone(), log, stats));
    }
    let table = report::compare_table(&results);
    let rank_x = report::ranking(&results, |s| s.x.sum_abs);
    let rank_y = report::ranking(&results, |s| s.y.sum_abs);
    println!("ZMP tracking error, measured − reference (seed 000 Table 3), as measured:\n");
    print!("{table}");
    println!("\nΣ|e_x| smallest first: {rank_x}\nΣ|e_y| smallest first: {rank_y}");
    let mut md = String::from("# ZMP tracking error by model (seed 000 Table 3)\n\n");
    md.push_str("As measured from the logs below; e = measured − reference ZMP.\n\n");
    for (name, path) in &runs {
        md.push_str(&format!("- {name}: `{}`\n", path.display()));
    }
    md.push('\n');
    md.push_str(&table);
    md.push_str(&format!(
        "\nΣ|e_x| smallest first: {rank_x}\n\nΣ|e_y| smallest first: {rank_y}\n"
    ));
    create_parent(&out)?;
    std::fs::write(&out, md)
        .map_err(|e| CliError::failed(format!("cannot write {}: {e}", out.display())))?;
    println!("\nwrote {}", out.display());
    Ok(())
}

fn run_capture(a: &mut Args) -> Result<(), CliError> {
    let list = a.flag("--list");
    let from = a.value("--from-file")?.map(PathBuf::from);
    let port = a.value("--port")?;
    let baud: Option<u32> = a.parsed("--baud")?;
    let out = a.value("--out")?.map(PathBuf::from);
    let seconds = seconds_arg(a, "--seconds")?.map(|d| d.as_secs_f64());
    a.finish()?;
    if baud == Some(0) {
        return Err(CliError::usage("walker capture: --baud must be positive"));
    }
    if list {
        let ports = capture::list_ports()?;
        if ports.is_empty() {
            println!("no serial port found");
        }
        for p in ports {
            println!("{p}");
        }
        return Ok(());
    }
    let log = match (from, port) {
        (Some(_), Some(_)) => {
            return Err(CliError::usage(
                "walker capture: give either --port or --from-file, not both",
            ))
        }
        (None, None) => {
            return Err(CliError::usage(
                "walker capture: --port (or --from-file) is required",
            ))
        }
        (Some(input), None) => {
            if !input.exists() {
                return Err(CliError::failed(format!(
                    "capture file {} not found",
                    input.display()
                )));
            }
            let (log, files) = capture::from_file(&input, out.as_deref())?;
            println!(
                "wrote {}",
                files
                    .iter()
                    .map(|f| f.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            log
        }
        (None, Some(port)) => {
            let out = out.ok_or_else(|| CliError::usage("walker capture: --out is required"))?;
            let opts = capture::CaptureOptions {
                port,
                baud: baud.unwrap_or(921_600),
                out: out.clone(),
                seconds,
            };
            let (log, _end) = capture::capture(&opts)?;
            println!(
                "wrote {}, {}, {}",
                out.display(),
                capture::csv_path(&out).display(),
                capture::events_path(&out).display()
            );
            log
        }
    };
    println!(
        "{} bytes: {} good records ({} ticks, {} events), {} bad, {} sequence gaps",
        log.bytes,
        log.good(),
        log.ticks.len(),
        log.events.len(),
        log.bad(),
        log.decoder.seq_gaps
    );
    Ok(())
}

/// Applies the shared physics options to `cfg`.
fn physics_args(a: &mut Args, cfg: &mut crate::sim::SimConfig) -> Result<(), CliError> {
    let cmd = a.cmd;
    let bad = |m: String| CliError::usage(format!("walker {cmd}: {m}"));
    if let Some(p) = a.value("--physics")? {
        cfg.physics = match p.as_str() {
            "mujoco" => crate::sim::PhysicsModel::MuJoCo,
            "kinematic" => crate::sim::PhysicsModel::Kinematic,
            other => {
                return Err(bad(format!(
                    "--physics: mujoco or kinematic (got {other:?})"
                )))
            }
        };
    }
    if let Some(list) = a.value("--push")? {
        for item in list.split(',').filter(|s| !s.trim().is_empty()) {
            cfg.pushes.push(
                crate::sim::Push::parse(item.trim()).map_err(|e| bad(format!("--push: {e}")))?,
            );
        }
    }
    let finite = |name: &str, v: Option<f64>| -> Result<Option<f64>, CliError> {
        match v {
            Some(x) if !x.is_finite() => Err(bad(format!("{name} must be a finite number"))),
            other => Ok(other),
        }
    };
    if let Some(v) = finite("--floor-friction", a.parsed("--floor-friction")?)? {
        cfg.env.floor_friction = v;
    }
    if let Some(v) = finite("--floor-steps", a.parsed("--floor-steps")?)? {
        cfg.env.step_height_m = v * 1e-3;
    }
    if let Some(v) = finite("--slope", a.parsed("--slope")?)? {
        cfg.env.slope_deg = v;
    }
    if let Some(v) = finite("--payload", a.parsed("--payload")?)? {
        cfg.env.payload_kg = v;
    }
    if let Some(v) = finite("--sensor-latency-ms", a.parsed("--sensor-latency-ms")?)? {
        if !(0.0..=1000.0).contains(&v) {
            return Err(bad(format!(
                "--sensor-latency-ms must be in 0..=1000 (got {v})"
            )));
        }
        cfg.noise.latency_us = (v * 1e3).round() as u64;
    }
    if let Some(v) = finite("--servo-voltage", a.parsed("--servo-voltage")?)? {
        cfg.xservo.supply_voltage = v;
    }
    if let Err(e) = cfg.env.validate() {
        return Err(bad(e));
    }
    if !cfg.xservo.is_valid() {
        return Err(bad("--servo-voltage must be > 0".into()));
    }
    Ok(())
}

/// The longest duration any option takes, s (11.6 days; `Duration::from_secs_f64` panics on
/// non-finite or huge values, so every duration is checked against this first).
const MAX_SECONDS: f64 = 1e6;

/// A duration option `name` in seconds: finite, > 0 and at most [`MAX_SECONDS`], else a usage
/// error (exit 2) naming the option.
fn seconds_arg(a: &mut Args, name: &str) -> Result<Option<std::time::Duration>, CliError> {
    match a.parsed::<f64>(name)? {
        None => Ok(None),
        Some(s) if s.is_finite() && s > 0.0 && s <= MAX_SECONDS => {
            Ok(Some(std::time::Duration::from_secs_f64(s)))
        }
        Some(s) => Err(CliError::usage(format!(
            "walker {}: {name} must be a number of seconds in (0, {MAX_SECONDS}] (got {s})",
            a.cmd
        ))),
    }
}

/// `--stall-torque NM`: the kinematic model's servo torque model (default XM430-class, 0 =
/// none) and the value given (for the MuJoCo servo model, see [`apply_stall_torque`]).
fn stall_torque_arg(
    a: &mut Args,
) -> Result<(Option<crate::sim::ServoTorque>, Option<f64>), CliError> {
    let xm430 = crate::sim::ServoTorque::XM430;
    match a.parsed::<f64>("--stall-torque")? {
        None => Ok((Some(xm430), None)),
        Some(0.0) => Ok((None, Some(0.0))),
        Some(t) if t.is_finite() && t > 0.0 => Ok((
            Some(crate::sim::ServoTorque {
                stall_torque: t,
                ..xm430
            }),
            Some(t),
        )),
        Some(t) => Err(CliError::usage(format!(
            "walker {}: --stall-torque must be >= 0 N·m (got {t})",
            a.cmd
        ))),
    }
}

/// `--stall-torque` for the MuJoCo servo model: its stall torque (0, "unlimited", is the
/// kinematic model's option only).
fn apply_stall_torque(
    cmd: &str,
    cfg: &mut crate::sim::SimConfig,
    raw: Option<f64>,
) -> Result<(), CliError> {
    match raw {
        Some(t) if t > 0.0 => cfg.xservo.stall_torque = t,
        Some(_) if cfg.physics == crate::sim::PhysicsModel::MuJoCo => {
            return Err(CliError::usage(format!(
                "walker {cmd}: --stall-torque 0 (unlimited) is for --physics kinematic; a MuJoCo servo needs a stall torque > 0"
            )))
        }
        _ => {}
    }
    Ok(())
}

fn run_simulate(a: &mut Args) -> Result<(), CliError> {
    let port: Option<u16> = a.parsed("--port")?;
    let lockstep: Option<u16> = a.parsed("--lockstep-port")?;
    let connect = a.flag("--connect");
    let seed: Option<u64> = a.parsed("--seed")?;
    let (servo_torque, stall_raw) = stall_torque_arg(a)?;
    let truth = a.value("--truth")?.map(PathBuf::from);
    let timeout = seconds_arg(a, "--timeout")?;
    let mut cfg = crate::sim::SimConfig {
        servo_torque,
        ..Default::default()
    };
    physics_args(a, &mut cfg)?;
    apply_stall_torque(a.cmd, &mut cfg, stall_raw)?;
    a.finish()?;
    if let Some(p) = port {
        cfg.port = p;
    }
    cfg.lockstep_port = lockstep;
    cfg.connect = connect;
    if let Some(s) = seed {
        cfg.seed = s;
    }
    if let Some(t) = timeout {
        cfg.connect_timeout = t;
    }
    if let Some(t) = &truth {
        create_parent(t)?;
    }
    cfg.log_truth = truth;
    eprintln!(
        "simulated robot on 127.0.0.1:{} (lock-step {}); waiting for the firmware…",
        cfg.port,
        cfg.lockstep_port
            .map_or("off".to_string(), |p| format!("127.0.0.1:{p}"))
    );
    let summary =
        crate::sim::run(cfg).map_err(|e| CliError::failed(format!("walker simulate: {e}")))?;
    println!("{summary:#?}");
    Ok(())
}

fn run_beyond(a: &mut Args) -> Result<(), CliError> {
    let elf = PathBuf::from(
        a.value("--elf")?
            .unwrap_or_else(|| "target/thumbv7em-none-eabihf/release/qemu".into()),
    );
    let out = PathBuf::from(a.value("--out")?.unwrap_or_else(|| "out/beyond".into()));
    let seed: Option<u64> = a.parsed("--seed")?;
    let (servo_torque, stall_raw) = stall_torque_arg(a)?;
    let machine = a.value("--machine")?.unwrap_or_else(|| "mps2-an500".into());
    let timeout = seconds_arg(a, "--timeout")?;
    let split = |t: Option<String>| -> Vec<String> {
        t.map(|t| t.split_whitespace().map(String::from).collect())
            .unwrap_or_default()
    };
    let extra = split(a.value("--firmware-args")?);
    let feedback = split(a.value("--feedback-args")?);
    let (spec, plan_name) = plan_arg(a)?;
    let mut sim = crate::sim::SimConfig {
        servo_torque,
        ..Default::default()
    };
    physics_args(a, &mut sim)?;
    apply_stall_torque(a.cmd, &mut sim, stall_raw)?;
    a.finish()?;
    let opts = crate::beyond::BeyondOptions {
        sim,
        elf,
        spec,
        out_dir: out.clone(),
        machine,
        seed: seed.unwrap_or(0),
        extra_tokens: extra,
        feedback_tokens: feedback,
        timeout: timeout.unwrap_or(std::time::Duration::from_secs(1800)),
        servo_torque,
    };
    eprintln!("walker beyond: {plan_name}, six firmware-in-the-loop walks");
    let runs = crate::beyond::run(&opts, |name| eprintln!("  walking {name} …"))?;
    let table = crate::beyond::table(&runs);
    let servos = match opts.sim.physics {
        crate::sim::PhysicsModel::MuJoCo => {
            let x = &opts.sim.xservo;
            format!(
                "Simulated robot: MuJoCo 3.17 full dynamics (the robot can tip, slip and fall). Servos: XM430-W350 position-mode model (Position P gain 800, PWM limit 885; DC motor line {} N·m stall, {:.2} rad/s no load at {} V; armature {} kg·m², gear damping {} N·m·s/rad, friction {} N·m; `host/src/sim/dynamixel.rs`).",
                x.stall_torque, x.no_load_speed, x.supply_voltage, x.armature, x.gear_damping, x.friction_loss
            )
        }
        crate::sim::PhysicsModel::Kinematic => format!(
            "Simulated robot: the IDEALISED kinematic model (stance sole bolted down; not a walking-quality figure). Servos: speed limit {} rad/s, second-order position loop, {}.",
            crate::beyond::XM430_SPEED_RAD_S,
            servo_torque.map_or("no torque limit".to_string(), |t| format!(
                "torque–speed line of a {} N·m stall torque and {} rad/s no-load speed, rotor inertia {} kg·m²",
                t.stall_torque, t.no_load_speed, t.armature
            ))
        ),
    };
    let mut md = format!(
        "# Beyond the paper: {plan_name}\n\n{servos}\nErrors against the firmware's ZMP reference over the walking ticks; peak joint speeds are the simulator's (true) and the firmware's targets'.\n\n"
    );
    md.push_str(&table);
    md.push('\n');
    md.push_str(&crate::beyond::goal_section(&runs));
    let mism: usize = runs.iter().map(|r| r.ref_mismatch).sum();
    if mism > 0 {
        md.push_str(&format!(
            "\nWarning: {mism} ticks whose reference differs from the host rebuild of the plan (support polygons may be misaligned).\n"
        ));
    }
    std::fs::create_dir_all(&out)
        .map_err(|e| CliError::failed(format!("{}: {e}", out.display())))?;
    std::fs::write(out.join("beyond.md"), &md)
        .map_err(|e| CliError::failed(format!("{}: {e}", out.display())))?;
    std::fs::write(out.join("beyond.csv"), crate::beyond::csv(&runs))
        .map_err(|e| CliError::failed(format!("{}: {e}", out.display())))?;
    print!("{md}");
    println!("\nwritten: {}", out.join("beyond.md").display());
    match runs.iter().find(|r| r.exit_code != Some(0)) {
        None => Ok(()),
        Some(r) => Err(CliError {
            message: format!("run {} exited with {:?}", r.variant.name, r.exit_code),
            code: 3,
        }),
    }
}

fn run_fil(a: &mut Args) -> Result<(), CliError> {
    let elf = PathBuf::from(
        a.value("--elf")?
            .unwrap_or_else(|| "target/thumbv7em-none-eabihf/release/qemu".into()),
    );
    let model = a.value("--model")?;
    let out = PathBuf::from(a.value("--out")?.unwrap_or_else(|| "out/fil".into()));
    let seed: Option<u64> = a.parsed("--seed")?;
    let (servo_torque, stall_raw) = stall_torque_arg(a)?;
    let p_drop: Option<f64> = a.parsed("--p-drop")?;
    let p_corrupt: Option<f64> = a.parsed("--p-corrupt")?;
    let dead = a.value("--dead")?;
    let fall_at: Option<f64> = a.parsed("--fall-at")?;
    let tau_const: Option<f64> = a.parsed("--tau-constant")?;
    let tau_random: Option<f64> = a.parsed("--tau-random")?;
    let machine = a.value("--machine")?.unwrap_or_else(|| "mps2-an500".into());
    let timeout = seconds_arg(a, "--timeout")?;
    let tokens = a.value("--firmware-args")?;
    let video = a.value("--video")?.map(PathBuf::from);
    let (mut spec, plan_name) = plan_arg(a)?;
    let mut sim = crate::sim::SimConfig {
        servo_torque,
        ..Default::default()
    };
    physics_args(a, &mut sim)?;
    apply_stall_torque(a.cmd, &mut sim, stall_raw)?;
    a.finish()?;
    if let Some(m) = model {
        spec.model = model_name("fil", &m)?;
    }
    if video.is_some() && sim.physics != crate::sim::PhysicsModel::MuJoCo {
        return Err(CliError::usage(
            "walker fil: --video needs the MuJoCo robot (--physics mujoco)",
        ));
    }
    if video.is_some() {
        sim.model_out = Some(out.join("model.xml"));
        sim.qpos_out = Some(out.join("qpos.csv"));
    }
    if let Some(s) = seed {
        sim.seed = s;
    }
    for (name, p) in [("--p-drop", p_drop), ("--p-corrupt", p_corrupt)] {
        if let Some(v) = p {
            if !(0.0..=1.0).contains(&v) {
                return Err(CliError::usage(format!(
                    "walker fil: {name} must be within 0..=1 (got {v})"
                )));
            }
        }
    }
    sim.faults.p_drop = p_drop.unwrap_or(0.0);
    sim.faults.p_corrupt = p_corrupt.unwrap_or(0.0);
    if let Some(d) = dead {
        for id in d.split(',').filter(|s| !s.is_empty()) {
            let id: u8 = id.trim().parse().map_err(|_| {
                CliError::usage(format!("walker fil: --dead: bad device id {id:?}"))
            })?;
            sim.faults.dead_ids.push(id);
        }
    }
    sim.fall.forced_at_s = fall_at;
    if let Some(t) = tau_const {
        sim.disturbance.constant_nm = t;
    }
    if let Some(t) = tau_random {
        sim.disturbance.random_std_nm = t;
    }
    let opts = crate::fil::FilOptions {
        elf,
        spec: spec.clone(),
        out_dir: out.clone(),
        machine,
        timeout: timeout.unwrap_or(std::time::Duration::from_secs(1800)),
        sim,
        extra_tokens: tokens
            .map(|t| t.split_whitespace().map(String::from).collect())
            .unwrap_or_default(),
    };
    // A command line QEMU would refuse: a clear error before anything starts.
    crate::fil::qemu_append(&opts).map_err(|e| CliError::usage(format!("walker fil: {e}")))?;
    eprintln!(
        "walker fil: {} ({:?}) in QEMU {} against the simulated robot",
        plan_name, spec.model, opts.machine
    );
    let last = std::cell::Cell::new(-1.0f64);
    let r = crate::fil::run(&opts, |t, n| {
        if t - last.get() >= 0.5 {
            eprint!("\r  simulated time {t:6.2} s, {n} bus instructions");
            last.set(t);
        }
    })?;
    eprintln!();
    eprintln!("  {}", crate::fil::summary_line(&r.sim));
    eprintln!("  wall clock {:.1} s", r.wall.as_secs_f64());
    // The report's support bounds follow the timing the firmware adjusted at start-up.
    let events = report::decode_file(&r.log)
        .map(|l| l.events)
        .unwrap_or_default();
    let ropts = report::ReportOptions {
        log: r.log.clone(),
        out_dir: out.join("report"),
        truth: Some(r.truth.clone()),
        spec: crate::beyond::adjusted_spec(&spec, &events),
        plan_name,
    };
    let rep = match report::run(&ropts, &Robot::reference()) {
        Ok(rep) => rep,
        // A firmware that stopped before walking: its exit code is the news, not the report.
        Err(e) if r.exit_code != Some(0) => {
            return Err(CliError {
                message: format!("the firmware exited with code {:?} ({e})", r.exit_code),
                code: 3,
            })
        }
        Err(e) => return Err(e.into()),
    };
    println!(
        "{}: {} good records ({} ticks, {} events), {} bad",
        r.log.display(),
        rep.log.good(),
        rep.log.ticks.len(),
        rep.log.events.len(),
        rep.log.bad()
    );
    for ev in &rep.log.events {
        let (_, t, kind, text) = report::event_text(ev);
        println!("  event at {:.3} s: {kind} {text}", t as f64 * 1e-6);
    }
    println!("\nZMP tracking error, measured − reference (seed 000 Table 3):\n");
    print!("{}", report::stats_table(&rep.stats));
    if let Some(ts) = &rep.truth_stats {
        println!("\nmeasured − true (simulator) ZMP:\n");
        print!("{}", report::stats_table(ts));
    }
    if let Ok(w) = crate::fil::walk_figures(&r.truth, &spec) {
        println!("\nin the physics: {}", w.line());
    }
    println!("\nreport: {}", out.join("report").display());
    if let Some(v) = &video {
        eprintln!("  rendering {} …", v.display());
        crate::video::render(&out.join("model.xml"), &out.join("qpos.csv"), v)
            .map_err(|e| CliError::failed(format!("walker fil: --video: {e}")))?;
        println!("video: {}", v.display());
    }
    match r.exit_code {
        Some(0) => Ok(()),
        code => Err(CliError {
            message: format!("the firmware exited with code {code:?}"),
            code: 3,
        }),
    }
}
