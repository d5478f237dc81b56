"""The exceptions of robobus: one base class, one subclass per error kind of the library.

Each subclass also derives from the matching builtin, so ``except ValueError`` catches bad
input and ``except TimeoutError`` a device that did not answer. The message is the
library's; ``kind`` is the kind's name (``"no-device"``); ``report`` is the report of a
request whose devices failed, when the error stands for one (``check=True``).
"""

from __future__ import annotations

from typing import Any


class RobobusError(Exception):
    """Any robobus error."""

    kind: str
    report: dict[str, Any] | None

    def __init__(self, message: str, kind: str = "runtime", report: dict[str, Any] | None = None):
        super().__init__(message)
        self.kind = kind
        self.report = report


class BadInputError(RobobusError, ValueError):
    """A value out of range or malformed, an unknown field; nothing was sent."""


class RefusedError(RobobusError, PermissionError):
    """Refused for safety or for the device's state (a write that needs ``confirm=True``,
    a gated register, an ID in use); nothing was sent."""


class NoDeviceError(RobobusError, TimeoutError):
    """No device answered in time, or the port / interface does not exist."""


class DeviceError(RobobusError, RuntimeError):
    """The device answered with an error, a malformed reply, or another state than asked."""


class ProtectionError(DeviceError):
    """The host's protection stopped a joint during a :class:`robobus.Robot` command (a
    stall, a collision, heat, a joint under effort turning past its ``max_velocity``).

    The joint was brought to rest (disabled where its brake holds it, else held where it
    stands), and every later command is refused (:class:`RefusedError`) until
    :meth:`robobus.Robot.clear_protection`. The message names the joint, the quantity, the
    limit and the time; so do the attributes: ``joint`` (its name), ``check``
    (``"stall"``, ``"collision"``, ``"thermal"``, ``"speed"``), ``quantity``
    (``"current_a"``, ``"current_jump_a"``, ``"following_error_jump_deg"``,
    ``"speed_deg_s"``, ``"temperature_c"``), ``value``, ``limit`` (in the quantity's unit)
    and ``at_s`` (seconds since the robot was opened, on its clock)."""

    joint: str
    check: str
    quantity: str
    value: float
    limit: float
    at_s: float

    def __init__(
        self,
        message: str,
        kind: str = "device",
        report: dict[str, Any] | None = None,
        fault: dict[str, Any] | None = None,
    ):
        super().__init__(message, kind, report)
        fault = fault or {}
        self.joint = fault.get("joint", "")
        self.check = fault.get("check", "")
        self.quantity = fault.get("quantity", "")
        self.value = float(fault.get("value", float("nan")))
        self.limit = float(fault.get("limit", float("nan")))
        self.at_s = float(fault.get("at_s", float("nan")))


class LinkError(RobobusError, OSError):
    """The link failed: I/O error, port busy, permission, bus off."""


class StoppedError(RobobusError):
    """Stopped by its stop token; the devices were brought to their safe state."""


class NotAvailableError(RobobusError, OSError):
    """The operation needs something this build or machine does not have."""


BY_KIND: dict[str, type[RobobusError]] = {
    "bad-input": BadInputError,
    "refused": RefusedError,
    "no-device": NoDeviceError,
    "device": DeviceError,
    "link": LinkError,
    "interrupted": StoppedError,
    "not-available": NotAvailableError,
}


def check(report: dict[str, Any]) -> dict[str, Any]:
    """Returns ``report`` if no device failed, else raises the class of its worst failure
    with the report attached."""
    kind = report.get("failed")
    if kind is None:
        return report
    cls = BY_KIND.get(kind, RobobusError)
    raise cls(report.get("error") or kind, kind, report)
