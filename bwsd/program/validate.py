"""Dry run of a program on the occupancy grid alone: impossible moves are refused up front."""

from __future__ import annotations

from pathlib import Path

from bwsd.errors import ProgramError
from bwsd.program.parser import MAX_INSTRUCTIONS, SourceMap, parse_program_with_positions
from bwsd.twin.instructions import Program, Shift, Span, Weft
from bwsd.twin.machine import Machine, unknown_segment, weft_off_fixed

Cell = tuple[int, int]


class Occupancy:
    """Which cells hold a case: the machine's matrix without any geometry."""

    def __init__(self, machine: Machine) -> None:
        self.rows = machine.rows
        self.cols = machine.cols
        self.cells: set[Cell] = set()

    def inside(self, cell: Cell) -> bool:
        """True when ``cell`` lies in the matrix."""
        return 0 <= cell[0] < self.rows and 0 <= cell[1] < self.cols

    def fill(self, cell: Cell) -> str | None:
        """Put a case into ``cell``; returns the reason when that is impossible."""
        if not self.inside(cell):
            return f"fill cell {cell} is outside the {self.rows} x {self.cols} matrix"
        if cell in self.cells:
            return f"cell {cell} is filled twice"
        self.cells.add(cell)
        return None

    def move(self, src: Cell, dst: Cell) -> str | None:
        """Move the case in ``src`` to ``dst``; returns the reason when that is impossible."""
        if not self.inside(dst):
            return f"the case in {src} would leave the matrix (to {dst})"
        if dst in self.cells:
            return f"the case in {src} would land on the occupied cell {dst}"
        self.cells.remove(src)
        self.cells.add(dst)
        return None

    def line_size(self, axis: str) -> int:
        """How many lines of ``axis`` the matrix has."""
        return self.rows if axis == "row" else self.cols

    def shift(self, axis: str, index: int, k: int, span: Span | None = None) -> str | None:
        """Shift every case of one line (or of its cells ``span``) by k cells, the leading
        case first (docs/twin.md); a case of a span must stay on it."""
        along = self.cols if axis == "row" else self.rows
        lo, hi = span if span is not None else (0, along - 1)
        if axis == "row":
            line = [(index, c) for c in range(lo, hi + 1)]
            step = (0, k)
        else:
            line = [(r, index) for r in range(lo, hi + 1)]
            step = (k, 0)
        cases = [cell for cell in line if cell in self.cells]
        for src in reversed(cases) if k > 0 else cases:
            dst = (src[0] + step[0], src[1] + step[1])
            if (
                span is not None
                and self.inside(dst)
                and not lo <= dst[1 if axis == "row" else 0] <= hi
            ):
                return (
                    f"the case in {src} would leave the segment {axis.upper()} "
                    f"{index}[{lo}..{hi}] (to {dst})"
                )
            reason = self.move(src, dst)
            if reason is not None:
                return reason
        return None


def _fail(
    message: str,
    program: Program,
    positions: SourceMap | None,
    source: str,
    index: int,
    entry: int | None,
) -> ProgramError:
    """A ProgramError for instruction ``index`` (0-based), at its entry ``entry`` if known."""
    line = program.lines[index] if index < len(program.lines) else 0
    column = 0
    if positions is not None and index < len(positions.keywords):
        column = positions.keywords[index]
        if entry is not None and entry < len(positions.entries[index]):
            column = positions.entries[index][entry]
    return ProgramError(
        f"instruction {index + 1}: {message}", line=line, column=column, source=source
    )


def _too_small(fill: tuple[Cell, ...], cell: Cell, grid: Occupancy) -> str:
    """Why a fill does not fit: the first cell outside, and the matrix the fill needs."""
    rows = max(r for r, _ in fill) + 1
    cols = max(c for _, c in fill) + 1
    return (
        f"fill cell {cell} is outside the {grid.rows} x {grid.cols} matrix: the program "
        f"fills cells up to row {rows - 1}, column {cols - 1}, so it needs a matrix of "
        f"at least {rows} x {cols}; this loom has {grid.rows} x {grid.cols}"
    )


def _check_fill(
    program: Program, grid: Occupancy, positions: SourceMap | None, source: str
) -> None:
    for i, cell in enumerate(program.fill):
        reason = grid.fill(cell)
        if reason is not None:
            if not grid.inside(cell):
                reason = _too_small(program.fill, cell, grid)
            line, column = positions.fill[i] if positions is not None else (0, 0)
            raise ProgramError(reason, line=line, column=column, source=source)


def _check_diameter(
    program: Program, machine: Machine, positions: SourceMap | None, source: str
) -> None:
    """A YARN diameter the machine cannot hold is refused at the YARN statement."""
    fault = None if program.diameter is None else machine.diameter_fault(program.diameter)
    if fault is not None:
        line, column = positions.diameter if positions is not None else (0, 0)
        raise ProgramError(fault, line=line, column=column, source=source)


def _check_shift(shift: Shift, grid: Occupancy, machine: Machine) -> tuple[int, str] | None:
    """Apply one ROW/COL to the grid; returns (entry, reason) of the first fault."""
    size = grid.line_size(shift.axis)
    for entry, (index, k, span) in enumerate(shift.moves):
        if not 0 <= index < size:
            lines = "rows" if shift.axis == "row" else "columns"
            return entry, (
                f"{shift.axis} {index} is outside the matrix (0 to {size - 1}): the "
                f"program needs at least {index + 1} {lines}; this loom has "
                f"{size}"
            )
        if span is not None and machine.segment(shift.axis, index, span) is None:
            return entry, unknown_segment(machine, shift.axis, index, span)
        reason = grid.shift(shift.axis, index, k, span)
        if reason is not None:
            return entry, reason
    return None


def validate(
    program: Program,
    machine: Machine,
    source: str = "<program>",
    positions: SourceMap | None = None,
) -> None:
    """Refuse a program whose fill or moves are impossible on ``machine``.

    Runs the fill and every ROW/COL on the occupancy grid only (no geometry), and refuses a
    WEFT off the inserter's fixed position along a coordinate the machine has no axis for.
    Errors name the line (from ``program.lines``) and, when ``positions`` is given, the column.
    """
    _check_diameter(program, machine, positions, source)
    grid = Occupancy(machine)
    _check_fill(program, grid, positions, source)
    for i, instruction in enumerate(program.instructions):
        if isinstance(instruction, Shift):
            fault = _check_shift(instruction, grid, machine)
            if fault is not None:
                raise _fail(fault[1], program, positions, source, i, fault[0])
        elif isinstance(instruction, Weft):
            off = weft_off_fixed(machine, instruction.x, instruction.y, instruction.z)
            if off is not None:
                raise _fail(off, program, positions, source, i, None)


def load_program(path: str | Path, machine: Machine, most: int = MAX_INSTRUCTIONS) -> Program:
    """Read, parse and validate a .bws file (``example:NAME``: a shipped one) for ``machine``
    (at most ``most`` instructions)."""
    from bwsd.shipped import resolve

    path = resolve(path)
    name = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ProgramError(f"cannot read: {exc.strerror}", source=name) from exc
    except UnicodeDecodeError as exc:
        raise ProgramError(f"not UTF-8 text: {exc.reason}", source=name) from exc
    program, positions = parse_program_with_positions(text, name, most)
    validate(program, machine, name, positions)
    return program
