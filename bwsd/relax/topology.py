"""Which side of the hit yarn each contact's moving yarn lies on (numpy only).

At a contact, X is the moving yarn's node and Y the hit yarn's. With t_X and t_Y the two
yarns' tangents there (each from its node's neighbours), the **side** is the sign of
det[t_X, t_Y, X - Y]: which way the moving yarn passes the hit one, as a crossing of a knot
diagram is over or under. It can change only if the two centrelines meet (or run parallel),
so a relaxation that keeps every contact's side has passed no yarn through another there.
"""

from __future__ import annotations

import numpy as np

from bwsd.twin.skeleton import FloatArray, SkeletonData

PARALLEL = 1e-3  # |sin| of the angle between the tangents below which a side is not told


def contact_sides(sk: SkeletonData) -> tuple[FloatArray, FloatArray]:
    """Per contact: the side (+1, -1, or 0 where the yarns run parallel or X = Y) and the
    sine of the angle between the two yarns there."""
    where: dict[int, tuple[int, int]] = {}
    for k, yarn in enumerate(sk.yarns):
        for i, node in enumerate(yarn.node_ids.tolist()):
            where[node] = (k, i)
    side = np.zeros(len(sk.contacts))
    sine = np.zeros(len(sk.contacts))
    for c, contact in enumerate(sk.contacts):
        x, tx = _point(sk, where[contact.moving_node])
        y, ty = _point(sk, where[contact.hit_node])
        cross = np.cross(tx, ty)
        sine[c] = float(np.linalg.norm(cross))
        value = float(np.dot(cross, x - y))
        side[c] = np.sign(value) if sine[c] > PARALLEL else 0.0
    return side, sine


def _point(sk: SkeletonData, at: tuple[int, int]) -> tuple[FloatArray, FloatArray]:
    """A node and its yarn's unit tangent there (from the neighbours)."""
    nodes = np.asarray(sk.yarns[at[0]].nodes)
    i = at[1]
    tangent = nodes[min(i + 1, len(nodes) - 1)] - nodes[max(i - 1, 0)]
    size = float(np.linalg.norm(tangent))
    return nodes[i], tangent / size if size > 0 else tangent
