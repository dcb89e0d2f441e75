#!/usr/bin/env bash
# Installs what the project's commands need on a fresh Debian/Ubuntu machine with rustup:
# the Rust targets (from rust-toolchain.toml) and QEMU (Debian's qemu-system-arm).
# Sourced by scripts/walk.sh and scripts/test.sh.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# rustup reads rust-toolchain.toml and installs the toolchain, components and targets.
rustup show active-toolchain >/dev/null
rustup target list --installed | grep -q thumbv7em-none-eabihf || rustup target add thumbv7em-none-eabihf thumbv7m-none-eabi
# llvm-objdump for scripts/stack-depth.py (listed in rust-toolchain.toml; added here too for a
# toolchain that was installed before the list had it).
rustup component list --installed | grep -q '^llvm-tools' || rustup component add llvm-tools

if ! command -v qemu-system-arm >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ]; then
        echo "setup: installing qemu-system-arm (Debian package)" >&2
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq qemu-system-arm >/dev/null
    else
        echo "setup: QEMU is missing. Run this once, then try again:" >&2
        echo "    sudo apt-get install -y qemu-system-arm" >&2
        exit 1
    fi
fi

# MuJoCo 3.17.0 (the physics of the simulated robot, linked by the `mujoco-rs` crate): the C
# library comes from PyPI's `mujoco==3.17.0` wheel, which ships a self-contained
# `libmujoco.so.3.17.0` (libc, libm, libdl, libpthread, librt only). It is unpacked into
# `.mujoco/lib/` (ignored by git); `.cargo/config.toml` points `MUJOCO_DYNAMIC_LINK_DIR` there
# and `host/build.rs` adds an rpath, so `walker` runs without environment variables.
mujoco_lib=.mujoco/lib
if [ ! -f "$mujoco_lib/libmujoco.so.3.17.0" ]; then
    echo "setup: fetching MuJoCo 3.17.0 (PyPI wheel mujoco==3.17.0) into $mujoco_lib" >&2
    wheel_dir=$(mktemp -d)
    python3 -m pip download --quiet --no-deps --only-binary=:all: --platform manylinux_2_28_x86_64 \
        --python-version 3.11 mujoco==3.17.0 -d "$wheel_dir" >&2
    mkdir -p "$mujoco_lib"
    python3 - "$wheel_dir" "$mujoco_lib" <<'PY'
import glob, os, shutil, sys, zipfile
wheel = glob.glob(os.path.join(sys.argv[1], "mujoco-3.17.0-*.whl"))[0]
with zipfile.ZipFile(wheel) as z, z.open("mujoco/libmujoco.so.3.17.0") as src, \
        open(os.path.join(sys.argv[2], "libmujoco.so.3.17.0.part"), "wb") as dst:
    shutil.copyfileobj(src, dst)
PY
    mv "$mujoco_lib/libmujoco.so.3.17.0.part" "$mujoco_lib/libmujoco.so.3.17.0"
    rm -rf "$wheel_dir"
fi
ln -sf libmujoco.so.3.17.0 "$mujoco_lib/libmujoco.so"
