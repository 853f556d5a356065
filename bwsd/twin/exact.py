"""The twin's numbers: exact decimals in, coordinates on the 2^-32 mm grid (docs/twin.md).

A number a user writes (config, program, a generator's parameter) is an exact decimal. The
project carries it as a Python float whose shortest repr is that decimal, so its exact value
is ``Fraction(repr(x))``: 2.54 is 254/100, not the nearest binary fraction. The parsers refuse
a decimal that no float carries this way (more than 15 significant digits can be lost).

Every coordinate of the twin is an integer q meaning q * 2^-32 mm, with |q| < 2^52
(2^20 mm): such values and their differences are float64 numbers exactly.
"""

from __future__ import annotations

import math
from decimal import Decimal, InvalidOperation
from fractions import Fraction

from bwsd.errors import TwinError

GRID_BITS = 32
SCALE = 1 << GRID_BITS  # grid points per millimetre
LIMIT_MM = 1 << 20  # coordinates stay strictly below this magnitude
LIMIT = LIMIT_MM * SCALE
MAX_DIAMETER = 1024  # mm: the kernel's exact fallbacks are sized for a diameter below this
MIN_LENGTH = Fraction(1, 10**6)  # mm: the smallest pitch and nonzero yarn diameter


def exact(x: float | int | Fraction) -> Fraction:
    """The exact value of a number: a float stands for the decimal it prints as."""
    if isinstance(x, Fraction):
        return x
    if isinstance(x, int):
        return Fraction(x)
    if not math.isfinite(x):
        raise ValueError(f"{x!r} is not a finite number")
    return Fraction(repr(float(x)))


def decimal_float(text: str) -> float:
    """The float that carries the decimal ``text`` exactly; ValueError if none does."""
    try:
        value = Decimal(text)
    except InvalidOperation:
        raise ValueError(f"{text!r} is not a decimal number") from None
    if not value.is_finite():
        raise ValueError(f"{text!r} is not a finite number")
    result = float(value)
    if not math.isfinite(result) or Decimal(repr(result)) != value:
        raise ValueError(
            f"{text!r} cannot be kept exactly: use at most 15 significant digits "
            "and a magnitude below 1e300"
        )
    return result + 0.0  # -0 is 0


def to_grid(value: Fraction, what: str = "a coordinate") -> int:
    """``value`` (mm) on the grid: the nearest multiple of 2^-32 mm, ties to even."""
    q = round(value * SCALE)
    if abs(q) >= LIMIT:
        raise TwinError(f"{what} of {float(value):.6g} mm is beyond the twin's range of 2^20 mm")
    return q


def to_mm(q: int) -> float:
    """A grid value in millimetres (exact)."""
    return math.ldexp(q, -GRID_BITS)


def as_bytes(n: int) -> bytes:
    """A non-negative integer as little-endian bytes (at least one byte)."""
    return n.to_bytes(max(1, (n.bit_length() + 7) // 8), "little")
