#!/usr/bin/env python3
"""A real ROS 2 node (rclpy) for the bridge's trajectory test: publishes one
trajectory_msgs/msg/JointTrajectory on `joint_trajectory` (relative: NS/joint_trajectory
under --namespace NS), as a MoveIt or a script hands one to joint_trajectory_controller's
topic, once a subscriber (the router's DDS reader for the bridge) is matched.

--joints j3,j2 names the joints; each --point T:P1,P2 (repeatable) is a point at T seconds
with one position per joint in rad. The header stamp is zero: the trajectory starts when it
arrives. Prints {"type": "published", "subscribers": N} and exits 0 once it published, 1 on
--timeout (no subscriber matched), 2 on bad arguments. QoS: reliable, volatile, keep-last
10. ROS_AUTOMATIC_DISCOVERY_RANGE defaults to LOCALHOST, as for tests/ros2/ros_node.py.
"""

import argparse
import json
import math
import os
import sys
import time

import rclpy
from builtin_interfaces.msg import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
)
# After publishing: time for the reliable writer to deliver it before the node goes.
LINGER_S = 1.0


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--namespace", default="")
    p.add_argument("--joints", required=True, help="joint names, comma separated")
    p.add_argument("--point", action="append", required=True, help="T:P1,P2,... (s: rad)")
    p.add_argument("--timeout", type=float, default=60.0)
    args = p.parse_args(argv)
    if args.namespace and not args.namespace.startswith("/"):
        args.namespace = "/" + args.namespace
    args.joints = args.joints.split(",")
    points = []
    for text in args.point:
        try:
            t, values = text.split(":")
            positions = [float(v) for v in values.split(",")]
            t = float(t)
        except ValueError:
            p.error(f"--point {text!r}: expected T:P1,P2,...")
        if len(positions) != len(args.joints) or not (t >= 0 and math.isfinite(t)):
            p.error(f"--point {text!r}: one position per joint and a time >= 0")
        sec = math.floor(t)
        points.append(JointTrajectoryPoint(
            positions=positions,
            time_from_start=Duration(sec=sec, nanosec=round((t - sec) * 1e9))))
    args.points = points
    return args


def main(argv=None):
    args = parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init()
    node = Node("robobus_trajectory_node", namespace=args.namespace)
    publisher = node.create_publisher(JointTrajectory, "joint_trajectory", QOS)
    msg = JointTrajectory(joint_names=args.joints, points=args.points)
    deadline = time.monotonic() + args.timeout
    ok = False
    try:
        while time.monotonic() < deadline:
            if publisher.get_subscription_count() > 0:
                # The reader is matched; a moment for its route to Zenoh to be declared.
                end = time.monotonic() + 0.5
                while time.monotonic() < end:
                    rclpy.spin_once(node, timeout_sec=0.05)
                publisher.publish(msg)
                ok = True
                break
            rclpy.spin_once(node, timeout_sec=0.05)
        if ok:
            end = time.monotonic() + LINGER_S
            while time.monotonic() < end:
                rclpy.spin_once(node, timeout_sec=0.05)
        print(json.dumps({"type": "published" if ok else "timeout",
                          "subscribers": publisher.get_subscription_count()}), flush=True)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
