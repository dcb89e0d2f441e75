#!/usr/bin/env bash
# Installs what scripts/render_walk.py (trajectory -> video) needs on a fresh Debian machine:
#   - Debian packages: ffmpeg (encoder, ffprobe) and the EGL/Mesa software rasteriser
#     (libegl1 libegl-mesa0 libgl1-mesa-dri) for MuJoCo's headless rendering (MUJOCO_GL=egl);
#     installed with apt-get when root, otherwise the one command to run is printed.
#   - a project-local venv .venv-render/ (python3 -m venv, reused if present) holding the PyPI
#     packages mujoco==3.17.0 (same version as the host tools' C library) and numpy.
# The venv carries its own .gitignore ('*'), so git never sees it.
# The LAST line printed on stdout is the venv's python, for callers:
#     py=$(bash scripts/render-setup.sh | tail -n1)
#     "$py" scripts/render_walk.py --model out/x/model.xml --qpos out/x/qpos.csv --out out/x/walk.mp4
# RENDER_VENV=/some/dir overrides the venv location. Everything else goes to stderr.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

apt_pkgs="ffmpeg libegl1 libegl-mesa0 libgl1-mesa-dri"
missing=""
for p in $apt_pkgs; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
# python3 -m venv needs Debian's python3-venv (ensurepip); check it the way venv will use it.
if ! python3 -c 'import ensurepip, venv' >/dev/null 2>&1; then
    missing="$missing python3-venv"
fi
if [ -n "$missing" ]; then
    if [ "$(id -u)" = 0 ]; then
        echo "render-setup: installing Debian packages:$missing" >&2
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq >&2
        # shellcheck disable=SC2086
        apt-get install -y -qq $missing >/dev/null
    else
        echo "render-setup: missing Debian packages:$missing. Run this once, then try again:" >&2
        echo "    sudo apt-get install -y$missing" >&2
        exit 1
    fi
fi

venv=${RENDER_VENV:-.venv-render}
py="$venv/bin/python"
if [ ! -x "$py" ]; then
    echo "render-setup: creating the venv $venv" >&2
    python3 -m venv "$venv" >&2
fi
[ -f "$venv/.gitignore" ] || echo '*' > "$venv/.gitignore"
if ! "$py" -c 'import mujoco, numpy, sys; sys.exit(mujoco.__version__ != "3.17.0")' >/dev/null 2>&1; then
    echo "render-setup: pip install mujoco==3.17.0 numpy into $venv" >&2
    "$py" -m pip install -q --disable-pip-version-check "mujoco==3.17.0" numpy >&2
fi

# Absolute path, last line on stdout.
echo "$(cd "$venv" && pwd)/bin/python"
