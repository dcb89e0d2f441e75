//! Link setup of the host tools: MuJoCo's shared library.
//!
//! `mujoco-rs` links `libmujoco.so` from `MUJOCO_DYNAMIC_LINK_DIR`, which `.cargo/config.toml`
//! points at the project-local `.mujoco/lib/` that `scripts/setup.sh` fills from PyPI's
//! `mujoco==3.17.0` wheel. This script adds that directory as an rpath to every binary and test
//! of the host crate, so `walker` runs with no environment variables, and stops the build with
//! one line naming the fixing command when the library is missing.
use std::env;
use std::path::PathBuf;

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    let Some(dir) = env::var_os("MUJOCO_DYNAMIC_LINK_DIR").map(PathBuf::from) else {
        println!(
            "cargo::error=MUJOCO_DYNAMIC_LINK_DIR is not set: build from the repository \
             (its .cargo/config.toml sets it) after `bash scripts/setup.sh`"
        );
        return;
    };
    if !dir.join("libmujoco.so").is_file() {
        println!(
            "cargo::error=MuJoCo 3.17.0 is missing from {}: run `bash scripts/setup.sh` once",
            dir.display()
        );
        return;
    }
    println!(
        "cargo::rerun-if-changed={}",
        dir.join("libmujoco.so").display()
    );
    println!("cargo::rustc-link-arg=-Wl,-rpath,{}", dir.display());
}
