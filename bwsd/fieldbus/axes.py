"""The machine's axes and their numbering on the wire (pure).

One shift actuator per matrix row (moves that row's cases along x), one per column (along
y), then the weft inserter's angle and insert axes, then the take-up, then one shift
actuator per line segment the machine declares (moves only the cases on its cells), then
the inserter's positioning axes the machine has (``[machine] weft_axes``). Axis i is
numbered the same on every bus: rows 0..R-1, columns R..R+C-1, then ``weft_angle``,
``weft_insert``, ``takeup``, then the segments in the order of ``[machine] segments``
(``row3[0..3]``...), then ``weft_x``, ``weft_y``, ``weft_z`` (those present, in that order):
the axes added later come last, so no axis a loom already had changes its number.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from bwsd.twin.machine import Machine

AxisKind = Literal[
    "row", "col", "weft_angle", "weft_insert", "takeup", "weft_x", "weft_y", "weft_z"
]
# The axes that place the inserter before a weft goes in (absolute; no case rides on them)
POSITIONING: tuple[AxisKind, ...] = ("weft_x", "weft_y", "weft_z", "weft_angle")
UM_PER_MM = 1000  # lengths travel as integer micrometres
MDEG_PER_DEG = 1000  # angles travel as integer millidegrees


@dataclass(frozen=True)
class Axis:
    """One actuator: its wire index, name (``row3``, ``col0``, ``row3[0..3]``, ``takeup``...)
    and kind."""

    index: int
    name: str
    kind: AxisKind
    line: int | None = None  # the row or column a shift axis moves
    span: tuple[int, int] | None = None  # a segment's first and last cell; None: the whole line

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
    axes += [
        Axis(
            base + 3 + i,
            segment_axis_name(seg.axis, seg.line, (seg.lo, seg.hi)),
            seg.axis,
            seg.line,
            (seg.lo, seg.hi),
        )
        for i, seg in enumerate(machine.segments)
    ]
    kinds: dict[str, AxisKind] = {"x": "weft_x", "y": "weft_y", "z": "weft_z"}
    axes += [Axis(len(axes) + i, kinds[a], kinds[a]) for i, a in enumerate(machine.weft_axes)]
    return tuple(axes)


def segment_axis_name(kind: str, line: int, span: tuple[int, int]) -> str:
    """The axis name of a segment: ``row3[0..3]`` for ``ROW 3[0..3]``."""
    return f"{kind}{line}[{span[0]}..{span[1]}]"


def moved_cells(machine: Machine, axis: Axis) -> tuple[int, int]:
    """The first and last cell (along its line) whose cases a shift axis moves."""
    if axis.span is not None:
        return axis.span
    return 0, (machine.cols if axis.kind == "row" else machine.rows) - 1


def axis_by_name(machine: Machine, name: str) -> Axis:
    """The axis called ``name``; ValueError naming the known ones otherwise."""
    for axis in machine_axes(machine):
        if axis.name == name:
            return axis
    segments = ", ".join(segment_axis_name(s.axis, s.line, (s.lo, s.hi)) for s in machine.segments)
    raise ValueError(
        f"no axis {name!r} (rows 0..{machine.rows - 1}, cols 0..{machine.cols - 1}, "
        f"segments: {segments or 'none declared in [machine] segments'})"
    )


def shift_stroke_um(machine: Machine, axis: Axis, cells: int) -> int:
    """Stroke of a shift axis for ``cells`` cells, in micrometres (signed)."""
    pitch = machine.pitch_x if axis.kind == "row" else machine.pitch_y
    return round(cells * pitch * UM_PER_MM)
