"""Plain weave of one warp layer and dual-direction 3D weave of a warp matrix (also U section)."""

from __future__ import annotations

import math

from bwsd.program import render
from bwsd.program.render import Cell, Generated
from bwsd.twin.machine import Machine

# Wefts go in at this fraction of d_mat above the fell: near the guides, where the warps
# opened by a shed have drifted furthest from the previous weft.
WEFT_LEVEL = 0.9
# The predicted clearance must exceed the yarn diameter by this factor.
CLEARANCE_MARGIN = 1.25
SHAPES = ("rect", "U")


def shed_clearance(machine: Machine, takeup: float, z: float, span: float) -> float:
    """Predicted smallest distance (centre lines, mm) between a new weft and an opened warp.

    A warp rests on the previous weft, ``takeup`` below the new one, at most one diameter
    on the wrong side; opening the shed moves its guide one pitch, and the weft sees the
    warp where the line from that rest to the guide crosses its height. On the first
    picks the warps also still lean towards the convergence point by up to
    (1 - fan) * ``span``, span the largest guide offset from it along the shed.
    """
    d = machine.yarn_diameter
    p = min(machine.pitch_x, machine.pitch_y)
    length = machine.d_mat - z + takeup
    reach = p + d
    tilt = length / math.hypot(length, reach)
    steady = (reach * takeup / length - d) * tilt
    fan = machine.c_mat + (1 - machine.c_mat) * z / machine.d_mat
    drift = (1 - fan) * (1 - takeup / length) * span
    early = (p * takeup / length - drift) * tilt
    return min(steady, early)


def _check_shed(machine: Machine, takeup: float, z: float, span: float) -> None:
    if takeup <= 0:
        raise ValueError("take-up must be positive")
    clearance = shed_clearance(machine, takeup, z, span)
    need = CLEARANCE_MARGIN * machine.yarn_diameter
    if clearance <= need:
        raise ValueError(
            f"the shed would not clear the weft (predicted {clearance:.2f} mm, need more"
            f" than {need:.2f} mm): raise the take-up or the pitch"
        )


def _pick(axis: str, moves: list[tuple[int, int]], wefts: list[str], takeup: float) -> list[str]:
    """Open a shed, insert its wefts, close the shed, take up."""
    closing = [(i, -k) for i, k in moves]
    return [
        render.shift(axis, moves),
        *wefts,
        render.shift(axis, closing),
        f"TAKEUP {render.num(takeup)}",
    ]


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
    machine = Machine(3, warps, pitch, pitch, d_mat, c_mat, diameter)
    z = WEFT_LEVEL * d_mat
    _check_shed(machine, takeup, z, 0.0)
    line = render.weft((warps - 1) / 2 * pitch, pitch, z, 0, (warps + 1) * pitch)
    body: list[str] = []
    for sign in (1, -1):
        moves = [(c, sign if c % 2 == 0 else -sign) for c in range(warps)]
        body += _pick("col", moves, [line], takeup)
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
        *render.fill_block(3, warps, [(1, c) for c in range(warps)]),
        *render.repeat(cycles, body, "even columns up, weft, close; then down"),
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


def _wefts(grid: frozenset[Cell], axis: int, z: float, pitch: float) -> list[str]:
    """One weft per run of warps of each grid row (axis 0, along x) or column (axis 1)."""
    members: dict[int, list[int]] = {}
    for cell in grid:
        members.setdefault(cell[axis], []).append(cell[1 - axis])
    out = []
    for line in sorted(members):
        for lo, hi in render.runs(members[line]):
            across = (lo + hi + 1) * pitch
            level = (2 * line + 1) * pitch
            length = (2 * (hi - lo) + 2) * pitch
            x, y = (across, level) if axis == 0 else (level, across)
            out.append(render.weft(x, y, z, 90 * axis, length))
    return out


def _cycle_3d(grid: frozenset[Cell], z: float, pitch: float, takeup: float) -> list[str]:
    rows = sorted({i for i, _ in grid})
    cols = sorted({j for _, j in grid})
    x_wefts, y_wefts = _wefts(grid, 0, z, pitch), _wefts(grid, 1, z, pitch)
    body: list[str] = []
    for sign in (1, -1):
        col_moves = [(2 * j + 1, sign if j % 2 == 0 else -sign) for j in cols]
        row_moves = [(2 * i + 1, sign if i % 2 == 0 else -sign) for i in rows]
        body += _pick("col", col_moves, x_wefts, takeup)
        body += _pick("row", row_moves, y_wefts, takeup)
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
    grid = warp_cells(shape, layers, warps, leg, base)
    machine = Machine(2 * layers + 1, 2 * warps + 1, pitch, pitch, d_mat, c_mat, diameter)
    z = WEFT_LEVEL * d_mat
    _check_shed(machine, takeup, z, (max(layers, warps) - 1) * pitch)
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
    cells = [(2 * i + 1, 2 * j + 1) for i, j in grid]
    lines = [
        *render.header(title, command, machine),
        *render.fill_block(machine.rows, machine.cols, cells),
        *render.repeat(
            cycles,
            _cycle_3d(grid, z, pitch, takeup),
            "column shed + wefts along x, row shed + wefts along y, twice",
        ),
    ]
    return Generated("weave-3d", title, command, machine, "\n".join(lines) + "\n")
