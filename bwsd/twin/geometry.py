"""The machine's exact geometry on the grid: guides, fill start nodes, weft ends (docs/twin.md)."""

from __future__ import annotations

import math
from fractions import Fraction

from bwsd.errors import TwinError
from bwsd.twin.exact import MIN_LENGTH, SCALE, exact, to_grid
from bwsd.twin.instructions import Weft
from bwsd.twin.machine import Machine

Point = tuple[int, int, int]
MAX_CELLS = 1 << 22  # cells of the broad-phase grid

# (cos, sin) of multiples of 90 degrees, exactly
_QUARTERS = ((1, 0), (0, 1), (-1, 0), (0, -1))


class Geometry:
    """Guides, convergence and fill positions of one machine, each rounded once to the grid."""

    def __init__(self, machine: Machine) -> None:
        self.machine = machine
        self.pitch_x, self.pitch_y = exact(machine.pitch_x), exact(machine.pitch_y)
        self.d_mat, self.c_mat = exact(machine.d_mat), exact(machine.c_mat)
        if min(self.pitch_x, self.pitch_y) < MIN_LENGTH:
            raise TwinError(f"a pitch below {float(MIN_LENGTH):g} mm is too fine for the twin")
        self.gx = [to_grid(c * self.pitch_x, "a guide") for c in range(machine.cols)]
        self.gy = [to_grid(r * self.pitch_y, "a guide") for r in range(machine.rows)]
        self.ox = Fraction(machine.cols - 1, 2) * self.pitch_x
        self.oy = Fraction(machine.rows - 1, 2) * self.pitch_y

    def guide_z(self, takeup: Fraction) -> int:
        """The guides' height after a total take-up of ``takeup`` mm."""
        return to_grid(self.d_mat + takeup, "the guides' height")

    def fell(self, row: int, col: int, takeup: Fraction) -> Point:
        """Where a warp filled into (row, col) meets the fell: round(O + c_mat (G - O), T)."""
        gx, gy = Fraction(self.gx[col], SCALE), Fraction(self.gy[row], SCALE)
        return (
            to_grid(self.ox + self.c_mat * (gx - self.ox)),
            to_grid(self.oy + self.c_mat * (gy - self.oy)),
            to_grid(takeup),
        )

    def cell_shift(self) -> int:
        """log2 of the broad-phase cell size in grid units: about a pitch, enough cells."""
        pitch = min(self.pitch_x, self.pitch_y) * SCALE
        shift = max(1, math.floor(math.log2(pitch)))
        span_x = self.gx[-1] - self.gx[0]
        span_y = self.gy[-1] - self.gy[0]
        while ((span_x >> shift) + 5) * ((span_y >> shift) + 5) > MAX_CELLS:
            shift += 1
        return shift


def weft_ends(weft: Weft, takeup: Fraction) -> tuple[Point, Point]:
    """round(centre -/+ length / 2 (cos a, sin a, 0)), centre (x, y, T + z).

    cos and sin are exact for multiples of 90 degrees, else math.cos(math.radians(a)) and
    math.sin of the same, taken as exact.
    """
    angle = exact(weft.angle)
    if angle % 90 == 0:
        cos, sin = (Fraction(v) for v in _QUARTERS[int(angle // 90) % 4])
    else:
        rad = math.radians(weft.angle)
        cos, sin = Fraction(math.cos(rad)), Fraction(math.sin(rad))
    half = exact(weft.length) / 2
    x, y, z = exact(weft.x), exact(weft.y), takeup + exact(weft.z)
    if half < 0:
        raise TwinError("a weft's length must not be negative")
    return (
        (
            to_grid(x - half * cos, "a weft end"),
            to_grid(y - half * sin, "a weft end"),
            to_grid(z, "a weft end"),
        ),
        (
            to_grid(x + half * cos, "a weft end"),
            to_grid(y + half * sin, "a weft end"),
            to_grid(z, "a weft end"),
        ),
    )
