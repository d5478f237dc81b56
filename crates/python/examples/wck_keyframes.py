"""A wCK keyframe motion on the built-in simulated humanoid: three poses of servos 0..3,
interpolated and sent as synchronized moves at 50 Hz, then the servos' status.

    python crates/python/examples/wck_keyframes.py
"""

from __future__ import annotations

import robobus

# The keyframe text `robobus wck play` reads: `pose T P0 P1 ...` reaches the positions
# (0..=254) in T ms; `hold T` keeps them.
MOTION = """\
torque 2
pose 400 100 150 127 127
pose 400 150 100 127 200
hold 100
pose 400 127 127 127 127
"""


def main() -> None:
    with robobus.Station.simulated() as station:
        played = station.wck.play(MOTION, rate_hz=50)
        summary = played.get("summary") or {}
        print(f"played {summary.get('moves', '?')} synchronized moves")
        status = station.wck.status([0, 1, 2, 3])
        for row in status["results"]:
            print(f"servo {row['id']}: position {row['position']} ({row['degrees']:.1f} deg)")


if __name__ == "__main__":
    main()
