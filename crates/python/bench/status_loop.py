"""Benchmark: loops of status reads and servo cycles through the Python bindings, against
the same loops in Rust and against the pure-Python peers of the benchmarks, in rate and in
CPU per transaction, one run each:

- wCK status reads on a simulated servo behind a pty at 115200 bit/s (`robobus sim wck`,
  the manual's turnaround): the bindings through a request (`station.run`) and through a
  servo handle (`station.wck_servo(0).status()`), on the main thread and on another; the
  Rust loop (`robobus-bench poll-wck --turnaround`); the pyserial peer
  (`scripts/bench/wck_poll_peer.py`, which waits for nothing but the two reply bytes).
- WHJ position servo cycles (one frame, its 16-byte feedback, per joint) with one and
  with seven joints on python-can's UDP multicast bus, against a simulator process with
  no processing delay (`robobus-bench serve-whj --delay-us 0`), inside a private network
  namespace: the bindings through a joint handle (`station.whj_joint(1).command_position
  (...)`) or, for seven, the group handle (`station.whj_joints(range(1, 8))
  .command_position(...)`, one call a cycle, its frames in one batch); the Rust loop
  (`robobus-bench servo-whj`, `Joint::command_position` joint after joint), the same loop
  with the duplicate check off (`--no-window`: what the check costs it), for seven also
  pipelined (`--pipelined`, `JointBus::servo_many`) both ways; and the python-can peer
  (`scripts/bench/whj_servo_peer.py`, joint after joint).

    target/pybind/bin/python crates/python/bench/status_loop.py [--seconds 3] [--no-wck] [--calls-only]

- The bindings' own cost per call, in-process on the built-in simulated robot (its
  simulators on their virtual clock, so a call is CPU only): each handle call in a Python
  loop against the same library call in a Rust loop on the same handle (the native
  module's `_bench_*`, the GIL released as the call releases it), and `station.run(request)`
  against the library running the same parsed request, beside the library's parse of the
  request's JSON text. Python and Rust alternate back to back, 31 rounds of 500 calls; the
  median of each and of each round's difference, in the process's CPU time per call (what
  other processes take of a shared host does not count).

Needs the package installed (scripts/py/test-bindings does it, with the dev profile; for
figures a user sees, install it with the release profile), the release robobus and
robobus-bench binaries (cargo build --release -p robobus-cli -p robobus-bench), the
Python peers' venv (scripts/py/ensure-pyserial) and `unshare -n` (root or user
namespaces) for the WHJ part.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import re
import signal
import subprocess
import sys
import threading
import time
from typing import Any

# numpy's BLAS threads would spin in this process's CPU time, which the call costs are
# measured in; none of the calls uses them.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import robobus  # noqa: E402

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
                if station.run(req, check=False).get("failed"):
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


def handle(port: str, seconds: float) -> dict[str, float]:
    with robobus.open_wck(port) as station:
        servo = station.wck_servo(0)
        servo.status()
        n = 0
        cpu0, t0 = time.process_time(), time.perf_counter()
        end = t0 + seconds
        while time.perf_counter() < end:
            servo.status()
            n += 1
        return {
            "rate": n / (time.perf_counter() - t0),
            "cpu_us": (time.process_time() - cpu0) / n * 1e6,
        }


def peers_python() -> str:
    return subprocess.run(
        [str(ROOT / "scripts" / "py" / "ensure-pyserial")], capture_output=True, text=True, check=True
    ).stdout.strip()


def servo_whj(joints: int, seconds: float, *flags: str) -> dict[str, float]:
    """`robobus-bench servo-whj` against its own simulator process: rate and client CPU."""
    r = subprocess.run(
        [str(RELEASE / "robobus-bench"), "servo-whj", "--joints", str(joints), "--delay-us", "0",
         "--secs", str(seconds), *flags],
        capture_output=True, text=True, check=True,
    )
    m = re.search(r"([\d.]+) Hz, \d+ errors, client CPU ([\d.]+) µs/cycle", r.stdout)
    assert m is not None, r.stdout + r.stderr
    return {"rate": float(m.group(1)), "cpu_us": float(m.group(2))}


def whj(seconds: float, joints: int) -> dict[str, dict[str, float]]:
    """The WHJ part for `joints` joints; runs inside the private network namespace. One
    joint: its handle's `command_position`; more: the group handle's, whose frames go out
    in one batch (`JointBus::servo_many`), against the Rust loop both ways."""
    out = {"Rust (robobus-bench servo-whj)": servo_whj(joints, seconds)}
    # The same loop with the duplicate check off: what the check costs this loop.
    out["Rust, the duplicate check off (--no-window)"] = servo_whj(joints, seconds, "--no-window")
    if joints > 1:
        out["Rust, pipelined (--pipelined)"] = servo_whj(joints, seconds, "--pipelined")
        out["Rust, pipelined, the duplicate check off"] = servo_whj(
            joints, seconds, "--pipelined", "--no-window")
    ids = ",".join(str(n) for n in range(1, joints + 1))
    sim = subprocess.Popen(
        [str(RELEASE / "robobus-bench"), "serve-whj", "--joints", str(joints), "--delay-us", "0"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )
    try:
        assert sim.stdout is not None and sim.stdout.readline().strip() == "READY"
        with robobus.open_whj("udp") as station:
            station.whj.mode(ids, "position", check=True)
            station.whj.enable(ids, check=True)
            if joints == 1:
                joint = station.whj_joint(1)
                here: Any = joint.status()["position_deg"]
                command = joint.command_position
                name = "bindings (joint handle)"
                native = joint._group._native
                targets = [here]
            else:
                group = station.whj_joints(range(1, joints + 1))
                here = group.read_positions()
                command = group.command_position
                name = "bindings (group handle, one call a cycle)"
                native = group._native
                targets = list(here)
            command(here)
            n = 0
            cpu0, t0 = time.process_time(), time.perf_counter()
            end = t0 + seconds
            while time.perf_counter() < end:
                command(here)
                n += 1
            out[name] = {
                "rate": n / (time.perf_counter() - t0),
                "cpu_us": (time.process_time() - cpu0) / n * 1e6,
            }
            # The same library call in a Rust loop on the same handle, as many times.
            cpu0 = time.process_time()
            each = native._bench_command("position", targets, n)
            out["the same handle call in a Rust loop (in the bindings)"] = {
                "rate": 1.0 / each,
                "cpu_us": (time.process_time() - cpu0) / n * 1e6,
            }
            station.whj.disable(ids, check=True)
        peer = subprocess.run(
            [peers_python(), str(ROOT / "scripts" / "bench" / "whj_servo_peer.py"),
             "--joints", str(joints), "--seconds", str(seconds)],
            capture_output=True, text=True, check=True,
        )
        d = json.loads(peer.stdout)
        out["python-can peer"] = {"rate": d["cycles"] / d["elapsed"], "cpu_us": d["cpu"] / d["cycles"] * 1e6}
    finally:
        assert sim.stdin is not None
        sim.stdin.close()
        sim.wait(timeout=20)
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
    r = subprocess.run(
        [peers_python(), str(ROOT / "scripts" / "bench" / "wck_poll_peer.py"), "--port", port,
         "--servos", "1", "--seconds", str(seconds)],
        capture_output=True, text=True, check=True,
    )
    d = json.loads(r.stdout)
    return {"rate": d["cycles"] / d["elapsed"], "cpu_us": d["cpu"] / d["cycles"] * 1e6}


def _per_call(f: Any, n: int) -> float:
    """The process's CPU time per call of `f` over `n` calls: on a shared host, what other
    processes take of the cores does not count, unlike wall time."""
    f()
    t0 = time.process_time()
    for _ in range(n):
        f()
    return (time.process_time() - t0) / n


def _rust_per_call(rust_loop: Any, n: int) -> float:
    """The process's CPU time per call of a native `_bench_*` loop of `n` calls (its own
    wall-clock figure is not used)."""
    t0 = time.process_time()
    rust_loop(n)
    return (time.process_time() - t0) / n


def _median(xs: list[float]) -> float:
    return sorted(xs)[len(xs) // 2]


def calls(rounds: int = 31, n: int = 500) -> list[tuple[str, float, float, float]]:
    """(call, Python µs, Rust µs, Python over Rust µs) per call, each the median of
    `rounds` alternations (the last: of each round's difference)."""
    from robobus import _robobus

    out: list[tuple[str, float, float, float]] = []
    with robobus.Station.simulated(clock="virtual") as station:
        station.whj.mode("1-7", "position", check=True)
        station.whj.enable("1-7", check=True)
        servo = station.wck_servo(0)
        joint = station.whj_joint(1)
        joints = station.whj_joints(range(1, 8))
        here = joint.status()["position_deg"]
        wck_native = servo._group._native
        whj_native = joint._group._native
        cases: list[tuple[str, Any, Any]] = [
            ("`wck_servo(0).status()`", servo.status, lambda k: wck_native._bench_status(k)),
            ("`whj_joint(1).status()`", joint.status, lambda k: whj_native._bench_status(k)),
            (
                "`whj_joint(1).command_position(x)`",
                lambda: joint.command_position(here),
                lambda k: whj_native._bench_command("position", [here], k),
            ),
            (
                "`whj_joints(1..7).read_positions()`",
                joints.read_positions,
                lambda k: joints._native._bench_positions(k),
            ),
        ]
        req = {"op": "wck.status", "ids": [0]}
        cases.append(
            (
                "`station.run({\"op\": \"wck.status\", \"ids\": [0]})`",
                lambda: station.run(req),
                lambda k: station._native._bench_run(req, k),  # type: ignore[attr-defined]
            )
        )
        for name, py_call, rust_loop in cases:
            py_t: list[float] = []
            rust_t: list[float] = []
            over: list[float] = []
            for r in range(rounds):
                # Each round's pair measured back to back, in turn Python first and Rust
                # first: the simulators' own cost drifts as their state grows, and the
                # difference of a pair does not see it.
                if r % 2 == 0:
                    p_, r_ = _per_call(py_call, n), _rust_per_call(rust_loop, n)
                else:
                    r_, p_ = _rust_per_call(rust_loop, n), _per_call(py_call, n)
                py_t.append(p_)
                rust_t.append(r_)
                over.append(p_ - r_)
            out.append((name, _median(py_t) * 1e6, _median(rust_t) * 1e6, _median(over) * 1e6))
        text = json.dumps(req)
        parse = _median(
            [_rust_per_call(lambda k: _robobus._bench_parse(text, k), n * 10) for _ in range(rounds)]
        ) * 1e6
        out.append((f"the library's parse of `{text}`", parse, parse, 0.0))
    return out


def calls_table(rows: list[tuple[str, float, float, float]]) -> None:
    print("\nThe bindings' cost per call, in-process simulated robot (virtual clock)\n")
    print("| call | Python µs | the same call in Rust µs | Python over Rust µs |")
    print("|---|---|---|---|")
    for name, py_us, rust_us, over_us in rows:
        print(f"| {name} | {py_us:.2f} | {rust_us:.2f} | {over_us:.2f} |")


def table(title: str, results: dict[str, dict[str, float]], base: str, peer: str) -> None:
    print(f"\n{title}\n")
    print(f"| loop | per second | CPU µs each | rate / Rust | rate / {peer.split()[0]} | CPU / {peer.split()[0]} |")
    print("|---|---|---|---|---|---|")
    for name, r in results.items():
        print(
            f"| {name} | {r['rate']:.0f} | {r['cpu_us']:.0f} | "
            f"{r['rate'] / results[base]['rate']:.2f} | {r['rate'] / results[peer]['rate']:.2f} | "
            f"{r['cpu_us'] / results[peer]['cpu_us']:.2f} |"
        )


def wck(seconds: float) -> None:
    sim, port = sim_port()
    try:
        results = {
            "bindings, request (main thread)": bindings(port, seconds, True),
            "bindings, request (other thread)": bindings(port, seconds, False),
            "bindings, servo handle": handle(port, seconds),
            "pyserial peer": pyserial(port, seconds),
        }
    finally:
        sim.send_signal(signal.SIGINT)
        sim.wait(timeout=20)
    results["Rust (robobus-bench poll-wck)"] = rust(seconds)
    table("wCK status reads, 1 servo, pty, 115200 bit/s", results, "Rust (robobus-bench poll-wck)", "pyserial peer")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--whj-only", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--calls-only", action="store_true", help="only the in-process call costs")
    ap.add_argument("--no-wck", action="store_true", help="without the wCK pty loops (no release robobus binary)")
    args = ap.parse_args()
    if args.calls_only:
        calls_table(calls())
        return
    if args.whj_only:
        print(json.dumps({str(n): whj(args.seconds, n) for n in (1, 7)}))
        return
    calls_table(calls())
    if not args.no_wck:
        wck(args.seconds)
    inner = subprocess.run(
        ["unshare", "-n", "sh", "-c",
         'ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec "$@"', "netns",
         sys.executable, __file__, "--whj-only", "--seconds", str(args.seconds)],
        capture_output=True, text=True,
    )
    if inner.returncode != 0:
        print(f"\nWHJ part skipped: {inner.stderr.strip()[-300:]}")
        return
    whj_results = json.loads(inner.stdout.strip().splitlines()[-1])
    for joints, results in whj_results.items():
        table(f"WHJ position servo cycles, {joints} joint(s), UDP multicast, 1 / 5 Mbit/s wire",
              results, "Rust (robobus-bench servo-whj)", "python-can peer")


if __name__ == "__main__":
    main()
