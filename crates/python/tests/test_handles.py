"""The hot-path handles against the in-process simulators: wCK servo and WHJ joint groups
read what the catalogue's requests read, take any array-like of numbers, refuse a bad
value before anything is sent, mark a silent device without stopping; the robot reads
and commands in radians behind its limits and watchdog, and closes into its safe state.
"""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import time
from typing import Iterator

import numpy as np
import pytest

import robobus

ROOT = pathlib.Path(__file__).resolve().parents[3]
BIN = os.environ.get("ROBOBUS_BIN", str(ROOT / "target" / "debug" / "robobus"))


@pytest.fixture
def station() -> Iterator[robobus.Station]:
    with robobus.Station.simulated() as s:
        yield s


def test_wck_status_is_the_status_request(station: robobus.Station) -> None:
    station.wck.move(1, 90, torque=2, check=True)
    group = station.wck_servos(np.arange(4))
    # On the virtual clock the servo moves as the reads go by: wait until it is there.
    for _ in range(500):
        if group.status().position[1] == 90.0:
            break
    got = group.status()
    report = station.wck.status("0-3", check=True)
    assert got.id.tolist() == [0, 1, 2, 3] and got.id.dtype == np.int64
    assert got.position.dtype == np.float64 and got.valid.dtype == np.bool_
    assert got.position.tolist() == [float(r["position"]) for r in report["results"]]
    # The load of the servo that moved still changes as it holds; the others rest.
    assert got.load[[0, 2, 3]].tolist() == [float(report["results"][i]["load"]) for i in (0, 2, 3)]
    assert got.valid.all() and got.error == [None] * 4 and got.check() is got
    assert got.position_deg.tolist() == pytest.approx([r["degrees"] for r in report["results"]], abs=0.005)


def test_a_silent_servo_is_marked_and_the_group_carries_on(station: robobus.Station) -> None:
    got = station.wck_servos([0, 20, 2]).status()
    assert got.valid.tolist() == [True, False, True]
    assert np.isnan(got.position[1]) and not np.isnan(got.position[2])
    assert got.kind == [None, "no-device", None]
    assert got.failed() == [20]
    with pytest.raises(robobus.NoDeviceError, match="servo 20 did not answer"):
        got.check()
    with pytest.raises(robobus.NoDeviceError):
        station.wck_servo(20).status()


@pytest.mark.parametrize(
    "positions",
    [
        [100, 110, 120],
        (100.0, 110.0, 120.0),
        np.array([100, 110, 120], dtype=np.int16),
        np.arange(100, 130)[::10],
        np.array([[100, 110, 120]]),
    ],
    ids=["list", "tuple", "int16", "strided", "2d"],
)
def test_wck_moves_take_any_array_of_numbers(station: robobus.Station, positions: object) -> None:
    group = station.wck_servos([0, 1, 2])
    replies = group.move(positions, torque=2)  # type: ignore[arg-type]
    assert replies.valid.all()
    group.sync_move(positions, torque=2)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("positions", "torque", "message"),
    [
        ([100, 255, 120], 2, "position of servo 1 255: allowed: whole steps 0..=254"),
        ([100, 110.5, 120], 2, "position of servo 1 110.5"),
        ([100, np.nan, 120], 2, "position of servo 1 NaN"),
        ([100, 110], 2, "positions 2 value"),
        ([100, 110, 120], 5, "torque 5"),
        (["a", "b", "c"], 2, "is not an array of numbers"),
    ],
)
def test_a_bad_wck_value_refuses_the_whole_move(
    station: robobus.Station, positions: list[object], torque: int, message: str
) -> None:
    group = station.wck_servos([0, 1, 2])
    before = group.status().position.tolist()
    for call in (group.move, group.sync_move):
        with pytest.raises(robobus.BadInputError, match=message.replace(".", r"\.")) as e:
            call(positions, torque)  # type: ignore[arg-type]
        assert isinstance(e.value, ValueError) and "nothing was sent" in str(e.value)
    assert group.status().position.tolist() == before


def test_a_sync_move_needs_servos_from_zero(station: robobus.Station) -> None:
    with pytest.raises(robobus.RefusedError, match=r"servos 0\.\.=1"):
        station.wck_servos([1, 2]).sync_move([100, 100])
    with pytest.raises(robobus.BadInputError, match="given twice"):
        station.wck_servos([1, 1])
    with pytest.raises(robobus.BadInputError, match="are not whole numbers"):
        station.wck_servos([1.5])


def test_one_wck_servo(station: robobus.Station) -> None:
    servo = station.wck_servo(3)
    assert servo.id == 3
    assert servo.move(100, torque=1)["position"] == 127.0
    assert set(servo.status()) == {"position", "position_deg", "load"}
    assert set(servo.passive()) == {"position", "position_deg"}


def test_whj_joints_read_and_command_within_their_limits(station: robobus.Station) -> None:
    joints = station.whj_joints([1, 2])
    assert joints.ids == [1, 2] and joints.bus == "sim-whj"
    assert joints.limits("speed").tolist() == [[-37.5, 37.5], [-37.5, 37.5]]
    station.whj.disable("1-2", check=True)
    with pytest.raises(robobus.RefusedError, match="not enabled|disabled"):
        joints.command_position([0.0, 0.0])
    station.whj.mode("1-2", "position", check=True)
    station.whj.enable("1-2", check=True)
    here = joints.status()
    report = station.whj.status("1-2", check=True)
    assert here.position_deg.tolist() == [r["position_deg"] for r in report["results"]]
    assert here.enabled.dtype == np.bool_ and here.enabled.all()
    assert here.errors == ["no error", "no error"]
    with pytest.raises(robobus.RefusedError, match="step limit"):
        joints.command_position(here.position_deg + [30.0, 0.0])
    low, high = joints.limits("position")[1]
    with pytest.raises(robobus.BadInputError, match="target of joint J2"):
        joints.command_position([here.position_deg[0], high + 1.0])
    fb = joints.command_position(here.position_deg + np.array([2.0, -2.0]))
    assert fb.valid.all() and fb.position_deg.dtype == np.float64
    assert fb.position_deg.tolist() == pytest.approx(here.position_deg.tolist(), abs=0.5)
    with pytest.raises(robobus.RefusedError, match="speed mode"):
        station.whj_joint(1).command_speed(1.0)
    assert station.whj_joint(2).status()["enabled"] is True
    # A silent joint, on the virtual clock: its timed-out queries pass at once (on the wall
    # clock they took 5 s), the error is the same.
    with robobus.Station.simulated(clock="virtual") as virtual, pytest.raises(robobus.NoDeviceError):
        virtual.whj_joint(9)


def test_no_servo_frame_while_a_cyclic_loop_runs(station: robobus.Station) -> None:
    station.whj.mode("1", "position", check=True)
    station.whj.enable("1", check=True)
    joint = station.whj_joint(1)
    here = joint.status()["position_deg"]
    with station.cyclic([1], rate_hz=100):
        with pytest.raises(robobus.RefusedError, match="cyclic loop"):
            joint.command_position(here)
    assert joint.command_position(here)["enabled"] is True


def test_the_robot_in_si_units() -> None:
    with robobus.Robot.simulated() as robot:
        names = robot.joint_names
        assert len(names) == 23 and names[0] == "s0" and names[-1] == "j7"
        assert robot.limits.shape == (23, 4)
        assert robot.limits[0].tolist() == [-2.0, 2.0, 2.0, 20.0]
        state = robot.read()
        assert state.position_rad.dtype == np.float64 and state.position_rad.shape == (23,)
        assert np.isnan(state.velocity_rad_s[:16]).all() and not np.isnan(state.velocity_rad_s[16:]).any()
        targets = state.position_rad.copy()
        targets[-1] = 5.0
        sent = robot.command(targets)
        assert {x["joint"] for x in sent.limited} == {"j7"}
        kinds = [x["kind"] for x in sent.limited]
        # The step limit acts too when the wall clock let the joint fall behind.
        assert kinds[:2] == ["position", "motion"] and set(kinds[2:]) <= {"step"}, kinds
        assert sent.limited[0]["limited_rad"] == 2.0
        assert abs(sent.sent_rad[-1]) < 0.1, "the set-point follows within the speed limit"
        with pytest.raises(robobus.BadInputError, match="22"):
            robot.command(targets[:22])
        robot.safe_stop()
        assert robot.stopped
        with pytest.raises(robobus.RobobusError, match="safe"):
            robot.command(state.position_rad)
        robot.resume()
        assert not robot.stopped
        robot.command(state.position_rad)
        # No command within the watchdog timeout: the safe stop.
        time.sleep(robot.watchdog_timeout + 0.3)
        assert robot.stopped
    assert robot.closed
    robot.close()
    with pytest.raises(robobus.BadInputError, match="closed"):
        robot.read()


def test_a_handle_does_not_keep_the_port_open_after_close() -> None:
    sim = subprocess.Popen([BIN, "sim", "wck", "--servos", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert sim.stdout is not None
        port = sim.stdout.readline().strip()
        station = robobus.open_wck(port)
        servo = station.wck_servo(0)
        assert servo.status()["position"] == 127.0
        station.close()
        with pytest.raises(robobus.BadInputError, match="WckServos.status: the station is closed"):
            servo.status()
        # The port is free at once, although the handle still exists.
        with robobus.open_wck(port) as again:
            assert again.wck_servo(0).status()["position"] == 127.0
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait(timeout=20)
