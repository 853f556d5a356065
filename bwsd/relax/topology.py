"""Which side of the hit yarn each contact's moving yarn lies on (numpy only).

At a contact, X is the moving yarn's node and Y the hit yarn's. With t_X and t_Y the two
yarns' tangents there (each from its node's neighbours), the **side** is the sign of
det[t_X, t_Y, X - Y]: which way the moving yarn passes the hit one, as a crossing of a knot
diagram is over or under. It can change only if the two centrelines meet (or run parallel),
so a relaxation that keeps every contact's side has passed no yarn through another there.
"""

from __future__ import annotations

import numpy as np

from bwsd.twin.skeleton import FloatArray, IntArray, SkeletonData

PARALLEL = 1e-3  # |sin| of the angle between the tangents below which a side is not told


def contact_sides(sk: SkeletonData) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per contact: the side (+1, -1, or 0 where the yarns run parallel or X = Y), the sine
    of the angle between the two yarns there, and the distance |X - Y|."""
    pos = np.vstack([np.asarray(y.nodes, np.float64).reshape(-1, 3) for y in sk.yarns])
    ids = np.concatenate([np.asarray(y.node_ids, np.int64) for y in sk.yarns])
    yarn = np.repeat(np.arange(len(sk.yarns)), [len(y.node_ids) for y in sk.yarns])
    order = np.argsort(ids, kind="stable")
    table = np.array([(c.moving_node, c.hit_node) for c in sk.contacts], np.int64).reshape(-1, 2)
    at = order[np.searchsorted(ids[order], table)]
    x, tx = pos[at[:, 0]], _tangent(pos, yarn, at[:, 0])
    y, ty = pos[at[:, 1]], _tangent(pos, yarn, at[:, 1])
    cross = np.cross(tx, ty)
    sine = np.linalg.norm(cross, axis=1)
    value = np.einsum("ij,ij->i", cross, x - y)
    side = np.where(sine > PARALLEL, np.sign(value), 0.0)
    return side, sine, np.linalg.norm(x - y, axis=1)


def _tangent(pos: FloatArray, yarn: IntArray, at: IntArray) -> FloatArray:
    """Unit tangent of each node ``at`` from its neighbours on its own yarn."""
    last = len(pos) - 1
    before = np.where((at > 0) & (yarn[np.maximum(at - 1, 0)] == yarn[at]), at - 1, at)
    after = np.where((at < last) & (yarn[np.minimum(at + 1, last)] == yarn[at]), at + 1, at)
    tangent = pos[after] - pos[before]
    size = np.linalg.norm(tangent, axis=1, keepdims=True)
    out: FloatArray = np.divide(tangent, size, out=np.zeros_like(tangent), where=size > 0)
    return out
