"""Brute-force interpenetration: an independent check of ``bwsd.export.overlap``.

Every fixed segment is cut into pieces of at most ``step`` mm; at each piece's midpoint the
distance to every segment of every other yarn is computed (no spatial index, no interval
algebra), and the piece overlaps when the least of them is below d. Slow by design.
"""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt

from bwsd.twin.skeleton import FloatArray, IntArray, SkeletonData

BoolArray = npt.NDArray[np.bool_]


def fixed_segments(sk: SkeletonData) -> tuple[FloatArray, FloatArray, IntArray, BoolArray]:
    """Start, end and yarn of every fixed segment of positive length, and whether both its
    nodes are contact nodes."""
    made = {n for c in sk.contacts for n in (c.moving_node, c.hit_node)}
    starts, ends, yarns, between = [], [], [], []
    for yarn in sk.yarns:
        nodes = yarn.nodes[:-1] if yarn.kind == "warp" else yarn.nodes
        ids = yarn.node_ids[: len(nodes)].tolist()
        starts += [nodes[:-1]]
        ends += [nodes[1:]]
        yarns += [np.full(len(nodes) - 1, yarn.id)]
        between += [[a in made and b in made for a, b in itertools.pairwise(ids)]]
    p0, p1, owner = np.vstack(starts), np.vstack(ends), np.concatenate(yarns)
    keep = np.linalg.norm(p1 - p0, axis=1) > 0
    return p0[keep], p1[keep], owner[keep], np.concatenate(between).astype(bool)[keep]


def sample_depths(
    sk: SkeletonData, step: float, low: float = -np.inf, high: float = np.inf, between: bool = False
) -> tuple[FloatArray, FloatArray, IntArray]:
    """Per sample of the yarn between heights ``low`` and ``high`` (with ``between``: on
    segments from contact node to contact node only): its weight (length), its overlap depth
    (0 where none) and its yarn. Distances are to every fixed segment of another yarn. (Only
    samples within d of a segment's heights can be closer than d to it: the one shortcut.)"""
    p0, p1, owner, contact_to_contact = fixed_segments(sk)
    length = np.linalg.norm(p1 - p0, axis=1)
    parts = np.maximum(np.ceil(length / step), 1).astype(int)
    seg = np.repeat(np.arange(len(p0)), parts)
    k = np.arange(len(seg)) - np.repeat(np.cumsum(parts) - parts, parts)
    points = p0[seg] + ((k + 0.5) / parts[seg])[:, None] * (p1 - p0)[seg]
    weight = length[seg] / parts[seg]
    keep = (points[:, 2] >= low) & (points[:, 2] <= high)
    keep &= contact_to_contact[seg] if between else True
    points, weight, yarn = points[keep], weight[keep], owner[seg][keep]
    order = np.argsort(points[:, 2])
    points, weight, yarn = points[order], weight[order], yarn[order]
    least = np.full(len(points), np.inf)
    d = sk.diameter
    for j in range(len(p0)):  # every segment, against the samples within d of its heights
        lo, hi = np.searchsorted(
            points[:, 2], [min(p0[j, 2], p1[j, 2]) - d, max(p0[j, 2], p1[j, 2]) + d]
        )
        window = slice(lo, hi)
        other = yarn[window] != owner[j]
        v = p1[j] - p0[j]
        q = points[window][other] - p0[j]
        t = np.clip(q @ v / (v @ v), 0.0, 1.0)
        gap = np.linalg.norm(q - t[:, None] * v, axis=1)
        index = np.arange(lo, hi)[other]
        least[index] = np.minimum(least[index], gap)
    return weight, np.maximum(d - least, 0.0), yarn


def percentile(values: FloatArray, weights: FloatArray, share: float) -> float:
    """The least value that ``share`` of the weight does not exceed."""
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, share * cumulative[-1])])
