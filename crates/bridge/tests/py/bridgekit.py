"""Test kit of the bridge's peer tests: a `robobus bridge` process, Zenoh sessions with
scouting off, queries, and the ROS 2 message types from rosbags (CDR written and read by
a library that is not ours)."""

from __future__ import annotations

import json
import os
import pathlib
import queue
import signal
import socket
import subprocess
import threading
import time

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_typestore

ROOT = pathlib.Path(__file__).resolve().parents[4]
ROBOBUS = os.environ.get("ROBOBUS", str(ROOT / "target" / "debug" / "robobus"))
TS = get_typestore(Stores.ROS2_HUMBLE)
JOINT_STATE = "sensor_msgs/msg/JointState"
F64_ARRAY = "std_msgs/msg/Float64MultiArray"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Bridge:
    """`robobus bridge` on the built-in simulated robot, listening on one endpoint."""

    def __init__(self, *args: str, host: str = "127.0.0.1", port: int | None = None,
                 prefix: list[str] | None = None, listen: bool = True):
        self.port = port or free_port()
        self.endpoint = f"tcp/{host}:{self.port}"
        cmd = [*(prefix or []), ROBOBUS, "bridge", *args]
        if listen:
            cmd += ["--listen", self.endpoint]
        self.stderr = open(os.environ.get("BRIDGE_LOG", os.devnull), "ab")  # noqa: SIM115
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self.stderr, text=True)
        self.first = self._first_line(30)

    def _first_line(self, timeout: float) -> str:
        out: queue.Queue[str] = queue.Queue()
        threading.Thread(target=lambda: out.put(self.proc.stdout.readline()), daemon=True).start()
        try:
            line = out.get(timeout=timeout)
        except queue.Empty:
            self.kill()
            raise AssertionError("the bridge printed nothing in 30 s") from None
        assert line.startswith("bridge: "), line
        # Keep reading stdout so the bridge never blocks on a full pipe.
        threading.Thread(target=self.proc.stdout.read, daemon=True).start()
        return line

    def stop(self, sig: int = signal.SIGINT, timeout: float = 15) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            raise AssertionError("the bridge did not stop on its signal") from None

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def session(connect: str) -> zenoh.Session:
    """A peer connected to `connect`, listening on nothing, with scouting off."""
    c = zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("connect/endpoints", json.dumps([connect]))
    c.insert_json5("listen/endpoints", "[]")
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "false")
    return zenoh.open(c)


class QueryError(Exception):
    def __init__(self, body: dict):
        super().__init__(body.get("message"))
        self.kind = body.get("kind")
        self.body = body


def query(s: zenoh.Session, key: str, payload: str | None = None, timeout: float = 20):
    for r in s.get(key, payload=payload, timeout=timeout):
        if r.ok is not None:
            return json.loads(r.ok.payload.to_string())
        raise QueryError(json.loads(r.err.payload.to_string()))
    raise AssertionError(f"no reply from {key}")


class Inbox:
    """A subscriber whose samples wait in a queue (with a timeout to read them)."""

    def __init__(self, s: zenoh.Session, key: str, liveliness: bool = False):
        self.q: queue.Queue = queue.Queue()
        if liveliness:
            self.sub = s.liveliness().declare_subscriber(key, self.q.put, history=True)
        else:
            self.sub = s.declare_subscriber(key, self.q.put)

    def get(self, timeout: float = 10):
        return self.q.get(timeout=timeout)

    def drain(self) -> None:
        while not self.q.empty():
            self.q.get_nowait()


def joint_state(sample) -> object:
    return TS.deserialize_cdr(bytes(sample.payload.to_bytes()), JOINT_STATE)


def command(values) -> bytes:
    M = TS.types[F64_ARRAY]
    L = TS.types["std_msgs/msg/MultiArrayLayout"]
    msg = M(layout=L(dim=[], data_offset=0), data=np.array(values, dtype=np.float64))
    return bytes(TS.serialize_cdr(msg, F64_ARRAY))


def health(s: zenoh.Session, prefix: str = "", timeout: float = 5) -> dict:
    """The next health message."""
    inbox = Inbox(s, f"{prefix}robobus/health")
    try:
        return json.loads(inbox.get(timeout).payload.to_string())
    finally:
        inbox.sub.undeclare()


def sim(s: zenoh.Session, prefix: str = "") -> dict:
    return query(s, f"{prefix}robobus/sim")


def whj_deg(snapshot: dict, joint: int) -> float:
    return next(j["position_deg"] for j in snapshot["whj"] if j["id"] == joint)


def wck_steps(snapshot: dict, servo: int) -> int:
    return next(s["position"] for s in snapshot["wck"] if s["id"] == servo)


def wait_for(predicate, timeout: float, step: float = 0.02):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        v = predicate()
        if v:
            return v
        time.sleep(step)
    return predicate()
