#!/usr/bin/env python3
"""The official ROBOTIS Dynamixel SDK (PyPI `dynamixel-sdk`) against `walker simulate`.

Standalone script (no pytest): starts `walker simulate --port PORT` (free-running, one
connection), connects with the SDK over TCP using Protocol 2.0 and exercises every device on
the simulated bus: the 12 XM430-W350 servos (IDs 1-12), the two foot force-sensor boards
(111, 112) and the IMU board (200). Every check prints one `ok` / `FAIL` line; the last line is
`N passed, M failed` and the exit status is non-zero when anything failed.

Run it through `scripts/sdk-test.sh [path/to/walker]`, which installs the SDK in a venv, or
directly with `WALKER=path/to/walker python3 host/tests/sdk/test_dynamixel_sdk.py`.
WALKER defaults to target/x86_64-unknown-linux-gnu/release/walker (relative to the repo root).

How the SDK reaches a TCP socket: through host/examples/sdk_drive.py's SocketPortHandler (a
PortHandler on pyserial's socket:// URL, TCP_NODELAY, a margin over the SDK's packet timeout for
a simulator that answers when its physics has caught up; see its docstring).
"""

import os
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
from sdk_drive import SocketPortHandler, s16  # noqa: E402 (the TCP port handler: see its doc)

from dynamixel_sdk import (  # noqa: E402
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupBulkRead,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
)

REPO = Path(__file__).resolve().parents[3]
DEFAULT_WALKER = "target/x86_64-unknown-linux-gnu/release/walker"

# Bus IDs and model numbers (dxl/src/table.rs).
SERVOS = list(range(1, 13))
FOOT_IDS = [111, 112]
IMU_ID = 200
MODEL_XM430_W350 = 1020
MODEL_FOOT = 0x5A11
MODEL_IMU = 0x5A20
EXPECTED_MODEL = {**{i: MODEL_XM430_W350 for i in SERVOS},
                  **{i: MODEL_FOOT for i in FOOT_IDS}, IMU_ID: MODEL_IMU}

# X-series control table.
ADDR_MODEL = 0
ADDR_RETURN_DELAY = 9
ADDR_TORQUE_ENABLE = 64
ADDR_GOAL_POSITION = 116
ADDR_PRESENT_CURRENT = 126
ADDR_PRESENT_VELOCITY = 128
ADDR_PRESENT_POSITION = 132
# Sensor boards: SAMPLE block at 128.
ADDR_SAMPLE = 128
FOOT_SAMPLE_LEN = 18  # 4 x i32 mN + u16 counter
IMU_SAMPLE_LEN = 26  # 3 x i32 urad/s + 3 x i32 um/s^2 + u16 counter

# Protocol 2.0 status error codes (the SDK's ERRNUM_*).
ERR_DATA_RANGE = 4
ERR_DATA_LIMIT = 6
ERR_ACCESS = 7

ROBOT_WEIGHT_N = 4.95 * 9.81
G = 9.81

# Goal offsets (ticks) for a small balanced move from the straight-leg start pose: a shallow
# crouch (hip pitch -d, knee +2d, ankle pitch -d keeps the torso upright and the soles flat).
# Hip yaw and roll keep their goals: with both soles planted (the MuJoCo robot has friction),
# twisting or rolling the hips is resisted by the floor, as on the real robot.
D = 40
LEG_DELTA = {"left": [0, 0, -D, +2 * D, -D, 0],
             "right": [0, 0, -D, +2 * D, -D, 0]}
GOAL_DELTA = dict(zip(SERVOS, LEG_DELTA["left"] + LEG_DELTA["right"]))
RAMP_S = 0.3
class Checks:
    def __init__(self):
        self.passed = 0
        self.failed = 0

    def check(self, name, ok, detail=""):
        if ok:
            self.passed += 1
        else:
            self.failed += 1
        print(f"{'ok  ' if ok else 'FAIL'} {name}" + (f"  ({detail})" if detail else ""), flush=True)
        return ok


def s32(v):
    return struct.unpack("<i", struct.pack("<I", v & 0xFFFFFFFF))[0]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def walker_path():
    w = os.environ.get("WALKER")
    return Path(w).resolve() if w else REPO / DEFAULT_WALKER


class Background:
    """A walker command in the background on a free TCP port (self.port); its stdout and stderr
    collected by threads into self.out / self.err."""

    def __init__(self, args, cwd=None):
        self.port = free_port()
        self.proc = subprocess.Popen([str(a).replace("{port}", str(self.port)) for a in args],
                                     cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True)
        self.out, self.err = [], []
        for stream, sink in ((self.proc.stdout, self.out), (self.proc.stderr, self.err)):
            threading.Thread(target=lambda s=stream, k=sink: k.extend(s), daemon=True).start()

    def wait_exit(self, timeout):
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def kill(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)


class Simulator(Background):
    """`walker simulate --port PORT` in the background."""

    def __init__(self, walker):
        super().__init__([walker, "simulate", "--port", "{port}", "--timeout", "30"])

    def wait_listening(self, timeout=15.0):
        """Waits for the 'simulated robot on 127.0.0.1:PORT' banner (printed once the socket is
        bound). Probing with a connect() would consume the simulator's only connection."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if any("simulated robot on" in line for line in self.err):
                return True
            if self.proc.poll() is not None:
                return False
            time.sleep(0.02)
        return False

def bulk_read_sensors(port, ph):
    """One BULK READ of the three sensor boards; returns ({id: (forces_mN, counter)}, imu) or a
    string describing the failure. Values decoded through the SDK's getData()."""
    br = GroupBulkRead(port, ph)
    for i in FOOT_IDS:
        br.addParam(i, ADDR_SAMPLE, FOOT_SAMPLE_LEN)
    br.addParam(IMU_ID, ADDR_SAMPLE, IMU_SAMPLE_LEN)
    r = br.txRxPacket()
    if r != COMM_SUCCESS:
        return f"bulk read: {ph.getTxRxResult(r)}"
    feet = {}
    for i in FOOT_IDS:
        if not br.isAvailable(i, ADDR_SAMPLE, FOOT_SAMPLE_LEN):
            return f"bulk read: no data from {i}"
        forces = [s32(br.getData(i, ADDR_SAMPLE + 4 * k, 4)) for k in range(4)]
        feet[i] = (forces, br.getData(i, ADDR_SAMPLE + 16, 2))
    if not br.isAvailable(IMU_ID, ADDR_SAMPLE, IMU_SAMPLE_LEN):
        return "bulk read: no data from the IMU"
    gyro = [s32(br.getData(IMU_ID, ADDR_SAMPLE + 4 * k, 4)) for k in range(3)]
    accel = [s32(br.getData(IMU_ID, ADDR_SAMPLE + 12 + 4 * k, 4)) for k in range(3)]
    imu = (gyro, accel, br.getData(IMU_ID, ADDR_SAMPLE + 24, 2))
    return feet, imu


def sensors_standing(c, label, sample):
    """Plausibility of one sensor sample of the standing robot."""
    if isinstance(sample, str):
        c.check(f"{label}: sensor bulk read", False, sample)
        return
    feet, (gyro, accel, _) = sample
    per_foot = {i: sum(f) / 1000.0 for i, (f, _) in feet.items()}
    total = sum(per_foot.values())
    c.check(f"{label}: total foot force {total:.1f} N ~ weight {ROBOT_WEIGHT_N:.1f} N (+-30%)",
            abs(total - ROBOT_WEIGHT_N) <= 0.3 * ROBOT_WEIGHT_N,
            ", ".join(f"{i}: {v:.2f} N" for i, v in per_foot.items()))
    a = [v * 1e-6 for v in accel]
    w = [v * 1e-6 for v in gyro]
    c.check(f"{label}: IMU accel z {a[2]:.2f} m/s^2 ~ +{G} (+-20%)",
            abs(a[2] - G) <= 0.2 * G, f"accel {[round(x, 3) for x in a]} m/s^2")
    c.check(f"{label}: IMU at rest (|gyro| < 0.5 rad/s, |accel x,y| < 2 m/s^2)",
            max(abs(x) for x in w) < 0.5 and max(abs(a[0]), abs(a[1])) < 2.0,
            f"gyro {[round(x, 4) for x in w]} rad/s")


def sync_read_state(port, ph):
    """SYNC READ of Present Current..Present Position (126..135) of all servos:
    {id: (current, velocity, position)} or an error string."""
    sr = GroupSyncRead(port, ph, ADDR_PRESENT_CURRENT, 10)
    for i in SERVOS:
        sr.addParam(i)
    r = sr.txRxPacket()
    if r != COMM_SUCCESS:
        return ph.getTxRxResult(r)
    out = {}
    for i in SERVOS:
        if not sr.isAvailable(i, ADDR_PRESENT_CURRENT, 10):
            return f"no data from servo {i}"
        out[i] = (s16(sr.getData(i, ADDR_PRESENT_CURRENT, 2)),
                  s32(sr.getData(i, ADDR_PRESENT_VELOCITY, 4)),
                  s32(sr.getData(i, ADDR_PRESENT_POSITION, 4)))
    return out


def check_written(c, port, ph, dev, addr, value, what):
    """Writes the byte `value` at `addr` of device `dev` and reads it back: both succeed."""
    r, err = ph.write1ByteTxRx(port, dev, addr, value)
    got, r2, err2 = ph.read1ByteTxRx(port, dev, addr)
    c.check(f"{what} {value}, read back {got}",
            r == COMM_SUCCESS and err == 0 and r2 == COMM_SUCCESS and err2 == 0 and got == value,
            f"write {ph.getTxRxResult(r)}/error {err}, read {ph.getTxRxResult(r2)}/error {err2}")


def check_refused(c, port, ph, dev, write, addr, value, want, what):
    """`write` of `value` at `addr` of device `dev`: answered with the error status `want`."""
    r, err = write(port, dev, addr, value)
    c.check(f"{what}", r == COMM_SUCCESS and err == want,
            f"{ph.getTxRxResult(r)}, error {err} {ph.getRxPacketError(err) if err else ''}")


def run(c, port, ph, sim):
    # --- PING -----------------------------------------------------------------------------
    for i in sorted(EXPECTED_MODEL):
        model, r, err = ph.ping(port, i)
        c.check(f"ping {i}: model {model} (expect {EXPECTED_MODEL[i]})",
                r == COMM_SUCCESS and err == 0 and model == EXPECTED_MODEL[i],
                f"{ph.getTxRxResult(r)}, error {err}")
    _, r, _ = ph.ping(port, 50)
    c.check("ping of an absent ID 50 times out", r == COMM_RX_TIMEOUT, ph.getTxRxResult(r))
    found, r = ph.broadcastPing(port)
    c.check("broadcast ping finds all 15 devices with their model numbers",
            r == COMM_SUCCESS and {k: v[0] for k, v in found.items()} == EXPECTED_MODEL,
            f"{ph.getTxRxResult(r)}, {sorted(found)}")

    # --- sensor boards (the robot stands, torque off) ---------------------------------------
    s1 = bulk_read_sensors(port, ph)
    time.sleep(0.05)
    s2 = bulk_read_sensors(port, ph)
    if c.check("BULK READ of the SAMPLE blocks of 111, 112, 200 (twice)",
               not isinstance(s1, str) and not isinstance(s2, str),
               s1 if isinstance(s1, str) else s2 if isinstance(s2, str) else ""):
        for i in FOOT_IDS:
            n1, n2 = s1[0][i][1], s2[0][i][1]
            c.check(f"foot {i}: counter advances between reads ({n1} -> {n2})",
                    0 < (n2 - n1) % 65536 < 32768)
        n1, n2 = s1[1][2], s2[1][2]
        c.check(f"IMU: counter advances between reads ({n1} -> {n2})",
                0 < (n2 - n1) % 65536 < 32768)
        sensors_standing(c, "standing", s2)

    # Unicast READ of each SAMPLE block (readTxRx), decoded with struct.
    for i, n, fmt in ((111, FOOT_SAMPLE_LEN, "<4iH"), (112, FOOT_SAMPLE_LEN, "<4iH"),
                      (IMU_ID, IMU_SAMPLE_LEN, "<6iH")):
        data, r, err = ph.readTxRx(port, i, ADDR_SAMPLE, n)
        ok = r == COMM_SUCCESS and err == 0 and len(data) == n
        vals = struct.unpack(fmt, bytes(data)) if ok else ()
        c.check(f"READ {n}-byte SAMPLE of {i}", ok,
                f"{ph.getTxRxResult(r)}, error {err}, counter {vals[-1] if vals else '-'}")

    # Return Delay Time (the boards' only writable register besides ID).
    for k, i in enumerate(FOOT_IDS + [IMU_ID]):
        check_written(c, port, ph, i, ADDR_RETURN_DELAY, 20 + k,
                      f"board {i}: write Return Delay Time")
    check_refused(c, port, ph, 111, ph.write4ByteTxRx, ADDR_SAMPLE, 1234, ERR_ACCESS,
                  "board 111: WRITE to the read-only SAMPLE block -> Access error")

    # --- servos -------------------------------------------------------------------------------
    for i in SERVOS:
        check_written(c, port, ph, i, ADDR_RETURN_DELAY, 10 + i,
                      f"servo {i}: torque off, write Return Delay Time (EEPROM)")

    start = sync_read_state(port, ph)
    if not c.check("SYNC READ of Present Current/Velocity/Position (126..135) of 12 servos",
                   isinstance(start, dict), start if isinstance(start, str) else ""):
        return
    time.sleep(0.3)
    still = sync_read_state(port, ph)
    c.check("torque off: the servos hold their position",
            isinstance(still, dict) and all(abs(still[i][2] - start[i][2]) <= 2 for i in SERVOS),
            str({i: still[i][2] - start[i][2] for i in SERVOS}) if isinstance(still, dict) else still)

    for i in SERVOS:
        r, err = ph.write1ByteTxRx(port, i, ADDR_TORQUE_ENABLE, 1)
        got, r2, _ = ph.read1ByteTxRx(port, i, ADDR_TORQUE_ENABLE)
        c.check(f"servo {i}: Torque Enable = 1", r == COMM_SUCCESS and err == 0 and got == 1,
                f"{ph.getTxRxResult(r)}, error {err}, read back {got}")

    # Writes servo 1 refuses: (write, address, value, the error status it answers, what).
    refused = [
        (ph.write1ByteTxRx, ADDR_RETURN_DELAY, 5, ERR_ACCESS,
         "EEPROM write with torque on -> Access error"),
        (ph.write4ByteTxRx, ADDR_PRESENT_POSITION, 1000, ERR_ACCESS,
         "WRITE to read-only Present Position -> Access error"),
        (ph.write4ByteTxRx, ADDR_GOAL_POSITION, 5000, ERR_DATA_LIMIT,
         "Goal Position 5000 (beyond 0..4095) -> Data Limit error"),
        (ph.write1ByteTxRx, ADDR_TORQUE_ENABLE, 2, ERR_DATA_RANGE,
         "Torque Enable = 2 -> Data Range error"),
    ]
    for write, addr, value, want, what in refused:
        check_refused(c, port, ph, 1, write, addr, value, want, f"servo 1: {what}")

    # The goals are ramped in over RAMP_S by one SYNC WRITE per loop (as a controller would:
    # a goal step would make the servos jerk the body and push the ZMP out of the feet), while
    # SYNC READ follows the motion for ~1 s of wall time.
    goal = {i: start[i][2] + GOAL_DELTA[i] for i in SERVOS}
    samples, errors, writes, latency = [], [], [], []
    t0 = time.monotonic()
    while time.monotonic() - t0 < 1.0:
        a = min(1.0, (time.monotonic() - t0) / RAMP_S)
        if not writes or writes[-1][1] < 1.0:
            sw = GroupSyncWrite(port, ph, ADDR_GOAL_POSITION, 4)
            for i in SERVOS:
                g = start[i][2] + round(a * GOAL_DELTA[i])
                sw.addParam(i, list(struct.pack("<i", g)))
            writes.append((sw.txPacket(), a))
        t1 = time.monotonic()
        s = sync_read_state(port, ph)
        latency.append(time.monotonic() - t1)
        if isinstance(s, dict):
            samples.append((time.monotonic() - t0, s))
        else:
            errors.append(s)
        time.sleep(0.01)
    c.check(f"{len(writes)} SYNC WRITEs of Goal Position (ramp over {RAMP_S} s) to 12 servos",
            all(r == COMM_SUCCESS for r, _ in writes) and writes[-1][1] == 1.0,
            ", ".join(sorted({ph.getTxRxResult(r) for r, _ in writes})))
    latency.sort()
    c.check(f"{len(samples)} SYNC READs during the move without a comm error",
            len(samples) >= 10 and not errors,
            "; ".join(errors[:3] + [f"round trip median {latency[len(latency) // 2] * 1e3:.1f} ms, "
                                     f"max {latency[-1] * 1e3:.1f} ms"]))
    sr = GroupSyncRead(port, ph, ADDR_GOAL_POSITION, 4)
    for i in SERVOS:
        sr.addParam(i)
    r = sr.txRxPacket()
    got = {i: s32(sr.getData(i, ADDR_GOAL_POSITION, 4)) for i in SERVOS}
    c.check("SYNC READ of Goal Position returns the goals written", r == COMM_SUCCESS and got == goal,
            f"{ph.getTxRxResult(r)}" + ("" if got == goal else f", {got} != {goal}"))
    if not samples:
        return
    end = samples[-1][1]
    for i in SERVOS:
        e0, e1 = goal[i] - start[i][2], goal[i] - end[i][2]
        vmax = max((s[i][1] for _, s in samples), key=abs)
        c.check(f"servo {i}: Present Position {start[i][2]} -> {end[i][2]} toward goal {goal[i]}, "
                f"peak velocity {vmax} x0.229 rpm",
                abs(e1) <= max(3, abs(e0) // 5) and (vmax * e0 > 0 or e0 == 0),
                f"remaining error {e1} ticks of {e0}")
    c.check("servos at rest after the move (|Present Velocity| <= 2)",
            all(abs(end[i][1]) <= 2 for i in SERVOS), str({i: end[i][1] for i in SERVOS}))
    currents = [s[i][0] for _, s in samples for i in SERVOS]
    c.check("Present Current: the knees carry the crouched robot (|I| > 0 on servos 4 and 10)",
            all(abs(end[i][0]) > 0 for i in (4, 10)), str({i: end[i][0] for i in SERVOS}))
    c.check("Present Current readable and within the XM430 limit (|I| <= 1193 x 2.69 mA)",
            all(abs(x) <= 1193 for x in currents),
            f"min {min(currents)}, max {max(currents)}")
    for i in (1, 4):
        v, r, err = ph.read4ByteTxRx(port, i, ADDR_PRESENT_VELOCITY)
        cur, r2, err2 = ph.read2ByteTxRx(port, i, ADDR_PRESENT_CURRENT)
        c.check(f"servo {i}: READ Present Velocity {s32(v)} / Present Current {s16(cur)}",
                r == COMM_SUCCESS and err == 0 and r2 == COMM_SUCCESS and err2 == 0,
                f"{ph.getTxRxResult(r)}, {ph.getTxRxResult(r2)}")

    sensors_standing(c, "after the move", bulk_read_sensors(port, ph))

    # --- torque off at the end -------------------------------------------------------------------
    # First servo 1 alone (left hip yaw; the other eleven hold the robot up): a goal written with
    # torque off is stored but not pursued.
    r, err = ph.write1ByteTxRx(port, 1, ADDR_TORQUE_ENABLE, 0)
    c.check("servo 1: Torque Enable = 0 (the others on)", r == COMM_SUCCESS and err == 0,
            f"{ph.getTxRxResult(r)}, error {err}")
    held = sync_read_state(port, ph)
    r, err = ph.write4ByteTxRx(port, 1, ADDR_GOAL_POSITION, (start[1][2] + 150) & 0xFFFFFFFF)
    time.sleep(0.3)
    after = sync_read_state(port, ph)
    c.check("torque off: a new goal does not move the servo",
            r == COMM_SUCCESS and err == 0 and isinstance(held, dict) and isinstance(after, dict)
            and abs(after[1][2] - held[1][2]) <= 3,
            "" if isinstance(after, dict) and isinstance(held, dict)
            else f"{held if isinstance(held, str) else after}")
    # Then all twelve (the unpowered robot is free to sag: nothing holds it in the physics).
    for i in SERVOS:
        r, err = ph.write1ByteTxRx(port, i, ADDR_TORQUE_ENABLE, 0)
        c.check(f"servo {i}: Torque Enable = 0", r == COMM_SUCCESS and err == 0,
                f"{ph.getTxRxResult(r)}, error {err}")


def main():
    c = Checks()
    t_start = time.monotonic()
    walker = walker_path()
    if not walker.is_file():
        c.check(f"walker binary {walker} exists", False, "set WALKER or build it")
        print(f"{c.passed} passed, {c.failed} failed")
        return 1
    for _ in range(3):  # the free port may be taken before the simulator binds it
        sim = Simulator(walker)
        if sim.wait_listening():
            break
        sim.kill()
    port = None
    try:
        if not c.check(f"walker simulate listens on port {sim.port}", sim.proc.poll() is None,
                       "".join(sim.err).strip()[-300:]):
            return 1
        port = SocketPortHandler(f"socket://127.0.0.1:{sim.port}")
        ph = PacketHandler(2.0)
        if not c.check("SDK opens socket:// port (PortHandler.openPort)", port.openPort()):
            return 1
        run(c, port, ph, sim)
        port.closePort()
        port = None
        rc = sim.wait_exit(10)
        c.check("simulator exits (status 0) once the SDK closes the port", rc == 0,
                f"exit status {rc}")
        summary = "".join(sim.out)
        standing = "fall_started_us: None" in summary
        c.check("the robot did not fall (simulator summary: fall_started_us: None)", standing,
                "" if standing else summary.strip()[-300:])
        for key in ("sim_time_us", "instructions", "status_sent", "crc_errors", "malformed",
                    "max_zmp_outside_m"):
            for line in summary.splitlines():
                if line.strip().startswith(key + ":"):
                    print(f"     sim summary {line.strip()}")
    except Exception as e:  # a crash of the test itself counts as a failure
        c.check("test ran without an exception", False, f"{type(e).__name__}: {e}")
    finally:
        if port is not None and port.is_open:
            port.closePort()
        sim.kill()
    print(f"     wall time {time.monotonic() - t_start:.1f} s")
    print(f"{c.passed} passed, {c.failed} failed")
    return 0 if c.failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
