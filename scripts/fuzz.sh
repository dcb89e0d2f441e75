#!/usr/bin/env bash
# The Dynamixel decoder's fuzz benchmark: CASES (default 10^8) random, mutated and
# junk-interleaved byte streams (truncated and corrupted packets between intact ones) through
# `dxl::Decoder`; every intact packet must come out (dxl/tests/props.rs `fuzz_streams`).
# CI runs 10^7 of them (scripts/test.sh); this runs the full 10^8 (≈ 9 min on one core here).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/setup.sh
cases=${1:-100000000}
time DXL_FUZZ_CASES="$cases" cargo test --release --target host-tuple -p dxl --test props fuzz_streams
