"""The Python form of every operation of the catalogue, from its request schema: its
parameters (the required fields in the command line's order, the rest keyword-only), their
types and docs, and its docstring. The generated methods (``station.wck.move``) carry them
at run time (``inspect.signature``, ``help()``), and ``stubgen.py`` writes the type stubs
from the same functions, so the two cannot say different things.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import keyword
import textwrap
from typing import Any


@dataclasses.dataclass(frozen=True)
class Field:
    """A request field as a Python parameter."""

    #: The field's name in the request (``from``).
    field: str
    #: The parameter's name (``from_``: a Python keyword gets a trailing ``_``).
    name: str
    #: Its Python type, as written in a stub (``int``, ``str | Sequence[int]``).
    type: str
    #: Whether the request needs it (then it may be given in order).
    required: bool
    #: The schema's description of it.
    doc: str
    #: The library's default when it is left out (``None``: no default or ``null``).
    default: Any


@dataclasses.dataclass(frozen=True)
class Operation:
    """One operation of the catalogue as a Python method."""

    op: str
    family: str
    #: The method's name within its family (``sync_move``).
    name: str
    #: What the operation does (the schema's description).
    summary: str
    #: Required fields first (the command line's order), then the optional ones by name.
    fields: tuple[Field, ...]


def arg(name: str) -> str:
    """A schema field as a parameter name (``from`` is a Python keyword: ``from_``)."""
    return name + "_" if keyword.iskeyword(name) else name


def method_name(op: str) -> str:
    """The Python name of an operation within its family: ``wck.sync-move`` is
    ``station.wck.sync_move``, ``wck.program.upload`` ``station.wck.program_upload``."""
    return op.split(".", 1)[1].replace(".", "_").replace("-", "_")


def py_type(prop: dict[str, Any], defs: dict[str, Any]) -> str:
    """The Python type of a schema property."""
    if "$ref" in prop:
        name = prop["$ref"].rsplit("/", 1)[1]
        return py_type(defs[name], defs)
    for key in ("oneOf", "anyOf"):
        if key in prop:
            alts = prop[key]
            if all("const" in a for a in alts):
                return "Literal[" + ", ".join(json.dumps(a["const"]) for a in alts) + "]"
            return " | ".join(dict.fromkeys(py_type(a, defs) for a in alts))
    if "const" in prop:
        return f"Literal[{json.dumps(prop['const'])}]"
    t = prop.get("type")
    if isinstance(t, list):
        return " | ".join(py_type({**prop, "type": one}, defs) for one in t)
    if not isinstance(t, str):
        return "Any"
    return {
        "integer": "int",
        "number": "float",
        "boolean": "bool",
        "string": "str",
        "null": "None",
    }.get(t, f"Sequence[{py_type(prop.get('items', {}), defs)}]" if t == "array" else "Any")


def _doc(prop: dict[str, Any], defs: dict[str, Any]) -> str:
    """A field's description; for a choice of names, each name's too."""
    text = " ".join(str(prop.get("description", "")).split())
    target = prop
    if "$ref" in prop:
        target = defs[prop["$ref"].rsplit("/", 1)[1]]
        if not text:
            text = " ".join(str(target.get("description", "")).split())
    alts = target.get("oneOf") or []
    if alts and all("const" in a for a in alts):
        choices = "; ".join(
            f"``{json.dumps(a['const'])}``: "
            + " ".join(str(a.get("description", "")).split()).rstrip(".")
            for a in alts
        )
        text = f"{text} {choices}." if text else f"{choices}."
    return text


def operations(schema: dict[str, Any]) -> dict[str, Operation]:
    """Every operation of the request ``schema``, by its name (``wck.move``)."""
    defs = schema.get("$defs", {})
    out: dict[str, Operation] = {}
    for variant in schema["oneOf"]:
        props = variant["properties"]
        op = props["op"]["const"]
        required = [f for f in variant.get("required", []) if f != "op"]
        optional = sorted(f for f in props if f not in required and f != "op")
        fields = []
        for f in required + optional:
            t = py_type(props[f], defs)
            if f not in required and "None" not in t.split(" | "):
                t += " | None"
            fields.append(
                Field(
                    field=f,
                    name=arg(f),
                    type=t,
                    required=f in required,
                    doc=_doc(props[f], defs),
                    default=props[f].get("default"),
                )
            )
        out[op] = Operation(
            op=op,
            family=op.split(".", 1)[0],
            name=method_name(op),
            summary=" ".join(str(variant.get("description", "")).split()) or f"The request ``{op}``.",
            fields=tuple(fields),
        )
    return out


CHECK_DOC = (
    "A device that failed raises its kind's error (a silent one NoDeviceError), the report "
    "under ``.report`` (the default); ``False`` returns the report with a row per device."
)


def docstring(o: Operation) -> str:
    """The method's docstring: what it does, each parameter with its type and doc, what it
    returns and raises."""
    lines = [*textwrap.wrap(o.summary, 88), "", f"The request ``{o.op}`` (docs/catalogue.md).", "", "Args:"]
    for f in o.fields:
        more = "" if f.required else ", optional"
        default = "" if f.required or f.default is None else f" Default: ``{json.dumps(f.default)}``."
        body = f"{f.name} ({f.type}{more}): {f.doc}{default}"
        lines.extend(textwrap.wrap(body, 88, initial_indent="    ", subsequent_indent="        "))
    lines.extend(
        textwrap.wrap(
            f"check (bool, optional): {CHECK_DOC}",
            88,
            initial_indent="    ",
            subsequent_indent="        ",
        )
    )
    lines += [
        "",
        "Returns:",
        "    The report as ``robobus run --json`` prints it: ``op``, ``bus``, ``results``",
        "    (a row per device, keyed ``id``), ``summary``.",
        "",
        "Raises:",
        "    BadInputError: an argument out of range or of the wrong type; nothing was sent.",
        "    RefusedError: refused for safety (``confirm``, disarmed, read-only); nothing sent.",
        "    NoDeviceError, DeviceError, LinkError: a device failed (with ``check=True``).",
    ]
    return "\n".join(lines)


def signature(o: Operation, *, self_: bool = True, check: bool = True) -> inspect.Signature:
    """The method's signature: ``self``, the required fields (positional or by name), the
    optional ones keyword-only with ``None`` (left out of the request), ``check``."""
    kind_req = inspect.Parameter.POSITIONAL_OR_KEYWORD
    kind_opt = inspect.Parameter.KEYWORD_ONLY
    params = [inspect.Parameter("self", kind_req)] if self_ else []
    for f in o.fields:
        if f.required:
            params.append(inspect.Parameter(f.name, kind_req, annotation=f.type))
        else:
            params.append(inspect.Parameter(f.name, kind_opt, default=None, annotation=f.type))
    if check:
        params.append(inspect.Parameter("check", kind_opt, default=True, annotation="bool"))
    return inspect.Signature(params, return_annotation="dict[str, Any]")
