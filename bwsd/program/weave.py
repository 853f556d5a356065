"""Plain weave of one warp layer and dual-direction 3D weave of a warp matrix (also U section)."""

from __future__ import annotations

from bwsd.program import render
from bwsd.program.render import Cell, Generated
from bwsd.program.sections import WEAVE_SHAPES
from bwsd.program.wefts import Item, Shed, woven
from bwsd.twin.instructions import Axis, Shift, TakeUp, as_moves
from bwsd.twin.machine import Machine

SHAPES = WEAVE_SHAPES
CYCLE_3D = "column shed + wefts along x, row shed + wefts along y, twice"


def _pick(axis: Axis, moves: list[tuple[int, int]], wefts: list[Shed], takeup: float) -> list[Item]:
    """Open a shed, insert its wefts (each placed near the fell), close the shed, take up."""
    closing = [(i, -k) for i, k in moves]
    return [Shift(axis, as_moves(moves)), *wefts, Shift(axis, as_moves(closing)), TakeUp(takeup)]


def weave_plain(
    warps: int = 10,
    cycles: int = 10,
    *,
    takeup: float = 4.0,
    pitch: float = 10.0,
    d_mat: float = 100.0,
    c_mat: float = 0.5,
    diameter: float = 1.0,
) -> Generated:
    """Plain weave: one layer of warps in row 1 of a 3-row matrix, two picks per cycle."""
    if warps < 2 or cycles < 1:
        raise ValueError("a plain weave needs at least 2 warps and 1 cycle")
    if takeup <= 0:
        raise ValueError("take-up must be positive")
    machine = Machine(3, warps, pitch, pitch, d_mat, c_mat, diameter)
    cycle: list[Item] = []
    for sign, name in ((1, "first pick"), (-1, "second pick")):
        moves = [(c, sign if c % 2 == 0 else -sign) for c in range(warps)]
        sides = [tuple((1 + k, c) for c, k in moves if k == way) for way in (1, -1)]
        cycle += _pick(
            "col", moves, [Shed(0, sides[0], sides[1], f"the weft of the {name}")], takeup
        )
    fill = tuple((1, c) for c in range(warps))
    command = " ".join(
        [
            "bwsd program weave-plain",
            render.option("warps", warps),
            render.option("cycles", cycles),
            render.option("takeup", takeup),
            *render.machine_options(machine),
        ]
    )
    title = f"Plain weave, {warps} warps, {cycles} cycles of two picks"
    lines = [
        *render.header(title, command, machine),
        *render.fill_block(3, warps, fill),
        *woven(machine, fill, [cycle] * cycles, "even columns up, weft, close; then down"),
    ]
    return Generated("weave-plain", title, command, machine, "\n".join(lines) + "\n")


def warp_cells(
    shape: str,
    layers: int,
    warps: int,
    leg: int = 2,
    base: int = 2,
) -> frozenset[Cell]:
    """The warp grid (layer, warp) of a 3D weave: a full rectangle or a U.

    The U's legs are the ``leg`` outermost warp columns on each side over every layer, its
    base the ``base`` last layers over every column; the opening is between the legs.
    """
    # Every weft must pass at least two warps, so that one of them crosses it whichever
    # way the shed opened (a lone warp may close without touching its weft).
    if layers < 2 or warps < 2:
        raise ValueError("layers and warps must be at least 2")
    full = frozenset((i, j) for i in range(layers) for j in range(warps))
    if shape == "rect":
        return full
    if shape != "U":
        raise ValueError(f"unknown shape {shape!r} (known: {', '.join(SHAPES)})")
    if leg < 2 or base < 2 or 2 * leg >= warps or base >= layers:
        raise ValueError("a U needs 2 <= leg < warps / 2 and 2 <= base < layers")
    return frozenset((i, j) for i, j in full if j < leg or j >= warps - leg or i >= layers - base)


def _wefts(grid: frozenset[Cell], axis: int, signs: dict[int, int]) -> list[Shed]:
    """One weft per run of warps of each grid row (axis 0, along x) or column (axis 1),
    between the warps the shed moved one way and those it moved the other (``signs``: the
    shift of each warp column for axis 0, of each warp row for axis 1)."""
    members: dict[int, list[int]] = {}
    for cell in grid:
        members.setdefault(cell[axis], []).append(cell[1 - axis])
    out = []
    for line in sorted(members):
        for lo, hi in render.runs(members[line]):
            sides: list[list[Cell]] = [[], []]
            for j in range(lo, hi + 1):
                k = signs[j]
                warp = (2 * line + 1 + k, 2 * j + 1) if axis == 0 else (2 * j + 1, 2 * line + 1 + k)
                sides[k > 0].append(warp)
            name = f"{'layer' if axis == 0 else 'column'} {line} weft (warps {lo}..{hi})"
            out.append(Shed(90 * axis, tuple(sides[0]), tuple(sides[1]), name))
    return out


def _cycle_3d(grid: frozenset[Cell], takeup: float) -> list[Item]:
    rows = sorted({i for i, _ in grid})
    cols = sorted({j for _, j in grid})
    body: list[Item] = []
    for sign in (1, -1):
        col_signs = {j: sign if j % 2 == 0 else -sign for j in cols}
        row_signs = {i: sign if i % 2 == 0 else -sign for i in rows}
        col_moves = [(2 * j + 1, k) for j, k in col_signs.items()]
        row_moves = [(2 * i + 1, k) for i, k in row_signs.items()]
        body += _pick("col", col_moves, _wefts(grid, 0, col_signs), takeup)
        body += _pick("row", row_moves, _wefts(grid, 1, row_signs), takeup)
    return body


def weave_3d(
    layers: int = 3,
    warps: int = 5,
    cycles: int = 10,
    *,
    shape: str = "rect",
    leg: int = 2,
    base: int = 2,
    takeup: float = 5.0,
    pitch: float = 10.0,
    d_mat: float = 100.0,
    c_mat: float = 0.6,
    diameter: float = 1.0,
) -> Generated:
    """Dual-direction shedding of a layers x warps grid (or U) of warps, four picks a cycle.

    Warp (i, j) sits in cell (2i + 1, 2j + 1), so that every grid line has an empty line
    on each side: alternate warp columns shed along y and leave the rows between layers
    open for wefts along x, then alternate warp rows shed along x for wefts along y.
    """
    if cycles < 1:
        raise ValueError("cycles must be at least 1")
    if takeup <= 0:
        raise ValueError("take-up must be positive")
    grid = warp_cells(shape, layers, warps, leg, base)
    machine = Machine(2 * layers + 1, 2 * warps + 1, pitch, pitch, d_mat, c_mat, diameter)
    what = [render.option("layers", layers), render.option("warps", warps)]
    if shape == "U":
        what += [
            render.option("shape", "U"),
            render.option("leg", leg),
            render.option("base", base),
        ]
    command = " ".join(
        [
            "bwsd program weave-3d",
            *what,
            render.option("cycles", cycles),
            render.option("takeup", takeup),
            *render.machine_options(machine),
        ]
    )
    title = (
        f"Dual-direction 3D weave, {'U section of ' if shape == 'U' else ''}"
        f"{layers} layers x {warps} warps ({len(grid)} warps), {cycles} cycles"
    )
    fill = tuple(sorted((2 * i + 1, 2 * j + 1) for i, j in grid))
    lines = [
        *render.header(title, command, machine),
        *render.fill_block(machine.rows, machine.cols, fill),
        *woven(machine, fill, [_cycle_3d(grid, takeup)] * cycles, CYCLE_3D),
    ]
    return Generated("weave-3d", title, command, machine, "\n".join(lines) + "\n")
