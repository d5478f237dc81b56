"""A WHJ cyclic sine on the built-in simulated arm: joint 1 enabled in position mode,
±10° at 0.5 Hz for 2 s as position servo frames at 200 Hz, with the loop's statistics,
then every joint's position in one array, and joint 1's read back through the telemetry
stream.

    python crates/python/examples/whj_sine.py
"""

from __future__ import annotations

import robobus


def main() -> None:
    with robobus.Station.simulated() as station:
        station.whj.enable("1")
        station.whj.mode("1", "position")
        wave = station.whj.wave(1, amplitude=10.0, frequency=0.5, duration=2.0, rate_hz=200)
        stats = wave.get("summary") or {}
        print(
            f"wave: {stats['cycles']} cycles, {stats['missing_replies']} missing replies, "
            f"tracking RMS {stats['tracking_rms']:.3f} {stats['unit']}"
        )
        # Every joint's position in one call and one array (the status queries pipelined).
        print("joints 1-7 at", station.whj_joints(range(1, 8)).read_positions().round(3), "deg")
        with station.telemetry({"op": "whj.sample", "joints": "1"}, 20.0, limit=5) as stream:
            for sample in stream:
                row = sample["report"]["results"][0]
                print(f"t={sample['unix_ms']:.0f} ms  joint 1 at {row['position_deg']:.3f} deg")


if __name__ == "__main__":
    main()
