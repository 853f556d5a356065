"""Execution of one instruction on the state: shifts, take-up and weft insertion."""

from __future__ import annotations

import math

import numpy as np

from bwsd.errors import MoveError, ShedClosedError
from bwsd.twin.instructions import Instruction, Shift, TakeUp, Weft
from bwsd.twin.predicates import FloatArray
from bwsd.twin.state import State
from bwsd.twin.sweep import sweep


def execute(state: State, instruction: Instruction, index: int) -> list[int]:
    """Run one instruction in place (logged); returns the yarns whose free node moved."""
    if isinstance(instruction, Shift):
        return _shift(state, instruction, index)
    if isinstance(instruction, TakeUp):
        return _takeup(state, instruction, index)
    _weft(state, instruction, index)
    return []


def shift_order(state: State, instruction: Shift, entry: int) -> list[tuple[int, tuple[int, int]]]:
    """The cases of one entry of a shift, leading case first, with their target cells."""
    line, k = instruction.moves[entry]
    m = state.machine
    limit = m.rows if instruction.axis == "row" else m.cols
    if not 0 <= line < limit:
        raise MoveError(f"{instruction.axis.upper()} {line} is outside the matrix", instruction=0)
    occ = state.occupancy[line, :] if instruction.axis == "row" else state.occupancy[:, line]
    cells = [i for i in range(len(occ)) if occ[i] >= 0]
    cells.sort(reverse=k > 0)
    out = []
    for i in cells:
        target = (line, i + k) if instruction.axis == "row" else (i + k, line)
        out.append((int(occ[i]), target))
    return out


def _shift(state: State, instruction: Shift, index: int) -> list[int]:
    m = state.machine
    z = m.d_mat + state.takeup
    moved: list[int] = []
    for entry in range(len(instruction.moves)):
        try:
            order = shift_order(state, instruction, entry)
        except MoveError as exc:
            raise MoveError(exc.reason, instruction=index) from None
        for warp, (row, col) in order:
            if not m.inside(row, col):
                raise MoveError(
                    f"case of yarn {warp} would leave the matrix at cell ({row}, {col})",
                    instruction=index,
                )
            if state.occupancy[row, col] >= 0:
                other = int(state.occupancy[row, col])
                raise MoveError(
                    f"case of yarn {warp} would land on cell ({row}, {col}), occupied by yarn "
                    f"{other}",
                    instruction=index,
                )
            state.place(warp, (row, col))
            gx, gy = m.guide_xy(row, col)
            sweep(state, warp, np.array((gx, gy, z)), index)
            moved.append(warp)
    return moved


def _takeup(state: State, instruction: TakeUp, index: int) -> list[int]:
    step = np.array((0.0, 0.0, instruction.length))
    state.set_takeup(state.takeup + instruction.length)
    for warp in range(state.n_warps):
        free = int(state.free_node.data[warp])
        sweep(state, warp, state.pos.data[free] + step, index)
    return list(range(state.n_warps))


def segment_distances(p0: FloatArray, p1: FloatArray, q0: FloatArray, q1: FloatArray) -> FloatArray:
    """Distances between segment p0-p1 and each segment q0[i]-q1[i] (closest points, clamped)."""
    u = p1 - p0
    v = q1 - q0
    w = p0 - q0
    a = float(u @ u)
    b = v @ u
    c = np.einsum("ij,ij->i", v, v)
    d = w @ u
    e = np.einsum("ij,ij->i", v, w)
    den = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(den > 1e-12 * a * c, (b * e - c * d) / den, 0.0)
    s = np.clip(s, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(c > 0, (b * s + e) / c, 0.0)
    t = np.clip(t, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(a > 0, np.clip((b * t - d) / a, 0.0, 1.0), 0.0)
    gap = w + s[:, None] * u - t[:, None] * v
    result: FloatArray = np.sqrt(np.einsum("ij,ij->i", gap, gap))
    return result


def _weft(state: State, instruction: Weft, index: int) -> None:
    d = state.diameter
    rad = math.radians(instruction.angle)
    axis = np.array((math.cos(rad), math.sin(rad), 0.0))
    centre = np.array((instruction.x, instruction.y, state.takeup + instruction.z))
    p0 = centre - instruction.length / 2 * axis
    p1 = centre + instruction.length / 2 * axis
    reach = np.full(3, d)
    lo, hi = np.minimum(p0, p1) - reach, np.maximum(p0, p1) + reach
    pos = state.pos.data
    fixed = state.segments_near(lo, hi)
    warps = np.arange(state.n_warps)
    q0 = np.concatenate((pos[state.seg_c.data[fixed]], pos[state.last_fixed.data[warps]]))
    q1 = np.concatenate((pos[state.seg_d.data[fixed]], pos[state.free_node.data[warps]]))
    yarns = np.concatenate((state.seg_yarn.data[fixed], warps))
    if len(yarns):
        gaps = segment_distances(p0, p1, q0, q1)
        closed = np.nonzero((gaps < d) | (gaps == 0))[0]
        if closed.size:
            i = int(closed[np.argmin(gaps[closed])])
            raise ShedClosedError(
                f"shed closed: the weft passes {float(gaps[i]):.4g} mm from yarn {int(yarns[i])}"
                f" (yarn diameter {d:g} mm)",
                instruction=index,
            )
    start = state.new_node(p0)
    end = state.new_node(p1)
    state.add_weft(start, end, instruction.angle)
