"""LeRobot on robobus: a motors bus (wCK servos and WHJ joints as the motors of a LeRobot
robot) and a robot class (a follower arm on robobus's joints).

:class:`RobobusMotorsBus` has the method set of LeRobot's ``MotorsBus`` (its
``MotorsBusBase`` and the serial bus's extras): ``connect`` / ``disconnect``, ``read`` /
``write`` / ``sync_read`` / ``sync_write`` by register name, ``enable_torque`` /
``disable_torque``, the calibration methods and ``scan_port`` / ``ping``. When LeRobot is
installed, the class is registered as a virtual subclass of its ``MotorsBusBase``. ::

    from robobus.lerobot import Motor, MotorNormMode, RobobusMotorsBus

    bus = RobobusMotorsBus("/dev/ttyUSB0", {
        "shoulder": Motor(0, "wck", MotorNormMode.RANGE_M100_100),
        "gripper": Motor(1, "wck", MotorNormMode.RANGE_0_100),
    })
    bus.connect()
    bus.write_calibration(bus.read_calibration())
    bus.sync_write("Goal_Position", {"shoulder": 0.0, "gripper": 50.0})
    print(bus.sync_read("Present_Position"))
    bus.disconnect()

The port is what the command line takes: a serial port for ``"wck"`` motors, a WHJ bus
(``"can0"``, ``"udp"``) for ``"whj"`` motors, or ``"sim"`` for the built-in simulated
robot (wCK servos 0..=15 and WHJ joints 1..=7, in-process, moving in real time as
hardware does; ``"sim:virtual"`` runs it on the simulators' virtual clock, which moves
only as the bus is driven: every run the same, and nothing moves while Python sleeps).
LeRobot's ``Motor``, ``MotorCalibration`` and ``MotorNormMode`` work as well as the ones
here.

Registers (``data_name``), raw units:

- wCK: ``Present_Position`` (steps 0..=254), ``Goal_Position`` (steps), ``Present_Load``
  (0..=254), ``Torque_Enable`` (write only: 1 holds the present position, 0 passive).
- WHJ: ``Present_Position`` / ``Goal_Position`` (0.0001° counts), ``Present_Velocity``
  (0.02 RPM counts), ``Present_Current`` (mA), ``Torque_Enable`` (the drive enabled),
  ``Goal_Velocity`` (0.002 RPM counts, speed mode), ``Goal_Current`` (mA, current mode).
- The settings LeRobot's robots write when they start, where the devices have them
  (each a request of the catalogue, checked before anything is sent and read back):
  ``Operating_Mode`` (:class:`OperatingMode`: 0 position, and on WHJ 1 speed mode),
  ``P_Coefficient`` / ``I_Coefficient`` / ``D_Coefficient`` (also ``Position_P_Gain``
  ...: a wCK servo's runtime gains, a WHJ joint's position-loop gain registers in RAM),
  ``Acceleration`` (a wCK servo's runtime acceleration 20..=100; a WHJ joint's
  acceleration limit in rpm/s, also as ``Maximum_Acceleration``). The others LeRobot's
  buses have (``Lock``, ``Return_Delay_Time``, ``Max_Torque_Limit``,
  ``Protection_Current``, ``Overload_Torque``, the position limits, ``Homing_Offset``)
  raise ``ValueError`` naming the register and why (:data:`REFUSED`), nothing sent.

:class:`RobobusFollower` (config :class:`RobobusFollowerConfig`) is a LeRobot robot over
this bus: a follower arm whose observations and actions are ``{"<motor>.pos": float}``.

How it differs from a Dynamixel or Feetech bus, on purpose:

- Every value is robobus's: read now, never an earlier one; a motor that does not answer
  raises ``ConnectionError`` naming it. Every target goes through robobus's checks
  (position ranges, the WHJ step limit, the joints' own limits) before anything is sent;
  a refused ``sync_write`` sends nothing to any motor.
- The calibration is kept by the host (LeRobot saves it to its calibration file as
  always), and the homing offset is applied by the host. The devices' own limits are not
  rewritten: on these devices that is an EEPROM or flash write with its own confirmation
  (the catalogue's ``wck.set`` ``bounds``, the WHJ limit registers).
- ``DEGREES`` uses each device's real angle per count (wCK: 269°/255 per step), not one
  turn per encoder range.
- Normalised targets outside -100..100 (0..100) are clamped to the calibrated range, as in
  LeRobot; a raw or degree target outside the calibrated range is refused.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import importlib.util
import json
import logging
import math
import os
import pathlib
import select
import sys
import time
from typing import Any, Callable, Iterator, Literal, Mapping, Sequence, TypeAlias

from . import JointBus, Station, WckBus
from ._robobus import NativeStation
from ._robobus import facts as _facts
from .errors import NotAvailableError, RobobusError
from .handles import WckServos, WhjJoints

__all__ = [
    "DeviceAlreadyConnectedError",
    "DeviceNotConnectedError",
    "Motor",
    "MotorCalibration",
    "MotorNormMode",
    "OperatingMode",
    "REFUSED",
    "RobobusFollower",
    "RobobusFollowerConfig",
    "RobobusMotorsBus",
]

log = logging.getLogger("robobus.lerobot")

NameOrID: TypeAlias = "str | int"
Value: TypeAlias = "int | float"

_FACTS: dict[str, Any] = _facts()
WCK, WHJ = "wck", "whj"
_DEG_PER_COUNT = {WCK: float(_FACTS["wck_degrees_per_step"]), WHJ: float(_FACTS["whj_degrees_per_count"])}
_WCK_MAX = int(_FACTS["wck_position_max"])


class MotorNormMode(str, enum.Enum):
    """How a normalised value maps to the calibrated range (LeRobot's values)."""

    RANGE_0_100 = "range_0_100"
    RANGE_M100_100 = "range_m100_100"
    DEGREES = "degrees"


@dataclasses.dataclass
class Motor:
    """A motor of the bus: its ID, its model (``"wck"`` or ``"whj"``) and its
    normalisation."""

    id: int
    model: str
    norm_mode: MotorNormMode


@dataclasses.dataclass
class MotorCalibration:
    """A motor's calibration, raw units: ``drive_mode`` 1 inverts the normalised
    direction, ``homing_offset`` is subtracted from every position read (and added to
    every position written), ``range_min`` / ``range_max`` bound the positions."""

    id: int
    drive_mode: int
    homing_offset: int
    range_min: int
    range_max: int


class DeviceNotConnectedError(ConnectionError):
    """The bus is not connected: call ``connect()`` first."""


class DeviceAlreadyConnectedError(ConnectionError):
    """``connect()`` was called twice."""


class OperatingMode(enum.IntEnum):
    """``Operating_Mode`` values (Feetech's numbers, which the SO-100 / SO-101 robots
    write): ``POSITION`` is a WHJ joint's position mode (a wCK servo is always in it),
    ``VELOCITY`` a WHJ joint's speed mode. Feetech's PWM (2) and step (3) modes have no
    counterpart and are refused."""

    POSITION = 0
    VELOCITY = 1


_READABLE = {
    WCK: ("Present_Position", "Present_Load"),
    WHJ: ("Present_Position", "Present_Velocity", "Present_Current", "Torque_Enable"),
}

# The settings registers LeRobot's robots write when they start (``configure``), and
# what each is on a robobus device: a mapped one is written through the catalogue's
# request (checked there, read back), a refused one names why.
_GAINS = {
    "P_Coefficient": "p",
    "I_Coefficient": "i",
    "D_Coefficient": "d",
    "Position_P_Gain": "p",
    "Position_I_Gain": "i",
    "Position_D_Gain": "d",
}
_SETTINGS = ("Operating_Mode", *_GAINS, "Acceleration", "Maximum_Acceleration")
_WRITABLE = {
    WCK: ("Goal_Position", "Torque_Enable", *_SETTINGS[:-1]),
    WHJ: ("Goal_Position", "Goal_Velocity", "Goal_Current", "Torque_Enable", *_SETTINGS),
}
_NO_LIMITS = (
    "the devices' own limits are not rewritten from LeRobot: write_calibration() keeps the "
    "range on the host, and the devices' limits are EEPROM / flash writes with their own "
    "confirmation (the catalogue's wck.set bounds, whj.write LIT_MIN_POSITION / "
    "LIT_MAX_POSITION)"
)
#: Registers of LeRobot's buses that robobus's devices do not have, with the reason.
REFUSED: dict[str, dict[str, str]] = {
    "Lock": {
        WCK: "a wCK servo has no EEPROM lock: each EEPROM write of the catalogue is "
        "confirmed on its own (confirm=True)",
        WHJ: "a WHJ joint has no flash lock: each flash write of the catalogue is confirmed "
        "on its own (confirm=True)",
    },
    "Return_Delay_Time": {
        WCK: "a wCK servo answers after a fixed turnaround: robobus computes each reply's "
        "deadline from the protocol (set_timeout() adds a margin)",
        WHJ: "a WHJ joint has no reply delay setting: its replies follow the CAN FD bus",
    },
    "Maximum_Acceleration": {
        WCK: "a wCK servo has one acceleration setting: write Acceleration",
    },
    "Max_Torque_Limit": {
        WCK: "a wCK servo's torque is a level 0..=4 sent with each move "
        "(RobobusMotorsBus(torque=...)), not a register",
        WHJ: "a WHJ joint limits its current (LIT_MAX_CURRENT, mA, factory-tuned flash), "
        "not a torque share: write it with the catalogue's whj.write, confirmed",
    },
    "Protection_Current": {
        WCK: "a wCK servo's overload current is an EEPROM setting in mA: the catalogue's "
        "wck.set overload, confirmed",
        WHJ: "a WHJ joint's current limit is LIT_MAX_CURRENT in mA (factory-tuned flash): "
        "the catalogue's whj.write, confirmed",
    },
    "Overload_Torque": {
        WCK: "a wCK servo has no reduced torque on overload: its overload current cuts the "
        "drive (wck.set overload)",
        WHJ: "a WHJ joint has no reduced torque on overload: it latches an error and stops",
    },
    "Min_Position_Limit": {WCK: _NO_LIMITS, WHJ: _NO_LIMITS},
    "Max_Position_Limit": {WCK: _NO_LIMITS, WHJ: _NO_LIMITS},
    "Homing_Offset": {
        WCK: "the homing offset is kept by the host (the calibration), not written to the servo",
        WHJ: "the homing offset is kept by the host (the calibration), not written to the joint",
    },
}


#: The simulated robot's ports and the clock each runs on.
_SIM_PORTS: dict[str, Literal["wall", "virtual"]] = {"sim": "wall", "sim:virtual": "virtual"}


def _simulated(port: str) -> Station:
    """The built-in simulated robot on the clock of ``port``."""
    return Station.simulated(clock=_SIM_PORTS[port])


def _validate(request: dict[str, Any]) -> None:
    """Checks a request as running it would (ranges, the host bounds); nothing is sent."""
    NativeStation.validate(request)


def _enter_pressed() -> bool:
    """Whether a line was entered on standard input (without waiting)."""
    try:
        ready = select.select([sys.stdin], [], [], 0)[0]
    except (OSError, ValueError):
        return False
    return bool(ready) and sys.stdin.readline().strip() == ""


class RobobusMotorsBus:
    """LeRobot's motors bus over robobus (see the module docs)."""

    apply_drive_mode: bool = True
    available_baudrates: list[int] = [int(b) for b in _FACTS["wck_bauds"]]
    default_baudrate: int = int(_FACTS["wck_default_baud"])
    #: Extra time for each reply past the protocol's timing model, ms (wCK).
    default_timeout: int = 0
    model_baudrate_table: dict[str, dict[int, int]] = {
        WCK: {b: b for b in available_baudrates},
        WHJ: {},
    }
    #: Every register of each model: its access (``r``, ``w``, ``rw``) and raw unit.
    model_ctrl_table: dict[str, dict[str, tuple[str, str]]] = {
        WCK: {
            "Present_Position": ("r", "step"),
            "Goal_Position": ("w", "step"),
            "Present_Load": ("r", "0..=254"),
            "Torque_Enable": ("w", "0/1"),
            "Operating_Mode": ("w", "0 position"),
            "P_Coefficient": ("w", "runtime P gain"),
            "I_Coefficient": ("w", "runtime I gain"),
            "D_Coefficient": ("w", "runtime D gain"),
            "Position_P_Gain": ("w", "runtime P gain"),
            "Position_I_Gain": ("w", "runtime I gain"),
            "Position_D_Gain": ("w", "runtime D gain"),
            "Acceleration": ("w", "runtime acceleration 20..=100"),
        },
        WHJ: {
            "Present_Position": ("r", "0.0001 deg"),
            "Goal_Position": ("w", "0.0001 deg"),
            "Present_Velocity": ("r", "0.02 RPM"),
            "Present_Current": ("r", "mA"),
            "Torque_Enable": ("rw", "0/1"),
            "Goal_Velocity": ("w", "0.002 RPM"),
            "Goal_Current": ("w", "mA"),
            "Operating_Mode": ("w", "0 position, 1 speed"),
            "P_Coefficient": ("w", "SEV_POSITION_P"),
            "I_Coefficient": ("w", "SEV_POSITION_I"),
            "D_Coefficient": ("w", "SEV_POSITION_D"),
            "Position_P_Gain": ("w", "SEV_POSITION_P"),
            "Position_I_Gain": ("w", "SEV_POSITION_I"),
            "Position_D_Gain": ("w", "SEV_POSITION_D"),
            "Acceleration": ("w", "LIT_MAX_ACC, rpm/s"),
            "Maximum_Acceleration": ("w", "LIT_MAX_ACC, rpm/s"),
        },
    }
    model_encoding_table: dict[str, dict[str, int]] = {WCK: {}, WHJ: {}}
    #: wCK servos report no model number: these are robobus's family numbers.
    model_number_table: dict[str, int] = {WCK: 1, WHJ: 2}
    #: Counts over one turn plus one (LeRobot's convention); a wCK servo covers 269°.
    model_resolution_table: dict[str, int] = {
        WCK: _WCK_MAX + 1,
        WHJ: round(360.0 / _DEG_PER_COUNT[WHJ]) + 1,
    }
    normalized_data: list[str] = ["Goal_Position", "Present_Position"]

    def __init__(
        self,
        port: str,
        motors: Mapping[str, Any],
        calibration: Mapping[str, Any] | None = None,
        *,
        baudrate: int | None = None,
        torque: int = 2,
    ):
        self.port = port
        self.motors: dict[str, Any] = dict(motors)
        self.calibration: dict[str, Any] = dict(calibration) if calibration else {}
        self._baud = int(baudrate) if baudrate is not None else self.default_baudrate
        self._torque = int(torque)
        self._timeout_ms: float | None = None
        self._station: Station | None = None
        self._groups: dict[tuple[str, tuple[int, ...]], WckServos | WhjJoints] = {}
        keys = [(m.model, m.id) for m in self.motors.values()]
        if len(keys) != len(set(keys)):
            raise ValueError(f"motors: some have the same id ({self.ids})")
        for name, m in self.motors.items():
            if m.model not in (WCK, WHJ):
                raise ValueError(f"motor {name!r}: model {m.model!r} is not one of 'wck', 'whj'")
        families = {m.model for m in self.motors.values()}
        if len(families) > 1 and port not in _SIM_PORTS:
            raise ValueError(
                f"port {port!r}: one port carries one family; wCK and WHJ motors on one bus "
                "only on the simulated robot ('sim')"
            )

    # ----- the LeRobot interface -----------------------------------------------------

    def __len__(self) -> int:
        return len(self.motors)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(port={self.port!r}, motors={self.motors!r})"

    @property
    def models(self) -> list[str]:
        """Each motor's model, in the motors' order."""
        return [m.model for m in self.motors.values()]

    @property
    def ids(self) -> list[int]:
        """Each motor's ID, in the motors' order."""
        return [m.id for m in self.motors.values()]

    @property
    def is_connected(self) -> bool:
        """Whether the port is open."""
        return self._station is not None and not self._station.closed

    def connect(self, handshake: bool = True) -> None:
        """Opens the port; with ``handshake``, reads every motor once (a silent one
        raises ``ConnectionError`` naming it, and the port is closed again)."""
        if self.is_connected:
            raise DeviceAlreadyConnectedError(f"{self!r} is already connected")
        self._open()
        if handshake:
            missing = [name for name in self.motors if self.ping(name) is None]
            if missing:
                self._close(leave=True)
                raise ConnectionError(
                    f"{type(self).__name__} on {self.port!r}: motors {missing} "
                    f"(IDs {[self.motors[n].id for n in missing]}) did not answer"
                )

    def disconnect(self, disable_torque: bool = True) -> None:
        """With ``disable_torque`` every motor goes limp (wCK passive, WHJ disabled) and
        the port is closed with every device in its safe state; without, the devices
        stay as they are."""
        self._require()
        if disable_torque:
            try:
                self.disable_torque(num_retry=2)
            finally:
                self._close(leave=False)
        else:
            self._close(leave=True)

    @classmethod
    def scan_port(cls, port: str, *args: Any, **kwargs: Any) -> dict[int, list[int]]:
        """The IDs that answer on ``port``, by baud rate: a wCK port at every rate (or at
        ``baudrate=`` only), a WHJ bus at its own (``family="whj"``; guessed from
        ``can*`` / ``vcan*`` / ``udp*``)."""
        family = kwargs.get("family") or (
            WHJ if port.startswith(("can", "vcan", "udp")) else WCK
        )
        if family == WHJ:
            with (_simulated(port) if port in _SIM_PORTS else JointBus.open(port)) as s:
                rows = s.whj.scan(check=False)["results"]
            ids = sorted(r["id"] for r in rows if "error" not in r)
            return {cls.default_baudrate: ids} if ids else {}
        baudrate = kwargs.get("baudrate")
        opened = (
            _simulated(port)
            if port in _SIM_PORTS
            else WckBus.open(port, int(baudrate or cls.default_baudrate))
        )
        with opened as s:
            rows = s.wck.scan(all_bauds=baudrate is None, check=False)["results"]
        found: dict[int, list[int]] = {}
        for r in rows:
            if "error" not in r:
                found.setdefault(int(r["baud"]), []).append(int(r["id"]))
        return {b: sorted(v) for b, v in sorted(found.items())}

    def setup_motor(
        self, motor: str, initial_baudrate: int | None = None, initial_id: int | None = None
    ) -> None:
        """Gives ``motor`` its ID (and, for wCK, the bus's baud rate): the one motor on
        the bus is found by a scan when ``initial_id`` / ``initial_baudrate`` are not
        given. The writes are the catalogue's ``set-id`` / ``set-baud``, read back."""
        m = self.motors[motor]
        if m.model == WHJ:
            if initial_id is None:
                found = self.scan_port(self.port, family=WHJ).get(self.default_baudrate, [])
                initial_id = self._single(found, motor)
            if initial_id != m.id:
                with self._temporary() as s:
                    s.whj.set_id(initial_id, m.id, confirm=True, check=True)
            return
        if initial_baudrate is None or initial_id is None:
            found_by_baud = self.scan_port(self.port, family=WCK, baudrate=initial_baudrate)
            if initial_baudrate is None:
                if len(found_by_baud) != 1:
                    raise RuntimeError(
                        f"setup_motor({motor!r}): connect this motor alone; found {found_by_baud}"
                    )
                initial_baudrate = next(iter(found_by_baud))
            if initial_id is None:
                initial_id = self._single(found_by_baud.get(initial_baudrate, []), motor)
        if self.port in _SIM_PORTS:
            with self._temporary() as s:
                if initial_id != m.id:
                    s.wck.set_id(initial_id, m.id, confirm=True, check=True)
            return
        was = self.is_connected
        self._close(leave=True)
        with WckBus.open(self.port, initial_baudrate) as s:
            if initial_id != m.id:
                s.wck.set_id(initial_id, m.id, confirm=True, check=True)
            if initial_baudrate != self._baud:
                s.wck.set_baud(m.id, self._baud, confirm=True, check=True)
        if was:
            self._open()

    def configure_motors(self) -> None:
        """Nothing to configure: robobus's devices have no SDK settings (return delay,
        locks) to prepare; their limits are set through the catalogue."""
        log.info("configure_motors: nothing to configure for wCK / WHJ motors")

    def enable_torque(self, motors: NameOrID | Sequence[NameOrID] | None = None, num_retry: int = 0) -> None:
        """wCK: each servo holds its present position (read now) at the bus's torque
        level; WHJ: each joint's drive is enabled."""
        names = self._names(motors)
        for family, ids in self._by_family(names).items():
            if family == WCK:
                group = self._wck(ids)
                now = self._retry(group.status, num_retry, "read Present_Position")
                self._retry(lambda: group.move(now.position, self._torque), num_retry, "enable torque")
            else:
                self._retry(
                    lambda: self._station_().whj.enable(ids, bus=self._whj(ids).bus, check=True),
                    num_retry,
                    "enable torque",
                )

    def disable_torque(self, motors: NameOrID | Sequence[NameOrID] | None = None, num_retry: int = 0) -> None:
        """wCK: each servo passive; WHJ: each joint's drive disabled."""
        names = self._names(motors)
        for family, ids in self._by_family(names).items():
            if family == WCK:
                self._retry(lambda: self._wck(ids).passive(), num_retry, "disable torque")
            else:
                self._retry(
                    lambda: self._station_().whj.disable(ids, bus=self._whj(ids).bus, check=True),
                    num_retry,
                    "disable torque",
                )

    @contextlib.contextmanager
    def torque_disabled(self, motors: NameOrID | Sequence[NameOrID] | None = None) -> Iterator[None]:
        """Torque off inside the block, on again after it."""
        self.disable_torque(motors)
        try:
            yield
        finally:
            self.enable_torque(motors)

    def set_timeout(self, timeout_ms: int | None = None) -> None:
        """Extra time for each wCK reply past the protocol's timing model (robobus
        computes every reply deadline from the baud rate and the command), from the next
        ``connect``; ``None``: the default."""
        self._timeout_ms = None if timeout_ms is None else float(timeout_ms)

    def get_baudrate(self) -> int:
        """The port's baud rate (WHJ: the bus's nominal rate)."""
        return self._baud

    def set_baudrate(self, baudrate: int) -> None:
        """Reopens a wCK port at ``baudrate``; a WHJ bus's rate is the interface's."""
        baudrate = int(baudrate)
        if baudrate == self._baud:
            return
        if any(m.model == WHJ for m in self.motors.values()) or baudrate not in self.available_baudrates:
            raise NotAvailableError(
                f"set_baudrate({baudrate}): a WHJ bus's bit rate is set on its interface, and "
                f"wCK rates are {self.available_baudrates}",
                "not-available",
            )
        was = self.is_connected
        self._close(leave=True)
        self._baud = baudrate
        if was:
            self._open()

    @property
    def is_calibrated(self) -> bool:
        """Whether every motor has a calibration within its device's own range."""
        if not all(name in self.calibration for name in self.motors):
            return False
        if not self.is_connected:
            return True
        device = self.read_calibration()
        for name, c in self.calibration.items():
            d = device.get(name)
            if d is not None and not (d.range_min <= c.range_min + c.homing_offset
                                      and c.range_max + c.homing_offset <= d.range_max):
                return False
        return True

    def read_calibration(self) -> dict[str, MotorCalibration]:
        """Each motor's own range, read now, raw units, no homing offset: a wCK servo's
        position boundaries, a WHJ joint's position limits."""
        self._require()
        out: dict[str, MotorCalibration] = {}
        for family, ids in self._by_family(list(self.motors)).items():
            if family == WCK:
                for i in ids:
                    row = self._station_().wck.get("bounds", i, bus=self._wck([i]).bus, check=True)
                    r = row["results"][0]
                    out[self._name(i, WCK)] = MotorCalibration(i, 0, 0, int(r["lower"]), int(r["upper"]))
            else:
                limits = self._whj(ids).limits("position")
                for i, (lo, hi) in zip(ids, limits):
                    out[self._name(i, WHJ)] = MotorCalibration(
                        i, 0, 0, math.ceil(lo / _DEG_PER_COUNT[WHJ]), math.floor(hi / _DEG_PER_COUNT[WHJ])
                    )
        return out

    def write_calibration(self, calibration_dict: Mapping[str, Any], cache: bool = True) -> None:
        """Checks the calibration against each motor's own range (raw positions, homing
        offset applied) and, with ``cache``, keeps it for the normalisation and as the
        position bounds of every target. The devices are not written (see the module
        docs)."""
        for name, c in calibration_dict.items():
            if name not in self.motors:
                raise ValueError(f"calibration of {name!r}: no such motor (motors: {list(self.motors)})")
            if not c.range_min < c.range_max:
                raise ValueError(f"calibration of {name!r}: range_min {c.range_min} >= range_max {c.range_max}")
        if self.is_connected:
            device = self.read_calibration()
            for name, c in calibration_dict.items():
                d = device[name]
                lo, hi = c.range_min + c.homing_offset, c.range_max + c.homing_offset
                if lo < d.range_min or hi > d.range_max:
                    raise ValueError(
                        f"calibration of {name!r}: {lo}..={hi} (raw, homing offset applied) is "
                        f"outside the device's own range {d.range_min}..={d.range_max}"
                    )
        if cache:
            self.calibration = dict(calibration_dict)

    def reset_calibration(self, motors: NameOrID | Sequence[NameOrID] | None = None) -> None:
        """The selected motors' calibration becomes their device range, homing offset 0."""
        device = self.read_calibration()
        for name in self._names(motors):
            self.calibration[name] = device[name]

    def set_half_turn_homings(self, motors: NameOrID | Sequence[NameOrID] | None = None) -> dict[NameOrID, Value]:
        """Sets each motor's homing offset so that its present position reads as the middle
        of its device range; returns the offsets (raw)."""
        names = self._names(motors)
        self.reset_calibration(names)
        raw = self.sync_read("Present_Position", names, normalize=False)
        offsets: dict[NameOrID, Value] = {}
        for name in names:
            c = self.calibration[name]
            offset = int(raw[name]) - (c.range_min + c.range_max) // 2
            self.calibration[name] = MotorCalibration(
                c.id, c.drive_mode, offset, c.range_min - offset, c.range_max - offset
            )
            offsets[name] = offset
        return offsets

    def record_ranges_of_motion(
        self,
        motors: NameOrID | Sequence[NameOrID] | None = None,
        display_values: bool = True,
        *,
        until: Callable[[], bool] | None = None,
        period: float = 0.02,
    ) -> tuple[dict[NameOrID, Value], dict[NameOrID, Value]]:
        """Reads the motors' positions (raw, homing offset applied) while they are moved
        by hand, until Enter is pressed (or ``until()`` is true); returns the smallest and
        the largest of each. Memory stays bounded: only the extremes are kept."""
        names = self._names(motors)
        stop = until or _enter_pressed
        first = self.sync_read("Present_Position", names, normalize=False)
        mins: dict[NameOrID, Value] = {n: v for n, v in first.items()}
        maxes: dict[NameOrID, Value] = {n: v for n, v in first.items()}
        while True:
            now = self.sync_read("Present_Position", names, normalize=False)
            for n in names:
                mins[n] = min(mins[n], now[n])
                maxes[n] = max(maxes[n], now[n])
            if display_values:
                print(" | ".join(f"{n}: {mins[n]}..{now[n]}..{maxes[n]}" for n in names), flush=True)
            if stop():
                break
            time.sleep(period)
        same = [n for n in names if mins[n] == maxes[n]]
        if same:
            raise ValueError(f"motors {same} did not move: their minimum equals their maximum")
        return mins, maxes

    def ping(self, motor: NameOrID, num_retry: int = 0, raise_on_error: bool = False) -> int | None:
        """The motor's model number if it answers a read now, else ``None`` (or the error
        with ``raise_on_error``)."""
        name = self._name(motor) if isinstance(motor, int) else motor
        m = self.motors[name]
        for _ in range(1 + num_retry):
            try:
                if m.model == WCK:
                    self._wck([m.id]).status().check()
                else:
                    self._whj([m.id]).status().check()
                return self.model_number_table[m.model]
            except RobobusError as e:
                err = e
        if raise_on_error:
            raise ConnectionError(f"ping {name!r} (ID {m.id}): {err}") from err
        return None

    def broadcast_ping(self, num_retry: int = 0, raise_on_error: bool = False) -> dict[int, int] | None:
        """Every ID that answers on the bus (a scan of every ID at the bus's rate), with
        its model number."""
        found: dict[int, int] = {}
        s = self._station_()
        wck, whj = s.buses
        for _ in range(1 + num_retry):
            try:
                if wck:
                    for r in s.wck.scan(bus=wck[0], check=False)["results"]:
                        if "error" not in r:
                            found[int(r["id"])] = self.model_number_table[WCK]
                if whj:
                    for r in s.whj.scan(bus=whj[0], check=False)["results"]:
                        if "error" not in r:
                            found[int(r["id"])] = self.model_number_table[WHJ]
                return found
            except RobobusError as e:
                if raise_on_error:
                    raise ConnectionError(f"broadcast_ping: {e}") from e
        return None

    def read(self, data_name: str, motor: str, *, normalize: bool = True, num_retry: int = 0) -> Value:
        """One register of one motor, read now."""
        return self.sync_read(data_name, [motor], normalize=normalize, num_retry=num_retry)[motor]

    def write(
        self, data_name: str, motor: str, value: Value, *, normalize: bool = True, num_retry: int = 0
    ) -> None:
        """One register of one motor; a position is confirmed by the motor's reply."""
        self._write(data_name, {motor: value}, normalize, num_retry, reply=True)

    def sync_read(
        self,
        data_name: str,
        motors: str | list[str] | None = None,
        *,
        normalize: bool = True,
        num_retry: int = 0,
    ) -> dict[str, Value]:
        """One register of several motors, each read now (a motor that does not answer
        raises ``ConnectionError`` naming it: never an older value)."""
        names = self._names(motors)
        for n in names:
            if data_name not in _READABLE[self.motors[n].model]:
                raise ValueError(
                    f"{data_name!r} of {n!r}: not readable on a {self.motors[n].model} motor "
                    f"(readable: {', '.join(_READABLE[self.motors[n].model])})"
                )
        raw: dict[str, Value] = {}
        for family, ids in self._by_family(names).items():
            if family == WCK:
                r = self._retry(lambda: self._wck(ids).status(), num_retry, f"sync read {data_name!r}", ids)
                column = r.position if data_name == "Present_Position" else r.load
                for i, v in zip(ids, column):
                    raw[self._name(i, WCK)] = int(v)
            else:
                j = self._retry(lambda: self._whj(ids).status(), num_retry, f"sync read {data_name!r}", ids)
                for k, i in enumerate(ids):
                    if data_name == "Present_Position":
                        raw[self._name(i, WHJ)] = round(float(j.position_deg[k]) / _DEG_PER_COUNT[WHJ])
                    elif data_name == "Present_Velocity":
                        raw[self._name(i, WHJ)] = round(float(j.speed_rpm[k]) / float(_FACTS["whj_rpm_per_speed_count"]))
                    elif data_name == "Present_Current":
                        raw[self._name(i, WHJ)] = int(j.current_ma[k])
                    else:
                        raw[self._name(i, WHJ)] = int(bool(j.enabled[k]))
        out: dict[str, Value] = {}
        for n in names:
            v = raw[n]
            if data_name == "Present_Position":
                v = int(v) - self._homing(n)
                if normalize:
                    v = self._normalize(n, v)
            out[n] = v
        return out

    def sync_write(
        self,
        data_name: str,
        values: Value | Mapping[str, Value],
        motors: str | list[str] | None = None,
        *,
        normalize: bool = True,
        num_retry: int = 0,
    ) -> None:
        """One register of several motors: a value for every motor (or for ``motors``),
        or a ``{motor: value}`` mapping. Every value is checked first; a refusal sends
        nothing to any motor. wCK positions of servos 0..N-1 go out as one synchronized
        packet (no replies), others one command each."""
        if isinstance(values, Mapping):
            targets = dict(values)
        else:
            targets = dict.fromkeys(self._names(motors), values)
        self._write(data_name, targets, normalize, num_retry, reply=False)

    # ----- internals ------------------------------------------------------------------

    def _open(self) -> None:
        families = {m.model for m in self.motors.values()}
        if self.port in _SIM_PORTS:
            self._station = _simulated(self.port)
        elif families == {WHJ}:
            self._station = JointBus.open(self.port)
        else:
            self._station = WckBus.open(self.port, self._baud, reply_margin_ms=self._timeout_ms)
        self._groups.clear()

    def _close(self, leave: bool) -> None:
        s, self._station = self._station, None
        self._groups.clear()
        if s is not None:
            if leave:
                s.leave()
            else:
                s.close()

    @contextlib.contextmanager
    def _temporary(self) -> Iterator[Station]:
        if self.is_connected:
            yield self._station_()
        else:
            self._open()
            try:
                yield self._station_()
            finally:
                self._close(leave=True)

    def _require(self) -> None:
        if not self.is_connected:
            raise DeviceNotConnectedError(f"{self!r} is not connected: call connect() first")

    def _station_(self) -> Station:
        self._require()
        assert self._station is not None
        return self._station

    def _single(self, found: Sequence[int], motor: str) -> int:
        if len(found) != 1:
            raise RuntimeError(f"setup_motor({motor!r}): connect this motor alone; found IDs {list(found)}")
        return int(found[0])

    def _name(self, motor_id: int, family: str | None = None) -> str:
        found = [
            name
            for name, m in self.motors.items()
            if m.id == motor_id and (family is None or m.model == family)
        ]
        if len(found) == 1:
            return found[0]
        if found:
            raise KeyError(f"ID {motor_id} is {found}: give the motor's name")
        raise KeyError(f"no motor with ID {motor_id} (IDs: {self.ids})")

    def _names(self, motors: NameOrID | Sequence[NameOrID] | None) -> list[str]:
        if motors is None:
            return list(self.motors)
        items = [motors] if isinstance(motors, (str, int)) else list(motors)
        out = []
        for m in items:
            name = self._name(m) if isinstance(m, int) else m
            if name not in self.motors:
                raise KeyError(f"no motor {name!r} (motors: {list(self.motors)})")
            out.append(name)
        return out

    def _by_family(self, names: Sequence[str]) -> dict[str, list[int]]:
        out: dict[str, list[int]] = {}
        for n in names:
            m = self.motors[n]
            out.setdefault(m.model, []).append(m.id)
        return out

    def _wck(self, ids: Sequence[int]) -> WckServos:
        key = (WCK, tuple(ids))
        g = self._groups.get(key)
        if g is None:
            wck, _ = self._station_().buses
            g = self._station_().wck_servos(list(ids), bus=wck[0] if len(wck) > 1 else None)
            self._groups[key] = g
        assert isinstance(g, WckServos)
        return g

    def _whj(self, ids: Sequence[int]) -> WhjJoints:
        key = (WHJ, tuple(ids))
        g = self._groups.get(key)
        if g is None:
            _, whj = self._station_().buses
            g = self._station_().whj_joints(list(ids), bus=whj[0] if len(whj) > 1 else None)
            self._groups[key] = g
        assert isinstance(g, WhjJoints)
        return g

    def _retry(self, call: Callable[[], Any], num_retry: int, what: str, ids: Sequence[int] = ()) -> Any:
        """``call`` until its readings are all valid, at most ``1 + num_retry`` times;
        then ``ConnectionError`` naming the motors that did not answer."""
        last: Exception | None = None
        for _ in range(1 + max(0, num_retry)):
            try:
                r = call()
                if hasattr(r, "check"):
                    r.check()
                return r
            except (RobobusError, ConnectionError) as e:
                if isinstance(e, DeviceNotConnectedError) or (
                    isinstance(e, RobobusError) and e.kind not in ("no-device", "link", "device")
                ):
                    raise
                last = e
        raise ConnectionError(f"Failed to {what} on ids={list(ids)} after {1 + num_retry} tries: {last}") from last

    def _setting(self, data_name: str, name: str, value: Value) -> Callable[[], Any]:
        """The request that writes settings register ``data_name`` of motor ``name``
        (checked now, sent when called)."""
        m = self.motors[name]
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
            or value != int(value)
        ):
            raise ValueError(f"{data_name!r} of {name!r}: {value!r} is not a whole number; nothing was sent")
        v = int(value)
        s = self._station_()
        wck, whj = s.buses
        if data_name == "Operating_Mode":
            try:
                mode = OperatingMode(v)
            except ValueError:
                raise ValueError(
                    f"Operating_Mode of {name!r}: {v} is no mode of a {m.model} motor (allowed: "
                    f"{OperatingMode.POSITION.value} position"
                    + (f", {OperatingMode.VELOCITY.value} velocity" if m.model == WHJ else "")
                    + "; Feetech's PWM and step modes have no counterpart); nothing was sent"
                ) from None
            if m.model == WCK:
                if mode is not OperatingMode.POSITION:
                    raise ValueError(
                        f"Operating_Mode of {name!r}: refused on a wck motor: a wCK servo's "
                        "wheel mode is a timed command (the catalogue's wck.wheel), not a mode "
                        "register; nothing was sent"
                    )
                # A wCK servo takes every position command in position mode.
                return lambda: None
            work: Literal["position", "speed"] = "position" if mode is OperatingMode.POSITION else "speed"
            return lambda: s.whj.mode(str(m.id), work, bus=self._bus(whj), check=True)
        # The value within the device's range, as the catalogue checks it (the request it
        # goes out in, with the value standing in for what is read when it is sent).
        _validate(self._setting_check(data_name, m, v))
        if data_name in _GAINS:
            gain = _GAINS[data_name]
            if m.model == WHJ:
                register = f"SEV_POSITION_{gain.upper()}"
                return lambda: s.whj.write(str(m.id), register, v, raw=True, bus=self._bus(whj), check=True)
            if gain == "i":
                return lambda: s.wck.set("i-gain", m.id, i=v, runtime=True, bus=self._bus(wck), check=True)

            def pd() -> Any:
                # The servo's runtime P and D are one command: the other gain is kept
                # as the servo reads it now.
                now = s.wck.get("gains", m.id, bus=self._bus(wck), check=True)["results"][0]
                p, d = (v, now["d_gain"]) if gain == "p" else (now["p_gain"], v)
                return s.wck.set("gains", m.id, p=p, d=d, runtime=True, bus=self._bus(wck), check=True)

            return pd
        # Acceleration, Maximum_Acceleration.
        if m.model == WHJ:
            return lambda: s.whj.write(str(m.id), "LIT_MAX_ACC", v, bus=self._bus(whj), check=True)

        def accel() -> Any:
            # Runtime speed and acceleration are one command: the speed goes with it as
            # wck.get reads it now.
            now = s.wck.get("speed", m.id, bus=self._bus(wck), check=True)["results"][0]
            return s.wck.set("speed", m.id, speed=now["speed"], accel=v, runtime=True, bus=self._bus(wck), check=True)

        return accel

    @staticmethod
    def _setting_check(data_name: str, m: Any, v: int) -> dict[str, Any]:
        """The request a settings write goes out in, for checking ``v`` before anything
        is sent."""
        if m.model == WHJ:
            if data_name in _GAINS:
                register = f"SEV_POSITION_{_GAINS[data_name].upper()}"
                return {"op": "whj.write", "joints": str(m.id), "register": register, "value": v, "raw": True}
            return {"op": "whj.write", "joints": str(m.id), "register": "LIT_MAX_ACC", "value": v}
        if data_name in _GAINS:
            if _GAINS[data_name] == "i":
                return {"op": "wck.set", "param": "i-gain", "id": m.id, "i": v, "runtime": True}
            return {"op": "wck.set", "param": "gains", "id": m.id, "p": v, "d": v, "runtime": True}
        return {"op": "wck.set", "param": "speed", "id": m.id, "speed": 0, "accel": v, "runtime": True}

    @staticmethod
    def _bus(names: list[str]) -> str | None:
        """The bus to name in a request: the first of its family when there are several."""
        return names[0] if len(names) > 1 else None

    def _homing(self, name: str) -> int:
        c = self.calibration.get(name)
        return int(c.homing_offset) if c is not None else 0

    def _range(self, name: str) -> tuple[int, int]:
        c = self.calibration.get(name)
        if c is None:
            raise RuntimeError(f"{name!r} has no calibration: write_calibration() first, or use normalize=False")
        return int(c.range_min), int(c.range_max)

    def _inverted(self, name: str) -> bool:
        c = self.calibration.get(name)
        return bool(self.apply_drive_mode and c is not None and c.drive_mode)

    def _normalize(self, name: str, raw: int) -> float:
        lo, hi = self._range(name)
        mode = MotorNormMode(getattr(self.motors[name].norm_mode, "value", self.motors[name].norm_mode))
        if mode is MotorNormMode.DEGREES:
            return (raw - (lo + hi) / 2) * _DEG_PER_COUNT[self.motors[name].model]
        span = (min(hi, max(lo, raw)) - lo) / (hi - lo)
        if mode is MotorNormMode.RANGE_0_100:
            v = span * 100
            return 100 - v if self._inverted(name) else v
        v = span * 200 - 100
        return -v if self._inverted(name) else v

    def _unnormalize(self, name: str, value: float) -> int:
        if not math.isfinite(value):
            raise ValueError(f"Goal_Position of {name!r}: {value} is not a finite number; nothing was sent")
        lo, hi = self._range(name)
        mode = MotorNormMode(getattr(self.motors[name].norm_mode, "value", self.motors[name].norm_mode))
        if mode is MotorNormMode.DEGREES:
            return round(value / _DEG_PER_COUNT[self.motors[name].model] + (lo + hi) / 2)
        if mode is MotorNormMode.RANGE_0_100:
            v = 100 - value if self._inverted(name) else value
            return round(min(100.0, max(0.0, v)) / 100 * (hi - lo) + lo)
        v = -value if self._inverted(name) else value
        return round((min(100.0, max(-100.0, v)) + 100) / 200 * (hi - lo) + lo)

    def _write(
        self, data_name: str, targets: Mapping[str, Value], normalize: bool, num_retry: int, reply: bool
    ) -> None:
        names = self._names(list(targets))
        for n in names:
            model = self.motors[n].model
            why = REFUSED.get(data_name, {}).get(model)
            if why is not None:
                raise ValueError(f"{data_name!r} of {n!r}: refused on a {model} motor: {why}; nothing was sent")
            if data_name not in _WRITABLE[model]:
                raise ValueError(
                    f"{data_name!r} of {n!r}: not writable on a {model} motor "
                    f"(writable: {', '.join(_WRITABLE[model])}); nothing was sent"
                )
        if data_name in _SETTINGS:
            # Every value checked, then each motor's request sent (checked and read back
            # by the library: a value out of the device's range is refused there).
            sends = [self._setting(data_name, n, targets[n]) for n in names]
            for send in sends:
                self._retry(send, num_retry, f"write {data_name!r}")
            return
        if data_name == "Torque_Enable":
            on = [n for n in names if targets[n]]
            off = [n for n in names if not targets[n]]
            if off:
                self.disable_torque(off, num_retry)
            if on:
                self.enable_torque(on, num_retry)
            return
        # Every value in raw device units, checked, before anything is sent.
        device: dict[str, float] = {}
        for n in names:
            v = float(targets[n])
            if data_name == "Goal_Position":
                counts = self._unnormalize(n, v) if normalize else v
                if not math.isfinite(counts) or counts != int(counts):
                    raise ValueError(f"Goal_Position of {n!r}: {counts} is not a whole count; nothing was sent")
                if n in self.calibration:
                    lo, hi = self._range(n)
                    if not lo <= counts <= hi:
                        raise ValueError(
                            f"Goal_Position of {n!r}: {counts} is outside the calibrated range "
                            f"{lo}..={hi}; nothing was sent"
                        )
                device[n] = counts + self._homing(n)
            else:
                device[n] = v
        groups = self._by_family(names)
        if WCK in groups:
            for n in names:
                if self.motors[n].model == WCK and not 0 <= device[n] <= _WCK_MAX:
                    raise ValueError(
                        f"Goal_Position of {n!r}: {device[n]} is outside the servo's 0..={_WCK_MAX}; "
                        "nothing was sent"
                    )
        if WHJ in groups:
            ids = groups[WHJ]
            vals = [device[self._name(i, WHJ)] for i in ids]
            g = self._whj(ids)
            if data_name == "Goal_Position":
                self._retry(lambda: g.command_position([v * _DEG_PER_COUNT[WHJ] for v in vals]), num_retry, "write Goal_Position", ids)
            elif data_name == "Goal_Velocity":
                self._retry(lambda: g.command_speed([v * float(_FACTS["whj_rpm_per_target_count"]) for v in vals]), num_retry, "write Goal_Velocity", ids)
            else:
                self._retry(lambda: g.command_current(vals), num_retry, "write Goal_Current", ids)
        if WCK in groups:
            ids = groups[WCK]
            positions = [device[self._name(i, WCK)] for i in ids]
            w = self._wck(ids)
            if not reply and sorted(ids) == list(range(len(ids))) and ids == sorted(ids):
                w.sync_move(positions, self._torque)
            else:
                self._retry(lambda: w.move(positions, self._torque), num_retry, "write Goal_Position", ids)


def _calibration_root() -> pathlib.Path:
    """Where LeRobot keeps calibration files: ``$HF_LEROBOT_CALIBRATION``, else
    ``$HF_LEROBOT_HOME/calibration``, else ``~/.cache/huggingface/lerobot/calibration``."""
    if os.environ.get("HF_LEROBOT_CALIBRATION"):
        return pathlib.Path(os.environ["HF_LEROBOT_CALIBRATION"]).expanduser()
    home = os.environ.get("HF_LEROBOT_HOME")
    if home:
        return pathlib.Path(home).expanduser() / "calibration"
    hf = os.environ.get("HF_HOME") or os.path.join(os.path.expanduser("~"), ".cache", "huggingface")
    return pathlib.Path(hf) / "lerobot" / "calibration"


def _default_motors() -> dict[str, Motor]:
    """The follower arm of the simulated robot: its WHJ joints 1..=6, named as the robot
    file names them (``j1``..``j6``)."""
    return {f"j{i}": Motor(i, WHJ, MotorNormMode.DEGREES) for i in range(1, 7)}


@dataclasses.dataclass(kw_only=True)
class RobobusFollowerConfig:
    """The configuration of a :class:`RobobusFollower` (LeRobot's ``RobotConfig`` fields
    ``id`` and ``calibration_dir``, and its followers' ``port``,
    ``disable_torque_on_disconnect``, ``max_relative_target`` and ``cameras``).

    ``port``: as :class:`RobobusMotorsBus` takes it (``"sim"``: the built-in simulated
    robot on the wall clock, ``"sim:virtual"`` on its virtual clock). ``motors``: the
    arm's motors by name (default: WHJ joints 1..=6 as ``j1``..``j6``, in degrees).
    ``gains``: ``(P, I, D)`` written to every motor by :meth:`RobobusFollower.configure`
    (``None``, the default: the devices keep theirs; WHJ joints come factory-tuned).
    ``calibrate_by_hand``: :meth:`RobobusFollower.calibrate` asks for the middle of the
    range and records the ranges moved by hand, as LeRobot's Feetech arms do (``False``,
    the default: each motor's calibrated range is its device's own limits, nothing to
    move: WHJ joints and wCK servos know their absolute position)."""

    port: str = "sim"
    id: str | None = None
    calibration_dir: pathlib.Path | None = None
    motors: dict[str, Motor] = dataclasses.field(default_factory=_default_motors)
    disable_torque_on_disconnect: bool = True
    max_relative_target: float | dict[str, float] | None = None
    cameras: dict[str, Any] = dataclasses.field(default_factory=dict)
    gains: tuple[int, int, int] | None = None
    calibrate_by_hand: bool = False

    @property
    def type(self) -> str:
        """The robot type's name (LeRobot's ``RobotConfig.type``)."""
        return RobobusFollower.name


def _safe_goal(
    goal_present: Mapping[str, tuple[float, float]], max_relative_target: float | Mapping[str, float]
) -> dict[str, float]:
    """Each goal moved no further than ``max_relative_target`` from the present position
    (LeRobot's ``ensure_safe_goal_position``); a clamped goal is logged."""
    if isinstance(max_relative_target, Mapping):
        if set(goal_present) - set(max_relative_target):
            raise ValueError(
                f"max_relative_target: no value for {sorted(set(goal_present) - set(max_relative_target))}"
            )
        cap = {k: float(max_relative_target[k]) for k in goal_present}
    else:
        cap = dict.fromkeys(goal_present, float(max_relative_target))
    out: dict[str, float] = {}
    clamped: dict[str, tuple[float, float]] = {}
    for key, (goal, present) in goal_present.items():
        safe = present + max(-cap[key], min(cap[key], goal - present))
        out[key] = safe
        if abs(safe - goal) > 1e-4:
            clamped[key] = (goal, safe)
    if clamped:
        log.warning("goal positions clamped to max_relative_target (goal, sent): %s", clamped)
    return out


class RobobusFollower:
    """A LeRobot robot: a follower arm on robobus's joints, with the interface of
    LeRobot's ``Robot`` (``connect`` / ``calibrate`` / ``configure`` /
    ``get_observation`` / ``send_action`` / ``disconnect``, ``observation_features`` and
    ``action_features`` as ``{"<motor>.pos": float}``), over a :class:`RobobusMotorsBus`
    (``self.bus``). ::

        from robobus.lerobot import RobobusFollower, RobobusFollowerConfig

        robot = RobobusFollower(RobobusFollowerConfig(port="sim", id="arm"))
        robot.connect()                      # calibrates if needed, then configures
        obs = robot.get_observation()        # {"j1.pos": 0.0, ...}, read now
        robot.send_action({"j1.pos": 5.0})   # checked whole before anything is sent
        robot.disconnect()

    The calibration file is LeRobot's (``<calibration_dir>/<id>.json``, the
    ``MotorCalibration`` fields by motor). ``configure`` writes what LeRobot's followers
    write at start: every motor's ``Operating_Mode`` to position and, when the config
    has ``gains``, its P, I and D. Cameras are LeRobot's own; none here. When LeRobot is
    installed, the class is registered as a virtual subclass of its ``Robot``.
    """

    config_class = RobobusFollowerConfig
    name = "robobus_follower"

    def __init__(self, config: RobobusFollowerConfig):
        if config.cameras:
            raise ValueError(
                f"cameras {sorted(config.cameras)}: a RobobusFollower has no cameras yet "
                "(LeRobot's cameras are not part of robobus); use an empty cameras"
            )
        self.config = config
        self.robot_type = self.name
        self.id = config.id
        self.calibration_dir = pathlib.Path(
            config.calibration_dir
            if config.calibration_dir is not None
            else _calibration_root() / "robots" / self.name
        )
        self.calibration_dir.mkdir(parents=True, exist_ok=True)
        self.calibration_fpath = self.calibration_dir / f"{self.id}.json"
        self.calibration: dict[str, MotorCalibration] = {}
        if self.calibration_fpath.is_file():
            self._load_calibration()
        self.bus = RobobusMotorsBus(config.port, dict(config.motors), calibration=self.calibration)

    def __str__(self) -> str:
        return f"{self.id} {type(self).__name__}"

    def __enter__(self) -> "RobobusFollower":
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()

    @property
    def _motors_ft(self) -> dict[str, type]:
        return {f"{motor}.pos": float for motor in self.bus.motors}

    @property
    def observation_features(self) -> dict[str, type]:
        """``{"<motor>.pos": float}``: what :meth:`get_observation` returns."""
        return self._motors_ft

    @property
    def action_features(self) -> dict[str, type]:
        """``{"<motor>.pos": float}``: what :meth:`send_action` takes."""
        return self._motors_ft

    @property
    def is_connected(self) -> bool:
        """Whether the bus is connected."""
        return self.bus.is_connected

    @property
    def is_calibrated(self) -> bool:
        """Whether every motor has a calibration within its device's range."""
        return self.bus.is_calibrated

    def connect(self, calibrate: bool = True) -> None:
        """Connects the bus (every motor read once: a silent one raises
        ``ConnectionError`` naming it), calibrates when ``calibrate`` and the
        calibration is missing or outside the devices' ranges, then :meth:`configure`."""
        if self.is_connected:
            raise DeviceAlreadyConnectedError(f"{self} already connected")
        self.bus.connect()
        try:
            if calibrate and not self.is_calibrated:
                log.info("%s: no calibration, or one outside the devices' ranges: calibrating", self)
                self.calibrate()
            self.configure()
        except BaseException:
            self.bus.disconnect(disable_torque=False)
            raise
        log.info("%s connected", self)

    def calibrate(self) -> None:
        """Each motor's calibration: its device's own range with no homing offset (or,
        with ``calibrate_by_hand``, LeRobot's procedure: the middle of the range, then
        the ranges moved by hand until Enter), written to the bus and saved to
        :attr:`calibration_fpath`."""
        self._require()
        if self.config.calibrate_by_hand:
            self.bus.disable_torque()
            input(f"Move {self} to the middle of its range of motion and press ENTER....")
            homings = self.bus.set_half_turn_homings()
            print("Move every joint through its whole range of motion. Press ENTER to stop...")
            mins, maxes = self.bus.record_ranges_of_motion()
            self.calibration = {
                motor: MotorCalibration(
                    id=m.id,
                    drive_mode=0,
                    homing_offset=int(homings[motor]),
                    range_min=int(mins[motor]),
                    range_max=int(maxes[motor]),
                )
                for motor, m in self.bus.motors.items()
            }
        else:
            self.calibration = self.bus.read_calibration()
        self.bus.write_calibration(self.calibration)
        self._save_calibration()
        log.info("%s: calibration saved to %s", self, self.calibration_fpath)

    def configure(self) -> None:
        """What LeRobot's followers write at start, with torque off: every motor's
        ``Operating_Mode`` to position and, with the config's ``gains``, its P, I and D
        (each a request of the catalogue, checked first and read back); torque is on
        again afterwards."""
        self._require()
        with self.bus.torque_disabled():
            self.bus.configure_motors()
            for motor in self.bus.motors:
                self.bus.write("Operating_Mode", motor, OperatingMode.POSITION.value)
                if self.config.gains is not None:
                    p, i, d = self.config.gains
                    self.bus.write("P_Coefficient", motor, p)
                    self.bus.write("I_Coefficient", motor, i)
                    self.bus.write("D_Coefficient", motor, d)

    def get_observation(self) -> dict[str, Any]:
        """Every motor's position, read now (normalised as its ``norm_mode`` says)."""
        self._require()
        return {f"{motor}.pos": val for motor, val in self.bus.sync_read("Present_Position").items()}

    def send_action(self, action: Mapping[str, Any]) -> dict[str, Any]:
        """Sends the ``"<motor>.pos"`` goals of ``action`` (a goal moved no further than
        ``max_relative_target`` from the present position, when set); every goal is
        checked before any is sent. Returns the goals sent."""
        self._require()
        goal = {k.removesuffix(".pos"): float(v) for k, v in action.items() if k.endswith(".pos")}
        unknown = sorted(set(goal) - set(self.bus.motors))
        if unknown:
            raise ValueError(
                f"action: no motor {unknown} (motors: {list(self.bus.motors)}); nothing was sent"
            )
        if self.config.max_relative_target is not None:
            present = self.bus.sync_read("Present_Position", list(goal))
            goal = _safe_goal({k: (g, present[k]) for k, g in goal.items()}, self.config.max_relative_target)
        self.bus.sync_write("Goal_Position", goal)
        return {f"{motor}.pos": val for motor, val in goal.items()}

    def disconnect(self) -> None:
        """Disconnects; with ``disable_torque_on_disconnect`` every motor goes limp first
        (the port closed with every device in its safe state)."""
        if not self.is_connected:
            raise DeviceNotConnectedError(f"{self} is not connected")
        self.bus.disconnect(self.config.disable_torque_on_disconnect)
        log.info("%s disconnected", self)

    def _require(self) -> None:
        if not self.is_connected:
            raise DeviceNotConnectedError(f"{self} is not connected: call connect() first")

    def _load_calibration(self, fpath: pathlib.Path | None = None) -> None:
        """Reads LeRobot's calibration file (``{motor: MotorCalibration fields}``)."""
        path = self.calibration_fpath if fpath is None else fpath
        data = json.loads(path.read_text())
        if not isinstance(data, dict):
            raise ValueError(f"{path}: not a calibration file (a JSON object of motors)")
        self.calibration = {name: MotorCalibration(**fields) for name, fields in data.items()}

    def _save_calibration(self, fpath: pathlib.Path | None = None) -> None:
        """Writes the calibration as LeRobot does (indented JSON, by motor)."""
        path = self.calibration_fpath if fpath is None else fpath
        path.write_text(
            json.dumps({name: dataclasses.asdict(c) for name, c in self.calibration.items()}, indent=4)
        )


def _register_with_lerobot() -> None:
    """Makes ``isinstance(bus, MotorsBusBase)`` true when LeRobot is installed."""
    if importlib.util.find_spec("lerobot") is None:
        return
    try:
        from lerobot.motors import motors_bus  # type: ignore[import-not-found]
    except Exception as e:  # noqa: BLE001 (LeRobot is optional and may be broken)
        log.debug("LeRobot is installed but does not import: %s", e)
        return
    base = getattr(motors_bus, "MotorsBusBase", None) or getattr(motors_bus, "MotorsBus", None)
    if base is not None and hasattr(base, "register"):
        base.register(RobobusMotorsBus)
    try:
        from lerobot.robots import Robot  # type: ignore[import-not-found]
    except Exception as e:  # noqa: BLE001 (LeRobot is optional and may be broken)
        log.debug("LeRobot's Robot does not import: %s", e)
        return
    Robot.register(RobobusFollower)


_register_with_lerobot()
