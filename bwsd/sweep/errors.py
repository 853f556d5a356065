"""Errors of a sweep, by phase, and the optional libraries it needs (the ``sweep`` extra)."""

from __future__ import annotations

from bwsd.errors import BwsdError, ConfigError
from bwsd.extras import Library

DASK = Library("Dask (dask[distributed])", ("dask", "distributed"), "sweep")
PYARROW = Library("pyarrow", ("pyarrow",), "sweep")
MATPLOTLIB = Library("matplotlib", ("matplotlib",), "sweep")


class SpecError(ConfigError):
    """A sweep spec is malformed: names the file, table and key."""


class SweepError(BwsdError):
    """A sweep cannot start or go on (output, scheduler, a failed task): says what to do."""
