"""The exact squared distance between segments, and the nearest one closer than a limit."""

from __future__ import annotations

import itertools
import random
from fractions import Fraction

import pytest

from bwsd.twin.shed import closest, distance2


def _brute(p0, p1, q0, q1, steps=60) -> float:
    """A fine sampling of the distance, never below the true minimum."""
    best = float("inf")
    for i, j in itertools.product(range(steps + 1), repeat=2):
        s, t = i / steps, j / steps
        gap = [p0[k] + s * (p1[k] - p0[k]) - q0[k] - t * (q1[k] - q0[k]) for k in range(3)]
        best = min(best, sum(g * g for g in gap))
    return best


def test_simple_cases():
    assert distance2((0, 0, 0), (10, 0, 0), (5, -5, 3), (5, 5, 3)) == 9  # crossing, 3 apart
    assert distance2((0, 0, 0), (10, 0, 0), (0, 2, 0), (10, 2, 0)) == 4  # parallel
    assert distance2((0, 0, 0), (10, 0, 0), (13, 4, 0), (20, 4, 0)) == 25  # end to end
    assert distance2((0, 0, 0), (10, 0, 0), (5, 0, 0), (5, 0, 0)) == 0  # a point on it
    assert distance2((0, 0, 0), (0, 0, 0), (1, 1, 1), (1, 1, 1)) == 3
    assert distance2((0, 0, 0), (2, 2, 0), (0, 2, 1), (2, 0, 1)) == 1  # interior point


@pytest.mark.slow
def test_against_sampling_on_random_integer_segments():
    rng = random.Random(7)
    for _ in range(150):
        pts = [tuple(rng.randint(-20, 20) for _ in range(3)) for _ in range(4)]
        exact = distance2(*pts)
        assert isinstance(exact, Fraction)
        sampled = _brute(*pts)
        assert exact <= sampled + 1e-9
        assert sampled - float(exact) <= 2.0  # the sampling is fine enough to come close


def test_closest_refuses_below_the_limit_only_and_names_the_nearest():
    weft = ((0, 5, 0), (10, 5, 0))
    segs = [(3, (0, 7, 0), (10, 7, 0)), (1, (0, 3, 0), (10, 3, 0)), (2, (0, 9, 0), (9, 9, 0))]
    assert closest(*weft, segs, Fraction(2)) is None  # exactly 2 away is allowed
    nearest = closest(*weft, segs, Fraction(2) + Fraction(1, 10**9))
    assert nearest == (1, Fraction(4))  # tie: smaller id
    assert closest(*weft, segs[2:], Fraction(5)) == (2, Fraction(16))
