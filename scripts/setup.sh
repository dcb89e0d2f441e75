#!/usr/bin/env bash
# Installs what the project's commands need on a fresh Debian/Ubuntu machine with rustup:
# the Rust targets (from rust-toolchain.toml) and QEMU (Debian's qemu-system-arm).
# Sourced by scripts/walk.sh and scripts/test.sh.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# rustup reads rust-toolchain.toml and installs the toolchain, components and targets.
rustup show active-toolchain >/dev/null
rustup target list --installed | grep -q thumbv7em-none-eabihf || rustup target add thumbv7em-none-eabihf thumbv7m-none-eabi

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
