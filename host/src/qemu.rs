//! The firmware's QEMU runs, as the host starts them. The QEMU command line has one definition,
//! `scripts/qemu-run.sh` (machine, `-nographic -monitor none`, the three UARTs, semihosting,
//! `-icount shift=0`, the semihosting command-line check); the host runs that script in its raw
//! mode (QEMU's stdout as it is, the script execs QEMU), a lock-step run without `-icount`
//! (the firmware's clock is its modelled one, docs/lockstep.md). The machines are the table
//! `scripts/qemu-machines.txt` (machine, core, the Rust target whose ELFs it runs by default),
//! read here and by the script.

use std::path::Path;
use std::process::Command;

/// The machine table (`scripts/qemu-machines.txt`).
const TABLE: &str = include_str!("../../scripts/qemu-machines.txt");

/// The script that starts QEMU.
pub const RUN_SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../scripts/qemu-run.sh");

/// One row of the machine table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Machine {
    /// QEMU machine name (`-M`).
    pub name: &'static str,
    /// The emulated core.
    pub core: &'static str,
    /// The Rust targets whose ELFs it runs.
    pub targets: Vec<&'static str>,
}

/// Every machine of the table, in its order.
pub fn machines() -> Vec<Machine> {
    TABLE
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| {
            let mut w = l.split_whitespace();
            let (name, core, targets) = (w.next()?, w.next()?, w.next()?);
            Some(Machine {
                name,
                core,
                targets: targets.split(',').collect(),
            })
        })
        .collect()
}

/// The machine names, in the table's order.
pub fn machine_names() -> Vec<&'static str> {
    machines().iter().map(|m| m.name).collect()
}

/// The table's target whose directory is in the ELF's path, if any.
fn elf_target(elf: &Path, all: &[Machine]) -> Option<&'static str> {
    all.iter()
        .flat_map(|m| m.targets.iter().copied())
        .find(|t| elf.components().any(|c| c.as_os_str() == *t))
}

/// The machine an ELF runs on when none is asked for: the first that runs the target whose
/// directory is in the ELF's path, else the table's first (the rule of `scripts/qemu-run.sh`).
pub fn default_machine(elf: &Path) -> &'static str {
    let all = machines();
    let target = elf_target(elf, &all);
    all.iter()
        .find(|m| target.is_some_and(|t| m.targets.contains(&t)))
        .or(all.first())
        .map_or("mps2-an500", |m| m.name)
}

/// Refuses a machine that cannot run the ELF's target (an ELF path under no target of the
/// table: any machine), as `scripts/qemu-run.sh` does.
pub fn check_machine(elf: &Path, machine: &str) -> Result<(), String> {
    let all = machines();
    let Some(m) = all.iter().find(|m| m.name == machine) else {
        return Err(format!(
            "unknown QEMU machine {machine} (expected one of {})",
            machine_names().join(", ")
        ));
    };
    match elf_target(elf, &all) {
        Some(t) if !m.targets.contains(&t) => Err(format!(
            "{machine} ({}) does not run {t} ELFs ({}); machines for it: {}",
            m.core,
            elf.display(),
            all.iter()
                .filter(|x| x.targets.contains(&t))
                .map(|x| x.name)
                .collect::<Vec<_>>()
                .join(", ")
        )),
        _ => Ok(()),
    }
}

/// The three UARTs of the board-qemu firmware as QEMU chardevs (`tcp:…`, `file:…`, `null`).
#[derive(Clone, Debug)]
pub struct Serials {
    /// UART0, the servo bus.
    pub bus: String,
    /// UART1, the ZMP log.
    pub log: String,
    /// UART2, the lock-step channel (turns lock-step on in the firmware), if any.
    pub lockstep: Option<String>,
    /// Lock-step over the host's pipes (the word `lockstep=PREFIX` in the command line).
    pub lockstep_pipes: bool,
    /// UART3, the command port (the firmware as a Dynamixel device), if any.
    pub command: Option<String>,
}

/// The command that runs `elf` on `machine` with `serials` and the semihosting command line
/// `append`, without a wall-clock limit (the caller keeps it); QEMU's stdout is the child's.
/// With lock-step (either transport) QEMU runs without `-icount`: nothing reads its clock.
pub fn command(elf: &Path, machine: &str, serials: &Serials, append: &str) -> Command {
    let mut c = Command::new("bash");
    c.arg(RUN_SCRIPT)
        .arg(elf)
        .args(["--raw", "--timeout", "0", "--machine", machine])
        .args(["--bus", &serials.bus, "--log", &serials.log]);
    if let Some(l) = &serials.lockstep {
        c.args(["--lockstep", l]);
    }
    if serials.lockstep.is_some() || serials.lockstep_pipes {
        c.arg("--no-icount");
    }
    if let Some(p) = &serials.command {
        c.args(["--command", p]);
    }
    c.args(["-append", append]);
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_machine_table_has_the_three_cores_and_picks_by_target() {
        let names = machine_names();
        assert_eq!(names, ["mps2-an500", "mps2-an386", "mps2-an385"]);
        let m3 = Path::new("target/thumbv7m-none-eabi/release/qemu");
        assert_eq!(default_machine(m3), "mps2-an385");
        let m7 = Path::new("target/thumbv7em-none-eabihf/release/qemu");
        assert_eq!(default_machine(m7), "mps2-an500");
        assert_eq!(default_machine(Path::new("fw.elf")), "mps2-an500");
        assert!(check_machine(m7, "mps2-an386").is_ok());
        let e = check_machine(m7, "mps2-an385").unwrap_err();
        assert!(e.contains("mps2-an500, mps2-an386"), "{e}");
        assert!(check_machine(m3, "mps2-an500").is_err());
        assert!(check_machine(Path::new("fw.elf"), "mps2-an385").is_ok());
        assert!(check_machine(m3, "mps2-an999").is_err());
        assert!(Path::new(RUN_SCRIPT).is_file());
    }
}
