"""The shed check of a weft, exactly: refused when it passes closer than d to a yarn.

Distances are compared squared, in integers on the grid: the squared distance between two
segments is the minimum of a convex quadratic over [0, 1]^2, taken at the interior critical
point when that lies inside, else on one of the four edges (a clamped 1-D minimum there).
Every value is rational with integer numerator and denominator, so "closer than d" is an
integer comparison. Exactly d is allowed.
"""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction

Point = Sequence[int]


def _sub(a: Point, b: Point) -> tuple[int, int, int]:
    return a[0] - b[0], a[1] - b[1], a[2] - b[2]


def _dot(a: Sequence[int], b: Sequence[int]) -> int:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _to_point(p: Point, q0: Point, q1: Point) -> tuple[int, int]:
    """Squared distance from p to segment q0-q1 as (numerator, denominator)."""
    v, w = _sub(q1, q0), _sub(p, q0)
    vv, wv = _dot(v, v), _dot(w, v)
    if vv == 0 or wv <= 0:
        return _dot(w, w), 1
    if wv >= vv:
        r = _sub(p, q1)
        return _dot(r, r), 1
    r = (w[0] * vv - wv * v[0], w[1] * vv - wv * v[1], w[2] * vv - wv * v[2])
    return _dot(r, r), vv * vv


def distance2(p0: Point, p1: Point, q0: Point, q1: Point) -> Fraction:
    """The exact squared distance between segments p0-p1 and q0-q1 (grid units squared)."""
    u, v, w = _sub(p1, p0), _sub(q1, q0), _sub(p0, q0)
    a, b, c, d, e = _dot(u, u), _dot(u, v), _dot(v, v), _dot(u, w), _dot(v, w)
    den = a * c - b * b
    if den > 0:
        s, t = b * e - c * d, a * e - b * d
        if 0 <= s <= den and 0 <= t <= den:
            r = (
                w[0] * den + s * u[0] - t * v[0],
                w[1] * den + s * u[1] - t * v[1],
                w[2] * den + s * u[2] - t * v[2],
            )
            return Fraction(_dot(r, r), den * den)
    return min(
        Fraction(*_to_point(p0, q0, q1)),
        Fraction(*_to_point(p1, q0, q1)),
        Fraction(*_to_point(q0, p0, p1)),
        Fraction(*_to_point(q1, p0, p1)),
    )


def closest(
    p0: Point, p1: Point, segments: Sequence[tuple[int, Point, Point]], limit: Fraction
) -> tuple[int, Fraction] | None:
    """Among ``segments`` (yarn, c, d), the nearest one closer than ``limit`` (grid units) to
    p0-p1, as (yarn, squared distance); ties go to the smaller yarn id. None if none is."""
    bound = limit * limit
    best: tuple[Fraction, int] | None = None
    for yarn, c, d in segments:
        gap = distance2(p0, p1, c, d)
        if gap < bound and (best is None or (gap, yarn) < best):
            best = (gap, yarn)
    return None if best is None else (best[1], best[0])
