"""The host's protection of a loop written in Python: `robobus sim whj` behind an emulated
slcan adapter on TCP (loopback) with a hand gripping joint 1's output and pulling it 80
degrees down; a Python loop commanding the joint up, away from the hand, through
`robobus.Robot` gets `ProtectionError` naming the joint, the quantity, the limit and the
time, the joint is left still and not pushing (disabled, its brake holding it), and later
commands are refused until `clear_protection`. With `protection=False` the same loop pushes
on.
"""

from __future__ import annotations

import os
import pathlib
import socket
import subprocess
import tempfile
import time
from typing import Iterator

import pytest

import robobus
from robobus.errors import ProtectionError, RefusedError

ROOT = pathlib.Path(__file__).resolve().parents[3]
BIN = os.environ.get("ROBOBUS_BIN", str(ROOT / "target" / "debug" / "robobus"))

# The WHJ30's rated current: the stall limit of the models table.
RATED_A = 7.8


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def gripped_robot_file() -> Iterator[str]:
    """A robot file of joint `j1`: `robobus sim whj` serving joint 1 (a WHJ30, its brake a
    pin brake, at 0 degrees), a hand gripping its output and pulling it toward -80 degrees
    (a spring of 50 N·m/rad: the joint holds against it with about 18 A, and its 23.4 A
    peak current carries it no further than about 23 degrees up)."""
    bus = f"slcan:socket://127.0.0.1:{free_port()}"
    sim = subprocess.Popen(
        [BIN, "sim", "whj", "--joints", "1", "--no-iap", "--bus", bus, "--hand", "1:-80:-80:1"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert sim.stderr is not None
        line = sim.stderr.readline()
        assert "serving 1 joint(s)" in line, line
        with tempfile.TemporaryDirectory() as d:
            path = pathlib.Path(d) / "gripped.toml"
            path.write_text(
                "watchdog_timeout = 0.5\n\n"
                f'[buses.arm]\nkind = "whj-bus"\nbus = "{bus}"\n\n'
                '[[joints]]\nname = "j1"\nbus = "arm"\nid = 1\nlimits = [-1.0, 1.0]\n'
                "max_velocity = 1.0\nmax_acceleration = 5.0\n")
            yield str(path)
    finally:
        sim.terminate()
        sim.wait(10)


def push(robot: robobus.Robot, seconds: float) -> float:
    """A Python loop: every 10 ms a target 1 rad/s further up, for at most `seconds`;
    returns the time it ran."""
    start = time.monotonic()
    while (t := time.monotonic() - start) < seconds:
        robot.command([min(t, 1.0)])
        time.sleep(0.01)
    return t


def test_a_python_loop_into_a_gripped_joint_raises_protection_error_and_the_joint_is_held(
    gripped_robot_file: str,
) -> None:
    with robobus.Robot.open(gripped_robot_file) as robot:
        assert robot.protection
        start = time.monotonic()
        with pytest.raises(ProtectionError) as caught:
            push(robot, 5.0)
        took = time.monotonic() - start
        e = caught.value
        # The joint turns up until its current reaches the drive's peak, then stands while
        # its target runs on; the stall time (0.3 s) later the loop is stopped.
        assert (e.joint, e.check, e.quantity, e.limit) == ("j1", "stall", "current_a", RATED_A), e
        assert e.value >= RATED_A and e.at_s > 0.3, e
        assert took < 2.0, f"stopped after {took:.2f} s: {e}"
        assert isinstance(e, robobus.DeviceError) and e.kind == "device"
        text = str(e)
        assert text.startswith("j1: stall protection: current "), text
        assert f"reached the limit {RATED_A} A at {e.at_s:.3f} s" in text, text
        assert "its drive disabled (its brake holds it" in text, text
        assert text.endswith("every later command is refused until Robot::clear_protection")
        assert robot.protection_stops == [robot.protection_events[-1]]

        # Held: its brake holds it where it stopped, against the hand, and nothing pushes
        # any more.
        first = robot.read()
        time.sleep(0.3)
        later = robot.read()
        assert 0.1 < first.position_rad[0] < 0.6, first.position_rad
        assert abs(later.position_rad[0] - first.position_rad[0]) < 1e-3
        assert abs(later.current_a[0]) < 0.1, later.current_a

        # Every later command is refused, nothing sent, until clear_protection.
        with pytest.raises(RefusedError, match="call Robot::clear_protection"):
            robot.command([0.0])
        cleared = robot.clear_protection()
        assert [c["joint"] for c in cleared] == ["j1"]
        assert robot.protection_stops == []
        robot.command([float(robot.read().position_rad[0])])


def test_with_protection_false_the_same_loop_pushes_on_into_the_grip(
    gripped_robot_file: str,
) -> None:
    with robobus.Robot.open(gripped_robot_file, protection=False) as robot:
        assert not robot.protection
        push(robot, 1.5)
        # Still pushing against the hand with more than the rated current.
        state = robot.read()
        assert abs(state.current_a[0]) > RATED_A, state.current_a
        assert robot.protection_events == []


def test_protection_takes_only_true_or_false() -> None:
    with robobus.Robot.simulated() as robot:
        with pytest.raises(robobus.BadInputError, match="expected True or False"):
            robot.protection = 0  # type: ignore[assignment]
        robot.protection = False
        assert not robot.protection
        robot.protection = True
        assert robot.protection
