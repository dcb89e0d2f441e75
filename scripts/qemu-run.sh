#!/usr/bin/env bash
# Runs a walker-firmware ELF (board-qemu build) in qemu-system-arm and decodes its defmt output.
#
# Usage: scripts/qemu-run.sh ELF [options] [extra qemu args]
#   --bus SPEC       chardev of UART0, the servo bus   (default: $WALKER_BUS or null)
#   --log SPEC       chardev of UART1, the ZMP log     (default: $WALKER_LOG or
#                    file:target/qemu-zmp-log.bin)
#   --lockstep SPEC  chardev of UART2, the lock-step channel; also turns lock-step on in the
#                    firmware (semihosting command line "lockstep") (default: $WALKER_LOCKSTEP;
#                    without it UART2 is null and the bus is unconnected: reads time out)
#   --machine M      mps2-an500 (Cortex-M7, default: $WALKER_QEMU_MACHINE) or mps2-an386 (M4F)
#   --timeout S      wall-clock limit in seconds (default: $WALKER_QEMU_TIMEOUT or 600; 0 = none)
#   SPEC is a qemu chardev, e.g. tcp:127.0.0.1:4000,nodelay=on  file:out.bin  null
#
# As a cargo runner (cargo passes the ELF first, then the program's arguments):
#   CARGO_TARGET_THUMBV7EM_NONE_EABIHF_RUNNER=scripts/qemu-run.sh \
#     cargo run --release --no-default-features --features board-qemu --bin qemu
#   CARGO_TARGET_THUMBV7EM_NONE_EABIHF_RUNNER=scripts/qemu-run.sh \
#     cargo test --release --no-default-features --features board-qemu --test on_target
#
# The exit status is the firmware's (semihosting SYS_EXIT_EXTENDED): 0 ok, non-zero failure
# (101 panic, 3 virtual watchdog, 124 wall-clock timeout, 127 qemu missing).
# defmt frames arrive on qemu's stdout (semihosting) and are decoded with `defmt-print -e ELF`
# when it is installed (`cargo install defmt-print --version 1.2.0 --locked`); otherwise the
# raw frames are saved next to the ELF (ELF.defmt) and decoded after the run by the `walker`
# binary when one is built (`walker capture --defmt ELF.defmt --elf ELF` → ELF.defmt.log),
# else a one-line hint is printed.
# Run-to-run determinism: -icount shift=0 (1 instruction = 1 virtual ns) and the firmware's
# virtual clock (see src/boards/qemu_mps2.rs and docs/lockstep.md).
set -u

if [ $# -lt 1 ]; then
    echo "usage: $0 ELF [--bus SPEC] [--log SPEC] [--lockstep SPEC] [--machine M] [--timeout S] [qemu args...]" >&2
    exit 2
fi
elf=$1
shift

if ! command -v qemu-system-arm >/dev/null 2>&1; then
    echo "qemu-run.sh: qemu-system-arm not found; install it with: apt-get install qemu-system-arm" >&2
    exit 127
fi
if [ ! -f "$elf" ]; then
    echo "qemu-run.sh: no such ELF: $elf" >&2
    exit 2
fi

bus=${WALKER_BUS:-null}
log=${WALKER_LOG:-file:target/qemu-zmp-log.bin}
lockstep=${WALKER_LOCKSTEP:-}
machine=${WALKER_QEMU_MACHINE:-mps2-an500}
timeout_s=${WALKER_QEMU_TIMEOUT:-600}
extra=()
while [ $# -gt 0 ]; do
    case "$1" in
        --bus) bus=$2; shift 2 ;;
        --log) log=$2; shift 2 ;;
        --lockstep) lockstep=$2; shift 2 ;;
        --machine) machine=$2; shift 2 ;;
        --timeout) timeout_s=$2; shift 2 ;;
        *) extra+=("$1"); shift ;;
    esac
done

# A log file's directory must exist.
case "$log" in
    file:*) mkdir -p "$(dirname "${log#file:}")" ;;
esac

append=()
if [ -n "$lockstep" ]; then
    append=(-append lockstep)
else
    lockstep=null
fi

cmd=(qemu-system-arm -M "$machine" -nographic -monitor none
    -serial "$bus" -serial "$log" -serial "$lockstep"
    -semihosting-config enable=on,target=native
    -icount shift=0
    -kernel "$elf" "${append[@]}" "${extra[@]}")

# QEMU hands the firmware "ELF -append-text" + NUL through semihosting and refuses when that is
# over the firmware's 1024-byte buffer (walker_contract::params::CMDLINE_MAX): the firmware
# would then read no parameter. Refuse it here, before QEMU starts (the last -append wins).
cmdline_max=1024
text=
prev=
for a in "${cmd[@]}"; do
    if [ "$prev" = "-append" ]; then text=$a; fi
    prev=$a
done
need=$(( ${#elf} + 1 + ${#text} + 1 ))
if [ -n "$text" ] && [ "$need" -gt "$cmdline_max" ]; then
    echo "qemu-run.sh: the firmware command line is $need bytes (ELF path + space + -append text + NUL), over the firmware's $cmdline_max-byte semihosting buffer" >&2
    exit 2
fi

limit=()
if [ "$timeout_s" != "0" ] && command -v timeout >/dev/null 2>&1; then
    limit=(timeout --foreground "$timeout_s")
fi

if command -v defmt-print >/dev/null 2>&1; then
    "${limit[@]}" "${cmd[@]}" | defmt-print -e "$elf" --show-skipped-frames stdin
    status=${PIPESTATUS[0]}
else
    raw="$elf.defmt"
    "${limit[@]}" "${cmd[@]}" > "$raw"
    status=$?
    # Without defmt-print, the host tool's decoder (defmt-decoder inside `walker`) when built.
    walker=$(ls -t target/*/release/walker target/*/debug/walker 2>/dev/null | head -n 1 || true)
    if [ -n "$walker" ] && "$walker" capture --defmt "$raw" --elf "$elf" >/dev/null; then
        cat "$raw.log"
    else
        echo "qemu-run.sh: raw defmt frames saved to $raw; decode them with \`cargo walker capture --defmt $raw --elf $elf\` (or install defmt-print: cargo install defmt-print --version 1.2.0 --locked)" >&2
    fi
fi

if [ "$status" -eq 124 ]; then
    echo "qemu-run.sh: wall-clock timeout after ${timeout_s}s" >&2
fi
exit "$status"
