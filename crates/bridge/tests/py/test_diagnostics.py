"""`NS/diagnostics` read by a Zenoh peer in Python and decoded with rosbags'
`diagnostic_msgs/msg/DiagnosticArray` (a CDR implementation that is not ours): one status
per joint and per bus of the robot, OK on the built-in simulated robot; a simulated joint
that falls silent is an error naming why, one that latches an error bit an error naming the
bit, and their bus a warning."""

from __future__ import annotations

import os
import pathlib
import subprocess
import tempfile
import time

import pytest

from bridgekit import ROBOBUS, TS, Bridge, Inbox, free_port, session
from diagnostics_vectors import VECTORS, vectors

ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
OK, WARN, ERROR, STALE = 0, 1, 2, 3


def diagnostics(sample) -> object:
    return TS.deserialize_cdr(bytes(sample.payload.to_bytes()), ARRAY)


def statuses(msg) -> dict[str, object]:
    return {s.name: s for s in msg.status}


def values(status) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


def test_the_checked_in_vectors_are_what_rosbags_writes():
    lines = dict(line.split(" ", 1) for line in VECTORS.read_text().splitlines())
    assert {k: v.strip() for k, v in lines.items()} == vectors()


def test_the_simulated_robot_is_diagnosed_ok_joint_by_joint_and_bus_by_bus():
    bridge = Bridge("--rate", "50", "--namespace", "bot1")
    peer = session(bridge.endpoint)
    try:
        inbox = Inbox(peer, "bot1/diagnostics")
        # The first message may come before the first sample (every joint stale).
        msg = None
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            msg = diagnostics(inbox.get(10))
            if all(s.level == OK for s in msg.status):
                break
        by_name = statuses(msg)
        assert all(s.level == OK for s in msg.status), [(s.name, s.level, s.message) for s in msg.status]
        joints = [n for n in by_name if " joint " in n]
        buses = [n for n in by_name if " bus " in n]
        assert len(joints) == 23, joints
        assert sorted(buses) == ["robobus: bot1 bus sim-wck", "robobus: bot1 bus sim-whj"]
        j1 = by_name["robobus: bot1 joint j1"]
        assert (j1.message, j1.hardware_id) == ("OK", "whj sim-whj 1")
        v = values(j1)
        assert v["error_bits"] == "no error" and v["error_code"] == "0x0000"
        assert v["model"] == "WHJ30"
        assert 20 <= float(v["temperature_c"]) < 75
        assert 20 <= float(v["voltage_v"]) <= 27
        for key in ("position_deg", "current_a", "last_read_s"):
            float(v[key])
        assert by_name["robobus: bot1 bus sim-whj"].message == "OK, 7 of 7 joints answering"
        assert msg.header.stamp.sec > 1_600_000_000
    finally:
        peer.close()
        assert bridge.stop() == 0


def robot_file(directory: str, bus: str) -> str:
    path = os.path.join(directory, "arm.toml")
    joints = "".join(
        f'\n[[joints]]\nname = "j{i}"\nbus = "arm"\nid = {i}\nlimits = [-1.0, 1.0]\n'
        "max_velocity = 1.0\nmax_acceleration = 5.0\n"
        for i in (1, 2, 3))
    pathlib.Path(path).write_text(f'[buses.arm]\nkind = "whj-bus"\nbus = "{bus}"\n{joints}')
    return path


@pytest.fixture
def faulty_arm():
    """`robobus sim whj` serving joints 1-3 behind an emulated slcan adapter on TCP
    (loopback): joint 3 falls silent and joint 2 latches over-temperature (0x0008) 3 s
    after serving starts."""
    bus = f"slcan:socket://127.0.0.1:{free_port()}"
    sim = subprocess.Popen(
        [ROBOBUS, "sim", "whj", "--joints", "1-3", "--no-iap", "--bus", bus,
         "--fault-silent", "3@3", "--fault-error", "2:0x0008@3"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        line = sim.stderr.readline()
        assert "serving 3 joint(s)" in line, line
        yield bus
    finally:
        sim.terminate()
        sim.wait(10)


def test_a_silent_joint_is_an_error_naming_why_and_its_bus_warns(faulty_arm):
    with tempfile.TemporaryDirectory() as d:
        bridge = Bridge("--rate", "10", "--namespace", "arm1", "--robot", robot_file(d, faulty_arm))
        peer = session(bridge.endpoint)
        try:
            inbox = Inbox(peer, "arm1/diagnostics")
            seen = []
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                by_name = statuses(diagnostics(inbox.get(10)))
                seen.append({n: (s.level, s.message) for n, s in by_name.items()})
                if by_name["robobus: arm1 joint j3"].level == ERROR:
                    break
            j1 = by_name["robobus: arm1 joint j1"]
            j2 = by_name["robobus: arm1 joint j2"]
            j3 = by_name["robobus: arm1 joint j3"]
            bus = by_name["robobus: arm1 bus arm"]
            assert j3.level == ERROR, seen
            assert j3.message.startswith("silent: "), j3.message
            assert "3" in j3.message and values(j3)["failure"] == "no-device"
            # Nothing of it that was not just read.
            assert "position_deg" not in values(j3) and "temperature_c" not in values(j3)
            assert j1.level == OK, (j1.message, seen)
            # The latched bit (3 s after serving too): named, an error.
            if j2.level != ERROR:
                by_name = statuses(diagnostics(inbox.get(10)))
                j2, bus = by_name["robobus: arm1 joint j2"], by_name["robobus: arm1 bus arm"]
            assert (j2.level, j2.message) == (ERROR, "error bits: over-temperature"), seen
            assert values(j2)["error_code"] == "0x0008"
            assert (bus.level, bus.message) == (WARN, "2 of 3 joints in error: j2, j3"), seen
        finally:
            peer.close()
            assert bridge.stop() == 0
