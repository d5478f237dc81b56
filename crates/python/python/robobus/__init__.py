"""robobus: drive RoboBuilder wCK servos and RealMan WHJ joints, or their simulators.

Every operation is a request of the library's catalogue: a dict in its JSON form
(``{"op": "whj.move", "joint": 1, "degrees": 30}``), planned and run by the library, with
the host safety limits and the confirmation rule decided there, as for the command line.

>>> import robobus
>>> with robobus.Station.simulated() as station:
...     report = station.wck.status("0-2")
...     [row["position"] for row in report["results"]]
[127, 127, 127]

- :class:`Station` holds the open buses: ``Station.simulated()`` (the built-in simulated
  robot: 16 wCK servos, 7 WHJ joints, in-process, moving in real time;
  ``clock="virtual"`` runs it on the simulators' virtual clock, ``station.clock`` says
  which), ``Station.open(...)`` from the command line's address strings,
  :func:`open_wck` / :func:`open_whj` for one bus.
- ``station.run(request)`` returns the request's report as a dict equal to what
  ``robobus run`` prints; ``station.wck.<op>(...)``, ``station.whj.<op>(...)`` and
  ``station.robot.sample()`` (and ``station.host.ports()``, the machine's serial ports) are
  the same requests with the request's field names as keyword arguments (the required
  ones may be given in order): each has its request's signature and docs
  (``help(station.whj.move)``), and a refused argument is named as written (``ids=``).
- ``station.telemetry(request, rate_hz)`` streams a reading request; iterate it.
- Hot paths take and give numpy arrays: ``station.wck_servos(ids)`` /
  ``station.whj_joints(ids)`` (and one device: ``wck_servo``, ``whj_joint``),
  ``station.cyclic(joints)``, and :class:`Robot` (a robot file's joints in radians).
- :mod:`robobus.lerobot` is a LeRobot motors bus over the same handles, and a LeRobot
  robot class on it (``RobobusFollower``, a follower arm).
- Errors are :mod:`robobus.errors` classes, one per error kind, also deriving from the
  matching builtin (``ValueError``, ``TimeoutError``, ``OSError``, ...). A device that
  failed raises its kind's class (a silent one :class:`NoDeviceError`) with the report
  under ``.report``; ``check=False`` returns the report with a row per device instead.
- :meth:`Station.close` (or leaving its ``with``, or dropping it) stops whatever runs on
  the station (telemetry streams, cyclic loops, calls on other threads), brings every
  device to its safe state and releases the ports; any later call on the station or on
  what was made from it raises. A station belongs to the process that opened it: in a
  child made by ``os.fork()`` (``multiprocessing``'s default on Linux) every call on it
  raises :class:`RefusedError` at once; open a new station in the child.
- Calls release the GIL while they wait on a device; Ctrl-C during a call brings its
  devices to their safe state and raises ``KeyboardInterrupt``.
"""

from __future__ import annotations

import atexit
import json
import weakref
from typing import Any, Iterator, Sequence

from . import _signatures, errors
import numpy as np
import numpy.typing as npt

from ._robobus import (
    NativeCyclic,
    NativeStation,
    NativeTelemetry,
    schema as _schema,
    version as _version,
)
from .handles import (
    JointReadings,
    Readings,
    Robot,
    RobotCommand,
    RobotState,
    WckReadings,
    WckServo,
    WckServos,
    WhjJoint,
    WhjJoints,
    _ids,
)
from .errors import (
    BadInputError,
    DeviceError,
    LinkError,
    NoDeviceError,
    NotAvailableError,
    ProtectionError,
    RefusedError,
    RobobusError,
    StoppedError,
    check,
)

__version__: str = _version()

__all__ = [
    "BadInputError",
    "DeviceError",
    "LinkError",
    "NoDeviceError",
    "NotAvailableError",
    "ProtectionError",
    "RefusedError",
    "RobobusError",
    "JointReadings",
    "Readings",
    "Robot",
    "RobotCommand",
    "RobotState",
    "Station",
    "StoppedError",
    "WckReadings",
    "WckServo",
    "WckServos",
    "WhjJoint",
    "WhjJoints",
    "Cycle",
    "Cyclic",
    "JointBus",
    "Telemetry",
    "arrays",
    "WckBus",
    "check",
    "errors",
    "open_wck",
    "open_whj",
    "operations",
    "plan",
    "schema",
]


def schema(of: str = "request") -> dict[str, Any]:
    """The JSON Schema of a ``"request"``, a ``"report"`` or a ``"plan"``."""
    return json.loads(_schema(of))


_SPECS = _signatures.operations(schema("request"))
# Each operation's parameters as a call takes them (no ``self``, no ``check``).
_REQUEST_SIGNATURES = {
    op: _signatures.signature(o, self_=False, check=False) for op, o in _SPECS.items()
}


def operations() -> list[str]:
    """The names of every operation (``"wck.scan"``, ``"whj.move"``, ...)."""
    return sorted(_SPECS)


method_name = _signatures.method_name


def _bind(op: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> dict[str, Any]:
    """The request dict of ``op`` from a call's arguments, bound to its signature (a
    missing, unknown or doubled argument is refused in Python's words, naming it)."""
    try:
        bound = _REQUEST_SIGNATURES[op].bind(*args, **kwargs)
    except TypeError as e:
        raise BadInputError(f"{op}: {e}; nothing was sent", "bad-input") from None
    req: dict[str, Any] = {"op": op}
    fields = {f.name: f.field for f in _SPECS[op].fields}
    for name, value in bound.arguments.items():
        if value is not None:
            req[fields[name]] = _plain(value)
    return req


def request(op: str, *args: Any, **kwargs: Any) -> dict[str, Any]:
    """The request dict of ``op`` with the required arguments given in order and the rest
    by name (``None`` values are left out, as an omitted option)."""
    if op not in _SPECS:
        raise BadInputError(f"op {op!r}: unknown operation; nothing was sent", "bad-input")
    return _bind(op, args, kwargs)


def _plain(value: Any) -> Any:
    """numpy scalars and arrays, tuples and ranges as plain JSON values."""
    if hasattr(value, "tolist") and callable(value.tolist):
        return value.tolist()
    if isinstance(value, (tuple, range)):
        return [_plain(v) for v in value]
    return value


def plan(request_: dict[str, Any] | str) -> dict[str, Any]:
    """The plan of a request: the exact packets / frames it sends (``steps``, ``text``: what
    ``--dry-run`` prints), its notes and what it needs confirmed. Opens nothing."""
    return NativeStation.plan(request_)


class _Family:
    """The operations of one family as methods (``station.wck.status("0-2")``), each with
    its request's signature and docs."""

    _family = ""

    def __init__(self, station: "Station"):
        self._station = station

    def __getattr__(self, name: str) -> Any:
        # Only names that are no method come here.
        if name.startswith("__"):
            raise AttributeError(name)
        ops = sorted(o.name for o in _SPECS.values() if o.family == self._family)
        raise AttributeError(
            f"robobus has no operation {self._family}.{name} (there are: {', '.join(ops)})"
        )

    def __repr__(self) -> str:
        return f"<robobus operations {self._family}.* of {self._station!r}>"


def _method(o: _signatures.Operation) -> Any:
    """The method of operation ``o``: binds its arguments, runs the request."""
    op = o.op

    def call(self: _Family, *args: Any, check: bool = True, **kwargs: Any) -> dict[str, Any]:
        return self._station.run(_bind(op, args, kwargs), check=check)

    call.__name__ = o.name
    call.__qualname__ = f"{o.family.capitalize()}Ops.{o.name}"
    call.__doc__ = _signatures.docstring(o)
    call.__signature__ = _signatures.signature(o)  # type: ignore[attr-defined]
    return call


def _family_class(family: str) -> type[_Family]:
    """The class of ``station.<family>``: one method per operation of the family."""
    body: dict[str, Any] = {
        "_family": family,
        "__doc__": f"The {family}.* operations of the catalogue, one method each "
        "(``help()`` shows each one's parameters).",
        "__module__": __name__,
    }
    for o in _SPECS.values():
        if o.family == family:
            body[o.name] = _method(o)
    return type(f"{family.capitalize()}Ops", (_Family,), body)


WckOps = _family_class("wck")
WhjOps = _family_class("whj")
RobotOps = _family_class("robot")
HostOps = _family_class("host")


class Station:
    """The open buses of a session, with every operation of the catalogue.

    Use it as a context manager, or call :meth:`close` (idempotent): every device is then
    brought to its safe state and the ports are released at once, so they can be opened
    again right away.
    """

    def __init__(self, native: NativeStation):
        self._native = native
        _OPEN.add(self)
        self.wck = WckOps(self)
        self.whj = WhjOps(self)
        self.robot = RobotOps(self)
        self.host = HostOps(self)

    @classmethod
    def simulated(cls, *, read_only: bool = False, clock: str = "wall") -> "Station":
        """The built-in simulated robot, in-process: 16 wCK servos (IDs 0..=15) on the
        bus ``sim-wck``, 7 WHJ30 joints (IDs 1..=7) on ``sim-whj``, and a robot file
        naming them ``s0``..``s15`` and ``j1``..``j7``. No pty, no network.

        ``clock="wall"`` (the default): the simulators run in real time, as hardware
        does (a joint moving at 30°/s has moved 30° a second later, whether or not it
        was read in between). ``clock="virtual"``: they run on their own virtual clock,
        which moves only as the buses are driven (each request advances it by the time
        its transfers and waits take on the wire), so every run gives the same readings
        and a long wait costs no wall time; a joint does not move while Python sleeps.
        :attr:`clock` says which. ``read_only``: see :meth:`open`."""
        return cls(NativeStation.simulated(read_only, clock))

    @classmethod
    def open(
        cls,
        wck_ports: Sequence[str] = (),
        whj_buses: Sequence[str] = (),
        robot: str | None = None,
        *,
        wck_baud: int = 115200,
        reply_margin_ms: float | None = None,
        wait: str = "sleep",
        read_only: bool = False,
    ) -> "Station":
        """Opens wCK serial ports (at ``wck_baud``), WHJ buses (``udp``,
        ``udp:GROUP:PORT``, a SocketCAN interface) and a robot file's buses, from the
        same strings as the command line's ``--wck-port``, ``--whj-bus`` and ``--robot``.
        Requests name a bus under ``bus`` when the station has several of a family.
        ``wait`` is the command line's ``--wait``: ``"sleep"`` (in the kernel), or
        ``"spin"`` / ``"spin:US"`` (poll from shortly before each reply is due: lower
        latency, a core busy while a reply is awaited).

        Every station admits requests as the studio and the bridge do: at most 10
        EEPROM / flash / ID writes a minute, motion only while armed (a station starts
        armed: :meth:`disarm` and :meth:`arm`), and with ``read_only=True`` only reading
        requests (it never arms); a refusal raises :class:`RefusedError`, nothing sent."""
        if isinstance(wck_ports, str):
            wck_ports = [wck_ports]
        if isinstance(whj_buses, str):
            whj_buses = [whj_buses]
        native = NativeStation.open(
            list(wck_ports), list(whj_buses), robot, wck_baud, reply_margin_ms, wait, read_only
        )
        return cls(native)

    def run(self, request_: dict[str, Any] | str, *, check: bool = True) -> dict[str, Any]:
        """Runs one request and returns its report (``op``, ``bus``, ``results``: one row
        per device keyed ``id``, ``summary``). A failed device raises its kind's error (the
        worst one's, a silent device :class:`NoDeviceError`), the report under ``.report``.
        With ``check=False`` the report is returned as it is: ``failed`` / ``error`` name
        the worst failure and each failed device's row has its ``kind`` and ``error``."""
        report: dict[str, Any] = self._native.run(request_)
        # No device failed (the common case) is seen here, without a call.
        if not check or report.get("failed") is None:
            return report
        return errors.check(report)

    def run_many(
        self, requests: Sequence[dict[str, Any]], *, check: bool = True
    ) -> list[dict[str, Any]]:
        """Runs requests in order, every one checked before any is sent; stops at the
        first that fails as a whole, or (unless ``check=False``) in which a device failed."""
        for r in requests:
            NativeStation.validate(r)
        return [self.run(r, check=check) for r in requests]

    @property
    def buses(self) -> tuple[list[str], list[str]]:
        """The names of the wCK ports and of the WHJ buses."""
        return self._native.names()

    @property
    def closed(self) -> bool:
        """Whether it is closed."""
        return self._native.closed

    @property
    def clock(self) -> str:
        """The clock the devices run on: ``"wall"`` (hardware, and the simulated robot
        by default) or ``"virtual"`` (``Station.simulated(clock="virtual")``)."""
        return str(self._native.clock)

    @property
    def armed(self) -> bool:
        """Whether motion is armed (moves, waves, handles' moves, cyclic loops)."""
        return self._native.armed

    @property
    def read_only(self) -> bool:
        """Whether it was opened ``read_only``: only reading requests run."""
        return self._native.read_only

    def arm(self) -> None:
        """Arms motion again after :meth:`disarm` (refused on a read-only station)."""
        self._native.arm()

    def disarm(self) -> None:
        """Disarms: every motion request, handle move and cyclic loop is refused
        (:class:`RefusedError`, nothing sent) until :meth:`arm`."""
        self._native.disarm()

    def telemetry(
        self,
        request_: dict[str, Any] | str,
        rate_hz: float,
        *,
        limit: int | None = None,
        queue: int = 256,
    ) -> "Telemetry":
        """Samples a reading request (``wck.sample``, ``wck.status``, ``whj.sample``,
        ``whj.status``, ``robot.sample``) at ``rate_hz`` on its own thread; iterate the
        stream for each sample (``seq``, ``unix_ms``, ``age_ms``, ``late``, ``lost``,
        ``report``). A subscriber that falls ``queue`` samples behind loses its oldest."""
        return Telemetry(self._native.telemetry(request_, rate_hz, limit, queue))

    def cyclic(
        self,
        joints: Sequence[int] | npt.ArrayLike,
        mode: str = "position",
        *,
        rate_hz: float = 200.0,
        bus: str | None = None,
    ) -> "Cyclic":
        """Starts a cyclic servo loop on a WHJ bus: ``mode`` targets (``"position"``
        degrees, ``"speed"`` RPM, ``"current"`` mA) for ``joints`` at ``rate_hz``. Each
        joint must be enabled in that work mode; every target is checked against its
        limits before the loop sends it. Position targets move along a speed- and
        acceleration-limited profile. Stop it with :meth:`Cyclic.stop` (or a ``with``)."""
        ids = [int(j) for j in np.asarray(joints).ravel()]
        return Cyclic(self._native.cyclic(ids, mode, rate_hz, bus))

    def wck_servos(self, ids: Sequence[int] | npt.ArrayLike, *, bus: str | None = None) -> WckServos:
        """A handle on wCK servos ``ids`` of the port ``bus`` (needed when the station has
        several): status, moves and passive with arrays in and out, no request per call.
        Nothing is sent until it is used."""
        return WckServos(self._native.wck_servos(_ids(ids, "ids"), bus))

    def wck_servo(self, id: int, *, bus: str | None = None) -> WckServo:
        """A handle on one wCK servo (see :meth:`wck_servos`)."""
        return WckServo(self._native.wck_servos(_ids([id], "id"), bus))

    def whj_joints(self, ids: Sequence[int] | npt.ArrayLike, *, bus: str | None = None) -> WhjJoints:
        """A handle on WHJ joints ``ids`` of the bus ``bus``: status and servo frames with
        arrays in and out, no request per call. Each joint is connected now (a silent one
        raises :class:`NoDeviceError`)."""
        return WhjJoints(self._native.whj_joints(_ids(ids, "ids"), bus))

    def whj_joint(self, id: int, *, bus: str | None = None) -> WhjJoint:
        """A handle on one WHJ joint (see :meth:`whj_joints`)."""
        return WhjJoint(self._native.whj_joints(_ids([id], "id"), bus))

    def close(self) -> list[str]:
        """Stops whatever runs on the station (its telemetry streams and cyclic loops,
        a call under way on another thread), brings every device to its safe state (wCK:
        the bus-wide break; WHJ: every connected joint disabled) and releases the ports.
        Returns the failures, one message per device. A second call does nothing; any
        other later call on the station, its streams, loops or handles raises
        :class:`BadInputError` naming the call. Dropping the station closes it too."""
        return self._native.close()

    def leave(self) -> None:
        """Releases the ports leaving every device as the last request left it (a joint
        enabled stays enabled); its streams and loops are stopped all the same."""
        self._native.leave()

    def __enter__(self) -> "Station":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        if self.closed:
            return "<robobus.Station closed>"
        try:
            wck, whj = self.buses
        except RefusedError:
            return "<robobus.Station of another process>"
        return f"<robobus.Station wck={wck} whj={whj} clock={self.clock}>"


# The stations not closed yet: closed when the interpreter exits (it need not collect
# them), so that no device is left moving and no stream's thread outlives Python.
_OPEN: "weakref.WeakSet[Station]" = weakref.WeakSet()


@atexit.register
def _close_open_stations() -> None:
    for station in list(_OPEN):
        try:
            station.close()
        except RobobusError:
            # A forked child's inherited station: the parent's to close.
            pass


class Cycle:
    """One cycle of a :class:`Cyclic` loop, as arrays in joint order: ``position_deg``,
    ``speed_rpm``, ``current_ma`` (``NaN`` where a joint's feedback did not arrive),
    ``enabled`` and ``valid`` (booleans), ``commanded`` (what was sent, the loop's unit),
    and ``cycle``, ``missed``, ``round_trip_us``, ``error`` (per joint, ``None`` when
    missing)."""

    __slots__ = (
        "commanded",
        "current_ma",
        "cycle",
        "enabled",
        "error",
        "missed",
        "position_deg",
        "round_trip_us",
        "speed_rpm",
        "valid",
    )

    def __init__(self, c: dict[str, Any]):
        nan = float("nan")
        self.cycle: int = c["cycle"]
        self.missed: bool = c["missed"]
        self.round_trip_us: float | None = c["round_trip_us"]
        self.commanded = np.asarray(c["commanded"], dtype=np.float64)
        self.valid = np.asarray(c["valid"], dtype=bool)
        self.position_deg = np.asarray(
            [nan if v is None else v for v in c["position_deg"]], dtype=np.float64
        )
        self.speed_rpm = np.asarray([nan if v is None else v for v in c["speed_rpm"]], dtype=np.float64)
        self.current_ma = np.asarray(
            [nan if v is None else v for v in c["current_ma"]], dtype=np.float64
        )
        self.enabled = np.asarray([bool(v) for v in c["enabled"]], dtype=bool)
        self.error: list[str | None] = c["error"]

    def __repr__(self) -> str:
        return (
            f"<robobus.Cycle {self.cycle}{' missed' if self.missed else ''} "
            f"position_deg={self.position_deg.tolist()}>"
        )


class Cyclic:
    """A running cyclic loop (see :meth:`Station.cyclic`): :meth:`set` the targets (an
    array, one per joint), read each cycle with :meth:`next` or by iterating."""

    def __init__(self, native: NativeCyclic):
        self._native = native

    @property
    def joints(self) -> list[int]:
        """The joints, in target and feedback order."""
        return list(self._native.joints)

    @property
    def limits(self) -> npt.NDArray[np.float64]:
        """Each joint's allowed targets: an ``(n, 2)`` array of ``low, high``."""
        return np.asarray(self._native.limits, dtype=np.float64).reshape(-1, 2)

    def set(self, targets: npt.ArrayLike) -> None:
        """Sets the targets (one per joint, any array-like of numbers); each is checked
        against its joint's limits first, and on a refusal none is changed."""
        self._native.set(np.asarray(targets, dtype=np.float64).ravel().tolist())

    def next(self, timeout: float = 1.0) -> Cycle | None:
        """The next cycle (oldest first), waiting at most ``timeout`` s; ``None`` on
        timeout or once stopped."""
        c = self._native.next(timeout)
        return None if c is None else Cycle(c)

    def latest(self) -> Cycle | None:
        """The most recent cycle, if one has finished."""
        c = self._native.latest()
        return None if c is None else Cycle(c)

    def clear(self) -> None:
        """Drops the queued cycles (before waiting for a fresh one)."""
        self._native.clear()

    def summary(self) -> dict[str, Any] | None:
        """What the loop did so far: cycles, misses, missing replies, round trips."""
        return self._native.summary()

    def stop(self) -> dict[str, Any] | None:
        """Stops the loop: what it did; ``None`` if it was stopped before (or by closing
        its station)."""
        return self._native.stop()

    def __iter__(self) -> Iterator[Cycle]:
        while True:
            c = self.next(1.0)
            if c is None:
                return
            yield c

    def __enter__(self) -> "Cyclic":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def arrays(report: dict[str, Any], *fields: str) -> dict[str, npt.NDArray[Any]]:
    """A report's rows as arrays, one per field (and ``id``): numbers as ``float64`` with
    ``NaN`` where a device failed (its row has no value: a report asked for with
    ``check=False``), booleans as ``bool``. Without ``fields``, every numeric field of the
    rows."""
    rows = report["results"]
    if not fields:
        seen: dict[str, None] = {}
        for r in rows:
            for k, v in r.items():
                if k != "id" and isinstance(v, (int, float)):
                    seen[k] = None
        fields = tuple(seen)
    out: dict[str, npt.NDArray[Any]] = {"id": np.asarray([r["id"] for r in rows])}
    for f in fields:
        values = [r.get(f) for r in rows]
        if all(isinstance(v, bool) for v in values):
            out[f] = np.asarray(values, dtype=bool)
        else:
            out[f] = np.asarray(
                [float("nan") if v is None or isinstance(v, str) else v for v in values],
                dtype=np.float64,
            )
    return out


class Telemetry:
    """A telemetry stream: an iterator of samples (dicts), until it is stopped or its
    ``limit`` is reached. Use it as a context manager, or call :meth:`stop`."""

    def __init__(self, native: NativeTelemetry):
        self._native = native

    def __iter__(self) -> Iterator[dict[str, Any]]:
        return self

    def __next__(self) -> dict[str, Any]:
        sample = self._native.next(None)
        if sample is None:
            raise StopIteration
        return sample

    def next(self, timeout: float | None = None) -> dict[str, Any] | None:
        """The next sample, waiting at most ``timeout`` seconds (:class:`NoDeviceError`
        after it); ``None`` once the stream has ended."""
        return self._native.next(timeout)

    @property
    def lost(self) -> int:
        """Samples this subscriber lost so far (its queue was full)."""
        return self._native.lost

    def stop(self) -> dict[str, int] | None:
        """Stops the stream: what it did (``samples``, ``late``, ``failed``); ``None`` if
        it was stopped before (or by closing its station)."""
        return self._native.stop()

    def __enter__(self) -> "Telemetry":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class WckBus(Station):
    """A station of one wCK serial port: ``WckBus.open("/dev/ttyUSB0", baud=115200)``."""

    @classmethod
    def open(  # type: ignore[override]
        cls, port: str, baud: int = 115200, *, reply_margin_ms: float | None = None
    ) -> "WckBus":
        """Opens the port (``/dev/ttyUSB0``, or the path ``robobus sim wck`` prints)."""
        return cls(NativeStation.open([port], [], None, baud, reply_margin_ms))


class JointBus(Station):
    """A station of one WHJ bus: ``JointBus.open("can0")``."""

    @classmethod
    def open(cls, bus: str) -> "JointBus":  # type: ignore[override]
        """Opens ``udp``, ``udp:GROUP:PORT`` or a SocketCAN interface."""
        return cls(NativeStation.open([], [bus], None, 115200, None))


def open_wck(port: str, baud: int = 115200, *, reply_margin_ms: float | None = None) -> WckBus:
    """:meth:`WckBus.open`."""
    return WckBus.open(port, baud, reply_margin_ms=reply_margin_ms)


def open_whj(bus: str) -> JointBus:
    """:meth:`JointBus.open`."""
    return JointBus.open(bus)
