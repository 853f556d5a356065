"""The woven U's section against its nominal shape: legs, base, an empty opening, and a size
between the fell's and the guides' (docs/program.md, "Where the wefts go")."""

from __future__ import annotations

import numpy as np
import pytest

from bwsd.export.crossings import crossings
from bwsd.program import parse_program
from bwsd.program.weave import weave_3d
from bwsd.twin import simulate

pytestmark = pytest.mark.slow  # every test here is in the slow tier

LAYERS, WARPS, LEG, BASE = 5, 6, 2, 2


def test_the_woven_u_keeps_its_legs_base_and_opening_between_fell_and_guide_scale():
    gen = weave_3d(LAYERS, WARPS, cycles=10, shape="U", leg=LEG, base=BASE)
    m, p = gen.machine, gen.machine.pitch_x
    sk = simulate(m, parse_program(gen.program)).skeleton()
    warps = [y for y in sk.yarns if y.kind == "warp"]
    pinned = np.vstack([y.nodes[1:-1] for y in warps])
    lo, hi = np.quantile(pinned[:, 2], [0.25, 0.75])  # the formed part, away from both ends
    guides_x = [(2 * j + 1) * p for j in range(WARPS)]
    guides_y = [(2 * i + 1) * p for i in range(LAYERS)]
    guide_w, guide_h = guides_x[-1] - guides_x[0], guides_y[-1] - guides_y[0]
    # opening between the legs' inner warps, above the first base layer, half a pitch in
    x0, x1 = guides_x[LEG - 1] + p / 2, guides_x[WARPS - LEG] - p / 2
    y1 = guides_y[LAYERS - BASE] - p / 2
    for z in np.linspace(lo, hi, 7):
        points = np.array(
            [(c.x, c.y) for c in crossings(sk, float(z)) if sk.yarns[c.yarn].kind == "warp"]
        )
        assert len(points) == len(warps), z  # each warp crosses once
        width, height = np.ptp(points[:, 0]), np.ptp(points[:, 1])
        assert m.c_mat * guide_w <= width <= guide_w + 2 * m.yarn_diameter, (z, width)
        assert m.c_mat * guide_h <= height <= guide_h + 2 * m.yarn_diameter, (z, height)
        inside = (points[:, 0] > x0) & (points[:, 0] < x1) & (points[:, 1] < y1)
        assert not inside.any(), (z, points[inside])
        left = points[:, 0] < x0
        right = points[:, 0] > x1
        base = points[:, 1] > y1
        assert left.sum() == right.sum() == LEG * LAYERS
        assert base.sum() == WARPS * BASE
