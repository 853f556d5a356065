"""Interpenetration: how much yarn lies closer than one diameter to another yarn
(docs/exports.md, "interpenetration"). numpy only.

For a point of a yarn, the **overlap depth** is d minus its distance to the nearest
centreline of another yarn, where that distance is below d. Along a segment A(s),
s in [0, 1], the squared distance to a segment B is a convex function f(s): the distance to
B's line where the nearest point of the line lies on B, else the distance to B's nearer
end. So the part of A closer than d to B is one interval, found exactly from three
quadratics, and the part closer than d to any other yarn is the union of those intervals.
The depths along that union are sampled (at the middles of equal steps of at most d /
``SAMPLES``, two at least to a stretch) for the 95th percentile; the deepest overlap is
exact.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bwsd.export.arrays import Arrays
from bwsd.export.formed import Pieces
from bwsd.twin.skeleton import FloatArray, IntArray

SAMPLES = 16  # depth samples per yarn diameter along overlapping yarn (for the percentile)
TINY = 1e-30  # a quadratic term this small relative to |A|^2 is taken as (nearly) none


def dot(u: FloatArray, v: FloatArray) -> FloatArray:
    """Row-wise dot products of (3, n) arrays."""
    out: FloatArray = u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
    return out


def candidates(
    p0: FloatArray, p1: FloatArray, yarn: IntArray, d: float
) -> tuple[IntArray, IntArray]:
    """Pairs (i, j), i < j, of segments of different yarns that may come closer than d: cut
    into pieces of at most a median segment's length (and 4 d), their boxes grown by d / 2
    meet. Sweep and prune along the axis where the boxes overlap least."""
    if len(p0) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    length = np.linalg.norm(p1 - p0, axis=1)
    cut = max(4 * d, float(np.median(length)))
    parts = np.maximum(np.ceil(length / cut), 1).astype(np.int64)
    owner = np.repeat(np.arange(len(p0)), parts)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(parts) - parts, parts)
    step = (p1 - p0)[owner] / parts[owner][:, None]
    q0 = p0[owner] + k[:, None] * step
    i, j = _meeting(np.minimum(q0, q0 + step) - d / 2, np.maximum(q0, q0 + step) + d / 2)
    a, b = owner[i], owner[j]
    keep = yarn[a] != yarn[b]
    a, b = np.minimum(a[keep], b[keep]), np.maximum(a[keep], b[keep])
    key = np.unique(a * len(p0) + b)
    return key // len(p0), key % len(p0)


def _meeting(lo: FloatArray, hi: FloatArray) -> tuple[IntArray, IntArray]:
    """Pairs (i, j) of boxes [lo, hi] that meet (closed), each pair once."""
    span = np.maximum(hi.max(axis=0) - lo.min(axis=0), 1e-300)
    axes = np.argsort((hi - lo).sum(axis=0) / span)
    order = np.argsort(lo[:, axes[0]], kind="stable")
    lo, hi = lo[order], hi[order]
    end = np.searchsorted(lo[:, axes[0]], hi[:, axes[0]], side="right")
    count = np.maximum(end - np.arange(1, len(order) + 1), 0)
    i = np.repeat(np.arange(len(order)), count)
    j = i + 1 + np.arange(len(i)) - np.repeat(np.cumsum(count) - count, count)
    for k in axes[1:]:
        meet = (lo[j, k] <= hi[i, k]) & (lo[i, k] <= hi[j, k])
        i, j = i[meet], j[meet]
    return order[i], order[j]


def _below(
    a: FloatArray, b: FloatArray, c: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """{s in [lo, hi]: a s^2 + b s + c < 0}, a > 0, as (start, end); none when start >= end.
    A nearly vanishing a gives roots far out, which the range cuts."""
    disc = b * b - 4 * a * c
    root = np.sqrt(np.maximum(disc, 0.0))
    q = -0.5 * (b + np.where(b < 0, -root, root))
    with np.errstate(divide="ignore", invalid="ignore"):
        r1, r2 = q / a, c / q
    start = np.maximum(np.minimum(r1, r2), lo)
    end = np.where(disc > 0, np.minimum(np.maximum(r1, r2), hi), -np.inf)
    return start, end


@dataclass(frozen=True)
class Quads:
    """f(s) for directed pairs (A on B) as three quadratics a s^2 + b s + c: to B's first
    end, to its second end, and to its line, the last where the line's nearest point is on B
    (``inner``). Each is at least f everywhere and equals it on its own range."""

    coef: FloatArray  # (3, 3, n): quadratic, then a, b, c
    inner: tuple[FloatArray, FloatArray]

    @classmethod
    def of(cls, a0: FloatArray, a1: FloatArray, b0: FloatArray, b1: FloatArray) -> Quads:
        """The pairs of segments a0-a1 on b0-b1, points as (3, n) arrays."""
        u, v, w = a1 - a0, b1 - b0, a0 - b0
        uu, vv, uv = dot(u, u), dot(v, v), dot(u, v)
        wu, wv, ww = dot(w, u), dot(w, v), dot(w, w)
        e = w - v
        line_a = np.maximum(uu - uv * uv / vv, TINY * uu)
        coef = np.array(
            [
                (uu, 2 * wu, ww),
                (uu, 2 * dot(e, u), dot(e, e)),
                (line_a, 2 * (wu - wv * uv / vv), ww - wv * wv / vv),
            ]
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            sa, sb = -wv / uv, (vv - wv) / uv  # where the nearest point is B's first, last end
        inside = (wv >= 0) & (wv <= vv)
        lo = np.where(uv > 0, sa, np.where(uv < 0, sb, np.where(inside, -np.inf, np.inf)))
        hi = np.where(uv > 0, sb, np.where(uv < 0, sa, np.where(inside, np.inf, -np.inf)))
        return cls(coef, (lo, hi))

    def take(self, keep: IntArray) -> Quads:
        """The pairs ``keep``."""
        return Quads(self.coef[:, :, keep], (self.inner[0][keep], self.inner[1][keep]))

    def _range(self, k: int, lo: FloatArray, hi: FloatArray) -> tuple[FloatArray, FloatArray]:
        if k < 2:
            return lo, hi
        return np.maximum(lo, self.inner[0]), np.minimum(hi, self.inner[1])

    def below(self, r2: float, lo: FloatArray, hi: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The interval of s in [lo, hi] where f(s) < r2 (start >= end: none)."""
        start, end = np.full(len(lo), np.inf), np.full(len(lo), -np.inf)
        for k in range(3):
            a, b, c = self.coef[k]
            s0, s1 = _below(a, b, c - r2, *self._range(k, lo, hi))
            some = s0 < s1
            start = np.where(some, np.minimum(start, s0), start)
            end = np.where(some, np.maximum(end, s1), end)
        return start, end

    def at(self, which: IntArray, s: FloatArray) -> FloatArray:
        """f(s) of the pairs ``which`` at the points ``s``: the least of the two ends'
        quadratics and, where the nearest point of B's line is on B, the line's."""
        a, b, c = self.coef[:, :, which].transpose(1, 0, 2)  # each (quadratic, pair)
        value = (a * s + b) * s + c
        inner = (s >= self.inner[0][which]) & (s <= self.inner[1][which])
        line = np.where(inner, value[2], np.inf)
        out: FloatArray = np.maximum(np.minimum(np.minimum(value[0], value[1]), line), 0.0)
        return out

    def minimum(self, lo: FloatArray, hi: FloatArray) -> FloatArray:
        """The least f(s) over s in [lo, hi] (lo <= hi)."""
        best = np.full(len(lo), np.inf)
        for k in range(3):
            a, b, c = self.coef[k]
            r0, r1 = self._range(k, lo, hi)
            vertex = np.clip(-b / (2 * a), r0, r1)
            for s in (r0, r1, vertex):
                value = (a * s + b) * s + c
                best = np.where((r0 <= r1) & np.isfinite(s), np.minimum(best, value), best)
        return np.maximum(best, 0.0)


def merge(
    group: IntArray, start: FloatArray, end: FloatArray
) -> tuple[IntArray, FloatArray, FloatArray, IntArray]:
    """The union of each group's intervals (within [0, 1]) as disjoint intervals, by group
    and start; and for each given interval the index of the one holding it (-1: empty)."""
    order = np.flatnonzero(start < end)
    order = order[np.lexsort((start[order], group[order]))]
    g, s0, s1 = group[order], start[order], end[order]
    base = 4.0 * g  # a running maximum of end + base never leaks across groups
    reach = np.maximum.accumulate(s1 + base) if len(g) else s1
    before = np.concatenate([[-np.inf], reach[:-1]]) - base
    new = s0 > before
    first = np.flatnonzero(new)
    holder = np.full(len(group), -1, dtype=np.int64)
    holder[order] = np.cumsum(new) - 1
    joined = np.maximum.reduceat(s1, first) if len(first) else s1
    return g[first], s0[first], joined, holder


@dataclass(frozen=True)
class Overlaps:
    """The directed pairs (A on B, indices of fixed segments) closer than d, sorted by A,
    with their distance functions."""

    a: IntArray
    b: IntArray
    quads: Quads

    @classmethod
    def none(cls) -> Overlaps:
        """No pairs (yarns of no diameter overlap nothing)."""
        empty = np.zeros(0, np.int64)
        return cls(empty, empty, Quads(np.zeros((3, 3, 0)), (np.zeros(0), np.zeros(0))))

    @classmethod
    def of(cls, arrays: Arrays) -> Overlaps:
        d = arrays.sk.diameter
        real = np.flatnonzero(arrays.seg_length > 0)
        i, j = candidates(arrays.seg_p0[real], arrays.seg_p1[real], arrays.seg_yarn[real], d)
        i, j = real[i], real[j]
        p0, p1 = arrays.seg_t0, arrays.seg_t1
        near = Quads.of(p0[:, i], p1[:, i], p0[:, j], p1[:, j])
        close = near.minimum(np.zeros(len(i)), np.ones(len(i))) < d * d  # symmetric
        a, b = np.concatenate([i[close], j[close]]), np.concatenate([j[close], i[close]])
        order = np.argsort(a, kind="stable")
        a, b = a[order], b[order]
        return cls(a, b, Quads.of(p0[:, a], p1[:, a], p0[:, b], p1[:, b]))

    def stretches(self, d: float, lo: FloatArray, hi: FloatArray) -> Stretches:
        """The stretches of fixed segments closer than d to another yarn, each segment taken
        within its part [lo, hi]."""
        start, end = self.quads.below(d * d, lo[self.a], hi[self.a])
        segment, s0, s1, holder = merge(self.a, start, end)
        listed = np.flatnonzero(holder >= 0)
        return Stretches(segment, s0, s1, listed, holder[listed], start[listed], end[listed])

    def worst(self, d: float, lo: FloatArray, hi: FloatArray) -> FloatArray:
        """Per pair, the deepest overlap over A's part [lo, hi] (0 where that is empty)."""
        lo, hi = lo[self.a], hi[self.a]
        some = lo < hi
        least = self.quads.minimum(np.where(some, lo, 0.0), np.where(some, hi, 1.0))
        return np.where(some, np.maximum(d - np.sqrt(least), 0.0), 0.0)

    def depths(self, arrays: Arrays, found: Stretches, steps: IntArray) -> FloatArray:
        """The overlap depth at the samples of the stretches (``steps`` of each, at the
        middles of equal steps): d minus the least distance to the segments B of the pairs
        whose own interval holds the sample (the others are farther than d there)."""
        width = found.end - found.start
        first = np.cumsum(steps) - steps  # each stretch's first sample
        t = found.holder
        scale = steps[t] / np.where(width[t] > 0, width[t], 1.0)
        k0 = np.maximum(np.ceil((found.pair_start - found.start[t]) * scale - 0.5), 0)
        k1 = np.minimum(np.floor((found.pair_end - found.start[t]) * scale - 0.5), steps[t] - 1)
        count = np.maximum(k1 - k0 + 1, 0).astype(np.int64)
        pair = np.repeat(found.pairs, count)
        k = (
            np.repeat(k0.astype(np.int64), count)
            + np.arange(len(pair))
            - np.repeat(np.cumsum(count) - count, count)
        )
        stretch = np.repeat(t, count)
        at = found.start[stretch] + (k + 0.5) / steps[stretch] * width[stretch]
        least = np.full(int(steps.sum()), np.inf)
        np.minimum.at(least, first[stretch] + k, self.quads.at(pair, at))
        out: FloatArray = np.maximum(arrays.sk.diameter - np.sqrt(least), 0.0)
        return out


@dataclass(frozen=True)
class Stretches:
    """Disjoint stretches (``segment``, ``start``..``end``) of fixed segments closer than d
    to another yarn; the pairs (``pairs``) and the stretch holding each (``holder``), with
    the pair's own interval (``pair_start``..``pair_end``)."""

    segment: IntArray
    start: FloatArray
    end: FloatArray
    pairs: IntArray
    holder: IntArray
    pair_start: FloatArray
    pair_end: FloatArray


def weighted_percentile(values: FloatArray, weights: FloatArray, share: float) -> float:
    """The value that ``share`` of the total weight does not exceed, each sample standing
    for its weight centred on it, linear between them (``values`` in increasing order)."""
    total = float(weights.sum()) if len(weights) else 0.0
    if total <= 0:
        return 0.0
    middle = np.cumsum(weights) - weights / 2
    return float(np.interp(share * total, middle, values))


def _measure(
    lengths: FloatArray, over: FloatArray, worst: FloatArray, depth: FloatArray, weight: FloatArray
) -> dict[str, Any]:
    total, overlapping = float(lengths.sum()), float(over.sum())
    return {
        "length": total,
        "overlapping": overlapping,
        "share": overlapping / total if total > 0 else None,
        "worst": float(worst.max()) if len(worst) else 0.0,
        "p95": weighted_percentile(depth, weight, 0.95),
    }


def _families(
    arrays: Arrays,
    lengths: FloatArray,
    over: FloatArray,
    worst: FloatArray,
    pair_family: IntArray,
    depth: FloatArray,
    weight: FloatArray,
    sample_family: IntArray,
) -> dict[str, Any]:
    """The measures of all yarns and of each family."""
    family = arrays.seg_family
    out = {"all": _measure(lengths, over, worst, depth, weight)}
    for f in arrays.present():
        mine, pair, sample = family == f, pair_family == f, sample_family == f
        out[arrays.names[f]] = _measure(
            lengths[mine], over[mine], worst[pair], depth[sample], weight[sample]
        )
    return out


def interpenetration(arrays: Arrays, pieces: Pieces) -> dict[str, Any]:
    """Over the whole skeleton and over the formed zone, for all yarns and per family: the
    yarn length, the length closer than d to another yarn, its share, the deepest overlap
    and the 95th percentile of the depth over the overlapping length (docs/exports.md).

    The depth samples of the whole skeleton serve the formed zone too: those that lie in
    it (so the formed zone's percentile is resolved to a sample at its ends)."""
    d, count, length = arrays.sk.diameter, len(arrays.seg_a), arrays.seg_length
    lo, hi = np.ones(count), np.zeros(count)
    seg = pieces.segment.astype(np.int64)
    lo[seg], hi[seg] = pieces.s0, pieces.s1
    formed = np.where(hi > lo, hi - lo, 0.0) * length
    pairs = Overlaps.of(arrays) if d > 0 else Overlaps.none()
    found = pairs.stretches(d, np.zeros(count), np.ones(count))
    segment, width = found.segment, found.end - found.start
    over = np.bincount(segment, weights=width, minlength=count) * length
    inside = np.maximum(
        np.minimum(found.end, hi[segment]) - np.maximum(found.start, lo[segment]), 0.0
    )
    over_formed = np.bincount(segment, weights=inside, minlength=count) * length
    steps = np.maximum(np.ceil(width * length[segment] * SAMPLES / max(d, 1e-300)), 2)
    steps = steps.astype(np.int64)
    stretch = np.repeat(np.arange(len(segment)), steps)
    k = np.arange(len(stretch)) - np.repeat(np.cumsum(steps) - steps, steps)
    s = found.start[stretch] + (k + 0.5) / steps[stretch] * width[stretch]
    weight = (width * length[segment] / steps)[stretch]
    depth = pairs.depths(arrays, found, steps)
    order = np.argsort(depth)  # every percentile below reads these in increasing depth
    at, s, depth, weight = segment[stretch][order], s[order], depth[order], weight[order]
    in_formed = (s >= lo[at]) & (s <= hi[at])
    pf, sf = arrays.seg_family[pairs.a], arrays.seg_family[at]
    whole = pairs.worst(d, np.zeros(count), np.ones(count))
    return {
        "skeleton": _families(arrays, length, over, whole, pf, depth, weight, sf),
        "formed": _families(
            arrays,
            formed,
            over_formed,
            pairs.worst(d, lo, hi),
            pf,
            depth[in_formed],
            weight[in_formed],
            sf[in_formed],
        ),
    }
