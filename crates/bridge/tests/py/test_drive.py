"""Velocity and effort commands from a Zenoh peer in Python: `robobus bridge --simulated
--robot crates/robobus/examples/sim_drive.toml` (the built-in simulators through a robot
file of a wheel `s0`, a WHJ joint `j1` with velocity and effort, and `j2` with position
alone), switched on `NS/robobus/interface`, commanded with `Float64MultiArray` written by
rosbags on `NS/joint_commands/velocity` and `NS/joint_commands/effort`, and seen in
`NS/joint_states` decoded by rosbags and in the simulators' own state."""

from __future__ import annotations

import math
import statistics
import time

import pytest

from bridgekit import (
    ROOT, Bridge, Inbox, QueryError, command, health, joint_state, query, session, sim,
    wait_for,
)

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    tomllib = None

ROBOT_FILE = ROOT / "crates" / "robobus" / "examples" / "sim_drive.toml"
NS = "bot"
# Tolerances: the WHJ joint's speed is what its speed mode reads back (0.1 RPM steps,
# 0.01 rad/s); the wheel's is fitted to the positions a wCK servo reads (about 1° a step,
# so ±0.02 rad) over at least 0.4 s of the states' stamps (a few ms of jitter).
WHJ_SPEED_TOLERANCE = 0.02  # of 0.5 rad/s
WHEEL_SPEED_TOLERANCE = 0.05  # of level 7's speed
# 0.5 N·m through the WHJ30's torque constant (30 N·m at 7.8 A) is 0.13 A; the current
# the joint measures has 5 mA of noise (0.02 N·m) and the drive's ripple.
EFFORT_TOLERANCE_NM = 0.05


def wheel_speeds() -> list[float]:
    """The robot file's wheel speeds of `s0` (levels 1..=15), rad/s."""
    if tomllib is not None:
        robot = tomllib.loads(ROBOT_FILE.read_text())
        return next(j["wheel_speeds"] for j in robot["joints"] if j["name"] == "s0")
    # The simulated wCK-1108 (as the file says): 400 °/s times k / 15, less 3 %.
    return [math.radians(400) * (k / 15 - 0.03) for k in range(1, 16)]


@pytest.fixture
def bot():
    """An armed bridge on the file, its WHJ joints enabled in position mode, and a peer."""
    bridge = Bridge("--simulated", "--robot", str(ROBOT_FILE), "--namespace", NS,
                    "--rate", "50", "--command-timeout", "200", "--armed")
    peer = session(bridge.endpoint)
    try:
        assert "3 joints (s0 j1 j2); ARMED" in bridge.first, bridge.first
        for r in ('{"op":"whj.mode","joints":"1-2","mode":"position"}',
                  '{"op":"whj.enable","joints":"1-2"}'):
            query(peer, f"{NS}/robobus/run", r)
        yield bridge, peer
    finally:
        peer.close()
        assert bridge.stop() == 0


def switch(peer, interface: str, joints: list[str]) -> dict:
    return query(peer, f"{NS}/robobus/interface",
                 f'{{"interface": "{interface}", "joints": {list(joints)!r}}}'.replace("'", '"'))


def stream(peer, key: str, values: list[float], seconds: float, states: Inbox | None = None):
    """Publishes `values` every 20 ms for `seconds`; the joint states received meanwhile."""
    publisher = peer.declare_publisher(f"{NS}/joint_commands/{key}")
    seen = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        publisher.put(command(values))
        time.sleep(0.02)
        while states is not None and not states.q.empty():
            seen.append(joint_state(states.q.get_nowait()))
    publisher.undeclare()
    return seen


def stamp(state) -> float:
    return state.header.stamp.sec + state.header.stamp.nanosec * 1e-9


def wheel_speed(states) -> float:
    """The least-squares slope of joint 0's position against the stamps, rad/s, over the
    longest run of states whose positions increase (at least 0.4 s of them)."""
    runs, run = [], []
    for s in states:
        if run and s.position[0] <= run[-1].position[0]:
            runs.append(run)
            run = []
        run.append(s)
    runs.append(run)
    best = max(runs, key=len)
    t = [stamp(s) for s in best]
    p = [float(s.position[0]) for s in best]
    assert t[-1] - t[0] >= 0.4, [round(float(s.position[0]), 3) for s in states]
    tm, pm = statistics.fmean(t), statistics.fmean(p)
    return (sum((a - tm) * (b - pm) for a, b in zip(t, p))
            / sum((a - tm) ** 2 for a in t))


def whj(snapshot: dict, joint: int) -> dict:
    return next(j for j in snapshot["whj"] if j["id"] == joint)


def wck(snapshot: dict, servo: int) -> dict:
    return next(s for s in snapshot["wck"] if s["id"] == servo)


def test_a_wheel_and_a_whj_joint_turn_at_the_asked_velocity_until_the_stream_stops(bot):
    bridge, peer = bot
    reply = switch(peer, "velocity", ["s0", "j1"])
    assert reply["velocity"] == ["s0", "j1"], reply
    assert {j["name"]: j["interface"] for j in reply["joints"]} == {
        "s0": "velocity", "j1": "velocity", "j2": "position"}
    level_7 = wheel_speeds()[6]
    states = Inbox(peer, f"{NS}/joint_states")
    # 1 s to reach the speeds (ramped at max_acceleration), then 2 s measured.
    stream(peer, "velocity", [level_7, 0.5], 1.0)
    states.drain()
    seen = stream(peer, "velocity", [level_7, 0.5], 2.0, states)
    assert len(seen) >= 50, len(seen)
    assert all(list(s.name) == ["s0", "j1", "j2"] for s in seen)
    # The simulators: the servo in wheel mode, the joint in speed mode (2).
    snap = sim(peer, f"{NS}/")
    assert wck(snap, 0)["mode"] == "wheel", wck(snap, 0)
    assert whj(snap, 1)["mode"] == 2, whj(snap, 1)
    assert whj(snap, 2)["mode"] == 3, whj(snap, 2)
    # j1 at 0.5 rad/s in every state; j2 still.
    j1 = [s.velocity[1] for s in seen]
    assert all(abs(v - 0.5) <= WHJ_SPEED_TOLERANCE * 0.5 for v in j1), j1
    assert all(abs(s.velocity[2]) < 0.01 for s in seen), [s.velocity[2] for s in seen]
    # The wheel: a wCK servo reads positions over 269° of a turn (in steps of about 1°),
    # its end step over the rest, and wraps once a turn: its speed is the slope of the
    # positions against the states' stamps over the longest run that moves forward.
    wheel = wheel_speed(seen)
    assert abs(wheel - level_7) <= WHEEL_SPEED_TOLERANCE * level_7, (wheel, level_7)
    h = health(peer, f"{NS}/")["drives"]
    assert h["velocity"]["applied"] > 100 and h["velocity"]["refused_out_of_range"] == 0, h
    # The stream stops: after --command-timeout (200 ms) the watchdog brings both to rest
    # and back on position.
    back = wait_for(lambda: (lambda n: n if whj(n, 1)["mode"] == 3
                             and wck(n, 0)["mode"] != "wheel" else None)(sim(peer, f"{NS}/")),
                    timeout=5, step=0.05)
    assert back, sim(peer, f"{NS}/")
    assert whj(back, 1)["target_speed_rpm"] == 0.0, whj(back, 1)
    h = wait_for(lambda: (lambda h: h if h["velocity"]["timeouts"] == 1 else None)(
        health(peer, f"{NS}/")["drives"]), timeout=5)
    assert h and h["velocity_joints"] == [] and "command timeout: s0, j1" in h["last"], h
    # At rest in the joint states too.
    states.drain()
    still = wait_for(lambda: (lambda s: s if abs(s.velocity[1]) < 0.01 else None)(
        joint_state(states.get())), timeout=5)
    assert still, "j1 still turning after the stream stopped"
    states.sub.undeclare()


def test_a_joint_without_the_interface_is_refused_nothing_sent_and_counted(bot):
    bridge, peer = bot
    for interface in ("velocity", "effort"):
        with pytest.raises(QueryError) as e:
            switch(peer, interface, ["j2"])
        assert e.value.kind == "bad-input", e.value.body
        assert str(e.value) == (f"j2 {interface}: an interface the robot file gives it: "
                                "position; nothing was sent"), e.value.body
    # The whole switch is refused: s0 too stays on position.
    with pytest.raises(QueryError):
        switch(peer, "velocity", ["s0", "j2"])
    reply = query(peer, f"{NS}/robobus/interface")
    assert (reply["velocity"], reply["effort"]) == ([], []), reply
    snap = sim(peer, f"{NS}/")
    assert whj(snap, 2)["mode"] == 3 and wck(snap, 0)["mode"] != "wheel", snap
    # Commands for joints that are on no such interface: refused, counted, nothing sent.
    stream(peer, "effort", [0.5], 0.2)
    stream(peer, "velocity", [0.5], 0.2)
    h = wait_for(lambda: (lambda h: h if h["effort"]["refused_out_of_range"] >= 5
                          and h["velocity"]["refused_out_of_range"] >= 5 else None)(
        health(peer, f"{NS}/")["drives"]), timeout=5)
    assert h, health(peer, f"{NS}/")["drives"]
    assert h["effort"]["applied"] == 0 and h["velocity"]["applied"] == 0, h
    assert "no joint is on its" in h["last"], h
    snap = sim(peer, f"{NS}/")
    assert [whj(snap, j)["mode"] for j in (1, 2)] == [3, 3], snap
    assert wck(snap, 0)["mode"] != "wheel", snap


def test_an_effort_drives_the_whj_joint_in_current_mode(bot):
    bridge, peer = bot
    assert switch(peer, "effort", ["j1"])["effort"] == ["j1"]
    states = Inbox(peer, f"{NS}/joint_states")
    stream(peer, "effort", [0.5], 0.3)
    states.drain()
    seen = stream(peer, "effort", [0.5], 0.5, states)
    snap = sim(peer, f"{NS}/")
    j1 = whj(snap, 1)
    assert j1["mode"] == 1, j1
    assert abs(j1["current_a"] - 0.5 / (30.0 / 7.8)) < EFFORT_TOLERANCE_NM / (30.0 / 7.8) + 0.01, j1
    efforts = [s.effort[1] for s in seen]
    assert len(efforts) >= 10 and all(abs(e - 0.5) <= EFFORT_TOLERANCE_NM for e in efforts), efforts
    h = health(peer, f"{NS}/")["drives"]
    assert h["effort"]["applied"] > 20 and h["effort"]["refused_out_of_range"] == 0, h
    # Quiet: back on position (6 s at most: rest first).
    back = wait_for(lambda: (lambda n: n if whj(n, 1)["mode"] == 3 else None)(
        sim(peer, f"{NS}/")), timeout=5, step=0.05)
    assert back, sim(peer, f"{NS}/")
    states.sub.undeclare()
