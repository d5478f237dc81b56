#!/usr/bin/env python3
"""A real ROS 2 node (rclpy) for the bridge tests: subscribes to `diagnostics`
(diagnostic_msgs/msg/DiagnosticArray, relative: NS/diagnostics under --namespace NS), as
rqt's monitors and diagnostic_aggregator read the bridge's `NS/diagnostics`, and prints
one JSON line per message received:
    {"type": "diagnostics", "stamp": [sec, nanosec],
     "status": [{"level": L, "name": ..., "message": ..., "hardware_id": ...,
                 "values": {key: value}}]}

The subscription is reliable, volatile, keep-last 10 (compatible with a default
publisher). ROS_AUTOMATIC_DISCOVERY_RANGE defaults to LOCALHOST, as in ros_node.py (the
router's Cyclone DDS discovers over unicast to localhost only).

Exits 0 once --expect messages arrived, 1 on --timeout (counted from the start), 2 on bad
arguments.
"""

import argparse
import json
import os
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--namespace", default="", help="ROS namespace of the node, e.g. /bot1")
    p.add_argument("--expect", type=int, default=2, help="DiagnosticArray messages to receive")
    p.add_argument("--timeout", type=float, default=60.0, help="seconds before giving up")
    args = p.parse_args(argv)
    if args.expect < 1 or args.timeout <= 0:
        p.error("--expect must be >= 1, --timeout > 0")
    if args.namespace and not args.namespace.startswith("/"):
        args.namespace = "/" + args.namespace
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init()
    node = Node("robobus_diagnostics_node", namespace=args.namespace)
    received = 0

    def on_diagnostics(msg):
        nonlocal received
        if received >= args.expect:
            return
        received += 1
        print(json.dumps({
            "type": "diagnostics",
            "stamp": [msg.header.stamp.sec, msg.header.stamp.nanosec],
            "status": [
                {"level": int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else int(s.level),
                 "name": s.name, "message": s.message, "hardware_id": s.hardware_id,
                 "values": {kv.key: kv.value for kv in s.values}}
                for s in msg.status
            ],
        }), flush=True)

    node.create_subscription(DiagnosticArray, "diagnostics", on_diagnostics, QOS)
    deadline = time.monotonic() + args.timeout
    try:
        while received < args.expect and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    if received < args.expect:
        print(f"diagnostics_node: timeout after {args.timeout:g} s: {received}/{args.expect} "
              "DiagnosticArray received", file=sys.stderr, flush=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
