"""The sweep of one free node (docs/twin.md, "The sweep, exactly").

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

import numpy as np

from bwsd.errors import TwinError
from bwsd.twin.batch import Batch
from bwsd.twin.predicates import (
    ERRBOUND,
    TINY,
    BoolArray,
    FloatArray,
    IntArray,
    Plane,
    Vec,
    exact_orient,
    orient,
)
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


def _crossing(
    plane: tuple[Vec, Vec, Vec], c: Vec, d: Vec, oc: float, od: float, sc: int, sd: int
) -> Vec:
    """Where segment c-d meets the plane; exactly an endpoint when that endpoint lies on it.

    s = oc / (oc - od) from the float plane values, clamped to [0, 1]; where those values
    cannot tell the ends apart (oc == od in floats), s is the exact ratio, rounded.
    """
    if sc == 0:
        return c
    if sd == 0:
        return d
    if oc != od:
        s = min(max(oc / (oc - od), 0.0), 1.0)
    else:
        ec, ed = exact_orient(*plane, c), exact_orient(*plane, d)
        s = float(ec / (ec - ed))
    return c[0] + s * (d[0] - c[0]), c[1] + s * (d[1] - c[1]), c[2] + s * (d[2] - c[2])


def _edges(
    b: Vec, a1: Vec, a2: Vec, c: Vec, d: Vec, oc: float, od: float, sc: int, sd: int
) -> Hit | None:
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
    point = _crossing((b, a1, a2), c, d, oc, od, sc, sd)
    if s1 == 0:
        return Hit(1.0, 0.0, True, -1, 0, c, d, point)
    room = abs(v2) + abs(v1) - e1 - e2
    slack = (e1 + e2) / room + 4e-16 if room > 0 else math.inf
    return Hit(_time(b, a1, a2, c, d, v1, v2), slack, False, -1, 0, c, d, point)


def _time(b: Vec, a1: Vec, a2: Vec, c: Vec, d: Vec, v1: float, v2: float) -> float:
    """Sweep time t = v2 / (v1 + v2) from the float values, clamped to [0, 1]; the exact
    ratio, rounded, where the float values cancel."""
    den = v1 + v2
    if den != 0:
        return min(max(v2 / den, 0.0), 1.0)
    w1, w2 = exact_orient(c, d, a2, b), exact_orient(c, d, b, a1)
    return float(w2 / (w1 + w2))


def _candidates(
    state: State, w: int, lo: Vec, hi: Vec, skip: tuple[int, ...], skip_warp: int
) -> tuple[FloatArray, IntArray, IntArray]:
    """Segments (n, 6), yarns and references of everything whose box meets [lo, hi]."""
    fixed = state.fixed_near(lo, hi)
    yarns = state.seg_yarn.data[fixed]
    keep = yarns != w
    if skip:
        keep &= ~np.isin(fixed, skip)
    fixed, yarns = fixed[keep], yarns[keep]
    warps = state.free_near(lo, hi)
    warps = warps[(warps != w) & (warps != skip_warp)]
    segs = np.concatenate((state.seg_xyz.data[fixed], state.free_seg.data[warps]))
    return segs, np.concatenate((yarns, warps)), np.concatenate((fixed, -warps - 1))


def _plausible(
    segs: FloatArray, oc: FloatArray, od: FloatArray, err: FloatArray, lo: Vec, hi: Vec
) -> BoolArray:
    """False where the crossing point lies provably outside the triangle's box.

    Only a filter: where the plane values are too uncertain to place the point, keep it.
    """
    gap = np.abs(oc - od)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = err / gap
        s = oc / (oc - od)
    c, d = segs[:, :3], segs[:, 3:]
    p = c + s[:, None] * (d - c)
    size = np.abs(d - c).max(axis=1) + np.abs(p).max(axis=1)
    tol = (4 * rel + 1e-12) * size
    inside = ((p >= np.subtract(lo, tol[:, None])) & (p <= np.add(hi, tol[:, None]))).all(axis=1)
    result: BoolArray = inside | ~(rel < 1e-6)
    return result


SCALAR_LIMIT = 24  # up to this many candidates, scalar side tests beat numpy's call overhead
Crossing = tuple[int, float, float, int, int]  # index, oc, od, sc, sd


def _sides_scalar(plane: Plane, rows: list[tuple[Vec, Vec]], lo: Vec, hi: Vec) -> list[Crossing]:
    """The float filter of ``Plane.side`` written out for speed; doubtful points go to it.

    A segment whose ends are surely on opposite sides but whose crossing point surely lies
    outside the triangle's box is dropped too (the scalar twin of ``_plausible``).
    """
    bx, by, bz = plane.b
    n0, n1, n2 = plane.n
    p0, p1, p2 = plane.p
    out = []
    for i, (c, d) in enumerate(rows):
        cx, cy, cz = c[0] - bx, c[1] - by, c[2] - bz
        oc = cx * n0 + cy * n1 + cz * n2
        perm_c = abs(cx) * p0 + abs(cy) * p1 + abs(cz) * p2
        dx, dy, dz = d[0] - bx, d[1] - by, d[2] - bz
        od = dx * n0 + dy * n1 + dz * n2
        perm_d = abs(dx) * p0 + abs(dy) * p1 + abs(dz) * p2
        if perm_c >= TINY and perm_d >= TINY:
            bc, bd = ERRBOUND * perm_c, ERRBOUND * perm_d
            if (oc > bc and od > bd) or (oc < -bc and od < -bd):
                continue  # both ends strictly on one side, by the filter alone
            gap = abs(oc - od)
            if gap > 1e6 * (bc + bd) and _outside(c, d, oc / (oc - od), (bc + bd) / gap, lo, hi):
                continue
        oc, sc, c_on = plane.side(c)
        od, sd, d_on = plane.side(d)
        if (sc >= 0) != (sd >= 0) and not (sc == 0 and c_on) and not (sd == 0 and d_on):
            out.append((i, oc, od, sc, sd))
    return out


def _outside(c: Vec, d: Vec, s: float, rel: float, lo: Vec, hi: Vec) -> bool:
    """The point c + s (d - c), known to relative error ``rel``, surely lies outside [lo, hi]."""
    size = max(abs(d[0] - c[0]), abs(d[1] - c[1]), abs(d[2] - c[2]))
    for k in range(3):
        p = c[k] + s * (d[k] - c[k])
        tol = (4 * rel + 1e-12) * (size + abs(p))
        if p < lo[k] - tol or p > hi[k] + tol:
            return True
    return False


def _sides_vector(plane: Plane, segs: FloatArray, lo: Vec, hi: Vec) -> list[Crossing]:
    det, sign, on_line, err = plane.sides(segs.reshape(-1, 3))
    s_c, s_d = sign[0::2], sign[1::2]
    cross = (s_c >= 0) != (s_d >= 0)
    cross &= ~((s_c == 0) & on_line[0::2]) & ~((s_d == 0) & on_line[1::2])
    idx = np.nonzero(cross)[0]
    o_c, o_d = det[0::2][idx], det[1::2][idx]
    idx = idx[_plausible(segs[idx], o_c, o_d, err[0::2][idx] + err[1::2][idx], lo, hi)]
    return [
        (i, float(det[2 * i]), float(det[2 * i + 1]), int(s_c[i]), int(s_d[i]))
        for i in idx.tolist()
    ]


def first_contact(
    state: State,
    w: int,
    b: Vec,
    a1: Vec,
    a2: Vec,
    skip: tuple[int, ...],
    skip_warp: int,
    batch: Batch | None = None,
    case: int = -1,
) -> Hit | None:
    """The contact with the smallest sweep time of triangle (b, a1, a2), or None.

    Candidates come from ``batch`` when the instruction has one, else from the state's
    broad phase. Scalar side tests for a few, vectorised for many: both take the same
    exact decisions on the same float values.
    """
    lo = (min(b[0], a1[0], a2[0]), min(b[1], a1[1], a2[1]), min(b[2], a1[2], a2[2]))
    hi = (max(b[0], a1[0], a2[0]), max(b[1], a1[1], a2[1]), max(b[2], a1[2], a2[2]))
    if batch is not None:
        found = batch.candidates(case, w, skip, skip_warp, lo, hi)
        yarns = [c[0] for c in found]
        refs = [c[1] for c in found]
        rows = [(c[2], c[3]) for c in found]
    else:
        segs, yarn_ids, ref_ids = _candidates(state, w, lo, hi, skip, skip_warp)
        yarns, refs = yarn_ids.tolist(), ref_ids.tolist()
        rows = [((r[0], r[1], r[2]), (r[3], r[4], r[5])) for r in segs.tolist()]
    if not rows:
        return None
    plane = Plane(b, a1, a2)
    if len(rows) <= SCALAR_LIMIT:
        crossings = _sides_scalar(plane, rows, lo, hi)
    else:
        crossings = _sides_vector(plane, np.array([c + d for c, d in rows]), lo, hi)
    hits = []
    for i, oc, od, sc, sd in crossings:
        c, d = rows[i]
        hit = _edges(b, a1, a2, c, d, oc, od, sc, sd)
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


def split_hit(state: State, hit: Hit, batch: Batch | None) -> tuple[int, tuple[int, ...], int]:
    """Insert Y into the hit yarn; returns Y and what this sweep skips next (segments, warp)."""
    y = state.new_node(hit.point)
    nodes = state.yarns[hit.yarn]
    grow = math.dist(hit.c, hit.point)
    if hit.seg < 0:
        warp = -hit.seg - 1
        b = state.last_fixed[warp]
        state.insert_node(hit.yarn, len(nodes) - 1, y)
        seg = state.add_segment(hit.yarn, b, y)
        if batch is not None:
            batch.gain(hit.yarn, seg)
        state.set_last_fixed(warp, y)
        state.add_length(hit.yarn, grow)
        return y, (seg,), warp
    c, d = state.seg_c[hit.seg], state.seg_d[hit.seg]
    state.insert_node(hit.yarn, index_from_end(nodes, d), y)
    state.kill_segment(hit.seg)
    first = state.add_segment(hit.yarn, c, y)
    second = state.add_segment(hit.yarn, y, d)
    if batch is not None:
        batch.split(hit.seg, (first, second))
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


def sweep(
    state: State, w: int, a2: Vec, instruction: int, batch: Batch | None = None, case: int = -1
) -> None:
    """Move warp w's free node to a2, inserting a node pair at every contact on the way."""
    a1 = state.xyz(state.free_node[w])
    skip: tuple[int, ...] = ()
    skip_warp = -1
    for _ in range(MAX_CONTACTS_PER_SWEEP):
        apex = state.last_fixed[w]
        b = state.xyz(apex)
        hit = first_contact(state, w, b, a1, a2, skip, skip_warp, batch, case)
        if hit is None:
            state.move_free(w, a2)
            if batch is not None:
                batch.moved(w)
            return
        y, skip, skip_warp = split_hit(state, hit, batch)
        x = state.new_node(rest_point(hit, a1, a2, state.diameter))
        state.insert_node(w, len(state.yarns[w]) - 1, x)
        seg = state.add_segment(w, apex, x)
        if batch is not None:
            batch.gain(w, seg)
        state.set_last_fixed(w, x)
        state.add_length(w, math.dist(b, state.xyz(x)))
        state.add_contact((instruction, w, x, hit.yarn, y))
        if hit.t_one:
            a1 = a2
        else:
            t = hit.t
            a1 = (
                a1[0] + t * (a2[0] - a1[0]),
                a1[1] + t * (a2[1] - a1[1]),
                a1[2] + t * (a2[2] - a1[2]),
            )
    raise TwinError(
        f"yarn {w}: more than {MAX_CONTACTS_PER_SWEEP} contacts in one sweep",
        instruction=instruction,
    )
