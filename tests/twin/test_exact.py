"""The twin's numbers: exact decimals, the 2^-32 mm grid and its range."""

from __future__ import annotations

from fractions import Fraction

import pytest

from bwsd.errors import TwinError
from bwsd.twin.exact import LIMIT_MM, SCALE, as_bytes, decimal_float, exact, to_grid, to_mm


def test_a_float_stands_for_the_decimal_it_prints_as():
    assert exact(2.54) == Fraction(254, 100) != Fraction(2.54)
    assert exact(0.1) == Fraction(1, 10)
    assert exact(-0.0) == 0 and exact(7) == 7
    with pytest.raises(ValueError):
        exact(float("inf"))


@pytest.mark.parametrize("text", ["2.54", "1e-3", "-7", "123456789012345", "0.1", "1.50", "-0"])
def test_decimals_a_float_carries_are_kept(text):
    assert exact(decimal_float(text)) == Fraction(text)


@pytest.mark.parametrize(
    "text", ["0.30000000000000001", "1.0000000000000000001", "1e999", "1e-400", "inf", "nan", "x"]
)
def test_decimals_no_float_carries_are_refused(text):
    with pytest.raises(ValueError, match=r"kept exactly|not a|finite"):
        decimal_float(text)


def test_rounding_to_the_grid_is_nearest_with_ties_to_even():
    half = Fraction(1, 2 * SCALE)
    assert to_grid(Fraction(0)) == 0
    assert to_grid(half) == 0 and to_grid(3 * half) == 2 and to_grid(-3 * half) == -2
    assert to_grid(half + Fraction(1, 10**30)) == 1
    assert to_grid(Fraction(100, 3)) == 143165576533
    assert to_mm(143165576533) == 143165576533 / SCALE


def test_the_range_is_strictly_below_2_to_the_20_mm():
    assert to_grid(Fraction(LIMIT_MM) - Fraction(1, SCALE)) == LIMIT_MM * SCALE - 1
    with pytest.raises(TwinError, match=r"beyond the twin's range of 2\^20 mm"):
        to_grid(Fraction(LIMIT_MM))
    with pytest.raises(TwinError, match=r"a weft end of -1\.04858e\+06 mm"):
        to_grid(Fraction(-LIMIT_MM), "a weft end")


def test_integers_as_bytes():
    assert as_bytes(0) == b"\0"
    assert int.from_bytes(as_bytes(3 * 2**70 + 5), "little") == 3 * 2**70 + 5
