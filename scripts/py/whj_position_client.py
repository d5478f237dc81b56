#!/usr/bin/env python3
"""External python-can client for the simulated WHJ joints (`robobus sim whj`).

Starts joint N (IAP handshake, clear errors, position mode, enable), then streams position
servo frames at a fixed rate for a +/- amplitude sine move around the start angle, and
checks that the 16-byte servo feedback follows. Prints one JSON line with the results and
exits 0 if the feedback followed, 1 if not, 2 if the joint did not answer.

Runs over any python-can FD bus, e.g. the UDP multicast bus (inside a network namespace
with `ip route add 224.0.0.0/4 dev lo`, see the robobus_link::udp docs):

    whj_position_client.py --interface udp_multicast --channel 239.74.163.2
"""

import argparse
import json
import math
import struct
import sys
import time

import can


def frame(arbitration_id, data):
    return can.Message(
        arbitration_id=arbitration_id,
        is_extended_id=False,
        is_fd=True,
        bitrate_switch=True,
        data=bytes(data),
    )


class Joint:
    def __init__(self, bus, joint_id):
        self.bus = bus
        self.id = joint_id

    def exchange(self, arbitration_id, data, reply_id, timeout=0.05):
        """Send one frame and wait for the reply on reply_id; None on timeout."""
        self.bus.send(frame(arbitration_id, data))
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            msg = self.bus.recv(timeout=left)
            if msg is not None and msg.arbitration_id == reply_id:
                return bytes(msg.data)

    def write(self, addr, value, tries=5):
        """Write one register (1-byte form, as the usage demo); retried on a lost reply
        (every write used here is idempotent)."""
        for _ in range(tries):
            reply = self.exchange(self.id, [0x02, addr, value], 0x100 + self.id, timeout=0.2)
            if reply is not None:
                return reply[:3] == bytes([0x02, addr, 0x01])
        return False

    def status(self):
        d = self.exchange(0x600 + self.id, [], 0x700 + self.id, timeout=0.2)
        if d is None or len(d) < 12:
            return None
        error, voltage, temp, enable, brake, position = struct.unpack_from("<HhhBBi", d)
        return {"error": error, "voltage": voltage / 100, "temperature": temp / 10,
                "enabled": enable, "brake": brake, "position": position}


def start(joint, timeout=5.0):
    """IAP handshake (retried: the joint may still be powering up), then clear errors,
    position mode and enable, as the usage demo recommends."""
    deadline = time.monotonic() + timeout
    while not joint.write(0x49, 0x00, tries=1):
        if time.monotonic() > deadline:
            return False
    return joint.write(0x0F, 1) and joint.write(0x30, 3) and joint.write(0x0A, 1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--interface", default="udp_multicast")
    ap.add_argument("--channel", default="239.74.163.2")
    ap.add_argument("--joint", type=int, default=1)
    ap.add_argument("--amplitude-deg", type=float, default=10.0)
    ap.add_argument("--period-s", type=float, default=2.0)
    ap.add_argument("--rate-hz", type=float, default=1000.0)
    ap.add_argument("--max-error-deg", type=float, default=1.0,
                    help="largest allowed |feedback - previous target|")
    ap.add_argument("--allow-lost", type=int, default=0,
                    help="servo frames that may go unanswered (UDP may drop datagrams "
                         "when a stalled process overflows its socket buffer)")
    args = ap.parse_args()

    bus = can.Bus(interface=args.interface, channel=args.channel, fd=True)
    try:
        joint = Joint(bus, args.joint)
        if not start(joint):
            print(json.dumps({"ok": False, "reason": "joint did not answer the start-up sequence"}))
            return 2
        st = joint.status()
        if st is None or not st["enabled"]:
            print(json.dumps({"ok": False, "reason": f"joint not enabled: {st}"}))
            return 2
        p0 = st["position"]
        amp = round(args.amplitude_deg * 10000)
        n = round(args.period_s * args.rate_hz)
        dt = 1.0 / args.rate_hz
        feedback_id = 0x500 + args.joint
        targets = []
        feedback = []

        def drain(until):
            """Collect servo feedback until the perf_counter time `until`."""
            while True:
                left = until - time.perf_counter()
                msg = bus.recv(timeout=max(left, 0.0))
                if msg is None:
                    return
                if msg.arbitration_id == feedback_id and len(msg.data) == 16:
                    feedback.append(struct.unpack("<iiiHH", bytes(msg.data)))

        # Stream: one position servo frame per slot, feedback collected in between (the
        # joint answers every frame, in order, so feedback k belongs to target k).
        t0 = time.perf_counter()
        for k in range(n + 1):
            target = p0 + round(amp * math.sin(2 * math.pi * k / n))
            bus.send(frame(0x200 + args.joint, struct.pack("<i", target)))
            targets.append(target)
            drain(t0 + (k + 1) * dt)
        elapsed = time.perf_counter() - t0
        drain(time.perf_counter() + 0.3)
        sent = len(targets)
        replies = len(feedback)
        worst = 0
        errors = 0
        for k, (_, _, pos, _, error) in enumerate(feedback):
            errors |= error
            # Feedback k is sampled before target k takes effect: compare with target k-1.
            # (After a lost datagram the pairing is off by the number lost; with --allow-lost
            # that is a few hundredths of a degree per lost frame at the test's slope.)
            prev = targets[k - 1] if k > 0 else p0
            worst = max(worst, abs(pos - prev))
        positions = [f[2] for f in feedback] or [p0]
        lo, hi = min(positions), max(positions)
        end = joint.status()
        result = {
            "sent": sent,
            "replies": replies,
            "rate_hz": sent / elapsed,
            "start_deg": p0 / 10000,
            "min_deg": lo / 10000,
            "max_deg": hi / 10000,
            "max_follow_error_deg": worst / 10000,
            "error_bits": errors,
            "end_deg": None if end is None else end["position"] / 10000,
        }
        ok = (
            replies >= sent - args.allow_lost
            and errors == 0
            and worst <= args.max_error_deg * 10000
            and hi - p0 >= amp * 0.9
            and p0 - lo >= amp * 0.9
            and end is not None
            and abs(end["position"] - p0) <= 200
        )
        result["ok"] = ok
        print(json.dumps(result))
        return 0 if ok else 1
    finally:
        bus.shutdown()


if __name__ == "__main__":
    sys.exit(main())
