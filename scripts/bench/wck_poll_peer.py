#!/usr/bin/env python3
"""The pyserial peer of the wCK polling benchmark: what a user would write instead of
robobus. Polls servos 0..N-1 one after the other with the status read command (manual
section 3-3: `FF, (5 << 5) | ID, 0x00, checksum` -> 2 reply bytes, load and position),
as fast as it goes, for the given time.

Tuned fairly: packets are prebuilt, each reply is read with one exact-length read
(`read(2)` with a timeout), no per-transaction buffer flush. Prints one JSON line:
{"cycles", "elapsed", "cpu", "errors"} (cpu = this process's CPU time over the run).
"""

import argparse
import json
import os
import time

import serial


def mark(name: str) -> None:
    """Leaves a marker in a system-call trace (robobus-bench syscalls): a stat of a path
    that does not exist."""
    try:
        os.stat("/robobus-bench-mark-" + name)
    except OSError:
        pass


def status_read(servo_id):
    d1 = (5 << 5) | servo_id
    d2 = 0x00
    return bytes([0xFF, d1, d2, (d1 ^ d2) & 0x7F])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", required=True)
    ap.add_argument("--baud", type=int, default=115200)
    ap.add_argument("--servos", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--timeout", type=float, default=0.05)
    args = ap.parse_args()

    packets = [status_read(i) for i in range(args.servos)]
    port = serial.Serial(args.port, args.baud, timeout=args.timeout)
    port.reset_input_buffer()
    # Warm-up cycle: every servo must answer.
    for p in packets:
        port.write(p)
        if len(port.read(2)) != 2:
            raise SystemExit("no reply during warm-up")

    errors = 0
    cycles = 0
    write = port.write
    read = port.read
    mark("start")
    cpu0 = time.process_time()
    t0 = time.perf_counter()
    end = t0 + args.seconds
    while time.perf_counter() < end:
        for p in packets:
            write(p)
            if len(read(2)) != 2:
                errors += 1
                port.reset_input_buffer()
        cycles += 1
    elapsed = time.perf_counter() - t0
    mark("end")
    cpu = time.process_time() - cpu0
    port.close()
    print(json.dumps({"cycles": cycles, "elapsed": elapsed, "cpu": cpu, "errors": errors}))


if __name__ == "__main__":
    main()
