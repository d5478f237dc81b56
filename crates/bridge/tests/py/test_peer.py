"""A Zenoh peer in Python (eclipse-zenoh from PyPI) against `robobus bridge` on the
built-in simulated robot: joint states decoded with rosbags' ROS 2 types, commands that
move the simulator, the safety rules checked on the simulator's own state."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import textwrap
import time

import pytest
import zenoh

from bridgekit import (
    JOINT_STATE, TS, Bridge, Inbox, QueryError, command, health, joint_state, query, session,
    sim, wait_for, wck_steps, whj_deg,
)


@pytest.fixture(scope="module")
def bridge():
    b = Bridge("--rate", "50", "--command-timeout", "200")
    yield b
    assert b.stop() == 0


@pytest.fixture(scope="module")
def peer(bridge):
    s = session(bridge.endpoint)
    yield s
    s.close()


@pytest.fixture
def disarmed(peer):
    query(peer, "robobus/arm", "false")
    yield peer


@pytest.fixture
def armed(peer):
    assert query(peer, "robobus/arm", "true")["armed"] is True
    yield peer
    query(peer, "robobus/arm", "false")


def latest_state(peer) -> object:
    inbox = Inbox(peer, "joint_states")
    try:
        return joint_state(inbox.get())
    finally:
        inbox.sub.undeclare()


def targets_from(state, **moves) -> list[float]:
    """The joints' positions now, with `moves` (name: rad) added."""
    t = [float(p) for p in state.position]
    for name, delta in moves.items():
        t[list(state.name).index(name)] += delta
    return t


def test_joint_states_are_ros2_joint_states(peer):
    names = [j["name"] for j in query(peer, "robobus/arm")["joints"]]
    inbox = Inbox(peer, "joint_states")
    msgs = [inbox.get() for _ in range(5)]
    inbox.sub.undeclare()
    stamps = []
    for sample in msgs:
        raw = bytes(sample.payload.to_bytes())
        assert raw[:4] == b"\x00\x01\x00\x00"
        js = TS.deserialize_cdr(raw, JOINT_STATE)
        # rosbags writes the same bytes back: our encoder is byte for byte a ROS one.
        assert bytes(TS.serialize_cdr(js, JOINT_STATE)) == raw
        assert list(js.name) == names
        assert len(js.position) == len(js.velocity) == len(js.effort) == len(names)
        assert all(math.isfinite(p) and -math.pi < p < math.pi for p in js.position)
        # WHJ joints have an effort (from their current); wCK servos measure none.
        i = names.index("j1")
        assert math.isfinite(js.effort[i]) and math.isnan(js.effort[0])
        stamps.append(js.header.stamp.sec + js.header.stamp.nanosec * 1e-9)
    assert stamps == sorted(stamps) and len(set(stamps)) == 5
    assert abs(stamps[-1] - time.time()) < 5


def test_not_armed_nothing_moves(bridge, disarmed):
    peer = disarmed
    before_sim = sim(peer)
    h0 = health(peer)
    pub = peer.declare_publisher("joint_commands")
    t = targets_from(latest_state(peer), j1=0.3, s0=0.15)
    for _ in range(30):
        pub.put(command(t))
        time.sleep(0.01)
    pub.undeclare()
    h = wait_for(lambda: (x := health(peer))["refused"]["not_armed"]
                 >= h0["refused"]["not_armed"] + 1 and x, 5)
    assert h and h["commands"]["applied"] == h0["commands"]["applied"]
    assert "not armed" in h["refused"]["last"]
    after = sim(peer)
    assert whj_deg(after, 1) == pytest.approx(whj_deg(before_sim, 1), abs=0.01)
    assert wck_steps(after, 0) == wck_steps(before_sim, 0)


def test_commands_move_the_robot_and_a_quiet_stream_holds(armed):
    peer = armed
    start = latest_state(peer)
    t = targets_from(start, j1=0.2, s0=0.15)
    want_j1 = math.degrees(t[list(start.name).index("j1")])
    want_s0 = wck_steps(sim(peer), 0) + round(math.degrees(0.15) / (269 / 255))
    pub = peer.declare_publisher("joint_commands")
    deadline = time.monotonic() + 10
    reached = False
    while time.monotonic() < deadline and not reached:
        for _ in range(10):
            pub.put(command(t))
            time.sleep(0.01)
        now = sim(peer)
        reached = abs(whj_deg(now, 1) - want_j1) < 0.3 and abs(wck_steps(now, 0) - want_s0) <= 1
    pub.undeclare()
    stopped = time.monotonic()
    assert reached, sim(peer)
    # The stream went quiet: within the timeout (200 ms) and a margin, a hold.
    h = wait_for(lambda: (x := health(peer))["last_safe_stop"] and x, 5)
    assert h["last_safe_stop"]["reason"] == "command timeout"
    assert h["commands"]["holds"] >= 1 and h["armed"] is True and h["streaming"] is False
    held = {d["bus"] + "/" + str(d["id"]) for d in h["last_safe_stop"]["devices"]}
    assert "sim-whj/1" in held and "sim-wck/0" in held
    assert time.monotonic() - stopped < 5
    a = sim(peer)
    time.sleep(0.3)
    b = sim(peer)
    assert whj_deg(b, 1) == pytest.approx(whj_deg(a, 1), abs=0.05)
    assert wck_steps(b, 0) == wck_steps(a, 0)
    j1 = next(j for j in b["whj"] if j["id"] == 1)
    assert j1["enabled"] and j1["target_position_deg"] == pytest.approx(j1["position_deg"], abs=0.5)


def test_malformed_and_out_of_range_commands_are_refused_and_counted(armed):
    peer = armed
    state = latest_state(peer)
    before = sim(peer)
    h0 = health(peer)
    pub = peer.declare_publisher("joint_commands")
    n = len(state.name)
    bad_cdr = [b"", b"\x00\x01", b"\x00\x07\x00\x00" + bytes(16),
               b"\x00\x01\x00\x00" + b"\xff" * 12]
    out_of_range = [command([0.0] * (n - 1)), command([float("nan")] * n),
                    command(targets_from(state, j1=5.0))]
    for p in bad_cdr + out_of_range:
        pub.put(p)
        time.sleep(0.05)
    pub.undeclare()

    def counted():
        h = health(peer)
        ok = (h["refused"]["malformed"] - h0["refused"]["malformed"] == len(bad_cdr)
              and h["refused"]["out_of_range"] - h0["refused"]["out_of_range"] == len(out_of_range))
        return ok and h

    h = wait_for(counted, 5)
    assert h, health(peer)
    assert h["commands"]["applied"] == h0["commands"]["applied"]
    assert "soft limits" in h["refused"]["last"]
    after = sim(peer)
    assert whj_deg(after, 1) == pytest.approx(whj_deg(before, 1), abs=0.01)
    assert [s["position"] for s in after["wck"]] == [s["position"] for s in before["wck"]]


COMMANDER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, {path!r})
    from bridgekit import command, session
    s = session({endpoint!r})
    pub = s.declare_publisher("joint_commands")
    t = {targets!r}
    print("publishing", flush=True)
    while True:
        pub.put(command(t))
        time.sleep(0.01)
""")


def test_a_killed_commander_brings_its_joints_to_the_safe_state(bridge, armed):
    peer = armed
    state = latest_state(peer)
    t = targets_from(state, j2=1.5)
    start = whj_deg(sim(peer), 2)
    h0 = health(peer)
    import bridgekit
    code = COMMANDER.format(path=str(bridgekit.ROOT / "crates/bridge/tests/py"),
                            endpoint=bridge.endpoint, targets=t)
    cmd = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert cmd.stdout.readline().strip() == "publishing"
        moving = wait_for(lambda: abs(whj_deg(sim(peer), 2) - start) > 10, 10)
        assert moving, health(peer)
    finally:
        cmd.send_signal(signal.SIGKILL)
        cmd.wait()
    killed = time.monotonic()
    # The stream's end: the bridge no longer streaming after a safe stop. (A loaded
    # machine can stall the commander for longer than the timeout before the kill: that
    # hold is counted too, and the stream resumed after it, so the count alone does not
    # say the stream has ended.)
    h = wait_for(lambda: (x := health(peer))["safe_stops"] > h0["safe_stops"]
                 and not x["streaming"] and x, 5)
    assert h and h["last_safe_stop"]["reason"] == "command timeout", h
    assert time.monotonic() - killed < 5
    # Held: it settles where the hold caught it (within one jog step of where it was
    # at the kill), well short of the target it was streaming toward, and stays there.
    at_kill = whj_deg(sim(peer), 2)
    time.sleep(0.5)
    a = sim(peer)
    time.sleep(0.3)
    b = sim(peer)
    assert whj_deg(b, 2) == pytest.approx(whj_deg(a, 2), abs=0.05)
    assert whj_deg(b, 2) == pytest.approx(at_kill, abs=3)
    assert abs(whj_deg(b, 2) - math.degrees(t[list(state.name).index("j2")])) > 5


def test_any_operation_runs_through_the_queryable(disarmed):
    peer = disarmed
    report = query(peer, "robobus/run", '{"op": "whj.status", "joints": "1-2"}')
    assert report["op"] == "whj.status" and [r["id"] for r in report["results"]] == [1, 2]
    with pytest.raises(QueryError) as e:
        query(peer, "robobus/run", '{"op": "whj.fly"}')
    assert e.value.kind == "bad-input" and "whj.fly" in str(e.value)
    with pytest.raises(QueryError) as e:
        query(peer, "robobus/run", '{"op": "whj.move", "joint": 1, "degrees": 3}')
    assert e.value.kind == "refused" and "armed" in str(e.value)
    plan = query(peer, "robobus/plan", '{"op": "whj.move", "joint": 1, "degrees": 3}')
    assert plan["op"] == "whj.move" and plan["steps"]
    with pytest.raises(QueryError) as e:
        query(peer, "robobus/arm", "maybe")
    assert e.value.kind == "bad-input"


def test_liveliness_shows_the_bridge_come_and_go():
    b = Bridge("--namespace", "/site/arm1")
    s = session(b.endpoint)
    try:
        alive = Inbox(s, "site/arm1/robobus/bridge", liveliness=True)
        put = alive.get()
        assert str(put.key_expr) == "site/arm1/robobus/bridge"
        assert put.kind == zenoh.SampleKind.PUT
        # The namespace prefixes every key.
        assert joint_state(Inbox(s, "site/arm1/joint_states").get()).name[0] == "s0"
        assert b.stop() == 0
        # The session ended with the process; its token is withdrawn (a peer that loses
        # the bridge's session sees the same).
        gone = alive.get(10)
        assert gone.kind == zenoh.SampleKind.DELETE
    finally:
        b.kill()
        s.close()
