"""Segment geometry for the relaxation, vectorised over pairs (numpy only)."""

from __future__ import annotations

import numpy as np

from bwsd.export.overlap import candidates
from bwsd.twin.skeleton import FloatArray, IntArray

EPS = 1e-300


def closest(
    p0: FloatArray, p1: FloatArray, q0: FloatArray, q1: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """For segment pairs p0-p1, q0-q1 ((n, 3) each): the parameters s, t (0..1) of their
    closest points and the distance between them."""
    u, v, w = p1 - p0, q1 - q0, p0 - q0
    a = np.einsum("ij,ij->i", u, u)
    b = np.einsum("ij,ij->i", u, v)
    c = np.einsum("ij,ij->i", v, v)
    e = np.einsum("ij,ij->i", u, w)
    f = np.einsum("ij,ij->i", v, w)
    den = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(den > 1e-12 * a * c, (b * f - c * e) / den, 0.0)
    s = np.clip(np.nan_to_num(s), 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(c > EPS, (b * s + f) / c, 0.0)
    t = np.nan_to_num(t)
    low, high = t < 0, t > 1
    t = np.clip(t, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s_low = np.where(a > EPS, -e / a, 0.0)
        s_high = np.where(a > EPS, (b - e) / a, 0.0)
    s = np.where(low, np.clip(np.nan_to_num(s_low), 0, 1), s)
    s = np.where(high, np.clip(np.nan_to_num(s_high), 0, 1), s)
    gap = (p0 + s[:, None] * u) - (q0 + t[:, None] * v)
    return s, t, np.sqrt(np.einsum("ij,ij->i", gap, gap))


def near_pairs(
    p0: FloatArray, p1: FloatArray, yarn: IntArray, reach: float
) -> tuple[IntArray, IntArray]:
    """Pairs (i, j), i < j, of segments of different yarns that may come within ``reach``."""
    return candidates(p0, p1, yarn, reach)
