"""Machine configuration (TOML): loaded once, every key range-checked, unknown keys refused."""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bwsd.errors import ConfigError
from bwsd.twin.machine import Machine

# Tables the daemon's later parts own; validated by them, accepted here.
DAEMON_TABLES: frozenset[str] = frozenset()

_MACHINE_KEYS: dict[str, tuple[type, float, float]] = {
    "rows": (int, 1, 1000),
    "cols": (int, 1, 1000),
    "pitch_x": (float, 1e-3, 1e4),
    "pitch_y": (float, 1e-3, 1e4),
    "d_mat": (float, 1e-3, 1e5),
    "c_mat": (float, 0.0, 1.0),
}
_YARN_KEYS: dict[str, tuple[type, float, float]] = {"diameter": (float, 0.0, 1e3)}


@dataclass(frozen=True)
class Config:
    """A loaded configuration: the machine geometry plus the raw daemon tables."""

    machine: Machine
    path: str
    tables: Mapping[str, Mapping[str, Any]]


def _number(table: str, key: str, value: Any, spec: tuple[type, float, float], path: str) -> Any:
    kind, low, high = spec
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"must be a number, got {value!r}", path=path, table=table, key=key)
    if kind is int and not isinstance(value, int):
        raise ConfigError(f"must be an integer, got {value!r}", path=path, table=table, key=key)
    if not low <= value <= high:
        raise ConfigError(
            f"must lie in [{low:g}, {high:g}], got {value!r}", path=path, table=table, key=key
        )
    return kind(value)


def _table(
    data: Mapping[str, Any],
    name: str,
    spec: dict[str, tuple[type, float, float]],
    path: str,
    required: bool,
) -> dict[str, Any]:
    raw = data.get(name)
    if raw is None:
        if required:
            raise ConfigError("missing table", path=path, table=name)
        return {}
    if not isinstance(raw, dict):
        raise ConfigError("must be a table", path=path, table=name)
    for key in raw:
        if key not in spec:
            raise ConfigError(
                f"unknown key (known: {', '.join(spec)})", path=path, table=name, key=key
            )
    out = {}
    for key, key_spec in spec.items():
        if key not in raw:
            if required:
                raise ConfigError("missing key", path=path, table=name, key=key)
            continue
        out[key] = _number(name, key, raw[key], key_spec, path)
    return out


def parse_config(data: Mapping[str, Any], path: str = "<config>") -> Config:
    """Validate an already-parsed TOML mapping."""
    for name in data:
        if name not in ("machine", "yarn") and name not in DAEMON_TABLES:
            raise ConfigError("unknown table", path=path, table=name)
    machine = _table(data, "machine", _MACHINE_KEYS, path, required=True)
    yarn = _table(data, "yarn", _YARN_KEYS, path, required=False)
    geometry = Machine(yarn_diameter=yarn.get("diameter", 0.0), **machine)
    tables = {k: v for k, v in data.items() if k in DAEMON_TABLES}
    return Config(machine=geometry, path=path, tables=tables)


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML configuration file."""
    text_path = str(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise ConfigError(f"cannot read: {exc.strerror}", path=text_path) from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML: {exc}", path=text_path) from exc
    return parse_config(data, text_path)
