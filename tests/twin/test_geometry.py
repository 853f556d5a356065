"""The machine's exact geometry: guides, fill start nodes and weft ends, each rounded once."""

from __future__ import annotations

import math
from fractions import Fraction

import pytest

from bwsd.errors import TwinError
from bwsd.twin import Machine, Weft
from bwsd.twin.exact import SCALE
from bwsd.twin.geometry import Geometry, weft_ends


def test_guides_are_the_exact_decimals_rounded_once():
    geo = Geometry(Machine(rows=3, cols=4, pitch_x=2.54, pitch_y=0.1, d_mat=100.3, c_mat=0.3))
    assert geo.gx == [round(c * Fraction(254, 100) * SCALE) for c in range(4)]
    assert geo.gy == [round(r * Fraction(1, 10) * SCALE) for r in range(3)]
    assert geo.guide_z(Fraction(1, 10)) == round(Fraction(1004, 10) * SCALE)
    assert geo.gy[1] == 429496730  # 0.1 * 2^32 = 429496729.6


def test_a_pitch_is_its_decimal_not_the_nearest_float():
    """1.0000180559 * 2^32 lies so near a midpoint that the nearest float rounds the other way."""
    pitch = 1.0000180559
    geo = Geometry(Machine(rows=1, cols=2, pitch_x=pitch, pitch_y=1, d_mat=10, c_mat=0.5))
    assert geo.gx[1] == 4295044845
    assert round(Fraction(pitch) * SCALE) == 4295044846


def test_the_fill_start_converges_from_the_rounded_guide():
    machine = Machine(rows=2, cols=3, pitch_x=10, pitch_y=7, d_mat=100, c_mat=0.3)
    geo = Geometry(machine)
    ox, oy = Fraction(10), Fraction(7, 2)
    x = ox + Fraction(3, 10) * (Fraction(geo.gx[2], SCALE) - ox)
    y = oy + Fraction(3, 10) * (Fraction(geo.gy[0], SCALE) - oy)
    assert geo.fell(0, 2, Fraction(5)) == (round(x * SCALE), round(y * SCALE), 5 * SCALE)


def test_weft_ends_are_exact_on_right_angles_and_float_otherwise():
    for angle, direction in ((0, (1, 0)), (90, (0, 1)), (180, (-1, 0)), (-90, (0, -1))):
        p0, p1 = weft_ends(Weft(x=5, y=6, z=7, angle=angle, length=4), Fraction(1))
        assert p1 == ((5 + 2 * direction[0]) * SCALE, (6 + 2 * direction[1]) * SCALE, 8 * SCALE)
        assert p0 == ((5 - 2 * direction[0]) * SCALE, (6 - 2 * direction[1]) * SCALE, 8 * SCALE)
    _, p1 = weft_ends(Weft(x=0, y=0, z=0, angle=30, length=2), Fraction(0))
    cos = Fraction(math.cos(math.radians(30)))
    assert p1[0] == round(cos * SCALE)
    with pytest.raises(TwinError, match="length"):
        weft_ends(Weft(x=0, y=0, z=0, angle=0, length=-1), Fraction(0))


def test_limits_of_the_grid():
    with pytest.raises(TwinError, match=r"a guide of 1\.04858e\+06 mm"):
        Geometry(Machine(rows=1, cols=2, pitch_x=2.0**20, pitch_y=1, d_mat=1, c_mat=0.5))
    with pytest.raises(TwinError, match="too fine"):
        Geometry(Machine(rows=1, cols=2, pitch_x=1e-7, pitch_y=1, d_mat=1, c_mat=0.5))


def test_the_broad_phase_cells_follow_the_pitch_and_stay_few():
    small = Geometry(Machine(rows=4, cols=4, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5))
    assert 2 ** small.cell_shift() <= 10 * SCALE < 2 ** (small.cell_shift() + 1)
    big = Geometry(Machine(rows=1000, cols=1000, pitch_x=0.01, pitch_y=0.01, d_mat=1, c_mat=0.5))
    span = big.gx[-1] >> big.cell_shift()
    assert (span + 5) ** 2 <= 1 << 22
