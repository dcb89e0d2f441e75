#!/usr/bin/env bash
# Where the control tick's instructions go (issue 14): an exact per-instruction count of the
# firmware's control loop on the bench's fake robot, in QEMU, attributed to the code.
#
# Usage: [TICK=worst|N] bash scripts/tick-profile.sh [m7|m3] [functions|lines|stack|calls|crates] [N] [PATTERN]
#   TICK=worst: the profile of the tick with the most instructions (TICK=N: of tick N, from 0)
#   instead of the average tick (per-tick totals: target/tick-profile/{m7,m3}-ticks.txt).
#   m7 (default): the hard-float bench on mps2-an500, math=f32 (the default configuration);
#   m3: the Cortex-M3 bench (profile release-m3, fixed-gait) on mps2-an385, math=fixed.
#   functions (default) | lines | stack | calls | crates: see scripts/tick-profile/attribute.py
#   (calls: who calls the functions matching PATTERN, default 'memcpy|memclr|memset|memmove').
#
# How: the bench is built control-only (BENCH_CONTROL_ONLY) with the feature `tick-profile`
# (its tick meter's methods out of line); QEMU runs it with the TCG plugin
# scripts/tick-profile/gate.c, which counts instructions only between TickMeter::tick and the
# next TickMeter::tick_start, minus the spans between TickMeter::enter and ::leave (the device
# emulation, as the bench leaves it out). The per-tick total agrees with the bench's
# control.tick avg to a few tens of instructions (the meter's own calls). Inlined code counts
# for the function it was inlined into (`lines`/`stack` show the inline chain).
# Needs: qemu-system-arm with plugin support (Debian's has it), a C compiler (cc), llvm-nm,
# llvm-objdump and llvm-symbolizer (Debian: apt-get install llvm), python3.
# Outputs: target/tick-profile/{m7,m3}.txt (address count), the plugin libgate.so.
set -euo pipefail
cd "$(dirname "$0")/.."

core=${1:-m7}
mode=${2:-functions}
rows=${3:-40}
pattern=${4:-memcpy|memclr|memset|memmove}
for tool in qemu-system-arm cc llvm-nm llvm-objdump llvm-symbolizer python3; do
    if ! command -v "$tool" >/dev/null 2>&1; then
        echo "tick-profile.sh: $tool not found (qemu: bash scripts/setup.sh; llvm: apt-get install llvm)" >&2
        exit 127
    fi
done

out=target/tick-profile
mkdir -p "$out"
cc -shared -fPIC -O2 -Wall -o "$out/libgate.so" scripts/tick-profile/gate.c

build_dir=target/tick-profile-build
case "$core" in
    m7)
        BENCH_CONTROL_ONLY=1 DEFMT_LOG=off cargo build --release --no-default-features \
            --features board-qemu,fake-robot,tick-profile --bin bench --target-dir "$build_dir"
        elf=$build_dir/thumbv7em-none-eabihf/release/bench
        machine=mps2-an500
        ;;
    m3)
        BENCH_CONTROL_ONLY=fixed DEFMT_LOG=off cargo build --profile release-m3 \
            --target thumbv7m-none-eabi --no-default-features \
            --features board-qemu,fixed-gait,fake-robot,tick-profile --bin bench \
            --target-dir "$build_dir"
        elf=$build_dir/thumbv7m-none-eabi/release-m3/bench
        machine=mps2-an385
        ;;
    *)
        echo "usage: $0 [m7|m3] [functions|lines|stack|calls|crates] [N] [PATTERN]" >&2
        exit 2
        ;;
esac

mark() { # the address of TickMeter's Observer method $1
    # (llvm-nm leaves these legacy-mangled: `…TickMeter$u20$as$u20$…Observer$GT$::tick::h…`)
    # awk reads to the end (an early exit would make llvm-nm fail writing: exit 74).
    llvm-nm -C "$elf" | awk -v m="$1" '!found && /TickMeter/ && /Observer/ && $0 ~ "::" m "(::h[0-9a-f]+)?$" {print $1; found = 1}'
}
on="$(mark tick),$(mark leave)"
off="$(mark tick_start),$(mark enter)"
case "$on,$off" in
    *,,*|,*|*,) echo "tick-profile.sh: the tick meter's methods are not in $elf (inlined?)" >&2; exit 1 ;;
esac

counts=$out/$core.txt
per_tick=$out/$core-ticks.txt
helpers=
if [ "$mode" = crates ]; then
    # The runtime helpers' instructions are counted at their call site (gate.c's PROF_HELPERS).
    helpers=$(python3 scripts/tick-profile/attribute.py "$elf" - 1 helpers)
fi
profile() { # the bench under the plugin; extra environment in "$@"
    env PROF_ON="$on" PROF_OFF="$off" PROF_OUT="$counts" PROF_TICKS="$per_tick" \
        PROF_HELPERS="$helpers" "$@" \
        qemu-system-arm -M "$machine" -nographic -monitor none \
        -serial null -serial null -serial null -serial null \
        -semihosting-config enable=on,target=native -icount shift=0 \
        -kernel "$elf" -plugin "$out/libgate.so" | tee "$out/$core-bench.txt" | grep -E 'tick'
}
profile
ticks=$(awk '/^control.*\.tick.*\.n /{print $2}' "$out/$core-bench.txt")
if [ -n "${TICK:-}" ]; then
    # One tick's profile: TICK=worst (the tick with the most instructions) or TICK=N.
    only=$TICK
    [ "$TICK" = worst ] && only=$(sort -k2,2n "$per_tick" | tail -1 | cut -d' ' -f1)
    echo "tick $only: $(awk -v t="$only" '$1 == t {print $2}' "$per_tick") instructions"
    profile PROF_ONLY_TICK="$only" >/dev/null
    ticks=1
fi
python3 scripts/tick-profile/attribute.py "$elf" "$counts" "$ticks" "$mode" "$rows" "$pattern"
