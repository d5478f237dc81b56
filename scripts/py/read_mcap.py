#!/usr/bin/env python3
"""Reads an MCAP recording of `robobus monitor --record FILE.mcap` (or `robobus robot play
--record`) with the `mcap` package (and `mcap-ros2-support` for the CDR joint states) and
prints one JSON summary: the channels with their encodings, schemas and message counts
from the summary section, the samples (JSON), the decoded joint states and the decoded
joint commands (a played trajectory's targets), each with its log time in ns.

Usage: read_mcap.py FILE.mcap
"""

import json
import math
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def main(path: str) -> None:
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        channels = {
            c.topic: {
                "message_encoding": c.message_encoding,
                "schema": summary.schemas[c.schema_id].name,
                "schema_encoding": summary.schemas[c.schema_id].encoding,
                "count": summary.statistics.channel_message_counts.get(c.id, 0),
            }
            for c in summary.channels.values()
        }
        samples = [
            {"log_time": message.log_time, "sample": json.loads(message.data)}
            for _schema, _channel, message in reader.iter_messages(topics=["/robobus/samples"])
        ]
        states = [
            {
                "log_time": message.log_time,
                "stamp_ns": decoded.header.stamp.sec * 1_000_000_000 + decoded.header.stamp.nanosec,
                "name": list(decoded.name),
                "position": list(decoded.position),
                # A velocity that was not measured is NaN in the message, null here.
                "velocity": [None if math.isnan(v) else v for v in decoded.velocity],
                # An effort without an estimate (a wCK servo's) is NaN too: null here.
                "effort": [None if math.isnan(e) else e for e in decoded.effort],
            }
            for _schema, _channel, message, decoded in reader.iter_decoded_messages(
                topics=["/joint_states"]
            )
        ]
        commands = [
            {
                "log_time": message.log_time,
                "stamp_ns": decoded.header.stamp.sec * 1_000_000_000 + decoded.header.stamp.nanosec,
                "name": list(decoded.name),
                "position": list(decoded.position),
            }
            for _schema, _channel, message, decoded in reader.iter_decoded_messages(
                topics=["/robobus/joint_commands"]
            )
        ]
    json.dump(
        {"channels": channels, "samples": samples, "states": states, "commands": commands},
        sys.stdout,
        allow_nan=False,
    )


if __name__ == "__main__":
    main(sys.argv[1])
