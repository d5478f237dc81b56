"""Handles for the hot paths: wCK servos and WHJ joints driven call by call, and a robot in
SI units, with numpy arrays in and out.

- :class:`WckServos` / :class:`WckServo` (``station.wck_servos(ids)``,
  ``station.wck_servo(id)``): status, position moves (one command each, or one
  synchronized packet), passive.
- :class:`WhjJoints` / :class:`WhjJoint` (``station.whj_joints(ids)``,
  ``station.whj_joint(id)``): status, every position in one array
  (:meth:`WhjJoints.read_positions`, the queries pipelined), and one position / speed /
  current servo frame per joint per call.
- :class:`Robot` (``Robot.simulated()``, ``Robot.open("robot.toml")``): every joint by
  name in radians, behind the robot file's soft limits, speed limits and watchdog.

Every value is checked before anything is sent: one out of range refuses the whole call
(:class:`~robobus.errors.BadInputError` naming the device, the value and the range) and
no device is sent anything. Every reading is fresh: a device that did not answer has
``valid`` ``False`` and ``NaN`` values in that call's arrays, never older ones; a group
call carries on past it, and :meth:`Readings.check` raises its error. The single-device
handles raise it at once.

The single-device calls cost a few microseconds over the same call in Rust: the result is a
dict built natively, and the GIL is released while the bus works.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from ._robobus import NativeRobot, NativeWckServos, NativeWhjJoints
from .errors import BY_KIND, RobobusError

__all__ = [
    "JointReadings",
    "Readings",
    "Robot",
    "RobotCommand",
    "RobotState",
    "WckReadings",
    "WckServo",
    "WckServos",
    "WhjJoint",
    "WhjJoints",
]


def _floats(values: npt.ArrayLike, what: str) -> list[float]:
    """Any array-like of numbers (lists, ints, numpy arrays, strided views) as a flat list
    of floats."""
    a = np.asarray(values)
    if not np.issubdtype(a.dtype, np.number):
        raise _bad_input(f"{what}: {values!r} is not an array of numbers; nothing was sent")
    return a.astype(np.float64).ravel().tolist()


def _bad_input(message: str) -> RobobusError:
    return BY_KIND["bad-input"](message, "bad-input")


def _ids(ids: int | Sequence[int] | npt.ArrayLike, what: str) -> list[int]:
    a = np.asarray(ids).ravel()
    if a.size and not np.issubdtype(a.dtype, np.integer):
        raise _bad_input(f"{what}: {ids!r} are not whole numbers; nothing was sent")
    return [int(v) for v in a]


class Readings:
    """One group call's results, in the group's order: ``id``, ``valid`` (the device
    answered), and per device ``error`` / ``kind`` (``None`` where it answered)."""

    id: npt.NDArray[np.int64]
    valid: npt.NDArray[np.bool_]
    error: list[str | None]
    kind: list[str | None]

    def __init__(self, cols: dict[str, Any]):
        self.id = np.asarray(cols["id"], dtype=np.int64)
        self.valid = np.asarray(cols["valid"], dtype=bool)
        self.error = cols["error"]
        self.kind = cols["kind"]

    def __len__(self) -> int:
        return len(self.id)

    def failed(self) -> list[int]:
        """The devices that did not answer (or answered with an error)."""
        return [int(i) for i, ok in zip(self.id, self.valid) if not ok]

    def check(self) -> "Readings":
        """Returns itself if every device answered, else raises the first failure's error
        class with its message."""
        for err, kind in zip(self.error, self.kind):
            if err is not None:
                raise BY_KIND.get(kind or "", RobobusError)(err, kind or "runtime")
        return self


class WckReadings(Readings):
    """wCK servos' readings: ``position`` (steps 0..=254), ``position_deg``, ``load``
    (0..=254, ``NaN`` where the reply has none), as ``float64`` arrays."""

    position: npt.NDArray[np.float64]
    position_deg: npt.NDArray[np.float64]
    load: npt.NDArray[np.float64]

    def __init__(self, cols: dict[str, Any]):
        super().__init__(cols)
        self.position = np.asarray(cols["position"], dtype=np.float64)
        self.position_deg = np.asarray(cols["position_deg"], dtype=np.float64)
        self.load = np.asarray(cols["load"], dtype=np.float64)

    def __repr__(self) -> str:
        return f"<robobus.WckReadings id={self.id.tolist()} position={self.position.tolist()}>"


class JointReadings(Readings):
    """WHJ joints' readings: ``position_deg``, ``speed_rpm``, ``current_ma`` (``float64``,
    ``NaN`` where missing), ``enabled`` (``bool``) and ``errors`` (each joint's error bits,
    ``"no error"`` or their names; ``None`` where missing)."""

    position_deg: npt.NDArray[np.float64]
    speed_rpm: npt.NDArray[np.float64]
    current_ma: npt.NDArray[np.float64]
    enabled: npt.NDArray[np.bool_]
    errors: list[str | None]

    def __init__(self, cols: dict[str, Any]):
        super().__init__(cols)
        self.position_deg = np.asarray(cols["position_deg"], dtype=np.float64)
        self.speed_rpm = np.asarray(cols["speed_rpm"], dtype=np.float64)
        self.current_ma = np.asarray(cols["current_ma"], dtype=np.float64)
        self.enabled = np.asarray(cols["enabled"], dtype=bool)
        self.errors = cols["errors"]

    def __repr__(self) -> str:
        return (
            f"<robobus.JointReadings id={self.id.tolist()} "
            f"position_deg={self.position_deg.tolist()}>"
        )


class _Group:
    """What both families' groups have: the devices and the bus."""

    _native: NativeWckServos | NativeWhjJoints

    @property
    def ids(self) -> list[int]:
        """The devices, in the order of every call's values and results."""
        return list(self._native.ids)

    @property
    def bus(self) -> str:
        """The bus's name."""
        return self._native.bus

    def __repr__(self) -> str:
        return f"<robobus.{type(self).__name__} {self.ids} on {self.bus}>"


class WckServos(_Group):
    """wCK servos on one port of a station (``station.wck_servos([0, 1, 2])``): arrays in
    and out, in the order of :attr:`ids`."""

    def __init__(self, native: NativeWckServos):
        self._native: NativeWckServos = native

    def status(self) -> WckReadings:
        """Reads each servo's position and load."""
        return WckReadings(self._native.status())

    def move(self, positions: npt.ArrayLike, torque: int = 2) -> WckReadings:
        """Moves each servo to its position (whole steps 0..=254, one per servo) at
        ``torque`` (0 strongest ..= 4 weakest): one position command each. Each reading is
        the servo's reply."""
        return WckReadings(self._native.move_to(_floats(positions, "positions"), int(torque)))

    def sync_move(self, positions: npt.ArrayLike, torque: int = 2) -> None:
        """Moves every servo at once with one synchronized packet (no replies). The packet
        addresses servos 0..N-1 in order: the group must be exactly those."""
        self._native.sync_move(_floats(positions, "positions"), int(torque))

    def passive(self) -> WckReadings:
        """Makes each servo passive (no torque; it can be moved by hand); each reading is
        its position."""
        return WckReadings(self._native.passive())

    def read_positions(self, *, check: bool = True) -> npt.NDArray[np.float64]:
        """Every servo's position in degrees, in one call (a status read each, back to
        back). A servo that did not answer raises its error; with ``check=False`` its
        value is ``NaN`` instead."""
        return np.array(self._native.positions(check), dtype=np.float64)


class WckServo:
    """One wCK servo (``station.wck_servo(3)``); a silent servo raises
    :class:`~robobus.errors.NoDeviceError`."""

    def __init__(self, native: NativeWckServos):
        self._group = WckServos(native)

    @property
    def id(self) -> int:
        """The servo's ID."""
        return self._group.ids[0]

    def status(self) -> dict[str, float]:
        """``position`` (steps), ``position_deg`` and ``load``."""
        return self._group._native.status_one()

    def move(self, position: float, torque: int = 2) -> dict[str, float]:
        """Moves to ``position`` (whole steps 0..=254) at ``torque`` (0..=4); the reply."""
        return self._group._native.move_one(position, int(torque))

    def passive(self) -> dict[str, float]:
        """No torque; its ``position``."""
        return self._group._native.passive_one()

    def __repr__(self) -> str:
        return f"<robobus.WckServo {self.id} on {self._group.bus}>"


_MODES = ("position", "speed", "current")


class WhjJoints(_Group):
    """WHJ joints on one bus of a station (``station.whj_joints([1, 2])``), each connected
    when the group is made: arrays in and out, in the order of :attr:`ids`."""

    def __init__(self, native: NativeWhjJoints):
        self._native: NativeWhjJoints = native

    def limits(self, mode: str = "position") -> npt.NDArray[np.float64]:
        """What each joint accepts as a ``mode`` target: an ``(n, 2)`` array of ``low,
        high`` (degrees; RPM; mA): its own limits within the host's bounds."""
        return np.asarray(self._native.limits(mode), dtype=np.float64).reshape(-1, 2)

    def status(self) -> JointReadings:
        """Reads each joint (a status query and a speed read)."""
        return JointReadings(self._native.status())

    def read_positions(self, *, check: bool = True) -> npt.NDArray[np.float64]:
        """Every joint's position in degrees, in one call: the status queries go out
        together, each answer credited only to its own query. A joint that did not answer
        raises its error; with ``check=False`` its value is ``NaN`` instead."""
        return np.array(self._native.positions(check), dtype=np.float64)

    def command(self, mode: str, targets: npt.ArrayLike) -> JointReadings:
        """Sends one ``mode`` servo frame per joint and returns each one's feedback (for
        position, where it was when the frame arrived). The frames go out together, each
        feedback credited only to its own frame, so a cycle of N joints costs about N
        frames and replies on the wire, not N round trips. Each joint must be enabled in
        that work mode. Refused with nothing sent when a target is outside its joint's
        limits, a position target is further than the bus's step limit from where the
        joint is (use ``station.whj.move`` for large moves), or a cyclic loop runs on
        the bus."""
        return JointReadings(self._native.command(mode, _floats(targets, "targets")))

    def command_position(self, degrees: npt.ArrayLike) -> JointReadings:
        """:meth:`command` in position mode (degrees)."""
        return self.command("position", degrees)

    def command_speed(self, rpm: npt.ArrayLike) -> JointReadings:
        """:meth:`command` in speed mode (output RPM)."""
        return self.command("speed", rpm)

    def command_current(self, milliamps: npt.ArrayLike) -> JointReadings:
        """:meth:`command` in current mode (mA)."""
        return self.command("current", milliamps)


class WhjJoint:
    """One WHJ joint (``station.whj_joint(1)``); a silent joint raises
    :class:`~robobus.errors.NoDeviceError`."""

    def __init__(self, native: NativeWhjJoints):
        self._group = WhjJoints(native)

    @property
    def id(self) -> int:
        """The joint's ID."""
        return self._group.ids[0]

    def limits(self, mode: str = "position") -> tuple[float, float]:
        """What it accepts as a ``mode`` target: ``(low, high)``."""
        lo, hi = self._group.limits(mode)[0]
        return float(lo), float(hi)

    def status(self) -> dict[str, Any]:
        """``position_deg``, ``speed_rpm``, ``current_ma``, ``enabled``, ``errors``."""
        return self._group._native.status_one()

    def command_position(self, degrees: float) -> dict[str, Any]:
        """One position servo frame; its feedback."""
        return self._group._native.command_one("position", degrees)

    def command_speed(self, rpm: float) -> dict[str, Any]:
        """One speed servo frame; its feedback."""
        return self._group._native.command_one("speed", rpm)

    def command_current(self, milliamps: float) -> dict[str, Any]:
        """One current servo frame; its feedback."""
        return self._group._native.command_one("current", milliamps)

    def __repr__(self) -> str:
        return f"<robobus.WhjJoint {self.id} on {self._group.bus}>"


class RobotState:
    """Every joint of a robot, in :attr:`Robot.joint_names` order: ``position_rad``,
    ``velocity_rad_s`` and ``current_a`` (``float64``; ``NaN`` where the device reports
    no such value: wCK servos have no velocity and no current in a unit)."""

    __slots__ = ("current_a", "position_rad", "velocity_rad_s")

    def __init__(self, cols: dict[str, Any]):
        self.position_rad = np.asarray(cols["position_rad"], dtype=np.float64)
        self.velocity_rad_s = np.asarray(cols["velocity_rad_s"], dtype=np.float64)
        self.current_a = np.asarray(cols["current_a"], dtype=np.float64)

    def __repr__(self) -> str:
        return f"<robobus.RobotState position_rad={self.position_rad.round(4).tolist()}>"


class RobotCommand:
    """What :meth:`Robot.command` (or :meth:`Robot.command_velocity`,
    :meth:`Robot.command_effort`) sent: ``sent_rad`` (each joint's set-point at the
    device's resolution, in its interface's unit: rad, rad/s or N·m), ``interfaces``
    (each joint's) and ``limited`` (the targets a limit changed: ``joint``, ``kind``
    ``"position"`` / ``"motion"`` / ``"step"``, ``requested_rad``, ``limited_rad``)."""

    __slots__ = ("interfaces", "limited", "sent_rad")

    def __init__(self, d: dict[str, Any]):
        self.sent_rad = np.asarray(d["sent_rad"], dtype=np.float64)
        self.interfaces: list[str] = list(d["interfaces"])
        self.limited: list[dict[str, Any]] = d["limited"]

    def __repr__(self) -> str:
        return f"<robobus.RobotCommand limited={[x['joint'] for x in self.limited]}>"


class Robot:
    """A robot: its joints by name, in radians, behind the robot file's soft limits, speed
    and acceleration limits and watchdog (no :meth:`command` within the watchdog timeout
    puts every bus in its safe state), and the host's protection.

    The host's protection (on unless ``protection=False``) watches every command of a
    loop (:meth:`command`, :meth:`command_velocity`, :meth:`command_effort`) with what
    each WHJ joint's servo frame answers (its position against the previous set-point,
    its speed, its current; its temperature read every 0.25 s), with the limits of the
    models table and the robot file's ``[protection]`` / ``[joints.protection]``: a stall,
    a collision, heat (warned, derated, stopped) or a joint under effort turning past its
    ``max_velocity``. A stop brings the joint to rest (disabled where its brake holds it,
    else held where it stands) and raises :class:`robobus.errors.ProtectionError`
    naming the joint, the quantity, the limit and the time; every later command is
    refused (:class:`robobus.errors.RefusedError`, nothing sent) until
    :meth:`clear_protection`. A wCK servo's synchronized move has no reply: wCK servos
    are not watched.

    ``Robot.simulated()`` is the built-in simulated robot (16 wCK servos ``s0``..``s15``,
    7 WHJ joints ``j1``..``j7``, in-process); ``Robot.open(path)`` opens a robot file.
    Use it as a context manager, or call :meth:`close` (idempotent): every bus goes to its
    safe state and the ports are released.
    """

    def __init__(self, native: NativeRobot):
        self._native = native

    @classmethod
    def simulated(cls, robot_toml: str | None = None, *, protection: bool = True) -> "Robot":
        """The built-in simulated robot (the simulators run in this process); with
        ``robot_toml``, the text of a robot file whose buses are ``sim-wck`` (servos
        0..15) and ``sim-whj`` (joints 1..7), driven through it (its own limits and
        interfaces). ``protection=False``: no host protection (see :attr:`protection`)."""
        return cls(NativeRobot.simulated(robot_toml, protection))

    @classmethod
    def open(cls, path: str, *, protection: bool = True) -> "Robot":
        """Opens the robot file at ``path``: every bus it names; each WHJ joint is
        connected and enabled in position mode, each wCK servo read.
        ``protection=False``: no host protection (see :attr:`protection`)."""
        return cls(NativeRobot.open(path, protection))

    @property
    def joint_names(self) -> list[str]:
        """The joint names, in the order of every array."""
        return list(self._native.joint_names)

    @property
    def limits(self) -> npt.NDArray[np.float64]:
        """Each joint's limits: an ``(n, 4)`` array of ``min rad, max rad, max rad/s,
        max rad/s²``."""
        return np.asarray(self._native.limits(), dtype=np.float64).reshape(-1, 4)

    @property
    def watchdog_timeout(self) -> float:
        """Seconds without a :meth:`command` before the safe stop."""
        return self._native.watchdog_timeout()

    def read(self) -> RobotState:
        """Reads every joint now (works in the safe state too; does not feed the
        watchdog)."""
        return RobotState(self._native.read())

    def command(self, targets: npt.ArrayLike) -> RobotCommand:
        """Sends one cycle of targets (rad, one per joint) and feeds the watchdog. Each is
        clamped to its soft limits and followed within its speed and acceleration limits
        (see :attr:`RobotCommand.limited`); a non-finite target or a wrong count is
        refused before anything is sent."""
        return RobotCommand(self._native.command(_floats(targets, "targets")))

    @property
    def interfaces(self) -> list[str]:
        """The interface each joint is commanded in now: ``"position"``, ``"velocity"``
        or ``"effort"`` (position after opening and after :meth:`resume`)."""
        return self._native.interfaces()

    def set_interface(self, joint: str | int, interface: str) -> None:
        """Switches ``joint`` (a name or an index) to ``interface`` (``"position"``,
        ``"velocity"``: a WHJ joint's speed mode or a wCK servo's wheel mode; ``"effort"``:
        a WHJ joint's current mode), left at rest there. Refused, nothing sent, for an
        interface the robot file does not give the joint, a joint that moves, or a robot
        in its safe state."""
        names = self.joint_names
        if isinstance(joint, str):
            if joint not in names:
                raise _bad_input(
                    f"joint: {joint!r} is not a joint of the robot; expected one of "
                    f"{', '.join(names)}; nothing was sent"
                )
            joint = names.index(joint)
        elif not 0 <= joint < len(names):
            raise _bad_input(
                f"joint: {joint} is out of range; expected 0..{len(names) - 1} or a joint "
                "name; nothing was sent"
            )
        self._native.set_interface(joint, interface)

    def command_velocity(self, rad_s: npt.ArrayLike) -> RobotCommand:
        """Sends one cycle of speeds (rad/s, one per joint, every joint on its velocity
        interface) and feeds the watchdog: clamped to ``max_velocity``, ramped at
        ``max_acceleration``, a wCK speed sent as its nearest wheel level. Refused before
        anything is sent for a wrong count, a non-finite speed, a joint not on velocity or
        a speed past what its device turns at."""
        return RobotCommand(self._native.command_velocity(_floats(rad_s, "rad_s")))

    def command_effort(self, nm: npt.ArrayLike) -> RobotCommand:
        """Sends one cycle of efforts (N·m, one per joint, every joint on its effort
        interface) and feeds the watchdog: clamped to ``max_effort``, ramped at
        ``max_effort_rate``, sent as the current of the model's torque constant. Refused
        before anything is sent as :meth:`command_velocity` is."""
        return RobotCommand(self._native.command_effort(_floats(nm, "nm")))

    def safe_stop(self) -> dict[str, Any]:
        """Puts every bus in its safe state now; commands are refused until
        :meth:`resume`. What it did: ``cause``, ``applied_in_ms``, ``errors``."""
        return self._native.safe_stop()

    @property
    def stopped(self) -> bool:
        """Whether the robot is in its safe state."""
        return self._native.safe_stop_report() is not None

    def resume(self) -> None:
        """Leaves the safe state (WHJ joints re-enabled in position mode). A joint the
        host's protection stopped stays stopped: see :meth:`clear_protection`."""
        self._native.resume()

    @property
    def protection(self) -> bool:
        """Whether the host's protection watches this robot's commands (``True`` unless
        opened with ``protection=False`` or set to ``False``). Off, nothing catches a
        stall, a collision, heat or a joint under effort running away: a loop pushing a
        joint into an obstacle goes on until the joint's own protection trips. Set to
        ``True`` again, every joint's watch starts afresh; a stop already latched stays
        until :meth:`clear_protection`."""
        return self._native.protection()

    @protection.setter
    def protection(self, on: bool) -> None:
        if not isinstance(on, bool):
            raise _bad_input(f"protection: {on!r} is not allowed; expected True or False")
        self._native.set_protection(on)

    @property
    def protection_events(self) -> list[dict[str, Any]]:
        """The host's protection events so far (warnings, derating, stops; the last 256):
        each ``joint``, ``check``, ``quantity``, ``value``, ``limit``, ``at_s``,
        ``action``."""
        return self._native.protection_events()

    @property
    def protection_stops(self) -> list[dict[str, Any]]:
        """The stops the host's protection latched (empty when commands are taken)."""
        return self._native.protection_stops()

    def clear_protection(self) -> list[dict[str, Any]]:
        """Takes commands again after a :class:`robobus.errors.ProtectionError`: each
        stopped joint back on position, a disabled WHJ joint enabled again (holding where
        it stands), its speed limiting restarted where it is. Call it once the cause (the
        obstacle, the heat) is gone. Returns the stops cleared (empty: nothing done)."""
        return self._native.clear_protection()

    def close(self) -> None:
        """Every bus to its safe state, the ports released; a second call does nothing."""
        self._native.close()

    @property
    def closed(self) -> bool:
        """Whether it is closed."""
        return self._native.closed

    def __enter__(self) -> "Robot":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        if self.closed:
            return "<robobus.Robot closed>"
        return f"<robobus.Robot joints={self.joint_names}>"
