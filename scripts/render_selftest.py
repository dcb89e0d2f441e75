#!/usr/bin/env python3
"""Self-test of scripts/render_walk.py without the Rust host tool.

Builds a small biped MJCF (pelvis box on a free joint at z ~ 0.25 m, two legs of hip yaw/roll/pitch,
knee, ankle pitch/roll hinges with 0.1 m capsule links, 0.1 x 0.06 x 0.02 m sole boxes, a checker
floor plane named `floor`, two low box steps, a light), writes model.xml and a qpos.csv of a
made-up 3 s stepping motion sampled at 200 Hz, runs render_walk.py on it (mp4 at 30 fps, and a
small GIF), checks the outputs with ffprobe (frame count within +-2) and extracts frame 30 as a PNG.

    py=$(bash scripts/render-setup.sh | tail -n1)
    "$py" scripts/render_selftest.py [--out-dir out/render-selftest]

Prints 'N passed, N failed' and exits non-zero on any failure (2 when a dependency is missing).
"""

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

DURATION_S = 3.0
RATE_HZ = 200.0


def leg_xml(side, y):
    """One leg: hip yaw/roll/pitch at the pelvis bottom, 0.1 m thigh and shin, ankle pitch/roll."""
    s = side[0]
    return f"""
      <body name="{side}_hip" pos="0 {y} -0.03">
        <joint name="{s}_hip_yaw" axis="0 0 1" range="-0.6 0.6"/>
        <joint name="{s}_hip_roll" axis="1 0 0" range="-0.6 0.6"/>
        <joint name="{s}_hip_pitch" axis="0 1 0" range="-1.5 1.5"/>
        <geom type="sphere" size="0.018" material="joint"/>
        <geom name="{s}_thigh" type="capsule" fromto="0 0 0 0 0 -0.1" size="0.016" material="link"/>
        <body name="{side}_shin" pos="0 0 -0.1">
          <joint name="{s}_knee" axis="0 1 0" range="-0.1 2.4"/>
          <geom type="sphere" size="0.017" material="joint"/>
          <geom name="{s}_shin" type="capsule" fromto="0 0 0 0 0 -0.1" size="0.015" material="link"/>
          <body name="{side}_foot" pos="0 0 -0.1">
            <joint name="{s}_ankle_pitch" axis="0 1 0" range="-1.2 1.2"/>
            <joint name="{s}_ankle_roll" axis="1 0 0" range="-0.6 0.6"/>
            <geom name="{s}_sole" type="box" pos="0.01 0 -0.01" size="0.05 0.03 0.01" material="sole"/>
          </body>
        </body>
      </body>"""


def model_xml():
    return f"""<mujoco model="selftest_biped">
  <compiler angle="radian"/>
  <option timestep="0.005"/>
  <visual>
    <headlight ambient="0.3 0.3 0.3" diffuse="0.4 0.4 0.4" specular="0.1 0.1 0.1"/>
    <global offwidth="1280" offheight="960"/>
  </visual>
  <asset>
    <texture name="grid" type="2d" builtin="checker" rgb1="0.82 0.82 0.8" rgb2="0.62 0.64 0.66"
             width="512" height="512" mark="edge" markrgb="0.4 0.4 0.4"/>
    <material name="grid" texture="grid" texrepeat="32 32" reflectance="0.05"/>
    <material name="link" rgba="0.25 0.35 0.55 1"/>
    <material name="joint" rgba="0.15 0.15 0.15 1"/>
    <material name="sole" rgba="0.85 0.45 0.15 1"/>
    <material name="body" rgba="0.85 0.85 0.88 1"/>
    <material name="step" rgba="0.55 0.5 0.45 1"/>
  </asset>
  <worldbody>
    <light name="sun" pos="0.5 -1 3" dir="-0.2 0.4 -1" directional="true" diffuse="0.7 0.7 0.7"
           castshadow="true"/>
    <geom name="floor" type="plane" size="4 4 0.05" material="grid"/>
    <geom name="step1" type="box" pos="0.45 0.06 0.01" size="0.08 0.15 0.01" material="step"/>
    <geom name="step2" type="box" pos="0.61 0.06 0.02" size="0.08 0.15 0.02" material="step"/>
    <body name="pelvis" pos="0 0 0.25">
      <freejoint name="root"/>
      <geom name="pelvis" type="box" size="0.04 0.07 0.03" material="body"/>
      <geom name="torso" type="box" pos="0 0 0.12" size="0.045 0.08 0.09" material="body"/>
      <geom name="head" type="sphere" pos="0 0 0.26" size="0.045" material="body"/>
      <geom name="eye" type="box" pos="0.04 0 0.27" size="0.01 0.03 0.008" material="joint"/>
      {leg_xml("left", 0.045)}
      {leg_xml("right", -0.045)}
    </body>
  </worldbody>
</mujoco>
"""


def stepping_qpos(t):
    """Made-up stepping gait: 1 s cycle (two 0.5 s steps), 0.1 m/s forward, lateral sway."""
    phi = 2 * math.pi * t
    ramp = min(1.0, t / 0.5)  # start from standing
    x = 0.1 * t
    y = 0.02 * ramp * math.sin(phi)
    lift_l = ramp * max(0.0, math.sin(phi))
    lift_r = ramp * max(0.0, -math.sin(phi))
    z = 0.245 - 0.01 * ramp
    q = [x, y, z, 1.0, 0.0, 0.0, 0.0]
    for lift, sgn in ((lift_l, 1.0), (lift_r, -1.0)):
        stride = 0.25 * ramp * sgn * math.cos(phi)  # hip swings fore/aft, legs opposite
        hip_pitch = -0.25 - 0.45 * lift - stride
        knee = 0.5 + 0.9 * lift
        ankle_pitch = -(hip_pitch + knee)  # keep the sole level
        hip_roll = -y / 0.2  # legs stay under the hips while the pelvis sways
        q += [0.0, hip_roll, hip_pitch, knee, ankle_pitch, -hip_roll]
    return q


def write_fixture(out_dir):
    os.makedirs(out_dir, exist_ok=True)
    model = os.path.join(out_dir, "model.xml")
    qpos = os.path.join(out_dir, "qpos.csv")
    with open(model, "w") as f:
        f.write(model_xml())
    n = int(round(DURATION_S * RATE_HZ)) + 1
    nq = len(stepping_qpos(0.0))
    with open(qpos, "w") as f:
        f.write("t_s," + ",".join(f"qpos_{i}" for i in range(nq)) + "\n")
        for k in range(n):
            t = k / RATE_HZ
            f.write(f"{t:.4f}," + ",".join(f"{v:.6f}" for v in stepping_qpos(t)) + "\n")
    return model, qpos, nq


def ffprobe_frames(path):
    r = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0",
                        "-show_entries", "stream=nb_read_frames,width,height", "-of", "json", path],
                       capture_output=True, text=True)
    if r.returncode != 0:
        return None
    s = json.loads(r.stdout)["streams"][0]
    return int(s["nb_read_frames"]), int(s["width"]), int(s["height"])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out-dir", default=os.path.join(ROOT, "out", "render-selftest"))
    ap.add_argument("--fps", type=float, default=30.0)
    a = ap.parse_args()

    for tool in ("ffmpeg", "ffprobe"):
        if not shutil.which(tool):
            print(f"render_selftest: {tool} is missing; install it with: apt-get install -y ffmpeg")
            return 2

    passed, failed = 0, 0

    def check(ok, what):
        nonlocal passed, failed
        print(f"{'ok  ' if ok else 'FAIL'} {what}")
        if ok:
            passed += 1
        else:
            failed += 1

    model, qpos, nq = write_fixture(a.out_dir)
    print(f"render_selftest: fixture {model} (nq = {nq}), {qpos} ({DURATION_S:g} s at {RATE_HZ:g} Hz)")

    # The model loads and its nq matches the CSV (when mujoco is importable here).
    try:
        import mujoco
        m = mujoco.MjModel.from_xml_path(model)
        check(m.nq == nq and m.njnt == 13, f"model loads: nq = {m.nq}, njnt = {m.njnt}")
    except ImportError:
        pass

    renderer = os.path.join(HERE, "render_walk.py")
    mp4 = os.path.join(a.out_dir, "walk.mp4")
    for stale in (mp4,):
        if os.path.exists(stale):
            os.remove(stale)
    cmd = [sys.executable, renderer, "--model", model, "--qpos", qpos, "--out", mp4,
           "--fps", f"{a.fps:g}", "--width", "640", "--height", "480"]
    print("render_selftest: $ " + " ".join(cmd))
    t0 = time.monotonic()
    r = subprocess.run(cmd)
    wall = time.monotonic() - t0
    if r.returncode == 2:
        print("render_selftest: a dependency is missing (see above)")
        return 2
    check(r.returncode == 0, f"render_walk.py exit {r.returncode} ({wall:.1f} s wall)")
    expected = int(math.floor(DURATION_S * a.fps + 1e-9)) + 1
    ok_file = os.path.isfile(mp4) and os.path.getsize(mp4) > 0
    check(ok_file, f"{mp4} exists, {os.path.getsize(mp4) if ok_file else 0} bytes")
    probe = ffprobe_frames(mp4) if ok_file else None
    check(probe is not None and abs(probe[0] - expected) <= 2 and probe[1:] == (640, 480),
          f"ffprobe: {probe} (frames, width, height), expected {expected} frames of 640x480")

    png = os.path.join(a.out_dir, "frame30.png")
    if ok_file:
        r = subprocess.run(["ffmpeg", "-y", "-v", "error", "-i", mp4, "-vf", r"select=eq(n\,30)",
                            "-vframes", "1", png])
        check(r.returncode == 0 and os.path.isfile(png), f"frame 30 extracted: {png}")

    # GIF path, small and at double speed: 1.5 s of video at 15 fps.
    gif = os.path.join(a.out_dir, "walk.gif")
    cmd = [sys.executable, renderer, "--model", model, "--qpos", qpos, "--out", gif, "--gif",
           "--fps", "15", "--speed", "2", "--width", "320", "--height", "240", "--progress"]
    print("render_selftest: $ " + " ".join(cmd))
    r = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)
    check(r.returncode == 0, f"render_walk.py --gif exit {r.returncode}")
    probe = ffprobe_frames(gif) if os.path.isfile(gif) else None
    expected_gif = int(math.floor(DURATION_S / 2 * 15 + 1e-9)) + 1
    # --progress: one 'progress K N' line per frame (walker's progress bar reads them).
    marks = [line.split() for line in r.stdout.splitlines() if line.startswith("progress ")]
    check(len(marks) == expected_gif and marks[-1] == ["progress", str(expected_gif), str(expected_gif)],
          f"--progress: {len(marks)} lines, the last {marks[-1] if marks else None}")
    check(probe is not None and abs(probe[0] - expected_gif) <= 2,
          f"gif ffprobe: {probe}, expected {expected_gif} frames of 320x240")

    # A CSV that does not match the model is refused with exit 1.
    bad = os.path.join(a.out_dir, "qpos_bad.csv")
    with open(bad, "w") as f:
        f.write("t_s,qpos_0,qpos_1\n0,0,0\n")
    r = subprocess.run([sys.executable, renderer, "--model", model, "--qpos", bad,
                        "--out", os.path.join(a.out_dir, "bad.mp4")], capture_output=True, text=True)
    check(r.returncode == 1 and "nq" in r.stderr, f"mismatched CSV refused: exit {r.returncode}")

    print(f"{passed} passed, {failed} failed")
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
