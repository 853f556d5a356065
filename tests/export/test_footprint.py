"""The footprint's discs counted as runs of sample rows: exactly the samples a per-sample
test of distance finds."""

from __future__ import annotations

import numpy as np
import pytest

from bwsd.export.footprint import Grid, disc_rows, disc_samples
from bwsd.twin import Machine

pytestmark = pytest.mark.slow  # every test here is in the slow tier


@pytest.mark.parametrize("diameter", [0.5, 1.0, 1.5])
def test_runs_hold_every_sample_within_the_radius_and_no_other(diameter):
    machine = Machine(6, 6, 10.0, 10.0, 150.0, 0.4)
    grid = Grid.of(machine, diameter)
    rng = np.random.default_rng(7)
    centres = np.vstack([rng.uniform(0, 60, (60, 2)), [[30.0, 30.0], [30.0, 30.0]]])
    i, j = disc_samples(centres, diameter / 2, grid)
    found = set(zip(i.tolist(), j.tolist(), strict=True))
    assert len(found) == len(i)  # distinct
    # every sample near a centre, tested one by one
    r = diameter / 2
    expected = set()
    for cx, cy in centres:
        ix = np.arange(int((cx - r - grid.x0) / grid.hx) - 2, int((cx + r - grid.x0) / grid.hx) + 3)
        iy = np.arange(int((cy - r - grid.y0) / grid.hy) - 2, int((cy + r - grid.y0) / grid.hy) + 3)
        x = grid.x0 + (ix + 0.5) * grid.hx
        y = grid.y0 + (iy + 0.5) * grid.hy
        near = (x[:, None] - cx) ** 2 + (y[None, :] - cy) ** 2 <= r * r
        expected |= {(int(ix[a]), int(iy[b])) for a, b in zip(*np.nonzero(near), strict=True)}
    assert found == expected
    rows, lo, hi = disc_rows(centres, r, grid)
    assert int((hi - lo + 1).sum()) == len(expected)
    order = np.lexsort((lo, rows))
    assert np.array_equal(order, np.arange(len(rows)))  # by row, then first sample
    same_row = rows[1:] == rows[:-1]
    assert (lo[1:][same_row] > hi[:-1][same_row] + 1).all()  # disjoint, not even touching
