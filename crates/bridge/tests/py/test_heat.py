"""A joint driven hot, seen in `NS/diagnostics` by a Zenoh peer in Python and decoded with
rosbags: `robobus sim whj` behind an emulated slcan adapter on TCP (loopback), a hand
holding joint 1's output 80° from where the joint holds it in position mode (the grip's
70 N·m draws about 18 A, 2.3 times the WHJ30's rated current), and its thermal model
warming the winding by about 0.7 °C a second; the robot file puts the joint's host
protection limits a few degrees over the 25 °C ambient. The joint's status goes from OK to
WARN at the warning limit, WARN at the derating limit, then ERROR at the stop limit, each
message naming the temperature and the limit, and its bus is in error with it."""

from __future__ import annotations

import os
import pathlib
import subprocess
import tempfile
import time

import pytest

from bridgekit import ROBOBUS, Bridge, Inbox, free_port, query, session
from test_diagnostics import ERROR, OK, WARN, diagnostics, statuses, values

WARN_C, DERATE_C, STOP_C = 26, 27, 29


@pytest.fixture
def gripped_joint():
    """`robobus sim whj` serving joint 1, a hand holding its output at 80°."""
    bus = f"slcan:socket://127.0.0.1:{free_port()}"
    sim = subprocess.Popen(
        [ROBOBUS, "sim", "whj", "--joints", "1", "--no-iap", "--bus", bus,
         "--hand", "1:80:80:1"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        line = sim.stderr.readline()
        assert "serving 1 joint(s)" in line, line
        yield bus
    finally:
        sim.terminate()
        sim.wait(10)


def robot_file(directory: str, bus: str) -> str:
    path = os.path.join(directory, "hot.toml")
    pathlib.Path(path).write_text(
        f'[buses.arm]\nkind = "whj-bus"\nbus = "{bus}"\n\n'
        '[[joints]]\nname = "j1"\nbus = "arm"\nid = 1\nlimits = [-1.0, 1.0]\n'
        "max_velocity = 1.0\nmax_acceleration = 5.0\n\n"
        f"[joints.protection]\ntemperature_warn_c = {WARN_C}\n"
        f"temperature_derate_c = {DERATE_C}\ntemperature_stop_c = {STOP_C}\n")
    return path


def test_a_joint_held_against_a_hand_warms_warns_derates_then_errs(gripped_joint):
    with tempfile.TemporaryDirectory() as d:
        bridge = Bridge("--rate", "10", "--namespace", "arm1", "--armed",
                        "--robot", robot_file(d, gripped_joint))
        peer = session(bridge.endpoint)
        try:
            inbox = Inbox(peer, "arm1/diagnostics")
            # Held where it stands: the hand pulls, the position loop resists.
            for r in ('{"op":"whj.mode","joints":"1","mode":"position"}',
                      '{"op":"whj.enable","joints":"1"}'):
                query(peer, "arm1/robobus/run", r)
            seen = []  # (level, message, temperature, bus level, bus message)
            deadline = time.monotonic() + 40
            while time.monotonic() < deadline:
                by_name = statuses(diagnostics(inbox.get(10)))
                j1, bus = by_name["robobus: arm1 joint j1"], by_name["robobus: arm1 bus arm"]
                v = values(j1)
                seen.append((j1.level, j1.message, float(v["temperature_c"]), bus.level,
                             bus.message))
                if j1.level == ERROR:
                    break
            levels = [s[0] for s in seen]
            temperatures = [s[2] for s in seen]
            # Warmer and warmer, worse and worse: OK, WARN, ERROR in that order.
            assert temperatures == sorted(temperatures), seen
            assert levels == sorted(levels) and levels[-1] == ERROR, seen
            for level, message, t, _, _ in seen:
                if level == OK:
                    assert t < WARN_C and message == "OK", seen
                elif level == WARN:
                    limit, at = ("derating", DERATE_C) if t >= DERATE_C else ("warning", WARN_C)
                    assert t < STOP_C, seen
                    assert message == f"temperature {t:.1f} °C at or over the {limit} limit {at} °C", seen
            # It was derated (WARN at the derating limit) before it was stopped.
            assert any(s[0] == WARN and "derating limit" in s[1] for s in seen), seen
            level, message, t, bus_level, bus_message = seen[-1]
            assert t >= STOP_C, seen
            assert message == f"temperature {t:.1f} °C at or over the stop limit {STOP_C} °C", seen
            # Its bus: in error with it (its only joint).
            assert (bus_level, bus_message) == (ERROR, "1 of 1 joints in error: j1"), seen
            # The heat is the winding's: the current held all along (a hand 80° away pulls
            # 70 N·m: about 18 A on the WHJ30).
            assert abs(float(values(by_name["robobus: arm1 joint j1"])["current_a"])) > 15, seen
        finally:
            peer.close()
            assert bridge.stop() == 0
