"""Benchmark: a loop of wCK status reads through the Python bindings, against the same loop
in Rust (`robobus-bench poll-wck --turnaround`: the client library on a simulated servo with
the manual's turnaround, as `robobus sim wck` has it) and against the pyserial peer of the
benchmarks (`scripts/bench/wck_poll_peer.py`, which waits for nothing but the two reply
bytes), each on a simulated servo behind a pty at 115200 bit/s on the wall clock. Prints
rates, CPU per transaction and the ratios, one run each.

    target/pybind/bin/python crates/python/bench/status_loop.py [--seconds 3]

Needs the package installed (scripts/py/test-bindings does it), the release robobus and
robobus-bench binaries (cargo build --release -p robobus-cli -p robobus-bench) and the
pyserial venv of the benchmarks (scripts/py/ensure-pyserial).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import re
import signal
import subprocess
import threading
import time

import robobus

ROOT = pathlib.Path(__file__).resolve().parents[3]
RELEASE = ROOT / "target" / "release"


def sim_port() -> tuple[subprocess.Popen[str], str]:
    sim = subprocess.Popen(
        [str(RELEASE / "robobus"), "sim", "wck", "--servos", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    assert sim.stdout is not None
    return sim, sim.stdout.readline().strip()


def bindings(port: str, seconds: float, on_main: bool) -> dict[str, float]:
    out: dict[str, float] = {}

    def loop() -> None:
        with robobus.open_wck(port) as station:
            req = {"op": "wck.status", "ids": [0]}
            station.run(req, check=True)
            n = errors = 0
            cpu0, t0 = time.process_time(), time.perf_counter()
            end = t0 + seconds
            while time.perf_counter() < end:
                if station.run(req).get("failed"):
                    errors += 1
                n += 1
            out.update(
                rate=n / (time.perf_counter() - t0),
                cpu_us=(time.process_time() - cpu0) / n * 1e6,
                errors=errors,
            )

    if on_main:
        loop()
    else:
        t = threading.Thread(target=loop)
        t.start()
        t.join()
    return out


def rust(seconds: float) -> dict[str, float]:
    r = subprocess.run(
        [str(RELEASE / "robobus-bench"), "poll-wck", "--servos", "1", "--baud", "115200",
         "--secs", str(seconds), "--turnaround"],
        capture_output=True, text=True, check=True,
    )
    text = r.stdout + r.stderr
    rate = float(re.search(r"([\d.]+) Hz", text).group(1))  # type: ignore[union-attr]
    cpu = float(re.search(r"client CPU ([\d.]+) µs/cycle", text).group(1))  # type: ignore[union-attr]
    return {"rate": rate, "cpu_us": cpu}


def pyserial(port: str, seconds: float) -> dict[str, float]:
    py = subprocess.run(
        [str(ROOT / "scripts" / "py" / "ensure-pyserial")], capture_output=True, text=True, check=True
    ).stdout.strip()
    r = subprocess.run(
        [py, str(ROOT / "scripts" / "bench" / "wck_poll_peer.py"), "--port", port,
         "--servos", "1", "--seconds", str(seconds)],
        capture_output=True, text=True, check=True,
    )
    d = json.loads(r.stdout)
    return {"rate": d["cycles"] / d["elapsed"], "cpu_us": d["cpu"] / d["cycles"] * 1e6}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=3.0)
    args = ap.parse_args()
    sim, port = sim_port()
    try:
        results = {
            "bindings (main thread)": bindings(port, args.seconds, True),
            "bindings (other thread)": bindings(port, args.seconds, False),
            "pyserial peer": pyserial(port, args.seconds),
        }
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait(timeout=20)
    results["Rust (robobus-bench poll-wck)"] = rust(args.seconds)
    base = results["Rust (robobus-bench poll-wck)"]
    peer = results["pyserial peer"]
    print("| loop | status reads/s | CPU µs/read | rate / Rust | rate / pyserial |")
    print("|---|---|---|---|---|")
    for name, r in results.items():
        print(
            f"| {name} | {r['rate']:.0f} | {r['cpu_us']:.0f} | "
            f"{r['rate'] / base['rate']:.2f} | {r['rate'] / peer['rate']:.2f} |"
        )


if __name__ == "__main__":
    main()
