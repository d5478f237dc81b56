"""A station's life in Python: `close()` (and leaving its `with`, dropping it, and leaving
Python with it still held) closes whatever runs on it (telemetry streams, cyclic loops,
calls on other threads) with every device in its safe state and the ports released, and
every later call raises naming the call; a forked child refuses the inherited station at
once instead of hanging, and can open its own; a device that failed raises its kind's error
unless the rows are asked for.

The command-line binary is `$ROBOBUS_BIN`, else the workspace's target/debug/robobus.
"""

from __future__ import annotations

import gc
import json
import os
import pathlib
import subprocess
import sys
import threading
import time

import pytest

import robobus

ROOT = pathlib.Path(__file__).resolve().parents[3]
BIN = os.environ.get("ROBOBUS_BIN", str(ROOT / "target" / "debug" / "robobus"))
INSIDE_NETNS = "ROBOBUS_PY_IN_NETNS"


def in_private_netns(body: str) -> None:
    """Runs `test_lifecycle.<body>()` inside `unshare -n` (loopback up, a multicast route on
    it), so the simulators' UDP bus cannot reach any other machine."""
    script = (
        "set -eu\n"
        "ip link set lo up\n"
        "ip route add 224.0.0.0/4 dev lo\n"
        f'cd "{pathlib.Path(__file__).parent}"\n'
        f'exec "{sys.executable}" -c "import test_lifecycle; test_lifecycle.{body}()"\n'
    )
    r = subprocess.run(
        ["timeout", "120", "unshare", "-n", "bash", "-c", script],
        capture_output=True,
        text=True,
        env={**os.environ, INSIDE_NETNS: "1"},
    )
    assert r.returncode == 0 and f"{body} passed" in r.stdout, r.stdout + r.stderr


def serving(sim: subprocess.Popen[str]) -> None:
    """Waits until `robobus sim whj` says it serves."""
    assert sim.stderr is not None
    deadline = time.monotonic() + 20
    seen = ""
    while "serving" not in seen:
        assert time.monotonic() < deadline, seen
        line = sim.stderr.readline()
        assert line, seen
        seen += line


def test_close_with_a_stream_and_a_loop_open_stops_both_leaves_the_joint_disabled_and_frees_the_port() -> None:
    in_private_netns("close_body")


def close_body() -> None:
    """The body of the test above, run by it inside the namespace: the joint and the port
    are simulated in processes of their own, so a fresh station reads what `close` left."""
    assert os.environ.get(INSIDE_NETNS) == "1"
    bus = "udp:239.74.163.41:43151"
    whj = subprocess.Popen(
        [BIN, "sim", "whj", "--joints", "1", "--bus", bus, "--current-noise-ma", "0"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    wck = subprocess.Popen(
        [BIN, "sim", "wck", "--servos", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        serving(whj)
        assert wck.stdout is not None
        port = wck.stdout.readline().strip()
        assert port.startswith("/"), port
        station = robobus.Station.open([port], [bus], reply_margin_ms=50)
        station.whj.mode("1", "position")
        station.whj.enable("1")
        stream = station.telemetry({"op": "whj.status", "joints": "1"}, 20.0)
        assert stream.next(timeout=5) is not None
        servo = station.wck_servo(0)
        joint = station.whj_joint(1)
        loop = station.cyclic([1], rate_hz=100)
        loop.set([60.0])
        # The loop moves the joint (along its speed-limited profile).
        first = loop.next(2.0)
        time.sleep(0.3)
        loop.clear()
        later = loop.next(2.0)
        assert first is not None and later is not None
        assert later.position_deg[0] - first.position_deg[0] > 1.0, (first, later)

        assert station.close() == []
        assert station.closed
        assert station.close() == []
        # The port is free at once.
        with robobus.open_wck(port, reply_margin_ms=50) as again:
            assert again.wck.status("0")["results"][0]["position"] == 127
        # The joint is disabled (its safe state) and stands still: the loop sends no more.
        with robobus.open_whj(bus) as fresh:
            a = fresh.whj.status("1")["results"][0]
            time.sleep(0.3)
            b = fresh.whj.status("1")["results"][0]
        assert a["enabled"] is False and b["enabled"] is False, (a, b)
        assert abs(b["position_deg"] - a["position_deg"]) < 0.05, (a, b)
        # Every later call raises, naming the call; stopping what was stopped is quiet.
        for call, name in [
            (lambda: station.whj.status("1"), r"Station.run\(whj.status\)"),
            (lambda: station.telemetry({"op": "whj.status", "joints": "1"}, 20.0), "Station.telemetry"),
            (lambda: station.cyclic([1]), "Station.cyclic"),
            (lambda: stream.next(timeout=1), "Telemetry.next"),
            (lambda: loop.next(1.0), "Cyclic.next"),
            (lambda: loop.set([0.0]), "Cyclic.set"),
            (servo.status, "WckServos.status"),
            (joint.status, "WhjJoints.status"),
        ]:
            with pytest.raises(robobus.BadInputError, match=f"{name}: the station is closed"):
                call()
        assert stream.stop() is None and loop.stop() is None

        print("close_body passed")
    finally:
        for sim in (whj, wck):
            sim.terminate()
            sim.wait(timeout=20)


def test_dropping_a_station_stops_its_stream_and_loop() -> None:
    station = robobus.Station.simulated()
    station.whj.mode("1", "position")
    station.whj.enable("1")
    stream = station.telemetry({"op": "whj.status", "joints": "1"}, 20.0)
    loop = station.cyclic([1], rate_hz=100)
    assert loop.next(2.0) is not None and stream.next(timeout=5) is not None
    del station
    gc.collect()
    with pytest.raises(robobus.BadInputError, match="Telemetry.next: the station is closed"):
        stream.next(timeout=1)
    with pytest.raises(robobus.BadInputError, match="Cyclic.next: the station is closed"):
        loop.next(1.0)
    assert stream.stop() is None and loop.stop() is None


def test_close_stops_a_call_under_way_on_another_thread() -> None:
    station = robobus.Station.simulated()
    station.whj.mode("1", "position")
    station.whj.enable("1")
    raised: list[BaseException] = []

    def long_move() -> None:
        try:
            # 90 degrees at 0.1 deg/s: minutes, were it not stopped.
            station.whj.move(1, 90.0, max_speed=0.1)
        except BaseException as e:  # noqa: BLE001 - recorded for the assertion
            raised.append(e)

    t = threading.Thread(target=long_move)
    t.start()
    time.sleep(0.2)
    assert t.is_alive()
    assert station.close() == []
    t.join(timeout=10)
    assert not t.is_alive()
    assert len(raised) == 1 and isinstance(raised[0], robobus.StoppedError), raised


FORK_SCRIPT = r"""
import json, multiprocessing, os, sys, time
import robobus

station = robobus.Station.simulated()
station.whj.mode("1", "position")
station.whj.enable("1")
stream = station.telemetry({"op": "whj.status", "joints": "1"}, 50.0)
assert stream.next(timeout=5) is not None


def inherited(out):
    t = time.monotonic()
    for name, call in [
        ("run", lambda: station.wck.status("0")),
        ("stream", lambda: stream.next(timeout=1)),
        ("close", station.close),
    ]:
        try:
            call()
            out[name] = "no error"
        except robobus.RefusedError as e:
            out[name] = str(e)
    out["seconds"] = time.monotonic() - t
    out["repr"] = repr(station)
    # A station of its own works in the child.
    with robobus.Station.simulated() as mine:
        out["fresh"] = mine.wck.status("0")["results"][0]["position"]


pid = os.fork()
if pid == 0:
    out = {}
    inherited(out)
    print("child " + json.dumps(out), flush=True)
    # Leaving normally: the interpreter drops the inherited station and stream here,
    # which must neither hang nor touch the parent's devices.
    sys.exit(0)
_, status = os.waitpid(pid, 0)
print("exit " + str(status), flush=True)


def target(q):
    out = {}
    inherited(out)
    q.put(out)


ctx = multiprocessing.get_context("fork")
q = ctx.Queue()
p = ctx.Process(target=target, args=(q,))
p.start()
print("mp " + json.dumps(q.get(timeout=30)), flush=True)
p.join(30)
print("mp-exit " + str(p.exitcode), flush=True)
# The parent's station and stream still work.
row = station.whj.status("1")["results"][0]
print("parent " + json.dumps({"enabled": row["enabled"], "sample": stream.next(timeout=5) is not None}))
stream.stop()
station.close()
"""


def test_a_forked_child_refuses_the_inherited_station_at_once_and_the_parent_keeps_it() -> None:
    r = subprocess.run(
        [sys.executable, "-W", "ignore::DeprecationWarning", "-c", FORK_SCRIPT],
        capture_output=True,
        text=True,
        timeout=90,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    lines = dict(line.split(" ", 1) for line in r.stdout.splitlines())
    assert lines["exit"] == "0" and lines["mp-exit"] == "0", r.stdout + r.stderr
    for child in (json.loads(lines["child"]), json.loads(lines["mp"])):
        assert child["seconds"] < 1.0, child
        for name, call in [("run", r"Station.run\(wck.status\)"), ("stream", "Telemetry.next"), ("close", "Station.close")]:
            msg = child[name]
            assert msg.startswith(call.replace("\\", "") + ": this station was opened in process"), child
            assert "a fork of it" in msg and "open a new station in this one" in msg, child
        assert child["repr"] == "<robobus.Station of another process>", child
        assert child["fresh"] == 127, child
    assert json.loads(lines["parent"]) == {"enabled": True, "sample": True}


def test_a_silent_device_raises_no_device_error_unless_the_rows_are_asked_for() -> None:
    # On the virtual clock: each silent device's reply timeouts pass at once (on the wall
    # clock its six timed-out requests took 11 s), the errors and rows are the same.
    with robobus.Station.simulated(clock="virtual") as station:
        with pytest.raises(robobus.NoDeviceError) as silent:
            station.wck.status("20")
        assert isinstance(silent.value, TimeoutError)
        assert silent.value.kind == "no-device"
        assert silent.value.report is not None and silent.value.report["failed"] == "no-device"
        with pytest.raises(robobus.NoDeviceError):
            station.run({"op": "whj.status", "joints": "9"})
        with pytest.raises(robobus.NoDeviceError):
            station.run_many([{"op": "wck.status", "ids": "0"}, {"op": "wck.status", "ids": "20"}])
        rows = station.wck.status("0,20", check=False)["results"]
        assert rows[0]["position"] == 127 and rows[1]["kind"] == "no-device", rows
        report = station.run({"op": "whj.status", "joints": "9"}, check=False)
        assert report["failed"] == "no-device" and report["results"][0]["id"] == 9, report
        assert len(station.run_many([{"op": "wck.status", "ids": "20"}], check=False)) == 1



EXIT_SCRIPT = r"""
import sys, threading, time
import robobus

station = robobus.open_whj(sys.argv[1])
station.whj.mode("1", "position")
station.whj.enable("1")
stream = station.telemetry({"op": "whj.status", "joints": "1"}, 100.0)
loop = station.cyclic([1], rate_hz=100)
loop.set([30.0])
assert stream.next(timeout=5) is not None and loop.next(2.0) is not None
# A daemon thread still holds the station: the interpreter never frees it.
threading.Thread(target=lambda held=(station, stream, loop): time.sleep(1000), daemon=True).start()
print("leaving", flush=True)
"""


def test_leaving_python_with_a_station_still_held_closes_it() -> None:
    in_private_netns("exit_body")


def exit_body() -> None:
    """The body of the test above, inside the namespace: a script leaves Python with a
    station open, a stream and a loop running and the joint enabled; the joint is then
    disabled (the station was closed at exit) and Python left without a panic."""
    assert os.environ.get(INSIDE_NETNS) == "1"
    bus = "udp:239.74.163.42:43152"
    whj = subprocess.Popen(
        [BIN, "sim", "whj", "--joints", "1", "--bus", bus, "--current-noise-ma", "0"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        serving(whj)
        r = subprocess.run(
            [sys.executable, "-c", EXIT_SCRIPT, bus], capture_output=True, text=True, timeout=60
        )
        assert r.returncode == 0 and r.stdout == "leaving\n", r.stdout + r.stderr
        assert "panicked" not in r.stderr, r.stderr
        with robobus.open_whj(bus) as fresh:
            row = fresh.whj.status("1")["results"][0]
        assert row["enabled"] is False, row
        print("exit_body passed")
    finally:
        whj.terminate()
        whj.wait(timeout=20)
