#!/usr/bin/env bash
# The on-target and host benchmarks, written into BENCHMARKS.md between <!-- bench:begin --> and
# <!-- bench:end --> (the rest of the file is hand-written and left alone).
#
# Usage: bash scripts/bench.sh [--no-host]
#   --no-host   skip the host criterion benches (their table keeps the previous figures out:
#               it says "not run")
#
# What it does:
#   1. builds the on-target bench (src/bin/bench.rs) for thumbv7em-none-eabihf (Cortex-M7/M4F,
#      FPU) and thumbv7m-none-eabi (Cortex-M3, soft float), and the release firmware ELFs
#      `qemu` and `opencr`;
#   2. runs the bench in qemu-system-arm with -icount shift=0 (1 instruction = 1 virtual ns;
#      SysTick counts one per 40 instructions) on mps2-an500 (M7) and mps2-an386 (M4F) with the
#      eabihf ELF and on mps2-an385 (M3) with the thumbv7m ELF — each twice, side by side, and
#      checks that both runs print identical lines (they must: the counts depend only on the
#      instruction stream);
#   3. reads flash/RAM of the firmware ELFs with binutils `readelf -S`;
#   4. computes the bus time of one control tick from the packet sizes the bench printed
#      (dxl's own encoders);
#   5. runs the host criterion benches of gait-core briefly (host figures vary run to run);
#   6. rewrites the marked section of BENCHMARKS.md.
# Raw outputs: target/bench/{an500,an386,an385}.txt, host logs target/bench/host-*.txt.
# Environment: BENCH_TURNAROUND_US (per-packet bus allowance, default 25),
#              BENCH_CPU_MHZ (OpenCR clock for the compute-time estimate, default 216),
#              BENCH_QEMU_TIMEOUT (s per QEMU run, default 900).
set -euo pipefail
cd "$(dirname "$0")/.."

host=1
for a in "$@"; do
    case "$a" in
        --no-host) host=0 ;;
        *) echo "usage: $0 [--no-host]" >&2; exit 2 ;;
    esac
done

turnaround_us=${BENCH_TURNAROUND_US:-25}
cpu_mhz=${BENCH_CPU_MHZ:-216}
qemu_timeout=${BENCH_QEMU_TIMEOUT:-900}
out=target/bench
mkdir -p "$out"

for tool in qemu-system-arm readelf awk; do
    if ! command -v "$tool" >/dev/null 2>&1; then
        echo "bench.sh: $tool not found (qemu-system-arm: bash scripts/setup.sh; readelf: binutils)" >&2
        exit 127
    fi
done

# ---- 1. builds ----
# The bench is built with defmt compiled out (DEFMT_LOG=off: the control loop's defmt logs
# would interleave with the bench's text on semihosting stdout) in its own target directory,
# so that switching DEFMT_LOG never rebuilds the firmware ELFs in target/.
qemu_feat=(--release --no-default-features --features board-qemu)
# The bench runs the control loop on the fake robot (src/fake_robot.rs, feature fake-robot).
bench_feat=(--release --no-default-features --features board-qemu,fake-robot)
bench_dir=target/bench-build
echo "bench.sh: building" >&2
DEFMT_LOG=off cargo build "${bench_feat[@]}" --bin bench --target-dir "$bench_dir"
# The Cortex-M3 bench as the M3 firmware is built: profile release-m3, the fixed-point path
# compiled in (its control loop is measured with math=f32 and math=fixed).
m3_feat=(--profile release-m3 --no-default-features --features board-qemu,fixed-gait,fake-robot)
DEFMT_LOG=off cargo build "${m3_feat[@]}" --bin bench --target-dir "$bench_dir" \
    --target thumbv7m-none-eabi
cargo build "${qemu_feat[@]}" --bin qemu
cargo build --release --no-default-features --features board-opencr --bin opencr
m3_fw=(--profile release-m3 --target thumbv7m-none-eabi --no-default-features)
cargo build "${m3_fw[@]}" --features board-qemu,fixed-gait --bin qemu
cargo build "${m3_fw[@]}" --features board-opencm --bin opencm
elf_hf=$bench_dir/thumbv7em-none-eabihf/release/bench
elf_m3=$bench_dir/thumbv7m-none-eabi/release-m3/bench

# ---- 2. QEMU runs ----
run_once() { # machine elf outfile (QEMU's command line: scripts/qemu-run.sh)
    scripts/qemu-run.sh "$2" --raw --machine "$1" --timeout "$qemu_timeout" --bus null \
        --log null >"$3" 2>"$3.err"
}
run_machine() { # machine elf name
    local m=$1 elf=$2 name=$3 rc1=0 rc2=0
    echo "bench.sh: running $elf on $m (twice, in parallel)" >&2
    run_once "$m" "$elf" "$out/$name.run1" & local p1=$!
    run_once "$m" "$elf" "$out/$name.run2" & local p2=$!
    wait "$p1" || rc1=$?
    wait "$p2" || rc2=$?
    if [ "$rc1" -ne 0 ] || [ "$rc2" -ne 0 ] || ! grep -q '^done 1$' "$out/$name.run1"; then
        echo "bench.sh: $m run failed (exit $rc1/$rc2); output in $out/$name.run1{,.err}" >&2
        cat "$out/$name.run1" "$out/$name.run1.err" >&2 || true
        exit 1
    fi
    if ! cmp -s "$out/$name.run1" "$out/$name.run2"; then
        echo "bench.sh: $m: the two runs differ — instruction counts are not deterministic:" >&2
        diff "$out/$name.run1" "$out/$name.run2" >&2 || true
        exit 1
    fi
    if [ -f "$out/$name.txt" ]; then
        if cmp -s "$out/$name.run1" "$out/$name.txt"; then
            echo "bench.sh: $m: identical to the previous bench.sh run" >&2
        else
            echo "bench.sh: $m: differs from the previous bench.sh run (code changed?):" >&2
            diff "$out/$name.txt" "$out/$name.run1" >&2 || true
        fi
    fi
    mv "$out/$name.run1" "$out/$name.txt"
    rm -f "$out/$name.run2" "$out/$name.run1.err" "$out/$name.run2.err"
}
run_machine mps2-an500 "$elf_hf" an500
run_machine mps2-an386 "$elf_hf" an386
run_machine mps2-an385 "$elf_m3" an385

declare -A M7 M4 M3
load() { # file assoc-array-name
    local -n arr=$2
    local k v
    while read -r k v; do
        [ -n "$k" ] && arr[$k]=$v
    done <"$1"
}
load "$out/an500.txt" M7
load "$out/an386.txt" M4
load "$out/an385.txt" M3

# ---- the control tick by crate ("the loop, not the library calls") ----
# scripts/tick-profile.sh counts every instruction of the M7 control tick in QEMU (a TCG
# plugin) and attributes it to the crate whose code runs (the runtime helpers, memcpy and
# the like, to their caller's crate). Needs llvm-nm / llvm-symbolizer (Debian: llvm) and a C
# compiler; without them the figures say "not measured".
prof_lib=; prof_loop=; prof_loop_master=; prof_tick=
if bash scripts/tick-profile.sh m7 crates 12 >"$out/tick-crates.txt" 2>"$out/tick-crates.err"; then
    prof_lib=$(awk '/^library calls/{print $(NF-2)}' "$out/tick-crates.txt")
    prof_loop=$(awk '/^the loop \(firmware/{print $(NF-2)}' "$out/tick-crates.txt")
    prof_loop_master=$(awk '/^the loop with the dxl master/{print $(NF-2)}' "$out/tick-crates.txt")
    prof_tick=$(awk '/^counted/{print $(NF-2)}' "$out/tick-crates.txt")
    # "gait-core 7,139; dxl codec 4,182; …" (the rows: count, share, crate).
    prof_crates=$(awk '/^ *[0-9.]+ +[0-9.]+% /{name = $0; sub(/^ *[0-9.]+ +[0-9.]+% +/, "", name);
        printf "%s\t%.0f\n", name, $1}' "$out/tick-crates.txt")
else
    echo "bench.sh: the tick profile did not run (see $out/tick-crates.err); its figures say not measured" >&2
fi

# ---- the QEMU board's compute time per tick (src/boards/tick_cost.rs, generated) ----
# The firmware's QEMU board charges the measured worst-case instructions per control tick at
# its modelled core clock (`core_mhz`) as the compute time of each tick; the constants come
# from this run. When they change, the firmware ELFs are rebuilt before their sizes are read.
tick_cost=src/boards/tick_cost.rs
tick_cost_new=$(mktemp)
cat >"$tick_cost_new" <<TICKCOST
//! Instructions per control tick measured by \`scripts/bench.sh\` (generated: the script
//! rewrites this file after each run; do not edit by hand).
//!
//! The firmware's control loop (\`control::run\`, default configuration: TLIPFM, f32 — or the
//! fixed-point path where named —, paper pipeline, stabilizer off) on the bench's emulated
//! bus, QEMU \`-icount shift=0\`, per walking tick: worst case and average over the Table 2
//! walk. The QEMU board charges the worst case
//! as its compute time per tick (see [\`super::qemu_mps2::compute_ns\`]).

/// Worst-case instructions per control tick, hard-float build (Cortex-M7/M4F, mps2-an500).
pub const TICK_INSTRUCTIONS_MAX_FPU: u32 = ${M7[control.tick.max]};
/// Average instructions per control tick, hard-float build (for reference).
pub const TICK_INSTRUCTIONS_AVG_FPU: u32 = ${M7[control.tick.avg]%.*};
/// Worst-case instructions per control tick, soft-float build (Cortex-M3, mps2-an385).
pub const TICK_INSTRUCTIONS_MAX_SOFT: u32 = ${M3[control.tick.max]};
/// Average instructions per control tick, soft-float build (for reference).
pub const TICK_INSTRUCTIONS_AVG_SOFT: u32 = ${M3[control.tick.avg]%.*};
/// Worst-case instructions per control tick, Cortex-M3 build with the fixed-point path
/// (\`fixed-gait\`, \`math=fixed\`; mps2-an385).
pub const TICK_INSTRUCTIONS_MAX_FIXED_SOFT: u32 = ${M3[control.tick_fixed.max]};
/// Average instructions per control tick, Cortex-M3 fixed-point path (for reference).
pub const TICK_INSTRUCTIONS_AVG_FIXED_SOFT: u32 = ${M3[control.tick_fixed.avg]%.*};
TICKCOST
if cmp -s "$tick_cost_new" "$tick_cost"; then
    rm -f "$tick_cost_new"
else
    mv "$tick_cost_new" "$tick_cost"
    echo "bench.sh: $tick_cost updated (the QEMU board's compute time per tick); rebuilding the ELFs" >&2
    cargo build "${qemu_feat[@]}" --bin qemu
    cargo build --release --no-default-features --features board-opencr --bin opencr
    cargo build "${m3_fw[@]}" --features board-qemu,fixed-gait --bin qemu
fi

# ---- helpers ----
calc() { awk "BEGIN { printf \"%.${2:-0}f\", $1 }"; }
commas() { # integer or decimal → thousands separators
    local s=$1 int frac=""
    int=${s%%.*}
    [ "$int" != "$s" ] && frac=".${s#*.}"
    int=$(echo "$int" | sed -E ':a;s/^(-?[0-9]+)([0-9]{3})/\1,\2/;ta')
    printf '%s%s' "$int" "$frac"
}
n() { commas "$(calc "$1")"; }              # rounded integer with separators
cell() { # array key → "avg (max)"
    local -n a=$1
    local avg=${a[$2.avg]:-} max=${a[$2.max]:-}
    if [ -z "$avg" ]; then printf 'n/a'; return; fi
    printf '%s (%s)' "$(n "$avg")" "$(n "$max")"
}
core_row() { # key column... → "| column | … | key's cell on the M7 | on the M4 | on the M3 |"
    local key=$1
    shift
    printf '| %s ' "$@"
    echo "| $(cell M7 "$key") | $(cell M4 "$key") | $(cell M3 "$key") |"
}

# ---- 3. sizes ----
elf_sizes() { # elf → "flash ram text rodata data bss" (bytes)
    local flash=0 ram=0 text=0 ro=0 data=0 bss=0 name type addr off size es flg rest sz
    while read -r name type addr off size es flg rest; do
        if [[ $flg != *A* ]]; then continue; fi
        sz=$((16#$size))
        if [ "$type" != NOBITS ]; then flash=$((flash + sz)); fi
        if [ $((16#$addr)) -ge $((0x20000000)) ]; then ram=$((ram + sz)); fi
        case $name in
            .text) text=$sz ;;
            .rodata) ro=$sz ;;
            .data) data=$sz ;;
            .bss) bss=$sz ;;
        esac
    done < <(readelf -S -W "$1" | sed -nE 's/^ *\[ *[0-9]+\] +//p')
    echo "$flash $ram $text $ro $data $bss"
}
read -r q_flash q_ram q_text q_ro q_data q_bss < <(elf_sizes target/thumbv7em-none-eabihf/release/qemu)
read -r o_flash o_ram o_text o_ro o_data o_bss < <(elf_sizes target/thumbv7em-none-eabihf/release/opencr)
read -r m_flash m_ram m_text m_ro m_data m_bss < <(elf_sizes target/thumbv7m-none-eabi/release-m3/opencm)
read -r q3_flash q3_ram q3_text q3_ro q3_data q3_bss < <(elf_sizes target/thumbv7m-none-eabi/release-m3/qemu)
kib() { calc "$1 / 1024" 2; }
verdict() { # value limit
    if awk "BEGIN { exit !(($1) <= ($2)) }"; then printf 'within'; else printf '**over**'; fi
}
profiled() { # how the loop's figure was measured
    if [ -n "$prof_loop" ]; then
        echo "\`bash scripts/tick-profile.sh m7 crates\`: each instruction of the control-only bench's tick, $(n "$prof_tick") a tick, counted for the crate whose code runs, the runtime helpers (\`memcpy\`, soft-float) for their caller's"
    else
        echo "\`scripts/tick-profile.sh m7 crates\` did not run: no llvm tools or C compiler"
    fi
}
profiled_loop() {
    if [ -n "$prof_loop" ]; then
        local crates="" name count
        while IFS=$'\t' read -r name count; do
            crates="${crates:+$crates; }$name $(n "$count")"
        done <<<"$prof_crates"
        echo "**$(n "$prof_loop")** in the firmware, the contract crate (the log writer, the bus map) and the bench's tick meter, $(n "$prof_lib") in the library calls (the tick by crate: $crates); with the dxl master's own code (\`dxl/src/master.rs\`: the transactions around the codec) counted as the loop, **$(n "$prof_loop_master")**"
    else
        echo "not measured"
    fi
}
profiled_target() {
    if [ -n "$prof_loop" ]; then
        echo "the loop $(n "$prof_loop") ($(n "$prof_loop_master") with the dxl master's transactions) of the profiled tick's $(n "$prof_tick") (\`tick-profile.sh m7 crates\`; counted instruction by instruction)"
    else
        echo "not measured (no llvm tools)"
    fi
}
profiled_verdict() {
    if [ -n "$prof_loop" ]; then
        echo "$(verdict "$prof_loop" 8000) ($(verdict "$prof_loop_master" 8000) with the master)"
    else
        echo "not measured"
    fi
}

# ---- 4. bus budget ----
br=${M7[bytes.bulk_read]}
sfl=${M7[bytes.status_foot_left]}
sfr=${M7[bytes.status_foot_right]}
simu=${M7[bytes.status_imu]}
sw=${M7[bytes.sync_write]}
bus_bytes=$((br + sfl + sfr + simu + sw))
packets=5
tick_m7_max=${M7[control.tick.max]}
bus_default_us=$(calc "$bus_bytes * 10000000 / ${M7[bus_baud]} + $packets * $turnaround_us")
if [ "$bus_default_us" -le "${M7[tick_us]}" ]; then fits="fits"; else fits="does **not** fit"; fi
compute_us=$(calc "$tick_m7_max / $cpu_mhz" 1)

# ---- 5. host criterion ----
crit() { # bench-name → "name value unit" lines
    cargo bench --target host-tuple -p gait-core --bench "$1" -- \
        --warm-up-time 0.3 --measurement-time 1 2>&1 | tee "$out/host-$1.txt" >&2
    awk '
        /time:/ {
            name = ($1 == "time:") ? prev : $1
            for (i = 1; i <= NF; i++) if ($i ~ /^\[/) { print name, $(i + 2), $(i + 3); break }
            next
        }
        NF > 0 && $1 !~ /^(Benchmarking|Found|change:|Performance|No|Change|[0-9]+)/ { prev = $1 }
    ' "$out/host-$1.txt"
}
declare -A H
if [ "$host" -eq 1 ]; then
    echo "bench.sh: host criterion benches (gait-core sampler, ik)" >&2
    while read -r k v u; do H[$k]="$v $u"; done < <(crit sampler; crit ik)
fi
h() { printf '%s' "${H[$1]:-not run}"; }

# ---- 6. the section ----
rustc_v=$(rustc --version | awk '{ print $2 }')
qemu_v=$(qemu-system-arm --version | head -1 | sed -E 's/.*version ([^ ]+).*/\1/')
t7=${M7[tick.f32.tlipfm.avg]}
t4=${M4[tick.f32.tlipfm.avg]}
t3=${M3[tick.fixed.tlipfm.avg]}
t3f=${M3[tick.f32.tlipfm.avg]}
t7cs=${M7[tick.comp_stab.tlipfm.avg]}
t3cs=${M3[tick.comp_stab.tlipfm.avg]}
codec() { # array → Dynamixel codec instructions per tick (decode + parse 3 replies + 2 encodes)
    local -n a=$1
    calc "${a[dxl.decode3_block.avg]} + ${a[dxl.sync_write12.avg]} + ${a[dxl.bulk_read3.avg]}"
}
# Per-byte codec figures (targets: decoder ≤ 20 per received byte, encoder ≤ 12 per sent byte).
rx_bytes=$((${M7[bytes.status_foot_left]} + ${M7[bytes.status_foot_right]} + ${M7[bytes.status_imu]}))
per_rx() { local -n a=$1; calc "${a[$2.avg]} / $rx_bytes" 1; }
per_sw() { local -n a=$1; calc "${a[dxl.sync_write12.avg]} / ${M7[bytes.sync_write]}" 1; }
per_br() { local -n a=$1; calc "${a[dxl.bulk_read3.avg]} / ${M7[bytes.bulk_read]}" 1; }
codec7=$(codec M7)
codec3=$(codec M3)
pct() { calc "100 * ($1) / ($2)"; }
ratio() { calc "($1) / ($2)" "${3:-1}"; }
# more/less: how a compares with b, in words.
than() { if awk "BEGIN { exit !(($1) < ($2)) }"; then printf 'less'; else printf 'more'; fi; }
# breakdown total "label|value" ... → "label value (p %), …" sorted by value, then the rest.
breakdown() {
    local total=$1 rest parts=() sum=0 l v
    shift
    for p in "$@"; do
        l=${p%%|*}
        v=${p#*|}
        sum=$(calc "$sum + $v" 1)
        parts+=("$(calc "$v" 1)|$l")
    done
    rest=$(calc "$total - $sum")
    printf '%s\n' "${parts[@]}" | sort -t'|' -k1,1 -g -r | while IFS='|' read -r v l; do
        printf '%s %s (%s %%), ' "$l" "$(n "$v")" "$(pct "$v" "$total")"
    done
    printf 'the rest of the loop (supervisor, corrections, the master, the log) %s (%s %%)' "$(n "$rest")" "$(pct "$rest" "$total")"
}
# Transcendental calls per two-leg IK, counted in gait-core/src/kinematics/leg.rs (legs_ik):
# 3 rot_cols × 3 sin_cos + 2 legs × 2 sin_cos, 2 legs × 7 atan2, 2 legs × 5 sqrt.
ik_sc=13 ik_at=14 ik_sq=10
ik_tr() { # array → instructions in the IK's sin_cos/atan2/sqrt (primitive figures × calls)
    local -n a=$1
    calc "$ik_sc * ${a[prim.sin_cos_fast.avg]} + $ik_at * ${a[prim.atan2_fast.avg]} + $ik_sq * ${a[prim.sqrt_fast.avg]}"
}
ik7=$(ik_tr M7)
ik3=$(ik_tr M3)
# The fixed-point IK (gait-core/src/kinematics/fixed_ik.rs, legs_ik): 2 legs × 7 atan2 and 5 isqrt; its
# sin_cos calls skip zero angles (the forward walk is level and straight: 2 legs × 2).
fik_at=14 fik_sc=4
fik3=$(calc "$fik_at * ${M3[prim.fx_atan2.avg]} + $fik_sc * ${M3[prim.fx_sin_cos.avg]}")
exp3=$(calc "2 * ${M3[prim.fx_exp_neg.avg]}")
opt_level=$(sed -n '/^\[profile\.release\]/,/^\[/ s/^opt-level *= *"\{0,1\}\([^"]*\)"\{0,1\}.*/\1/p' Cargo.toml)
opt_level_m3=$(sed -n '/^\[profile\.release-m3\]/,/^\[/ s/^opt-level *= *"\{0,1\}\([^"]*\)"\{0,1\}.*/\1/p' Cargo.toml)

section=$out/section.md
{
    cat <<EOF
## On target: instructions per call (QEMU \`-icount shift=0\`), sizes, bus budget

Generated by \`bash scripts/bench.sh\` (rustc $rustc_v, qemu-system-arm $qemu_v); do not edit
between the markers. The instruction counts are exact and deterministic: every QEMU run is done
twice and the script stops if the two outputs differ; running the script again gives the same
counts (only the host criterion figures change, they are wall-clock).

How it counts (\`src/bin/bench.rs\`): with \`-icount shift=0\` one instruction is one virtual
ns and SysTick counts at 25 MHz, i.e. one count per 40 instructions. Each stage runs K times in
a loop (K = every tick of the Table 2 walk at the firmware's ${M7[tick_us]} µs period,
$(n "${M7[walk.tlipfm.ticks]}") ticks, for the gait stages; 4,096 otherwise),
SysTick read before and after each call. **avg** = telescoped counts × 40 / K minus the loop's
own overhead (an empty call: ${M7[overhead.avg]} instructions per iteration); **max** = the largest
single call, resolution 40 instructions (one count), call and timer reads included. QEMU counts
instructions, not cycles: the M7 and M4F run the same ELF and give the same counts (a real M7
dual-issues; cycles are not modelled). Inputs a stage takes from an earlier stage (the IK's gait
samples) are computed beforehand, so each stage is timed alone. Release profile of Cargo.toml:
**opt-level "$opt_level"** (dxl at 3; chosen by measurement, the figures are in Cargo.toml's
comment), fat LTO, one codegen unit.

Reproduce one machine by hand:

\`\`\`sh
DEFMT_LOG=off cargo build --release --no-default-features --features board-qemu,fake-robot --bin bench --target-dir target/bench-build
DEFMT_LOG=off cargo build --profile release-m3 --no-default-features --features board-qemu,fixed-gait,fake-robot --bin bench --target-dir target/bench-build --target thumbv7m-none-eabi
scripts/qemu-run.sh target/bench-build/thumbv7em-none-eabihf/release/bench --raw      # an500; also --machine mps2-an386
scripts/qemu-run.sh target/bench-build/thumbv7m-none-eabi/release-m3/bench --raw      # an385 (by the target)
\`\`\`

### Full control tick, instructions (avg over the walk, max per tick in parentheses)

The firmware's control loop itself, \`control::run\` (\`control::controller::Controller::tick\`),
walking Table 2 with each model on an in-memory bus of emulated devices (12 servos, two loaded
foot boards, the IMU; ramp and final hold cut to one tick). Per walking tick = SysTick from the
return of one \`wait_tick\` to the next, minus the time inside the board's methods (device
emulation behind \`send\`, byte queue behind \`recv\`, log sink; the calls themselves count),
the first 2 and last 4 ticks left out. The paths:

- **f32**: the defaults (paper pipeline, the gyro damping, the compliance feed-forward, the
  catching step with the levelling and the clock hold, the leg odometry; stabilizer off).
- **f32 + compensation + stabilizer** (\`comp=wholebody stab=on\`): the stabilizer's shift
  from the measured ZMP and the gyro, and the whole-body compensation with it
  (\`gait::Targets::WholeBody\`, 2 iterations: 4 two-leg IK and 3 FK/CoM evaluations).
- **fixed** (\`math=fixed\`, the \`fixed-gait\` build of the Cortex-M3): integer pitch-rate
  filter with τ in mN·m, fixed-point sampler, fixed-point measured ZMP, integer-only two-leg
  IK and the integer limit and rad → tick conversion: no float in the tick but the sampler's
  once-per-segment bookkeeping.

| machine | path | LIPM | DLIPM | TLIPFM |
| --- | --- | --- | --- | --- |
| Cortex-M7, mps2-an500 | f32 | $(cell M7 tick.f32.lipm) | $(cell M7 tick.f32.dlipm) | $(cell M7 tick.f32.tlipfm) |
| Cortex-M7, mps2-an500 | f32 + compensation + stabilizer | $(cell M7 tick.comp_stab.lipm) | $(cell M7 tick.comp_stab.dlipm) | $(cell M7 tick.comp_stab.tlipfm) |
| Cortex-M4F, mps2-an386 | f32 | $(cell M4 tick.f32.lipm) | $(cell M4 tick.f32.dlipm) | $(cell M4 tick.f32.tlipfm) |
| Cortex-M4F, mps2-an386 | f32 + compensation + stabilizer | $(cell M4 tick.comp_stab.lipm) | $(cell M4 tick.comp_stab.dlipm) | $(cell M4 tick.comp_stab.tlipfm) |
| Cortex-M3, mps2-an385 | fixed | $(cell M3 tick.fixed.lipm) | $(cell M3 tick.fixed.dlipm) | $(cell M3 tick.fixed.tlipfm) |
| Cortex-M3, mps2-an385 | f32 (soft float) | $(cell M3 tick.f32.lipm) | $(cell M3 tick.f32.dlipm) | $(cell M3 tick.f32.tlipfm) |
| Cortex-M3, mps2-an385 | f32 + compensation + stabilizer (soft float) | $(cell M3 tick.comp_stab.lipm) | $(cell M3 tick.comp_stab.dlipm) | $(cell M3 tick.comp_stab.tlipfm) |

### The tick by stage

The default configuration (${M7[control.model]}) as above, each stage of
\`Controller::tick\` metered by the controller's stage marks (\`board::Stage\`), avg (max)
per walking tick over $(n "${M7[control.tick.n]}") ticks; the log record is
≈ $(calc "${M7[control.log_bytes]} / ${M7[control.ticks]}") bytes per tick.

| stage | Cortex-M7 | Cortex-M4F | Cortex-M3, f32 soft float | Cortex-M3, fixed-point path |
| --- | --- | --- | --- | --- |
$(for st in sense estimate command walk act report; do
    echo "| $st | $(cell M7 control.stage.$st) | $(cell M4 control.stage.$st) | $(cell M3 control.stage.$st) | $(cell M3 control_fixed.stage.$st) |"
done)
| the tick | $(cell M7 control.tick) | $(cell M4 control.tick) | $(cell M3 control.tick) | $(cell M3 control.tick_fixed) |

sense: the sensors' BULK READ (the dxl master's transaction), the plausibility checks, the
supervisor's freshness (and the leg odometry's reads, two ticks a step); estimate: the attitude,
τ, the measured ZMP, the loads; command: the command port; walk: the walk mode, the sample
corrections, the IK, the joint corrections; act: the servo ticks, the SYNC WRITE, the servo
monitor; report: the tick record and the command port's status. The stages' sum is the tick
less the tick's own bookkeeping (the crash cell, the overrun count).

The Cortex-M3 bench is built as the M3 firmware is (profile \`release-m3\`, opt-level "$opt_level_m3", with
the \`fixed-gait\` feature); its stage figures below are of that build too.

What dominates (TLIPFM, avg; the parts are the stage figures below, the rest is the tick minus
their sum):

- **M7, f32 tick $(n "$t7")**: $(breakdown "$t7" "Dynamixel codec|$codec7" \
        "IK|${M7[ik.tlipfm.avg]}" "measured ZMP|${M7[mzmp.tlipfm.avg]}" \
        "gait sample|${M7[sample.f32.tlipfm.avg]}" "pitch filter|${M7[imu.pitch_accel.avg]}").
  The codec: decoding and parsing the $rx_bytes reply bytes $(n "${M7[dxl.decode3_block.avg]}") ≈ $(per_rx M7 dxl.decode3_block) per byte, the
  ${M7[bytes.sync_write]}-byte SYNC WRITE $(n "${M7[dxl.sync_write12.avg]}"), the BULK READ $(n "${M7[dxl.bulk_read3.avg]}") (a 72-byte
  CRC alone: $(n "${M7[dxl.crc16_72.avg]}"); per-byte figures in the codec table below). The IK's
  $ik_sc sin_cos + $ik_at \`atan2\` + $ik_sq \`sqrt\` (\`gait_core::maths::fastmath\`) are ≈ $(n "$ik7") by the primitive figures below
  (\`sqrt\` is the FPU's \`VSQRT.F32\`, $(n "${M7[prim.sqrt_fast.avg]}") a call with the bench's loads and stores, against
  $(n "${M7[prim.sqrtf.avg]}") for libm's software \`sqrtf\`; \`atan2\` $(n "${M7[prim.atan2_fast.avg]}") against $(n "${M7[prim.atan2f.avg]}") for \`libm::atan2f\`). Without the codec the tick
  is $(n "$t7 - $codec7").
- **M7, f32 + compensation + stabilizer $(n "$t7cs")** ($(ratio "$t7cs" "$t7")× the f32 tick):
  $(breakdown "$t7cs" "whole-body compensation|${M7[wholebody.tlipfm.avg]}" \
        "stabilizer step|${M7[stab.tlipfm.avg]}" "Dynamixel codec|$codec7" \
        "measured ZMP|${M7[mzmp.tlipfm.avg]}" "gait sample|${M7[sample.f32.tlipfm.avg]}" \
        "pitch filter|${M7[imu.pitch_accel.avg]}"). The stabilizer step takes the support polygon
  from \`control::SupportCache\`; building one (\`control::support_of\`, $(n "${M7[support.tlipfm.avg]}")) is paid
  only when the support phase or a supporting foot changes.
- **M3, fixed tick $(n "$t3")**: $(breakdown "$t3" "Dynamixel codec|$codec3" \
        "fixed-point IK|${M3[ik.fixed.tlipfm.avg]}" "measured ZMP (fixed point)|${M3[mzmp.fixed.tlipfm.avg]}" \
        "fixed-point sample|${M3[sample.fixed.tlipfm.avg]}" "pitch filter (integer)|${M3[imu.pitch_accel_fixed.avg]}").
  The fixed-point IK's $fik_at \`atan2\` + $fik_sc \`sin_cos\` are ≈ $(n "$fik3") by the primitives, plus 10 exact
  integer square roots of up to 62-bit operands (\`isqrt\`; the \`fixed_ik::sqrt\` primitive,
  $(n "${M3[prim.fx_sqrt.avg]}"), takes a shorter operand). The fixed-point IK costs $(n "${M3[ik.fixed.tlipfm.avg]}") against
  $(n "${M3[ik.tlipfm.avg]}") for the f32 IK in soft float ($(ratio "${M3[ik.tlipfm.avg]}" "${M3[ik.fixed.tlipfm.avg]}")× less) and against $(n "${M7[ik.tlipfm.avg]}")
  for the f32 IK on the M7's FPU. The fixed-point sampler's two \`exp_neg\` (reciprocal tables,
  \`i64\` only, no division) are $(n "$exp3") of its $(n "${M3[sample.fixed.tlipfm.avg]}"); it costs $(ratio "${M3[sample.f32.tlipfm.avg]}" "${M3[sample.fixed.tlipfm.avg]}")× less than the f32
  sampler in soft float ($(n "${M3[sample.f32.tlipfm.avg]}")) and $(n "${M7[sample.fixed.tlipfm.avg]}") on the M7, $(than "${M7[sample.fixed.tlipfm.avg]}" "${M7[sample.f32.tlipfm.avg]}") than the M7's f32
  sampler ($(n "${M7[sample.f32.tlipfm.avg]}")). The tick's worst case, $(n "${M3[tick.fixed.tlipfm.max]}"), is the sampler's once-per-segment
  plan bookkeeping, still f32 in soft float (the fixed-point sample's max is $(n "${M3[sample.fixed.tlipfm.max]}")). The fixed path saves $(n "$t3f - $t3") instructions per tick on the M3 against
  f32 soft float ($(n "$t3f")).
- **Control loop, M7 $(n "${M7[control.tick.avg]}")**: the loop alone, measured
  instruction by instruction ($(profiled)): $(profiled_loop).

### Targets

| target | measured | verdict |
| --- | --- | --- |
| M7 firmware control-loop tick, the loop alone (not the library calls) ≤ 8,000 instructions avg | $(profiled_target) | $(profiled_verdict) |
| codec: decode ≤ 20 per received byte, encode ≤ 12 per sent byte (M7) | decode (block) $(per_rx M7 dxl.feed3), SYNC WRITE $(per_sw M7), BULK READ $(per_br M7) | decode $(verdict "$(per_rx M7 dxl.feed3)" 20), SYNC WRITE $(verdict "$(per_sw M7)" 12), BULK READ $(verdict "$(per_br M7)" 12) |
| M3 control-loop tick with the fixed-point path ≤ 25,000 | $(n "${M3[control.tick_fixed.avg]}") avg, $(n "${M3[control.tick_fixed.max]}") max | $(verdict "${M3[control.tick_fixed.avg]}" 25000) |
| M3 builds ≤ 112 KiB flash, ≤ 16 KiB static RAM | OpenCM 9.04 $(n "$m_flash") B / $(n "$m_ram") B; QEMU M3 $(n "$q3_flash") B / $(n "$q3_ram") B | OpenCM $(verdict "$m_flash" 114688) / $(verdict "$m_ram" 16384); QEMU M3 $(verdict "$q3_flash" 114688) / $(verdict "$q3_ram" 16384) |

### Dynamixel codec per byte (targets: decode ≤ 20 per received byte, encode ≤ 12 per sent byte)

The three status replies ($rx_bytes bytes: $sfl + $sfr + $simu) and the two instruction packets of a
tick, instructions per byte (stage avg ÷ bytes). **Block decoding** (\`Decoder::feed\`) is what the
bus master uses: it reads the rest of a frame from the UART in one \`recv\` (\`Decoder::wanted\`)
and feeds it at once (a whole clean frame is checked with one CRC pass over it); **byte by byte**
(\`Decoder::push\`) is the same decoder one byte per call. Parsing (\`Status::from_packet\`, the
foot and IMU records) comes on top in the "decode + parse" row (the tick's figure).

| per byte | Cortex-M7 | Cortex-M4F | Cortex-M3 | target | M7 verdict |
| --- | --- | --- | --- | --- | --- |
| decode, block (\`dxl.feed3\`) | $(per_rx M7 dxl.feed3) | $(per_rx M4 dxl.feed3) | $(per_rx M3 dxl.feed3) | ≤ 20 | $(verdict "$(per_rx M7 dxl.feed3)" 20) |
| decode + parse, block (\`dxl.decode3_block\`) | $(per_rx M7 dxl.decode3_block) | $(per_rx M4 dxl.decode3_block) | $(per_rx M3 dxl.decode3_block) | | |
| decode, byte by byte (\`dxl.push3\`) | $(per_rx M7 dxl.push3) | $(per_rx M4 dxl.push3) | $(per_rx M3 dxl.push3) | | |
| encode SYNC WRITE, 12 goals (${sw} B) | $(per_sw M7) | $(per_sw M4) | $(per_sw M3) | ≤ 12 | $(verdict "$(per_sw M7)" 12) |
| encode BULK READ (${br} B) | $(per_br M7) | $(per_br M4) | $(per_br M3) | ≤ 12 | $(verdict "$(per_br M7)" 12) |
| CRC-16, 72 B (\`crc::crc16\`, slicing by 4) | $(calc "${M7[dxl.crc16_72.avg]} / 72" 1) | $(calc "${M4[dxl.crc16_72.avg]} / 72" 1) | $(calc "${M3[dxl.crc16_72.avg]} / 72" 1) | | |

The encode rows include the bench's own assembly of the 12 \`(id, bytes)\` entries.

### Stages, instructions per call: avg (max)

| stage | model | Cortex-M7 (an500) | Cortex-M4F (an386) | Cortex-M3 (an385, soft float) |
| --- | --- | --- | --- | --- |
EOF
    for st in "sample.f32:exact closed-form sample, f32 (\`Sampler::next\`)" \
        "sample.fixed:fixed-point sample (\`FixedSampler::next\`)" \
        "fourier24:Fourier CoM, 24 terms, f32 (\`FourierCom::sample\`)" \
        "ik:two-leg IK, f32 (\`pipeline::joint_targets\`)" \
        "ik.fixed:two-leg IK, fixed point (\`fixed_ik::joint_targets\`)" \
        "wholebody:whole-body compensation, f32, 2 iterations (\`WholeBody::joint_targets\`)" \
        "support:support polygon of a sample (\`control::support_of\`)" \
        "stab:stabilizer step: support polygon + \`Stabilizer::update\`" \
        "mzmp:measured ZMP, f32 (\`measured::measured_zmp\`)" \
        "mzmp.fixed:measured ZMP, fixed point (\`measure::zmp::FixedZmpMeter::zmp\`)" \
        "tick.f32:control loop tick, f32 (\`control::run\`)" \
        "tick.comp_stab:control loop tick, f32 + compensation + stabilizer" \
        "tick.fixed:control loop tick, fixed point"; do
        for m in lipm dlipm tlipfm; do
            core_row "${st%%:*}.$m" "${st#*:}" "$m"
        done
    done
    for st in "swing.cycloid:swing foot alone, cycloid (\`swing::swing_foot\`)" \
        "imu.pitch_accel:pitch-rate filter and τ (\`imu::PitchAccel\`)" \
        "imu.pitch_accel_fixed:pitch-rate filter and τ, integer (\`imu::FixedPitchAccel\`)" \
        "dxl.sync_write12:encode SYNC WRITE, 12 goal positions (${sw} bytes)" \
        "dxl.bulk_read3:encode BULK READ, feet + IMU (${br} bytes)" \
        "dxl.decode3:decode + parse 3 status replies byte by byte (${sfl} + ${sfr} + ${simu} bytes)" \
        "dxl.decode3_block:decode + parse 3 status replies, block feeds" \
        "dxl.feed3:decode 3 status replies, block feeds (\`Decoder::feed\`), no parse" \
        "dxl.push3:decode 3 status replies byte by byte (\`Decoder::push\`), no parse" \
        "dxl.crc16_72:CRC-16 over 72 bytes (\`dxl::crc::crc16\`)"; do
        core_row "${st%%:*}" "${st#*:}" all
    done
    cat <<EOF

The stabilizer rows feed it a measured ZMP off the reference by a deterministic ±12.6 mm
pattern and a constant gyro, so its saturation, rate limit and support-polygon limit all act.

Primitives (per call, including a \`black_box\` store and load of the argument and result):

| function | Cortex-M7 | Cortex-M4F | Cortex-M3 |
| --- | --- | --- | --- |
EOF
    for st in "prim.expf:\`libm::expf\`" "prim.sqrtf:\`libm::sqrtf\` (software)" \
        "prim.sqrt_fast:\`gait_core::maths::fastmath::sqrt\` (\`VSQRT.F32\` on M7/M4F, libm on M3)" \
        "prim.atan2f:\`libm::atan2f\`" "prim.atan2_fast:\`gait_core::maths::fastmath::atan2\`" \
        "prim.sin_cos_fast:\`gait_core::maths::fastmath::sin_cos\`" \
        "prim.sinf_libm:\`libm::sinf\` (software doubles)" "prim.fmul:f32 multiply" \
        "prim.fdiv:f32 divide" "prim.fx_exp_neg:\`fixed_point::exp_neg\`" \
        "prim.fx_sin_cos:\`fixed_point::sin_cos\`" "prim.fx_sqrt:\`fixed_ik::sqrt\` (Fx)" \
        "prim.fx_atan2:\`fixed_ik::atan2\`"; do
        core_row "${st%%:*}" "${st#*:}"
    done
    cat <<EOF

### Firmware sizes (release ELFs, \`readelf -S\`)

\`cargo build --release --no-default-features --features board-qemu --bin qemu\`,
\`cargo build --release --no-default-features --features board-opencr --bin opencr\`, and the
Cortex-M3 builds with the fixed-point path, \`cargo build --profile release-m3 --target
thumbv7m-none-eabi --no-default-features --features board-opencm --bin opencm\` (and
\`--features board-qemu,fixed-gait --bin qemu\`; CI limit 112 KiB flash, 16 KiB static RAM). Flash =
every allocated section with contents (vector table, .text, .rodata, the .data image); static
RAM = .data + .bss + .uninit (the stack comes on top).

| ELF | .text | .rodata | .data | .bss | flash | static RAM | share of the board |
| --- | --- | --- | --- | --- | --- | --- | --- |
| \`qemu\` (mps2) | $(commas "$q_text") | $(commas "$q_ro") | $(commas "$q_data") | $(commas "$q_bss") | $(commas "$q_flash") B ($(kib "$q_flash") KiB) | $(commas "$q_ram") B ($(kib "$q_ram") KiB) | flash $(calc "100 * $q_flash / 4194304" 1) % of 4 MiB |
| \`opencr\` (STM32F746) | $(commas "$o_text") | $(commas "$o_ro") | $(commas "$o_data") | $(commas "$o_bss") | $(commas "$o_flash") B ($(kib "$o_flash") KiB) | $(commas "$o_ram") B ($(kib "$o_ram") KiB) | flash $(calc "100 * $o_flash / 1048576" 1) % of 1 MiB, RAM $(calc "100 * $o_ram / 327680" 1) % of 320 KiB |
| \`opencm\` (STM32F103CB, M3, release-m3) | $(commas "$m_text") | $(commas "$m_ro") | $(commas "$m_data") | $(commas "$m_bss") | $(commas "$m_flash") B ($(kib "$m_flash") KiB) | $(commas "$m_ram") B ($(kib "$m_ram") KiB) | flash $(calc "100 * $m_flash / 116736" 1) % of 114 KiB, static RAM $(calc "100 * $m_ram / 20480" 1) % of 20 KiB |
| \`qemu\` M3 (mps2-an385, release-m3, fixed-gait) | $(commas "$q3_text") | $(commas "$q3_ro") | $(commas "$q3_data") | $(commas "$q3_bss") | $(commas "$q3_flash") B ($(kib "$q3_flash") KiB) | $(commas "$q3_ram") B ($(kib "$q3_ram") KiB) | flash $(calc "100 * $q3_flash / 114688" 1) % of the 112 KiB limit |

Built from the working tree at the time of the run. The firmware keeps its state (sampler,
plan, IK) on the stack, so static RAM understates its RAM use; the stack is not measured here.

### Bus budget per control tick

Packet sizes from dxl's encoders (printed by the bench): BULK READ request $br B, status replies
$sfl + $sfr + $simu B (feet 18 data bytes, IMU 26), SYNC WRITE of 12 goal positions $sw B:
**$bus_bytes bytes per tick**, $packets packets, 10 bits per byte, Return Delay Time 0. Turnaround
allowance: $turnaround_us µs per packet (assumed, not measured: the line changes direction or the
talker changes before each of the 5 packets; an AX-12 at Return Delay 0 answers a READ after
≈ 22 µs, X-series and our boards are not measured; \`BENCH_TURNAROUND_US\` changes it). The
last column adds the M7 control-loop tick's worst case ($(n "$tick_m7_max") instructions) at
$cpu_mhz MHz assuming one instruction per cycle (≈ $compute_us µs; an estimate, the bus and the
CPU do not overlap in a blocking loop). Not in the table: the servo monitor's READs
(\`src/monitor.rs\`), one every 2.5 ms whatever the tick rate — Torque Enable .. Hardware Error
Status (14 + 18 B, the longest), voltage and temperature (14 + 14 B) or current (14 + 13 B),
≤ 320 µs at 1 Mbps, ≤ 71 µs at 4.5 Mbps each, plus a turnaround: two on a 5 ms tick, at most
one on a 1 ms tick.

| bus | bytes on the wire | + allowance | bus time per tick | highest servo rate (bus only) | with the M7 compute |
| --- | --- | --- | --- | --- | --- |
EOF
    for mbps in 1 3 4.5; do
        wire=$(calc "$bus_bytes * 10 / $mbps" 1)
        total=$(calc "$wire + $packets * $turnaround_us" 1)
        echo "| $mbps Mbps | $wire µs | $(calc "$packets * $turnaround_us") µs | $total µs | $(n "1000000 / $total - 0.5") Hz | $(n "1000000 / ($total + $compute_us) - 0.5") Hz |"
    done
    cat <<EOF

**The QEMU board's clock** charges each tick's compute time as this run's worst-case control-loop
tick over the modelled core clock, one instruction per cycle (\`src/boards/tick_cost.rs\`,
regenerated by this script; \`qemu_mps2::compute_ns\`): $(n "${M7[control.tick.max]}") instructions
÷ 216 MHz (\`core_mhz\`, the OpenCR) = $(calc "${M7[control.tick.max]} / 216" 1) µs per tick on the hard-float ELF;
the soft-float (Cortex-M3) figure $(n "${M3[control.tick.max]}") ÷ 72 MHz = $(calc "${M3[control.tick.max]} / 72" 1) µs. \`compute_us=\` still
overrides it.

The firmware's default configuration (tick ${M7[tick_us]} µs, bus $(calc "${M7[bus_baud]} / 1000000" 1) Mbps) $fits: the bus
needs $(calc "$bus_bytes * 10000000 / ${M7[bus_baud]} + $packets * $turnaround_us") µs of it. A 1 kHz tick needs at least 3 Mbps.

### Host (criterion, x86-64, this run)

\`cargo bench --target host-tuple -p gait-core --bench sampler -- --warm-up-time 0.3 --measurement-time 1\`
and \`... --bench ik -- --warm-up-time 0.3 --measurement-time 1\`; the middle of criterion's
interval. Wall-clock figures on a shared 2-core machine: they change from run to run (±20 %).

| model | exact f32 | exact f64 | fixed point | Fourier N = 24, f32 |
| --- | --- | --- | --- | --- |
EOF
    for m in lipm dlipm tlipfm; do
        echo "| $m | $(h "sample/$m/f32") | $(h "sample/$m/f64") | $(h "sample/$m/fixed") | $(h "sample/$m/fourier24-f32") |"
    done
    cat <<EOF

| two-leg IK | time |
| --- | --- |
| \`legs_ik\` f32 | $(h legs_ik_f32) |
| \`legs_ik\` f64 | $(h legs_ik_f64) |
| \`LegKinematics::legs_ik\` f32 | $(h legs_ik_f32_precomputed) |
| \`LegKinematics::legs_ik\` f64 | $(h legs_ik_f64_precomputed) |
EOF
} >"$section"

# ---- splice into BENCHMARKS.md ----
md=BENCHMARKS.md
tmp=$(mktemp)
if grep -q '^<!-- bench:begin -->$' "$md" && grep -q '^<!-- bench:end -->$' "$md"; then
    awk -v sec="$section" '
        /^<!-- bench:begin -->$/ { print; while ((getline l < sec) > 0) print l; skip = 1; next }
        /^<!-- bench:end -->$/ { skip = 0 }
        !skip { print }
    ' "$md" >"$tmp"
else
    { cat "$md"; echo; echo '<!-- bench:begin -->'; cat "$section"; echo '<!-- bench:end -->'; } >"$tmp"
fi
mv "$tmp" "$md"
echo "bench.sh: BENCHMARKS.md updated (raw outputs in $out/)" >&2
