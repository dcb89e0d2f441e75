#!/usr/bin/env bash
# Wall time of the simulated robot (MuJoCo), written into BENCHMARKS.md between
# <!-- sim:begin --> and <!-- sim:end -->:
#   1. the MuJoCo robot alone (host/examples/physics_rate.rs): 15 s of standing on a flat and on
#      a ±5 mm tiled floor, physics steps per second and real-time factor;
#   2. the firmware-in-the-loop walk of the Table 2 plan (14 steps, TLIPFM, the paper's timing):
#      wall time and real-time factor (simulated / wall), without and with its video.
# Wall-clock figures on a shared 2-core machine: they change from run to run.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh
host=$(rustc -vV | sed -n 's/^host: //p')
cargo build --release --no-default-features --features board-qemu --bin qemu
cargo build --release --target host-tuple -p walker-host --bin walker --example physics_rate
walker=target/$host/release/walker
out=target/bench
mkdir -p "$out"

"target/$host/release/examples/physics_rate" | tee "$out/physics-rate.txt"

fil() {
    local start end
    start=$(date +%s.%N)
    "$walker" fil --plan plans/table2.toml --model tlipfm --out "$out/fil-$1" \
        --firmware-args feasibility=off "${@:2}" > "$out/fil-$1.txt" 2>&1
    end=$(date +%s.%N)
    awk -v a="$start" -v b="$end" 'BEGIN { printf "%.1f", b - a }'
}
wall=$(fil plain)
sim_s=$(grep -o 'simulated [0-9.]* s' "$out/fil-plain.txt" | awk '{print $2}')
py=$(bash scripts/render-setup.sh | tail -n 1)
[ -x "$py" ] || { echo "bench-sim.sh: renderer missing" >&2; exit 1; }
wall_video=$(fil video --video "$out/fil-video/walk.mp4")

section=$(cat <<MD
<!-- sim:begin -->
## The simulated robot: MuJoCo wall time (\`bash scripts/bench-sim.sh\`)

Host wall clock on the shared 2-core machine (quiet when run: other jobs slow it down up to ≈ 4×).

| what | figure |
| --- | --- |
$(sed -E 's/^([^:]+): (.*)$/| MuJoCo robot alone, \1 | \2 |/' "$out/physics-rate.txt")
| firmware-in-the-loop Table 2 walk (14 steps, TLIPFM, QEMU lock-step) | ${sim_s} s simulated in ${wall} s wall: real-time factor $(awk -v s="$sim_s" -v w="$wall" 'BEGIN { printf "%.2f", s / w }') |
| the same walk with its video (\`--video\`, 640×480, 30 fps, EGL software rendering) | ${wall_video} s wall |
<!-- sim:end -->
MD
)
python3 - "$section" <<'PY'
import sys
sec = sys.argv[1]
p = "BENCHMARKS.md"
s = open(p).read()
b, e = "<!-- sim:begin -->", "<!-- sim:end -->"
if b in s:
    s = s[: s.index(b)] + sec + s[s.index(e) + len(e):]
else:
    s = s.rstrip("\n") + "\n\n" + sec + "\n"
open(p, "w").write(s)
PY
echo "bench-sim.sh: BENCHMARKS.md updated"
