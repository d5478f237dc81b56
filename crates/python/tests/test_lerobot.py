"""The LeRobot motors bus (`robobus.lerobot`): its method set is LeRobot's (checked against a
recorded list of LeRobot's signatures, and against LeRobot itself when it imports), and it
drives the simulated robot's wCK servos and WHJ joints as LeRobot drives its motors: the
handshake, calibration and normalisation, torque, sync reads and writes with nothing sent
on a refusal, homing, range recording, scans and motor setup on the simulator's pty.
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
    b = RobobusMotorsBus("sim", MOTORS)
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
    missing = RobobusMotorsBus("sim", {"a": Motor(0, "wck", MotorNormMode.DEGREES), "b": Motor(20, "wck", MotorNormMode.DEGREES)})
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
    assert RobobusMotorsBus.scan_port("sim") == {115200: list(range(16))}
    assert RobobusMotorsBus.scan_port("sim", family="whj") == {115200: list(range(1, 8))}


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
