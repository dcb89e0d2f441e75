//! One configuration file per run (`walker fil --config run.toml`, `walker beyond --config`):
//! the walk, the firmware's parameters, the simulated robot and the QEMU run in one TOML file.
//!
//! ```toml
//! plan_file = "table2.toml"     # a plan file, relative to this file; or an inline [plan] table
//! [plan]                        # the keys of a plan file (host/src/planfile.rs, plans/*.toml)
//! model = "tlipfm"
//! steps = 14
//! [firmware]                    # firmware parameters by token key (docs/parameters.md):
//! stab_kp = 0.5                 # any key of the contract's table without a plan key
//! feasibility = "stretch"
//! [sim]                         # the simulated robot: the options of `walker fil --help`
//! physics = "mujoco"            # (same names, `_` for `-`), e.g.
//! floor_steps = 5.0             # mm
//! push = ["3.2:1.5:0"]          # T:IMPULSE_NS:DIRECTION_DEG
//! [qemu]
//! machine = "mps2-an500"
//! timeout_s = 1800
//! ```
//!
//! Deserialised with serde through `serde_path_to_error`, so an error names the field's path
//! (`sim.floor_friction`, `plan.footsteps[1].x`); every table refuses unknown keys and the
//! message lists the valid ones (serde's `deny_unknown_fields`; for `[firmware]`, the keys of
//! the contract's parameter table, `walker_contract::params::PARAMS`, the one list of them).
//! The plan is then checked as a plan file is ([`planfile::load`]), the firmware keys by the
//! firmware's own parser, the `[sim]` numbers by the command line's value parsers
//! ([`SimArgs::check`]). Options given on the command line override the file.

use crate::cli::SimArgs;
use crate::planfile::{self, PlanError, WalkSpec};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A run configuration file as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunFile {
    /// A plan file, relative to the configuration file (instead of `[plan]`).
    pub plan_file: Option<PathBuf>,
    /// The walk, inline: the keys of a plan file.
    pub plan: Option<WalkSpec>,
    /// Firmware parameters by token key (added to the plan's own `[firmware]` table).
    #[serde(default)]
    pub firmware: toml::Table,
    /// The simulated robot.
    #[serde(default)]
    pub sim: SimArgs,
    /// The QEMU run.
    #[serde(default)]
    pub qemu: QemuSection,
}

/// The `[qemu]` table.
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QemuSection {
    /// Firmware ELF (relative to the working directory, as on the command line).
    pub elf: Option<PathBuf>,
    /// QEMU machine (a name of `scripts/qemu-machines.txt`).
    pub machine: Option<String>,
    /// Wall-clock limit, s.
    pub timeout_s: Option<f64>,
}

/// A checked run configuration.
#[derive(Debug)]
pub struct RunConfig {
    /// The walk, its `[firmware]` table holding the file's firmware parameters.
    pub spec: WalkSpec,
    /// The simulated robot's settings.
    pub sim: SimArgs,
    /// Firmware ELF.
    pub elf: Option<PathBuf>,
    /// QEMU machine.
    pub machine: Option<String>,
    /// Wall-clock limit.
    pub timeout: Option<Duration>,
}

/// A configuration error: the file, the field path and the reason.
fn error(file: &Path, field: &str, reason: impl std::fmt::Display) -> String {
    if field.is_empty() || field == "." {
        format!("{}: {reason}", file.display())
    } else {
        format!("{}: field `{field}`: {reason}", file.display())
    }
}

/// Reads and checks a run configuration file.
pub fn load(path: &Path) -> Result<RunConfig, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| error(path, "", format!("cannot read the configuration: {e}")))?;
    let base = path.parent().unwrap_or(Path::new(""));
    parse(&text, base).map_err(|(field, reason)| error(path, &field, reason))
}

/// Parses configuration text; plan files are looked up relative to `base`. Errors are
/// (field path, reason).
pub fn parse(text: &str, base: &Path) -> Result<RunConfig, (String, String)> {
    let de = toml::Deserializer::parse(text).map_err(|e| (String::new(), e.to_string()))?;
    let file: RunFile = serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        (path, inner.message().trim().to_string())
    })?;
    let mut spec = match (&file.plan_file, file.plan) {
        (Some(_), Some(_)) => {
            return Err((
                "plan_file".into(),
                "give either plan_file or a [plan] table, not both".into(),
            ))
        }
        (Some(p), None) => {
            planfile::load(&base.join(p)).map_err(|e| ("plan_file".into(), e.to_string()))?
        }
        (None, Some(spec)) => {
            spec.check(spec.robot())
                .map_err(|e| plan_field("plan.", e))?;
            spec
        }
        (None, None) => WalkSpec::default(),
    };
    for (k, v) in file.firmware {
        if spec.firmware.contains_key(&k) {
            return Err((
                format!("firmware.{k}"),
                "also set in the plan's own [firmware] table".into(),
            ));
        }
        spec.firmware.insert(k, v);
    }
    spec.firmware_config().map_err(|e| plan_field("", e))?;
    file.sim.check().map_err(|(f, e)| (format!("sim.{f}"), e))?;
    if let Some(m) = &file.qemu.machine {
        let names = crate::qemu::machine_names();
        if !names.contains(&m.as_str()) {
            return Err((
                "qemu.machine".into(),
                format!("{m:?}: expected one of {}", names.join(", ")),
            ));
        }
    }
    let timeout = file
        .qemu
        .timeout_s
        .map(|t| crate::cli::seconds(&t.to_string()))
        .transpose()
        .map_err(|e| ("qemu.timeout_s".to_string(), e))?;
    Ok(RunConfig {
        spec,
        sim: file.sim,
        elf: file.qemu.elf,
        machine: file.qemu.machine,
        timeout,
    })
}

/// A plan error as (field path, reason), the field under `prefix`.
fn plan_field(prefix: &str, e: PlanError) -> (String, String) {
    (format!("{prefix}{}", e.field), e.reason)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn workspace() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
    }

    /// The Cortex-M3 1 kHz run loads as its comment says: Table 2 at dt = 0.001 s, 4.5 Mbps, the
    /// fixed-point path at 72 MHz, the M3 ELF on `mps2-an385`.
    #[test]
    fn the_m3_1khz_run_loads() {
        let rc = load(&workspace().join("plans/run-m3-1khz.toml")).unwrap();
        assert_eq!(rc.spec.dt, 0.001);
        assert_eq!(rc.spec.steps, 14);
        let fw = rc.spec.firmware_config().unwrap();
        assert_eq!(fw.tick_period_us, 1000);
        assert_eq!(fw.bus_baud, 4_500_000);
        assert_eq!(fw.core_mhz, 72);
        assert_eq!(fw.arithmetic, walker_contract::config::Arithmetic::Fixed);
        assert_eq!(rc.machine.as_deref(), Some("mps2-an385"));
        assert_eq!(
            rc.elf.as_deref(),
            Some(Path::new("target/thumbv7m-none-eabi/release-m3/qemu"))
        );
    }

    /// The example loads, and every value reaches the walk, the firmware configuration and the
    /// simulator as written there.
    #[test]
    fn the_example_loads() {
        let rc = load(&workspace().join("plans/run-example.toml")).unwrap();
        assert_eq!(rc.spec.steps, 14);
        assert_eq!(rc.spec.compensation, planfile::CompensationName::Wholebody);
        let fw = rc.spec.firmware_config().unwrap();
        assert_eq!(fw.stabilizer.kp, 0.5);
        assert_eq!(fw.stabilizer.ki, 2.0);
        assert!(fw.stabilizer_on);
        let tokens = rc.spec.firmware_tokens().unwrap();
        assert!(
            tokens.contains(&"feasibility=stretch".to_string()),
            "{tokens:?}"
        );
        assert!(tokens.contains(&"gyro_hip=0.1".to_string()), "{tokens:?}");
        assert!(
            tokens.contains(&"compliance_roll=0.75".to_string()),
            "{tokens:?}"
        );
        assert!(tokens.contains(&"baud=1000000".to_string()), "{tokens:?}");
        let mut sim = crate::sim::SimConfig::default();
        rc.sim.apply("fil", &mut sim).unwrap();
        assert_eq!(sim.seed, 7);
        assert_eq!(sim.noise.latency_us, 1000);
        assert_eq!(sim.noise.force_std_n, 0.2);
        assert_eq!(sim.env.floor_friction, 0.9);
        assert!((sim.env.step_height_m - 0.002).abs() < 1e-12);
        assert_eq!(sim.pushes.len(), 1);
        assert_eq!((sim.pushes[0].at_s, sim.pushes[0].impulse_ns), (6.0, 1.0));
        assert_eq!(rc.machine.as_deref(), Some("mps2-an500"));
        assert_eq!(rc.timeout, Some(Duration::from_secs(1800)));
        // The command line wins over the file; lists add up.
        let cli = SimArgs {
            seed: Some(9),
            push: vec![crate::sim::Push::parse("7:1:90").unwrap()],
            ..SimArgs::default()
        };
        let merged = cli.over(rc.sim);
        assert_eq!(merged.seed, Some(9));
        assert_eq!(merged.floor_friction, Some(0.9));
        assert_eq!(merged.push.len(), 2);
    }

    fn err(text: &str) -> (String, String) {
        parse(text, &workspace().join("plans")).unwrap_err()
    }

    /// A typo anywhere is refused with the field's path and the valid keys.
    #[test]
    fn typos_name_the_field_and_list_the_valid_keys() {
        let (field, reason) = err("[sim]\nfloor_frction = 0.5\n");
        assert_eq!(field, "sim.floor_frction");
        assert!(reason.contains("unknown field `floor_frction`"), "{reason}");
        assert!(
            reason.contains("`floor_friction`") && reason.contains("`tau_random`"),
            "{reason}"
        );
        let (field, reason) = err("[plan]\nstep_lenght = 0.02\n");
        assert_eq!(field, "plan.step_lenght");
        assert!(reason.contains("`step_length`"), "{reason}");
        let (field, reason) = err("[qemu]\nmachne = \"x\"\n");
        assert_eq!(field, "qemu.machne");
        assert!(
            reason.contains("`machine`") && reason.contains("`timeout_s`"),
            "{reason}"
        );
        let (field, reason) = err("palns = 1\n");
        assert_eq!(field, "palns");
        assert!(
            reason.contains("`plan_file`") && reason.contains("`sim`"),
            "{reason}"
        );
        // [firmware]: the keys of the contract's table.
        let (field, reason) = err("[firmware]\nstab_kk = 1\n");
        assert_eq!(field, "firmware.stab_kk");
        for p in walker_contract::params::PARAMS
            .iter()
            .filter(|p| p.plan_key.is_none())
        {
            assert!(reason.contains(p.key), "{} not listed: {reason}", p.key);
        }
        // Values: wrong type, out of range (the firmware's parser, the CLI's checks).
        let (field, reason) = err("[sim]\np_drop = 1.5\n");
        assert_eq!(
            (field.as_str(), reason.as_str()),
            ("sim.p_drop", "must be within 0..=1 (got 1.5)")
        );
        let (field, _) = err("[sim]\nseed = \"x\"\n");
        assert_eq!(field, "sim.seed");
        let (field, reason) = err("[sim]\npush = [\"1:2\"]\n");
        assert_eq!(field, "sim.push");
        assert!(reason.contains("T:IMPULSE_NS:DIRECTION_DEG"), "{reason}");
        let (field, reason) = err("[firmware]\nstab_kp = 11\n");
        assert_eq!(field, "firmware.stab_kp");
        assert!(reason.contains("out of range"), "{reason}");
        let (field, _) = err("[plan]\nt2 = 0.1\n");
        assert_eq!(field, "plan.t2");
        let (field, _) = err("[plan]\n[[plan.footsteps]]\nside = \"left\"\nx = 0.02\n");
        assert!(field.starts_with("plan.footsteps[0]"), "{field}");
        let (field, _) = err("[qemu]\ntimeout_s = -1\n");
        assert_eq!(field, "qemu.timeout_s");
        let (field, _) = err("plan_file = \"table2.toml\"\n[plan]\nsteps = 3\n");
        assert_eq!(field, "plan_file");
        // A plan file relative to the configuration.
        let rc = parse("plan_file = \"turn.toml\"\n", &workspace().join("plans")).unwrap();
        assert!(rc.spec.footsteps.is_some());
    }
}
