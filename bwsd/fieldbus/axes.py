"""The machine's axes and their numbering on the wire (pure).

One shift actuator per matrix row (moves that row's cases along x), one per column (along
y), then the weft inserter's angle and insert axes, then the take-up. Axis i is numbered
the same on every bus: rows 0..R-1, columns R..R+C-1, then ``weft_angle``, ``weft_insert``,
``takeup``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from bwsd.twin.machine import Machine

AxisKind = Literal["row", "col", "weft_angle", "weft_insert", "takeup"]
UM_PER_MM = 1000  # lengths travel as integer micrometres
MDEG_PER_DEG = 1000  # angles travel as integer millidegrees


@dataclass(frozen=True)
class Axis:
    """One actuator: its wire index, name (``row3``, ``col0``, ``takeup``...) and kind."""

    index: int
    name: str
    kind: AxisKind
    line: int | None = None  # the row or column a shift axis moves

    @property
    def relative(self) -> bool:
        """Shift and insert strokes are relative and end back home; the others are absolute."""
        return self.kind in ("row", "col", "weft_insert")


def machine_axes(machine: Machine) -> tuple[Axis, ...]:
    """Every axis of ``machine`` in wire order."""
    axes = [Axis(r, f"row{r}", "row", r) for r in range(machine.rows)]
    axes += [Axis(machine.rows + c, f"col{c}", "col", c) for c in range(machine.cols)]
    base = machine.rows + machine.cols
    axes += [
        Axis(base, "weft_angle", "weft_angle"),
        Axis(base + 1, "weft_insert", "weft_insert"),
        Axis(base + 2, "takeup", "takeup"),
    ]
    return tuple(axes)


def axis_by_name(machine: Machine, name: str) -> Axis:
    """The axis called ``name``; ValueError naming the known ones otherwise."""
    for axis in machine_axes(machine):
        if axis.name == name:
            return axis
    raise ValueError(f"no axis {name!r} (rows 0..{machine.rows - 1}, cols 0..{machine.cols - 1})")


def shift_stroke_um(machine: Machine, axis: Axis, cells: int) -> int:
    """Stroke of a shift axis for ``cells`` cells, in micrometres (signed)."""
    pitch = machine.pitch_x if axis.kind == "row" else machine.pitch_y
    return round(cells * pitch * UM_PER_MM)
