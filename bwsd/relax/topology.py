"""Which side of the hit yarn each contact's moving yarn passes (numpy only).

A contact is a crossing of two yarns: the moving yarn's node X rests against the hit
yarn's node Y. Relaxation slides nodes along their yarns, so X and Y need not stay where
the yarns cross; the crossing is found again each time as the closest pair of segments of
the two yarns within ``WINDOW`` diameters of arc length of X (on the moving yarn) and of Y
(on the hit yarn). With u and v those segments' directions and p - q the gap from the hit
yarn's closest point to the moving yarn's, the **side** is the sign of det[u, v, p - q]: the
crossing's sign in a knot diagram, over or under. It changes only when the two centrelines
meet or the segments run parallel, so a relaxation that keeps every contact's side has
passed no yarn through another there.
"""

from __future__ import annotations

import numpy as np

from bwsd.relax.geometry import closest
from bwsd.twin.skeleton import FloatArray, IntArray, SkeletonData

PARALLEL = 1e-3  # |sin| of the angle between the segments below which a side is not told
WINDOW = 4.0  # diameters of arc length either side of X and Y searched for the crossing


def contact_sides(sk: SkeletonData) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per contact: the side (+1, -1, or 0 where the yarns run parallel there), the sine of
    the angle between the two yarns at their crossing, and the distance between them."""
    pos = np.vstack([np.asarray(y.nodes, np.float64).reshape(-1, 3) for y in sk.yarns])
    ids = np.concatenate([np.asarray(y.node_ids, np.int64) for y in sk.yarns])
    yarn = np.repeat(np.arange(len(sk.yarns)), [len(y.node_ids) for y in sk.yarns])
    if len(sk.contacts) == 0:
        empty = np.zeros(0)
        return empty, empty, empty
    order = np.argsort(ids, kind="stable")
    table = np.array([(c.moving_node, c.hit_node) for c in sk.contacts], np.int64).reshape(-1, 2)
    at = order[np.searchsorted(ids[order], table)]
    a = np.flatnonzero(yarn[:-1] == yarn[1:])
    key = _arc_keys(pos, yarn)
    reach = WINDOW * max(sk.diameter, 1e-9)
    first_m, count_m = _window(key, a, at[:, 0], reach)
    first_h, count_h = _window(key, a, at[:, 1], reach)
    return _crossings(pos, a, (first_m, count_m), (first_h, count_h))


def _arc_keys(pos: FloatArray, yarn: IntArray) -> FloatArray:
    """Each node's arc length along its yarn, yarns laid end to end with gaps between them,
    so one sorted array serves every yarn's searches."""
    step = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    step = np.where(yarn[1:] == yarn[:-1], step, 0.0)
    arc = np.concatenate([[0.0], np.cumsum(step)])
    gap = float(arc[-1]) + 1.0
    out: FloatArray = arc + yarn * gap
    return out


def _window(
    key: FloatArray, a: IntArray, node: IntArray, reach: float
) -> tuple[IntArray, IntArray]:
    """The segments (first index into ``a`` and count) within ``reach`` of arc of ``node``,
    on its own yarn (at least the node's own segments)."""
    lo = np.searchsorted(key[a + 1], key[node] - reach, side="left")
    hi = np.searchsorted(key[a], key[node] + reach, side="right")
    return lo, np.maximum(hi - lo, 0)


Window = tuple[IntArray, IntArray]


def _crossings(
    pos: FloatArray, a: IntArray, moving: Window, hit: Window
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Side, sine and distance of the closest pair of segments of each contact's windows."""
    (fm, cm), (fh, ch) = moving, hit
    total = cm * ch
    contact = np.repeat(np.arange(len(cm)), total)
    k = np.arange(len(contact)) - np.repeat(np.cumsum(total) - total, total)
    i = fm[contact] + k // ch[contact]
    j = fh[contact] + k % ch[contact]
    p0, p1, q0, q1 = pos[a[i]], pos[a[i] + 1], pos[a[j]], pos[a[j] + 1]
    s, t, dist = closest(p0, p1, q0, q1)
    best = np.lexsort((np.arange(len(contact)), dist, contact))
    take = best[np.searchsorted(contact[best], np.arange(len(cm)))]
    u, v = p1[take] - p0[take], q1[take] - q0[take]
    gap = (p0[take] + s[take, None] * u) - (q0[take] + t[take, None] * v)
    cross = np.cross(u, v)
    size = np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1)
    sine = np.divide(np.linalg.norm(cross, axis=1), size, out=np.zeros(len(u)), where=size > 0)
    side = np.where(sine > PARALLEL, np.sign(np.einsum("ij,ij->i", cross, gap)), 0.0)
    return side, sine, dist[take]
