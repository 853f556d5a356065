"""The sweep of one free node (TWIN.md, "The sweep").

Candidates come from the grids of ``State``; each is tested by exact predicates
(``bwsd.twin.predicates``). Constructions (new nodes, the restart point) are float64 formulas
in a fixed order, snapped to the exact value where a decision says a quantity is exactly zero:
a crossing exactly at a segment's end is that end, a touch of the final edge restarts exactly
at the new guide.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from bwsd.errors import TwinError
import numpy as np

from bwsd.twin.predicates import Plane, Vec, exact_orient, orient
from bwsd.twin.state import State

MAX_CONTACTS_PER_SWEEP = 100_000
PARALLEL = 1e-12  # |component of the move across the hit segment| / |move| treated as zero


@dataclass(slots=True)
class Hit:
    """A contact candidate of one sweep step."""

    t: float  # float sweep time (exactly 1.0 when ``t_one``)
    slack: float  # bound on |t - exact t|
    t_one: bool  # exactly on the final edge
    yarn: int
    seg: int  # fixed segment id, or -(warp + 1) for a warp's free segment
    c: Vec
    d: Vec
    point: Vec


def _crossing(c: Vec, d: Vec, oc: float, od: float, sc: int, sd: int) -> Vec:
    """Where segment c-d meets the plane; exactly an endpoint when that endpoint lies on it."""
    if sc == 0:
        return c
    if sd == 0:
        return d
    s = oc / (oc - od)
    return c[0] + s * (d[0] - c[0]), c[1] + s * (d[1] - c[1]), c[2] + s * (d[2] - c[2])


def _edges(b: Vec, a1: Vec, a2: Vec, c: Vec, d: Vec, oc: float, od: float, sc: int,
           sd: int) -> Hit | None:
    """Exact barycentric test of a segment crossing the plane; None if no contact."""
    _, sb, _ = orient(c, d, a1, a2)
    if sb == 0:
        return None
    v2, s2, e2 = orient(c, d, b, a1)
    if s2 != sb:
        return None
    v1, s1, e1 = orient(c, d, a2, b)
    if s1 != 0 and s1 != sb:
        return None
    point = _crossing(c, d, oc, od, sc, sd)
    if s1 == 0:
        return Hit(1.0, 0.0, True, -1, 0, c, d, point)
    room = abs(v2) + abs(v1) - e1 - e2
    slack = (e1 + e2) / room + 4e-16 if room > 0 else math.inf
    return Hit(v2 / (v1 + v2), slack, False, -1, 0, c, d, point)


SCALAR_LIMIT = 24  # up to this many candidates the scalar side test beats numpy's overhead


def _gather(state: State, w: int, lo: Vec, hi: Vec, skip: tuple[int, ...],
            skip_warp: int) -> tuple[list[Vec], list[Vec], list[int], list[int]]:
    """Endpoints, yarn and reference of every segment whose box meets [lo, hi]."""
    cs: list[Vec] = []
    ds: list[Vec] = []
    yarns: list[int] = []
    refs: list[int] = []
    seg_c, seg_d, seg_yarn, xyz = state.seg_c, state.seg_d, state.seg_yarn.data, state.xyz
    for s in state.fixed_near(lo, hi):
        yarn = int(seg_yarn[s])
        if yarn != w and s not in skip:
            cs.append(xyz(seg_c[s]))
            ds.append(xyz(seg_d[s]))
            yarns.append(yarn)
            refs.append(s)
    last, free = state.last_fixed, state.free_node
    for warp in state.free_near(lo, hi):
        if warp != w and warp != skip_warp:
            cs.append(xyz(last[warp]))
            ds.append(xyz(free[warp]))
            yarns.append(warp)
            refs.append(-warp - 1)
    return cs, ds, yarns, refs


def _sides(plane: Plane, cs: list[Vec], ds: list[Vec]) -> list[tuple[float, int, bool]]:
    """Side of every endpoint, c's then d's: scalar for a few, vectorised for many."""
    if len(cs) <= SCALAR_LIMIT:
        return [plane.side(p) for p in cs + ds]
    det, sign, on_line = plane.sides(np.array(cs + ds))
    return list(zip(det.tolist(), sign.tolist(), on_line.tolist(), strict=True))


def first_contact(state: State, w: int, b: Vec, a1: Vec, a2: Vec, skip: tuple[int, ...],
                  skip_warp: int) -> Hit | None:
    """The contact with the smallest sweep time of triangle (b, a1, a2), or None."""
    lo = (min(b[0], a1[0], a2[0]), min(b[1], a1[1], a2[1]), min(b[2], a1[2], a2[2]))
    hi = (max(b[0], a1[0], a2[0]), max(b[1], a1[1], a2[1]), max(b[2], a1[2], a2[2]))
    cs, ds, yarns, refs = _gather(state, w, lo, hi, skip, skip_warp)
    n = len(cs)
    if n == 0:
        return None
    sides = _sides(Plane(b, a1, a2), cs, ds)
    hits = []
    for i in range(n):
        oc, sc, c_on_line = sides[i]
        od, sd, d_on_line = sides[n + i]
        if (sc >= 0) == (sd >= 0):
            continue
        if (sc == 0 and c_on_line) or (sd == 0 and d_on_line):
            continue  # crosses on the guide path itself: never strictly inside
        hit = _edges(b, a1, a2, cs[i], ds[i], oc, od, sc, sd)
        if hit is not None:
            hit.yarn, hit.seg = yarns[i], refs[i]
            hits.append(hit)
    if not hits:
        return None
    return _earliest(state, hits, b, a1, a2)


def _earliest(state: State, hits: list[Hit], b: Vec, a1: Vec, a2: Vec) -> Hit:
    """The hit with the smallest exact t; ties: smaller yarn id, then nearer the yarn's start."""
    if len(hits) == 1:
        return hits[0]
    ceiling = min(h.t + h.slack for h in hits)
    near = [h for h in hits if h.t - h.slack <= ceiling]
    if len(near) == 1:
        return near[0]
    return min(near, key=lambda h: (_exact_t(h, b, a1, a2), h.yarn, _seg_rank(state, h.seg)))


def _exact_t(hit: Hit, b: Vec, a1: Vec, a2: Vec) -> Fraction:
    if hit.t_one:
        return Fraction(1)
    w1 = exact_orient(hit.c, hit.d, a2, b)
    w2 = exact_orient(hit.c, hit.d, b, a1)
    return w2 / (w1 + w2)


def _seg_rank(state: State, ref: int) -> int:
    """Position of a segment along its yarn (0 = the segment at the yarn's start)."""
    if ref < 0:
        return len(state.yarns[-ref - 1]) - 2
    return index_from_end(state.yarns[int(state.seg_yarn.data[ref])], state.seg_c[ref])


def index_from_end(nodes: Any, node: int) -> int:
    """Position of node in a yarn's node list, searched from the free end (where work happens)."""
    for i in range(len(nodes) - 1, -1, -1):
        if nodes[i] == node:
            return i
    raise ValueError(node)


def split_hit(state: State, hit: Hit) -> tuple[int, tuple[int, ...], int]:
    """Insert Y into the hit yarn; returns Y and what this sweep skips next (segments, warp)."""
    y = state.new_node(hit.point)
    nodes = state.yarns[hit.yarn]
    grow = math.dist(hit.c, hit.point)
    if hit.seg < 0:
        warp = -hit.seg - 1
        b = state.last_fixed[warp]
        state.insert_node(hit.yarn, len(nodes) - 1, y)
        seg = state.add_segment(hit.yarn, b, y)
        state.set_last_fixed(warp, y)
        state.add_length(hit.yarn, grow)
        return y, (seg,), warp
    c, d = state.seg_c[hit.seg], state.seg_d[hit.seg]
    state.insert_node(hit.yarn, index_from_end(nodes, d), y)
    state.kill_segment(hit.seg)
    first = state.add_segment(hit.yarn, c, y)
    second = state.add_segment(hit.yarn, y, d)
    state.add_length(hit.yarn, grow + math.dist(hit.point, hit.d) - math.dist(hit.c, hit.d))
    return y, (first, second), -1


def rest_point(hit: Hit, a1: Vec, a2: Vec, diameter: float) -> Vec:
    """X = P - d n: the moving yarn rests against the hit one on the side it came from."""
    if diameter == 0:
        return hit.point
    mx, my, mz = a2[0] - a1[0], a2[1] - a1[1], a2[2] - a1[2]
    ax, ay, az = hit.d[0] - hit.c[0], hit.d[1] - hit.c[1], hit.d[2] - hit.c[2]
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    ax, ay, az = ax / norm, ay / norm, az / norm
    along = mx * ax + my * ay + mz * az
    nx, ny, nz = mx - along * ax, my - along * ay, mz - along * az
    size = math.sqrt(nx * nx + ny * ny + nz * nz)
    if size <= PARALLEL * math.sqrt(mx * mx + my * my + mz * mz):
        return hit.point
    k = diameter / size
    px, py, pz = hit.point
    return px - k * nx, py - k * ny, pz - k * nz


def sweep(state: State, w: int, a2: Vec, instruction: int) -> None:
    """Move warp w's free node to a2, inserting a node pair at every contact on the way."""
    a1 = state.xyz(state.free_node[w])
    skip: tuple[int, ...] = ()
    skip_warp = -1
    for _ in range(MAX_CONTACTS_PER_SWEEP):
        apex = state.last_fixed[w]
        b = state.xyz(apex)
        hit = first_contact(state, w, b, a1, a2, skip, skip_warp)
        if hit is None:
            state.move_free(w, a2)
            return
        y, skip, skip_warp = split_hit(state, hit)
        x = state.new_node(rest_point(hit, a1, a2, state.diameter))
        state.insert_node(w, len(state.yarns[w]) - 1, x)
        state.add_segment(w, apex, x)
        state.set_last_fixed(w, x)
        state.add_length(w, math.dist(b, state.xyz(x)))
        state.add_contact((instruction, w, x, hit.yarn, y))
        if hit.t_one:
            a1 = a2
        else:
            t = hit.t
            a1 = (a1[0] + t * (a2[0] - a1[0]), a1[1] + t * (a2[1] - a1[1]),
                  a1[2] + t * (a2[2] - a1[2]))
    raise TwinError(f"yarn {w}: more than {MAX_CONTACTS_PER_SWEEP} contacts in one sweep",
                    instruction=instruction)
