#!/usr/bin/env bash
# The official ROBOTIS Dynamixel SDK (PyPI `dynamixel-sdk`) against `walker simulate`:
# installs the SDK and pyserial in a project-local venv (.venv-sdk/, reused when present) and runs
# host/tests/sdk/test_dynamixel_sdk.py, which pings, reads and writes every simulated device.
#
#   scripts/sdk-test.sh [path/to/walker]     (default target/x86_64-unknown-linux-gnu/release/walker)
#   scripts/sdk-test.sh --fil [path/to/walker] [path/to/qemu-elf]
#
# With --fil it runs host/tests/sdk/test_sdk_command_port.py instead: the SDK drives the
# firmware's command port (ID 150) in a firmware-in-the-loop run (`walker fil --command-port`,
# QEMU + the MuJoCo robot; default ELF target/thumbv7em-none-eabihf/release/qemu): identity,
# bad commands rejected with error statuses, walk, read status, stop, torque off.
#
# Needs python3 (3.8+) with pip. Without the venv module's ensurepip (Debian's python3-venv not
# installed), the packages are installed with `pip install --target .venv-sdk/site-packages`
# instead. The last line of the output is `N passed, M failed`; the exit status is non-zero on
# any failure.
set -euo pipefail
TEST=host/tests/sdk/test_dynamixel_sdk.py
if [[ "${1:-}" == --fil ]]; then
    TEST=host/tests/sdk/test_sdk_command_port.py
    shift
fi
# Paths given as arguments are relative to the caller's directory, the defaults to the repo.
args=()
for a in "$@"; do
    if [[ "$a" != /* ]]; then a="$PWD/$a"; fi
    args+=("$a")
done
set -- "${args[@]}"
cd "$(dirname "${BASH_SOURCE[0]}")/.."

WALKER="${1:-$PWD/target/x86_64-unknown-linux-gnu/release/walker}"
if [[ $# -ge 2 ]]; then
    export QEMU_ELF="$2"
fi
PYTHON="${PYTHON:-python3}"
VENV=.venv-sdk
# Versions the test was written against (the test subclasses the SDK's PortHandler).
PACKAGES=(dynamixel-sdk==4.1.0 pyserial==3.5)

if [[ ! -x "$WALKER" ]]; then
    echo "sdk-test: walker binary not found: $WALKER (build it or pass its path)" >&2
    exit 2
fi

py=()
if [[ -x "$VENV/bin/python" ]] && "$VENV/bin/python" -m pip --version >/dev/null 2>&1; then
    py=("$VENV/bin/python")
elif [[ -d "$VENV/site-packages" ]]; then
    py=(env "PYTHONPATH=$PWD/$VENV/site-packages${PYTHONPATH:+:$PYTHONPATH}" "$PYTHON")
else
    rm -rf "$VENV"
    if "$PYTHON" -m venv "$VENV" >/dev/null 2>&1 && "$VENV/bin/python" -m pip --version >/dev/null 2>&1; then
        py=("$VENV/bin/python")
    else
        # No ensurepip: a plain package directory (--target is allowed even in an externally
        # managed, PEP 668, system Python).
        echo "sdk-test: '$PYTHON -m venv' unavailable; installing into $VENV/site-packages" >&2
        rm -rf "$VENV"
        mkdir -p "$VENV/site-packages"
        py=(env "PYTHONPATH=$PWD/$VENV/site-packages${PYTHONPATH:+:$PYTHONPATH}" "$PYTHON")
    fi
    echo '*' >"$VENV/.gitignore"
fi

# pip only when a pinned version is missing (a no-op pip install costs seconds on every run).
installed='import importlib.metadata as m, sys
sys.exit(any(m.version(n) != v for n, v in (a.split("==") for a in sys.argv[1:])))'
if [[ "${py[0]}" == "$VENV/bin/python" ]]; then
    if ! "${py[@]}" -c "$installed" "${PACKAGES[@]}" >/dev/null 2>&1; then
        "${py[@]}" -m pip install --quiet --disable-pip-version-check "${PACKAGES[@]}"
    fi
elif ! "${py[@]}" -c 'import dynamixel_sdk, serial' >/dev/null 2>&1; then
    "$PYTHON" -m pip install --quiet --disable-pip-version-check --upgrade \
        --target "$VENV/site-packages" "${PACKAGES[@]}"
fi

WALKER="$WALKER" exec "${py[@]}" "$TEST"
