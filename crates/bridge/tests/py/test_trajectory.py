"""A Zenoh peer in Python publishes trajectory_msgs/msg/JointTrajectory written by rosbags
on `joint_trajectory`: the simulated arm of `robobus bridge` follows it to its points on
time (its progress on `controller_state`, control_msgs 5's JointTrajectoryControllerState
read by rosbags; its end on `joint_trajectory/result`), a bad one is refused whole and
nothing moves, an unarmed bridge refuses. The golden vectors of robobus::cdr are checked
against what rosbags writes."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from rosbags.typesys import get_types_from_msg

from bridgekit import TS, Bridge, Inbox, health, query, session, sim, wait_for, whj_deg

TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"
STATE = "control_msgs/msg/JointTrajectoryControllerState"
# control_msgs 5 (ROS 2 Jazzy and later): what the bridge writes on controller_state.
TS.register(get_types_from_msg("""std_msgs/Header header
string[] joint_names
trajectory_msgs/JointTrajectoryPoint reference
trajectory_msgs/JointTrajectoryPoint feedback
trajectory_msgs/JointTrajectoryPoint error
trajectory_msgs/JointTrajectoryPoint output
string[] multi_dof_joint_names
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_reference
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_feedback
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_output
""", STATE))
T = TS.types
# How close to a point a joint must be at the tick the point is due, degrees (its reading
# at a tick answers that tick's command, before it moved toward it: one tick of a 2 rad/s
# joint at 50 Hz is 2.3 degrees), and at the end (the bridge's goal tolerance).
ON_TIME_DEG = 1.5
TOLERANCE_DEG = 1.0


def array(*v: float) -> np.ndarray:
    return np.array(v, dtype=np.float64)


def point(t: float, positions, velocities=()):
    sec = math.floor(t)
    return T["trajectory_msgs/msg/JointTrajectoryPoint"](
        positions=array(*positions), velocities=array(*velocities), accelerations=array(),
        effort=array(), time_from_start=T["builtin_interfaces/msg/Duration"](
            sec=sec, nanosec=round((t - sec) * 1e9)))


def trajectory(names, points, stamp=(0, 0), frame="") -> bytes:
    msg = T[TRAJECTORY](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=stamp[0], nanosec=stamp[1]),
            frame_id=frame),
        joint_names=list(names), points=list(points))
    return bytes(TS.serialize_cdr(msg, TRAJECTORY))


def test_the_golden_vectors_are_the_bytes_rosbags_writes():
    # robobus::cdr's GOLDEN_TRAJECTORY and GOLDEN_CONTROLLER_STATE (crates/robobus/src/cdr.rs).
    raw = trajectory(["j1", "j2"], [point(1.5, [0.5, -0.25], [0.0, 0.1]), point(2.0, [1.0, 0.0])],
                     stamp=(3, 4), frame="base")
    assert raw.hex() == (
        "00010000030000000400000005000000626173650000000002000000030000006a31000003000000"
        "6a3200000200000002000000000000000000e03f000000000000d0bf020000000000000000000000"
        "000000009a9999999999b93f0000000000000000010000000065cd1d020000000000000000000000"
        "0000f03f00000000000000000000000000000000000000000200000000000000")
    P = T["trajectory_msgs/msg/JointTrajectoryPoint"]
    D = T["builtin_interfaces/msg/Duration"]
    M = T["trajectory_msgs/msg/MultiDOFJointTrajectoryPoint"]
    pt = lambda p: P(positions=array(p), velocities=array(), accelerations=array(),  # noqa: E731
                     effort=array(), time_from_start=D(sec=0, nanosec=250000000))
    md = M(transforms=[], velocities=[], accelerations=[], time_from_start=D(sec=0, nanosec=0))
    state = T[STATE](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=5, nanosec=6),
                                        frame_id=""),
        joint_names=["j3"], reference=pt(0.5), feedback=pt(0.25), error=pt(0.25), output=pt(0.5),
        multi_dof_joint_names=[], multi_dof_reference=md, multi_dof_feedback=md,
        multi_dof_error=md, multi_dof_output=md)
    raw = bytes(TS.serialize_cdr(state, STATE))
    assert len(raw) == 244
    assert raw.hex() == (
        "000100000500000006000000010000000000000001000000030000006a3300000100000000000000"
        "0000e03f0000000000000000000000000000000080b2e60e01000000000000000000d03f00000000"
        "00000000000000000000000080b2e60e01000000000000000000d03f000000000000000000000000"
        "0000000080b2e60e01000000000000000000e03f0000000000000000000000000000000080b2e60e"
        "00000000000000000000000000000000000000000000000000000000000000000000000000000000"
        "00000000000000000000000000000000000000000000000000000000000000000000000000000000"
        "00000000")


@pytest.fixture(scope="module")
def bridge():
    b = Bridge("--rate", "20")
    yield b
    assert b.stop() == 0


@pytest.fixture(scope="module")
def peer(bridge):
    s = session(bridge.endpoint)
    yield s
    s.close()


@pytest.fixture
def armed(peer):
    assert query(peer, "robobus/arm", "true")["armed"] is True
    for r in ({"op": "whj.mode", "joints": "1-7", "mode": "position"},
              {"op": "whj.enable", "joints": "1-7"}):
        query(peer, "robobus/run", json.dumps(r))
    yield peer
    query(peer, "robobus/arm", "false")


def send(peer, payload: bytes, states: bool = True):
    """Publishes `payload` on joint_trajectory; its result, and the controller states."""
    results = Inbox(peer, "joint_trajectory/result")
    progress = Inbox(peer, "controller_state")
    pub = peer.declare_publisher("joint_trajectory")
    # The bridge's subscriber is matched before the trajectory goes.
    assert wait_for(lambda: pub.matching_status.matching, 10)
    pub.put(payload)
    result = json.loads(results.get(timeout=60).payload.to_string())
    got = []
    while not progress.q.empty():
        got.append(TS.deserialize_cdr(bytes(progress.q.get_nowait().payload.to_bytes()), STATE))
    for i in (results, progress):
        i.sub.undeclare()
    pub.undeclare()
    return result, got


def test_a_rosbags_trajectory_is_followed_to_its_points_on_time(armed):
    before = sim(armed)
    # j3 to 15 degrees at 1 s, back to 5 at 2 s (arriving still); j2 to -10 at 1 s, 0 at 2 s.
    rad = math.radians
    payload = trajectory(["j3", "j2"], [point(1.0, [rad(15), rad(-10)]),
                                        point(2.0, [rad(5), 0.0], [0.0, 0.0])])
    result, states = send(armed, payload)
    assert result["status"] == "reached", result
    assert result["error_code"] == 0
    assert result["tolerance_deg"] == TOLERANCE_DEG
    for j in result["joints"]:
        assert j["error_deg"] <= TOLERANCE_DEG, result
    assert states and list(states[0].joint_names) == ["j3", "j2"]

    def at(t: float):
        m = next(m for m in states
                 if abs(m.feedback.time_from_start.sec + m.feedback.time_from_start.nanosec / 1e9
                        - t) < 1e-6)
        return [math.degrees(p) for p in m.feedback.positions]

    for t, want in ((1.0, (15.0, -10.0)), (2.0, (5.0, 0.0))):
        for a, w in zip(at(t), want):
            assert abs(a - w) < ON_TIME_DEG, (t, at(t), want)
    # The simulator's own state: j3 at 5 degrees, j1 (not named) where it was.
    after = sim(armed)
    assert abs(whj_deg(after, 3) - 5.0) <= TOLERANCE_DEG, after
    assert abs(whj_deg(after, 1) - whj_deg(before, 1)) < 0.05


def test_a_bad_trajectory_is_refused_whole_and_nothing_moves(armed):
    before = sim(armed)
    refused = health(armed)["trajectories"]["refused"]
    # Its second point is beyond j3's soft limits (+-2 rad): the first must not play either.
    result, states = send(armed, trajectory(["j3"], [point(1.0, [0.3]), point(2.0, [2.5])]))
    assert result["status"] == "refused" and result["error_code"] == -1, result
    assert result["error_string"] == (
        "joint_trajectory: point 1: j3 = 2.5 rad is outside its soft limits -2..=2 rad (the "
        "robot file's limits)")
    assert states == []
    assert abs(whj_deg(sim(armed), 3) - whj_deg(before, 3)) < 0.05
    assert wait_for(lambda: health(armed)["trajectories"]["refused"] == refused + 1, 5)


def test_an_unarmed_bridge_refuses_a_trajectory(peer):
    query(peer, "robobus/arm", "false")
    before = whj_deg(sim(peer), 3)
    result, states = send(peer, trajectory(["j3"], [point(1.0, [0.3])]))
    assert result["status"] == "refused", result
    assert result["error_string"].startswith(
        "joint_trajectory: not armed: motion needs this bridge armed"), result
    assert states == []
    assert abs(whj_deg(sim(peer), 3) - before) < 0.05
