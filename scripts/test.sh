#!/usr/bin/env bash
# Runs every check of the project: format, clippy (host and target), host tests, firmware builds
# for both boards, on-target tests in QEMU and the firmware-in-the-loop walks.
#
#   bash scripts/test.sh          every check; of the firmware-in-the-loop walks, all but the slow
#                                 full-walk suite (`slow` below)
#   bash scripts/test.sh --full   every check and every walk (CI: .ci/run)
#
# Host tools and the firmware-in-the-loop tests run in the dev profile the host tests build,
# with the same --workspace feature set (the release profile, fat LTO, is the firmware's: a
# second build of the host crates in it took ≈ 10 minutes on 2 cores). CARGO_TARGET_DIR is
# honoured.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
full=0
for a in "$@"; do
    case $a in
        --full) full=1 ;;
        *) echo "usage: $0 [--full]" >&2; exit 2 ;;
    esac
done
source scripts/setup.sh
target=${CARGO_TARGET_DIR:-target}
host_bin="$target/$(rustc -vV | sed -n 's/^host: //p')/debug"

# Each step prints the wall time of the one before it, and the total at the end.
last=$SECONDS
step() {
    printf '\n(%ds)\n== %s\n' $((SECONDS - last)) "$*"
    last=$SECONDS
}

# Host-target cargo with clippy: clippy-driver is the workspace crates' compiler, as `cargo clippy`
# runs it (its lints, -D warnings), but compiling them for real, so that the dependencies are
# compiled once for the tests rather than also checked for a separate clippy run. Every host
# cargo call below goes through it: the same compiler for the same crates, no rebuild between
# the steps.
clippy_driver="$(rustc --print sysroot)/bin/clippy-driver"
if [ ! -x "$clippy_driver" ]; then
    echo "clippy-driver not found at $clippy_driver (rustup component add clippy)" >&2
    exit 1
fi
host_cargo() {
    RUSTC_WORKSPACE_WRAPPER="$clippy_driver" \
        CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__" cargo "$@"
}

step "cargo fmt --check"
cargo fmt --all --check

step "clippy (thumbv7em-none-eabihf, no_std crates)"
cargo clippy -p gait-core -p dxl -p walker-contract -- -D warnings
cargo clippy -p gait-core --features fixed-engine -- -D warnings
# As the OpenCM 9.04 build has it: without the Fourier CoM.
cargo clippy -p gait-core --no-default-features --features fixed-engine -- -D warnings

step "clippy (host: every workspace crate and target, as compiled for the tests) and host tests"
host_cargo test --target host-tuple --workspace --all-targets --no-run
host_cargo test --target host-tuple --workspace
# gait-core as the OpenCM 9.04 build has it (no Fourier CoM): that method refused.
host_cargo test --target host-tuple -p gait-core --no-default-features --lib without_fourier_com
# The control loop with the fixed-point path (`math=fixed`, feature fixed-gait) against f32.
host_cargo test --target host-tuple -p walker-firmware --features fixed-gait --lib -- control::tests::fixed control::stage_tests::the_fixed_path

step "Dynamixel codec: 10^7 random, mutated and junk-interleaved byte streams (one shard per core)"
# The test build of the step before (no release build of the test's dependencies just for it).
DXL_FUZZ_CASES=10000000 host_cargo test --target host-tuple -p dxl --test props fuzz_streams

step "firmware: clippy and release builds for all boards"
cargo clippy --release --no-deps --no-default-features --features board-qemu,fake-robot --bins -- -D warnings
cargo clippy --release --no-deps --no-default-features --features board-opencr --bins -- -D warnings
# The fixed-point gait (`math=fixed`) is a build feature (≈ 17 KB of flash): its ELF is kept as
# qemu-fixed for the firmware-in-the-loop test, then the default ELF is built.
cargo clippy --release --no-deps --no-default-features --features board-qemu,fixed-gait --bins -- -D warnings
cargo build --release --no-default-features --features board-qemu,fixed-gait --bin qemu
cp "$target/thumbv7em-none-eabihf/release/qemu" "$target/thumbv7em-none-eabihf/release/qemu-fixed"
cargo build --release --no-default-features --features board-qemu --bin qemu
# The OpenCR image for ROBOTIS' USB bootloader (`walker flash`): sector 5 only, kept as opencr-boot.
cargo build --release --no-default-features --features board-opencr,opencr-bootloader --bin opencr
cp "$target/thumbv7em-none-eabihf/release/opencr" "$target/thumbv7em-none-eabihf/release/opencr-boot"
# The same image for a ROBOTIS OP3's OpenCR (the OP3's description as the build's robot).
cargo clippy --release --no-deps --no-default-features --features robot-op3,opencr-bootloader --bins -- -D warnings
cargo build --release --no-default-features --features robot-op3,opencr-bootloader --bin opencr
cp "$target/thumbv7em-none-eabihf/release/opencr" "$target/thumbv7em-none-eabihf/release/opencr-op3-boot"
cargo build --release --no-default-features --features board-opencr --bin opencr
# The FPU-less Cortex-M3 builds (fixed-point path, size-oriented profile release-m3): the
# ROBOTIS OpenCM 9.04 and the QEMU board for mps2-an385 (firmware-in-the-loop on the M3).
m3=(--profile release-m3 --target thumbv7m-none-eabi --no-default-features)
cargo clippy "${m3[@]}" --no-deps --features board-opencm --bins -- -D warnings
cargo build "${m3[@]}" --features board-opencm --bin opencm
cargo clippy "${m3[@]}" --no-deps --features board-qemu,fixed-gait --bins -- -D warnings
cargo build "${m3[@]}" --features board-qemu,fixed-gait --bin qemu

step "firmware sizes: flash and static RAM of every board build (the FPU-less M3 board, OpenCM 9.04: ≤ 112 KiB flash, ≤ 16 KiB RAM; the OpenCR image for its bootloader ≤ 256 KiB)"
python3 scripts/sizes.py \
    "$target/thumbv7em-none-eabihf/release/qemu" \
    "$target/thumbv7em-none-eabihf/release/qemu-fixed" \
    "$target/thumbv7em-none-eabihf/release/opencr" \
    --limit 256:320 "$target/thumbv7em-none-eabihf/release/opencr-boot" \
    --limit 256:320 "$target/thumbv7em-none-eabihf/release/opencr-op3-boot" \
    "$target/thumbv7m-none-eabi/release-m3/qemu" \
    --limit 112:16 "$target/thumbv7m-none-eabi/release-m3/opencm"
# The limit check itself must be able to fail: the qemu ELF is far over 1 KiB of flash.
if python3 scripts/sizes.py --limit 1:16 "$target/thumbv7em-none-eabihf/release/qemu" >/dev/null; then
    echo "scripts/sizes.py did not flag an ELF over its limit" >&2
    exit 1
fi

step "firmware RAM: the OpenCM 9.04's worst-case stack plus static RAM within its 20 KiB (call graph of the ELF)"
python3 scripts/stack-depth.py --ram 20 --top 5 "$target/thumbv7m-none-eabi/release-m3/opencm"
python3 scripts/stack-depth.py --top 0 "$target/thumbv7em-none-eabihf/release/opencr"
# The check must be able to fail: no build fits 1 KiB.
if python3 scripts/stack-depth.py --ram 1 --top 0 "$target/thumbv7m-none-eabi/release-m3/opencm" >/dev/null; then
    echo "scripts/stack-depth.py did not flag a build over its RAM" >&2
    exit 1
fi

step "firmware: on-target tests in QEMU (mps2-an500, Cortex-M7)"
CARGO_TARGET_THUMBV7EM_NONE_EABIHF_RUNNER=scripts/qemu-run.sh \
    cargo test --release --no-default-features --features board-qemu --test on_target

step "firmware: boots in QEMU without a robot and reports every device missing (exit 11)"
code=0
scripts/qemu-run.sh "$target/thumbv7em-none-eabihf/release/qemu" --timeout 120 || code=$?
if [ "$code" != 11 ]; then
    echo "expected exit code 11 (device missing at start-up), got $code" >&2
    exit 1
fi

step "firmware: a command line over its 1024-byte semihosting buffer is refused (script: before QEMU; firmware: exit 2, not defaults)"
long=$(printf 'stop_at=1 %.0s' $(seq 110))
code=0
scripts/qemu-run.sh "$target/thumbv7em-none-eabihf/release/qemu" --timeout 60 -append "$long" || code=$?
if [ "$code" != 2 ]; then
    echo "qemu-run.sh: expected exit 2 for an over-long command line, got $code" >&2
    exit 1
fi
code=0
scripts/qemu-run.sh "$target/thumbv7em-none-eabihf/release/qemu" --raw --unchecked --timeout 60 \
    --log null -append "$long" >/dev/null || code=$?
if [ "$code" != 2 ]; then
    echo "firmware: expected exit 2 (configuration rejected) for a refused command line, got $code" >&2
    exit 1
fi

step "the official ROBOTIS dynamixel-sdk (PyPI) reads and writes every simulated device"
# The dev-profile `walker` that `cargo test --workspace` built above (for host/tests/cli.rs). No
# cargo call for it here: `-p walker-host` alone unifies the dependencies' features differently
# and would build them again.
bash scripts/sdk-test.sh "$host_bin/walker"

step "the official dynamixel-sdk drives the firmware's command port in a firmware-in-the-loop run (walk, read status, stop; bad commands rejected with error statuses; README's example script)"
bash scripts/sdk-test.sh --fil "$host_bin/walker" "$target/thumbv7em-none-eabihf/release/qemu"

step "video: MuJoCo renders a walk headless (EGL) into an MP4"
render_py=$(bash scripts/render-setup.sh | tail -n 1)
"$render_py" scripts/render_selftest.py

# The firmware-in-the-loop walks (host/tests/fil.rs): each a QEMU process and a simulation in
# lock-step on virtual time, so that their figures do not depend on the host's load; they run
# side by side, WALKER_FIL_JOBS at a time (default: the cores), the longest first. `slow`: the
# full-walk suite, run with --full (CI): the 1 kHz walks (five times the ticks a second of a
# 200 Hz one), the M3 fixed-point Table 2 against the M7's, the Fourier CoM walks, the idealised
# goal walks and the MCAP export; the everyday walks cover the same firmware paths on shorter or
# fewer walks.
slow=(
    four_steps_at_1_khz_and_4_5_mbps_have_no_overrun_on_the_m7
    four_steps_at_1_khz_and_4_5_mbps_have_no_overrun_on_the_m3_fixed_point
    m3_fixed_point_walks_table2_and_agrees_with_the_m7_f32_walk
    fourier_com_walks_on_the_mujoco_robot
    compensation_and_feedback_meet_the_goal_under_xm430_limits_in_the_idealised_model
    table2_mcap_is_foxglove_ready_and_at_most_5_mb
)
fil_args=(--ignored --test-threads 64)
if [ "$full" = 1 ]; then
    what="every walk"
else
    what="all but the slow full-walk suite (${#slow[@]} tests, run by: bash scripts/test.sh --full)"
    for t in "${slow[@]}"; do fil_args+=(--skip "$t"); done
fi
step "firmware in the loop: walks in QEMU against the MuJoCo robot (determinism, faults, falls, pushes, a 14-step walk with its video, walking on command, the Cortex-M3 fixed-point walk on mps2-an385, 1 kHz at 4.5 Mbps): $what"
WALKER_QEMU_ELF="$target/thumbv7em-none-eabihf/release/qemu" \
WALKER_QEMU_FIXED_ELF="$target/thumbv7em-none-eabihf/release/qemu-fixed" \
WALKER_QEMU_M3_ELF="$target/thumbv7m-none-eabi/release-m3/qemu" \
    host_cargo test --target host-tuple --workspace --test fil -- "${fil_args[@]}"

printf '\n(%ds)\nall checks passed in %dm%02ds\n' $((SECONDS - last)) $((SECONDS / 60)) $((SECONDS % 60))
