#!/usr/bin/env python3
"""Drive the walking firmware with the official ROBOTIS Dynamixel SDK through its command port.

The firmware is a Dynamixel Protocol 2.0 device on its command port (ID 150;
docs/command-port.md has the control table). Any Dynamixel master drives it; this is the Python SDK
(`pip install dynamixel-sdk==4.1.0 pyserial==3.5`):

    # the firmware in QEMU against the MuJoCo robot, its command port on TCP 5770:
    target/x86_64-unknown-linux-gnu/release/walker fil --plan plans/table2.toml --command-port 5770 &
    python3 host/examples/sdk_drive.py socket://127.0.0.1:5770

    # the OpenCR's 4-pin UART connector (USART2, 1 Mbps) through a USB-TTL adapter:
    python3 host/examples/sdk_drive.py /dev/ttyUSB0 --baud 1000000

It waits until the robot stands, walks forward at 0.05 m/s for 5 s, turns in place at 0.3 rad/s
for 4 s, stops, waits for standing and turns the torque off (which also ends a `walker fil`
run; --keep-torque leaves the robot standing). A status line is printed every 0.5 s.

While it walks it writes the Heartbeat register every 0.1 s: the firmware's command deadman
(`deadman_ms`, 500 ms by default) stops a walk to standing when no valid command write (an
accepted WRITE) came for that long — READs do not count (docs/command-port.md).

The helpers (register map, status decoding, the TCP port handler) are used by the SDK tests in
host/tests/sdk/, and a Rust test (host/tests/cli.rs
`sdk_example_uses_the_contract_registers`) checks the numbers below against the contract
(contract/src/command_port.rs).
"""

import argparse
import os
import socket
import struct
import sys
import time

import serial
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

# The command port's device (contract/src/command_port.rs).
PORT_ID = 150
PORT_MODEL = 0x5A30
ADDR_MODEL = 0
ADDR_FIRMWARE_VERSION = 6
ADDR_ID = 7
ADDR_MODE = 64
ADDR_VELOCITY_X = 66  # then Velocity Y (68) and Yaw Rate (70): i16 mm/s, mm/s, mrad/s
ADDR_HEARTBEAT = 72  # any value: a valid command write that changes no command
HEARTBEAT_S = 0.1  # how often a walking master writes it (well under the 500 ms deadman)
STOP_CODE_DEADMAN = 13  # Stop Code after the command deadman stopped the walk
ADDR_STATUS = 128  # State; the status block runs to Supply Voltage (150, 2 bytes)
STATUS_LEN = 24
ADDR_STEP_COUNT = 130
ADDR_COMMAND_COUNT = 146
VELOCITY_X_MAX = 200  # mm/s
MODE_TORQUE_OFF = 0
MODE_STAND = 1
MODE_WALK = 2
MODE_STOP = 3
STATE_STANDING = 1
STATE_WALKING = 2
STATE_NAMES = {0: "starting", 1: "standing", 2: "walking", 3: "stopping", 4: "stopped", 5: "waiting"}
SUPPORT_NAMES = {0: "both", 1: "left", 2: "right"}

# Extra packet timeout on a TCP port, ms (see SocketPortHandler).
SOCKET_MARGIN_MS = float(os.environ.get("SDK_TEST_MARGIN_MS", "250"))


class SocketPortHandler(PortHandler):
    """A PortHandler whose port name may be a pyserial URL, e.g. socket://127.0.0.1:5770.

    The SDK's setupPort() opens `serial.Serial(port=name)`, which only takes device paths;
    `serial.serial_for_url()` also takes URLs, and its socket:// handler offers the
    read/write/in_waiting/reset_input_buffer interface the SDK uses. On a socket it sets
    TCP_NODELAY (pyserial does not: without it an instruction sent right after one that gets no
    reply waits for the peer's delayed ACK, ~40 ms, and misses the SDK's packet timeout) and adds
    SOCKET_MARGIN_MS to the SDK's packet timeout (sized for a USB adapter's latency timer): a
    simulated robot answers when its physics has caught up, up to ~50 ms late on a busy machine.
    """

    def setPacketTimeout(self, packet_length):
        super().setPacketTimeout(packet_length)
        if "://" in self.port_name:
            self.packet_timeout += SOCKET_MARGIN_MS

    def setupPort(self, cflag_baud):
        if self.is_open:
            self.closePort()
        self.ser = serial.serial_for_url(self.port_name, baudrate=self.baudrate,
                                         bytesize=serial.EIGHTBITS, timeout=0)
        sock = getattr(self.ser, "_socket", None)  # pyserial's socket:// handler keeps it here
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True


def s16(v):
    """A 16-bit register value as signed."""
    return struct.unpack("<h", struct.pack("<H", v & 0xFFFF))[0]


def decode_status(d):
    """The status block (STATUS_LEN bytes from ADDR_STATUS) as a dict."""
    def u16(i):
        return d[i] | (d[i + 1] << 8)
    return {
        "state": d[0], "support": d[1], "steps": u16(2),
        "zmp_x_mm": s16(u16(4)), "zmp_y_mm": s16(u16(6)), "zmp_valid": d[8],
        "stop_code": d[9], "fault": d[10], "list_len": d[11],
        "walk_vx": s16(u16(12)), "walk_vy": s16(u16(14)), "walk_vyaw": s16(u16(16)),
        "commands": u16(18),
        "servo_stiffness_nm_per_rad": u16(20) / 100.0, "supply_v": u16(22) / 10.0,
    }


def read_status(port, ph):
    """One READ of the status block, decoded; None when it failed."""
    data, r, err = ph.readTxRx(port, PORT_ID, ADDR_STATUS, STATUS_LEN)
    if r != COMM_SUCCESS:
        # A reply that comes after the SDK gave up must not pass for the next one's.
        time.sleep(0.3)
        port.clearPort()
        return None
    if err != 0 or len(data) != STATUS_LEN:
        return None
    return decode_status(data)


def status_line(st):
    """One line for a terminal."""
    return (f"{STATE_NAMES.get(st['state'], st['state'])}, support {SUPPORT_NAMES.get(st['support'], '?')}, "
            f"{st['steps']} steps, walk ({st['walk_vx']} mm/s, {st['walk_vy']} mm/s, "
            f"{st['walk_vyaw']} mrad/s), ZMP ({st['zmp_x_mm']}, {st['zmp_y_mm']}) mm"
            + ("" if st["zmp_valid"] else " (invalid)")
            + (f", stop code {st['stop_code']}" if st["stop_code"] else ""))


def set_velocity(port, ph, vx_mm_s, vy_mm_s, vyaw_mrad_s):
    """One WRITE of the three velocity registers; returns (comm result, error status)."""
    data = []
    for v in (vx_mm_s, vy_mm_s, vyaw_mrad_s):
        data += list(int(v).to_bytes(2, "little", signed=True))
    return ph.writeTxRx(port, PORT_ID, ADDR_VELOCITY_X, len(data), data)


def heartbeat(port, ph):
    """WRITE Heartbeat (the command deadman's keep-alive); returns (comm result, error status)."""
    return ph.write1ByteTxRx(port, PORT_ID, ADDR_HEARTBEAT, 0)


def set_mode(port, ph, mode):
    """WRITE Mode; returns (comm result, error status)."""
    return ph.write1ByteTxRx(port, PORT_ID, ADDR_MODE, mode)


def wait_state(port, ph, state, timeout_s, every_s=0.5):
    """Polls the status until State == state, printing it every every_s; the last status and
    whether the state was reached."""
    end = time.monotonic() + timeout_s
    st, shown = None, 0.0
    while time.monotonic() < end:
        st = read_status(port, ph) or st
        if st is not None and time.monotonic() - shown >= every_s:
            print(status_line(st), flush=True)
            shown = time.monotonic()
        if st is not None and st["state"] == state:
            return st, True
        time.sleep(0.05)
    return st, False


def hold(port, ph, seconds, every_s=0.5):
    """Writes Heartbeat every HEARTBEAT_S and prints the status every every_s, for seconds."""
    end = time.monotonic() + seconds
    shown = 0.0
    while time.monotonic() < end:
        heartbeat(port, ph)
        if time.monotonic() - shown >= every_s:
            st = read_status(port, ph)
            if st is not None:
                print(status_line(st), flush=True)
            shown = time.monotonic()
        time.sleep(HEARTBEAT_S)


def wait_ready(port, ph, timeout_s=120.0):
    """Waits until the firmware answers, leaving no late reply on the way: it answers its
    command port from its control loop only, so instructions sent during its start-up (probe,
    servo-speed check) queue up and are all answered at once when the loop starts — replies the
    SDK would take for the next instruction's. So: PING until one is answered, drop what comes
    for 0.5 s, then READ the ID register, which must be the port's (a late PING reply would
    carry the model number). True when ready."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        _, r, err = ph.ping(port, PORT_ID)
        if r == COMM_SUCCESS and err == 0:
            time.sleep(0.5)
            port.clearPort()
            value, r, err = ph.read1ByteTxRx(port, PORT_ID, ADDR_ID)
            if r == COMM_SUCCESS and err == 0 and value == PORT_ID:
                return True
        time.sleep(0.3)
        port.clearPort()
    return False


def open_port(name, baud, timeout_s=30.0):
    """Opens a device path or a socket:// URL, retrying until it opens (a `walker fil` run's
    QEMU listens a moment after it starts); None when it did not."""
    end = time.monotonic() + timeout_s
    while True:
        port = SocketPortHandler(name)
        try:
            if port.openPort() and port.setBaudRate(baud):
                return port
        except Exception as e:  # connection refused, no such device
            if time.monotonic() >= end:
                print(f"cannot open {name}: {e}", file=sys.stderr)
                return None
        time.sleep(0.2)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("port", help="socket://HOST:PORT or a serial device such as /dev/ttyUSB0")
    ap.add_argument("--baud", type=int, default=1_000_000)
    ap.add_argument("--keep-torque", action="store_true", help="leave the robot standing")
    a = ap.parse_args()
    port = open_port(a.port, a.baud)
    if port is None:
        return 1
    ph = PacketHandler(2.0)
    if not wait_ready(port, ph):
        print(f"no answer from ID {PORT_ID} on {a.port}")
        return 1
    model, r, err = ph.ping(port, PORT_ID)
    if r != COMM_SUCCESS or model != PORT_MODEL:
        print(f"no walking firmware at ID {PORT_ID}: {ph.getTxRxResult(r)}, model {model:#x}")
        return 1
    print(f"ID {PORT_ID}: model {model:#x}; waiting for standing")
    if not wait_state(port, ph, STATE_STANDING, 300)[1]:
        return 1
    steps = [("forward 0.05 m/s", (50, 0, 0), 5.0), ("turn 0.3 rad/s", (0, 0, 300), 4.0)]
    for what, vel, seconds in steps:
        print(f"-- {what} for {seconds:.0f} s")
        for r, err in (set_velocity(port, ph, *vel), set_mode(port, ph, MODE_WALK)):
            if r != COMM_SUCCESS or err != 0:
                print(f"refused: {ph.getTxRxResult(r)}, error {err}")
                return 1
        hold(port, ph, seconds)
    print("-- stop")
    set_mode(port, ph, MODE_STOP)
    if not wait_state(port, ph, STATE_STANDING, 60)[1]:
        return 1
    if not a.keep_torque:
        print("-- torque off")
        set_mode(port, ph, MODE_TORQUE_OFF)
    port.closePort()
    return 0


if __name__ == "__main__":
    sys.exit(main())
