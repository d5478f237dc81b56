"""A station admits requests by the library's one admission, as the studio and the bridge
do: at most 10 EEPROM / flash / ID writes a minute, motion only while armed, read-only
stations that only read; and a request that is none is refused in the one wording."""

from __future__ import annotations

import pytest

import robobus

WRITE = {"op": "wck.set", "id": 0, "param": "gains", "p": 20, "d": 30, "confirm": True}
MOVE = {"op": "whj.move", "joint": 3, "degrees": 10}


def test_the_eleventh_eeprom_write_within_a_minute_is_refused() -> None:
    with robobus.Station.simulated() as station:
        for _ in range(10):
            station.run(WRITE, check=False)
        with pytest.raises(robobus.RefusedError) as e:
            station.run(WRITE)
        assert e.value.kind == "refused"
        assert str(e.value).startswith(
            "wck.set: at most 10 EEPROM / flash / ID writes a minute (they wear the device's "
            "memory); try again in "
        ), str(e.value)
        assert str(e.value).endswith(" s; nothing was sent")
        # Reads are not counted.
        station.wck.status("0")
    # Each station counts its own writes.
    with robobus.Station.simulated() as other:
        other.run(WRITE, check=False)


def test_motion_needs_the_station_armed_and_it_starts_armed() -> None:
    with robobus.Station.simulated() as station:
        assert station.armed and not station.read_only
        station.disarm()
        assert not station.armed
        with pytest.raises(robobus.RefusedError) as e:
            station.run(MOVE)
        assert str(e.value) == (
            "whj.move: not armed: motion needs this station armed (station.arm()); "
            "nothing was sent"
        )
        with pytest.raises(robobus.RefusedError, match="not armed"):
            station.wck_servo(2).move(100)
        with pytest.raises(robobus.RefusedError, match="not armed"):
            station.cyclic([1])
        # A change that does not move needs no arming.
        station.whj.disable("3")
        station.arm()
        station.wck.move(3, 100)
        station.wck_servo(2).move(100)


def test_a_read_only_station_reads_and_never_arms() -> None:
    with robobus.Station.simulated(read_only=True) as station:
        assert station.read_only and not station.armed
        station.wck.status("0")
        with pytest.raises(robobus.RefusedError) as e:
            station.run(WRITE)
        assert str(e.value) == (
            "wck.set: this station is read-only (opened with read_only=True): only reading "
            "requests run; nothing was sent"
        )
        with pytest.raises(robobus.RefusedError, match="read-only"):
            station.arm()
        with pytest.raises(robobus.RefusedError, match="read-only"):
            station.run(MOVE)
        with pytest.raises(robobus.RefusedError, match="read-only"):
            station.wck_servos([1, 2]).passive()


def test_bad_input_is_said_as_such_before_a_read_only_or_unarmed_refusal() -> None:
    bad_write = dict(WRITE, p=300)
    bad_move = dict(MOVE, degrees=1000)
    write_says = "p=300: P gain 300 is out of range 1..=254; nothing was sent"
    move_says = (
        "degrees=1000: angle (degrees) 1000 is out of range -360..=360 (allowed: -360..=360 "
        "deg); nothing was sent"
    )
    with robobus.Station.simulated(read_only=True) as station:
        for request, says in ((bad_write, write_says), (bad_move, move_says)):
            with pytest.raises(robobus.BadInputError) as e:
                station.run(request)
            assert str(e.value) == says
    with robobus.Station.simulated() as station:
        station.disarm()
        with pytest.raises(robobus.BadInputError) as e:
            station.run(bad_move)
        assert str(e.value) == move_says


def test_a_request_that_is_none_is_refused_in_the_one_wording() -> None:
    with robobus.Station.simulated() as station:
        with pytest.raises(robobus.BadInputError) as e:
            station.run({"op": "wck.status", "ids": "0", "colour": "red"})
        m = str(e.value)
        assert m.startswith("request JSON: unknown field `colour`"), m
        assert m.endswith(
            "(one request object, as the request schema (`robobus schema`) describes); "
            "nothing was sent"
        ), m


def test_the_plan_is_the_one_plan_view() -> None:
    view = robobus.plan({"op": "whj.save", "joints": "4"})
    assert view["effect"] == "configure"
    assert view["confirm"] == "non-volatile"
    assert view["ask"] == view["confirm_text"]
    assert view["text"]
    assert robobus.plan({"op": "whj.save", "joints": "4", "confirm": True})["ask"] is None
