"""Actuator buses: one async interface (``Fieldbus``), a backend per bus, chosen by config.

The config's ``[fieldbus] backend = "..."`` names the backend; its module is imported only
when it is used, so a missing bus library only matters to the bus that needs it. The
interface's names (bwsd.fieldbus.base, which needs numpy) are imported when first used, so
that `bwsd hw --help` stays light.
"""

from __future__ import annotations

import importlib
from contextlib import nullcontext
from functools import partial
from typing import TYPE_CHECKING, Any

from bwsd.config import Config
from bwsd.errors import ConfigError
from bwsd.extras import CANOPEN, needs

if TYPE_CHECKING:
    from bwsd.fieldbus.base import (
        AxisMove,
        BusSettings,
        DriveFault,
        EStopError,
        Fieldbus,
        FieldbusConnectionError,
        FieldbusError,
        FieldbusTimeout,
        MachineState,
    )

_BASE = (
    "AxisMove",
    "BusSettings",
    "DriveFault",
    "EStopError",
    "Fieldbus",
    "FieldbusConnectionError",
    "FieldbusError",
    "FieldbusTimeout",
    "MachineState",
)

BACKENDS = {
    "modbus": ("bwsd.fieldbus.modbus", "ModbusBus"),
    "canopen": ("bwsd.fieldbus.canopen", "CanopenBus"),
}
# The optional libraries a backend needs (the package's extras); Modbus is in the core.
BACKEND_LIBRARIES = {"canopen": CANOPEN}

__all__ = [
    "BACKENDS",
    "BACKEND_LIBRARIES",
    "AxisMove",
    "BusSettings",
    "DriveFault",
    "EStopError",
    "Fieldbus",
    "FieldbusConnectionError",
    "FieldbusError",
    "FieldbusTimeout",
    "MachineState",
    "open_bus",
    "settings_from_config",
]


def __getattr__(name: str) -> Any:
    if name not in _BASE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module("bwsd.fieldbus.base"), name)
    globals()[name] = value  # found once
    return value


def settings_from_config(config: Config) -> BusSettings:
    """The shared bus settings of the ``[fieldbus]`` table."""
    from bwsd.fieldbus.base import BusSettings

    table = config.table("fieldbus")
    return BusSettings(**{k: table[k] for k in BusSettings.__dataclass_fields__})


def open_bus(config: Config) -> Fieldbus:
    """The backend the config names, built from its tables (not yet connected)."""
    name = config.table("fieldbus")["backend"]
    try:
        module_name, class_name = BACKENDS[name]
    except KeyError:
        raise ConfigError(
            f"unknown backend {name!r}", path=config.path, table="fieldbus", key="backend"
        ) from None
    library = BACKEND_LIBRARIES.get(name)
    missing = partial(ConfigError, path=config.path, table="fieldbus", key="backend")
    try:
        with needs(library, f"backend {name!r}", missing) if library else nullcontext():
            module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ConfigError(
            f"backend {name!r} cannot be loaded: {exc}",
            path=config.path,
            table="fieldbus",
            key="backend",
        ) from exc
    bus: Fieldbus = getattr(module, class_name).from_config(config)
    return bus
