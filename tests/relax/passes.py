"""An independent continuous check that no centreline passes through another during a step.

A step moves every node in a straight line from its old to its new position (all at once).
For two segments of different yarns whose four ends move by at most m1 and m2, the distance
between the segments changes by at most m = m1 + m2 over the step, at a rate bounded by m, so
over a part [t0, t1] of the step it stays above (D(t0) + D(t1) - m (t1 - t0)) / 2. A pair is
cleared where that is positive; else the part is halved, down to 2^-40 of the step, where a
pair still not cleared is a pass-through (the segments meet, up to that resolution).
"""

from __future__ import annotations

import numpy as np

from bwsd.export.overlap import candidates
from bwsd.relax.geometry import closest
from bwsd.twin.skeleton import FloatArray, IntArray

DEPTH = 40


def _distance(
    old: FloatArray,
    new: FloatArray,
    a: IntArray,
    b: IntArray,
    i: IntArray,
    j: IntArray,
    t: FloatArray,
) -> FloatArray:
    """Distance of the segment pairs (i, j) at times t of the step."""

    def at(n: IntArray) -> FloatArray:
        out: FloatArray = old[n] + t[:, None] * (new[n] - old[n])
        return out

    return closest(at(a[i]), at(b[i]), at(a[j]), at(b[j]))[2]


def passes_through(
    old: FloatArray, new: FloatArray, a: IntArray, b: IntArray, yarn: IntArray
) -> int:
    """How many pairs of segments (ends ``a``, ``b``; ``yarn`` per segment) meet during the
    step from ``old`` to ``new`` positions."""
    move = np.linalg.norm(new - old, axis=1)
    seg_move = np.maximum(move[a], move[b])
    reach = 2 * float(seg_move.max(initial=0.0)) + 1e-9
    i, j = candidates(old[a], old[b], yarn, reach)  # pairs that may meet: within reach at first
    if len(i) == 0:
        return 0
    m = seg_move[i] + seg_move[j]
    t0, t1 = np.zeros(len(i)), np.ones(len(i))
    d0 = _distance(old, new, a, b, i, j, t0)
    d1 = _distance(old, new, a, b, i, j, t1)
    for _ in range(DEPTH):
        open_ = (d0 + d1 - m * (t1 - t0)) <= 0
        if not open_.any():
            return 0
        i, j, m, t0, t1, d0, d1 = (v[open_] for v in (i, j, m, t0, t1, d0, d1))
        mid = (t0 + t1) / 2
        dm = _distance(old, new, a, b, i, j, mid)
        i, j, m = np.concatenate([i, i]), np.concatenate([j, j]), np.concatenate([m, m])
        t0, t1 = np.concatenate([t0, mid]), np.concatenate([mid, t1])
        d0, d1 = np.concatenate([d0, dm]), np.concatenate([dm, d1])
    return len(np.unique(i * (int(yarn.size) + 1) + j))
