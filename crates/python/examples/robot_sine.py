"""The built-in simulated robot driven in SI units at 50 Hz: every joint follows a
0.3 rad sine (0.5 Hz) for 2 s through the robot's soft limits, speed limits and
watchdog, with the state read back as numpy arrays each cycle; then the safe stop.

    python crates/python/examples/robot_sine.py
"""

from __future__ import annotations

import time

import numpy as np

import robobus


def main() -> None:
    with robobus.Robot.simulated() as robot:
        names = robot.joint_names
        phase = np.linspace(0.0, np.pi, len(names))
        start = robot.read().position_rad
        lag = []
        t0 = time.monotonic()
        cycle = 0
        while (t := time.monotonic() - t0) < 2.0:
            target = start + 0.3 * np.sin(2 * np.pi * 0.5 * t + phase)
            sent = robot.command(target)
            if cycle % 10 == 5:
                # A read costs more than a command (each wCK servo answers in turn).
                lag.append(float(np.max(np.abs(robot.read().position_rad - sent.sent_rad))))
            cycle += 1
            time.sleep(max(0.0, t0 + cycle * 0.02 - time.monotonic()))
        state = robot.read()
        print(f"{cycle} cycles of {len(names)} joints; lag behind the set-points up to {max(lag):.3f} rad")
        arm = [i for i, n in enumerate(names) if n.startswith("j")]
        print("arm at (rad):", np.round(state.position_rad[arm], 3).tolist())
        report = robot.safe_stop()
        print(f"safe stop in {report['applied_in_ms']:.1f} ms, errors: {report['errors'] or 'none'}")


if __name__ == "__main__":
    main()
