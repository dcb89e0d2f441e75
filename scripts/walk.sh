#!/usr/bin/env bash
# Main job: the firmware, built for the emulated board (QEMU mps2-an500, Cortex-M7), walks the
# seed's Table 2 plan (14 steps) against the simulated robot in lock-step, once per model (LIPM,
# DLIPM, TLIPFM) open loop as the paper (feedback and feed-forward off, factory servo gains), then TLIPFM
# with the firmware's default closed loop (gyro balance feedback, compliance handling, catching step); each run writes its captured log, the simulator's ground truth and the
# ZMP-response report (CSV, SVG/PNG plots like seed 000 Figs. 14-16, Table 3 statistics) to
# out/fil-MODEL/ (out/fil-tlipfm-closed/), and the four runs are compared in out/compare.md.
# The paper's timing is walked as published (feasibility=off): Table 2's swing asks the swing
# knee for ≈ 5.8 rad/s, above the simulated XM430-class servos' 4.8 rad/s; the firmware logs that
# warning and the servos saturate, as on the real robot. FEASIBILITY=stretch lets the firmware
# stretch the timing instead (its default on the robot). The simulated robot is MuJoCo 3.17 in
# full dynamics (host/src/sim/mujoco.rs) with XM430-W350 servo models (host/src/sim/dynamixel.rs):
# it can tip, slip and fall by itself; each run also renders a video (out/fil-MODEL/walk.mp4).
# Options: PLAN=plans/other.toml bash scripts/walk.sh; MODELS="tlipfm" for one model only;
# VIDEO=0 skips the videos; JOBS=1 walks one at a time (default: as many as the cores).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh
plan=${PLAN:-plans/table2.toml}
models=${MODELS:-"lipm dlipm tlipfm"}
feasibility=${FEASIBILITY:-off}

video=${VIDEO:-1}
if [ "$video" = 1 ]; then
    echo "== the renderer (ffmpeg, EGL, PyPI mujoco==3.17.0 in .venv-render/)"
    bash scripts/render-setup.sh >/dev/null
fi

echo "== building the firmware (board-qemu) and the host tools"
cargo build --release --no-default-features --features board-qemu --bin qemu
cargo build --release --target host-tuple -p walker-host --bin walker
walker=target/$(rustc -vV | sed -n 's/^host: //p')/release/walker

# The walks run side by side, JOBS at a time (default: the cores; each is a QEMU process and a
# simulator in lock-step on virtual time, so that running them together changes no figure);
# each one's output goes to out/fil-NAME.txt and is printed when the walks have ended.
jobs_max=${JOBS:-$(nproc)}
names=()
# walk NAME TITLE ARGS...: starts `walker fil ARGS... --out out/fil-NAME` in the background.
walk() {
    local name=$1 title=$2
    shift 2
    while [ "$(jobs -rp | wc -l)" -ge "$jobs_max" ]; do
        wait -n || true
    done
    echo "== started: $title (out/fil-$name.txt)"
    local video_args=()
    [ "$video" = 1 ] && video_args=(--video "out/fil-$name/walk.mp4")
    mkdir -p out
    rm -f "out/fil-$name.status"
    (
        code=0
        "$walker" fil "$@" --out "out/fil-$name" "${video_args[@]}" >"out/fil-$name.txt" 2>&1 || code=$?
        echo "$code" >"out/fil-$name.status"
    ) &
    names+=("$name")
}

for model in $models; do
    # `--open-loop`: the firmware's feedback off, as plans/table2-paper.toml and the ablation's
    # open loop (host/src/beyond.rs OPEN_LOOP): no gyro damping, no compliance feed-forward,
    # the servos' factory Position I Gain, no catching step, no swing sole levelling.
    walk "$model" "$plan with $model, open loop as the paper: firmware in QEMU against the simulated robot" \
        --plan "$plan" --model "$model" --open-loop --firmware-args "feasibility=$feasibility"
done
walk tlipfm-closed "$plan with tlipfm and the firmware's closed loop (gyro balance feedback, its default)" \
    --plan "$plan" --model tlipfm --firmware-args "feasibility=$feasibility"
wait

runs=()
failed=()
for name in "${names[@]}"; do
    echo
    echo "== out/fil-$name.txt"
    cat "out/fil-$name.txt"
    code=$(cat "out/fil-$name.status" 2>/dev/null || echo "none")
    [ "$code" = 0 ] || failed+=("$name (exit $code)")
    runs+=("$name=out/fil-$name/walk.log")
done
if [ "${#failed[@]}" -gt 0 ]; then
    echo "walk.sh: walks failed: ${failed[*]}" >&2
    exit 1
fi

echo
echo "== side by side"
"$walker" compare --runs "$(IFS=,; echo "${runs[*]}")" --out out/compare.md
