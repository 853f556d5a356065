"""The instructions the twin executes: the machine's own moves (docs/twin.md)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Axis = Literal["row", "col"]


@dataclass(frozen=True)
class Shift:
    """ROW or COL: each listed line (index, k) shifts all its cases by k cells.

    For ``axis == "row"`` the cases move along x (their column changes); for ``"col"``
    along y (their row changes). Entries are resolved in the order written.
    """

    axis: Axis
    moves: tuple[tuple[int, int], ...]


@dataclass(frozen=True)
class TakeUp:
    """TAKEUP p: advance the preform by p millimetres."""

    length: float


@dataclass(frozen=True)
class Weft:
    """WEFT: a straight weft centred at (x, y, T + z), direction (cos angle, sin angle, 0)."""

    x: float
    y: float
    z: float
    angle: float
    length: float


Instruction = Shift | TakeUp | Weft


@dataclass(frozen=True)
class Program:
    """A parsed program: optional yarn diameter, the filled cells and the instructions.

    ``fill`` lists the filled cells (row, col) in fill order (row by row, then column),
    which is also the order of the warp yarn ids. ``lines`` gives the source line of each
    instruction (the same line repeats when it sits inside a REPEAT). ``cycle_length`` is
    the number of instructions in one pass of the program's outermost REPEAT body (the
    machine cycle), None when the program has no REPEAT.
    """

    diameter: float | None
    fill: tuple[tuple[int, int], ...]
    instructions: tuple[Instruction, ...]
    lines: tuple[int, ...] = ()
    cycle_length: int | None = None
