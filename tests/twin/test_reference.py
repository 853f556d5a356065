"""Tests of the exact reference alone (tests/twin/reference.py), mirroring the module."""

from __future__ import annotations

import math
import random
import re
from collections.abc import Callable, Sequence
from decimal import Decimal, localcontext
from fractions import Fraction
from pathlib import Path
from typing import overload

import pytest

from bwsd.twin.instructions import Axis, Shift, TakeUp, Weft
from bwsd.twin.machine import Machine
from tests.twin.conftest import BRAID_CYCLE as BRAID_SHIFTS
from tests.twin.conftest import BRAID_FILL
from tests.twin.reference import (
    LIMIT,
    SCALE,
    MoveRefused,
    Point,
    RefTwin,
    ShedClosed,
    crossing,
    exact,
    rest_point,
    restart_point,
    round_grid,
    segment_distance2,
)

S = SCALE


@overload
def g(x: float | Fraction, y: float | Fraction, z: float | Fraction, /) -> Point: ...
@overload
def g(*mm: float | Fraction) -> tuple[int, ...]: ...
def g(*mm: float | Fraction) -> tuple[int, ...]:
    """Grid coordinates of a point given in mm (exact inputs)."""
    return tuple(round_grid(exact(v) if not isinstance(v, Fraction) else v) for v in mm)


def _point(rng: random.Random, span: int) -> Point:
    """A random grid point with coordinates in [-span, span]."""
    x, y, z = (rng.randint(-span, span) for _ in range(3))
    return x, y, z


# --- independence -------------------------------------------------------------------------


def test_the_reference_imports_only_the_input_data_classes_of_the_twin():
    source = Path(__file__).with_name("reference.py").read_text()
    imports = set(re.findall(r"^\s*(?:from|import)\s+(bwsd[\w.]*)", source, re.MULTILINE))
    assert imports == {"bwsd.twin.instructions", "bwsd.twin.machine"}


# --- numbers ------------------------------------------------------------------------------


def test_exact_reads_floats_as_the_decimal_they_print_as():
    assert exact(2.54) == Fraction(254, 100)
    assert exact(0.1) == Fraction(1, 10)
    assert exact(-1.5) == Fraction(-3, 2)
    assert exact(3) == 3 and isinstance(exact(3), Fraction)
    assert exact(1e-3) == Fraction(1, 1000)
    with pytest.raises(ValueError):
        exact(float("nan"))
    with pytest.raises(ValueError):
        exact(float("inf"))
    with pytest.raises(TypeError):
        exact("1")  # type: ignore[arg-type]  # a str on purpose


def test_round_grid_is_nearest_with_ties_to_even():
    half = Fraction(1, 2 * S)  # half a grid step
    assert round_grid(half) == 0
    assert round_grid(3 * half) == 2
    assert round_grid(5 * half) == 2
    assert round_grid(7 * half) == 4
    assert round_grid(-half) == 0
    assert round_grid(-3 * half) == -2
    assert round_grid(-5 * half) == -2
    assert round_grid(half + Fraction(1, 10**30)) == 1
    assert round_grid(-half - Fraction(1, 10**30)) == -1
    assert round_grid(Fraction(100, 3)) == 143165576533
    assert round_grid(-Fraction(100, 3)) == -143165576533
    assert round_grid(exact(2.54)) == 10909216932  # 2.54 * 2^32 = 10909216931.84
    assert round_grid(exact(0.1)) == 429496730  # 0.1 * 2^32 = 429496729.6
    assert round_grid(7) == 7 * S


def test_round_grid_refuses_coordinates_of_2_to_the_20_mm_and_beyond():
    assert round_grid(2**20 - Fraction(1, S)) == LIMIT - 1
    assert round_grid(-(2**20) + Fraction(1, S)) == -(LIMIT - 1)
    for v in (2**20, -(2**20), Fraction(2 * LIMIT - 1, 2 * S)):  # the last ties up to 2^52
        with pytest.raises(ValueError, match="2\\^20 mm"):
            round_grid(v)


def test_restart_point():
    a1, a2 = (0, 0, 0), (10, 7, -3)
    assert restart_point(a1, a2, Fraction(1)) == a2
    assert restart_point(a1, a2, Fraction(1, 2)) == (5, 4, -2)  # 3.5 -> 4, -1.5 -> -2
    assert restart_point(a1, a2, Fraction(1, 4)) == (2, 2, -1)  # 2.5 -> 2, 1.75, -0.75
    assert restart_point((1, 1, 1), (1, 1, 1), Fraction(1, 3)) == (1, 1, 1)


# --- rest_point ---------------------------------------------------------------------------


def _compare_sqrt(c: Fraction, n2: int, r: Fraction) -> int:
    """Sign of c / sqrt(n2) - r, exactly (n2 > 0), by squares."""
    left, right = (c > 0) - (c < 0), (r > 0) - (r < 0)  # signs of c and of r * sqrt(n2)
    if left != right:
        return 1 if left > right else -1
    if left == 0:
        return 0
    diff = c * c - r * r * n2  # |c| vs |r| sqrt(n2)
    sign = (diff > 0) - (diff < 0)
    return sign if left > 0 else -sign


def _is_rounding(x: int, y: int, c: Fraction, n2: int) -> bool:
    """x == round(y - c / sqrt(n2)), ties to even, checked by its defining inequalities.

    |y - w - x| <= 1/2 with w = c / sqrt(n2), i.e. y - x - 1/2 <= w <= y - x + 1/2, and at
    either bound (an exact tie) x must be even.
    """
    low = _compare_sqrt(c, n2, Fraction(2 * (y - x) - 1, 2))
    high = _compare_sqrt(c, n2, Fraction(2 * (y - x) + 1, 2))
    if low < 0 or high > 0:
        return False
    if low == 0 or high == 0:
        return x % 2 == 0
    return True


def _direction(m, u) -> tuple[tuple[int, int, int], int]:
    uu = sum(a * a for a in u)
    mu = sum(a * b for a, b in zip(m, u, strict=True))
    n = tuple(uu * a - mu * b for a, b in zip(m, u, strict=True)) if uu else tuple(m)
    return n, sum(a * a for a in n)


def _check_rest_point(y, m, u, d: Fraction) -> tuple[int, int, int]:
    x = rest_point(y, m, u, d)
    n, n2 = _direction(m, u)
    if d == 0 or n2 == 0:
        assert x == tuple(y)
        return x
    for k in range(3):
        assert _is_rounding(x[k], y[k], d * S * n[k], n2), (y, m, u, d, k, x)
    # An independent high-precision evaluation agrees wherever it is not (nearly) a tie.
    with localcontext() as ctx:
        ctx.prec = 150
        dd = Decimal((d * S).numerator) / Decimal((d * S).denominator)
        norm = Decimal(n2).sqrt()
        for k in range(3):
            v = Decimal(y[k]) - dd * Decimal(n[k]) / norm
            frac = v - v.to_integral_value(rounding="ROUND_FLOOR")
            if abs(frac - Decimal("0.5")) > Decimal("1e-100"):
                assert x[k] == int(v.to_integral_value(rounding="ROUND_HALF_EVEN"))
    return x


def test_rest_point_is_y_when_d_is_zero_or_n_vanishes():
    y = (123, -456, 789)
    assert rest_point(y, (5, 6, 7), (1, 0, 0), Fraction(0)) == y
    assert rest_point(y, (0, 0, 0), (1, 2, 3), Fraction(1)) == y  # no move
    assert rest_point(y, (2, 4, 6), (1, 2, 3), Fraction(1)) == y  # move along the hit segment
    assert rest_point(y, (-3, -6, -9), (1, 2, 3), Fraction(5)) == y


def test_rest_point_moves_back_against_the_move_by_d():
    # Move along +x, hit segment along y: n = +x, X = Y - d x.
    assert rest_point((0, 0, 0), (10 * S, 0, 0), (0, 5 * S, 0), Fraction(1)) == (-S, 0, 0)
    # The component along the hit segment is removed: m = (3, 4, 7), u along z -> n = (3, 4, 0).
    assert rest_point((0, 0, 0), (3, 4, 7), (0, 0, 2), Fraction(5)) == (-3 * S, -4 * S, 0)
    # u = 0 (degenerate hit segment): nothing to remove.
    assert rest_point((0, 0, 0), (0, -2, 0), (0, 0, 0), Fraction(1)) == (0, S, 0)


@pytest.mark.parametrize(
    ("y", "sign", "want"),
    [(0, 1, -2), (1, 1, 0), (2, 1, 0), (3, 1, 2), (0, -1, 2), (1, -1, 2), (-1, -1, 0)],
)
def test_rest_point_exact_ties_go_to_even_on_an_axis(y, sign, want):
    # d = 1.5 grid steps exactly, n along +-x: X = Y -+ 1.5, an exact tie every time.
    d = Fraction(3, 2 * S)
    assert _check_rest_point((y, 7, -7), (sign * 10, 0, 0), (0, 1, 0), d) == (want, 7, -7)


def test_rest_point_exact_ties_with_a_rational_norm():
    # n = (3, 4, 0), |n| = 5, d = 2.5 steps: d n / |n| = (1.5, 2, 0), a tie in x only.
    d = Fraction(5, 2 * S)
    assert _check_rest_point((0, 0, 0), (3, 4, 9), (0, 0, 1), d) == (-2, -2, 0)
    assert _check_rest_point((1, 1, 1), (3, 4, 9), (0, 0, 1), d) == (0, -1, 1)
    # n = (2, 3, 6), |n| = 7, d = 3.5 steps: (1, 1.5, 3).
    d = Fraction(7, 2 * S)
    assert _check_rest_point((0, 0, 0), (2, 3, 6), (0, 0, 0), d) == (-1, -2, -3)
    assert _check_rest_point((0, 1, 0), (-2, -3, -6), (0, 0, 0), d) == (1, 2, 3)
    # The same direction scaled, and with a component along u removed exactly.
    assert _check_rest_point((0, 0, 0), (20, 30, 60), (0, 0, 0), d) == (-1, -2, -3)
    assert _check_rest_point((0, 0, 0), (6, 8, 5), (0, 0, 7), Fraction(5, 2 * S)) == (-2, -2, 0)


def test_rest_point_against_brute_force_on_random_input():
    rng = random.Random(20240611)
    for _ in range(400):
        scale = rng.choice([1, 10, 1000, S, 50 * S])
        y = tuple(rng.randint(-(2**45), 2**45) for _ in range(3))
        m = tuple(rng.randint(-scale, scale) for _ in range(3))
        u = tuple(rng.randint(-scale, scale) for _ in range(3))
        if rng.random() < 0.2:  # axis-aligned pieces: many rational norms and ties
            m = tuple(v if rng.random() < 0.5 else 0 for v in m)
            u = tuple(v if rng.random() < 0.5 else 0 for v in u)
        d = rng.choice(
            [
                exact(round(rng.uniform(0, 5), rng.randint(0, 6))),
                Fraction(rng.randint(0, 20), 2 * S),
                exact(1.5),
            ]
        )
        _check_rest_point(y, m, u, d)


@pytest.mark.slow
def test_rest_point_on_small_random_input_rich_in_exact_ties():
    rng = random.Random(1)
    ties = 0
    for _ in range(1500):
        y = tuple(rng.randint(-1000, 1000) for _ in range(3))
        m = tuple(rng.choice([0, rng.randint(-9, 9)]) for _ in range(3))
        u = tuple(rng.choice([0, rng.randint(-9, 9)]) for _ in range(3))
        d = Fraction(rng.randint(0, 20), 2 * S)
        x = _check_rest_point(y, m, u, d)
        n, n2 = _direction(m, u)
        if d == 0 or n2 == 0:
            continue
        for k in range(3):
            c = d * S * n[k]
            bounds = (Fraction(2 * (y[k] - x[k]) + e, 2) for e in (-1, 1))
            ties += any(_compare_sqrt(c, n2, b) == 0 for b in bounds)  # an exact tie
            # neither neighbour of the result satisfies the definition
            assert not _is_rounding(x[k] - 1, y[k], c, n2)
            assert not _is_rounding(x[k] + 1, y[k], c, n2)
    assert ties > 100


# --- exact predicates: the contact test -----------------------------------------------------


def _volume(p: Point, q: Point, r: Point, s: Point) -> int:
    a = [q[k] - p[k] for k in range(3)]
    b = [r[k] - p[k] for k in range(3)]
    c = [s[k] - p[k] for k in range(3)]
    return (
        a[0] * (b[1] * c[2] - b[2] * c[1])
        - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
    )


def _crossing_by_orientations(
    b: Point, a1: Point, a2: Point, c: Point, d: Point
) -> tuple[Fraction, tuple[Fraction, ...]] | None:
    """The same rule, formulated with orientations of C-D against the triangle's edges."""
    sc, sd = _volume(b, a1, a2, c), _volume(b, a1, a2, d)
    if (sc >= 0) == (sd >= 0):
        return None
    wb, wa1, wa2 = _volume(c, d, a1, a2), _volume(c, d, a2, b), _volume(c, d, b, a1)
    sign = (wb > 0) - (wb < 0)
    if sign == 0 or (wa2 > 0) - (wa2 < 0) != sign or (wa1 > 0) - (wa1 < 0) not in (0, sign):
        return None
    total = wb + wa1 + wa2
    p = tuple(Fraction(wb * b[k] + wa1 * a1[k] + wa2 * a2[k], total) for k in range(3))
    return Fraction(wa2, wa1 + wa2), p


def test_crossing_agrees_with_an_orientation_formulation_on_degenerate_and_random_points():
    rng = random.Random(7)
    hits = 0
    for trial in range(6000):
        span = 2 if trial < 4000 else 1000  # a tiny grid: coplanar, collinear, shared points
        pts = [_point(rng, span) for _ in range(5)]
        got = crossing(*pts)
        want = _crossing_by_orientations(*pts)
        assert got == want, pts
        if got is not None:
            hits += 1
            assert 0 < got[0] <= 1
    assert hits > 300


# The triangle B=(0,0,0), A1=(0,0,100), A2=(10,0,100) lies in the plane y = 0; its normal
# (A1-B) x (A2-B) points to +y, so a point's side is the sign of its y (zero positive).
TB, TA1, TA2 = g(0, 0, 0), g(0, 0, 100), g(10, 0, 100)


def test_crossing_in_the_middle():
    found = crossing(TB, TA1, TA2, g(5, -10, 80), g(5, 10, 80))
    assert found is not None
    t, p = found
    assert t == Fraction(5, 8)
    assert p == tuple(Fraction(v) for v in g(5, 0, 80))


def test_crossing_on_the_final_edge_counts_and_on_the_initial_edge_or_apex_does_not():
    on_final_edge = crossing(TB, TA1, TA2, g(5, -10, 50), g(5, 10, 50))
    assert on_final_edge is not None and on_final_edge[0] == 1  # on B-A2
    assert crossing(TB, TA1, TA2, g(0, -10, 50), g(0, 10, 50)) is None  # on B-A1: t = 0
    assert crossing(TB, TA1, TA2, g(0, -10, 0), g(0, 10, 0)) is None  # through the apex
    assert crossing(TB, TA1, TA2, g(5, -10, 100), g(5, 10, 100)) is None  # on the path A1-A2
    assert crossing(TB, TA1, TA2, g(10, -10, 100), g(10, 10, 100)) is None  # through A2
    assert crossing(TB, TA1, TA2, g(6, -10, 50), g(6, 10, 50)) is None  # just outside


def test_crossing_at_a_node_is_counted_once():
    node = g(5, 0, 80)  # in the triangle, shared by two segments of one yarn
    before, after = g(4, -10, 80), g(6, 10, 80)
    assert crossing(TB, TA1, TA2, before, node) is not None  # from - to 0 (positive)
    assert crossing(TB, TA1, TA2, node, after) is None  # 0 (positive) to +
    assert crossing(TB, TA1, TA2, node, before) is not None  # either direction
    # A yarn that only touches the plane at the node and goes back is not crossed at all.
    assert crossing(TB, TA1, TA2, g(6, 10, 80), node) is None


def test_coplanar_segment_and_degenerate_triangle_are_never_a_contact():
    assert crossing(TB, TA1, TA2, g(3, 0, 80), g(7, 0, 80)) is None
    assert crossing(TB, TA1, TA2, g(-20, 0, 50), g(30, 0, 90)) is None
    assert crossing(TB, TA1, TA1, g(0, -1, 50), g(0, 1, 50)) is None  # A1 = A2
    assert crossing(TB, TA1, g(0, 0, 200), g(0, -1, 150), g(0, 1, 150)) is None  # collinear


# --- exact predicates: the distance between segments ----------------------------------------


def _f(pts: Sequence[Point], s: float | Fraction, t: float | Fraction) -> float | Fraction:
    p0, p1, q0, q1 = pts
    return sum((p0[k] + s * (p1[k] - p0[k]) - q0[k] - t * (q1[k] - q0[k])) ** 2 for k in range(3))


def _ternary(fn: Callable[[float], float], iters: int = 60) -> float:
    lo, hi = 0.0, 1.0
    for _ in range(iters):
        a, b = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        if fn(a) <= fn(b):
            hi = b
        else:
            lo = a
    return fn((lo + hi) / 2)


def _numeric_distance2(pts: list[Point]) -> float:
    """min over s of (min over t of f): nested ternary searches of a convex function."""

    def inner(s: float) -> float:
        return _ternary(lambda t: float(_f(pts, s, t)))

    return _ternary(inner)


def test_segment_distance_on_simple_cases():
    o = (0, 0, 0)
    assert segment_distance2(o, (10, 0, 0), (5, 3, -5), (5, 3, 5)) == 9  # crossing at distance 3
    assert segment_distance2(o, (10, 0, 0), (0, 2, 0), (10, 2, 0)) == 4  # parallel, overlapping
    assert segment_distance2(o, (10, 0, 0), (13, 4, 0), (20, 4, 0)) == 25  # parallel, apart
    assert segment_distance2(o, (10, 0, 0), (12, 0, 0), (20, 0, 0)) == 4  # collinear
    assert segment_distance2(o, o, (3, 4, 0), (3, 4, 0)) == 25  # two points
    assert segment_distance2(o, (10, 0, 0), (5, 0, 0), (5, 0, 0)) == 0  # a point on it
    assert segment_distance2(o, (10, 0, 0), (12, 1, -5), (12, 1, 5)) == 5  # end to interior
    assert segment_distance2((0, 0, 0), (2, 2, 0), (2, 0, 1), (0, 2, 1)) == 1
    assert segment_distance2((0, 0, 0), (1, 1, 0), (0, 1, 1), (1, 0, 1)) == 1


@pytest.mark.slow
def test_segment_distance_against_a_numeric_minimum_and_exact_bounds():
    rng = random.Random(11)
    for trial in range(80):
        span = 5 if trial < 40 else 10**6
        pts = [_point(rng, span) for _ in range(4)]
        if trial % 10 == 0:  # parallel segments
            x, y, z = (pts[2][k] + 2 * (pts[1][k] - pts[0][k]) for k in range(3))
            pts[3] = (x, y, z)
        got = segment_distance2(*pts)
        numeric = _numeric_distance2(pts)
        assert math.isclose(float(got), numeric, rel_tol=1e-9, abs_tol=1e-9 * span * span)
        for _ in range(20):  # never above any point of the square
            s, t = Fraction(rng.randint(0, 64), 64), Fraction(rng.randint(0, 64), 64)
            assert got <= _f(pts, s, t)


# --- the twin: worked example ---------------------------------------------------------------

WORKED = Machine(rows=2, cols=2, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5)
WORKED_CYCLE = [
    Shift("row", ((0, 1), (1, -1))),
    Shift("col", ((1, 1), (0, -1))),
    Shift("row", ((1, -1), (0, 1))),
    Shift("col", ((0, -1), (1, 1))),
]


def test_worked_example():
    ref = RefTwin(WORKED, [(0, 0), (1, 1)], 1)
    for ins in WORKED_CYCLE * 4:
        ref.run(ins)
    assert ref.done == 16
    assert len(ref.yarns) == 2
    assert len(ref.contacts) == 15
    assert len(ref.nodes) == 34
    first = ref.contacts[0]
    assert first == (2, 1, 5, 0, 4)  # Y then X, after the four fill nodes
    assert ref.nodes[4] == (5 * S, 5 * S, 143165576533)
    assert sorted(i for ids in ref.yarns for i in ids) == list(range(34))
    assert [c[0] for c in ref.contacts] == sorted(c[0] for c in ref.contacts)


def test_worked_example_first_contact_in_detail():
    ref = RefTwin(WORKED, [(0, 0), (1, 1)], 1)
    assert ref.nodes == [
        (5 * S // 2, 5 * S // 2, 0),
        (0, 0, 100 * S),
        (15 * S // 2, 15 * S // 2, 0),
        (10 * S, 10 * S, 100 * S),
    ]
    ref.run(WORKED_CYCLE[0])
    assert ref.contacts == []
    assert ref.nodes[1] == g(10, 0, 100) and ref.nodes[3] == g(0, 10, 100)
    ref.run(WORKED_CYCLE[1])
    # Yarn 1 moves from (0, 10) to (0, 0) and hits yarn 0's free segment, from its fell
    # (2.5, 2.5, 0) to its guide (10, 10, 100), at t = 1: Y splits that free segment.
    assert ref.contacts == [(2, 1, 5, 0, 4)]
    assert ref.yarns == [[0, 4, 1], [2, 5, 3]]
    assert ref.nodes[3] == g(0, 0, 100)
    # X = round(Y - d n / |n|), n = the move (0, -10, 0) without its part along (7.5, 7.5, 100).
    m, u = (0, -10 * S, 0), (15 * S // 2, 15 * S // 2, 100 * S)
    assert ref.nodes[5] == rest_point(ref.nodes[4], m, u, Fraction(1))
    axis = (7.5, 7.5, 100.0)
    along = -10 * axis[1] / sum(a * a for a in axis)
    n = [-along * axis[0], -10 - along * axis[1], -along * axis[2]]  # m - (m.a / a.a) a
    norm = math.sqrt(sum(a * a for a in n))
    x = ref.mm(5)
    assert all(isinstance(v, float) for v in x)
    for k, want in enumerate((5, 5, 100 / 3)):
        assert math.isclose(x[k], want - n[k] / norm, abs_tol=1e-9)
    assert ref.mm(4) == (5.0, 5.0, 143165576533 / 2**32)


BRAID = Machine(rows=4, cols=4, pitch_x=10, pitch_y=10, d_mat=150, c_mat=0.4)
BRAID_CYCLE = [*BRAID_SHIFTS, TakeUp(3.0)]


def test_braid_of_eight_carriers_is_deterministic_and_consistent():
    runs = []
    for _ in range(2):
        ref = RefTwin(BRAID, BRAID_FILL, 1.5)
        for ins in BRAID_CYCLE * 10:
            ref.run(ins)
        runs.append(ref)
    a, b = runs
    assert (a.nodes, a.yarns, a.contacts) == (b.nodes, b.yarns, b.contacts)
    # Pinned from this reference (a regression value, not a figure of docs/twin.md).
    assert (len(a.contacts), len(a.nodes)) == (73, 162)
    assert len(a.nodes) == 2 * len(BRAID_FILL) + 2 * len(a.contacts)
    assert a.takeup == 30
    for k, yarn in enumerate(a.yarns):  # every free node at its case's guide
        r, c = a.cell_of[k]
        assert a.nodes[yarn[-1]] == g(c * 10, r * 10, 180)


# --- the twin: hand-built sweeps ------------------------------------------------------------

# One warp in cell (0, 0) of a 1 x 3 matrix with its fell right below the guide (c_mat = 1):
# ROW 0:+1 sweeps the triangle TB, TA1, TA2 above (plane y = 0, side = sign of y).
LINE = Machine(rows=1, cols=3, pitch_x=10, pitch_y=10, d_mat=100, c_mat=1.0)
RIGHT = Shift("row", ((0, 1),))
LEFT = Shift("row", ((0, -1),))


def _line(diameter, *wefts: Weft) -> RefTwin:
    ref = RefTwin(LINE, [(0, 0)], diameter)
    for weft in wefts:
        ref.run(weft)
    return ref


def _spy(ref: RefTwin) -> list[tuple[Point, Point, Point, tuple[int, int]]]:
    """Record the triangles (B, A1, A2) the sweep asks about."""
    calls: list[tuple[Point, Point, Point, tuple[int, int]]] = []
    inner = ref._first_contact

    def spy(moving, b, a1, a2, skip):
        calls.append((b, a1, a2, skip))
        return inner(moving, b, a1, a2, skip)

    ref._first_contact = spy  # type: ignore[method-assign]  # the spy records each call
    return calls


def test_weft_crossing_the_triangle_in_the_middle_one_contact_restart_at_t():
    ref = _line(1, Weft(x=5, y=0, z=80, angle=90, length=20))
    assert ref.yarns == [[0, 1], [2, 3]]
    assert ref.nodes[2:] == [g(5, -10, 80), g(5, 10, 80)]
    calls = _spy(ref)
    ref.run(RIGHT)
    assert ref.contacts == [(2, 0, 5, 1, 4)]
    assert ref.yarns == [[0, 5, 1], [2, 4, 3]]
    assert ref.nodes[4] == g(5, 0, 80)  # Y = P
    assert ref.nodes[5] == g(4, 0, 80)  # X = Y - d x (the move is along +x)
    assert ref.nodes[1] == g(10, 0, 100)
    # t = 5/8: the second sub-sweep starts at A(t) = (6.25, 0, 100) from the apex X and skips
    # the two halves of the weft (the segments ending at Y).
    assert len(calls) == 2
    assert calls[0] == (g(0, 0, 0), g(0, 0, 100), g(10, 0, 100), (-1, -1))
    assert calls[1] == (g(4, 0, 80), g(6.25, 0, 100), g(10, 0, 100), (1, 4))


def test_the_new_apex_shields_what_the_old_triangle_would_have_hit():
    # (9, 0, 92) lies in the first triangle later than the first contact (t = 0.978), but the
    # yarn now bends at X = (4, 0, 80): from there to A2 it passes above (9, 0, 92).
    ref = _line(
        1,
        Weft(x=5, y=0, z=80, angle=90, length=20),
        Weft(x=9, y=0, z=92, angle=90, length=20),
    )
    ref.run(RIGHT)
    assert [c[3] for c in ref.contacts] == [1]
    # (7, 0, 95) lies inside the second triangle: it is hit next, from the new apex.
    ref = _line(
        1,
        Weft(x=5, y=0, z=80, angle=90, length=20),
        Weft(x=7, y=0, z=95, angle=90, length=20),
    )
    ref.run(RIGHT)
    assert [(c[3], c[4]) for c in ref.contacts] == [(1, 6), (2, 8)]
    assert ref.nodes[8] == g(7, 0, 95)
    assert ref.yarns[0] == [0, 7, 9, 1]  # X nodes in contact order, before the free node


@pytest.mark.parametrize("diameter", [0, 1])
def test_touch_of_the_final_edge_counts_once(diameter):
    ref = _line(diameter, Weft(x=5, y=0, z=50, angle=90, length=20))  # on the edge B-A2
    calls = _spy(ref)
    ref.run(RIGHT)
    assert ref.contacts == [(2, 0, 5, 1, 4)]
    assert ref.nodes[4] == g(5, 0, 50)
    assert ref.nodes[5] == g(5 - diameter, 0, 50)
    # t = 1: the restart point is A2 itself, the last triangle is degenerate.
    assert calls[1][1] == calls[1][2] == g(10, 0, 100)
    ref.run(LEFT)  # the move back does not count it again
    ref.run(RIGHT)  # nor does the same move again (the yarn now bends round the weft)
    assert len(ref.contacts) == 1
    assert ref.done == 4


def test_touch_of_the_initial_edge_does_not_count():
    # d = 0: a weft straight through the warp's centreline (allowed), then the warp moves away.
    ref = _line(0, Weft(x=0, y=0, z=50, angle=90, length=20))
    ref.run(RIGHT)
    assert ref.contacts == []
    assert ref.nodes[1] == g(10, 0, 100)


def test_crossing_exactly_at_a_weft_end():
    # y from -10 to 0: the end lies on the plane, counted positive: a crossing, Y at the end.
    ref = _line(1, Weft(x=5, y=-5, z=80, angle=90, length=10))
    ref.run(RIGHT)
    assert ref.contacts == [(2, 0, 5, 1, 4)]
    assert ref.nodes[4] == ref.nodes[3] == g(5, 0, 80)
    assert ref.yarns[1] == [2, 4, 3]
    # y from 0 to 10: both ends positive, no crossing.
    ref = _line(1, Weft(x=5, y=5, z=80, angle=90, length=10))
    ref.run(RIGHT)
    assert ref.contacts == []


def test_coplanar_weft_is_never_a_contact():
    ref = _line(1, Weft(x=5, y=0, z=80, angle=0, length=4))  # from (3,0,80) to (7,0,80)
    ref.run(RIGHT)
    ref.run(LEFT)
    assert ref.contacts == []
    assert ref.yarns == [[0, 1], [2, 3]]


@pytest.mark.parametrize("angles", [(90, 135), (135, 90)])
def test_hits_at_the_same_time_go_to_the_smaller_yarn_id(angles):
    # d = 0: two wefts through the same point of the triangle (their rounded ends are
    # symmetric about the centre), hit at the same t: the first inserted (yarn 1) wins; the
    # other then passes through the new apex X = Y, which is no contact.
    ref = _line(0, *(Weft(x=5, y=0, z=80, angle=a, length=20) for a in angles))
    ref.run(RIGHT)
    assert ref.contacts == [(3, 0, 7, 1, 6)]
    assert ref.nodes[6] == ref.nodes[7] == g(5, 0, 80)


def test_take_up_sweeps_every_warp_in_yarn_id_order():
    ref = RefTwin(WORKED, [(0, 0), (1, 1)], 0)
    calls = _spy(ref)
    ref.run(TakeUp(0.1))
    ref.run(TakeUp(0.1))
    ref.run(TakeUp(0.1))
    assert ref.takeup == Fraction(3, 10)
    z = round(Fraction(1003, 10) * S)
    assert ref.nodes[1] == (0, 0, z) and ref.nodes[3] == (10 * S, 10 * S, z)
    assert [c[1] for c in calls][:2] == [g(0, 0, 100), g(10, 10, 100)]
    assert calls[1][2] == (10 * S, 10 * S, round_grid(Fraction(1001, 10)))
    # New wefts and new fell positions are measured from the take-up.
    ref.run(Weft(x=1, y=2, z=3, angle=180, length=4))
    assert ref.nodes[4:6] == [g(3, 2, Fraction(33, 10)), g(-1, 2, Fraction(33, 10))]


def test_weft_directions_exact_on_right_angles_float_otherwise():
    ref = RefTwin(WORKED, [], 0)
    for angle, start, end in [
        (0, (-2, 0), (2, 0)),
        (90, (0, -2), (0, 2)),
        (-90, (0, 2), (0, -2)),
        (450.0, (0, -2), (0, 2)),
        (540, (2, 0), (-2, 0)),
    ]:
        ref.run(Weft(x=0, y=0, z=1, angle=angle, length=4))
        assert ref.nodes[-2:] == [g(*start, 1), g(*end, 1)]
    ref.run(Weft(x=0.1, y=0, z=1, angle=30, length=2.5))
    cos, sin = Fraction(math.cos(math.radians(30.0))), Fraction(math.sin(math.radians(30.0)))
    half = Fraction(5, 4)
    assert ref.nodes[-2] == (
        round((Fraction(1, 10) - half * cos) * S),
        round(-half * sin * S),
        S,
    )
    assert ref.nodes[-1] == (round((Fraction(1, 10) + half * cos) * S), round(half * sin * S), S)


# --- the twin: the shed check ---------------------------------------------------------------

# d = 1.25 and the warp of LINE along the z axis. Each weft passes exactly d from a yarn
# (grid-exact numbers): along y at x = 1.25 (interior point of both), along y from
# (0.75, 1) (its end: 0.75^2 + 1^2 = 1.25^2), along x 1.25 above the first weft (skew).
EXACTLY_D = [
    Weft(x=1.25, y=0, z=50, angle=90, length=20),
    Weft(x=0.75, y=3, z=20, angle=90, length=4),
    Weft(x=5, y=5, z=51.25, angle=0, length=10),
]
STEP = 2.0**-32  # one grid step: these floats print as decimals that round back to the grid
JUST_BELOW = [
    Weft(x=1.25 - STEP, y=0, z=50, angle=90, length=20),
    Weft(x=0.75, y=3 - STEP, z=20, angle=90, length=4),
    Weft(x=5, y=5, z=51.25 - STEP, angle=0, length=10),
]


def test_shed_check_allows_exactly_d():
    ref = _line(1.25, *EXACTLY_D)
    assert ref.done == 3
    assert (
        segment_distance2(ref.nodes[0], ref.nodes[1], ref.nodes[4], ref.nodes[5])
        == (Fraction(5, 4) * S) ** 2
    )


@pytest.mark.parametrize("k", range(3))
def test_shed_check_refuses_just_below_d_and_changes_nothing(k):
    ref = _line(1.25, *EXACTLY_D[:k])
    before = (list(ref.nodes), [list(y) for y in ref.yarns], ref.done)
    with pytest.raises(ShedClosed, match=f"1.24999999\\d* mm from yarn {0 if k < 2 else 1}\\b"):
        ref.run(JUST_BELOW[k])
    assert (ref.nodes, [list(y) for y in ref.yarns], ref.done) == before
    ref.run(EXACTLY_D[k])  # and the exact one still goes in
    assert ref.done == k + 1


def test_shed_check_never_refuses_with_d_zero():
    ref = _line(0, Weft(x=0, y=0, z=50, angle=0, length=20))  # through the warp
    ref.run(Weft(x=0, y=0, z=50, angle=90, length=20))  # through both
    assert ref.done == 2


# --- the twin: moves ------------------------------------------------------------------------


def test_leading_case_moves_first():
    ref = RefTwin(LINE, [(0, 0), (0, 1)], 0)
    calls = _spy(ref)
    ref.run(RIGHT)
    assert ref.case_at == {(0, 2): 1, (0, 1): 0}
    assert [c[2] for c in calls] == [g(20, 0, 100), g(10, 0, 100)]
    ref.run(LEFT)
    assert ref.case_at == {(0, 1): 1, (0, 0): 0}
    assert [c[2] for c in calls[2:]] == [g(0, 0, 100), g(10, 0, 100)]


def test_entries_in_the_order_written_on_current_cells():
    ref = RefTwin(LINE, [(0, 0)], 0)
    ref.run(Shift("row", ((0, 1), (0, 1))))  # the same case twice
    assert ref.case_at == {(0, 2): 0}
    assert ref.nodes[1] == g(20, 0, 100)


def test_refused_moves_change_nothing():
    ref = RefTwin(LINE, [(0, 0)], 0)
    with pytest.raises(MoveRefused, match="leave"):
        ref.run(Shift("row", ((0, 1), (0, 1), (0, 1))))  # the third would leave
    assert ref.case_at == {(0, 0): 0} and ref.nodes[1] == g(0, 0, 100) and ref.done == 0
    square = RefTwin(WORKED, [(0, 0), (0, 1), (1, 1)], 0)
    before = (list(square.nodes), dict(square.case_at), dict(square.cell_of))
    with pytest.raises(MoveRefused, match=r"cell \(0, 1\) would leave"):
        square.run(Shift("col", ((0, 1), (1, -1))))  # (0,0) -> (1,0) fine, then (0,1) leaves
    assert (square.nodes, square.case_at, square.cell_of, square.done) == (*before, 0)
    with pytest.raises(MoveRefused, match="outside"):
        square.run(Shift("row", ((2, 1),)))
    with pytest.raises(MoveRefused, match="leave"):
        square.run(Shift("col", ((1, 1),)))
    assert (square.nodes, square.case_at, square.cell_of, square.done) == (*before, 0)
    square.run(Shift("col", ((0, 1),)))
    assert square.case_at == {(1, 0): 0, (0, 1): 1, (1, 1): 2} and square.done == 1


def test_fill_and_range_errors():
    with pytest.raises(ValueError, match="outside"):
        RefTwin(WORKED, [(2, 0)], 0)
    with pytest.raises(ValueError, match="twice"):
        RefTwin(WORKED, [(0, 0), (0, 0)], 0)
    with pytest.raises(ValueError, match="2\\^20"):
        RefTwin(Machine(rows=1, cols=2, pitch_x=2**20, pitch_y=1, d_mat=1, c_mat=0.5), [], 0)
    ref = RefTwin(WORKED, [(0, 0)], 0)
    with pytest.raises(ValueError, match="2\\^20"):
        ref.run(TakeUp(2**20))
    assert ref.takeup == 0 and ref.nodes[1] == g(0, 0, 100) and ref.done == 0


def test_a_zero_move_sweeps_nothing():
    ref = _line(0, Weft(x=5, y=0, z=80, angle=90, length=20))
    ref.run(Shift("row", ((0, 0),)))
    ref.run(TakeUp(0))
    assert ref.contacts == [] and ref.done == 3


def test_random_programs_keep_the_bookkeeping_consistent():
    rng = random.Random(3)
    machine = Machine(rows=4, cols=4, pitch_x=7.5, pitch_y=6.25, d_mat=80, c_mat=0.3)
    for _ in range(3):
        cells = sorted(rng.sample([(r, c) for r in range(4) for c in range(4)], 7))
        ref = RefTwin(machine, cells, rng.choice([0, 0.5, 1.2]))
        ran = 0
        axes: list[Axis] = ["row", "col"]
        while ran < 25:
            ins: Shift | TakeUp | Weft
            kind = rng.random()
            if kind < 0.15:
                ins = TakeUp(rng.choice([1, 2.5]))
            elif kind < 0.25:
                ins = Weft(x=rng.uniform(0, 22), y=rng.uniform(0, 18), z=3, angle=30, length=8)
            else:
                axis = rng.choice(axes)
                ins = Shift(axis, ((rng.randrange(4), rng.choice([-1, 1])),))
            try:
                ref.run(ins)
            except (MoveRefused, ShedClosed):
                continue
            ran += 1
        assert ref.done == 25
        wefts = len(ref.yarns) - len(cells)
        assert len(ref.nodes) == 2 * len(cells) + 2 * wefts + 2 * len(ref.contacts)
        assert sorted(i for ids in ref.yarns for i in ids) == list(range(len(ref.nodes)))
        for index, moving, x, hit, y in ref.contacts:
            assert 1 <= index <= 25 and moving < len(cells) and hit != moving
            assert x in ref.yarns[moving][1:-1] and y in ref.yarns[hit][1:]
            assert x == y + 1
        for k in range(len(cells)):
            r, c = ref.cell_of[k]
            assert ref.nodes[ref.yarns[k][-1]][:2] == g(c * 7.5, r * 6.25)
