#!/usr/bin/env bash
# Runs every check of the project: format, clippy (host and target), host tests, firmware builds
# for both boards, on-target tests in QEMU and a short firmware-in-the-loop walk.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh

step() { printf '\n== %s\n' "$*"; }

step "cargo fmt --check"
cargo fmt --all --check

step "clippy (host)"
cargo clippy --target host-tuple --workspace --all-targets -- -D warnings

step "clippy (thumbv7em-none-eabihf, no_std crates)"
cargo clippy -p gait-core -p dxl -- -D warnings

step "gait-core builds for the target"
cargo build -p gait-core --target thumbv7em-none-eabihf

step "host tests"
cargo test --target host-tuple --workspace
