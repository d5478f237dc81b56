#!/usr/bin/env python3
"""Talks to a `robobus sim wck --servos 0-5` endpoint with pyserial and checks the replies
byte for byte (manual appendix A-1 packets; four misprinted checksums used corrected).

Usage: wck_endpoint_check.py PATH
Exit status 0 when every check passed; prints one line per check.
"""

import sys
import time

import serial


def cs(*data):
    x = 0
    for b in data:
        x ^= b
    return x & 0x7F


def op(d1, d2):
    return bytes([0xFF, d1, d2, cs(d1, d2)])


def setcmd(id_, code, d3, d4):
    d1 = 0xE0 | id_
    return bytes([0xFF, d1, code, d3, d4, cs(d1, code, d3, d4)])


class Bus:
    def __init__(self, path):
        self.port = serial.Serial(path, 115200, timeout=0.2)

    def transact(self, packet, n=2, timeout=0.2):
        self.port.reset_input_buffer()
        self.port.timeout = timeout
        t0 = time.monotonic()
        self.port.write(packet)
        reply = self.port.read(n) if n else b""
        return reply, time.monotonic() - t0


failures = 0


def check(name, got, expected):
    global failures
    ok = got == expected
    if not ok:
        failures += 1
    print(f"{'ok  ' if ok else 'FAIL'} {name}: got {got.hex(' ') if isinstance(got, bytes) else got}"
          f", expected {expected.hex(' ') if isinstance(expected, bytes) else expected}")


def main():
    bus = Bus(sys.argv[1])
    time.sleep(0.1)  # modules are deaf for 65 ms after power-up

    # (3) status read of every servo: load 0, position 127 at rest.
    for i in range(6):
        reply, _ = bus.transact(op(0xA0 | i, 0x00))
        check(f"status read of servo {i}", reply, bytes([0x00, 0x7F]))
    # The manual's own example packet for servo 0.
    reply, dt = bus.transact(bytes([0xFF, 0xA0, 0x00, 0x20]))
    check("status read FF A0 00 20", reply, bytes([0x00, 0x7F]))
    # The simulator paces the reply: about 1.18 ms after the command at 115200.
    check("reply not before the modelled response time", dt >= 0.0011, True)

    # (9) P, D gain read: defaults 20, 30.
    check("gain read", bus.transact(bytes([0xFF, 0xE0, 0x0A, 0x00, 0x00, 0x6A]))[0], bytes([20, 30]))
    # (16) speed read, (19) over-load read, (21) boundary read: A-5 defaults.
    check("speed read", bus.transact(bytes([0xFF, 0xE0, 0x0E, 0x00, 0x00, 0x6E]))[0], bytes([0, 60]))
    check("over-load read", bus.transact(bytes([0xFF, 0xE0, 0x10, 0x00, 0x00, 0x70]))[0], bytes([33, 33]))
    check("boundary read", bus.transact(bytes([0xFF, 0xE0, 0x12, 0x00, 0x00, 0x72]))[0], bytes([1, 254]))
    # (22) I/O write and (23) I/O read (checksum 0x05; the manual misprints 0x04).
    check("I/O write", bus.transact(bytes([0xFF, 0xE0, 0x64, 0x03, 0x03, 0x04]))[0], bytes([3, 3]))
    check("I/O read", bus.transact(bytes([0xFF, 0xE0, 0x65, 0x00, 0x00, 0x05]))[0], bytes([3, 0]))
    # (12) runtime P, D gain set (checksum 0x6B; the manual misprints 0x69).
    check("runtime gain set", bus.transact(bytes([0xFF, 0xE0, 0x0B, 0x64, 0x64, 0x6B]))[0], bytes([0x64, 0x64]))
    # (17) runtime speed set: no reply.
    check("runtime speed set has no reply",
          bus.transact(bytes([0xFF, 0xE0, 0x17, 0x1E, 0x64, 0x0D]), 2, 0.05)[0], b"")
    # (1) position move of servo 2 to 200: replies load and position before it moves.
    check("position move", bus.transact(op(0x02, 200))[0], bytes([0x00, 0x7F]))
    time.sleep(1.0)
    reply, _ = bus.transact(op(0xA2, 0x00))
    check("servo 2 arrived at 200", reply[1:], bytes([200]))
    # (27) 10-bit position read of servo 3 at rest at standard position 127 (134.0 deg):
    # 412 steps of 333/1023 deg = 0x19C -> H3 = 3, L7<<1 = 0x38.
    check("10-bit position read", bus.transact(bytes([0xFF, 0xE0, 0xC9, 0x03, 0x03, cs(0xE0, 0xC9, 3, 3)]))[0],
          bytes([0x03, 0x38]))
    # A servo that does not exist stays silent.
    check("servo 9 is silent", bus.transact(op(0xA9, 0x00), 2, 0.05)[0], b"")
    # (24) motion data write: the manual's example, answered 04 04 after the EEPROM write.
    reply, dt = bus.transact(bytes([0xFF, 0xE0, 0x96, 0x04, 0x10, 0x52, 0x31, 0x0A, 0x10, 0xAC, 0x31, 0x0A, 0x0C]),
                             2, 0.5)
    check("motion data write", reply, bytes([4, 4]))
    check("EEPROM write takes about 121 ms", 0.118 <= dt <= 0.4, True)
    # (5) wheel mode CCW at speed 15 on servo 4: no rotations yet.
    check("wheel", bus.transact(op(0xC4, 0x3F))[0], bytes([0x00, 0x7F]))

    # A client at the wrong baud rate gets nothing sensible back.
    bus.port.baudrate = 57600
    time.sleep(0.05)
    reply, _ = bus.transact(op(0xA1, 0x00), 2, 0.05)
    check("at 57600 the 115200 bus answers garbage or nothing", reply != bytes([0x00, 0x7F]), True)
    bus.port.baudrate = 115200
    time.sleep(0.05)
    check("back at 115200", bus.transact(op(0xA1, 0x00))[0], bytes([0x00, 0x7F]))

    print("FAILED" if failures else "OK", f"({failures} failures)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
