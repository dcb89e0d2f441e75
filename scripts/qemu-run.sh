#!/usr/bin/env bash
# Runs a walker-firmware ELF (board-qemu build) in qemu-system-arm and decodes its defmt output.
# This script is the one definition of the QEMU command line: the bench (scripts/bench.sh), CI
# (scripts/test.sh), cargo's runner and the host's firmware-in-the-loop run (host/src/qemu.rs)
# all start QEMU through it; the machines are the table scripts/qemu-machines.txt.
#
# Usage: scripts/qemu-run.sh ELF [options] [extra qemu args]
#   --bus SPEC       chardev of UART0, the servo bus   (default: $WALKER_BUS or null)
#   --log SPEC       chardev of UART1, the ZMP log     (default: $WALKER_LOG or
#                    file:target/qemu-zmp-log.bin)
#   --lockstep SPEC  chardev of UART2, the lock-step channel; also turns lock-step on in the
#                    firmware (semihosting command line "lockstep") (default: $WALKER_LOCKSTEP;
#                    without it UART2 is null and the bus is unconnected: reads time out)
#   --command SPEC   chardev of UART3, the command port (the firmware as a Dynamixel device)
#                    (default: $WALKER_COMMAND or null)
#   --machine M      a machine of scripts/qemu-machines.txt: mps2-an500 (Cortex-M7),
#                    mps2-an386 (M4F), mps2-an385 (M3) (default: $WALKER_QEMU_MACHINE, else the
#                    table's first machine for the ELF's target directory, e.g.
#                    thumbv7m-none-eabi → an385; a machine that cannot run that target: exit 2)
#   --timeout S      wall-clock limit in seconds (default: $WALKER_QEMU_TIMEOUT or 600; 0 = none)
#   --no-icount      without `-icount shift=0` (1 instruction = 1 virtual ns): for runs that do
#                    not read QEMU's clock, as the lock-step runs (docs/lockstep.md), whose host
#                    time it saves
#   --raw            QEMU's stdout (semihosting) as it is, no defmt decoding; the script execs
#                    QEMU, so the caller's child process is QEMU itself (killing it stops QEMU)
#   --unchecked      skip the command-line length check (to test the firmware's own refusal)
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
# Run-to-run determinism: the firmware's virtual clock (see src/boards/qemu_mps2.rs and
# docs/lockstep.md); -icount shift=0 (1 instruction = 1 virtual ns) unless --no-icount.
set -u

if [ $# -lt 1 ]; then
    echo "usage: $0 ELF [--bus SPEC] [--log SPEC] [--lockstep SPEC] [--command SPEC] [--machine M] [--timeout S] [--no-icount] [--raw] [--unchecked] [qemu args...]" >&2
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
command_port=${WALKER_COMMAND:-null}
machine=${WALKER_QEMU_MACHINE:-}
timeout_s=${WALKER_QEMU_TIMEOUT:-600}
raw=0
icount=(-icount shift=0)
checked=1
extra=()
while [ $# -gt 0 ]; do
    case "$1" in
        --bus) bus=$2; shift 2 ;;
        --log) log=$2; shift 2 ;;
        --lockstep) lockstep=$2; shift 2 ;;
        --command) command_port=$2; shift 2 ;;
        --machine) machine=$2; shift 2 ;;
        --timeout) timeout_s=$2; shift 2 ;;
        --raw) raw=1; shift ;;
        --no-icount) icount=(); shift ;;
        --unchecked) checked=0; shift ;;
        *) extra+=("$1"); shift ;;
    esac
done

# The machine: asked for, else the first of the table that runs the ELF's target (its
# target/<triple>/ directory), else the table's first; refused when the table says it cannot run
# that target.
table=$(dirname "$0")/qemu-machines.txt
elf_target=
first=
default=
while read -r m _core targets; do
    case "$m" in '#'*|'') continue ;; esac
    [ -z "$first" ] && first=$m
    for t in ${targets//,/ }; do
        if [[ "$elf" == *"/$t/"* ]]; then
            elf_target=$t
            [ -z "$default" ] && default=$m
        fi
    done
done < "$table"
machine=${machine:-${default:-$first}}
row=$(grep "^$machine " "$table" || true)
if [ -z "$row" ]; then
    echo "qemu-run.sh: unknown machine $machine (the machines are in $table)" >&2
    exit 2
fi
if [ -n "$elf_target" ] && [[ ",$(echo "$row" | awk '{print $3}')," != *",$elf_target,"* ]]; then
    echo "qemu-run.sh: $machine does not run $elf_target ELFs (see $table)" >&2
    exit 2
fi

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
    -serial "$bus" -serial "$log" -serial "$lockstep" -serial "$command_port"
    -semihosting-config enable=on,target=native
    "${icount[@]}"
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
if [ "$checked" = 1 ] && [ -n "$text" ] && [ "$need" -gt "$cmdline_max" ]; then
    echo "qemu-run.sh: the firmware command line is $need bytes (ELF path + space + -append text + NUL), over the firmware's $cmdline_max-byte semihosting buffer" >&2
    exit 2
fi

limit=()
if [ "$timeout_s" != "0" ] && command -v timeout >/dev/null 2>&1; then
    limit=(timeout --foreground "$timeout_s")
fi

if [ "$raw" = 1 ]; then
    exec "${limit[@]}" "${cmd[@]}"
elif command -v defmt-print >/dev/null 2>&1; then
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
