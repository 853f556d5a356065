"""Yarn volume fraction (docs/exports.md, "volume_fraction"): yarn cuts over the convex hull
of the yarn discs, at three heights of the formed zone."""

from __future__ import annotations

import math

import pytest

from bwsd.export.arrays import Arrays
from bwsd.export.formed import Zone
from bwsd.export.fraction import at_height, hull_area, volume_fraction

from .conftest import build, warp, weft

TOP = (0.0, 0.0, 500.0)  # the warps' free nodes, far above: free segments never count


def test_four_upright_yarns_on_a_square():
    s, d = 10.0, 1.0
    sk = build(
        [warp([(x, y, 0), (x, y, 50), TOP]) for x, y in ((0, 0), (s, 0), (0, s), (s, s))],
        diameter=d,
    )
    found = at_height(Arrays.of(sk), 20.0)
    disc = math.pi * d * d / 4
    assert found["crossings"] == 4
    assert found["yarn_area"] == pytest.approx(4 * disc)
    assert found["section_area"] == pytest.approx(s * s + 4 * s * d / 2 + disc)
    assert found["fraction"] == pytest.approx(4 * disc / (s * s + 2 * s * d + disc))


def test_an_inclined_yarn_cuts_an_ellipse_and_a_weft_near_the_plane_a_strip():
    d = 1.0
    slope = math.radians(60)
    top = (50 * math.tan(slope), 0, 50)
    sk = build(
        [
            warp([(0, 0, 0), top, TOP]),
            warp([(10, 0, 0), (10, 0, 50), TOP]),
            weft([(-5, 3, 20.3), (0, 3, 20.3), (10, 3, 20.3), (15, 3, 20.3)]),
        ],
        [(1, 0, 0, 2, 7), (2, 1, 3, 2, 8)],
        diameter=d,
    )
    found = at_height(Arrays.of(sk), 20.0)
    ellipses = math.pi * d * d / 4 * (1 / math.cos(slope) + 1)
    # the weft lies 0.3 mm above the plane: a strip 2 sqrt(0.25 - 0.09) = 0.8 mm wide along
    # its 10 mm between its outermost contacts (not its loose ends)
    assert found["yarn_area"] == pytest.approx(ellipses + 0.8 * 10)
    assert found["crossings"] == 2


def test_degenerate_sections():
    import numpy as np

    assert hull_area(np.zeros((0, 2)), 0.5) == 0.0
    assert hull_area(np.array([[1.0, 1.0]]), 0.5) == pytest.approx(math.pi / 4)
    line = np.array([[0.0, 0.0], [3.0, 4.0], [6.0, 8.0]])
    assert hull_area(line, 0.5) == pytest.approx(2 * 10 * 0.5 + math.pi / 4)


def test_three_heights_of_the_formed_zone_or_none():
    sk = build(
        [
            warp([(0, 0, 0), (0, 0, 40), TOP]),
            warp([(5, 0, 0), (5, 0, 40), TOP]),
            warp([(0, 5, 0), (0, 5, 40), TOP]),
        ]
    )
    arrays = Arrays.of(sk)
    heights = volume_fraction(arrays, Zone((10.0, 30.0), (2, 3), 4, ()))
    assert heights is not None
    assert [h["z"] for h in heights] == [15.0, 20.0, 25.0]
    assert volume_fraction(arrays, Zone(None, None, 2, (), "too short")) is None
