//! The `walker` command line, declared with `clap` (derive): one documented struct per
//! command ([`Command`]), the simulated robot's options shared by `simulate`, `fil` and `beyond`
//! ([`SimArgs`]). Every option has a one-line help (a test checks it); a misspelt option gets a
//! suggestion; paths are `PathBuf` parsed from `OsString` (a non-UTF-8 path never panics);
//! an option given twice, or two options that exclude each other, are refused; every number is
//! checked by its value parser (finite, in range, with a message naming the option) before any
//! work starts.
//!
//! Exit codes: 0 success (also `--help`, `--version`), 1 failure (bad plan file, unreadable log,
//! serial port not found, …), 2 usage error (unknown command or option, missing or malformed
//! value), 3 the firmware failed (`fil`, `beyond`).

use crate::planfile::{self, ModelName, WalkSpec};
use crate::progress::{Progress, StatusLine, STATUS_EVERY};
use crate::{capture, export, report};
use clap::{Args, Parser, Subcommand, ValueEnum};
use gait_core::Robot;
use serde::Deserialize;
use std::ffi::OsString;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A command-line error with its exit code.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CliError {
    /// What went wrong.
    pub message: String,
    /// Exit code (1 failure, 2 usage, 3 firmware failed).
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

/// The default firmware ELF of `fil` and `beyond` (the board-qemu release build).
pub const DEFAULT_ELF: &str = "target/thumbv7em-none-eabihf/release/qemu";

/// `walker`: host tools of the walking controller.
#[derive(Debug, Parser)]
#[command(
    name = "walker",
    version,
    about = "Host tools of the walking controller: simulated robot, firmware in the loop, log capture, reports",
    propagate_version = true,
    arg_required_else_help = true
)]
pub struct Cli {
    /// The command to run.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands, in the order of the help text.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Sample a plan and write ZMP, CoM, feet and the 12 joint angles as CSV.
    Export(ExportArgs),
    /// Decode a firmware log: ZMP CSV, plots (SVG/PNG), Table 3 statistics, MCAP.
    Report(ReportArgs),
    /// Table 3 statistics of several runs side by side.
    Compare(CompareArgs),
    /// Record the firmware log from a serial port (or decode a saved capture).
    Capture(CaptureArgs),
    /// Serve the simulated robot on the servo bus (TCP) for the firmware.
    Simulate(SimulateArgs),
    /// Firmware in the loop: the firmware in QEMU against the simulated robot.
    ///
    /// Runs the firmware ELF in QEMU in lock-step with the simulated robot, captures its log to
    /// OUT/walk.log, decodes its defmt output to OUT/firmware.log and writes the report to
    /// OUT/report. Exit code 3: the firmware failed.
    Fil(FilArgs),
    /// LIPM, DLIPM, TLIPFM, TLIPFM with the Fourier CoM, + whole-body compensation, + feedback: side by side in the FIL walk.
    ///
    /// Walks the plan six times in the firmware-in-the-loop setup and prints per run the true
    /// and measured ZMP errors, the time the true ZMP is inside the support polygon (5 mm
    /// margin), distance walked vs planned, peak joint speeds and motor torques; writes
    /// OUT/beyond.md, OUT/beyond.csv and OUT/<run>/.
    Beyond(BeyondArgs),
    /// Robustness sweep: the plan walked in the FIL setup nominal and with each perturbation of the robot.
    ///
    /// The firmware (its defaults: the closed loop) walks the plan on the MuJoCo robot once
    /// nominal and once per case (servo torque and gains ±20 %, link masses ±10 %, floor
    /// friction 0.5 / 0.75, +5 ms sensor latency, 5 % dropped status packets; host/src/sweep.rs)
    /// and writes OUT/sweep.md with the goals each case misses, and OUT/<case>/.
    Sweep(SweepArgs),
    /// Largest torso push survived: four directions, standing and walking, on the MuJoCo robot.
    ///
    /// For each condition and direction (forward, left, backward, right) climbs the push's
    /// impulse in steps of 2·STEP until the robot falls, then tries the level in between
    /// (host/src/pushes.rs); writes OUT/pushes.md and one folder per run.
    Pushes(PushesArgs),
    /// Fastest forward velocity and turn rate sustained for 10 s on the MuJoCo robot, on command.
    ///
    /// One run per level through the firmware's command port (host/src/speed.rs): sustained =
    /// no fall, the run ends by the commanded torque off and the pelvis's mean over the 10 s
    /// hold is within 10 % of the level; writes OUT/speed.md and one folder per run.
    Speed(SpeedArgs),
    /// Keyboard teleoperation of the walk on the firmware's command port (arrows/WASD, space =
    /// stop, t = torque off, Esc = quit), with a live status line.
    ///
    /// On a TCP command port (`--connect`, e.g. a `walker fil --command-port` run), a serial port
    /// (`--serial`, the OpenCR's UART connector) or the simulated robot started in the
    /// background (`--sim`: the firmware in QEMU against the MuJoCo robot). host/src/drive.rs.
    Drive(DriveArgs),
    /// The firmware's run-time parameters over its command port: list, get, set, load a plan,
    /// diff, save (`key=value`, docs/parameters.md).
    ///
    /// On a TCP command port (`--connect`) or a serial port (`--serial`). A set is in force for
    /// the next run, a save for the next boot; both are refused while a run is going: the
    /// firmware serves them while it waits for the enable (`wait_enable=1`, the OpenCR build's
    /// default; the OpenCM 9.04 build answers "not in this board's build"). host/src/param.rs.
    Param(ParamArgs),
    /// Flash a firmware image through ROBOTIS' USB bootloader (no probe): the OpenCR 1.0
    /// (default) or the OpenCM 9.04 (`--board opencm`).
    ///
    /// OpenCR: speaks its bootloader's protocol (ROBOTIS' opencr_ld: MAVLink v1 messages over
    /// the board's USB CDC port): board name and version, erase of the sectors the image covers
    /// from sector 5 (0x0804_0000), 16 KiB blocks in 128-byte packets, the bootloader's CRC,
    /// a byte-for-byte read-back, the jump to the firmware. The walker firmware has no USB
    /// stack: hold the push switch SW2 while pressing RESET to stay in the bootloader
    /// (docs/boards.md). host/src/opencr_boot.rs.
    ///
    /// OpenCM 9.04: speaks its bootloader's protocol (ROBOTIS' opencm9.04_ld: text commands
    /// over the USB CDC port): AT&NAME, AT&LD (erases 0x0800_3000..0x0801_F800), the image in
    /// 64-byte packets and its 8-bit sum, the bootloader's verdict, AT&GO. Hold the USER
    /// button while plugging the USB cable in to stay in the bootloader (docs/boards.md).
    /// host/src/opencm_boot.rs.
    Flash(FlashArgs),
}

/// The board `walker flash` talks to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FlashBoard {
    /// ROBOTIS OpenCR 1.0 (STM32F746): images for 0x0804_0000 (feature opencr-bootloader).
    Opencr,
    /// ROBOTIS OpenCM 9.04 (STM32F103CB): images for 0x0800_3000 (feature board-opencm).
    Opencm,
}

/// `walker flash`.
#[derive(Debug, Args)]
pub struct FlashArgs {
    /// The board, and so its bootloader's protocol.
    #[arg(long, value_enum, default_value_t = FlashBoard::Opencr)]
    pub board: FlashBoard,
    /// The board's USB port (its CDC ACM device: /dev/ttyACM0, /dev/cu.usbmodem…, COM5).
    #[arg(long, value_name = "DEV")]
    pub serial: String,
    /// Firmware image: an ELF (its loadable bytes from the bootloader's start address: 0x0804_0000 OpenCR, 0x0800_3000 OpenCM) or a raw binary for that address.
    #[arg(value_name = "IMAGE")]
    pub image: PathBuf,
    /// Stay in the bootloader after the checks (do not start the firmware).
    #[arg(long)]
    pub no_jump: bool,
    /// Largest image accepted, KiB. OpenCR: 256 by default (sector 5 only; a larger image erases sector 6, the saved parameters' first slot), up to 768. OpenCM: 114 by default and at most (the region the bootloader erases).
    #[arg(long, value_name = "KIB",
          value_parser = clap::value_parser!(u32).range(1..=768))]
    pub limit_kib: Option<u32>,
    /// Baud rate the port is opened at (the boards' USB CDC ports ignore it).
    #[arg(long, value_name = "BAUD", default_value_t = 115_200,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub baud: u32,
    /// Skip the reset request that sends an Arduino sketch into the bootloader (OpenCR: open at 1200 baud, send "OpenCR 5555AAAA", close, wait 1.5 s; OpenCM: open at 1200 baud, send "CM9X", close, wait 1 s).
    #[arg(long)]
    pub no_touch: bool,
    /// OpenCR only: skip the byte-for-byte read-back (the bootloader's own CRC misses over 40 % of single-bit errors).
    #[arg(long)]
    pub no_read_back: bool,
    /// OpenCR only: block size, KiB (default 16, which fills the bootloader's buffer; ROBOTIS' opencr_ld sends 8).
    #[arg(long, value_name = "KIB",
          value_parser = clap::value_parser!(u32).range(1..=16))]
    pub block_kib: Option<u32>,
}

/// The firmware's command port, on TCP or a serial port (`walker drive`, `walker param`).
#[derive(Debug, Args)]
pub struct PortArgs {
    /// A command port on TCP, e.g. 127.0.0.1:5770 (`walker fil --command-port 5770`).
    #[arg(long, value_name = "HOST:PORT")]
    pub connect: Option<String>,
    /// A serial port, e.g. /dev/ttyUSB0 (the OpenCR's UART connector through a USB–TTL adapter).
    #[arg(long, value_name = "DEV")]
    pub serial: Option<String>,
    /// Baud rate of --serial (the firmware's command UART runs at 1 Mbps).
    #[arg(long, value_name = "BAUD", default_value_t = 1_000_000)]
    pub baud: u32,
}

/// `walker param`.
#[derive(Debug, Args)]
pub struct ParamArgs {
    /// The command port.
    #[command(flatten)]
    pub port: PortArgs,
    /// What to do.
    #[command(subcommand)]
    pub action: ParamAction,
}

/// `walker param` actions.
#[derive(Debug, Subcommand)]
pub enum ParamAction {
    /// Every parameter as `key=value`, one a line (empty value: not set).
    List,
    /// The values of these keys, as `key=value`.
    Get {
        /// Keys (docs/parameters.md).
        #[arg(required = true)]
        keys: Vec<String>,
    },
    /// Sets these `key=value` tokens, in order; stops at the first refused.
    Set {
        /// Tokens, e.g. catch_gain=0.5 gyro_ankle=0.04.
        #[arg(required = true)]
        tokens: Vec<String>,
    },
    /// Sets every parameter a plan file gives (its walk and its `[firmware]` table), checked
    /// by the firmware's parser first.
    Load {
        /// Plan file (TOML, e.g. plans/table2.toml).
        file: PathBuf,
    },
    /// Saves the values in force to the board's store: the firmware loads them at its next
    /// boot (two copies, a power cut loses nothing).
    Save,
    /// The parameters whose values differ from the defaults (or from a plan file's).
    Diff {
        /// Plan file to compare against (default: the firmware's defaults).
        file: Option<PathBuf>,
    },
}

/// `walker export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Plan file (TOML, e.g. plans/table2.toml) or a run configuration (its walk); default: the built-in Table 2 walk.
    #[arg(long, value_name = "FILE")]
    pub plan: Option<PathBuf>,
    /// CSV to write.
    #[arg(long, value_name = "FILE", default_value = "out/plan.csv")]
    pub out: PathBuf,
    /// Sample time, s (default: the plan's dt).
    #[arg(long, value_name = "S", value_parser = positive, allow_negative_numbers = true)]
    pub dt: Option<f64>,
}

/// `walker report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// Captured firmware log (binary COBS frames).
    #[arg(long, value_name = "FILE")]
    pub log: PathBuf,
    /// Folder for zmp_response.csv, events.csv, the plots (.svg/.png), report.md, stats.json.
    #[arg(long, value_name = "DIR", default_value = "out/report")]
    pub out: PathBuf,
    /// Truth CSV of the simulator (t_s, zmp_x_m, zmp_y_m, …), same clock as the log.
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
    /// The plan the firmware walked (support-polygon bounds); default: Table 2.
    #[arg(long, value_name = "FILE")]
    pub plan: Option<PathBuf>,
    /// The model the firmware ran (report title); default: the plan's.
    #[arg(long, value_enum)]
    pub model: Option<ModelName>,
    /// Also write the run as MCAP for Foxglove / PlotJuggler (docs/simulation.md: "Opening a run in Foxglove").
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
}

/// `walker compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The runs, NAME=LOG[,NAME=LOG…], e.g. lipm=out/lipm.log,tlipfm=out/tlipfm.log.
    #[arg(long, value_name = "LIST", value_parser = parse_runs)]
    pub runs: RunList,
    /// Markdown table to write.
    #[arg(long, value_name = "FILE", default_value = "out/compare.md")]
    pub out: PathBuf,
}

/// The `--runs` of `walker compare`: (name, log file) pairs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunList(pub Vec<(String, PathBuf)>);

/// `walker capture`.
#[derive(Debug, Args)]
#[command(group = clap::ArgGroup::new("source").required(true).multiple(true)
    .args(["list", "port", "from_file", "defmt"]))]
pub struct CaptureArgs {
    /// List the serial ports found and exit.
    #[arg(long, conflicts_with_all = ["port", "from_file", "defmt", "elf"])]
    pub list: bool,
    /// Serial port of the log UART (/dev/ttyUSB0, /dev/cu.usbserial-…, COM3).
    #[arg(long, value_name = "PORT", requires = "out")]
    pub port: Option<String>,
    /// Decode a saved capture instead of reading a port.
    #[arg(long, value_name = "FILE", conflicts_with = "port")]
    pub from_file: Option<PathBuf>,
    /// Baud rate of the log UART (any rate the port accepts).
    #[arg(long, value_name = "BAUD", default_value_t = 921_600,
          value_parser = clap::value_parser!(u32).range(1..), allow_negative_numbers = true)]
    pub baud: u32,
    /// Raw stream to write; the ticks go to <out>.csv, the events to <out>.events.csv.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Stop after this many seconds (default: at Ctrl-C or when the port hangs up).
    #[arg(long, value_name = "S", value_parser = seconds, allow_negative_numbers = true)]
    pub seconds: Option<Duration>,
    /// Raw defmt stream saved from the firmware (e.g. scripts/qemu-run.sh's ELF.defmt, RTT), decoded to <FILE>.log.
    #[arg(long, value_name = "FILE", requires = "elf")]
    pub defmt: Option<PathBuf>,
    /// The firmware ELF whose defmt table decodes --defmt.
    #[arg(long, value_name = "ELF", requires = "defmt")]
    pub elf: Option<PathBuf>,
}

/// The simulated robot's options (`simulate`, `fil`, `beyond`) and the `[sim]` table of a run
/// configuration file (same names, `_` for `-`); an option given on the command line overrides
/// the file's value (`push` and `dead` lists are added to).
#[derive(Debug, Args, Clone, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimArgs {
    /// Physics of the simulated robot (default mujoco: full dynamics; kinematic: idealised, stance sole bolted down).
    #[arg(long, value_enum)]
    pub physics: Option<PhysicsArg>,
    /// Seed of the noise and fault streams.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Servo stall torque, N·m (MuJoCo: XM430-W350 4.1 by default; kinematic: 3.5, 0 = unlimited).
    #[arg(long, value_name = "NM", value_parser = non_negative, allow_negative_numbers = true)]
    pub stall_torque: Option<f64>,
    /// Servo supply voltage, V (default 12; XM430-W350 datasheet at 12 V).
    #[arg(long, value_name = "V", value_parser = positive, allow_negative_numbers = true)]
    pub servo_voltage: Option<f64>,
    /// Push on the torso, T:IMPULSE_NS:DIRECTION_DEG (0° forward, 90° left), e.g. 3.2:1.5:0; comma-separated or repeated.
    #[arg(long, value_name = "PUSH", value_delimiter = ',', value_parser = parse_push, allow_negative_numbers = true)]
    #[serde(deserialize_with = "pushes")]
    pub push: Vec<crate::sim::Push>,
    /// Sole–floor friction coefficient (default 1.0).
    #[arg(long, value_name = "MU", value_parser = finite, allow_negative_numbers = true)]
    pub floor_friction: Option<f64>,
    /// Floor of square 5 cm tiles with random heights within ±MM, mm (seeded; level under the start).
    #[arg(long, value_name = "MM", value_parser = finite, allow_negative_numbers = true)]
    pub floor_steps: Option<f64>,
    /// Floor slope, degrees (uphill forward).
    #[arg(long, value_name = "DEG", value_parser = finite, allow_negative_numbers = true)]
    pub slope: Option<f64>,
    /// Extra mass on the torso, 15 cm above the pelvis, kg.
    #[arg(long, value_name = "KG", value_parser = finite, allow_negative_numbers = true)]
    pub payload: Option<f64>,
    /// Latency of the foot boards' and the IMU's samples, ms (0..=1000).
    #[arg(long, value_name = "MS", value_parser = latency_ms, allow_negative_numbers = true)]
    pub sensor_latency_ms: Option<f64>,
    /// Standard deviation of each load cell's noise, N.
    #[arg(long, value_name = "N", value_parser = non_negative, allow_negative_numbers = true)]
    pub force_noise: Option<f64>,
    /// Standard deviation of each gyro axis' noise, rad/s.
    #[arg(long, value_name = "RAD_S", value_parser = non_negative, allow_negative_numbers = true)]
    pub gyro_noise: Option<f64>,
    /// Standard deviation of each accelerometer axis' noise, m/s².
    #[arg(long, value_name = "M_S2", value_parser = non_negative, allow_negative_numbers = true)]
    pub accel_noise: Option<f64>,
    /// Probability that the bus drops an instruction packet (0..=1).
    #[arg(long, value_name = "P", value_parser = probability, allow_negative_numbers = true)]
    pub p_drop: Option<f64>,
    /// Probability that the bus corrupts a status packet (0..=1).
    #[arg(long, value_name = "P", value_parser = probability, allow_negative_numbers = true)]
    pub p_corrupt: Option<f64>,
    /// Devices that never answer, by bus id (e.g. 111,112); comma-separated or repeated.
    #[arg(long, value_name = "ID", value_delimiter = ',')]
    pub dead: Vec<u8>,
    /// A device that dies for a while, ID:FROM_S[:FOR_S] (e.g. 4:6:0.2: servo 4 dead from 6 s,
    /// back at 6.2 s with its torque off; without FOR_S it never comes back); comma-separated or repeated.
    #[arg(long, value_name = "OUTAGE", value_delimiter = ',', value_parser = crate::sim::Outage::parse)]
    #[serde(deserialize_with = "outages")]
    pub outage: Vec<crate::sim::Outage>,
    /// Force a fall at this simulated time, s.
    #[arg(long, value_name = "S", value_parser = non_negative, allow_negative_numbers = true)]
    pub fall_at: Option<f64>,
    /// Constant pitch torque on the upper body, N·m (positive pitches it forward).
    #[arg(long, value_name = "NM", value_parser = finite, allow_negative_numbers = true)]
    pub tau_constant: Option<f64>,
    /// Standard deviation of a random pitch torque on the upper body, N·m.
    #[arg(long, value_name = "NM", value_parser = non_negative, allow_negative_numbers = true)]
    pub tau_random: Option<f64>,
}

/// The `outage` list of a configuration file: strings `ID:FROM_S[:FOR_S]`.
fn outages<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<crate::sim::Outage>, D::Error> {
    let items = <Vec<String> as Deserialize>::deserialize(d)?;
    items
        .iter()
        .map(|s| crate::sim::Outage::parse(s).map_err(serde::de::Error::custom))
        .collect()
}

/// The `push` list of a configuration file: strings `T:IMPULSE_NS:DIRECTION_DEG`.
fn pushes<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<crate::sim::Push>, D::Error> {
    let items = <Vec<String> as Deserialize>::deserialize(d)?;
    items
        .iter()
        .map(|s| parse_push(s).map_err(serde::de::Error::custom))
        .collect()
}

/// `--physics`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PhysicsArg {
    /// MuJoCo full dynamics (the robot can tip, slip and fall).
    Mujoco,
    /// The idealised kinematic model (stance sole bolted down).
    Kinematic,
}

impl From<PhysicsArg> for crate::sim::PhysicsModel {
    fn from(p: PhysicsArg) -> Self {
        match p {
            PhysicsArg::Mujoco => crate::sim::PhysicsModel::MuJoCo,
            PhysicsArg::Kinematic => crate::sim::PhysicsModel::Kinematic,
        }
    }
}

/// `walker simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Bus TCP port on 127.0.0.1 (QEMU -serial tcp:127.0.0.1:PORT).
    #[arg(long, value_name = "PORT", default_value_t = 5760)]
    pub port: u16,
    /// Lock-step time channel's TCP port (default: free-running).
    #[arg(long, value_name = "PORT")]
    pub lockstep_port: Option<u16>,
    /// Connect to a listening QEMU instead of listening.
    #[arg(long)]
    pub connect: bool,
    /// Write the ground truth (true ZMP, …) to this CSV (for `walker report --truth`).
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
    /// Seconds to wait for the firmware (default 30).
    #[arg(long, value_name = "S", value_parser = seconds, allow_negative_numbers = true)]
    pub timeout: Option<Duration>,
    /// The simulated robot.
    #[command(flatten)]
    pub sim: SimArgs,
}

/// The options of a firmware-in-the-loop run shared by `fil`, `beyond` and `sweep`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Run configuration (TOML: plan, firmware parameters, simulator, QEMU; plans/run-example.toml); options given here override it.
    #[arg(long, value_name = "FILE", conflicts_with = "plan")]
    pub config: Option<PathBuf>,
    /// Plan file (TOML, e.g. plans/table2.toml); default: the built-in Table 2 walk.
    #[arg(long, value_name = "FILE")]
    pub plan: Option<PathBuf>,
    /// Firmware ELF (board-qemu build; default target/thumbv7em-none-eabihf/release/qemu).
    #[arg(long, value_name = "ELF")]
    pub elf: Option<PathBuf>,
    /// QEMU machine (scripts/qemu-machines.txt): mps2-an500 (Cortex-M7), mps2-an386 (Cortex-M4F), mps2-an385 (Cortex-M3); default: by the ELF's target.
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(crate::qemu::machine_names()))]
    pub machine: Option<String>,
    /// Firmware parameters for every run, 'key=value …' (docs/parameters.md), checked before QEMU starts.
    #[arg(long, value_name = "'K=V …'")]
    pub firmware_args: Option<String>,
    /// The robot walked, by its description: the simulated robot and the firmware's `robot=`
    /// (default: the plan's `robot`, else tku-x, the reference robot; a plan written for
    /// another robot is refused).
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(gait_core::robot::ROBOT_NAMES))]
    pub robot: Option<String>,
    /// Wall-clock limit per run, s (default 1800).
    #[arg(long, value_name = "S", value_parser = seconds, allow_negative_numbers = true)]
    pub timeout: Option<Duration>,
    /// The simulated robot (sweep: the nominal one).
    #[command(flatten)]
    pub sim: SimArgs,
}

/// `walker fil`.
#[derive(Debug, Args)]
pub struct FilArgs {
    /// Pendulum model (overrides the plan's).
    #[arg(long, value_enum)]
    pub model: Option<ModelName>,
    /// Output folder (walk.log, firmware.log, truth.csv, report/).
    #[arg(long, value_name = "DIR", default_value = "out/fil")]
    pub out: PathBuf,
    /// Render the walk to this video (MuJoCo, headless; needs `bash scripts/render-setup.sh`).
    #[arg(long, value_name = "FILE")]
    pub video: Option<PathBuf>,
    /// Also write the run as one MCAP file for Foxglove (robot model, transforms, scene, events;
    /// docs/simulation.md: "Opening a run in Foxglove").
    #[arg(long, value_name = "FILE", conflicts_with_all = ["commands", "command_port"])]
    pub mcap: Option<PathBuf>,
    /// Walk on command: the firmware starts without autostart and this script of `[[command]]`
    /// tables (`t` s from standing ready; `vx`, `vy` m/s, `vyaw` rad/s, or `stop = true`; a
    /// footstep list `steps = [{ foot = "left", dx = 0.03, dy = 0, dyaw = 0 }, …]`) drives it
    /// through its command port; e.g. plans/commands-demo.toml, plans/commands-steps.toml.
    #[arg(long, value_name = "FILE")]
    pub commands: Option<PathBuf>,
    /// Walk on command from outside: the firmware starts without autostart and its command
    /// port (Dynamixel Protocol 2.0, ID 150) listens on 127.0.0.1:PORT (0 = a free port, printed)
    /// for any master: `walker drive --connect`, the ROBOTIS SDK (pyserial URL
    /// `socket://127.0.0.1:PORT`). Writing Mode = 0 (torque off) ends the run.
    #[arg(long, value_name = "PORT", conflicts_with = "commands")]
    pub command_port: Option<u16>,
    /// The firmware's feedback off, as the paper walked (the tokens of `walker beyond`'s open
    /// loop, host/src/beyond.rs `OPEN_LOOP`: no gyro damping, no compliance feed-forward, the
    /// servos' factory Position I Gain, no catching step, no swing sole levelling), before the
    /// tokens of --firmware-args.
    #[arg(long)]
    pub open_loop: bool,
    /// The run.
    #[command(flatten)]
    pub run: RunArgs,
}

/// `walker beyond`.
#[derive(Debug, Args)]
pub struct BeyondArgs {
    /// Output folder (beyond.md, beyond.csv, one folder per run).
    #[arg(long, value_name = "DIR", default_value = "out/beyond")]
    pub out: PathBuf,
    /// Firmware parameters for the feedback run only, e.g. 'stab_ki=2'.
    #[arg(long, value_name = "'K=V …'")]
    pub feedback_args: Option<String>,
    /// The closed-loop ablation instead of the six methods: LIPM, DLIPM, TLIPFM open loop,
    /// then TLIPFM with one part added at a time: gyro at the ankles, at the hips, the servos'
    /// compliance handling, the catching step, the swing sole's levelling (the default),
    /// whole-body compensation, the stabilizer (ten walks, OUT/beyond.md).
    #[arg(long)]
    pub ablation: bool,
    /// The runs.
    #[command(flatten)]
    pub run: RunArgs,
}

/// `walker sweep`.
#[derive(Debug, Args)]
pub struct SweepArgs {
    /// Output folder (sweep.md, rows.csv, one folder per case).
    #[arg(long, value_name = "DIR", default_value = "out/sweep")]
    pub out: PathBuf,
    /// The robot family walked: the reference robot's (11 cases) or the servos a robot of this
    /// class really has (21 cases: stall torque, speed, gains, supply, masses, trunk CoM,
    /// friction, sensor and Present Position latency, gear backlash).
    #[arg(long, value_enum, default_value_t = crate::sweep::Family::Reference)]
    pub family: crate::sweep::Family,
    /// Walks at a time (each a QEMU process and a simulator thread).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
    pub jobs: u16,
    /// Only the K-th of N interleaved parts of the case list (case i when i mod N = K − 1); its
    /// rows go to OUT/rows.csv for `--merge`.
    #[arg(long, value_name = "K/N", value_parser = crate::sweep::Shard::parse)]
    pub shard: Option<crate::sweep::Shard>,
    /// Only these cases (names as in the table, comma-separated or repeated), e.g. to walk the
    /// failing ones again.
    #[arg(
        long,
        value_name = "NAME",
        value_delimiter = ',',
        conflicts_with = "merge"
    )]
    pub case: Vec<String>,
    /// No walks: the table of the rows.csv of these sweep folders (the shards of one sweep),
    /// written to OUT/sweep.md.
    #[arg(long, value_name = "DIR", num_args = 1.., conflicts_with_all = ["shard", "jobs"])]
    pub merge: Vec<PathBuf>,
    /// Walk the family with the defaults and once per feature off (host/src/ablation.rs
    /// `FEATURES`) into OUT/defaults/ and OUT/FEATURE/, and write OUT/ablation.md: which
    /// feature is nowhere worse on than off. With --merge: the DIRs are ablation folders.
    #[arg(long)]
    pub ablate: bool,
    /// The runs (each case changes one knob of the nominal simulated robot).
    #[command(flatten)]
    pub run: RunArgs,
}

/// `walker pushes`.
#[derive(Debug, Args)]
pub struct PushesArgs {
    /// Output folder (pushes.md, one folder per run).
    #[arg(long, value_name = "DIR", default_value = "out/pushes")]
    pub out: PathBuf,
    /// The search's resolution, N·s.
    #[arg(long, value_name = "NS", default_value_t = 0.25)]
    pub step: f64,
    /// The largest impulse tried, N·s.
    #[arg(long, value_name = "NS", default_value_t = 4.0)]
    pub max: f64,
    /// When a walking push lands, s of simulated time (Table 2: 6 s is left single support).
    #[arg(long, value_name = "S", default_value_t = 6.0)]
    pub walk_at: f64,
    /// How long after standing ready a standing push lands, s.
    #[arg(long, value_name = "S", default_value_t = 1.0)]
    pub stand_after: f64,
    /// Only standing or only walking (default both).
    #[arg(long, value_parser = ["standing", "walking"])]
    pub only: Option<String>,
    /// The runs.
    #[command(flatten)]
    pub run: RunArgs,
}

/// `walker drive`.
#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("port").required(true).args(["connect", "serial", "sim"])))]
pub struct DriveArgs {
    /// The command port.
    #[command(flatten)]
    pub port: PortArgs,
    /// Start the simulated robot in the background (`walker fil --command-port`: the firmware in
    /// QEMU against the MuJoCo robot, its output in --out) and drive it; quitting stops the walk,
    /// turns the torque off (ending the run) and prints the run's figures.
    #[arg(long)]
    pub sim: bool,
    /// With --sim: the plan file (walking parameters; default the built-in Table 2 walk).
    #[arg(long, value_name = "FILE", requires = "sim")]
    pub plan: Option<PathBuf>,
    /// With --sim: the robot walked, by its description (default: the plan's robot, else
    /// tku-x).
    #[arg(long, requires = "sim", value_parser = clap::builder::PossibleValuesParser::new(gait_core::robot::ROBOT_NAMES))]
    pub robot: Option<String>,
    /// With --sim: the firmware ELF (default target/thumbv7em-none-eabihf/release/qemu).
    #[arg(long, value_name = "ELF", requires = "sim")]
    pub elf: Option<PathBuf>,
    /// With --sim: the run's output folder (walk.log, truth.csv, fil.out, fil.err).
    #[arg(long, value_name = "DIR", default_value = "out/drive")]
    pub out: PathBuf,
}

/// `walker speed`.
#[derive(Debug, Args)]
pub struct SpeedArgs {
    /// Output folder (speed.md, one folder per run).
    #[arg(long, value_name = "DIR", default_value = "out/speed")]
    pub out: PathBuf,
    /// Resolution of the forward velocity search, m/s.
    #[arg(long, value_name = "M_S", default_value_t = 0.01)]
    pub step_v: f64,
    /// Resolution of the turn rate search, rad/s.
    #[arg(long, value_name = "RAD_S", default_value_t = 0.05)]
    pub step_w: f64,
    /// The runs.
    #[command(flatten)]
    pub run: RunArgs,
}

/// The longest duration any option takes, s (11.6 days; `Duration::from_secs_f64` panics on
/// non-finite or huge values, so every duration is checked against this first).
pub const MAX_SECONDS: f64 = 1e6;

/// A duration in seconds: finite, > 0 and at most [`MAX_SECONDS`].
pub(crate) fn seconds(s: &str) -> Result<Duration, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 && x <= MAX_SECONDS => Ok(Duration::from_secs_f64(x)),
        Ok(_) => Err(format!(
            "must be a number of seconds in (0, {MAX_SECONDS}] (got {})",
            s.trim()
        )),
        Err(e) => Err(format!("not a number of seconds: {e}")),
    }
}

/// A finite number.
fn finite(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        Ok(_) => Err(format!("must be a finite number (got {})", s.trim())),
        Err(e) => Err(format!("not a number: {e}")),
    }
}

/// A finite number that `ok` accepts; else the error says it `must be {what}`.
fn finite_where(s: &str, ok: impl Fn(f64) -> bool, what: &str) -> Result<f64, String> {
    let x = finite(s)?;
    if ok(x) {
        Ok(x)
    } else {
        Err(format!("must be {what} (got {x})"))
    }
}

/// A finite number ≥ 0.
fn non_negative(s: &str) -> Result<f64, String> {
    finite_where(s, |x| x >= 0.0, ">= 0")
}

/// A finite number > 0.
fn positive(s: &str) -> Result<f64, String> {
    finite_where(s, |x| x > 0.0, "> 0")
}

/// A probability, 0..=1.
fn probability(s: &str) -> Result<f64, String> {
    finite_where(s, |x| (0.0..=1.0).contains(&x), "within 0..=1")
}

/// A sensor latency, ms (0..=1000).
fn latency_ms(s: &str) -> Result<f64, String> {
    finite_where(s, |x| (0.0..=1000.0).contains(&x), "in 0..=1000")
}

/// One push, `T:IMPULSE_NS:DIRECTION_DEG`.
fn parse_push(s: &str) -> Result<crate::sim::Push, String> {
    crate::sim::Push::parse(s.trim())
}

/// Parses `name=path,name=path` (`walker compare --runs`).
pub fn parse_runs(s: &str) -> Result<RunList, String> {
    let mut out = Vec::new();
    for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        match item.split_once('=') {
            Some((name, path)) if !name.is_empty() && !path.is_empty() => {
                out.push((name.to_string(), PathBuf::from(path)))
            }
            _ => return Err(format!("item {item:?} is not name=path")),
        }
    }
    if out.is_empty() {
        return Err("lists no run".into());
    }
    Ok(RunList(out))
}

/// Runs the command line `args` (without the program name); returns the exit code.
pub fn main_with<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let argv = std::iter::once(OsString::from("walker")).chain(args.into_iter().map(Into::into));
    let cli = match Cli::try_parse_from(argv) {
        Ok(cli) => cli,
        Err(e) => {
            // Help and version go to stdout with exit code 0, usage errors to stderr with 2.
            let _ = e.print();
            return e.exit_code();
        }
    };
    match run(cli.command) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {e}");
            e.code
        }
    }
}

/// Runs one parsed command.
pub fn run(command: Command) -> Result<(), CliError> {
    match command {
        Command::Export(a) => run_export(a),
        Command::Report(a) => run_report(a),
        Command::Compare(a) => run_compare(a),
        Command::Capture(a) => run_capture(a),
        Command::Simulate(a) => run_simulate(a),
        Command::Fil(a) => run_fil(a),
        Command::Beyond(a) => run_beyond(a),
        Command::Sweep(a) => run_sweep(a),
        Command::Pushes(a) => run_pushes(a),
        Command::Speed(a) => run_speed(a),
        Command::Drive(a) => run_drive(a),
        Command::Param(a) => run_param(a),
        Command::Flash(a) => run_flash(a),
    }
}

/// How long `walker flash` tries to open the port (after the touch: the board re-enumerates).
const FLASH_OPEN_WAIT: Duration = Duration::from_secs(5);

fn run_flash(a: FlashArgs) -> Result<(), CliError> {
    match a.board {
        FlashBoard::Opencr => run_flash_opencr(a),
        FlashBoard::Opencm => run_flash_opencm(a),
    }
}

/// Before anything touches the port (the bootloader client checks again): refuses an image
/// whose `sent` bytes are over `--limit-kib` or whose vector table is wrong (`vectors`), then
/// says what will be flashed where.
fn announce_flash_image(
    shown: &str,
    kind: &dyn std::fmt::Display,
    image: &[u8],
    sent: usize,
    limit_kib: u32,
    base: u32,
    vectors: Result<(), String>,
) -> Result<(), CliError> {
    let fail = |e: String| CliError::failed(format!("walker flash: {shown}: {e}"));
    let kib = image.len() as f64 / 1024.0;
    if sent > limit_kib as usize * 1024 {
        return Err(fail(format!(
            "the image is {} B ({kib:.1} KiB), over --limit-kib {limit_kib} (nothing was sent)",
            image.len()
        )));
    }
    vectors.map_err(fail)?;
    println!(
        "{shown}: {kind}, {} B ({kib:.1} KiB) for 0x{base:08X}, limit {limit_kib} KiB",
        image.len()
    );
    Ok(())
}

/// How a flash ended: the firmware started, or left in the bootloader (`--no-jump`).
fn flash_ending(jumped: bool) -> &'static str {
    if jumped {
        "firmware started"
    } else {
        "left in the bootloader (--no-jump)"
    }
}

/// The image file's bytes, or why not.
fn read_flash_image(a: &FlashArgs) -> Result<Vec<u8>, CliError> {
    let fail = |e: String| CliError::failed(format!("walker flash: {e}"));
    let shown = a.image.display();
    match std::fs::read(&a.image) {
        Ok(b) => Ok(b),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            Err(fail(format!("image {shown} not found")))
        }
        Err(e) => Err(fail(format!("cannot read {shown}: {e}"))),
    }
}

fn run_flash_opencr(a: FlashArgs) -> Result<(), CliError> {
    use crate::opencr_boot as boot;
    let fail = |e: String| CliError::failed(format!("walker flash: {e}"));
    let shown = a.image.display().to_string();
    let bytes = read_flash_image(&a)?;
    let (image, kind) = boot::load_image(&bytes).map_err(|e| fail(format!("{shown}: {e}")))?;
    let limit_kib = a.limit_kib.unwrap_or(256);
    let block_kib = a.block_kib.unwrap_or(16);
    let limit = limit_kib as usize * 1024;
    let vectors = boot::check_vector_table(&image);
    announce_flash_image(
        &shown,
        &kind,
        &image,
        image.len(),
        limit_kib,
        boot::FW_BASE,
        vectors,
    )?;
    if !a.no_touch {
        println!("1200-baud touch on {}", a.serial);
        boot::touch_1200(&a.serial).map_err(fail)?;
    }
    let port = boot::open_port(&a.serial, a.baud, FLASH_OPEN_WAIT).map_err(fail)?;
    let opts = boot::FlashOptions {
        limit,
        block_len: block_kib as usize * 1024,
        jump: !a.no_jump,
        read_back: !a.no_read_back,
        ..boot::FlashOptions::default()
    };
    let mut client = boot::Bootloader::new(port, opts);
    let mut bar: Option<(Progress, &str)> = None;
    let mut on_stage = |s: boot::Stage| match s {
        boot::Stage::Connected {
            board_name,
            version,
            revision,
        } => println!(
            "board {board_name:?}, bootloader version 0x{version:08X} revision 0x{revision:08X}"
        ),
        boot::Stage::Erasing { sectors } => println!(
            "erasing {sectors} sector(s) of 256 KiB from 0x{:08X}",
            boot::FW_BASE
        ),
        boot::Stage::Writing { done, total } | boot::Stage::Reading { done, total } => {
            let label = match s {
                boot::Stage::Writing { .. } => "KiB written",
                _ => "KiB read back",
            };
            if bar.as_ref().is_none_or(|(_, l)| *l != label) {
                bar = Some((Progress::stderr(total.div_ceil(1024), "flashing"), label));
            }
            if let Some((p, l)) = &bar {
                p.position(done.div_ceil(1024), l);
            }
        }
        boot::Stage::Verifying => {
            bar = None;
            println!("checking the board's CRC");
        }
        boot::Stage::Jumping => {
            bar = None;
            println!("starting the firmware");
        }
    };
    let r = client.flash(&image, &mut on_stage).map_err(|e| {
        match e.starts_with("read_board_name") {
            true => fail(format!(
            "{e}: is the board in its bootloader? (hold the push switch SW2 while pressing RESET)"
        )),
            false => fail(e),
        }
    })?;
    let secs = |d: Duration| format!("{:.1} s", d.as_secs_f64());
    println!(
        "wrote {} B ({} B image + {} B of 0xFF padding) in {} block(s) of {} KiB; erase {}, write {}, read-back {}, total {}",
        r.written_len,
        r.image_len,
        r.written_len - r.image_len,
        r.blocks,
        block_kib,
        secs(r.erase_time),
        secs(r.write_time),
        if r.read_back { secs(r.read_time) } else { "skipped".into() },
        secs(r.total_time)
    );
    println!(
        "CRC 0x{:08X} (image) = 0x{:08X} (board){}",
        r.crc,
        r.board_crc,
        if r.read_back {
            ", read back byte for byte"
        } else {
            ""
        }
    );
    if r.retries > 0 || r.stray_frames > 0 {
        println!(
            "{} command(s) sent again after a lost answer, {} stray frame(s) skipped",
            r.retries, r.stray_frames
        );
    }
    println!("{}", flash_ending(r.jumped));
    Ok(())
}

fn run_flash_opencm(a: FlashArgs) -> Result<(), CliError> {
    use crate::opencm_boot as boot;
    let fail = |e: String| CliError::failed(format!("walker flash: {e}"));
    for (given, opt) in [
        (a.no_read_back, "--no-read-back"),
        (a.block_kib.is_some(), "--block-kib"),
    ] {
        if given {
            return Err(CliError::usage(format!(
                "walker flash --board opencm: {opt} is an OpenCR option (the OpenCM 9.04's bootloader has no read command and takes the image in 64-byte USB packets)"
            )));
        }
    }
    let max_kib = (boot::APP_REGION / 1024) as u32;
    let limit_kib = a.limit_kib.unwrap_or(max_kib);
    if limit_kib > max_kib {
        return Err(CliError::usage(format!(
            "walker flash --board opencm: --limit-kib {limit_kib} is over the {max_kib} KiB the bootloader erases (0x{:08X}..0x{:08X}; the last 2 KiB of flash keep its control table)",
            boot::APP_BASE,
            boot::RESERVED_BASE
        )));
    }
    let shown = a.image.display().to_string();
    let bytes = read_flash_image(&a)?;
    let (image, kind) = boot::load_image(&bytes).map_err(|e| fail(format!("{shown}: {e}")))?;
    let limit = limit_kib as usize * 1024;
    let vectors = boot::check_vector_table(&image);
    let sent = boot::sendable(&image).len();
    announce_flash_image(
        &shown,
        &kind,
        &image,
        sent,
        limit_kib,
        boot::APP_BASE,
        vectors,
    )?;
    if !a.no_touch {
        println!("reset request on {} (1200 baud, \"CM9X\")", a.serial);
        boot::request_bootloader(&a.serial).map_err(fail)?;
    }
    let port = flash_open_port(&a.serial, a.baud)?;
    let opts = boot::FlashOptions {
        limit,
        jump: !a.no_jump,
        ..boot::FlashOptions::default()
    };
    let mut client = boot::Bootloader::new(port, opts);
    let mut on_stage = |s: boot::Stage| match s {
        boot::Stage::Connected { board_name } => println!("board {board_name:?}"),
        boot::Stage::Erasing { attempt } => println!(
            "erasing {} pages of 1 KiB from 0x{:08X}{}",
            boot::ERASED_PAGES,
            boot::APP_BASE,
            if attempt > 1 {
                format!(" (download {attempt})")
            } else {
                String::new()
            }
        ),
        boot::Stage::Writing { done, .. } => println!("sent {done} B and the checksum byte"),
        boot::Stage::Checking => println!("waiting for the bootloader's checksum verdict"),
        boot::Stage::Jumping => println!("starting the firmware (AT&GO)"),
    };
    let r = client.flash(&image, &mut on_stage).map_err(|e| {
        match e.starts_with("AT&NAME: no answer") {
            true => fail(format!(
                "{e}: is the board in its bootloader? (hold the USER button while plugging the USB cable in)"
            )),
            false => fail(e),
        }
    })?;
    let secs = |d: Duration| format!("{:.1} s", d.as_secs_f64());
    println!(
        "sent {} B ({} B image{}); checksum 0x{:02X} accepted (\"Success..\"); erase {}, write {}, total {}",
        r.sent_len,
        r.image_len,
        if r.sent_len > r.image_len {
            " + one 0xFF byte: its checksum was the bootloader's wildcard '*'"
        } else {
            ""
        },
        r.checksum,
        secs(r.erase_time),
        secs(r.write_time),
        secs(r.total_time)
    );
    if r.retries > 0 {
        println!(
            "{} query or download(s) repeated after a lost answer or \"Fail..\"",
            r.retries
        );
    }
    for line in &r.other_lines {
        println!("bootloader said: {line:?}");
    }
    println!("{}", flash_ending(r.jumped));
    Ok(())
}

/// Opens the bootloader's port as `walker flash` does for both boards.
fn flash_open_port(dev: &str, baud: u32) -> Result<Box<dyn serialport::SerialPort>, CliError> {
    crate::opencr_boot::open_port(dev, baud, FLASH_OPEN_WAIT)
        .map_err(|e| CliError::failed(format!("walker flash: {e}")))
}

fn run_param(a: ParamArgs) -> Result<(), CliError> {
    let mut master = match (&a.port.connect, &a.port.serial) {
        (Some(addr), _) => crate::drive::connect(addr, None),
        (_, Some(dev)) => crate::commands::PortMaster::serial(dev, a.port.baud),
        _ => Err("give --connect or --serial".to_string()),
    }
    .map_err(|e| CliError::failed(format!("walker param: {e}")))?;
    let fail = |e: String| CliError::failed(format!("walker param: {e}"));
    master
        .wait_ready(crate::drive::CONNECT_WAIT)
        .map_err(fail)?;
    match a.action {
        ParamAction::List => {
            for (k, v) in crate::param::list(&mut master).map_err(fail)? {
                println!("{k}={v}");
            }
        }
        ParamAction::Get { keys } => {
            for k in keys {
                let v = crate::param::get(&mut master, &k).map_err(fail)?;
                println!("{k}={v}");
            }
        }
        ParamAction::Set { tokens } => set_tokens(&mut master, &tokens).map_err(fail)?,
        ParamAction::Save => {
            crate::param::save(&mut master).map_err(fail)?;
            println!("saved");
        }
        ParamAction::Load { file } => {
            let tokens = plan_tokens(&file).map_err(fail)?;
            crate::param::expected(&tokens)
                .map_err(|e| fail(format!("{}: {e}", file.display())))?;
            set_tokens(&mut master, &tokens).map_err(fail)?;
        }
        ParamAction::Diff { file } => {
            let tokens = match &file {
                Some(f) => plan_tokens(f).map_err(fail)?,
                None => Vec::new(),
            };
            let want = crate::param::expected(&tokens).map_err(fail)?;
            let now = crate::param::list(&mut master).map_err(fail)?;
            let against = file
                .as_ref()
                .map_or("the defaults".to_string(), |f| f.display().to_string());
            for (k, f, e) in crate::param::diff(&now, &want) {
                println!("{k}: firmware {f:?}, {against} {e:?}");
            }
        }
    }
    Ok(())
}

/// Sets `key=value` tokens in order, printing each; stops at the first refused.
fn set_tokens(master: &mut crate::commands::PortMaster, tokens: &[String]) -> Result<(), String> {
    for t in tokens {
        let (k, v) = crate::param::split_token(t)?;
        crate::param::set(master, k, v)?;
        println!("{k}={v}");
    }
    Ok(())
}

/// A plan file's firmware tokens (its walk and its `[firmware]` table).
fn plan_tokens(file: &Path) -> Result<Vec<String>, String> {
    crate::planfile::load(file)
        .and_then(|p| p.firmware_tokens())
        .map_err(|e| format!("{}: {e}", file.display()))
}

/// What `fil`, `beyond` and `sweep` start from: the walk, the simulated robot, the QEMU run
/// and the extra firmware tokens, from `--config` (or `--plan`) and the command line's options
/// over it; the firmware tokens are checked with the firmware's own parser.
struct RunSetup {
    spec: WalkSpec,
    plan_name: String,
    sim: crate::sim::SimConfig,
    elf: PathBuf,
    machine: String,
    timeout: Duration,
    extra_tokens: Vec<String>,
}

impl RunSetup {
    fn new(cmd: &str, a: RunArgs) -> Result<RunSetup, CliError> {
        let (mut spec, plan_name, file_sim, file) = match &a.config {
            Some(c) => {
                let rc = crate::runconfig::load(c).map_err(CliError::failed)?;
                let file = (rc.elf, rc.machine, rc.timeout);
                (rc.spec, c.display().to_string(), rc.sim, file)
            }
            None => {
                let (spec, name) = load_plan(a.plan.as_deref())?;
                (spec, name, SimArgs::default(), (None, None, None))
            }
        };
        let mut sim = crate::sim::SimConfig::default();
        a.sim.over(file_sim).apply(cmd, &mut sim)?;
        let extra_tokens = tokens(a.firmware_args.as_deref());
        if let Some(name) = &a.robot {
            with_robot(cmd, &mut spec, name)?;
        }
        // The firmware's own parser, on the host, before QEMU starts; the simulated robot is
        // the one the firmware will walk (the plan's, or a `robot=` of --firmware-args).
        let (_, fw) = crate::fil::check_tokens(&spec, &extra_tokens)
            .map_err(|e| CliError::usage(format!("walker {cmd}: --firmware-args: {e}")))?;
        sim.robot = *fw.robot;
        for w in crate::fil::token_overrides(&spec, &extra_tokens) {
            eprintln!("warning: walker {cmd}: --firmware-args: {w}");
        }
        let elf = a.elf.or(file.0).unwrap_or_else(|| DEFAULT_ELF.into());
        let machine = a
            .machine
            .or(file.1)
            .unwrap_or_else(|| crate::qemu::default_machine(&elf).into());
        crate::qemu::check_machine(&elf, &machine)
            .map_err(|e| CliError::usage(format!("walker {cmd}: --machine: {e}")))?;
        Ok(RunSetup {
            spec,
            plan_name,
            sim,
            machine,
            elf,
            timeout: a.timeout.or(file.2).unwrap_or(Duration::from_secs(1800)),
            extra_tokens,
        })
    }
}

impl RunSetup {
    /// The runs' options with their output in `out_dir`, and the plan's name.
    fn into_fil(self, out_dir: PathBuf) -> (crate::fil::FilOptions, String) {
        let opts = crate::fil::FilOptions {
            elf: self.elf,
            spec: self.spec,
            out_dir,
            machine: self.machine,
            timeout: self.timeout,
            sim: self.sim,
            extra_tokens: self.extra_tokens,
        };
        (opts, self.plan_name)
    }
}

/// The plan `spec` walked by the robot `name` (`--robot`): a plan written for another robot is
/// refused; one that names none is checked against this robot's legs and walks it (the
/// firmware's `robot=` and the simulated robot follow the plan's robot).
fn with_robot(cmd: &str, spec: &mut WalkSpec, name: &str) -> Result<(), CliError> {
    let robot = Robot::by_name(name)
        .ok_or_else(|| CliError::usage(format!("walker {cmd}: unknown robot {name}")))?;
    match spec.robot.as_deref() {
        Some(own) if own != name => Err(CliError::usage(format!(
            "walker {cmd}: --robot {name}: the plan is written for the robot {own}"
        ))),
        Some(_) => Ok(()),
        None => {
            spec.robot = Some(name.to_string());
            spec.check(robot)
                .map_err(|e| CliError::usage(format!("walker {cmd}: --robot {name}: {e}")))
        }
    }
}

/// Loads `--plan` (or the built-in Table 2 walk); the plan's name for the reports.
fn load_plan(plan: Option<&Path>) -> Result<(WalkSpec, String), CliError> {
    match plan {
        Some(p) => Ok((planfile::load(p)?, p.display().to_string())),
        None => Ok((WalkSpec::default(), "built-in Table 2 walk".to_string())),
    }
}

fn create_parent(p: &Path) -> Result<(), CliError> {
    if let Some(d) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)
            .map_err(|e| CliError::failed(format!("cannot create {}: {e}", d.display())))?;
    }
    Ok(())
}

/// Splits `'k=v k=v'` into tokens.
fn tokens(s: Option<&str>) -> Vec<String> {
    s.map(|t| t.split_whitespace().map(String::from).collect())
        .unwrap_or_default()
}

impl SimArgs {
    /// Applies the options given to `cfg` (the shared physics options, the seed and the stall
    /// torque); a value the simulator refuses is a usage error naming the option.
    pub fn apply(&self, cmd: &str, cfg: &mut crate::sim::SimConfig) -> Result<(), CliError> {
        let bad = |m: String| CliError::usage(format!("walker {cmd}: {m}"));
        if let Some(p) = self.physics {
            cfg.physics = p.into();
        }
        if let Some(s) = self.seed {
            cfg.seed = s;
        }
        cfg.pushes.extend(self.push.iter().copied());
        if let Some(v) = self.floor_friction {
            cfg.env.floor_friction = v;
        }
        if let Some(v) = self.floor_steps {
            cfg.env.step_height_m = v * 1e-3;
        }
        if let Some(v) = self.slope {
            cfg.env.slope_deg = v;
        }
        if let Some(v) = self.payload {
            cfg.env.payload_kg = v;
        }
        if let Some(v) = self.sensor_latency_ms {
            cfg.noise.latency_us = (v * 1e3).round() as u64;
        }
        if let Some(v) = self.servo_voltage {
            cfg.xservo.supply_voltage = v;
        }
        if let Some(v) = self.force_noise {
            cfg.noise.force_std_n = v;
        }
        if let Some(v) = self.gyro_noise {
            cfg.noise.gyro_std_rad_s = v;
        }
        if let Some(v) = self.accel_noise {
            cfg.noise.accel_std_m_s2 = v;
        }
        if let Some(p) = self.p_drop {
            cfg.faults.p_drop = p;
        }
        if let Some(p) = self.p_corrupt {
            cfg.faults.p_corrupt = p;
        }
        cfg.faults.dead_ids.extend(self.dead.iter().copied());
        cfg.faults.outages.extend(self.outage.iter().copied());
        if self.fall_at.is_some() {
            cfg.fall.forced_at_s = self.fall_at;
        }
        if let Some(t) = self.tau_constant {
            cfg.disturbance.constant_nm = t;
        }
        if let Some(t) = self.tau_random {
            cfg.disturbance.random_std_nm = t;
        }
        if let Some(t) = self.stall_torque {
            apply_stall_torque(cfg, t).map_err(|e| bad(format!("--stall-torque: {e}")))?;
        }
        cfg.env
            .validate()
            .map_err(|e| bad(format!("floor/payload options: {e}")))?;
        if !cfg.xservo.is_valid() {
            return Err(bad("--servo-voltage must be > 0".into()));
        }
        Ok(())
    }
}

impl SimArgs {
    /// These options over `base` (a configuration file's): a value given here wins, lists are
    /// `base`'s followed by these.
    pub fn over(self, base: SimArgs) -> SimArgs {
        let mut push = base.push;
        push.extend(self.push);
        let mut dead = base.dead;
        dead.extend(self.dead);
        let mut outage = base.outage;
        outage.extend(self.outage);
        SimArgs {
            physics: self.physics.or(base.physics),
            seed: self.seed.or(base.seed),
            stall_torque: self.stall_torque.or(base.stall_torque),
            servo_voltage: self.servo_voltage.or(base.servo_voltage),
            push,
            floor_friction: self.floor_friction.or(base.floor_friction),
            floor_steps: self.floor_steps.or(base.floor_steps),
            slope: self.slope.or(base.slope),
            payload: self.payload.or(base.payload),
            sensor_latency_ms: self.sensor_latency_ms.or(base.sensor_latency_ms),
            force_noise: self.force_noise.or(base.force_noise),
            gyro_noise: self.gyro_noise.or(base.gyro_noise),
            accel_noise: self.accel_noise.or(base.accel_noise),
            p_drop: self.p_drop.or(base.p_drop),
            p_corrupt: self.p_corrupt.or(base.p_corrupt),
            dead,
            outage,
            fall_at: self.fall_at.or(base.fall_at),
            tau_constant: self.tau_constant.or(base.tau_constant),
            tau_random: self.tau_random.or(base.tau_random),
        }
    }

    /// Checks the numbers of a configuration file's `[sim]` table with the very value parsers
    /// of the command line; an error names the field.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        type Check = fn(&str) -> Result<f64, String>;
        let checks: [(&'static str, Option<f64>, Check); 15] = [
            ("stall_torque", self.stall_torque, non_negative),
            ("servo_voltage", self.servo_voltage, positive),
            ("floor_friction", self.floor_friction, finite),
            ("floor_steps", self.floor_steps, finite),
            ("slope", self.slope, finite),
            ("payload", self.payload, finite),
            ("sensor_latency_ms", self.sensor_latency_ms, latency_ms),
            ("force_noise", self.force_noise, non_negative),
            ("gyro_noise", self.gyro_noise, non_negative),
            ("accel_noise", self.accel_noise, non_negative),
            ("p_drop", self.p_drop, probability),
            ("p_corrupt", self.p_corrupt, probability),
            ("fall_at", self.fall_at, non_negative),
            ("tau_constant", self.tau_constant, finite),
            ("tau_random", self.tau_random, non_negative),
        ];
        for (name, value, check) in checks {
            if let Some(x) = value {
                check(&x.to_string()).map_err(|e| (name, e))?;
            }
        }
        Ok(())
    }
}

/// A stall torque `t` (N·m) for both servo models: the kinematic model's torque–speed line
/// (0 = unlimited) and the MuJoCo XM430-W350 model's stall torque (which must be > 0).
pub fn apply_stall_torque(cfg: &mut crate::sim::SimConfig, t: f64) -> Result<(), String> {
    if !(t.is_finite() && t >= 0.0) {
        return Err(format!("must be >= 0 N·m (got {t})"));
    }
    if t == 0.0 {
        if cfg.physics == crate::sim::PhysicsModel::MuJoCo {
            return Err(
                "0 (unlimited) is for --physics kinematic; a MuJoCo servo needs a stall torque > 0"
                    .into(),
            );
        }
        cfg.servo_torque = None;
    } else {
        cfg.servo_torque = Some(crate::sim::ServoTorque {
            stall_torque: t,
            ..cfg.servo_torque.unwrap_or(crate::sim::ServoTorque::XM430)
        });
        cfg.xservo.stall_torque = t;
    }
    Ok(())
}

fn run_export(a: ExportArgs) -> Result<(), CliError> {
    let ExportArgs { plan, out, dt } = a;
    let (spec, name) = match plan.as_deref() {
        Some(p) => (
            export::load_for_export(p).map_err(CliError::failed)?,
            p.display().to_string(),
        ),
        None => load_plan(None)?,
    };
    let dt = dt.unwrap_or(spec.dt);
    let (rows, summary) = export::export_rows(&spec, spec.robot(), dt).map_err(|e| {
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

fn run_report(a: ReportArgs) -> Result<(), CliError> {
    let ReportArgs {
        log,
        out,
        truth,
        plan,
        model,
        mcap,
    } = a;
    let (mut spec, plan_name) = load_plan(plan.as_deref())?;
    if let Some(m) = model {
        spec.model = m;
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
    let r = report::run(&opts, opts.spec.robot())?;
    for w in &r.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(m) = &mcap {
        let counts = crate::mcap_export::export_run(&opts, &r, opts.spec.robot(), None, m)?;
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

fn run_compare(a: CompareArgs) -> Result<(), CliError> {
    let CompareArgs {
        runs: RunList(runs),
        out,
    } = a;
    let mut results = Vec::new();
    for (name, path) in &runs {
        if !path.exists() {
            return Err(CliError::failed(format!(
                "log file {} (run {name}) not found",
                path.display()
            )));
        }
        let log = report::decode_file(path)?;
        let warnings = report::check_walking(&log, path)
            .map_err(|e| CliError::failed(format!("run {name}: {e}")))?;
        for w in warnings {
            eprintln!("warning: run {name}: {w}");
        }
        let stats = report::error_stats(&report::tick_rows(&log.ticks));
        if stats.x.count == 0 {
            return Err(CliError::failed(format!(
                "run {name}: the log {} has no tick with a valid measured ZMP ({} ticks): nothing to compare",
                path.display(),
                stats.ticks
            )));
        }
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

fn run_capture(a: CaptureArgs) -> Result<(), CliError> {
    let CaptureArgs {
        list,
        port,
        from_file: from,
        baud,
        out,
        seconds,
        defmt,
        elf,
    } = a;
    let seconds = seconds.map(|d| d.as_secs_f64());
    // Decoded first: a missing ELF or stream is reported before a capture starts.
    if let (Some(raw), Some(elf)) = (&defmt, &elf) {
        let mut name = raw.file_name().unwrap_or_default().to_os_string();
        name.push(".log");
        let text = raw.with_file_name(name);
        let (l, warnings) = crate::defmt_log::decode_checked_file(elf, raw, &text)?;
        for w in warnings {
            eprintln!("warning: {w}");
        }
        println!("{}: {}", text.display(), l.summary());
        for w in l.warnings().take(20) {
            println!("  {}", w.text);
        }
        if from.is_none() && port.is_none() {
            return Ok(());
        }
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
        // clap's group and conflict: one of --list, --port, --from-file (and --defmt).
        (Some(_), Some(_)) | (None, None) => {
            return Err(CliError::usage(
                "walker capture: give one of --list, --port, --from-file, --defmt",
            ))
        }
        (Some(input), None) => {
            if !input.exists() {
                return Err(CliError::failed(format!(
                    "capture file {} not found",
                    input.display()
                )));
            }
            let (log, files, warnings) = capture::from_file(&input, out.as_deref())?;
            for w in warnings {
                eprintln!("warning: {w}");
            }
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
                baud,
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
            // What was read is kept whatever it is; a capture that is no usable log fails.
            match report::check_log(&log, &out) {
                Ok(warnings) => {
                    for w in warnings {
                        eprintln!("warning: {w}");
                    }
                }
                Err(e) => {
                    return Err(CliError::failed(format!(
                        "{e} (the bytes read are kept in {}; wrong baud rate or port?)",
                        out.display()
                    )))
                }
            }
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

fn run_simulate(a: SimulateArgs) -> Result<(), CliError> {
    let mut cfg = crate::sim::SimConfig::default();
    a.sim.apply("simulate", &mut cfg)?;
    cfg.port = a.port;
    cfg.lockstep_port = a.lockstep_port;
    cfg.connect = a.connect;
    if let Some(t) = a.timeout {
        cfg.connect_timeout = t;
    }
    if let Some(t) = &a.truth {
        create_parent(t)?;
    }
    cfg.log_truth = a.truth;
    let connect = cfg.connect;
    let handle = crate::sim::transport::spawn(cfg)
        .map_err(|e| CliError::failed(format!("walker simulate: {e}")))?;
    // The addresses bound (with `--port 0`: the port the system chose, never 0).
    eprintln!(
        "simulated robot on {} (lock-step {}); {}",
        handle
            .bus_addr()
            .map_or("the lock-step pipes".to_string(), |a| a.to_string()),
        handle
            .lockstep_addr()
            .map_or("off".to_string(), |a| a.to_string()),
        match connect {
            true => "connecting to the firmware (QEMU listening) …",
            false => "waiting for the firmware to connect …",
        }
    );
    let summary = handle
        .join()
        .map_err(|e| CliError::failed(format!("walker simulate: {e}")))?;
    println!("{summary:#?}");
    Ok(())
}

fn run_beyond(a: BeyondArgs) -> Result<(), CliError> {
    let RunSetup {
        spec,
        plan_name,
        sim,
        elf,
        machine,
        timeout,
        extra_tokens: extra,
    } = RunSetup::new("beyond", a.run)?;
    let feedback = tokens(a.feedback_args.as_deref());
    crate::fil::check_tokens(&spec, &feedback)
        .map_err(|e| CliError::usage(format!("walker beyond: --feedback-args: {e}")))?;
    let out = a.out;
    let opts = crate::beyond::BeyondOptions {
        elf,
        spec,
        out_dir: out.clone(),
        machine,
        seed: sim.seed,
        extra_tokens: extra,
        feedback_tokens: feedback,
        timeout,
        servo_torque: sim.servo_torque,
        sim,
    };
    let variants: Vec<crate::beyond::Variant> = if a.ablation {
        crate::beyond::ablation().to_vec()
    } else {
        crate::beyond::variants().to_vec()
    };
    eprintln!(
        "walker beyond: {plan_name}, {} firmware-in-the-loop walks",
        variants.len()
    );
    let progress = Progress::stderr(variants.len(), "walking");
    let runs = crate::beyond::run(&opts, &variants, &progress)?;
    let table = crate::beyond::table(&runs);
    let servo_torque = opts.servo_torque;
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
    let title = if a.ablation {
        "The closed loop, one part at a time"
    } else {
        "Beyond the paper"
    };
    let mut md = format!(
        "# {title}: {plan_name}\n\n{servos}\nErrors against the firmware's ZMP reference over the walking ticks; peak joint speeds are the simulator's (true) and the firmware's targets'.\n\n"
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

/// `walker fil --command-port`: the firmware waits for an external master; the run ends when
/// it exits (torque off on command is a normal end).
fn run_fil_command_port(
    opts: &crate::fil::FilOptions,
    spec: &WalkSpec,
    plan_name: &str,
    port: u16,
) -> Result<(), CliError> {
    let port = match port {
        0 => crate::fil::free_port()?,
        p => p,
    };
    eprintln!(
        "walker fil: {plan_name} on command in QEMU {}; command port on 127.0.0.1:{port} \
         (Dynamixel Protocol 2.0, ID {}, QEMU listening; Mode = 0 ends the run)",
        opts.machine,
        walker_contract::command_port::PORT_ID
    );
    let status = StatusLine::stderr(STATUS_EVERY);
    let r = crate::fil::run_command_port(opts, port, |t, _| {
        status.set(&format!("  simulated time {t:6.2} s"))
    });
    status.finish();
    let r = r?;
    eprintln!("  {}", crate::fil::summary_line(&r.sim));
    eprintln!("  wall clock {:.1} s", r.wall.as_secs_f64());
    match crate::fil::command_figures(&r, spec, &opts.extra_tokens) {
        Ok(f) => println!("{}", f.line()),
        Err(e) => println!("no command figures: {e}"),
    }
    println!("log: {}, truth: {}", r.log.display(), r.truth.display());
    firmware_end(r.exit_code, &[0, crate::fil::END_BY_COMMAND])
}

/// The run's result by the firmware's exit code: `ok` codes are a normal end, anything else
/// (or no code: killed, timed out) exit code 3.
fn firmware_end(code: Option<i32>, ok: &[i32]) -> Result<(), CliError> {
    match code {
        Some(c) if ok.contains(&c) => Ok(()),
        code => Err(CliError {
            message: format!("the firmware exited with code {code:?}"),
            code: 3,
        }),
    }
}

fn run_fil(a: FilArgs) -> Result<(), CliError> {
    let RunSetup {
        mut spec,
        plan_name,
        mut sim,
        elf,
        machine,
        timeout,
        extra_tokens,
    } = RunSetup::new("fil", a.run)?;
    let extra_tokens = if a.open_loop {
        let open = crate::beyond::OPEN_LOOP.iter().map(|t| t.to_string());
        open.chain(extra_tokens).collect()
    } else {
        extra_tokens
    };
    if let Some(m) = a.model {
        spec.model = m;
    }
    if sim.physics == crate::sim::PhysicsModel::Kinematic && !a.open_loop {
        // docs/simulation.md: the idealised model checks the open-loop chain.
        eprintln!(
            "warning: walker fil: the kinematic robot's trunk follows its joints exactly; the \
             firmware's feedback acts on it without meaning (long walks end \"fallen\"): add \
             --open-loop"
        );
    }
    let out = a.out;
    let video = a.video;
    if video.is_some() && sim.physics != crate::sim::PhysicsModel::MuJoCo {
        return Err(CliError::usage(
            "walker fil: --video needs the MuJoCo robot (--physics mujoco)",
        ));
    }
    if video.is_some() {
        sim.model_out = Some(out.join("model.xml"));
        sim.qpos_out = Some(out.join("qpos.csv"));
    }
    let opts = crate::fil::FilOptions {
        elf,
        spec: spec.clone(),
        out_dir: out.clone(),
        machine,
        timeout,
        sim,
        extra_tokens,
    };
    // A command line QEMU would refuse: a clear error before anything starts.
    crate::fil::qemu_append(&opts).map_err(|e| CliError::usage(format!("walker fil: {e}")))?;
    if let Some(path) = &a.commands {
        let script = crate::commands::CommandScript::read(path)
            .map_err(|e| CliError::usage(format!("walker fil: --commands {e}")))?;
        eprintln!(
            "walker fil: {} on command ({}, {} commands) in QEMU {}",
            plan_name,
            path.display(),
            script.command.len(),
            opts.machine
        );
        let status = StatusLine::stderr(STATUS_EVERY);
        let ran = crate::fil::run_commands_to_the_end(&opts, &script, |t, _| {
            status.set(&format!("  simulated time {t:6.2} s"))
        });
        status.finish();
        let (r, d) = ran?;
        eprintln!("  {}", crate::fil::summary_line(&r.sim));
        match &d {
            Ok(d) => eprintln!(
                "  stood ready at {:.2} s; commands sent at {:?} s",
                d.ready_us as f64 * 1e-6,
                d.sent_us
                    .iter()
                    .map(|t| (*t as f64 * 1e-6 * 100.0).round() / 100.0)
                    .collect::<Vec<_>>()
            ),
            Err(e) => eprintln!("  the script did not finish: {e}"),
        }
        let f = crate::fil::command_figures(&r, &spec, &opts.extra_tokens)?;
        println!("{}", f.line());
        println!("log: {}, truth: {}", r.log.display(), r.truth.display());
        return match d {
            Ok(_) => Ok(()),
            Err(_) => Err(CliError {
                message: format!(
                    "the firmware ended (exit code {:?}) before the command script did",
                    r.exit_code
                ),
                code: 3,
            }),
        };
    }
    if let Some(port) = a.command_port {
        return run_fil_command_port(&opts, &spec, &plan_name, port);
    }
    eprintln!(
        "walker fil: {} ({:?}) in QEMU {} against the simulated robot",
        plan_name, spec.model, opts.machine
    );
    let status = StatusLine::stderr(STATUS_EVERY);
    let r = crate::fil::run(&opts, |t, n| {
        status.set(&format!("  simulated time {t:6.2} s, {n} bus instructions"))
    });
    status.finish();
    let r = r?;
    eprintln!("  {}", crate::fil::summary_line(&r.sim));
    match &r.firmware_log {
        Ok(l) => {
            eprintln!(
                "  firmware log: {} ({})",
                out.join("firmware.log").display(),
                l.summary()
            );
            for w in l.warnings().take(20) {
                eprintln!("    {}", w.text);
            }
        }
        Err(e) => eprintln!("  firmware log: not decoded: {e}"),
    }
    eprintln!("  wall clock {:.1} s", r.wall.as_secs_f64());
    // The report draws the plan with the timing the firmware adjusted at start-up (it reads
    // the adjustments from the log).
    let ropts = report::ReportOptions {
        log: r.log.clone(),
        out_dir: out.join("report"),
        truth: Some(r.truth.clone()),
        spec: spec.clone(),
        plan_name,
    };
    let rep = match report::run(&ropts, spec.robot()) {
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
    for w in &rep.warnings {
        eprintln!("warning: {w}");
    }
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
    // The truth file read once for both figures.
    if let Ok(t) = crate::report::read_truth(&r.truth) {
        if let Ok(w) = crate::fil::walk_figures_of(&t, &r.truth, &spec) {
            println!("\nin the physics: {}", w.line());
        }
        let planned = crate::fil::planned_feet_travel(&spec).ok();
        if let Some(f) = planned.and_then(|p| crate::fil::sole_figures(&t, p)) {
            println!("  {}", f.line());
        }
    }
    println!("\nreport: {}", out.join("report").display());
    if let Some(m) = &a.mcap {
        let tokens: Vec<String> = crate::fil::qemu_append(&opts)
            .map(|t| t.split_whitespace().map(str::to_string).collect())
            .map_err(|e| CliError::failed(format!("walker fil: {e}")))?;
        let counts = crate::mcap_export::export_run(&ropts, &rep, spec.robot(), Some(&tokens), m)?;
        println!(
            "mcap: {} ({} channels, {} messages)",
            m.display(),
            counts.len(),
            counts.values().sum::<u64>()
        );
    }
    if let Some(v) = &video {
        eprintln!("  rendering {} …", v.display());
        crate::video::render(&out.join("model.xml"), &out.join("qpos.csv"), v)
            .map_err(|e| CliError::failed(format!("walker fil: --video: {e}")))?;
        println!("video: {}", v.display());
    }
    firmware_end(r.exit_code, &[0])
}

fn run_sweep(a: SweepArgs) -> Result<(), CliError> {
    use crate::sweep::{self, goal, Shard};
    if a.ablate {
        return run_ablation(a);
    }
    let out = a.out;
    if !a.merge.is_empty() {
        return merge_sweep(&out, a.family, &a.merge);
    }
    let (opts, plan_name) = RunSetup::new("sweep", a.run)?.into_fil(out.clone());
    let shard = a.shard.unwrap_or(Shard::ALL);
    let cases = sweep::shard_cases(a.family, shard, &a.case).map_err(CliError::failed)?;
    let n = cases.len();
    eprintln!(
        "walker sweep: {plan_name}, {n} firmware-in-the-loop walks (shard {}/{}), {} at a time",
        shard.index, shard.count, a.jobs
    );
    let progress = Progress::stderr(n, "walking");
    let rows = sweep::walk_cases(&opts, &cases, usize::from(a.jobs), &progress)?;
    std::fs::create_dir_all(&out)
        .map_err(|e| CliError::failed(format!("{}: {e}", out.display())))?;
    sweep::write_rows(&out.join("rows.csv"), &rows).map_err(CliError::failed)?;
    let title = match shard {
        Shard::ALL => plan_name,
        s => format!(
            "{plan_name} (shard {}/{}; `walker sweep --merge` joins the shards)",
            s.index, s.count
        ),
    };
    let mut md = format!(
        "# Robustness sweep: {title}\n\nThe firmware's defaults (closed loop) on the MuJoCo robot, nominal and one perturbation per case; true CoP − reference over the walking ticks. Goals: no fall, ≥ {:.0} % of the planned distance, heading drift < {}°, ZMP mean |e| < {} mm sagittal and < {} mm lateral.\n\n",
        goal::DISTANCE * 100.0,
        goal::HEADING_DEG,
        goal::ZMP_X * 1e3,
        goal::ZMP_Y * 1e3
    );
    md.push_str(&sweep::table(&rows));
    write_report(&out, "sweep.md", &md)?;
    match rows.iter().find(|r| r.exit_code != Some(0)) {
        None => Ok(()),
        Some(r) => Err(CliError {
            message: format!("case {} exited with {:?}", r.name, r.exit_code),
            code: 3,
        }),
    }
}

/// `walker sweep --ablate`: the family walked with the defaults and once per feature off (each
/// into its sub-folder, sharded like a sweep), or with `--merge` the sub-folders of the shards
/// joined; then OUT/ablation.md.
fn run_ablation(a: SweepArgs) -> Result<(), CliError> {
    use crate::ablation::{self, DEFAULTS, FEATURES};
    let out = a.out.clone();
    use crate::sweep::{self, Shard};
    let configs: Vec<(&str, &[&str])> = std::iter::once((DEFAULTS, &[][..]))
        .chain(FEATURES.iter().map(|f| (f.name, f.off)))
        .collect();
    let mut all: Vec<Vec<sweep::SweepRow>> = Vec::new();
    if a.merge.is_empty() {
        let (opts, plan_name) = RunSetup::new("sweep", a.run)?.into_fil(out.clone());
        let shard = a.shard.unwrap_or(Shard::ALL);
        let cases = sweep::shard_cases(a.family, shard, &a.case).map_err(CliError::failed)?;
        let n = cases.len();
        eprintln!(
            "walker sweep --ablate: {plan_name}, {} configurations × {n} walks (shard {}/{}), {} at a time",
            configs.len(),
            shard.index,
            shard.count,
            a.jobs
        );
        for (name, off) in &configs {
            let mut o = opts.in_sub(name);
            o.extra_tokens.extend(off.iter().map(|t| t.to_string()));
            // Resume: the cases this folder's rows.csv already holds are not walked again.
            let rows_csv = o.out_dir.join("rows.csv");
            let done = sweep::read_rows(&rows_csv).unwrap_or_default();
            let todo: Vec<sweep::SweepCase> = cases
                .iter()
                .copied()
                .filter(|c| !done.iter().any(|r| r.name == c.name))
                .collect();
            if !done.is_empty() {
                eprintln!(
                    "  {name}: {} cases from {}, {} to walk",
                    n - todo.len(),
                    rows_csv.display(),
                    todo.len()
                );
            }
            let progress = Progress::stderr(todo.len(), &format!("{name}: walking"));
            let walked = sweep::walk_cases(&o, &todo, usize::from(a.jobs), &progress)?;
            let (rows, _) = sweep::merge(a.family, vec![done, walked]).map_err(CliError::failed)?;
            std::fs::create_dir_all(&o.out_dir)
                .map_err(|e| CliError::failed(format!("{}: {e}", o.out_dir.display())))?;
            sweep::write_rows(&rows_csv, &rows).map_err(CliError::failed)?;
            let md = format!(
                "# Robustness sweep: {plan_name}, {name}\n\nFirmware tokens after the run's own: `{}`.\n\n{}",
                off.join(" "),
                sweep::table(&rows)
            );
            write_report(&o.out_dir, "sweep.md", &md)?;
            all.push(rows);
        }
    } else {
        for (name, off) in &configs {
            let parts = a
                .merge
                .iter()
                .map(|d| {
                    let path = d.join(name).join("rows.csv");
                    if path.exists() {
                        sweep::read_rows(&path)
                    } else {
                        eprintln!("walker sweep --ablate --merge: {} absent", path.display());
                        Ok(Vec::new())
                    }
                })
                .collect::<Result<Vec<_>, _>>()
                .map_err(CliError::failed)?;
            let (rows, missing) = sweep::merge(a.family, parts).map_err(CliError::failed)?;
            if !missing.is_empty() {
                eprintln!(
                    "walker sweep --ablate --merge: {name}: no shard ran {}",
                    missing.join(", ")
                );
            }
            let dir = out.join(name);
            std::fs::create_dir_all(&dir)
                .map_err(|e| CliError::failed(format!("{}: {e}", dir.display())))?;
            sweep::write_rows(&dir.join("rows.csv"), &rows).map_err(CliError::failed)?;
            let md = format!(
                "# Robustness sweep (merged from {} shards), {name}\n\nFirmware tokens after the run's own: `{}`.\n\n{}",
                a.merge.len(),
                off.join(" "),
                sweep::table(&rows)
            );
            write_report(&dir, "sweep.md", &md)?;
            all.push(rows);
        }
    }
    let mut it = all.into_iter();
    let defaults = it.next().unwrap_or_default();
    let offs: [Vec<sweep::SweepRow>; FEATURES.len()] =
        std::array::from_fn(|_| it.next().unwrap_or_default());
    let md = format!(
        "# Ablation over the {:?} family\n\nThe family walked with the firmware's defaults and once per feature off; a feature stays on by default only if it is nowhere worse than off (host/src/ablation.rs).\n\n{}",
        a.family,
        ablation::tables(&defaults, &offs)
    );
    write_report(&out, "ablation.md", &md)
}

/// `walker sweep --merge DIR…`: the table of the shards' rows.
fn merge_sweep(
    out: &std::path::Path,
    family: crate::sweep::Family,
    dirs: &[PathBuf],
) -> Result<(), CliError> {
    use crate::sweep;
    let parts = dirs
        .iter()
        .map(|d| sweep::read_rows(&d.join("rows.csv")))
        .collect::<Result<Vec<_>, _>>()
        .map_err(CliError::failed)?;
    let (rows, missing) = sweep::merge(family, parts).map_err(CliError::failed)?;
    if !missing.is_empty() {
        eprintln!(
            "walker sweep --merge: no shard ran {} of {} cases: {}",
            missing.len(),
            family.cases().len(),
            missing.join(", ")
        );
    }
    std::fs::create_dir_all(out)
        .map_err(|e| CliError::failed(format!("{}: {e}", out.display())))?;
    sweep::write_rows(&out.join("rows.csv"), &rows).map_err(CliError::failed)?;
    let mut md = format!(
        "# Robustness sweep (merged from {} shards)\n\nThe firmware's defaults (closed loop) on the MuJoCo robot; true CoP − reference over the walking ticks.\n\n",
        dirs.len()
    );
    md.push_str(&sweep::table(&rows));
    write_report(out, "sweep.md", &md)?;
    match rows.iter().find(|r| r.exit_code != Some(0)) {
        Some(r) => Err(CliError {
            message: format!("case {} exited with {:?}", r.name, r.exit_code),
            code: 3,
        }),
        None if !missing.is_empty() => Err(CliError::failed(format!(
            "{} cases missing from the shards",
            missing.len()
        ))),
        None => Ok(()),
    }
}

fn run_pushes(a: PushesArgs) -> Result<(), CliError> {
    use crate::pushes::{self, Condition};
    let out = a.out;
    let (base, plan_name) = RunSetup::new("pushes", a.run)?.into_fil(out.clone());
    if !(a.walk_at.is_finite()
        && a.walk_at >= 0.0
        && a.stand_after.is_finite()
        && a.stand_after >= 0.0
        && a.stand_after < pushes::STAND_HOLD)
    {
        return Err(CliError::usage(format!(
            "walker pushes: --walk-at must be ≥ 0 and --stand-after in [0, {}) s",
            pushes::STAND_HOLD
        )));
    }
    let conditions = match a.only.as_deref() {
        Some("standing") => vec![Condition::Standing],
        Some("walking") => vec![Condition::Walking],
        _ => vec![Condition::Standing, Condition::Walking],
    };
    let opts = pushes::PushOptions {
        base,
        step: a.step,
        max: a.max,
        walk_at: a.walk_at,
        stand_after: a.stand_after,
        conditions,
    };
    let total = pushes::planned_runs(&opts);
    eprintln!("walker pushes: {plan_name}, at most {total} firmware-in-the-loop walks");
    let progress = Progress::stderr(total, "walking");
    let rows = pushes::run(&opts, &progress).map_err(CliError::failed)?;
    let mut md = format!(
        "# Largest torso push survived: {plan_name}\n\nThe firmware's defaults on the MuJoCo robot; a push is a 10 ms horizontal force on the torso. Walking: pushed at {:.2} s of the walk, survived = no fall and the walk ends normally. Standing: pushed {:.2} s after standing ready, survived = no fall and the run ends by the commanded torque off. Resolution {:.2} N·s, up to {:.2} N·s; one run per level (host/src/pushes.rs).\n\n",
        a.walk_at, a.stand_after, a.step, a.max
    );
    md.push_str(&pushes::table(&rows, a.max));
    write_report(&out, "pushes.md", &md)
}

/// Writes the Markdown report `md` to OUT/`name` and prints it.
fn write_report(out: &std::path::Path, name: &str, md: &str) -> Result<(), CliError> {
    std::fs::create_dir_all(out)
        .map_err(|e| CliError::failed(format!("{}: {e}", out.display())))?;
    let path = out.join(name);
    std::fs::write(&path, md).map_err(|e| CliError::failed(format!("{}: {e}", path.display())))?;
    print!("{md}");
    println!("\nwritten: {}", path.display());
    Ok(())
}

/// `walker drive`: the port, the terminal in raw mode, the session, then (with `--sim`) the
/// run's end.
fn run_drive(a: DriveArgs) -> Result<(), CliError> {
    let mut sim = match a.sim {
        true => Some(crate::drive::SimRun::start(
            a.plan.as_deref(),
            a.robot.as_deref(),
            a.elf.as_deref(),
            &a.out,
        )?),
        false => None,
    };
    let wait = crate::drive::CONNECT_WAIT.as_secs();
    let master = match (&a.port.connect, &a.port.serial, &mut sim) {
        (Some(addr), _, _) => {
            eprintln!("walker drive: waiting for the firmware on {addr} (up to {wait} s) …");
            crate::drive::connect(addr, None)
        }
        (_, Some(dev), _) => {
            eprintln!("walker drive: opening {dev} at {} baud …", a.port.baud);
            crate::commands::PortMaster::serial(dev, a.port.baud)
        }
        (_, _, Some(run)) => {
            eprintln!(
                "walker drive: the simulated robot starts (walker fil --command-port {}, output in {})",
                run.port,
                a.out.display()
            );
            eprintln!(
                "walker drive: waiting for the firmware on 127.0.0.1:{} (up to {wait} s) …",
                run.port
            );
            crate::drive::connect(&format!("127.0.0.1:{}", run.port), Some(run))
        }
        _ => Err("walker drive: give --connect, --serial or --sim".to_string()),
    };
    let mut master = match master {
        Ok(m) => m,
        Err(e) => {
            if let Some(run) = sim.as_mut() {
                run.kill();
            }
            return Err(CliError::failed(e));
        }
    };
    let port_name = match (&a.port.connect, &a.port.serial, &sim) {
        (Some(addr), _, _) => addr.clone(),
        (_, Some(dev), _) => dev.clone(),
        (_, _, Some(run)) => format!("127.0.0.1:{}", run.port),
        _ => String::new(),
    };
    eprintln!(
        "walker drive: waiting for the firmware's command port on {port_name} to answer (up to {wait} s) …"
    );
    if let Err(e) = master.wait_ready(crate::drive::CONNECT_WAIT) {
        if let Some(run) = sim.as_mut() {
            run.kill();
        }
        return Err(CliError::failed(format!("walker drive: {e}")));
    }
    eprintln!("{}", crate::drive::HELP);
    let ended = {
        let _raw = crate::drive::RawTerminal::enter()?;
        // The drive's terminal is in raw mode (a terminal, never a file): the whole status
        // line is rewritten in place, however wide.
        use std::io::Write as _;
        let mut out = std::io::stderr();
        let ended = crate::drive::session(&mut master, crate::drive::terminal_key, |line| {
            let _ = write!(out, "\r{line}\x1b[K");
            let _ = out.flush();
        });
        eprintln!();
        ended
    };
    let ended = match ended {
        Ok(e) => e,
        Err(e) => {
            if let Some(run) = sim.as_mut() {
                run.kill();
            }
            return Err(CliError::failed(format!("walker drive: {e}")));
        }
    };
    eprintln!("walker drive: {ended:?}");
    if let Some(mut run) = sim {
        if ended == crate::drive::Ended::Quit {
            eprintln!("walker drive: waiting for the robot to stand, then torque off");
            let st = crate::drive::wait_standing(&mut master, Duration::from_secs(20))?;
            eprintln!("  {}", crate::drive::status_line(&st, &Default::default()));
            crate::drive::send(&mut master, crate::drive::Action::TorqueOff)?;
        }
        let text = run.finish(Duration::from_secs(120))?;
        print!("{text}");
    }
    Ok(())
}

fn run_speed(a: SpeedArgs) -> Result<(), CliError> {
    use crate::speed;
    let out = a.out;
    let (base, plan_name) = RunSetup::new("speed", a.run)?.into_fil(out.clone());
    let ok = |v: f64| v.is_finite() && v > 0.0;
    if !(ok(a.step_v) && ok(a.step_w)) {
        return Err(CliError::usage(
            "walker speed: --step-v and --step-w must be > 0".to_string(),
        ));
    }
    let opts = speed::SpeedOptions {
        base,
        step_v: a.step_v,
        step_w: a.step_w,
    };
    let total = speed::planned_runs(&opts);
    eprintln!("walker speed: {plan_name}, at most {total} firmware-in-the-loop walks");
    let progress = Progress::stderr(total, "walking");
    let rows = speed::run(&opts, &progress).map_err(CliError::failed)?;
    let mut md = format!(
        "# Fastest sustained walk on command: {plan_name}\n\nThe firmware's defaults on the MuJoCo robot, through the command port: the level held {:.0} s after the acceleration ramp; sustained = no fall, the run ends by the commanded torque off and the pelvis's mean over the hold within ± {:.0} % of the level. \"Delivered\" is what the step generator steps for the level after the leg's reach (host/src/speed.rs). Resolution {:.3} m/s and {:.3} rad/s, up to the command limits.\n\n",
        speed::HOLD_S,
        100.0 * speed::SUSTAIN_TOLERANCE,
        a.step_v,
        a.step_w
    );
    md.push_str(&speed::table(&rows));
    write_report(&out, "speed.md", &md)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_consistent() {
        Cli::command().debug_assert();
    }

    /// Every command and every option of every command has a help line.
    #[test]
    fn every_option_is_documented() {
        let cli = Cli::command();
        let mut options = 0;
        for cmd in cli.get_subcommands() {
            assert!(cmd.get_about().is_some(), "{}: no summary", cmd.get_name());
            for arg in cmd.get_arguments() {
                let id = arg.get_id().as_str();
                if id == "help" || id == "version" {
                    continue;
                }
                let help = arg.get_help().map(|h| h.to_string()).unwrap_or_default();
                assert!(
                    help.len() > 10,
                    "walker {} --{id}: no help line",
                    cmd.get_name()
                );
                options += 1;
            }
        }
        // export 3, report 6, compare 2, capture 5, simulate 5 + 10, fil 14 + 10, beyond 7 + 10.
        assert!(options >= 72, "{options} options");
    }

    #[test]
    fn numbers_are_checked_by_their_parsers() {
        for bad in ["nan", "-5", "1e300", "0", "inf", "x"] {
            assert!(seconds(bad).is_err(), "{bad}");
        }
        assert_eq!(seconds("2.5"), Ok(Duration::from_millis(2500)));
        assert!(probability("1.01").is_err() && probability("-0").is_ok());
        assert!(latency_ms("1000.5").is_err() && latency_ms("20").is_ok());
        assert!(finite("inf").is_err() && finite("-3").is_ok());
        assert!(non_negative("-1e-9").is_err() && positive("0").is_err());
        assert_eq!(
            parse_runs("a=x.log, b=y.log").unwrap().0,
            vec![("a".into(), "x.log".into()), ("b".into(), "y.log".into())]
        );
        for bad in ["", ",", "lipm", "=x", "a="] {
            assert!(parse_runs(bad).is_err(), "{bad:?}");
        }
    }
}
