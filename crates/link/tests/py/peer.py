"""python-can peer for robobus's interop test (run inside a private network namespace).

Joins the udp_multicast bus on python-can's defaults, prints "ready", then answers each of
the first three frames it receives from robobus (IDs below 0x100) with a frame of ID | 0x100
carrying the payload reversed, as CAN FD with BRS. Every received frame is printed as
"rx <id hex> <is_fd> <brs> <data hex>". Exits non-zero on timeout.
"""
import sys

import can

bus = can.Bus(interface="udp_multicast", channel="239.74.163.2", port=43113, fd=True)
print("ready", flush=True)
answered = 0
try:
    while answered < 3:
        msg = bus.recv(timeout=20)
        if msg is None:
            sys.exit("peer.py: timed out waiting for robobus frames")
        if msg.arbitration_id >= 0x100:
            continue  # python-can receives its own datagrams back
        print(
            "rx %x %d %d %s"
            % (msg.arbitration_id, msg.is_fd, msg.bitrate_switch, msg.data.hex()),
            flush=True,
        )
        reply = can.Message(
            arbitration_id=msg.arbitration_id | 0x100,
            is_extended_id=False,
            data=bytes(reversed(msg.data)),
            is_fd=True,
            bitrate_switch=True,
        )
        bus.send(reply)
        answered += 1
finally:
    bus.shutdown()
print("done", flush=True)
