"""Exact orientation signs: a float filter with a proven bound, integers where it cannot decide.

``orient(p0, p1, p2, p3) = det[p1 - p0, p2 - p0, p3 - p0]``. The float value is computed as the
three 2x2 minors of two difference vectors dotted with the third, summed left to right.
Shewchuk's analysis of this form ("Adaptive Precision Floating-Point Arithmetic and Fast
Robust Geometric Predicates", 1997: o3derrboundA = (7 + 56 eps) eps, eps = 2**-53) bounds its
error by that constant times the permanent (the same sum with every product in absolute
value, itself computed in floating point). We use a slightly larger constant. Where |det|
does not exceed the bound, or the permanent is so small that underflow could void the
analysis, the sign is recomputed exactly from the same float64 inputs.

The float formulas are part of the contract: the sweep reuses these values for its
constructions, and the exact reference in the test suite repeats them operation by operation.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import numpy.typing as npt

Vec = tuple[float, float, float]
FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

ERRBOUND = 8.0e-16  # > (7 + 56 * 2**-53) * 2**-53 = 7.7716e-16
TINY = 1.0e-200  # below this permanent the float analysis is not trusted (underflow)


def _exact_scaled(p0: Vec, p1: Vec, p2: Vec, p3: Vec) -> tuple[int, int]:
    """The exact determinant as (integer numerator, power-of-two denominator).

    Every float64 is an integer times a power of two: scaling all twelve coordinates by the
    largest denominator turns them into integers, and Python's integers are exact.
    """
    ratios = [v.as_integer_ratio() for p in (p0, p1, p2, p3) for v in p]
    den = max(d for _, d in ratios)
    n = [num * (den // d) for num, d in ratios]
    ax, ay, az = n[3] - n[0], n[4] - n[1], n[5] - n[2]
    bx, by, bz = n[6] - n[0], n[7] - n[1], n[8] - n[2]
    cx, cy, cz = n[9] - n[0], n[10] - n[1], n[11] - n[2]
    det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
    return det, den**3


def exact_orient(p0: Vec, p1: Vec, p2: Vec, p3: Vec) -> Fraction:
    """det[p1 - p0, p2 - p0, p3 - p0] in exact rational arithmetic."""
    return Fraction(*_exact_scaled(p0, p1, p2, p3))


def exact_sign(p0: Vec, p1: Vec, p2: Vec, p3: Vec) -> int:
    """Sign of det[p1 - p0, p2 - p0, p3 - p0], exactly."""
    num, _ = _exact_scaled(p0, p1, p2, p3)
    return (num > 0) - (num < 0)


def orient(p0: Vec, p1: Vec, p2: Vec, p3: Vec) -> tuple[float, int, float]:
    """Float value, exact sign and error bound of det[p1 - p0, p2 - p0, p3 - p0]."""
    ox, oy, oz = p0
    ax, ay, az = p1[0] - ox, p1[1] - oy, p1[2] - oz
    bx, by, bz = p2[0] - ox, p2[1] - oy, p2[2] - oz
    cx, cy, cz = p3[0] - ox, p3[1] - oy, p3[2] - oz
    m0, m1 = ay * bz, az * by
    m2, m3 = az * bx, ax * bz
    m4, m5 = ax * by, ay * bx
    det = cx * (m0 - m1) + cy * (m2 - m3) + cz * (m4 - m5)
    perm = abs(cx) * (abs(m0) + abs(m1)) + abs(cy) * (abs(m2) + abs(m3))
    perm = perm + abs(cz) * (abs(m4) + abs(m5))
    bound = ERRBOUND * perm
    if det > bound and perm >= TINY:
        return det, 1, bound
    if -det > bound and perm >= TINY:
        return det, -1, bound
    return det, exact_sign(p0, p1, p2, p3), bound


class Plane:
    """The plane of a sweep triangle (b, a1, a2): side tests of one point or of many.

    Both give the float value of ``orient(b, a1, a2, x)`` (same formula as ``orient``), its
    exact sign, and whether x is known to lie exactly on the line a1-a2 (the guide path:
    other guides of the moving line sit there), whose sign is zero without any arithmetic.
    """

    def __init__(self, b: Vec, a1: Vec, a2: Vec) -> None:
        self.b, self.a1, self.a2 = b, a1, a2
        bx, by, bz = b
        ax, ay, az = a1[0] - bx, a1[1] - by, a1[2] - bz
        cx, cy, cz = a2[0] - bx, a2[1] - by, a2[2] - bz
        m0, m1, m2, m3, m4, m5 = ay * cz, az * cy, az * cx, ax * cz, ax * cy, ay * cx
        self.n = (m0 - m1, m2 - m3, m4 - m5)
        self.p = (abs(m0) + abs(m1), abs(m2) + abs(m3), abs(m4) + abs(m5))
        same = [a1[k] == a2[k] for k in range(3)]
        self.line_axes = [k for k in range(3) if same[k]] if sum(same) >= 2 else []

    def side(self, x: Vec) -> tuple[float, int, bool]:
        bx, by, bz = self.b
        cx, cy, cz = x[0] - bx, x[1] - by, x[2] - bz
        n0, n1, n2 = self.n
        p0, p1, p2 = self.p
        det = cx * n0 + cy * n1 + cz * n2
        perm = abs(cx) * p0 + abs(cy) * p1 + abs(cz) * p2
        bound = ERRBOUND * perm
        if perm >= TINY:
            if det > bound:
                return det, 1, False
            if -det > bound:
                return det, -1, False
        axes = self.line_axes
        if axes and all(x[k] == self.a1[k] for k in axes):
            return det, 0, True
        return det, exact_sign(self.b, self.a1, self.a2, x), False

    def sides(self, x: FloatArray) -> tuple[FloatArray, IntArray, BoolArray, FloatArray]:
        """``side`` for many points x (n, 3); also returns the error bounds of the values."""
        rel = x - np.array(self.b)
        n0, n1, n2 = self.n
        p0, p1, p2 = self.p
        det = rel[:, 0] * n0 + rel[:, 1] * n1 + rel[:, 2] * n2
        arel = np.abs(rel)
        perm = arel[:, 0] * p0 + arel[:, 1] * p1 + arel[:, 2] * p2
        bound = ERRBOUND * perm
        trusted = perm >= TINY
        sign = np.where(trusted & (det > bound), 1, np.where(trusted & (-det > bound), -1, 0))
        on_line = np.zeros(len(det), dtype=np.bool_)
        unsure = np.nonzero(sign == 0)[0]
        if unsure.size and self.line_axes:
            hit = np.ones(unsure.size, dtype=np.bool_)
            for k in self.line_axes:
                hit &= x[unsure, k] == self.a1[k]
            on_line[unsure] = hit
        for i in unsure[~on_line[unsure]].tolist():
            px, py, pz = x[i].tolist()
            sign[i] = exact_sign(self.b, self.a1, self.a2, (px, py, pz))
        return det, sign.astype(np.int64), on_line, bound
