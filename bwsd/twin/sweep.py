"""The sweep of one free node (TWIN.md, "The sweep"), vectorised over candidate segments.

Decisions (which segment is hit, and in which order) use exact signs from
``bwsd.twin.predicates``; constructions (the new nodes' coordinates) are float64, computed by
fixed formulas, and snap to the exact value where a decision says a quantity is exactly zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np

from bwsd.errors import TwinError
from bwsd.twin.predicates import FloatArray, edge_signs, exact_orient, side_signs
from bwsd.twin.state import State

MAX_CONTACTS_PER_SWEEP = 100_000
PARALLEL = 1e-12  # |component of the move across the hit segment| / |move| treated as zero


@dataclass
class Hit:
    """The first contact of a sweep step."""

    t: float
    yarn: int
    seg: int  # fixed segment id, or -(warp + 1) for a warp's free segment
    c: FloatArray
    d: FloatArray
    point: FloatArray


@dataclass
class Candidates:
    """Segments that may be hit: endpoints, yarn, and segment reference."""

    c: FloatArray
    d: FloatArray
    yarn: np.ndarray[Any, Any]
    ref: np.ndarray[Any, Any]


def _gather(state: State, w: int, lo: FloatArray, hi: FloatArray, skip: tuple[int, ...],
            skip_warp: int) -> Candidates:
    pos = state.pos.data
    fixed = state.segments_near(lo, hi)
    if skip:
        fixed = fixed[~np.isin(fixed, skip)]
    fixed = fixed[state.seg_yarn.data[fixed] != w]
    warps = np.arange(state.n_warps)
    keep = warps != w
    if skip_warp >= 0:
        keep &= warps != skip_warp
    warps = warps[keep]
    c = np.concatenate((pos[state.seg_c.data[fixed]], pos[state.last_fixed.data[warps]]))
    d = np.concatenate((pos[state.seg_d.data[fixed]], pos[state.free_node.data[warps]]))
    yarn = np.concatenate((state.seg_yarn.data[fixed], warps))
    ref = np.concatenate((fixed, -(warps + 1)))
    box = np.all(np.maximum(c, d) >= lo, axis=1) & np.all(np.minimum(c, d) <= hi, axis=1)
    return Candidates(c[box], d[box], yarn[box], ref[box])


def first_contact(state: State, w: int, b: FloatArray, a1: FloatArray, a2: FloatArray,
                  skip: tuple[int, ...], skip_warp: int) -> Hit | None:
    """The contact with the smallest sweep time of triangle (b, a1, a2), or None."""
    lo = np.minimum(np.minimum(b, a1), a2)
    hi = np.maximum(np.maximum(b, a1), a2)
    cand = _gather(state, w, lo, hi, skip, skip_warp)
    n = len(cand.yarn)
    if n == 0:
        return None
    o, s, _ = side_signs(b, a1, a2, np.concatenate((cand.c, cand.d)))
    oc, od, sc, sd = o[:n], o[n:], s[:n], s[n:]
    cross = np.nonzero((sc >= 0) != (sd >= 0))[0]
    if cross.size == 0:
        return None
    c, d = cand.c[cross], cand.d[cross]
    vb, sb, _ = edge_signs(c, d, a1, a2)
    v1, s1, e1 = edge_signs(c, d, a2, b)
    v2, s2, e2 = edge_signs(c, d, b, a1)
    ok = (sb != 0) & (s2 == sb) & ((s1 == 0) | (s1 == sb))
    idx = np.nonzero(ok)[0]
    if idx.size == 0:
        return None
    best = _earliest(idx, v1, v2, s1, e1, e2, c, d, b, a1, a2, cand.yarn[cross], cand.ref[cross],
                     state)
    i = int(cross[best])
    t = 1.0 if s1[best] == 0 else float(v2[best] / (v1[best] + v2[best]))
    point = _crossing(cand.c[i], cand.d[i], float(oc[i]), float(od[i]), int(sc[i]), int(sd[i]))
    return Hit(t, int(cand.yarn[i]), int(cand.ref[i]), cand.c[i], cand.d[i], point)


def _crossing(c: FloatArray, d: FloatArray, oc: float, od: float, sc: int, sd: int) -> FloatArray:
    """Where segment c-d meets the plane; exactly an endpoint when that endpoint lies on it."""
    if sc == 0:
        return c.copy()
    if sd == 0:
        return d.copy()
    result: FloatArray = c + (oc / (oc - od)) * (d - c)
    return result


def _earliest(idx: np.ndarray[Any, Any], v1: FloatArray, v2: FloatArray, s1: Any,
              e1: FloatArray, e2: FloatArray, c: FloatArray, d: FloatArray, b: FloatArray,
              a1: FloatArray, a2: FloatArray, yarn: np.ndarray[Any, Any],
              ref: np.ndarray[Any, Any], state: State) -> int:
    """Index (into the crossing arrays) of the hit with the smallest exact t, ties broken."""
    if idx.size == 1:
        return int(idx[0])
    x, y = np.abs(v2[idx]), np.abs(v1[idx])
    ex, ey = e2[idx], e1[idx]
    exact_one = s1[idx] == 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(exact_one, 1.0, x / (x + y))
        slack = np.where(exact_one, 0.0, (ex + ey) / np.maximum(x + y - ex - ey, 0.0))
    slack = np.nan_to_num(slack, nan=np.inf) + 4e-16
    lo, hi = t - slack, t + slack
    near = idx[lo <= hi.min()]
    if near.size == 1:
        return int(near[0])
    keys = [(_exact_t(c[i], d[i], b, a1, a2), int(yarn[i]), _seg_rank(state, int(ref[i])), int(i))
            for i in near.tolist()]
    return min(keys)[3]


def _exact_t(c: FloatArray, d: FloatArray, b: FloatArray, a1: FloatArray,
             a2: FloatArray) -> Fraction:
    w1 = exact_orient(c, d, a2, b)
    w2 = exact_orient(c, d, b, a1)
    return w2 / (w1 + w2)


def _seg_rank(state: State, ref: int) -> int:
    """Position of a segment along its yarn (0 = the segment at the yarn's start)."""
    if ref < 0:
        return len(state.yarns[-ref - 1]) - 2
    seg_start = int(state.seg_c.data[ref])
    return state.yarns[int(state.seg_yarn.data[ref])].index(seg_start)


def index_from_end(nodes: Any, node: int) -> int:
    """Position of node in a yarn's node list, searched from the free end (where work happens)."""
    for i in range(len(nodes) - 1, -1, -1):
        if nodes[i] == node:
            return i
    raise ValueError(node)


def split_hit(state: State, hit: Hit) -> tuple[int, tuple[int, ...], int]:
    """Insert Y into the hit yarn; returns Y and what this sweep skips next (segments, warp)."""
    y = state.new_node(hit.point)
    yarn = state.yarns[hit.yarn]
    grow = math.dist(hit.c, hit.point)
    if hit.seg < 0:
        warp = -hit.seg - 1
        b = int(state.last_fixed.data[warp])
        state.insert_node(hit.yarn, len(yarn) - 1, y)
        seg = state.add_segment(hit.yarn, b, y)
        state.set_last_fixed(warp, y)
        state.add_length(hit.yarn, grow)
        return y, (seg,), warp
    c, d = int(state.seg_c.data[hit.seg]), int(state.seg_d.data[hit.seg])
    state.insert_node(hit.yarn, index_from_end(yarn, d), y)
    state.kill_segment(hit.seg)
    first = state.add_segment(hit.yarn, c, y)
    second = state.add_segment(hit.yarn, y, d)
    state.add_length(hit.yarn, grow + math.dist(hit.point, hit.d) - math.dist(hit.c, hit.d))
    return y, (first, second), -1


def rest_point(hit: Hit, a1: FloatArray, a2: FloatArray, diameter: float) -> FloatArray:
    """X = P - d n: the moving yarn rests against the hit one on the side it came from.

    Scalar float formulas in a fixed order (the exact reference repeats them).
    """
    if diameter == 0:
        return hit.point.copy()
    mx, my, mz = (float(v) for v in a2 - a1)
    ax, ay, az = (float(v) for v in hit.d - hit.c)
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    ax, ay, az = ax / norm, ay / norm, az / norm
    along = mx * ax + my * ay + mz * az
    nx, ny, nz = mx - along * ax, my - along * ay, mz - along * az
    size = math.sqrt(nx * nx + ny * ny + nz * nz)
    if size <= PARALLEL * math.sqrt(mx * mx + my * my + mz * mz):
        return hit.point.copy()
    k = diameter / size
    px, py, pz = (float(v) for v in hit.point)
    return np.array((px - k * nx, py - k * ny, pz - k * nz))


def sweep(state: State, w: int, a2: FloatArray, instruction: int) -> None:
    """Move warp w's free node to a2, inserting a node pair at every contact on the way."""
    free = int(state.free_node.data[w])
    a1 = state.pos.data[free].copy()
    skip: tuple[int, ...] = ()
    skip_warp = -1
    for _ in range(MAX_CONTACTS_PER_SWEEP):
        apex = int(state.last_fixed.data[w])
        b = state.pos.data[apex].copy()
        hit = first_contact(state, w, b, a1, a2, skip, skip_warp)
        if hit is None:
            state.move_node(free, a2)
            return
        y, skip, skip_warp = split_hit(state, hit)
        x = state.new_node(rest_point(hit, a1, a2, state.diameter))
        state.insert_node(w, len(state.yarns[w]) - 1, x)
        state.add_segment(w, apex, x)
        state.set_last_fixed(w, x)
        state.add_length(w, math.dist(b, state.pos.data[x]))
        state.add_contact((instruction, w, x, hit.yarn, y))
        a1 = a2.copy() if hit.t == 1.0 else a1 + hit.t * (a2 - a1)
    raise TwinError(f"yarn {w}: more than {MAX_CONTACTS_PER_SWEEP} contacts in one sweep",
                    instruction=instruction)
