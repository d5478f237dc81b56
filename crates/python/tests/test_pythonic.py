"""The package as Python users expect it: the simulated robot moves in real time unless the
virtual clock is asked for (and says which it runs on); every generated operation has its
request's signature, docs and stub; a refused argument is named as Python writes it; a
failed device raises, the per-device report attached.
"""

from __future__ import annotations

import ast
import inspect
import pathlib
import pydoc
import time
from typing import Any

import pytest

import robobus
from robobus import _signatures

PKG = pathlib.Path(robobus.__file__).resolve().parent
STUB = pathlib.Path(__file__).resolve().parents[1] / "python" / "robobus" / "__init__.pyi"


def first_position(station: robobus.Station, joint: int) -> float:
    return float(station.whj.status(str(joint))["results"][0]["position_deg"])


def aim_three_degrees(station: robobus.Station) -> float:
    """Joint 1 in position mode, enabled, sent one servo frame with a target of 3 degrees;
    the position read right after it."""
    station.whj.mode("1", "position")
    station.whj.enable("1")
    joint = station.whj_joint(1)
    joint.command_position(3.0)
    return first_position(station, 1)


def test_the_simulated_robot_reaches_a_goal_after_its_wall_clock_time() -> None:
    with robobus.Station.simulated() as station:
        assert station.clock == "wall"
        assert "clock=wall" in repr(station)
        aim_three_degrees(station)
        time.sleep(2.0)
        # Two seconds of wall time later it is there, with nothing sent in between (on
        # the virtual clock it reads a few thousandths of a degree here, however long
        # Python sleeps).
        assert first_position(station, 1) == pytest.approx(3.0, abs=0.01)
        # A move of 3 degrees at 2 degrees/s takes its 1.5 s of wall time, frame by frame.
        start = time.monotonic()
        station.whj.move(1, 6.0, max_speed=2.0)
        assert time.monotonic() - start >= 1.5
        assert first_position(station, 1) == pytest.approx(6.0, abs=0.01)


def test_the_virtual_clock_is_still_there_when_asked_for() -> None:
    with robobus.Station.simulated(clock="virtual") as station:
        assert station.clock == "virtual"
        aim_three_degrees(station)
        # The simulators' clock moves only as the bus is driven: Python's sleep moves
        # nothing (the surprise the wall clock is now the default against).
        time.sleep(0.5)
        assert first_position(station, 1) < 0.1
    with pytest.raises(robobus.BadInputError) as bad:
        robobus.Station.simulated(clock="sundial")
    assert str(bad.value) == (
        "clock=\"sundial\": not a clock (allowed: \"wall\", \"virtual\"); nothing was opened"
    )


def test_a_silent_device_among_others_raises_with_every_row_attached() -> None:
    with robobus.Station.simulated(clock="virtual") as station:
        with pytest.raises(robobus.NoDeviceError) as silent:
            station.wck.status("0,20,1")
        report = silent.value.report
        assert report is not None and report["failed"] == "no-device"
        rows = {r["id"]: r for r in report["results"]}
        assert rows[0]["position"] == 127 and rows[1]["position"] == 127
        assert rows[20]["kind"] == "no-device"
        # check=False returns the same rows instead of raising.
        assert station.wck.status("0,20,1", check=False)["results"] == report["results"]


def stub_methods() -> dict[str, ast.FunctionDef]:
    """The generated methods as the checked-in stub declares them, by ``family.name``."""
    tree = ast.parse(STUB.read_text())
    out: dict[str, ast.FunctionDef] = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name.endswith("Ops"):
            family = node.name.removesuffix("Ops").lower()
            for f in node.body:
                if isinstance(f, ast.FunctionDef):
                    out[f"{family}.{f.name}"] = f
    return out


def test_every_generated_operation_has_its_requests_signature_docs_and_stub() -> None:
    schema = robobus.schema("request")
    stubs = stub_methods()
    station = robobus.Station.simulated(clock="virtual")
    try:
        walked = 0
        for variant in schema["oneOf"]:
            props = variant["properties"]
            op = props["op"]["const"]
            family = op.split(".", 1)[0]
            name = robobus.method_name(op)
            method = getattr(getattr(station, family), name)
            sig = inspect.signature(method)
            params = list(sig.parameters.values())
            kinds = {p.kind for p in params}
            assert inspect.Parameter.VAR_POSITIONAL not in kinds, (op, sig)
            assert inspect.Parameter.VAR_KEYWORD not in kinds, (op, sig)
            required = [f for f in variant.get("required", []) if f != "op"]
            fields = [f for f in props if f != "op"]
            # The required fields in order (positional or by name), then every other
            # field by name, then check.
            expected = [_signatures.arg(f) for f in required]
            expected += sorted(_signatures.arg(f) for f in fields if f not in required)
            assert [p.name for p in params] == [*expected, "check"], (op, sig)
            for p in params[: len(required)]:
                assert p.kind is p.POSITIONAL_OR_KEYWORD and p.default is p.empty, (op, p)
            for p in params[len(required) :]:
                assert p.kind is p.KEYWORD_ONLY, (op, p)
            assert sig.parameters["check"].default is True
            # help() shows the signature and each field's doc.
            text = pydoc.render_doc(method, renderer=pydoc.plaintext)
            assert f"{name}{sig}" in " ".join(text.split()), op
            doc = inspect.getdoc(method) or ""
            flat = " ".join(doc.split())
            for f in fields:
                described = " ".join(str(props[f].get("description", "")).split())
                assert f"{_signatures.arg(f)} (" in doc, (op, f)
                assert described[:40] in flat, (op, f, described)
            # The stub declares the same parameters, of the same kinds.
            stub = stubs[f"{family}.{name}"]
            assert [a.arg for a in stub.args.args] == ["self", *[_signatures.arg(f) for f in required]], op
            assert [a.arg for a in stub.args.kwonlyargs] == [p.name for p in params[len(required) :]], op
            assert ast.get_docstring(stub) == doc, op
            walked += 1
        assert walked == len(robobus.operations()) == len(stubs)
    finally:
        station.close()


def test_the_operations_classes_are_in_help_and_unknown_names_say_what_there_is() -> None:
    with robobus.Station.simulated(clock="virtual") as station:
        assert type(station.wck).__name__ == "WckOps"
        listing = pydoc.render_doc(type(station.whj), renderer=pydoc.plaintext)
        assert "move(self, joint: 'int', degrees: 'float', *" in listing
        with pytest.raises(AttributeError, match=r"no operation wck.fly \(there are: backup, brake"):
            station.wck.fly(1)


@pytest.mark.parametrize(
    "call,message",
    [
        (
            lambda s: s.wck.status("0-300"),
            "ids=0-300: servo ID 300 is out of range 0..=30; nothing was sent",
        ),
        (
            lambda s: s.wck.move(3, 300),
            "position=300: position 300 is out of range 0..=254; nothing was sent",
        ),
        (
            lambda s: s.whj.move(1, 30, max_speed=-3),
            "max_speed=-3: speed (degrees/s) -3 is out of range 0.1..=180 "
            "(allowed: 0.1..=180 deg/s); nothing was sent",
        ),
        (
            lambda s: s.whj.wave(1, amplitude=500),
            "offset= / amplitude= 0 / 500: reach 500 deg, outside -360..=360 deg; nothing was sent",
        ),
        (lambda s: s.wck.status(), "wck.status: missing a required argument: 'ids'; nothing was sent"),
        (
            lambda s: s.wck.status("0", colour="red"),
            "wck.status: got an unexpected keyword argument 'colour'; nothing was sent",
        ),
        (
            lambda s: s.wck.move(3, 100, 2),
            "wck.move: too many positional arguments; nothing was sent",
        ),
    ],
    ids=["ids", "position", "max_speed", "offset-amplitude", "missing", "unknown", "positional"],
)
def test_a_refused_argument_is_named_as_python_writes_it(call: Any, message: str) -> None:
    with robobus.Station.simulated(clock="virtual") as station:
        with pytest.raises(robobus.BadInputError) as bad:
            call(station)
        assert str(bad.value) == message
        assert "<" not in str(bad.value) and "--" not in str(bad.value)
