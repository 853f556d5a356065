"""Execution of one instruction on the state: shifts, take-up and weft insertion."""

from __future__ import annotations

import math

from bwsd.errors import MoveError, ShedClosedError
from bwsd.twin.batch import Batch
from bwsd.twin.instructions import Instruction, Shift, TakeUp, Weft
from bwsd.twin.predicates import Vec
from bwsd.twin.state import State
from bwsd.twin.sweep import sweep


def execute(state: State, instruction: Instruction, index: int) -> dict[int, float]:
    """Run one instruction in place (logged).

    Returns the warps whose free node moved, each with its path length before the move.
    """
    if isinstance(instruction, Shift):
        return _shift(state, instruction, index)
    if isinstance(instruction, TakeUp):
        return _takeup(state, instruction, index)
    _weft(state, instruction, index)
    return {}


def path_length(state: State, warp: int) -> float:
    """A warp's path: its fixed polyline plus its free segment to the guide."""
    return state.yarn_len[warp] + math.dist(
        state.xyz(state.last_fixed[warp]), state.xyz(state.free_node[warp])
    )


def _plan_shift(state: State, instruction: Shift, index: int) -> list[tuple[int, tuple[int, int]]]:
    """Every case's move (warp, target cell) in execution order; refused before anything moves."""
    m = state.machine
    limit = m.rows if instruction.axis == "row" else m.cols
    occ = [row[:] for row in state.occupancy]
    plan = []
    for line, k in instruction.moves:
        if not 0 <= line < limit:
            raise MoveError(
                f"{instruction.axis.upper()} {line} is outside the matrix", instruction=index
            )
        if instruction.axis == "row":
            cases = [(occ[line][i], (line, i)) for i in range(m.cols) if occ[line][i] >= 0]
        else:
            cases = [(occ[i][line], (i, line)) for i in range(m.rows) if occ[i][line] >= 0]
        cases.sort(key=lambda case: case[1], reverse=k > 0)
        for warp, (row, col) in cases:
            target = (row, col + k) if instruction.axis == "row" else (row + k, col)
            _check_target(state, occ, warp, target, index)
            occ[row][col], occ[target[0]][target[1]] = -1, warp
            plan.append((warp, target))
    return plan


def _shift(state: State, instruction: Shift, index: int) -> dict[int, float]:
    m = state.machine
    z = m.d_mat + state.takeup
    plan = _plan_shift(state, instruction, index)
    targets = [(w, (*m.guide_xy(*cell), z)) for w, cell in plan]
    batch = Batch.plan(state, targets)
    before: dict[int, float] = {}
    for case, ((warp, cell), (_, a2)) in enumerate(zip(plan, targets, strict=True)):
        before.setdefault(warp, path_length(state, warp))
        state.place(warp, cell)
        sweep(state, warp, a2, index, batch, case)
    return before


def _check_target(
    state: State, occ: list[list[int]], warp: int, cell: tuple[int, int], index: int
) -> None:
    row, col = cell
    if not state.machine.inside(row, col):
        raise MoveError(
            f"case of yarn {warp} would leave the matrix at cell ({row}, {col})", instruction=index
        )
    other = occ[row][col]
    if other >= 0:
        raise MoveError(
            f"case of yarn {warp} would land on cell ({row}, {col}), occupied by yarn {other}",
            instruction=index,
        )


def _takeup(state: State, instruction: TakeUp, index: int) -> dict[int, float]:
    p = instruction.length
    state.set_takeup(state.takeup + p)
    targets = []
    for warp in range(state.n_warps):
        x, y, z = state.xyz(state.free_node[warp])
        targets.append((warp, (x + 0.0, y + 0.0, z + p)))
    batch = Batch.plan(state, targets)
    before: dict[int, float] = {}
    for case, (warp, a2) in enumerate(targets):
        before[warp] = path_length(state, warp)
        sweep(state, warp, a2, index, batch, case)
    return before


def segment_distance(p0: Vec, p1: Vec, q0: Vec, q1: Vec) -> float:
    """Shortest distance between segments p0-p1 and q0-q1 (closest points, clamped)."""
    u = (p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2])
    v = (q1[0] - q0[0], q1[1] - q0[1], q1[2] - q0[2])
    w = (p0[0] - q0[0], p0[1] - q0[1], p0[2] - q0[2])
    a = u[0] * u[0] + u[1] * u[1] + u[2] * u[2]
    b = u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
    c = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    d = u[0] * w[0] + u[1] * w[1] + u[2] * w[2]
    e = v[0] * w[0] + v[1] * w[1] + v[2] * w[2]
    den = a * c - b * b
    s = min(max((b * e - c * d) / den, 0.0), 1.0) if den > 1e-12 * a * c else 0.0
    t = min(max((b * s + e) / c, 0.0), 1.0) if c > 0 else 0.0
    s = min(max((b * t - d) / a, 0.0), 1.0) if a > 0 else 0.0
    gap = [w[i] + s * u[i] - t * v[i] for i in range(3)]
    return math.sqrt(gap[0] ** 2 + gap[1] ** 2 + gap[2] ** 2)


def _weft(state: State, instruction: Weft, index: int) -> None:
    d = state.diameter
    rad = math.radians(instruction.angle)
    ax, ay = math.cos(rad), math.sin(rad)
    half = instruction.length / 2
    cz = state.takeup + instruction.z
    p0 = (instruction.x - half * ax, instruction.y - half * ay, cz)
    p1 = (instruction.x + half * ax, instruction.y + half * ay, cz)
    lo = (min(p0[0], p1[0]) - d, min(p0[1], p1[1]) - d, cz - d)
    hi = (max(p0[0], p1[0]) + d, max(p0[1], p1[1]) + d, cz + d)
    segments = [
        (int(state.seg_yarn.data[s]), state.xyz(state.seg_c[s]), state.xyz(state.seg_d[s]))
        for s in state.fixed_near(lo, hi)
    ]
    segments += [
        (w, state.xyz(state.last_fixed[w]), state.xyz(state.free_node[w]))
        for w in state.free_near(lo, hi)
    ]
    closest: tuple[float, int] | None = None
    for yarn, c, e in segments:
        gap = segment_distance(p0, p1, c, e)
        if (gap < d or gap == 0) and (closest is None or gap < closest[0]):
            closest = (gap, yarn)
    if closest is not None:
        raise ShedClosedError(
            f"shed closed: the weft passes {closest[0]:.4g} mm from yarn {closest[1]}"
            f" (yarn diameter {d:g} mm)",
            instruction=index,
        )
    start = state.new_node(p0)
    end = state.new_node(p1)
    state.add_weft(start, end, instruction.angle)
