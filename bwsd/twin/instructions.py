"""The instructions the twin executes: the machine's own moves (docs/twin.md)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal, NamedTuple

Axis = Literal["row", "col"]
Span = tuple[int, int]  # the first and last cell of a line segment, along the line


class Move(NamedTuple):
    """One entry of a ROW or COL: line ``line`` shifts its cases by ``k`` cells.

    ``span`` None moves the whole line. A span ``(a, b)`` moves only the cases on cells
    a..b of the line (a separately actuated segment of it, declared by the machine), and
    none of them may leave those cells.
    """

    line: int
    k: int
    span: Span | None = None

    def text(self) -> str:
        """As written in a program: ``3:+1`` or ``3[0..3]:+1``."""
        where = "" if self.span is None else f"[{self.span[0]}..{self.span[1]}]"
        return f"{self.line}{where}:{self.k:+d}"


# What ``as_moves`` and ``Shift`` take for one entry: a Move, ``(line, k)``,
# ``(line, k, span)`` or ``(line, k, a, b)``.
MoveEntry = Move | tuple[int, int] | tuple[int, int, Span | None] | tuple[int, int, int, int]


def as_moves(entries: Iterable[MoveEntry]) -> tuple[Move, ...]:
    """Entries as Moves: ``(line, k)``, ``(line, k, span)`` or ``(line, k, a, b)``."""
    out = []
    for entry in entries:
        if isinstance(entry, Move):
            out.append(entry)
        elif len(entry) == 4:
            out.append(Move(entry[0], entry[1], (entry[2], entry[3])))
        else:
            out.append(Move(*entry))
    return tuple(out)


@dataclass(frozen=True, init=False)
class Shift:
    """ROW or COL: each listed line (or line segment) shifts its cases by k cells.

    For ``axis == "row"`` the cases move along x (their column changes); for ``"col"``
    along y (their row changes). Entries are resolved in the order written. ``moves`` may
    be given as plain ``(line, k)`` tuples; they are kept as :class:`Move`.
    """

    axis: Axis
    moves: tuple[Move, ...]

    def __init__(self, axis: Axis, moves: Iterable[MoveEntry]) -> None:
        object.__setattr__(self, "axis", axis)
        object.__setattr__(self, "moves", as_moves(moves))

    def text(self) -> str:
        """As written in a program: ``ROW 1:+1 3[0..3]:-1``."""
        return " ".join([self.axis.upper(), *(m.text() for m in self.moves)])


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

    def line_of(self, instruction: int) -> int:
        """The source line of instruction number ``instruction`` (1-based; 0: not known)."""
        return self.lines[instruction - 1] if 0 < instruction <= len(self.lines) else 0
