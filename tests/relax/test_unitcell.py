"""The relaxed four-step braid's volume fraction against the jammed unit-cell model
(docs/relax.md, "Against a unit-cell model"); the model checked on its own geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bwsd.program.generators import braid4
from bwsd.program.parser import parse_program
from bwsd.relax.unitcell import compare, interior_fraction, jammed_spacing, section_fraction

pytestmark = pytest.mark.slow  # every test here is in the slow tier

D = 1.0


def _cuts(spacing: float, angle: float, n: int = 600) -> tuple[float, int]:
    """The interior's section drawn point by point: the share of a periodic 2 x 2 block of
    the grid covered by the yarns' cuts, and how many points two cuts cover.

    Each carrier's yarn is a cylinder of diameter D at ``angle`` to the axis, running along
    one diagonal of the grid: (+, +) at (even, even), (-, -) at (odd, odd), (+, -) at
    (even, odd) and (-, +) at (odd, even), as the four-step braid's carriers move. A point is
    in a yarn when it lies within D / 2 of its centreline, measured in 3-D."""
    t = math.radians(angle)
    side = 2 * spacing
    grid = (np.arange(n) + 0.5) / n * side
    px, py = np.meshgrid(grid, grid)
    points = np.stack([px.ravel(), py.ravel(), np.zeros(px.size)], axis=1)
    count = np.zeros(len(points), dtype=int)
    for i, j, sx, sy in ((0, 0, 1, 1), (1, 1, -1, -1), (0, 1, 1, -1), (1, 0, -1, 1)):
        axis = np.array([sx * math.sin(t) / math.sqrt(2), sy * math.sin(t) / math.sqrt(2), 0.0])
        axis[2] = math.cos(t)
        inside = np.zeros(len(points), dtype=bool)
        for di in (-1, 0, 1):  # the block's neighbours, so that the block is periodic
            for dj in (-1, 0, 1):
                centre = np.array([(i + 2 * di) * spacing, (j + 2 * dj) * spacing, 0.0])
                rel = points - centre
                along = rel @ axis
                off = np.linalg.norm(rel - along[:, None] * axis, axis=1)
                inside |= off <= D / 2
        count += inside
    return float((count > 0).mean()), int((count > 1).sum())


@pytest.mark.parametrize("angle", [0.0, 30.0, 59.3])
def test_the_model_formula_is_its_own_unit_cell_drawn_point_by_point(angle):
    spacing = jammed_spacing(D, angle)
    covered, twice = _cuts(spacing, angle)
    assert twice == 0  # jammed: the cuts touch, none overlaps another
    assert covered == pytest.approx(interior_fraction(angle), rel=5e-3)
    _, closer = _cuts(0.98 * spacing, angle)
    assert closer > 0  # 2 % closer, neighbours overlap: the spacing is the least


def test_the_model_at_its_limits():
    # straight yarns: a square packing of parallel cylinders, pi / 4
    assert interior_fraction(0.0) == pytest.approx(math.pi / 4)
    assert jammed_spacing(D, 0.0) == pytest.approx(D)
    # the fraction falls as the yarns lean: a cut is longer than the room a row gives it
    values = [interior_fraction(a) for a in range(0, 90, 5)]
    assert values == sorted(values, reverse=True)
    # a small section holds less than the interior (its rim counts, the boundary carriers'
    # rows are half full); a large one tends to it (the hull runs through the outer
    # yarns' centres, widened by d / 2, so it may hold a little more)
    fill = parse_program(braid4(6, 6, cycles=1).program).fill
    assert len(fill) == 48
    small = section_fraction(fill, D, 59.3)
    big = section_fraction([(r, c) for r in range(200) for c in range(200)], D, 59.3)
    assert small < interior_fraction(59.3) and small < big
    assert big == pytest.approx(interior_fraction(59.3), rel=0.02)


@pytest.mark.xfail(
    strict=True,
    reason="missed: a relaxed 6 x 6 braid4 of 12 cycles holds 6.2 % yarn in its formed zone "
    "at 59.3 degrees, the jammed model 58.5 % (ratio 0.11): the ends stay at the guides "
    "(docs/relax.md, Limits)",
)
def test_a_relaxed_four_step_braid_reaches_the_jammed_fraction_within_25_percent():
    found = compare(6, 6, 12)
    assert 0.0 < found.relaxed < 1.0 and 0.0 < found.model < found.interior
    assert 0.75 <= found.ratio <= 1.25, found
