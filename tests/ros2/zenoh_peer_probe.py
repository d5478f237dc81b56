#!/usr/bin/env python3
"""A tiny Zenoh peer for the ROS 2 bridge tests (tests/ros2/check_pipeline.sh).

Publishes a sensor_msgs/msg/JointState as a ROS 2 DDS sample on a Zenoh key (default
`joint_states`) at --rate Hz: the 4-byte encapsulation header 00 01 00 00 (CDR little
endian), then the CDR body, encoded with rosbags. Sample i has names --names, position
[i * 0.5, -1.25, ...], velocity [0.25, ...], effort [1.0, ...] (one value per name: the
first position counts, the others are exact binary fractions a test can compare) and the
wall clock as its stamp.

Subscribes to --command-key (default `joint_commands`) and prints one JSON line per sample,
decoded as std_msgs/msg/Float64MultiArray:
    {"type": "command", "key": K, "data": [...], "dim": [[label, size, stride], ...],
     "data_offset": N, "hex": "<payload as hex>"}
(a payload that does not decode prints "error" and "hex" instead of the fields).

Runs for --seconds or until SIGTERM / SIGINT, then prints
    {"type": "probe", "published": N, "commands": M}
Needs eclipse-zenoh and rosbags (scripts/bridge/ros2-setup puts both in target/bridge-venv).
"""

import argparse
import json
import signal
import sys
import threading
import time

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_typestore

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
JOINT_STATE = "sensor_msgs/msg/JointState"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"


def emit(obj):
    print(json.dumps(obj), flush=True)


def joint_state(i, names, now):
    t = TYPESTORE.types
    n = len(names)
    sec = int(now)
    stamp = t["builtin_interfaces/msg/Time"](sec=sec, nanosec=int((now - sec) * 1e9))
    msg = t[JOINT_STATE](
        header=t["std_msgs/msg/Header"](stamp=stamp, frame_id="base"),
        name=list(names),
        position=np.array([i * 0.5] + [-1.25] * (n - 1), dtype=np.float64),
        velocity=np.full(n, 0.25, dtype=np.float64),
        effort=np.full(n, 1.0, dtype=np.float64),
    )
    return bytes(TYPESTORE.serialize_cdr(msg, JOINT_STATE))


def command_line(key, payload):
    line = {"type": "command", "key": key, "hex": payload.hex()}
    try:
        msg = TYPESTORE.deserialize_cdr(payload, FLOAT64_MULTI_ARRAY)
    except Exception as e:  # noqa: BLE001 - any decoding failure is reported, not raised
        line["error"] = f"{type(e).__name__}: {e}"
        return line
    line["data"] = [float(v) for v in msg.data]
    line["dim"] = [[d.label, int(d.size), int(d.stride)] for d in msg.layout.dim]
    line["data_offset"] = int(msg.layout.data_offset)
    return line


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--connect", action="append", help="Zenoh endpoint (repeatable; default tcp/127.0.0.1:7450)")
    p.add_argument("--mode", choices=["client", "peer"], default="client")
    p.add_argument("--key", default="joint_states", help="key of the JointState samples")
    p.add_argument("--command-key", default="joint_commands", help="key of the Float64MultiArray samples")
    p.add_argument("--names", default="joint1,joint2", help="joint names, comma separated")
    p.add_argument("--rate", type=float, default=50.0, help="JointState samples per second")
    p.add_argument("--seconds", type=float, default=60.0, help="how long to run at most")
    args = p.parse_args()
    names = [n for n in args.names.split(",") if n]
    if not names or args.rate <= 0:
        p.error("--names needs at least one name and --rate must be positive")

    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())

    zenoh.init_log_from_env_or("error")
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(args.mode))
    conf.insert_json5("connect/endpoints", json.dumps(args.connect or ["tcp/127.0.0.1:7450"]))
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")

    commands = 0
    lock = threading.Lock()

    def on_command(sample):
        nonlocal commands
        line = command_line(str(sample.key_expr), bytes(sample.payload.to_bytes()))
        with lock:
            commands += 1
            emit(line)

    published = 0
    with zenoh.open(conf) as session:
        session.declare_subscriber(args.command_key, on_command)
        publisher = session.declare_publisher(args.key)
        period = 1.0 / args.rate
        start = time.monotonic()
        next_tick = start
        while not stop.is_set() and time.monotonic() - start < args.seconds:
            publisher.put(joint_state(published, names, time.time()))
            published += 1
            next_tick += period
            stop.wait(max(0.0, next_tick - time.monotonic()))
    with lock:
        emit({"type": "probe", "published": published, "commands": commands})
    return 0


if __name__ == "__main__":
    sys.exit(main())
