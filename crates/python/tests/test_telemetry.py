"""Python's telemetry streams are subscriptions to the station's one sampling of a bus
(the library's `Station::telemetry`), shared with every other reader of the bus: a
second subscriber costs the bus nothing, and `limit` and `stop()`'s statistics are the
subscription's own.

The frames are counted where the host hands them to the simulated bus
(`_robobus._whj_frames_sent`), on the simulators' virtual clock.
"""

from __future__ import annotations

from typing import Any

import pytest

import robobus
from robobus import _robobus

#: Frames of one `whj.sample` of one joint: its status query and its speed read.
FRAMES_PER_JOINT = 2


def _ids(sample: dict[str, Any]) -> list[int]:
    return [row["id"] for row in sample["report"]["results"]]


def _drain(stream: robobus.Telemetry) -> list[dict[str, Any]]:
    """Everything a stopped stream still had queued."""
    out = []
    while (s := stream.next(timeout=5)) is not None:
        out.append(s)
    return out


def test_two_python_streams_and_a_studio_style_one_share_one_sampling_of_the_bus() -> None:
    with robobus.Station.simulated(clock="virtual") as station:
        # The joints connected and their limits read once, as a first sample does.
        station.run({"op": "whj.sample", "joints": "1-3"})
        before = _robobus._whj_frames_sent(station._native)
        # A subscriber as a studio page makes one (joints 1-3 at 100 Hz, a queue of 64),
        # then two Python ones: joints 1-2 at the same rate, joint 3 at a quarter of it.
        studio = station.telemetry({"op": "whj.sample", "joints": "1-3"}, 100.0, queue=64)
        first = studio.next(timeout=5)
        assert first is not None and _ids(first) == [1, 2, 3]
        a = station.telemetry({"op": "whj.sample", "joints": "1-2"}, 100.0, queue=4096)
        b = station.telemetry({"op": "whj.sample", "joints": "3"}, 25.0, queue=4096)
        seen = [first]
        got_a = []
        for _ in range(20):
            got_a.append(a.next(timeout=5))
            seen.append(studio.next(timeout=5))
        got_b = [b.next(timeout=5) for _ in range(5)]
        stats_a, stats_b = a.stop(), b.stop()
        got_a += _drain(a)
        got_b += _drain(b)
        seen += [studio.next(timeout=5) for _ in range(10)]
        stats_studio = studio.stop()
        seen += _drain(studio)
        after = _robobus._whj_frames_sent(station._native)

    assert stats_a is not None and stats_b is not None and stats_studio is not None
    # Each got its own joints, numbered 0, 1, 2, ... with nothing lost, from the one
    # sampling: every sample the Python streams got is one the studio's got, read once
    # (the same read time and duration), the bus read pipelined.
    reads = {(s["unix_ms"], s["read_ms"]) for s in seen}
    for got, joints, stats in [(got_a, [1, 2], stats_a), (got_b, [3], stats_b)]:
        assert all(s is not None for s in got)
        assert [s["seq"] for s in got] == list(range(len(got)))
        for s in got:
            assert _ids(s) == joints and s["lost"] == 0 and s["sampled_by"] == "pipelined"
            assert s["report"].get("failed") is None, s
            assert (s["unix_ms"], s["read_ms"]) in reads, s
        late = sum(s["late"] for s in got)
        assert stats == {"samples": len(got), "late": late, "failed": 0}
    assert all(s is not None and s["lost"] == 0 for s in seen)
    assert [s["seq"] for s in seen] == list(range(len(seen)))
    assert stats_studio["samples"] == len(seen) and stats_studio["failed"] == 0
    # The slow stream's samples are a quarter of the others': every 4th of the bus's.
    assert len(got_b) < len(got_a) // 2
    # The bus carried one read of the union (joints 1-3) per sample, however many
    # streams: the studio's stream got every sample taken, but those a stopped stream
    # no longer took (its last read under way, at most the delivery's 4 queued).
    frames = after - before
    per_sample = 3 * FRAMES_PER_JOINT
    assert frames % per_sample == 0, frames
    assert len(seen) <= frames // per_sample <= len(seen) + 5, (frames, len(seen))


def test_a_limited_stream_ends_after_its_count_and_stop_says_what_it_was_given() -> None:
    with robobus.Station.simulated(clock="virtual") as station:
        other = station.telemetry({"op": "whj.sample", "joints": "2"}, 100.0)
        assert other.next(timeout=5) is not None
        with station.telemetry({"op": "whj.sample", "joints": "1"}, 100.0, limit=4) as s:
            got = list(s)
            assert [x["seq"] for x in got] == [0, 1, 2, 3]
            assert all(_ids(x) == [1] for x in got)
            stats = s.stop()
            assert stats is not None and stats["samples"] == 4 and stats["failed"] == 0
            assert s.stop() is None
        # The other subscriber reads on.
        assert [_ids(other.next(timeout=5) or {}) for _ in range(3)] == [[2]] * 3
        other.stop()
        with pytest.raises(robobus.BadInputError, match="limit"):
            station.telemetry({"op": "whj.sample", "joints": "1"}, 100.0, limit=0)
