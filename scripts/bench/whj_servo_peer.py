#!/usr/bin/env python3
"""The python-can peer of the WHJ servo-cycle benchmark: what a user would write instead
of robobus. Prepares joints 1..N (IAP release, clear errors, position mode, enable), reads
each position, then cycles: for each joint, send one position servo frame (0x200+ID,
4-byte target = its present position, prebuilt) and wait for its 16-byte feedback
(0x500+ID), as fast as it goes, for the given time.

Runs over python-can's UDP multicast bus (default group and port; inside a private
network namespace with `ip route add 224.0.0.0/4 dev lo`). Prints one JSON line:
{"cycles", "elapsed", "cpu", "errors"} (cpu = this process's CPU time over the run).
"""

import argparse
import json
import os
import struct
import time

import can


def mark(name: str) -> None:
    """Leaves a marker in a system-call trace (robobus-bench syscalls): a stat of a path
    that does not exist."""
    try:
        os.stat("/robobus-bench-mark-" + name)
    except OSError:
        pass


def frame(arbitration_id, data):
    return can.Message(
        arbitration_id=arbitration_id,
        is_extended_id=False,
        is_fd=True,
        bitrate_switch=True,
        data=bytes(data),
    )


def exchange(bus, msg, reply_id, timeout):
    """Send one frame and wait for the reply on reply_id; None on timeout."""
    bus.send(msg)
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        r = bus.recv(timeout=left)
        if r is not None and r.arbitration_id == reply_id:
            return r


def write(bus, joint, addr, value):
    for _ in range(5):
        r = exchange(bus, frame(joint, [0x02, addr, value]), 0x100 + joint, 0.2)
        if r is not None:
            return bytes(r.data[:3]) == bytes([0x02, addr, 0x01])
    return False


def prepare(bus, joint):
    deadline = time.monotonic() + 5.0
    while not write(bus, joint, 0x49, 0x00):
        if time.monotonic() > deadline:
            raise SystemExit(f"joint {joint} does not answer")
    if not (write(bus, joint, 0x0F, 1) and write(bus, joint, 0x30, 3) and write(bus, joint, 0x0A, 1)):
        raise SystemExit(f"joint {joint}: enabling failed")
    r = exchange(bus, frame(0x600 + joint, []), 0x700 + joint, 0.2)
    if r is None:
        raise SystemExit(f"joint {joint}: no status")
    return struct.unpack_from("<i", bytes(r.data), 8)[0]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--joints", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--channel", default="239.74.163.2")
    ap.add_argument("--timeout", type=float, default=0.02)
    args = ap.parse_args()

    bus = can.Bus(interface="udp_multicast", channel=args.channel, fd=True)
    try:
        cycle = []
        for j in range(1, args.joints + 1):
            position = prepare(bus, j)
            cycle.append((frame(0x200 + j, struct.pack("<i", position)), 0x500 + j))

        send = bus.send
        recv = bus.recv
        timeout = args.timeout
        errors = 0
        cycles = 0
        mark("start")
        cpu0 = time.process_time()
        t0 = time.perf_counter()
        end = t0 + args.seconds
        while time.perf_counter() < end:
            for msg, reply_id in cycle:
                send(msg)
                while True:
                    r = recv(timeout=timeout)
                    if r is None:
                        errors += 1
                        break
                    if r.arbitration_id == reply_id:
                        break
            cycles += 1
        elapsed = time.perf_counter() - t0
        mark("end")
        cpu = time.process_time() - cpu0
    finally:
        bus.shutdown()
    print(json.dumps({"cycles": cycles, "elapsed": elapsed, "cpu": cpu, "errors": errors}))


if __name__ == "__main__":
    main()
