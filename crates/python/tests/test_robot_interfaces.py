"""Velocity and effort on the robot handle: Robot.set_interface, command_velocity and
command_effort translate to the library's Robot (its checks, limits and frames), on the
built-in simulators driven through a robot file that gives the joints those interfaces."""

from __future__ import annotations

import math
import time

import pytest

import robobus

# What the simulated wCK-1108's wheel levels 1..15 turn it at, rad/s (its no-load speed
# times the level's duty, less its gear friction).
WHEEL_SPEEDS = [math.radians(400) * (k / 15 - 0.03) for k in range(1, 16)]

HEAD = """
watchdog_timeout = 0.5
[buses.sim-wck]
kind = "wck-external"
[buses.sim-whj]
kind = "whj-external"
"""

WHEEL = f"""
[[joints]]
name = "s0"
bus = "sim-wck"
id = 0
limits = [-2.0, 2.0]
max_velocity = 7.0
max_acceleration = 100.0
interfaces = ["position", "velocity"]
wheel_speeds = {WHEEL_SPEEDS!r}
"""

ELBOW = """
[[joints]]
name = "j1"
bus = "sim-whj"
id = 1
limits = [-3.0, 3.0]
max_velocity = 2.0
max_acceleration = 20.0
interfaces = ["position", "velocity", "effort"]
max_effort = 5.0
"""


def hold(robot: robobus.Robot, send, values: list[float], seconds: float) -> robobus.RobotCommand:
    """Sends ``values`` every 20 ms for ``seconds``; the last report."""
    last = None
    for _ in range(round(seconds / 0.02)):
        last = send(values)
        time.sleep(0.02)
    assert last is not None
    return last


def test_velocities_turn_a_wheel_and_a_whj_joint_once_switched() -> None:
    with robobus.Robot.simulated(HEAD + WHEEL + ELBOW) as robot:
        assert robot.interfaces == ["position", "position"]
        # Not switched: refused, nothing sent.
        with pytest.raises(robobus.RefusedError, match="velocity"):
            robot.command_velocity([0.5, 0.5])
        with pytest.raises(robobus.BadInputError, match="nope"):
            robot.set_interface("nope", "velocity")
        with pytest.raises(robobus.BadInputError, match="interface"):
            robot.set_interface("j1", "torque")
        robot.set_interface("s0", "velocity")
        robot.set_interface(1, "velocity")
        assert robot.interfaces == ["velocity", "velocity"]
        level_7 = WHEEL_SPEEDS[6]
        done = hold(robot, robot.command_velocity, [level_7, 0.5], 0.6)
        assert done.interfaces == ["velocity", "velocity"]
        assert done.sent_rad[0] == pytest.approx(level_7, abs=1e-9)
        assert done.sent_rad[1] == pytest.approx(0.5, abs=2e-4)
        # The WHJ joint turns at it (its own speed reading).
        assert robot.read().velocity_rad_s[1] == pytest.approx(0.5, rel=0.05)
        # Past max_velocity: refused whole.
        with pytest.raises(robobus.BadInputError):
            robot.command_velocity([level_7, float("nan")])
        hold(robot, robot.command_velocity, [0.0, 0.0], 0.2)
        robot.set_interface("s0", "position")
        robot.set_interface("j1", "position")
        assert robot.interfaces == ["position", "position"]


def test_a_whj_joint_takes_efforts_in_current_mode() -> None:
    with robobus.Robot.simulated(HEAD + WHEEL) as wheel:
        with pytest.raises(robobus.BadInputError, match="effort"):
            wheel.set_interface("s0", "effort")
    with robobus.Robot.simulated(HEAD + ELBOW) as robot:
        robot.set_interface("j1", "effort")
        done = hold(robot, robot.command_effort, [0.5], 0.2)
        assert done.interfaces == ["effort"]
        # 0.5 N·m through the WHJ30's 30/7.8 N·m per A.
        assert done.sent_rad[0] == pytest.approx(0.5, abs=0.01)
        assert robot.read().current_a[0] == pytest.approx(0.5 / (30 / 7.8), abs=0.05)
