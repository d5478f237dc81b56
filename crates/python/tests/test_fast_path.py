"""The fast path: a call runs on the calling thread with the GIL released while the bus
works (no hand-off to a worker thread), requests cross as Python objects walked natively
(bounded, every bad value named), the single-device handles give dicts built natively, and
reading N joints into a numpy array is one call that gives what the per-joint reads give.

The command-line binary is `$ROBOBUS_BIN`, else the workspace's target/debug/robobus.
"""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import threading
import time
from typing import Any, Iterator

import numpy as np
import pytest

import robobus

ROOT = pathlib.Path(__file__).resolve().parents[3]
BIN = os.environ.get("ROBOBUS_BIN", str(ROOT / "target" / "debug" / "robobus"))


@pytest.fixture
def station() -> Iterator[robobus.Station]:
    with robobus.Station.simulated() as s:
        yield s


def _threads_named(prefix: str) -> list[str]:
    names = []
    for task in pathlib.Path("/proc/self/task").iterdir():
        try:
            names.append((task / "comm").read_text().strip())
        except OSError:
            pass
    return [n for n in names if n.startswith(prefix)]


def test_a_request_on_the_main_thread_runs_there_without_a_worker_thread(
    station: robobus.Station,
) -> None:
    assert threading.current_thread() is threading.main_thread()
    for _ in range(3):
        station.run({"op": "wck.status", "ids": [0]})
    # The earlier design handed every request to a thread of this name.
    assert _threads_named("robobus-main") == []


def test_the_whj_read_positions_is_one_array_equal_to_the_per_joint_reads(
    station: robobus.Station,
) -> None:
    ids = [1, 2, 3, 4, 5, 6, 7]
    joints = station.whj_joints(ids)
    got = joints.read_positions()
    assert isinstance(got, np.ndarray) and got.dtype == np.float64 and got.shape == (7,)
    # The joints rest: each one's own status read gives the same value.
    each = [station.whj_joint(i).status()["position_deg"] for i in ids]
    assert got.tolist() == each
    assert joints.status().position_deg.tolist() == each
    assert joints.read_positions(check=False).tolist() == each


def test_the_wck_read_positions_marks_a_silent_servo_nan_or_raises(
    station: robobus.Station,
) -> None:
    group = station.wck_servos([0, 20, 2])
    got = group.read_positions(check=False)
    assert got.dtype == np.float64 and got.shape == (3,)
    each = group.status()
    assert np.isnan(got[1]) and got[[0, 2]].tolist() == each.position_deg[[0, 2]].tolist()
    with pytest.raises(robobus.NoDeviceError, match="servo 20 did not answer"):
        group.read_positions()


def test_single_device_calls_give_dicts_and_refuse_a_non_number(station: robobus.Station) -> None:
    servo = station.wck_servo(3)
    per_step = robobus._robobus.facts()["wck_degrees_per_step"]
    assert servo.status() == {"position": 127.0, "position_deg": 127 * per_step, "load": 0.0}
    with pytest.raises(robobus.BadInputError, match="position: 'a' is not a number; nothing was sent"):
        servo.move("a")  # type: ignore[arg-type]
    with pytest.raises(robobus.BadInputError, match="position of servo 3 300"):
        servo.move(300)
    station.whj.mode("1", "position", check=True)
    station.whj.enable("1", check=True)
    joint = station.whj_joint(1)
    st = joint.status()
    assert set(st) == {"position_deg", "speed_rpm", "current_ma", "enabled", "errors"}
    assert st["enabled"] is True and st["errors"] == "no error"
    fb = joint.command_position(st["position_deg"])
    assert fb["position_deg"] == pytest.approx(st["position_deg"], abs=0.01)
    with pytest.raises(robobus.BadInputError, match="target: None is not a number"):
        joint.command_position(None)  # type: ignore[arg-type]
    with pytest.raises(robobus.NoDeviceError):
        station.wck_servo(20).status()


def _nested(depth: int) -> list[Any]:
    v: list[Any] = [1]
    for _ in range(depth):
        v = [v]
    return v


@pytest.mark.parametrize(
    ("request_", "message"),
    [
        ({"op": "wck.status", "ids": float("nan")}, "the number NaN is not finite"),
        ({"op": "wck.status", "ids": {1, 2}}, "a set is not a JSON value"),
        ({"op": "wck.status", 3: "0-2"}, "the key 3 is not a string"),
        ({"op": "wck.status", "ids": 2**70}, "out of range (allowed: 64-bit integers)"),
        ({"op": "wck.status", "ids": "x" * (5 << 20)}, "over 4194304 bytes"),
        ({"op": "wck.status", "ids": _nested(40)}, "nested deeper than 32 levels"),
    ],
    ids=["nan", "set", "key", "bigint", "size", "depth"],
)
def test_a_request_that_is_not_json_is_refused_naming_the_value(
    station: robobus.Station, request_: dict[Any, Any], message: str
) -> None:
    with pytest.raises(robobus.BadInputError, match=message.replace("(", r"\(").replace(")", r"\)")) as e:
        station.run(request_)
    assert "nothing was sent" in str(e.value)


def test_a_request_takes_numpy_values_tuples_and_json_text(station: robobus.Station) -> None:
    want = station.run({"op": "wck.status", "ids": [0, 1, 2]})
    assert station.run({"op": "wck.status", "ids": np.arange(3)}) == want
    assert station.run({"op": "wck.status", "ids": (np.int16(0), 1, 2)}) == want
    assert station.run('{"op": "wck.status", "ids": [0, 1, 2]}') == want
    # A float stays a float, as Python's json writes it: refused where a whole number goes.
    with pytest.raises(robobus.BadInputError, match="nothing was sent"):
        station.run({"op": "wck.status", "ids": [0.0, 1, 2]})
    # The report keeps the library's field order.
    assert list(want)[:2] == ["op", "bus"]


def test_a_handle_call_releases_the_gil_while_it_waits_on_the_bus() -> None:
    sim = subprocess.Popen([BIN, "sim", "wck", "--servos", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert sim.stdout is not None
        port = sim.stdout.readline().strip()
        with robobus.open_wck(port, reply_margin_ms=20) as station:
            # Four servos that do not answer: each read waits out its reply time (about
            # 0.3 s each, so the call lasts over a second).
            group = station.wck_servos(range(1, 5))
            stamps: list[float] = []
            done = threading.Event()

            def other() -> None:
                while not done.is_set():
                    stamps.append(time.monotonic())
                    time.sleep(0.001)

            t = threading.Thread(target=other)
            t.start()
            time.sleep(0.05)
            t0 = time.monotonic()
            got = group.status()
            t1 = time.monotonic()
            done.set()
            t.join()
        assert not got.valid.any()
        assert t1 - t0 >= 0.3, t1 - t0
        # With the GIL held through the call the other thread could not run at all between
        # the call's first and last 50 ms (it might just before the call started: Python
        # switches threads every 5 ms).
        inside = [s for s in stamps if t0 + 0.05 < s < t1 - 0.05]
        assert len(inside) >= 10, (len(inside), t1 - t0)
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait(timeout=20)


@pytest.mark.parametrize(
    "request_",
    [
        {"op": "whj.move", "joint": 1, "degrees": -12.5, "from": -3, "max_speed": 1e1, "rate_hz": 200},
        {"op": "wck.sync-move", "positions": (10, 40, 70)},
        {"op": "whj.status", "joints": [1, 2, -9223372036854775808]},
        {"op": "whj.status", "joints": 18446744073709551615},
        {"op": "wck.status", "ids": 'é0,"1\\\n\u0001\t'},
        {"op": "wck.status", "ids": [True, False, None, {"a": [1.5, -0.0]}]},
    ],
    ids=["numbers", "tuple", "i64-min", "u64-max", "escapes", "nested"],
)
def test_a_request_dict_reads_as_its_json_text_reads(request_: dict[str, Any]) -> None:
    """The dict is written natively as JSON text: the library sees what it sees of the
    text Python's json writes (the same plan, or the same refusal naming the same value)."""
    import json

    def outcome(r: dict[str, Any] | str) -> tuple[str, Any]:
        try:
            return ("plan", robobus.plan(r))
        except robobus.RobobusError as e:
            return (type(e).__name__, str(e))

    assert outcome(request_) == outcome(json.dumps(request_))
