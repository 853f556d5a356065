"""The jammed yarn volume fraction of a 1 x 1 four-step braid of circular yarns, from the
unit-cell idealisation (docs/relax.md, "Against a unit-cell model"), to set beside the
relaxed preform's measured fraction.

In the interior of a four-step braid the yarns cross a section normal to the braid's axis
on a square grid (one carrier position each) and each runs along one of the grid's two
diagonals, at the yarn angle t to the axis. The cut of a circular yarn of diameter d is
then an ellipse, d across and d / cos t along its diagonal. Neighbours along a row or a
column run along the two different diagonals and are mirror images of each other; the
section is jammed when they touch, at the grid spacing

    s = d sqrt((1 + 1 / cos^2 t) / 2)

(neighbours along a diagonal, on one line, touch only at a spacing of d / (sqrt 2 cos t),
which is never more). The interior's fraction is one cut per s^2:

    Vf = (pi d^2 / (4 cos t)) / s^2 = pi cos t / (2 (1 + cos^2 t)),

pi / 4 for straight yarns (t = 0: a square packing of parallel cylinders). A whole section
puts the preform's carriers on that grid and is measured as ``bwsd.export.fraction`` measures
a section: the yarns' cuts over the convex hull of the discs of diameter d on the crossings.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from bwsd.export.fraction import hull_area


def jammed_spacing(d: float, angle: float) -> float:
    """The grid spacing (mm) at which neighbouring cuts of yarns of diameter ``d`` at
    ``angle`` degrees to the axis touch."""
    c = math.cos(math.radians(angle))
    return d * math.sqrt((1 + 1 / (c * c)) / 2)


def interior_fraction(angle: float) -> float:
    """The interior's jammed yarn volume fraction at the yarn angle ``angle`` (degrees)."""
    c = math.cos(math.radians(angle))
    return math.pi * c / (2 * (1 + c * c))


def section_fraction(cells: Iterable[tuple[int, int]], d: float, angle: float) -> float:
    """The jammed fraction of a whole section: a yarn on each carrier cell (row, col) of the
    grid at the jammed spacing, measured as the formed zone's fraction is."""
    s = jammed_spacing(d, angle)
    points = np.array([(col * s, row * s) for row, col in cells], dtype=float)
    cut = math.pi * d * d / 4 / math.cos(math.radians(angle))
    return len(points) * cut / hull_area(points, d / 2)


@dataclass(frozen=True)
class Comparison:
    """A relaxed four-step braid's formed-zone fraction beside the model's at its angle."""

    braid: str
    angle: float  # the relaxed formed zone's braid angle (warps, all), degrees
    relaxed: float  # its yarn volume fraction: the mean of its three heights
    model: float  # the model's whole section of the same carriers, at that angle
    interior: float  # the model's interior, at that angle

    @property
    def ratio(self) -> float:
        """Relaxed over model."""
        return self.relaxed / self.model


def compare(rows: int = 6, cols: int = 6, cycles: int = 12) -> Comparison:
    """Relax a rectangular braid4 (the generator's defaults otherwise; its config leaves the
    tensions at 1) and set its formed zone's fraction beside the model's."""
    from bwsd.export.formed import takeups_of
    from bwsd.export.metrics import metrics
    from bwsd.program.generators import braid4
    from bwsd.program.parser import parse_program
    from bwsd.relax import Options, relax
    from bwsd.twin import simulate

    generated = braid4(rows, cols, cycles=cycles)
    program = parse_program(generated.program)
    sk = simulate(generated.machine, program).skeleton()
    relaxed = relax(sk, Options()).skeleton
    found = metrics(relaxed, program.cycle_length, takeups=takeups_of(program))
    if found["angles"] is None or found["volume_fraction"] is None:
        raise ValueError(f"the relaxed {rows} x {cols} braid has no formed zone")
    angle = float(found["angles"]["warp"]["all"]["mean"])
    fractions = [h["fraction"] for h in found["volume_fraction"] if h["fraction"]]
    return Comparison(
        f"braid4 {rows} x {cols}, {cycles} cycles",
        angle,
        sum(fractions) / len(fractions),
        section_fraction(program.fill, sk.diameter, angle),
        interior_fraction(angle),
    )
