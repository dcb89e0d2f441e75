#!/usr/bin/env bash
# Main job: the firmware, built for the emulated board (QEMU mps2-an500, Cortex-M7), walks the
# seed's Table 2 plan (14 steps) against the simulated robot in lock-step, once per model (LIPM,
# DLIPM, TLIPFM); each run writes its captured log, the simulator's ground truth and the
# ZMP-response report (CSV, SVG/PNG plots like seed 000 Figs. 14-16, Table 3 statistics) to
# out/fil-MODEL/, and the three models are compared side by side in out/compare.md.
# Options: PLAN=plans/other.toml bash scripts/walk.sh; MODELS="tlipfm" for one model only.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh
plan=${PLAN:-plans/table2.toml}
models=${MODELS:-"lipm dlipm tlipfm"}

echo "== building the firmware (board-qemu) and the host tools"
cargo build --release --no-default-features --features board-qemu --bin qemu
cargo build --release --target host-tuple -p walker-host --bin walker
walker=target/$(rustc -vV | sed -n 's/^host: //p')/release/walker

runs=()
for model in $models; do
    echo
    echo "== $plan with $model: firmware in QEMU against the simulated robot"
    "$walker" fil --plan "$plan" --model "$model" --out "out/fil-$model"
    runs+=("$model=out/fil-$model/walk.log")
done

echo
echo "== side by side"
"$walker" compare --runs "$(IFS=,; echo "${runs[*]}")" --out out/compare.md
