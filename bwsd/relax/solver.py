"""The relaxation's iterations: separate the twin's overlaps, then tighten (numpy only).

One **step** moves every free node at once (a Jacobi step), each by at most its *cap*: 0.45
times the distance from each of its segments to the nearest segment of another yarn (and
less than the reach of the pair list). Two segments whose four ends each move at most 0.45
of their distance cannot meet during the step's straight-line motion, so no centreline
passes through another (docs/relax.md, "Topology").

- **Separate** (phase 1): every pair of segments of different yarns closer than d is pushed
  apart along its closest points' direction, the correction shared by the four ends as in
  position-based dynamics (weights of the closest points, fixed components not moving),
  averaged over each node's pairs.
- **Tighten** (phase 2): each free node moves along its yarn's pull, T (u_prev + u_next),
  over its stiffness T (1 / l_prev + 1 / l_next), scaled by the step size; then the
  separation passes remove what that pushed into other yarns. A step is kept only if the
  tension-weighted length did not rise and the worst overlap stayed within the tolerance;
  otherwise the step size halves and the step is tried again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bwsd.relax.geometry import closest, near_pairs
from bwsd.relax.state import Chains
from bwsd.twin.skeleton import FloatArray, IntArray

CAP = 0.45  # a node moves at most this share of its segments' distance to other yarns a step
REACH = 0.5  # pairs are listed within d + REACH d; nodes move at most CAP of that between lists


@dataclass
class Pairs:
    """Segment pairs of different yarns listed within the reach, with their closest points."""

    i: IntArray
    j: IntArray
    s: FloatArray = field(default_factory=lambda: np.zeros(0))
    t: FloatArray = field(default_factory=lambda: np.zeros(0))
    dist: FloatArray = field(default_factory=lambda: np.zeros(0))
    normal: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass(frozen=True)
class Layout:
    """The segments of a layout of chains: ends, tension, and the free components."""

    a: IntArray
    b: IntArray
    tension: FloatArray
    free: FloatArray  # (n, 3) 1.0 where a component moves, else 0.0
    yarn: IntArray  # (segments,)

    @classmethod
    def of(cls, chains: Chains) -> Layout:
        a = chains.seg_a
        return cls(
            a, a + 1, chains.tension[chains.yarn[a]], chains.free.astype(np.float64), chains.yarn[a]
        )


def energy(pos: FloatArray, lay: Layout) -> float:
    """The tension-weighted length: sum over segments of T |b - a|."""
    seg = pos[lay.b] - pos[lay.a]
    return float(np.dot(lay.tension, np.sqrt(np.einsum("ij,ij->i", seg, seg))))


def list_pairs(pos: FloatArray, lay: Layout, d: float) -> Pairs:
    """The pairs of segments of different yarns within d + REACH d of each other."""
    i, j = near_pairs(pos[lay.a], pos[lay.b], lay.yarn, d * (1 + REACH))
    return measure(pos, lay, Pairs(i, j))


def measure(pos: FloatArray, lay: Layout, pairs: Pairs) -> Pairs:
    """``pairs`` with their closest points, distances and directions (from j to i) at ``pos``."""
    p0, p1 = pos[lay.a[pairs.i]], pos[lay.b[pairs.i]]
    q0, q1 = pos[lay.a[pairs.j]], pos[lay.b[pairs.j]]
    s, t, dist = closest(p0, p1, q0, q1)
    gap = (p0 + s[:, None] * (p1 - p0)) - (q0 + t[:, None] * (q1 - q0))
    normal = gap / np.maximum(dist, 1e-300)[:, None]
    return Pairs(pairs.i, pairs.j, s, t, dist, normal)


def caps(pairs: Pairs, lay: Layout, count: int, room: FloatArray) -> FloatArray:
    """Per node, how far it may move this step: CAP times the least distance of its
    segments' pairs, and no more than ``room`` (what is left of the reach since the list)."""
    cap = room.copy()
    limit = CAP * pairs.dist
    for ends in (lay.a, lay.b):
        np.minimum.at(cap, ends[pairs.i], limit)
        np.minimum.at(cap, ends[pairs.j], limit)
    return cap


def clamp(step: FloatArray, cap: FloatArray) -> FloatArray:
    """Each node's move shortened to its cap."""
    length = np.sqrt(np.einsum("ij,ij->i", step, step))
    scale = np.where(length > cap, cap / np.maximum(length, 1e-300), 1.0)
    out: FloatArray = step * scale[:, None]
    return out


def separation(pairs: Pairs, lay: Layout, d: float, count: int) -> FloatArray:
    """The move of each node that pushes its overlapping pairs apart to d, averaged over
    its pairs (position-based: each pair's correction shared by its four ends)."""
    over = np.flatnonzero(pairs.dist < d)
    step = np.zeros((count, 3))
    if len(over) == 0:
        return step
    s, t = pairs.s[over], pairs.t[over]
    ends = (lay.a[pairs.i[over]], lay.b[pairs.i[over]], lay.a[pairs.j[over]], lay.b[pairs.j[over]])
    weights = (1 - s, s, -(1 - t), -t)
    normal = pairs.normal[over]
    mass = [lay.free[e] for e in ends]  # (k, 3) each: inverse masses per component
    denom = sum(w[:, None] ** 2 * m for w, m in zip(weights, mass, strict=True))
    depth = (d - pairs.dist[over])[:, None] * normal
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(denom > 0, depth / denom, 0.0)
    hits = np.zeros(count)
    for e, w, m in zip(ends, weights, mass, strict=True):
        np.add.at(step, e, w[:, None] * m * lam)
        np.add.at(hits, e, (np.abs(w) > 0) * 1.0)
    out: FloatArray = step / np.maximum(hits, 1.0)[:, None]
    return out


def pull(pos: FloatArray, lay: Layout, count: int) -> FloatArray:
    """Each free node's move toward its yarn's chord: T (u_prev + u_next) over
    T (1 / l_prev + 1 / l_next) (a Newton step along the pull, for one node alone)."""
    seg = pos[lay.b] - pos[lay.a]
    length = np.maximum(np.sqrt(np.einsum("ij,ij->i", seg, seg)), 1e-12)
    unit = seg * (lay.tension / length)[:, None]
    force = np.zeros((count, 3))
    np.add.at(force, lay.a, unit)
    np.add.at(force, lay.b, -unit)
    stiff = np.zeros(count)
    np.add.at(stiff, lay.a, lay.tension / length)
    np.add.at(stiff, lay.b, lay.tension / length)
    out: FloatArray = force / np.maximum(stiff, 1e-300)[:, None] * lay.free
    return out


def forces(pos: FloatArray, lay: Layout, count: int) -> FloatArray:
    """The yarns' pull on each node: T (u_prev + u_next), on free components only."""
    seg = pos[lay.b] - pos[lay.a]
    length = np.maximum(np.sqrt(np.einsum("ij,ij->i", seg, seg)), 1e-300)
    unit = seg * (lay.tension / length)[:, None]
    force = np.zeros((count, 3))
    np.add.at(force, lay.a, unit)
    np.add.at(force, lay.b, -unit)
    out: FloatArray = force * lay.free
    return out
