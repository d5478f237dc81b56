"""The golden vectors of the bridge's `diagnostic_msgs/msg/DiagnosticArray` encoder, written
by rosbags (a CDR implementation that is not ours): `python diagnostics_vectors.py` prints
them in the format of `crates/bridge/tests/vectors/diagnostic_array.hex` (one `name hex`
line per message), which the Rust unit tests read and test_diagnostics.py checks against
rosbags again."""

from __future__ import annotations

import pathlib

from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_HUMBLE)
ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
VECTORS = pathlib.Path(__file__).resolve().parents[1] / "vectors" / "diagnostic_array.hex"


def message(stamp: tuple[int, int], frame_id: str, statuses: list) -> object:
    T = TS.types
    header = T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=stamp[0], nanosec=stamp[1]), frame_id=frame_id)
    status = [
        T["diagnostic_msgs/msg/DiagnosticStatus"](
            level=level, name=name, message=msg, hardware_id=hw,
            values=[T["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in values])
        for level, name, msg, hw, values in statuses
    ]
    return T[ARRAY](header=header, status=status)


# The messages, as the Rust tests build them (crates/bridge/src/diagnostics.rs).
MESSAGES = {
    "two": message((1, 2), "", [
        (0, "robobus: bot1 joint j1", "OK", "whj arm 1",
         [("position_deg", "12.500"), ("temperature_c", "35.0")]),
        (2, "robobus: bot1 bus arm", "1 of 3 joints in error: j3", "whj arm", []),
    ]),
    "empty": message((1_700_000_000, 999_999_999), "base", []),
}


def vectors() -> dict[str, str]:
    return {name: bytes(TS.serialize_cdr(m, ARRAY)).hex() for name, m in MESSAGES.items()}


if __name__ == "__main__":
    for name, h in vectors().items():
        print(name, h)
