#!/usr/bin/env bash
# Main job. Target: the firmware walks the Table 2 plan (14 steps) in QEMU against the simulated
# robot and writes the ZMP-response report. Today (see README "Main job") it builds and boots the
# QEMU firmware, then walks the Table 2 plan through gait-core on the host for all three models
# and writes the planned trajectories (ZMP, CoM, feet, 12 joint angles) to out/.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh
mkdir -p out

echo "== firmware for the emulated board (mps2-an500, Cortex-M7)"
cargo build --release --no-default-features --features board-qemu --bin qemu
scripts/qemu-run.sh target/thumbv7em-none-eabihf/release/qemu --timeout 120

echo "== Table 2 walk (14 steps) planned by gait-core: LIPM, DLIPM, TLIPFM"
cargo build --release --target host-tuple -p walker-host --bin walker
walker=target/x86_64-unknown-linux-gnu/release/walker
[ -x "$walker" ] || walker=$(find target -path '*release/walker' -type f | head -n 1)
for model in lipm dlipm tlipfm; do
    sed "s/^model *=.*/model = \"$model\"/" plans/table2.toml > "out/table2-$model.toml"
    "$walker" export --plan "out/table2-$model.toml" --out "out/plan-$model.csv"
    echo "   out/plan-$model.csv: $(($(wc -l < "out/plan-$model.csv") - 1)) samples"
done
echo "done: see out/"
