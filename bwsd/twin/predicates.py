"""Exact orientation signs: a float filter with a proven bound, fractions where it cannot decide.

``orient(p0, p1, p2, p3) = det[p1 - p0, p2 - p0, p3 - p0]``. The float value is computed as the
three 2x2 minors of two difference vectors dotted with the third; Shewchuk's analysis of this
form ("Adaptive Precision Floating-Point Arithmetic and Fast Robust Geometric Predicates",
1997, bound o3derrboundA = (7 + 56 eps) eps * permanent, eps = 2**-53) bounds its error by
that constant times the permanent (the same sum with every product taken in absolute value).
We use a slightly larger constant. Where |det| does not exceed the bound, or the permanent is
so small that underflow could void the analysis, the sign is recomputed with exact rationals
from the same float64 inputs.
"""

from __future__ import annotations

# The float formulas below are part of the contract: the constructions of the sweep reuse
# these values, and the exact reference in the test suite recomputes them operation by
# operation, so they are written out in a fixed order.

from fractions import Fraction

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
SignArray = npt.NDArray[np.int8]

ERRBOUND = 8.0e-16  # > (7 + 56 * 2**-53) * 2**-53 = 7.7716e-16
TINY = 1.0e-200  # below this permanent the float analysis is not trusted (underflow)


def exact_orient(p0: FloatArray, p1: FloatArray, p2: FloatArray, p3: FloatArray) -> Fraction:
    """det[p1 - p0, p2 - p0, p3 - p0] in exact rational arithmetic."""
    o = [Fraction(float(v)) for v in p0]
    a = [Fraction(float(v)) - w for v, w in zip(p1, o, strict=True)]
    b = [Fraction(float(v)) - w for v, w in zip(p2, o, strict=True)]
    c = [Fraction(float(v)) - w for v, w in zip(p3, o, strict=True)]
    return (
        a[0] * (b[1] * c[2] - b[2] * c[1])
        + a[1] * (b[2] * c[0] - b[0] * c[2])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
    )


def _sign(value: Fraction) -> int:
    return (value > 0) - (value < 0)


def _minors(a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """a x b and the matching absolute 'permanent' minors, row-wise on (..., 3) arrays."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    p0, p1 = ay * bz, az * by
    p2, p3 = az * bx, ax * bz
    p4, p5 = ax * by, ay * bx
    cross = np.stack((p0 - p1, p2 - p3, p4 - p5), axis=-1)
    perm = np.stack(
        (np.abs(p0) + np.abs(p1), np.abs(p2) + np.abs(p3), np.abs(p4) + np.abs(p5)), axis=-1
    )
    return cross, perm


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    """Row-wise dot product summed left to right (no BLAS, no fused multiply-add)."""
    result: FloatArray = a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
    return result


def _finish(
    det: FloatArray,
    perm: FloatArray,
    points: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
) -> tuple[FloatArray, SignArray, FloatArray]:
    bound = ERRBOUND * perm
    sign = np.sign(det).astype(np.int8)
    unsure = np.nonzero((np.abs(det) <= bound) | (perm < TINY))[0]
    if unsure.size:
        p0, p1, p2, p3 = (np.broadcast_to(p, det.shape + (3,)) for p in points)
        for i in unsure.tolist():
            sign[i] = _sign(exact_orient(p0[i], p1[i], p2[i], p3[i]))
    return det, sign, bound


def side_signs(
    b: FloatArray, a1: FloatArray, a2: FloatArray, x: FloatArray
) -> tuple[FloatArray, SignArray, FloatArray]:
    """orient(b, a1, a2, x[i]) for one plane (b, a1, a2) and many points x (n, 3).

    Returns the float values (used for constructions only), their exact signs and the bound
    on the float values' error.
    """
    cross, perm3 = _minors(a1 - b, a2 - b)
    c = x - b
    det = _dot(c, cross)
    perm = _dot(np.abs(c), perm3)
    return _finish(det, perm, (b, a1, a2, x))


def edge_signs(
    c: FloatArray, d: FloatArray, q: FloatArray, r: FloatArray
) -> tuple[FloatArray, SignArray, FloatArray]:
    """orient(c[i], d[i], q, r) for many segments c-d (n, 3) and one edge q-r.

    Returns the float values, their exact signs and the bound on the float values' error.
    """
    u = d - c
    cross, perm3 = _minors(q - c, r - c)
    det = _dot(u, cross)
    perm = _dot(np.abs(u), perm3)
    return _finish(det, perm, (c, d, q, r))
