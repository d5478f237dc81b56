"""The LeRobot motors bus (`robobus.lerobot`): its method set is LeRobot's (checked against a
recorded list of LeRobot's signatures, and against LeRobot itself when it imports), and it
drives the simulated robot's wCK servos and WHJ joints as LeRobot drives its motors: the
handshake, calibration and normalisation, torque, sync reads and writes with nothing sent
on a refusal, homing, range recording, scans and motor setup on the simulator's pty; the
settings registers LeRobot's robots write at start, mapped or refused naming why; and the
robot class (a follower arm) connecting, calibrating, reading and writing on the simulator.

LeRobot itself needs torch and is not installed here: the robot class is held against
LeRobot 0.4.4's ``Robot`` base class as recorded below (its abstract members and helpers).
"""

from __future__ import annotations

import importlib.util
import inspect
import json
import os
import pathlib
import signal
import subprocess
from typing import Any, Iterator

import pytest

import robobus
from robobus.lerobot import (
    DeviceAlreadyConnectedError,
    DeviceNotConnectedError,
    Motor,
    MotorCalibration,
    MotorNormMode,
    OperatingMode,
    RobobusFollower,
    RobobusFollowerConfig,
    RobobusMotorsBus,
)

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[2]
BIN = os.environ.get("ROBOBUS_BIN", str(ROOT / "target" / "debug" / "robobus"))
RECORDED = json.loads((HERE / "data" / "lerobot_motors_bus.json").read_text())
STEP = 269.0 / 255.0


def incompatible(ours: Any, recorded: list[list[Any]]) -> str | None:
    """Why a call written for the recorded signature would fail on ``ours`` (``None`` if
    none would): the recorded positional parameters are ours in the same order, the
    keyword ones exist, every default is the same, and our extra parameters have
    defaults."""
    params = [p for p in inspect.signature(ours).parameters.values() if p.name not in ("self", "cls")]
    by_name = {p.name: p for p in params}
    positional = [p for p in params if p.kind is p.POSITIONAL_OR_KEYWORD]
    i = 0
    for entry in recorded:
        name, kind = entry[0], entry[1]
        p = by_name.get(name)
        if kind == "var_positional":
            if not any(q.kind is q.VAR_POSITIONAL for q in params):
                return f"no *{name}"
            continue
        if kind == "var_keyword":
            if not any(q.kind is q.VAR_KEYWORD for q in params):
                return f"no **{name}"
            continue
        if p is None:
            return f"no parameter {name!r}"
        if kind == "positional":
            if i >= len(positional) or positional[i].name != name:
                return f"parameter {name!r} is not positional number {i + 1}"
            i += 1
        elif p.kind not in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD):
            return f"parameter {name!r} cannot be given by name"
        # (A default where LeRobot has none only accepts more calls.)
        if len(entry) > 2 and p.default != entry[2]:
            return f"parameter {name!r} defaults to {p.default!r}, not {entry[2]!r}"
    recorded_names = {e[0] for e in recorded}
    for p in params:
        if p.name not in recorded_names and p.default is p.empty and p.kind not in (
            p.VAR_POSITIONAL,
            p.VAR_KEYWORD,
        ):
            return f"extra parameter {p.name!r} has no default"
    return None


def test_the_method_set_is_lerobots() -> None:
    for name in RECORDED["class_attributes"]:
        assert hasattr(RobobusMotorsBus, name), name
    for name in RECORDED["properties"]:
        assert isinstance(inspect.getattr_static(RobobusMotorsBus, name), property), name
    for name, params in RECORDED["methods"].items():
        method = getattr(RobobusMotorsBus, name)
        assert callable(method), name
        assert incompatible(method, params) is None, (name, incompatible(method, params))
    assert incompatible(RobobusMotorsBus.sync_write, RECORDED["base_sync_write"]) is None
    for name, params in RECORDED["classmethods"].items():
        assert isinstance(inspect.getattr_static(RobobusMotorsBus, name), classmethod), name
        assert incompatible(getattr(RobobusMotorsBus, name), params) is None, name
    assert [f.name for f in __import__("dataclasses").fields(Motor)] == RECORDED["dataclasses"]["Motor"]
    assert [f.name for f in __import__("dataclasses").fields(MotorCalibration)] == (
        RECORDED["dataclasses"]["MotorCalibration"]
    )
    assert {m.name: m.value for m in MotorNormMode} == RECORDED["norm_modes"]
    bus = RobobusMotorsBus("sim", {"a": Motor(1, "wck", MotorNormMode.DEGREES)})
    for name in RECORDED["instance_attributes"]:
        assert hasattr(bus, name), name


def test_the_method_set_against_lerobot_itself() -> None:
    if importlib.util.find_spec("lerobot") is None:
        pytest.skip("LeRobot is not installed here (it needs torch); the recorded list stands in")
    from lerobot.motors import motors_bus  # type: ignore[import-not-found]

    serial = motors_bus.SerialMotorsBus
    for name, value in inspect.getmembers(serial):
        if name.startswith("_") and name not in ("__init__", "__len__", "__repr__"):
            continue
        if callable(value) and not isinstance(inspect.getattr_static(serial, name), property):
            theirs = [
                [p.name, "keyword" if p.kind is p.KEYWORD_ONLY else "positional"]
                + ([] if p.default is p.empty else [p.default])
                for p in inspect.signature(value).parameters.values()
                if p.name not in ("self", "cls") and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
            ]
            assert incompatible(getattr(RobobusMotorsBus, name), theirs) is None, name
    bus = RobobusMotorsBus("sim", {"a": Motor(1, "wck", MotorNormMode.DEGREES)})
    assert isinstance(bus, motors_bus.MotorsBusBase)


MOTORS = {
    "wrist": Motor(0, "wck", MotorNormMode.RANGE_M100_100),
    "gripper": Motor(1, "wck", MotorNormMode.RANGE_0_100),
    "elbow": Motor(2, "wck", MotorNormMode.DEGREES),
    "shoulder": Motor(1, "whj", MotorNormMode.DEGREES),
    "base": Motor(2, "whj", MotorNormMode.RANGE_M100_100),
}


@pytest.fixture
def bus() -> Iterator[RobobusMotorsBus]:
    # On the virtual clock: each read moves the simulators on by its own time, so a test
    # waits for a motion by reading, the same readings every run.
    b = RobobusMotorsBus("sim:virtual", MOTORS)
    b.connect()
    yield b
    if b.is_connected:
        b.disconnect()


def settle(bus: RobobusMotorsBus, motor: str, want: int) -> None:
    """Reads until the servo is at ``want`` (it moves as time passes on the simulators'
    clock, which advances with each read)."""
    for _ in range(500):
        if bus.read("Present_Position", motor, normalize=False) == want:
            return
    raise AssertionError(f"{motor} never reached {want}")


def test_connect_checks_every_motor_and_the_state_is_lerobots(bus: RobobusMotorsBus) -> None:
    assert bus.is_connected and len(bus) == 5
    assert bus.ids == [0, 1, 2, 1, 2] and bus.models == ["wck"] * 3 + ["whj"] * 2
    with pytest.raises(DeviceAlreadyConnectedError):
        bus.connect()
    missing = RobobusMotorsBus("sim:virtual", {"a": Motor(0, "wck", MotorNormMode.DEGREES), "b": Motor(20, "wck", MotorNormMode.DEGREES)})
    with pytest.raises(ConnectionError, match=r"motors \['b'\] \(IDs \[20\]\) did not answer"):
        missing.connect()
    assert not missing.is_connected
    with pytest.raises(DeviceNotConnectedError):
        missing.read("Present_Position", "a")
    with pytest.raises(ValueError, match="same id"):
        RobobusMotorsBus("sim", {"a": Motor(1, "wck", MotorNormMode.DEGREES), "b": Motor(1, "wck", MotorNormMode.DEGREES)})
    with pytest.raises(ValueError, match="one port carries one family"):
        RobobusMotorsBus("/dev/ttyUSB0", MOTORS)


def test_calibration_and_normalisation(bus: RobobusMotorsBus) -> None:
    assert not bus.is_calibrated
    with pytest.raises(RuntimeError, match="no calibration"):
        bus.read("Present_Position", "wrist")
    device = bus.read_calibration()
    assert device["wrist"] == MotorCalibration(0, 0, 0, 1, 254)
    assert device["shoulder"].range_min < 0 < device["shoulder"].range_max
    bus.write_calibration(device)
    assert bus.is_calibrated
    raw = bus.sync_read("Present_Position", normalize=False)
    assert raw == {"wrist": 127, "gripper": 127, "elbow": 127, "shoulder": 0, "base": 0}
    got = bus.sync_read("Present_Position")
    assert got["wrist"] == pytest.approx((127 - 1) / 253 * 200 - 100)
    assert got["gripper"] == pytest.approx((127 - 1) / 253 * 100)
    assert got["elbow"] == pytest.approx((127 - 127.5) * STEP)
    assert got["shoulder"] == 0.0 and got["base"] == pytest.approx(0.0)
    inverted = dict(device)
    inverted["gripper"] = MotorCalibration(1, 1, 0, 1, 254)
    bus.write_calibration(inverted)
    assert bus.read("Present_Position", "gripper") == pytest.approx(100 - (127 - 1) / 253 * 100)
    with pytest.raises(ValueError, match="outside the device's own range 1..=254"):
        bus.write_calibration({"wrist": MotorCalibration(0, 0, 0, 0, 254)})
    with pytest.raises(ValueError, match="not readable on a wck motor"):
        bus.read("Goal_Position", "wrist")


def test_sync_write_checks_everything_before_it_sends(bus: RobobusMotorsBus) -> None:
    bus.write_calibration(bus.read_calibration())
    bus.enable_torque()
    before = bus.sync_read("Present_Position", normalize=False)
    refusals: list[tuple[dict[str, float], type[Exception], str]] = [
        ({"wrist": 10.0, "elbow": 200.0}, ValueError, "outside the calibrated range"),
        ({"wrist": 10.0, "elbow": float("nan")}, ValueError, "not a finite number"),
        ({"wrist": 10.0, "shoulder": 30.0}, robobus.RefusedError, "step limit"),
    ]
    for targets, error, message in refusals:
        with pytest.raises(error, match=message):
            bus.sync_write("Goal_Position", targets)
        assert bus.sync_read("Present_Position", normalize=False) == before, "nothing was sent"
    bus.sync_write("Goal_Position", {"wrist": 150.0, "gripper": 0.0, "elbow": 5.2 * STEP, "shoulder": 1.0})
    # Normalised targets past the range are clamped to it, as in LeRobot.
    settle(bus, "wrist", 254)
    settle(bus, "gripper", 1)
    settle(bus, "elbow", 133)
    for _ in range(2000):
        if abs(bus.read("Present_Position", "shoulder", normalize=False) - 10_000) < 300:
            break
    else:
        raise AssertionError("the shoulder never reached 1 degree")
    bus.write("Goal_Position", "elbow", 100, normalize=False)
    settle(bus, "elbow", 100)
    with pytest.raises(ValueError, match="not writable on a wck motor"):
        bus.write("Present_Position", "elbow", 100)


def test_torque_and_the_whj_registers(bus: RobobusMotorsBus) -> None:
    bus.disable_torque(["shoulder", "base"])
    assert bus.sync_read("Torque_Enable", ["shoulder", "base"]) == {"shoulder": 0, "base": 0}
    with bus.torque_disabled("shoulder"):
        assert bus.read("Torque_Enable", "shoulder") == 0
    assert bus.read("Torque_Enable", "shoulder") == 1
    bus.write("Torque_Enable", "base", 1)
    assert bus.read("Torque_Enable", "base") == 1
    assert isinstance(bus.read("Present_Velocity", "shoulder"), int)
    assert isinstance(bus.read("Present_Current", "shoulder"), int)
    bus.disable_torque("wrist")
    assert bus.ping("wrist") == RobobusMotorsBus.model_number_table["wck"]
    # ID 1 is a wCK servo and a WHJ joint on the simulated robot: only a name tells them apart.
    with pytest.raises(KeyError, match="give the motor's name"):
        bus.ping(1)


def test_homing_and_recorded_ranges(bus: RobobusMotorsBus) -> None:
    bus.write_calibration(bus.read_calibration())
    bus.write("Goal_Position", "elbow", 100, normalize=False)
    settle(bus, "elbow", 100)
    offsets = bus.set_half_turn_homings(["elbow"])
    assert offsets == {"elbow": 100 - (1 + 254) // 2}
    assert bus.read("Present_Position", "elbow", normalize=False) == (1 + 254) // 2
    assert bus.calibration["elbow"].homing_offset == offsets["elbow"]

    reads = iter(range(400))
    targets = iter([120, 80])

    def until() -> bool:
        n = next(reads)
        if n in (5, 200):
            bus.write("Goal_Position", "elbow", next(targets) - offsets["elbow"], normalize=False)
        return n >= 399

    mins, maxes = bus.record_ranges_of_motion(["elbow"], display_values=False, until=until, period=0)
    assert mins["elbow"] < (1 + 254) // 2 < maxes["elbow"]
    with pytest.raises(ValueError, match="did not move"):
        bus.record_ranges_of_motion(["wrist"], display_values=False, until=lambda: True, period=0)


def test_scans_find_the_simulated_motors() -> None:
    # On the virtual clock: every silent ID's timeout passes at once (7 s on the wall clock).
    assert RobobusMotorsBus.scan_port("sim:virtual") == {115200: list(range(16))}
    assert RobobusMotorsBus.scan_port("sim:virtual", family="whj") == {115200: list(range(1, 8))}


def test_setup_motor_on_the_simulators_pty() -> None:
    sim = subprocess.Popen([BIN, "sim", "wck", "--servos", "3"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert sim.stdout is not None
        port = sim.stdout.readline().strip()
        assert RobobusMotorsBus.scan_port(port) == {115200: [3]}
        bus = RobobusMotorsBus(port, {"gripper": Motor(5, "wck", MotorNormMode.RANGE_0_100)})
        # Found at its rate by the scan above; setup_motor's own scan looks at that rate.
        bus.setup_motor("gripper", initial_baudrate=115200)
        bus.connect()
        assert bus.read("Present_Position", "gripper", normalize=False) == 127
        assert bus.broadcast_ping() == {5: RobobusMotorsBus.model_number_table["wck"]}
        bus.disconnect()
        assert not bus.is_connected
        with pytest.raises(DeviceNotConnectedError):
            bus.disconnect()
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait(timeout=20)


def test_the_settings_lerobots_robots_write_are_mapped_where_the_devices_have_them(
    bus: RobobusMotorsBus,
) -> None:
    station = bus._station_()
    # WHJ: the work mode, the position-loop gains (RAM registers), the acceleration limit.
    bus.disable_torque(["shoulder", "base"])
    bus.write("Operating_Mode", "shoulder", OperatingMode.VELOCITY.value)
    assert station.whj.status("1")["results"][0]["mode"] == "speed"
    bus.sync_write("Operating_Mode", {"shoulder": OperatingMode.POSITION, "base": 0})
    assert [r["mode"] for r in station.whj.status("1-2")["results"]] == ["position", "position"]
    for data_name, register, value in (
        ("P_Coefficient", "SEV_POSITION_P", 16),
        ("I_Coefficient", "SEV_POSITION_I", 0),
        ("D_Coefficient", "SEV_POSITION_D", 32),
        ("Position_P_Gain", "SEV_POSITION_P", 17),
    ):
        bus.write(data_name, "shoulder", value)
        assert station.whj.read("1", register)["results"][0]["raw"] == value, data_name
    bus.write("Acceleration", "base", 2500)
    assert station.whj.read("2", "LIT_MAX_ACC")["results"][0]["value"] == 2500.0
    # wCK: the runtime gains (P and D are one command: the other is kept) and acceleration.
    bus.write("P_Coefficient", "elbow", 16)
    bus.write("D_Coefficient", "elbow", 32)
    bus.write("I_Coefficient", "elbow", 3)
    assert station.wck.get("gains", 2)["results"][0] | {"id": 2} == {"id": 2, "p_gain": 16, "d_gain": 32}
    assert station.wck.get("i-gain", 2)["results"][0]["i_gain"] == 3
    bus.write("Operating_Mode", "elbow", OperatingMode.POSITION)


def test_the_settings_the_devices_do_not_have_are_refused_naming_why(bus: RobobusMotorsBus) -> None:
    station = bus._station_()
    elbow_gains = station.wck.get("gains", 2)["results"][0]
    refusals = [
        ("Lock", "wrist", 0, "'Lock' of 'wrist': refused on a wck motor: a wCK servo has no EEPROM lock"),
        ("Lock", "shoulder", 1, "'Lock' of 'shoulder': refused on a whj motor: a WHJ joint has no flash lock"),
        ("Return_Delay_Time", "wrist", 0, "refused on a wck motor: a wCK servo answers after a fixed turnaround"),
        ("Maximum_Acceleration", "wrist", 254, "a wCK servo has one acceleration setting: write Acceleration"),
        ("Max_Torque_Limit", "gripper", 500, "a wCK servo's torque is a level 0..=4 sent with each move"),
        ("Protection_Current", "shoulder", 250, "a WHJ joint's current limit is LIT_MAX_CURRENT in mA"),
        ("Overload_Torque", "gripper", 25, "has no reduced torque on overload"),
        ("Homing_Offset", "base", 0, "the homing offset is kept by the host"),
        ("Min_Position_Limit", "base", 0, "the devices' own limits are not rewritten from LeRobot"),
        ("Operating_Mode", "wrist", 1, "a wCK servo's wheel mode is a timed command"),
        ("Operating_Mode", "shoulder", 2, "2 is no mode of a whj motor \\(allowed: 0 position, 1 velocity"),
        ("Acceleration", "wrist", 254, "accel=254: acceleration 254 is out of range 20..=100"),
        ("P_Coefficient", "wrist", 1.5, "1.5 is not a whole number"),
    ]
    for data_name, motor, value, why in refusals:
        with pytest.raises(ValueError, match=why):
            bus.write(data_name, motor, value)
    # A refusal among several motors sends nothing to any.
    with pytest.raises(ValueError, match="'P_Coefficient' of 'wrist': 5.5 is not a whole number"):
        bus.sync_write("P_Coefficient", {"elbow": 5, "wrist": 5.5})
    with pytest.raises(ValueError, match="acceleration 300 is out of range"):
        bus.sync_write("Acceleration", {"elbow": 50, "wrist": 300})
    with pytest.raises(ValueError, match="p=300: "):
        bus.sync_write("P_Coefficient", {"elbow": 5, "wrist": 300})
    assert station.wck.get("gains", 2)["results"][0] == elbow_gains, "nothing was sent"


# LeRobot 0.4.4's `Robot` (lerobot/robots/robot.py): its abstract members, the helpers and
# attributes its subclasses and its scripts use, and `connect`'s parameter.
ROBOT_PROPERTIES = ["observation_features", "action_features", "is_connected", "is_calibrated"]
ROBOT_METHODS = {
    "connect": [["calibrate", "positional", True]],
    "calibrate": [],
    "configure": [],
    "get_observation": [],
    "send_action": [["action", "positional"]],
    "disconnect": [],
    "_load_calibration": [["fpath", "positional", None]],
    "_save_calibration": [["fpath", "positional", None]],
}
ROBOT_ATTRIBUTES = ["robot_type", "id", "calibration_dir", "calibration_fpath", "calibration", "config"]
ROBOT_CONFIG_FIELDS = ["id", "calibration_dir", "port", "disable_torque_on_disconnect", "max_relative_target", "cameras"]


@pytest.fixture
def follower(tmp_path: pathlib.Path) -> Iterator[RobobusFollower]:
    robot = RobobusFollower(RobobusFollowerConfig(port="sim:virtual", id="arm", calibration_dir=tmp_path))
    yield robot
    if robot.is_connected:
        robot.disconnect()


def test_the_robot_class_has_lerobots_robot_interface(tmp_path: pathlib.Path) -> None:
    assert RobobusFollower.config_class is RobobusFollowerConfig
    assert RobobusFollower.name == "robobus_follower"
    for name in ROBOT_PROPERTIES:
        assert isinstance(inspect.getattr_static(RobobusFollower, name), property), name
    for name, params in ROBOT_METHODS.items():
        assert incompatible(getattr(RobobusFollower, name), params) is None, (name, incompatible(getattr(RobobusFollower, name), params))
    fields = [f.name for f in __import__("dataclasses").fields(RobobusFollowerConfig)]
    for name in ROBOT_CONFIG_FIELDS:
        assert name in fields, name
    robot = RobobusFollower(RobobusFollowerConfig(id="x", calibration_dir=tmp_path))
    for name in ROBOT_ATTRIBUTES:
        assert hasattr(robot, name), name
    assert str(robot) == "x RobobusFollower"
    assert robot.calibration_fpath == tmp_path / "x.json"
    assert robot.observation_features == robot.action_features == {f"j{i}.pos": float for i in range(1, 7)}
    assert robot.config.port == "sim" and not robot.is_connected
    with pytest.raises(ValueError, match="has no cameras"):
        RobobusFollower(RobobusFollowerConfig(cameras={"front": object()}, calibration_dir=tmp_path))


def test_the_robot_connects_calibrates_reads_and_writes_on_the_simulator(
    follower: RobobusFollower, tmp_path: pathlib.Path
) -> None:
    follower.connect()
    assert follower.is_connected and follower.is_calibrated
    with pytest.raises(DeviceAlreadyConnectedError):
        follower.connect()
    # Calibrated from the joints' own limits, saved in LeRobot's file format.
    saved = json.loads((tmp_path / "arm.json").read_text())
    assert list(saved) == [f"j{i}" for i in range(1, 7)]
    assert set(saved["j1"]) == {"id", "drive_mode", "homing_offset", "range_min", "range_max"}
    assert saved["j1"]["homing_offset"] == 0 and saved["j1"]["range_min"] < 0 < saved["j1"]["range_max"]
    station = follower.bus._station_()
    # configure() left every joint enabled in position mode.
    rows = station.whj.status("1-6")["results"]
    assert [(r["mode"], r["enabled"]) for r in rows] == [("position", True)] * 6
    obs = follower.get_observation()
    assert set(obs) == set(follower.observation_features)
    middle = {k: v for k, v in obs.items()}
    sent = follower.send_action({"j1.pos": middle["j1.pos"] + 1.0, "j3.pos": middle["j3.pos"] - 1.0})
    assert sent == {"j1.pos": middle["j1.pos"] + 1.0, "j3.pos": middle["j3.pos"] - 1.0}
    for _ in range(3000):
        now = follower.get_observation()
        if abs(now["j1.pos"] - sent["j1.pos"]) < 0.01 and abs(now["j3.pos"] - sent["j3.pos"]) < 0.01:
            break
    else:
        raise AssertionError(f"the joints never reached {sent}: {now}")
    assert now["j2.pos"] == pytest.approx(middle["j2.pos"], abs=0.01)
    with pytest.raises(ValueError, match=r"action: no motor \['gripper'\]; nothing was sent|no motor \['gripper'\]"):
        follower.send_action({"gripper.pos": 3.0})
    follower.disconnect()
    assert not follower.is_connected
    with pytest.raises(DeviceNotConnectedError):
        follower.get_observation()
    # A second robot of the same id finds the calibration file and needs no calibration.
    again = RobobusFollower(RobobusFollowerConfig(port="sim:virtual", id="arm", calibration_dir=tmp_path))
    assert again.calibration == follower.calibration
    again.connect(calibrate=False)
    assert again.is_calibrated
    again.disconnect()


def test_max_relative_target_caps_each_step_and_says_so(tmp_path: pathlib.Path) -> None:
    robot = RobobusFollower(
        RobobusFollowerConfig(port="sim:virtual", id="capped", calibration_dir=tmp_path, max_relative_target=0.5)
    )
    robot.connect()
    try:
        start = robot.get_observation()["j2.pos"]
        sent = robot.send_action({"j2.pos": start + 2.0})
        assert sent == {"j2.pos": pytest.approx(start + 0.5)}
    finally:
        robot.disconnect()


def test_configure_writes_the_configs_gains(tmp_path: pathlib.Path) -> None:
    robot = RobobusFollower(
        RobobusFollowerConfig(
            port="sim:virtual",
            id="tuned",
            calibration_dir=tmp_path,
            motors={"j1": Motor(1, "whj", MotorNormMode.DEGREES), "j2": Motor(2, "whj", MotorNormMode.RANGE_M100_100)},
            gains=(250, 1, 40),
        )
    )
    robot.connect()
    try:
        station = robot.bus._station_()
        for register, value in (("SEV_POSITION_P", 250), ("SEV_POSITION_I", 1), ("SEV_POSITION_D", 40)):
            for joint in ("1", "2"):
                assert station.whj.read(joint, register)["results"][0]["raw"] == value, (joint, register)
    finally:
        robot.disconnect()


def test_the_sim_port_runs_on_the_wall_clock_and_sim_virtual_on_the_virtual_one() -> None:
    for port, clock in (("sim", "wall"), ("sim:virtual", "virtual")):
        b = RobobusMotorsBus(port, {"shoulder": Motor(1, "whj", MotorNormMode.DEGREES)})
        b.connect()
        try:
            assert b._station_().clock == clock
        finally:
            b.disconnect()
