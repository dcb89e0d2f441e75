#!/usr/bin/env python3
"""The official ROBOTIS Dynamixel SDK drives the firmware's command port in a firmware-in-the-loop run.

Standalone script (no pytest), the firmware-in-the-loop sibling of test_dynamixel_sdk.py:
starts `walker fil --command-port PORT` (the firmware in QEMU, without autostart, against the
MuJoCo robot; QEMU's UART3 listens on 127.0.0.1:PORT) and, as any Dynamixel master would, with
the SDK over TCP (Protocol 2.0, ID 150):

1. pings the device and reads its identity (model number 0x5A30, firmware version, ID);
2. waits for State = standing (the firmware stood up by itself and waits for commands);
3. sends bad commands, each of which must get the protocol's error status and change nothing:
   Velocity X over its range (Data Range), an unknown Mode (Data Range), a write to the
   read-only State (Access), a write covering half of Velocity X (Data Length), an address
   outside the table (Data Range); Command Count, the velocity and State must stay as they were;
4. walks: Velocity X = 50 mm/s (one 6-byte write of the velocity block), Mode = walk; waits for
   State = walking and Step Count >= 4, reading the status block (128..147) with READ and with a
   GroupSyncRead, and checks it (support foot, walk velocity within the command, ZMP);
5. stops: Mode = stop; waits for State = standing with the step count settled;
6. Mode = torque off ends the run: `walker fil` must exit 0 and report no fall;
7. runs the example of docs/command-port.md, host/examples/sdk_drive.py (walk, turn, stop, torque off), against a
   second run: it must exit 0 having printed walking status lines, and the robot not fall;
8. `walker drive --sim` (keyboard teleoperation) in a pseudo-terminal: waits for the standing
   status line, types w w w w (walk +40 mm/s), a (turn +100 mrad/s), x (quit: stop, torque off)
   and reads the status line back; the run must end without a fall, every footstep the
   commands'.

Every check prints one `ok` / `FAIL` line; the last line is `N passed, M failed` and the exit
status is non-zero when anything failed. Run it through `scripts/sdk-test.sh --fil [walker]`,
which installs the SDK, or directly with
`WALKER=path/to/walker QEMU_ELF=path/to/qemu python3 host/tests/sdk/test_sdk_command_port.py`.
The register map and helpers are the example script's (host/examples/sdk_drive.py, which the
test also runs against a second `walker fil --command-port` run); the Rust test
`sdk_example_uses_the_contract_registers` (host/tests/cli.rs) checks its numbers and the error
and fault codes below against the contract.
"""

import os
import pty
import re
import select
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# QEMU in lock-step with MuJoCo stalls longer than the simulator alone when the machine is busy:
# a larger margin over the SDK's packet timeout (read by sdk_drive at import).
os.environ.setdefault("SDK_TEST_MARGIN_MS", "1000")
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
from test_dynamixel_sdk import REPO, Background, Checks, walker_path  # noqa: E402

from dynamixel_sdk import (  # noqa: E402
    COMM_RX_CORRUPT, COMM_RX_TIMEOUT, COMM_SUCCESS, GroupSyncRead, PacketHandler)
# The register map and helpers of the example script (checked against the contract by
# host/tests/cli.rs `sdk_example_uses_the_contract_registers`).
from sdk_drive import (  # noqa: E402
    ADDR_FIRMWARE_VERSION, ADDR_ID, ADDR_MODE, ADDR_MODEL, ADDR_STATUS, ADDR_VELOCITY_X,
    HEARTBEAT_S, MODE_STOP, MODE_TORQUE_OFF, MODE_WALK, PORT_ID, PORT_MODEL, STATE_STANDING,
    STATE_WALKING, STATUS_LEN, decode_status, heartbeat, open_port, read_status, set_mode,
    set_velocity, wait_ready)

DEFAULT_QEMU_ELF = "target/thumbv7em-none-eabihf/release/qemu"
EXAMPLE = REPO / "host/examples/sdk_drive.py"

# Protocol 2.0 status error codes (the SDK's ERRNUM_*).
ERR_DATA_RANGE = 4
ERR_DATA_LENGTH = 5
ERR_ACCESS = 7

WALK_MM_S = 50
STEPS = 4
# Wall-clock limits: the run is QEMU in lock-step with MuJoCo, slower than real time on a busy
# 2-core machine.
CONNECT_S = 60.0
STAND_S = 180.0
WALK_S = 300.0
EXIT_S = 120.0


class FilRun(Background):
    """`walker fil --command-port PORT` in the background."""

    def __init__(self, walker, elf, out):
        super().__init__([walker, "fil", "--plan", "plans/table2.toml", "--command-port", "{port}",
                          "--out", out, "--elf", elf, "--timeout", "900"], cwd=REPO)


def connect(run):
    """Opens the SDK's port on QEMU's listening UART3 (retrying until QEMU listens)."""
    if run.proc.poll() is not None:
        return None
    return open_port(f"socket://127.0.0.1:{run.port}", 1_000_000, CONNECT_S)


def wait_for(port, ph, what, timeout, run, beats=None):
    """Polls the status block until what(status) holds; returns the last status (or None).
    With `beats` (a dict counting "ok" and "lost"), writes Heartbeat every HEARTBEAT_S too (the
    command deadman's keep-alive while walking), counting the accepted ones and those without a
    reply (which the firmware may have accepted)."""
    end = time.monotonic() + timeout
    st = None
    beat_at = 0.0
    while time.monotonic() < end and run.proc.poll() is None:
        if beats is not None and time.monotonic() - beat_at >= HEARTBEAT_S:
            r, err = heartbeat(port, ph)
            beats["ok" if r == COMM_SUCCESS and err == 0 else "lost"] += 1
            beat_at = time.monotonic()
        st = read_status(port, ph) or st
        if st is not None and what(st):
            return st, True
        time.sleep(0.05)
    return st, False


def again(port, transaction, attempts=3):
    """A side-effect-free transaction (PING, READ) repeated when it got no reply: on a busy
    machine the lock-stepped firmware can answer after the SDK's timeout; the late reply is
    dropped before the next attempt. Writes are never repeated (the test counts them)."""
    for _ in range(attempts):
        result = transaction()
        r = result if isinstance(result, int) else result[-2]
        if r != COMM_RX_TIMEOUT and r != COMM_RX_CORRUPT:
            return result
        time.sleep(0.3)
        port.clearPort()
    return result


def run_checks(c, port, ph, run):
    c.check("the command port answers once the firmware's loop runs (PING, late replies dropped)",
            wait_ready(port, ph, STAND_S))
    model, r, err = again(port, lambda: ph.ping(port, PORT_ID))
    c.check("PING ID 150: the firmware's command port answers", r == COMM_SUCCESS and err == 0,
            ph.getTxRxResult(r))
    c.check("PING reports model number 0x5A30", model == PORT_MODEL, f"model {model:#x}")
    ident, r, err = again(port, lambda: ph.readTxRx(port, PORT_ID, ADDR_MODEL, 8))
    ok = r == COMM_SUCCESS and err == 0 and len(ident) == 8
    c.check("READ the identity (model, firmware version, ID)",
            ok and ident[0] | ident[1] << 8 == PORT_MODEL and ident[ADDR_ID] == PORT_ID
            and ident[ADDR_FIRMWARE_VERSION] >= 1, f"{list(ident)}")

    st, ok = wait_for(port, ph, lambda s: s["state"] == STATE_STANDING, STAND_S, run)
    if not c.check("State = standing: the firmware stood up and waits (no autostart)", ok,
                   f"{st}"):
        return
    before = st

    # Bad commands: each gets its error status and changes nothing.
    bad = [
        ("Velocity X over its range (+300 mm/s)", lambda: ph.write2ByteTxRx(
            port, PORT_ID, ADDR_VELOCITY_X, 300), ERR_DATA_RANGE),
        ("Velocity X under its range (-300 mm/s, two's complement)", lambda: ph.write2ByteTxRx(
            port, PORT_ID, ADDR_VELOCITY_X, (-300) & 0xFFFF), ERR_DATA_RANGE),
        ("Mode = 9 (no such mode)", lambda: ph.write1ByteTxRx(
            port, PORT_ID, ADDR_MODE, 9), ERR_DATA_RANGE),
        ("a write to the read-only State", lambda: ph.write1ByteTxRx(
            port, PORT_ID, ADDR_STATUS, STATE_WALKING), ERR_ACCESS),
        ("one byte of the two-byte Velocity X", lambda: ph.write1ByteTxRx(
            port, PORT_ID, ADDR_VELOCITY_X, 40), ERR_DATA_LENGTH),
        ("an address outside the table (300)", lambda: ph.write1ByteTxRx(
            port, PORT_ID, 300, 1), ERR_DATA_RANGE),
    ]
    for name, send, want in bad:
        r, err = send()
        c.check(f"rejected: {name} -> error status {want}", r == COMM_SUCCESS and err == want,
                f"{ph.getTxRxResult(r)}, error {err}")
    vx, r, err = again(port, lambda: ph.read2ByteTxRx(port, PORT_ID, ADDR_VELOCITY_X))
    c.check("the rejected writes left Velocity X at 0", r == COMM_SUCCESS and vx == 0, f"{vx}")
    st = read_status(port, ph)
    c.check("... and Command Count and State unchanged (nothing reached the gait)",
            st is not None and st["commands"] == before["commands"]
            and st["state"] == STATE_STANDING, f"before {before}, after {st}")

    # Walk.
    r, err = set_velocity(port, ph, WALK_MM_S, 0, 0)
    c.check(f"WRITE velocity (vx {WALK_MM_S} mm/s, vy 0, yaw 0) accepted",
            r == COMM_SUCCESS and err == 0, f"{ph.getTxRxResult(r)}, error {err}")
    r, err = set_mode(port, ph, MODE_WALK)
    c.check("WRITE Mode = walk accepted", r == COMM_SUCCESS and err == 0,
            f"{ph.getTxRxResult(r)}, error {err}")
    beats = {"ok": 0, "lost": 0}
    st, ok = wait_for(port, ph, lambda s: s["state"] == STATE_WALKING and s["steps"] >= STEPS,
                      WALK_S, run, beats)
    if not c.check(f"State = walking and Step Count >= {STEPS} (Heartbeat written every "
                   f"{HEARTBEAT_S} s: no deadman stop)", ok, f"{st}, heartbeats {beats}"):
        return
    low = before["commands"] + 2 + beats["ok"]
    c.check("Command Count counts the two accepted writes and the accepted heartbeats",
            low <= st["commands"] <= low + beats["lost"],
            f"{before['commands']} -> {st['commands']}, heartbeats {beats}")
    c.check(f"Walk Velocity X in (0, {WALK_MM_S}] mm/s, Y and yaw rate ~0 (the heading hold "
            "may turn a little)", 0 < st["walk_vx"] <= WALK_MM_S and abs(st["walk_vy"]) <= 5,
            f"{st}")
    c.check("Support Foot is both, left or right; no stop code; Fault Kind none (the start-up's "
            "timing stretch is a notice, not a fault)",
            st["support"] in (0, 1, 2) and st["fault"] == 0 and st["stop_code"] == 0, f"{st}")
    c.check("Measured ZMP valid and under the robot (|x| < 0.3 m, |y| < 0.3 m)",
            st["zmp_valid"] == 1 and abs(st["zmp_x_mm"]) < 300 and abs(st["zmp_y_mm"]) < 300,
            f"{st}")
    # The same block through the SDK's GroupSyncRead (SYNC READ of the status block).
    gsr = GroupSyncRead(port, ph, ADDR_STATUS, STATUS_LEN)
    gsr.addParam(PORT_ID)
    r = again(port, gsr.txRxPacket)
    ok = r == COMM_SUCCESS and gsr.isAvailable(PORT_ID, ADDR_STATUS, STATUS_LEN)
    if r != COMM_SUCCESS:  # a late reply must not pass for the next instruction's
        time.sleep(0.3)
        port.clearPort()
    sync = None
    if ok:
        sync = decode_status([gsr.getData(PORT_ID, ADDR_STATUS + i, 1) for i in range(STATUS_LEN)])
    c.check("SYNC READ (GroupSyncRead) of the status block: walking, the step count growing",
            ok and sync["state"] == STATE_WALKING and sync["steps"] >= st["steps"],
            f"{ph.getTxRxResult(r)} {sync}")

    # Stop to standing.
    r, err = set_mode(port, ph, MODE_STOP)
    c.check("WRITE Mode = stop accepted", r == COMM_SUCCESS and err == 0,
            f"{ph.getTxRxResult(r)}, error {err}")
    st, ok = wait_for(port, ph, lambda s: s["state"] == STATE_STANDING, WALK_S, run)
    c.check("State = standing after the stop", ok, f"{st}")
    if ok:
        steps = st["steps"]
        time.sleep(1.0)
        st2 = read_status(port, ph)
        c.check("standing still: the step count stays", st2 is not None
                and st2["steps"] == steps and st2["state"] == STATE_STANDING, f"{st} -> {st2}")

    r, err = set_mode(port, ph, MODE_TORQUE_OFF)
    c.check("WRITE Mode = torque off accepted (ends the run)", r == COMM_SUCCESS and err == 0,
            f"{ph.getTxRxResult(r)}, error {err}")


def check_run_end(c, run, what):
    """walker fil exited 0 (torque off on command ends the run) and the robot did not fall."""
    rc = run.wait_exit(EXIT_S)
    c.check(f"{what}: walker fil exits 0 once torque off was commanded", rc == 0,
            f"exit status {rc}; {''.join(run.err)[-800:]}")
    out_text = "".join(run.out)
    c.check(f"{what}: the robot did not fall (walker fil: 'no fall')", "no fall" in out_text,
            out_text.strip()[-500:])
    for line in out_text.splitlines():
        print(f"     {line}")


def session(c, walker, elf):
    """The SDK session of run_checks on one `walker fil --command-port` run."""
    out = Path(tempfile.mkdtemp(prefix="sdk-fil-"))
    run = FilRun(walker, elf, out)
    port = None
    try:
        port = connect(run)
        if not c.check(f"SDK opens socket://127.0.0.1:{run.port} (QEMU's UART3)",
                       port is not None, "".join(run.err)[-500:]):
            return
        run_checks(c, port, PacketHandler(2.0), run)
        port.closePort()
        check_run_end(c, run, "SDK session")
    finally:
        if port is not None and port.is_open:
            port.closePort()
        run.kill()
        print(f"     output in {out}")


def example(c, walker, elf):
    """host/examples/sdk_drive.py (the example of docs/command-port.md) against another run."""
    out = Path(tempfile.mkdtemp(prefix="sdk-example-"))
    run = FilRun(walker, elf, out)
    try:
        ex = subprocess.run([sys.executable, str(EXAMPLE), f"socket://127.0.0.1:{run.port}"],
                            capture_output=True, text=True, timeout=WALK_S)
        text = ex.stdout + ex.stderr
        walked = [ln for ln in text.splitlines() if ln.startswith("walking")]
        c.check("the example script (host/examples/sdk_drive.py) exits 0", ex.returncode == 0,
                text[-800:])
        c.check("... walking (status lines 'walking, …'), then stops and turns the torque off",
                len(walked) >= 3 and "-- torque off" in text, text[-800:])
        for line in text.splitlines()[-6:]:
            print(f"     example: {line}")
        check_run_end(c, run, "example")
    finally:
        run.kill()
        print(f"     output in {out}")


def drive(c, walker, elf):
    """`walker drive --sim` in a pseudo-terminal: keys typed, the status line read back."""
    out = Path(tempfile.mkdtemp(prefix="sdk-drive-"))
    pid, fd = pty.fork()
    if pid == 0:  # the child: walker drive on the pty
        os.chdir(REPO)
        os.execv(str(walker), [str(walker), "drive", "--sim", "--out", str(out), "--elf", str(elf)])
    text = []

    def pump(seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            r, _, _ = select.select([fd], [], [], 0.05)
            if r:
                try:
                    data = os.read(fd, 65536)
                except OSError:  # the child closed the pty
                    return False
                if not data:
                    return False
                text.append(data.decode(errors="replace"))
        return True

    def until(pattern, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if re.search(pattern, "".join(text)):
                return True
            if not pump(0.2):
                return bool(re.search(pattern, "".join(text)))
        return False

    def last_status():
        lines = "".join(text).replace("\x1b[K", "").replace("\r", "\n").splitlines()
        st = [ln for ln in lines if re.match(r"(starting|standing|walking|stopping|STOPPED) ", ln)]
        return st[-1] if st else "no status line"

    try:
        ok = until(r"standing support", STAND_S)
        c.check("walker drive --sim: the status line shows the robot standing", ok, last_status())
        for _ in range(4):
            os.write(fd, b"w")
            pump(0.3)
        ok = until(r"walking .*steps +([4-9]|\d\d+) \| cmd  \+40", WALK_S)
        c.check("4 x 'w': walking at the commanded +40 mm/s, 4 steps", ok, last_status())
        os.write(fd, b"a")
        ok = until(r"cmd  \+40   \+0 mm/s \+100 mrad/s \| walk  \+40   \+0 \+100", WALK_S)
        c.check("'a': the walk turns left at +100 mrad/s", ok, last_status())
        os.write(fd, b"x")
        ok = until(r"no fall; \d+ footsteps, 0 not the commands'", EXIT_S)
        c.check("'x': stop, standing, torque off: the run's figures say no fall and every footstep "
                "the commands'", ok, "".join(text)[-600:])
        _, status = os.waitpid(pid, 0)
        pid = None
        c.check("walker drive exits 0", os.waitstatus_to_exitcode(status) == 0, f"status {status}")
        for line in "".join(text).splitlines()[-3:]:
            print(f"     drive: {line.strip()}")
    finally:
        if pid is not None:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        os.close(fd)
        print(f"     output in {out}")


def main():
    c = Checks()
    t_start = time.monotonic()
    walker = walker_path()
    elf = Path(os.environ.get("QEMU_ELF", REPO / DEFAULT_QEMU_ELF)).resolve()
    for what, p in (("walker", walker), ("firmware ELF", elf)):
        if not p.is_file():
            print(f"{what} not found: {p}", file=sys.stderr)
            return 2
    for part in (session, example, drive):
        try:
            part(c, walker, elf)
        except Exception as e:  # a crash of the test itself counts as a failure
            c.check(f"{part.__name__} ran without an exception", False, f"{type(e).__name__}: {e}")
    print(f"     wall time {time.monotonic() - t_start:.1f} s")
    print(f"{c.passed} passed, {c.failed} failed")
    return 0 if c.failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
