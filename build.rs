//! Link setup of the firmware (only for the bare-metal ARM target; host builds get nothing).
//!
//! * `-Tlink.x` (cortex-m-rt) and `-Tdefmt.x` (defmt) go to the binaries and the on-target
//!   tests through `cargo:rustc-link-arg-bins` / `-tests`, never to host builds.
//! * Memory layout by board feature: the top-level `memory.x` is the real board's
//!   (STM32F746ZG, used by `board-opencr`). `board-qemu` needs the mps2-an500/an386 layout
//!   (FLASH 0x0000_0000 4 MiB, RAM 0x2000_0000 4 MiB). Writing that to OUT_DIR and putting
//!   OUT_DIR first on the search path does NOT work: rust-lld resolves cortex-m-rt's
//!   `INCLUDE memory.x` in its working directory (the workspace root, where the top-level
//!   `memory.x` is) before any `-L` path — tried: the QEMU ELF came out linked at
//!   0x0800_0000 and locked up. So the top-level `memory.x` selects the layout with
//!   `DEFINED(_walker_qemu_mps2)`, and this script passes `--defsym=_walker_qemu_mps2=1` for
//!   `board-qemu`; likewise `--defsym=_walker_opencm=1` selects the ROBOTIS OpenCM 9.04's
//!   layout for `board-opencm` (FLASH 0x0800_3000 114 KiB after ROBOTIS' bootloader, RAM
//!   20 KiB), and `--defsym=_walker_opencr_boot=1` the OpenCR's after ROBOTIS' USB bootloader
//!   for `opencr-bootloader` (FLASH 0x0804_0000, 256 KiB: sector 5). The chosen layout is still copied to OUT_DIR (`memory.x`, first on the
//!   search path) for builds whose linker runs elsewhere, and the mps2 one is written there
//!   as `memory-qemu-mps2.x` for reference.
use std::env;
use std::fs;
use std::path::PathBuf;

const QEMU_MEMORY_X: &str =
    "/* mps2-an500 (Cortex-M7) / mps2-an386 (Cortex-M4F) under qemu-system-arm:
 * 4 MiB of code memory at 0 (where -kernel loads the ELF) and 4 MiB of RAM. Written by build.rs
 * for reference only: the link uses the top-level memory.x with --defsym=_walker_qemu_mps2=1. */
MEMORY
{
  FLASH : ORIGIN = 0x00000000, LENGTH = 4M
  RAM   : ORIGIN = 0x20000000, LENGTH = 4M
}
";

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=memory.x");

    let qemu = env::var_os("CARGO_FEATURE_BOARD_QEMU").is_some();
    let opencr = env::var_os("CARGO_FEATURE_BOARD_OPENCR").is_some();
    let opencm = env::var_os("CARGO_FEATURE_BOARD_OPENCM").is_some();
    if usize::from(qemu) + usize::from(opencr) + usize::from(opencm) > 1 {
        eprintln!(
            "error: features `board-qemu`, `board-opencr` and `board-opencm` are exclusive \
             (use `--no-default-features --features board-qemu`)"
        );
        std::process::exit(1);
    }

    // Host builds (unit tests, host tools decoding the log): no link arguments at all.
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }

    let out = match env::var_os("OUT_DIR") {
        Some(o) => PathBuf::from(o),
        None => {
            eprintln!("error: OUT_DIR not set");
            std::process::exit(1);
        }
    };
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let layout = match fs::read_to_string(manifest.join("memory.x")) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: cannot read memory.x: {e}");
            std::process::exit(1);
        }
    };
    for (name, text) in [
        ("memory.x", layout.as_str()),
        ("memory-qemu-mps2.x", QEMU_MEMORY_X),
    ] {
        if let Err(e) = fs::write(out.join(name), text) {
            eprintln!("error: cannot write {}/{name}: {e}", out.display());
            std::process::exit(1);
        }
    }
    println!("cargo:rustc-link-search={}", out.display());
    if qemu {
        for kind in ["bins", "tests"] {
            println!("cargo:rustc-link-arg-{kind}=--defsym=_walker_qemu_mps2=1");
        }
    }
    if opencm {
        println!("cargo:rustc-link-arg-bins=--defsym=_walker_opencm=1");
    }
    if env::var_os("CARGO_FEATURE_OPENCR_BOOTLOADER").is_some() {
        println!("cargo:rustc-link-arg-bins=--defsym=_walker_opencr_boot=1");
    }

    if qemu || opencr || opencm {
        for kind in ["bins", "tests"] {
            println!("cargo:rustc-link-arg-{kind}=-Tlink.x");
            println!("cargo:rustc-link-arg-{kind}=-Tdefmt.x");
        }
    }
}
