#!/usr/bin/env bash
# Robustness sweep of the closed-loop issue (item 5): the firmware (its defaults: the closed
# loop) walks the Table 2 plan in QEMU against the MuJoCo robot, nominal and with servo torque
# and gains ±20 %, link masses ±10 %, floor friction 0.5 / 0.75, +5 ms sensor latency and 5 %
# dropped status packets (`walker sweep`, host/src/sweep.rs). Writes out/sweep/sweep.md (the
# robustness sweep of docs/results.md; `bash scripts/results.sh` regenerates it) and one folder per case. ≈ 11 walks, 5-10 min on 2 cores.
# Options: PLAN=plans/other.toml, SEED=N, and any `walker sweep` options after the script name.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh
host=$(rustc -vV | sed -n 's/^host: //p')
cargo build --release --no-default-features --features board-qemu --bin qemu
cargo build --release --target host-tuple -p walker-host --bin walker
"target/$host/release/walker" sweep --plan "${PLAN:-plans/table2.toml}" --seed "${SEED:-0}" \
    --out out/sweep "$@"
