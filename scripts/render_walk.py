#!/usr/bin/env python3
"""Renders a recorded MuJoCo trajectory (model.xml + qpos.csv) into a video of the robot walking.

    python3 scripts/render_walk.py --model out/x/model.xml --qpos out/x/qpos.csv --out out/x/walk.mp4 \
        [--fps 30] [--width 640] [--height 480] [--speed 1.0] [--gif]

Run it with the venv made by scripts/render-setup.sh (its last line is that python):
    py=$(bash scripts/render-setup.sh | tail -n1); "$py" scripts/render_walk.py ...

Inputs (written by the host tool next to each run's output):
  model.xml  a self-contained MJCF model: a free-floating biped (free joint on the torso/pelvis,
             hinge joints), a floor plane; primitive geoms only.
  qpos.csv   header `t_s,qpos_0,...,qpos_{nq-1}`, one row per recorded time, MuJoCo qpos order.
             Rows need not be at the video rate: frame k (sim time t0 + k*speed/fps) shows the
             latest row at or before that time.

Rendering is headless with EGL (MUJOCO_GL=egl, Mesa's llvmpipe software rasteriser when there is
no GPU); frames are piped as raw RGB into Debian's ffmpeg (libx264 mp4, or a GIF with --gif).
The camera is a free camera whose look-at point follows the free body (smoothed over --smooth s so
the pelvis sway does not shake the picture), at a 3/4 front-side view relative to the robot's
initial heading; the distance is chosen from the robot's height unless --distance is given.

Exit codes: 0 ok, 1 bad input or encoder failure, 2 a dependency (mujoco, EGL, ffmpeg) missing.
"""

import argparse
import math
import os
import shutil
import subprocess
import sys
import time

# Headless EGL unless the caller chose otherwise; must be set before mujoco is imported.
os.environ.setdefault("MUJOCO_GL", "egl")
if os.environ["MUJOCO_GL"].lower() == "egl":
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

MUJOCO_VERSION = "3.17.0"
SETUP_HINT = "bash scripts/render-setup.sh (or: python3 -m venv .venv-render && " \
             ".venv-render/bin/pip install mujoco==3.17.0 numpy), then run this with .venv-render/bin/python"
EGL_HINT = "apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri"
FFMPEG_HINT = "apt-get install -y ffmpeg"


def missing(what, cmd, detail=None):
    msg = f"render_walk: {what} is missing; install it with: {cmd}"
    if detail:
        msg += f"  ({detail})"
    print(msg, file=sys.stderr)
    sys.exit(2)


def fail(msg):
    print(f"render_walk: {msg}", file=sys.stderr)
    sys.exit(1)


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", required=True, help="MJCF model (model.xml)")
    p.add_argument("--qpos", required=True, help="trajectory CSV: t_s,qpos_0..qpos_{nq-1}")
    p.add_argument("--out", required=True, help="output video (.mp4, or .gif with --gif)")
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--speed", type=float, default=1.0,
                   help="playback speed: 2 = twice as fast as real time, 0.5 = slow motion")
    p.add_argument("--gif", action="store_true", help="write an animated GIF instead of an mp4")
    p.add_argument("--distance", type=float, default=None,
                   help="camera distance in m (default: from the robot's height, ~0.9 m for 0.56 m)")
    p.add_argument("--azimuth", type=float, default=135.0,
                   help="camera azimuth in degrees relative to the robot's initial heading "
                        "(135 = front-right 3/4 view, 90 = right side, 180 = front)")
    p.add_argument("--elevation", type=float, default=-18.0, help="camera elevation in degrees")
    p.add_argument("--smooth", type=float, default=0.8,
                   help="window (s) of the moving average of the tracked x,y (0 = follow exactly)")
    p.add_argument("--camera", default=None,
                   help="render from this camera of the model instead (e.g. a trackcom camera)")
    p.add_argument("--no-shadows", action="store_true",
                   help="about 2x faster on software rendering (no GPU)")
    p.add_argument("--shadow-size", type=int, default=2048,
                   help="upper bound of the shadow map size (the model's default is 4096)")
    p.add_argument("--no-text", action="store_true", help="no time overlay")
    p.add_argument("--crf", type=int, default=20, help="x264 quality (lower = better)")
    p.add_argument("--progress", action="store_true",
                   help="print 'progress K N' on stdout after each frame (for walker's progress bar)")
    a = p.parse_args(argv)
    if a.fps <= 0 or a.speed <= 0:
        p.error("--fps and --speed must be > 0")
    if a.width < 16 or a.height < 16:
        p.error("--width and --height must be >= 16")
    return a


def load_qpos(path, nq):
    import numpy as np
    try:
        with open(path) as f:
            header = f.readline().strip().split(",")
    except OSError as e:
        fail(f"cannot read {path}: {e}")
    if not header or header[0].strip() != "t_s":
        fail(f"{path}: the header must start with t_s, got {header[:3]}")
    if len(header) - 1 != nq:
        fail(f"{path}: {len(header) - 1} qpos columns but the model has nq = {nq}")
    try:
        rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, dtype=np.float64)
    except ValueError as e:
        fail(f"{path}: {e}")
    if rows.shape[0] == 0:
        fail(f"{path}: no rows")
    t = rows[:, 0]
    if np.any(np.diff(t) < 0):
        order = np.argsort(t, kind="stable")
        rows, t = rows[order], t[order]
    if not np.all(np.isfinite(rows)):
        fail(f"{path}: non-finite values")
    return t, rows[:, 1:]


def moving_average(t, x, window):
    """Centred moving average over `window` seconds of samples x(t) (t sorted)."""
    import numpy as np
    if window <= 0 or len(t) < 2:
        return x.copy()
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])
    lo = np.searchsorted(t, t - window / 2, side="left")
    hi = np.searchsorted(t, t + window / 2, side="right")
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def load_model(mujoco, path):
    """Loads the MJCF; adds a gradient skybox if the model has none (else the sky is black)."""
    try:
        spec = mujoco.MjSpec.from_file(path)
        has_sky = any(tex.type == mujoco.mjtTexture.mjTEXTURE_SKYBOX for tex in spec.textures)
        if not has_sky:
            spec.add_texture(name="render_walk_sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                             builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                             rgb1=[0.55, 0.7, 0.9], rgb2=[0.95, 0.97, 1.0],
                             width=256, height=1536)
        return spec.compile()
    except Exception as e:  # fall back to the model as it is
        print(f"render_walk: note: no skybox added ({e})", file=sys.stderr)
    try:
        return mujoco.MjModel.from_xml_path(path)
    except Exception as e:
        fail(f"cannot load {path}: {e}")


def main(argv=None):
    a = parse_args(sys.argv[1:] if argv is None else argv)

    ffmpeg = shutil.which("ffmpeg")
    if not ffmpeg:
        missing("ffmpeg", FFMPEG_HINT)
    import importlib.util
    for pkg in ("numpy", "mujoco"):
        if importlib.util.find_spec(pkg) is None:
            missing(f"the Python package {pkg} (for {sys.executable})", SETUP_HINT)
    gl_backend = os.environ.get("MUJOCO_GL", "").lower()
    import numpy as np
    try:
        import mujoco
    except Exception as e:  # noqa: BLE001
        # A missing libEGL surfaces here (PyOpenGL fails while mujoco loads its GL context).
        if isinstance(e, ModuleNotFoundError) and e.name == "mujoco":
            missing("the mujoco Python package", SETUP_HINT, str(e))
        missing(f"OpenGL/EGL (MUJOCO_GL={gl_backend}: mujoco could not load its GL context)",
                EGL_HINT, f"{type(e).__name__}: {e}")
    if mujoco.__version__ != MUJOCO_VERSION:
        print(f"render_walk: warning: mujoco {mujoco.__version__}, expected {MUJOCO_VERSION}",
              file=sys.stderr)
    if not hasattr(mujoco, "GLContext"):
        detail = None
        if gl_backend == "egl":
            try:
                import mujoco.egl  # noqa: F401  (re-import to get the real error)
            except Exception as e:
                detail = str(e)
        missing(f"OpenGL/EGL (MUJOCO_GL={gl_backend})", EGL_HINT, detail)

    if not os.path.isfile(a.model):
        fail(f"no model file {a.model}")
    model = load_model(mujoco, a.model)
    data = mujoco.MjData(model)
    t, qpos = load_qpos(a.qpos, model.nq)

    # The tracked body: the one carrying the free joint (else the first body below the world).
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    body = int(model.jnt_bodyid[free[0]]) if free else min(1, model.nbody - 1)
    qadr = int(model.jnt_qposadr[free[0]]) if free else None

    # Frame schedule: sim time t0 + k*speed/fps, latest row at or before it.
    t0, t1 = float(t[0]), float(t[-1])
    n_frames = int(math.floor((t1 - t0) / a.speed * a.fps + 1e-9)) + 1
    frame_t = t0 + np.arange(n_frames) * (a.speed / a.fps)
    rows = np.clip(np.searchsorted(t, frame_t + 1e-9, side="right") - 1, 0, len(t) - 1)

    # Robot extent and heading from the first frame.
    data.qpos[:] = qpos[rows[0]]
    mujoco.mj_forward(model, data)
    robot_geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] != 0]
    if robot_geoms:
        zs = [(data.geom_xpos[g][2] - model.geom_rbound[g], data.geom_xpos[g][2] + model.geom_rbound[g])
              for g in robot_geoms]
        floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        floor_z = float(data.geom_xpos[floor][2]) if floor >= 0 else 0.0
        zmin, zmax = max(floor_z, min(z[0] for z in zs)), max(z[1] for z in zs)
    else:
        zmin, zmax = 0.0, 0.5
    height = max(zmax - zmin, 0.1)
    fovy = float(model.vis.global_.fovy)
    distance = a.distance or max(0.3, 0.65 * height / math.tan(math.radians(fovy / 2)))
    mat = data.xmat[body].reshape(3, 3)
    heading = math.degrees(math.atan2(mat[1, 0], mat[0, 0]))  # body x axis in the world plane
    base_z_offset = 0.5 * (zmin + zmax) - float(data.xpos[body][2])

    # Look-at path: the tracked body's x,y (from the free joint's qpos, smoothed), z fixed relative
    # to its mean height so the walking bob does not move the camera.
    if qadr is not None:
        xy = moving_average(t, qpos[:, qadr:qadr + 2], a.smooth)[rows]
        zc = float(np.mean(qpos[:, qadr + 2])) + base_z_offset
    else:
        xy = np.repeat(data.xpos[body][None, :2], n_frames, axis=0)
        zc = 0.5 * (zmin + zmax)

    # Offscreen buffer big enough for the requested size.
    w, h = a.width, a.height
    if not a.gif and (w % 2 or h % 2):
        w, h = w + (w % 2), h + (h % 2)  # yuv420p needs even sizes
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), w)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), h)
    # Software rasterising (llvmpipe) cost: the 4096 shadow map is ~25 ms of a ~80 ms frame at
    # 640x480; 2048 looks the same at this scale and costs about half.
    model.vis.quality.shadowsize = min(int(model.vis.quality.shadowsize), a.shadow_size)

    try:
        gl = mujoco.GLContext(w, h)
        gl.make_current()
    except Exception as e:
        missing(f"a working EGL display (MUJOCO_GL={gl_backend})", EGL_HINT, str(e))
    con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
    mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, con)
    scene = mujoco.MjvScene(model, maxgeom=max(1000, 4 * model.ngeom))
    if a.no_shadows:
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
    opt = mujoco.MjvOption()
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.distance = distance
    cam.azimuth = heading + a.azimuth
    cam.elevation = a.elevation
    if a.camera is not None:
        cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, a.camera)
        if cam_id < 0:
            fail(f"the model has no camera named {a.camera!r}")
        cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        cam.fixedcamid = cam_id
    rect = mujoco.MjrRect(0, 0, w, h)
    rgb = np.empty((h, w, 3), dtype=np.uint8)

    out = a.out
    gif = a.gif or out.lower().endswith(".gif")
    if gif and not out.lower().endswith(".gif"):
        out = os.path.splitext(out)[0] + ".gif"
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    cmd = [ffmpeg, "-y", "-hide_banner", "-loglevel", "error",
           "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}", "-r", f"{a.fps:g}", "-i", "-"]
    if gif:
        cmd += ["-vf", "split[a][b];[a]palettegen=max_colors=128[p];[b][p]paletteuse=dither=bayer",
                "-loop", "0", out]
    else:
        cmd += ["-pix_fmt", "yuv420p", "-c:v", "libx264", "-preset", "veryfast",
                "-crf", str(a.crf), "-movflags", "+faststart", out]
    enc = subprocess.Popen(cmd, stdin=subprocess.PIPE)

    start = time.monotonic()
    try:
        for k in range(n_frames):
            data.qpos[:] = qpos[rows[k]]
            mujoco.mj_forward(model, data)
            cam.lookat[:] = (xy[k, 0], xy[k, 1], zc)  # (ignored by a --camera of the model)
            mujoco.mjv_updateScene(model, data, opt, None, cam, mujoco.mjtCatBit.mjCAT_ALL.value, scene)
            mujoco.mjr_render(rect, scene, con)
            if not a.no_text:
                mujoco.mjr_overlay(mujoco.mjtFont.mjFONT_NORMAL, mujoco.mjtGridPos.mjGRID_TOPLEFT, rect,
                                   f"t = {frame_t[k]:5.2f} s", None, con)
            mujoco.mjr_readPixels(rgb, None, rect, con)
            enc.stdin.write(rgb[::-1].tobytes())  # OpenGL rows are bottom-up
            if a.progress:
                print(f"progress {k + 1} {n_frames}", flush=True)
    except BrokenPipeError:
        pass
    finally:
        try:
            enc.stdin.close()
        except BrokenPipeError:
            pass
        rc = enc.wait()
        con.free()
        gl.free()
    wall = time.monotonic() - start
    if rc != 0:
        fail(f"ffmpeg failed (exit {rc}): {' '.join(cmd)}")
    sim = (n_frames - 1) * a.speed / a.fps
    print(f"render_walk: wrote {out}: {n_frames} frames {w}x{h} @ {a.fps:g} fps "
          f"({sim:.2f} s simulated, speed {a.speed:g}, "
          f"camera {a.camera if a.camera is not None else f'{distance:.2f} m'}) "
          f"in {wall:.1f} s wall ({n_frames / max(wall, 1e-9):.1f} frames/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
