"""Configuration (TOML): loaded once, every key range-checked, unknown keys refused.

Tables: ``[machine]`` (required) and ``[yarn]`` describe the geometry; ``[fieldbus]`` with
``[fieldbus.modbus]`` or ``[fieldbus.canopen]`` the actuator bus; ``[daemon]`` where the
daemon keeps its state; ``[simulator]`` the mock loom. Every key of every table is
documented in docs/config.md and set, with a comment, in config/loom.toml.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from decimal import Decimal
from pathlib import Path
from typing import Any, Literal

from bwsd.errors import ConfigError, TwinError
from bwsd.limits import MODBUS_MAX_AXES, MODBUS_MAX_CELLS
from bwsd.twin.exact import MIN_LENGTH, decimal_float
from bwsd.twin.machine import WEFT_AXES, Machine, Segment


@dataclass(frozen=True)
class Num:
    """A number key: its type, range and default (None: required)."""

    kind: type
    low: float
    high: float
    default: float | None = None


@dataclass(frozen=True)
class Text:
    """A string key, optionally one of ``choices``."""

    default: str | None = None
    choices: tuple[str, ...] = ()


@dataclass(frozen=True)
class Flag:
    """A true/false key."""

    default: bool


@dataclass(frozen=True)
class Segments:
    """A list of line segments, each written as in a program: ``"ROW 3[0..3]"``."""

    default: tuple[Segment, ...] = ()


@dataclass(frozen=True)
class Names:
    """A list of distinct names out of ``choices`` (kept in the order of ``choices``)."""

    choices: tuple[str, ...]
    default: tuple[str, ...]


@dataclass(frozen=True)
class Point:
    """An optional point: a list of three numbers (mm), read as exact decimals."""

    default: tuple[float, float, float] | None = None


Spec = Num | Text | Flag | Segments | Names | Point
_SEGMENT = re.compile(
    r"\s*(row|col)\s+([0-9]{1,6})\s*\[\s*([0-9]{1,6})\s*\.\.\s*([0-9]{1,6})\s*\]\s*",
    re.IGNORECASE | re.ASCII,
)

SCHEMA: dict[str, dict[str, Spec]] = {
    "machine": {
        "rows": Num(int, 1, 1000),
        "cols": Num(int, 1, 1000),
        "pitch_x": Num(float, 1e-3, 1e4),
        "pitch_y": Num(float, 1e-3, 1e4),
        "d_mat": Num(float, 1e-3, 1e5),
        "c_mat": Num(float, 0.0, 1.0),
        "segments": Segments(),
        "weft_axes": Names(WEFT_AXES, WEFT_AXES),
        "weft_fixed": Point(),
    },
    "yarn": {
        "diameter": Num(float, 0.0, 1e3, 0.0),
        "tension": Num(float, 1e-6, 1e6, 1.0),  # N, warps (the relaxation: only ratios matter)
        "weft_tension": Num(float, 1e-6, 1e6, 1.0),  # N, wefts
    },
    "fieldbus": {
        "backend": Text("modbus", ("modbus", "canopen")),
        "timeout": Num(float, 1e-3, 3600.0, 5.0),
        "io_timeout": Num(float, 1e-3, 60.0, 1.0),
        "reconnect_delay": Num(float, 1e-3, 60.0, 0.1),
        "reconnect_delay_max": Num(float, 1e-3, 600.0, 2.0),
        "reconnect_attempts": Num(int, 1, 1000, 5),
        "position_tolerance": Num(int, 0, 1_000_000, 10),
        "poll_max": Num(float, 1e-3, 1.0, 0.01),
    },
    "fieldbus.modbus": {
        "host": Text("127.0.0.1"),
        "port": Num(int, 1, 65535, 15020),
        "device_id": Num(int, 0, 247, 1),
        "map": Num(int, 2, 3, 3),
    },
    "fieldbus.canopen": {
        "interface": Text("socketcand", ("socketcan", "socketcand", "virtual")),
        "channel": Text("can0"),
        "host": Text("127.0.0.1"),
        "port": Num(int, 1, 65535, 29536),
        "node_base": Num(int, 1, 127, 1),
        "io_node": Num(int, 1, 127, 127),
        "heartbeat_ms": Num(int, 0, 65535, 100),
    },
    "controller": {
        "max_contacts": Num(int, 0, 10_000_000, 10_000),
        "tensioner_stroke": Num(float, 0.0, 1e5, 0.0),
        "max_instructions": Num(int, 1, 1_000_000, 1_000_000),
        "snapshot_every": Num(int, 0, 1_000_000, 200),
    },
    "daemon": {"state_dir": Text("state")},
    "journal": {"path": Text("journal.db"), "busy_timeout": Num(float, 0.1, 600.0, 5.0)},
    "api": {
        "host": Text("127.0.0.1"),
        "port": Num(int, 0, 65535, 8080),
        "tokens_file": Text("tokens.json"),
        "open_reads": Flag(False),
        "origins": Text(""),
        "hosts": Text(""),
        "web_root": Text(""),
        "max_connections": Num(int, 1, 100_000, 64),
        "max_connections_per_client": Num(int, 1, 100_000, 16),
        "body_timeout": Num(float, 0.1, 3600.0, 10.0),
        "certfile": Text(""),
        "keyfile": Text(""),
    },
    "plc": {
        "enabled": Flag(True),
        "host": Text("127.0.0.1"),
        "port": Num(int, 0, 65535, 15502),
        "device_id": Num(int, 0, 247, 1),
        "allow": Text("127.0.0.1 ::1"),
        "read_only": Flag(False),
    },
    "opcua": {
        "enabled": Flag(False),
        "host": Text("127.0.0.1"),
        "port": Num(int, 0, 65535, 4840),
        "policy": Text(
            "Basic256Sha256", ("Basic256Sha256", "Aes128Sha256RsaOaep", "Aes256Sha256RsaPss")
        ),
        "mode": Text("SignAndEncrypt", ("SignAndEncrypt", "Sign")),
        "allow_none": Flag(False),
        "anonymous": Flag(False),
        "folder": Text("opcua"),
    },
    "simulator": {
        "host": Text("127.0.0.1"),
        "modbus_port": Num(int, 0, 65535, 15020),
        "socketcand_port": Num(int, 0, 65535, 29536),
        "canopen": Text("auto", ("auto", "on", "off")),
        "control_port": Num(int, 0, 65535, 15021),
        "stroke_speed": Num(float, 0.0, 1e6, 0.0),
        "takeup_speed": Num(float, 0.0, 1e6, 0.0),
        "weft_speed": Num(float, 0.0, 1e6, 0.0),
        "weft_travel_speed": Num(float, 0.0, 1e6, 0.0),
        "heartbeat_ms": Num(int, 0, 65535, 100),
        "state_file": Text(""),
    },
}
REQUIRED = ("machine",)


@dataclass(frozen=True)
class Config:
    """A loaded configuration: the machine geometry and every table with defaults filled."""

    machine: Machine
    path: str
    tables: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def table(self, name: str) -> Mapping[str, Any]:
        """A table by dotted name (``fieldbus.modbus``), defaults filled in."""
        return self.tables[name]


def _value(where: tuple[str, str, str], value: Any, spec: Spec) -> Any:
    path, table, key = where
    if isinstance(spec, Segments):
        return _segments(where, value)
    if isinstance(spec, Names):
        return _names(where, value, spec.choices)
    if isinstance(spec, Point):
        return _point(where, value)
    if isinstance(spec, Flag):
        if not isinstance(value, bool):
            raise ConfigError(
                f"must be true or false, got {value!r}", path=path, table=table, key=key
            )
        return value
    if isinstance(spec, Text):
        if not isinstance(value, str):
            raise ConfigError(f"must be a string, got {value!r}", path=path, table=table, key=key)
        if spec.choices and value not in spec.choices:
            raise ConfigError(
                f"must be one of {', '.join(spec.choices)}, got {value!r}",
                path=path,
                table=table,
                key=key,
            )
        return value
    if isinstance(value, Decimal | float):
        value = _exact_number(where, value)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"must be a number, got {value!r}", path=path, table=table, key=key)
    if spec.kind is int and not isinstance(value, int):
        raise ConfigError(f"must be an integer, got {value!r}", path=path, table=table, key=key)
    if not spec.low <= value <= spec.high:
        raise ConfigError(
            f"must lie in [{spec.low:g}, {spec.high:g}], got {value!r}",
            path=path,
            table=table,
            key=key,
        )
    return spec.kind(value)


def _segments(where: tuple[str, str, str], value: Any) -> tuple[Segment, ...]:
    path, table, key = where
    if not isinstance(value, list):
        raise ConfigError(
            'must be a list of segments like "ROW 3[0..3]"', path=path, table=table, key=key
        )
    found = []
    for i, text in enumerate(value):
        match = _SEGMENT.fullmatch(text) if isinstance(text, str) else None
        if match is None:
            raise ConfigError(
                f"entry {i + 1}: {str(text)[:40]!r} is not a segment like "
                '"ROW 3[0..3]" or "COL 2[4..9]"',
                path=path,
                table=table,
                key=key,
            )
        axis: Literal["row", "col"] = "row" if match[1].lower() == "row" else "col"
        found.append(Segment(axis, int(match[2]), int(match[3]), int(match[4])))
    return tuple(found)


def _names(where: tuple[str, str, str], value: Any, choices: tuple[str, ...]) -> tuple[str, ...]:
    path, table, key = where
    named = ", ".join(f'"{c}"' for c in choices)
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ConfigError(
            f"must be a list of names out of {named}", path=path, table=table, key=key
        )
    for i, name in enumerate(value):
        if name not in choices:
            why = f"entry {i + 1}: {name[:20]!r} is not one of {named}"
            raise ConfigError(why, path=path, table=table, key=key)
        if name in value[:i]:
            why = f"entry {i + 1}: {name!r} is named twice"
            raise ConfigError(why, path=path, table=table, key=key)
    return tuple(c for c in choices if c in value)


def _point(where: tuple[str, str, str], value: Any) -> tuple[float, float, float]:
    path, table, key = where
    if not isinstance(value, list) or len(value) != 3:
        why = "must be a list of three numbers [x, y, z] (mm)"
        raise ConfigError(why, path=path, table=table, key=key)
    x, y, z = (_value(where, v, Num(float, -1e5, 1e5)) for v in value)
    return x, y, z


def _exact_number(where: tuple[str, str, str], value: Decimal | float) -> float:
    """A number read as the exact decimal written (docs/twin.md): carried by a float."""
    path, table, key = where
    try:
        return decimal_float(str(value))
    except ValueError as exc:
        raise ConfigError(str(exc), path=path, table=table, key=key) from None


def _table(raw: Any, name: str, path: str) -> dict[str, Any]:
    spec = SCHEMA[name]
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError("must be a table", path=path, table=name)
    out: dict[str, Any] = {}
    for key, value in raw.items():
        if f"{name}.{key}" in SCHEMA:
            continue  # a sub-table, validated on its own
        if key not in spec:
            raise ConfigError(
                f"unknown key (known: {', '.join(spec)})", path=path, table=name, key=key
            )
        out[key] = _value((path, name, key), value, spec[key])
    for key, key_spec in spec.items():
        if key not in out:
            if key_spec.default is None and not isinstance(key_spec, Point):
                raise ConfigError("missing key", path=path, table=name, key=key)
            out[key] = key_spec.default
    return out


def _lookup(data: Mapping[str, Any], dotted: str) -> Any:
    node: Any = data
    for part in dotted.split("."):
        if not isinstance(node, Mapping):
            return None
        node = node.get(part)
    return node


def parse_config(data: Mapping[str, Any], path: str = "<config>") -> Config:
    """Validate an already-parsed TOML mapping."""
    for name in data:
        if name not in SCHEMA:
            raise ConfigError("unknown table", path=path, table=name)
    for name in REQUIRED:
        if name not in data:
            raise ConfigError("missing table", path=path, table=name)
    tables = {name: _table(_lookup(data, name), name, path) for name in SCHEMA}
    _weft_axes_of_map(data, tables, path)
    try:
        machine = Machine(**tables["machine"])
    except ValueError as exc:  # the segments: each key alone is in range
        raise ConfigError(str(exc), path=path, table="machine", key="segments") from None
    fault = machine.diameter_fault(tables["yarn"]["diameter"])
    if fault is not None:
        raise ConfigError(fault, path=path, table="yarn", key="diameter")
    machine = dataclasses.replace(machine, yarn_diameter=tables["yarn"]["diameter"])
    _check_geometry(machine, path)
    if tables["fieldbus"]["backend"] == "canopen":
        _check_canopen_ids(tables["fieldbus.canopen"], machine, path)
    else:
        _check_modbus_map(machine, path)
    return Config(machine=machine, path=path, tables=tables)


def _weft_axes_of_map(
    data: Mapping[str, Any], tables: dict[str, dict[str, Any]], path: str
) -> None:
    """Modbus map 2 has no weft positioning axes: ``weft_axes`` is none there by default, and
    naming one is refused."""
    fieldbus, modbus = tables["fieldbus"], tables["fieldbus.modbus"]
    if fieldbus["backend"] != "modbus" or modbus["map"] != 2:
        return
    if _lookup(data, "machine.weft_axes") not in (None, []):
        why = (
            "Modbus map 2 has no weft positioning axes ([fieldbus.modbus] map = 2): leave "
            "weft_axes out or set it to []"
        )
        raise ConfigError(why, path=path, table="machine", key="weft_axes")
    tables["machine"]["weft_axes"] = ()


def _check_geometry(machine: Machine, path: str) -> None:
    """The twin's grid has a range (2^20 mm) and a finest pitch and diameter (docs/twin.md)."""
    from bwsd.twin.geometry import Geometry

    try:
        Geometry(machine)
    except TwinError as exc:
        raise ConfigError(str(exc), path=path, table="machine") from None
    if 0 < machine.yarn_diameter < float(MIN_LENGTH):
        raise ConfigError(
            f"must be 0 or at least {float(MIN_LENGTH):g} mm",
            path=path,
            table="yarn",
            key="diameter",
        )


def _check_modbus_map(machine: Machine, path: str) -> None:
    """Occupancy sensors are discrete inputs 0 .. R*C-1 (e-stop R*C); an axis block per row,
    column, weft and take-up axis and segment, ending at holding register 65535."""
    if machine.rows * machine.cols > MODBUS_MAX_CELLS:
        raise ConfigError(
            f"{machine.rows * machine.cols} cells: the Modbus map addresses at "
            f"most {MODBUS_MAX_CELLS}",
            path=path,
            table="fieldbus",
            key="backend",
        )
    axes = axis_count(machine)
    if axes > MODBUS_MAX_AXES:  # only segments get there while rows and cols are <= 1000
        raise ConfigError(
            f"the Modbus map addresses at most {MODBUS_MAX_AXES} axes, the machine "
            f"has {axes} ({machine.rows} rows, {machine.cols} cols, "
            f"{3 + len(machine.weft_axes)} weft and take-up axes, "
            f"{len(machine.segments)} segments)",
            path=path,
            table="machine",
            key="segments" if machine.segments else "",
        )


def _check_canopen_ids(table: Mapping[str, Any], machine: Machine, path: str) -> None:
    """A drive per axis (rows, cols, weft angle and insert, take-up, segments, the weft's
    positioning axes), node ids from ``node_base``, all within 127 and apart from the I/O
    node."""
    axes = axis_count(machine)
    last = table["node_base"] + axes - 1
    if last > 127:
        what = f" ({len(machine.segments)} of them segments)" if machine.segments else ""
        raise ConfigError(
            f"{axes} axes{what} from node {table['node_base']} pass node id 127",
            path=path,
            table="fieldbus.canopen",
            key="node_base",
        )
    if table["node_base"] <= table["io_node"] <= last:
        raise ConfigError(
            f"collides with the drives' node ids {table['node_base']}..{last}",
            path=path,
            table="fieldbus.canopen",
            key="io_node",
        )


def axis_count(machine: Machine) -> int:
    """The machine's axes (as ``bwsd.fieldbus.axes.machine_axes`` numbers them)."""
    return machine.rows + machine.cols + 3 + len(machine.segments) + len(machine.weft_axes)


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML configuration file (``example:NAME``: a shipped one)."""
    from bwsd.shipped import resolve

    path = resolve(path)
    text_path = str(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh, parse_float=Decimal)
    except OSError as exc:
        raise ConfigError(f"cannot read: {exc.strerror}", path=text_path) from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML: {exc}", path=text_path) from exc
    except UnicodeDecodeError as exc:
        byte = exc.object[exc.start]
        raise ConfigError(
            f"not UTF-8 text: byte 0x{byte:02x} at offset {exc.start}", path=text_path
        ) from None
    except RecursionError:
        raise ConfigError("not valid TOML: nested too deeply", path=text_path) from None
    return parse_config(data, text_path)


def port_option(text: str) -> int:
    """A port given on the command line in place of a config's: 0 (any free port) to 65535.

    For ``argparse``'s ``type=``: a bad one is an ``ArgumentTypeError`` naming the option.
    """
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"a port lies in 0..65535 (0: any free one), got {port}")
    return port
