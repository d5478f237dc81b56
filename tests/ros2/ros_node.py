#!/usr/bin/env python3
"""A real ROS 2 node (rclpy) for the bridge tests: the ROS side of tests/ros2/.

Subscribes to `joint_states` (sensor_msgs/msg/JointState) and prints one JSON line per
message received:
    {"type": "joint_state", "names": [...], "position": [...], "velocity": [...],
     "effort": [...], "stamp": [sec, nanosec]}
With --command "v1,v2,...", publishes that std_msgs/msg/Float64MultiArray to
`joint_commands` at --rate Hz for --seconds s, from the first JointState on. Both names are
relative: under --namespace NS they are NS/joint_states and NS/joint_commands.

Both endpoints use reliable, volatile, keep-last 10: compatible with a default publisher
and subscriber. The DDS domain is ROS_DOMAIN_ID from the environment (rclpy reads it), as
is RMW_IMPLEMENTATION (the PyPI build's default is rmw_fastrtps_cpp). rclpy from PyPI
needs no ROS installation (scripts/bridge/ros2-setup puts it in target/bridge-venv).

ROS_AUTOMATIC_DISCOVERY_RANGE defaults to LOCALHOST here when it is not set: the router
(robobus-ros2-router) runs its Cyclone DDS with that range, i.e. unicast discovery to
localhost and no multicast, and Fast DDS with its own default (SUBNET: multicast
discovery) never discovers it, even with a multicast route: no sample flows either way.

Diagnostics go to stderr: when the first JointState arrived, and why it failed.

At the end it prints {"type": "published", "count": N} and exits 0 when it received
--expect messages and, with --command, published for the whole --seconds; 1 on --timeout
(counted from the start); 2 on bad arguments.
"""

import argparse
import json
import os
import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
)
# After the last command: time for the reliable writer to deliver it before the node goes.
LINGER_S = 0.3


def emit(obj):
    print(json.dumps(obj), flush=True)


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--namespace", default="", help="ROS namespace of the node, e.g. /bot1 (default none)")
    p.add_argument("--expect", type=int, default=5, help="JointState messages to receive")
    p.add_argument("--command", help="Float64MultiArray data to publish, comma separated")
    p.add_argument("--rate", type=float, default=20.0, help="commands per second")
    p.add_argument("--seconds", type=float, default=2.0, help="how long to publish commands")
    p.add_argument("--timeout", type=float, default=60.0, help="seconds before giving up")
    p.add_argument("--node-name", default="robobus_test_node")
    args = p.parse_args(argv)
    if args.expect < 0 or args.rate <= 0 or args.seconds < 0 or args.timeout <= 0:
        p.error("--expect and --seconds must be >= 0, --rate and --timeout > 0")
    if args.namespace and not args.namespace.startswith("/"):
        args.namespace = "/" + args.namespace
    try:
        args.command = [float(v) for v in args.command.split(",")] if args.command else None
    except ValueError:
        p.error(f"--command {args.command!r}: expected numbers separated by commas")
    return args


def main(argv=None):
    args = parse_args(argv)
    started = time.monotonic()
    # Read by rmw when rclpy.init() creates the DDS participant.
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init()
    node = Node(args.node_name, namespace=args.namespace)
    received = 0
    first_at = None

    def on_joint_state(msg):
        nonlocal received, first_at
        if first_at is None:
            first_at = time.monotonic()
            print(f"ros_node: first JointState after {first_at - started:.2f} s", file=sys.stderr, flush=True)
        if received >= args.expect:
            return
        received += 1
        emit(
            {
                "type": "joint_state",
                "names": list(msg.name),
                "position": [float(v) for v in msg.position],
                "velocity": [float(v) for v in msg.velocity],
                "effort": [float(v) for v in msg.effort],
                "stamp": [msg.header.stamp.sec, msg.header.stamp.nanosec],
            }
        )

    node.create_subscription(JointState, "joint_states", on_joint_state, QOS)
    publisher = node.create_publisher(Float64MultiArray, "joint_commands", QOS) if args.command else None
    published = 0
    command = Float64MultiArray(data=args.command or [])
    deadline = time.monotonic() + args.timeout
    next_pub = None
    ok = False
    why = "stopped by an error"
    try:
        while time.monotonic() < deadline:
            now = time.monotonic()
            publishing_done = publisher is None or (first_at is not None and now - first_at >= args.seconds)
            if received >= args.expect and publishing_done:
                ok = True
                break
            if publisher is not None and first_at is not None and not publishing_done:
                if next_pub is None:
                    next_pub = first_at
                if now >= next_pub:
                    publisher.publish(command)
                    published += 1
                    next_pub += 1.0 / args.rate
            wait = 0.05 if next_pub is None else max(0.0, min(0.05, next_pub - time.monotonic()))
            rclpy.spin_once(node, timeout_sec=wait)
        if ok and published:
            end = time.monotonic() + LINGER_S
            while time.monotonic() < end:
                rclpy.spin_once(node, timeout_sec=0.05)
    except KeyboardInterrupt:
        ok = False
        why = "interrupted"
    else:
        why = f"timeout after {args.timeout:g} s"
    finally:
        emit({"type": "published", "count": published})
        if not ok:
            print(
                f"ros_node: {why}: {received}/{args.expect} JointState received, "
                f"{published} commands published",
                file=sys.stderr,
                flush=True,
            )
        node.destroy_node()
        rclpy.try_shutdown()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
