"""The preform's footprint at one height against the nominal shape of its section (numpy only).

The measured footprint is the union of discs of the yarn diameter centred where yarn
centrelines cross the plane z = Z (the crossings `bwsd slice` draws). The nominal shape is
the section's body cells mapped to the fell as the twin maps a guide, one tile of
``c_mat * pitch`` per cell. Areas are counted on a fine grid of sample points aligned with
those tiles (docs/exports.md, "footprint").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from bwsd.export.crossings import crossings
from bwsd.program.sections import Section
from bwsd.twin.machine import Machine
from bwsd.twin.skeleton import FloatArray, IntArray, SkeletonData

BoolArray = npt.NDArray[np.bool_]
SAMPLES_PER_DIAMETER = 64  # grid spacing at most d / 64: one disc's area within 1 %


def crossing_points(sk: SkeletonData, z: float) -> tuple[FloatArray, BoolArray]:
    """The (x, y) of every crossing of the plane z = Z (``crossings``), by yarn then along
    it, and whether each lies on a warp's free segment."""
    found = crossings(sk, z)
    if not found:
        return np.zeros((0, 2)), np.zeros(0, dtype=bool)
    xy: FloatArray = np.array([(c.x, c.y) for c in found], dtype=np.float64)
    return xy, np.array([c.free for c in found], dtype=bool)


@dataclass(frozen=True)
class Grid:
    """Sample points ``(x0 + (i + 0.5) hx, y0 + (j + 0.5) hy)``, aligned with the fell tiles.

    Each fell tile of ``c_mat * pitch`` holds exactly ``per_tile`` samples along each axis,
    and (x0, y0) is the corner of the tile of cell (0, 0): a tile boundary never passes
    through a sample. The spacing is the largest that divides the tile and is at most d / 64.
    """

    x0: float
    y0: float
    hx: float
    hy: float
    per_tile: tuple[int, int]

    @classmethod
    def of(cls, machine: Machine, diameter: float) -> Grid:
        """The grid for yarns of ``diameter`` (> 0) on ``machine``'s fell."""
        finest = diameter / SAMPLES_PER_DIAMETER
        tile = (machine.c_mat * machine.pitch_x, machine.c_mat * machine.pitch_y)
        fx, fy = machine.fell_xy(0, 0)
        if tile[0] == 0 or tile[1] == 0:  # c_mat 0: every tile is a point
            return cls(fx, fy, finest, finest, (0, 0))
        n = (math.ceil(tile[0] / finest), math.ceil(tile[1] / finest))
        return cls(fx - tile[0] / 2, fy - tile[1] / 2, tile[0] / n[0], tile[1] / n[1], n)

    @property
    def cell_area(self) -> float:
        """Area one sample stands for."""
        return self.hx * self.hy


def disc_rows(
    centres: FloatArray, radius: float, grid: Grid
) -> tuple[IntArray, IntArray, IntArray]:
    """The samples within ``radius`` of a centre (closed discs), as disjoint runs of each
    sample row: (row j, first i, last i), by row and first i. A disc covers, in each row
    it reaches, the samples whose x lies within its chord there."""
    if not len(centres):
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    c = centres - np.array([grid.x0, grid.y0])
    first = np.ceil((c[:, 1] - radius) / grid.hy - 0.5).astype(np.int64)
    count = np.floor((c[:, 1] + radius) / grid.hy - 0.5).astype(np.int64) - first + 1
    disc = np.repeat(np.arange(len(c)), np.maximum(count, 0))
    row = first[disc] + np.arange(len(disc)) - np.repeat(np.cumsum(count) - count, count)
    dy = (row + 0.5) * grid.hy - c[disc, 1]
    half = np.sqrt(np.maximum(radius * radius - dy * dy, 0.0))
    lo = np.ceil((c[disc, 0] - half) / grid.hx - 0.5).astype(np.int64)
    hi = np.floor((c[disc, 0] + half) / grid.hx - 0.5).astype(np.int64)
    keep = (lo <= hi) & (dy * dy <= radius * radius)
    row, lo, hi = row[keep], lo[keep], hi[keep]
    order = np.lexsort((lo, row))
    row, lo, hi = row[order], lo[order], hi[order]
    # merge each row's runs: with the row as an offset no run reaches into the next row
    width = int(hi.max() - lo.min()) + 3 if len(row) else 0
    key_lo, key_hi = lo + row * width, hi + row * width
    reach = np.maximum.accumulate(key_hi) if len(row) else key_hi
    start = np.flatnonzero(key_lo > np.concatenate([key_lo[:1] - 2, reach[:-1]]) + 1)
    last = np.maximum.reduceat(hi, start) if len(start) else hi
    return row[start], lo[start], last


def disc_samples(centres: FloatArray, radius: float, grid: Grid) -> tuple[IntArray, IntArray]:
    """Indices (i, j) of the distinct samples within ``radius`` of a centre (closed discs)."""
    row, lo, hi = disc_rows(centres, radius, grid)
    size = hi - lo + 1
    j = np.repeat(row, size)
    i = np.repeat(lo, size) + np.arange(len(j)) - np.repeat(np.cumsum(size) - size, size)
    return i, j


class Nominal:
    """A section's body cells at the fell: cell (r, c) is the tile of ``c_mat * pitch``
    centred on ``Machine.fell_xy(r, c)`` (where the twin starts a warp filled there)."""

    def __init__(self, section: Section, machine: Machine) -> None:
        self.section = section
        self.size = (machine.c_mat * machine.pitch_x, machine.c_mat * machine.pitch_y)
        fx, fy = machine.fell_xy(0, 0)
        self.origin = (fx - self.size[0] / 2, fy - self.size[1] / 2)
        self.mask = np.zeros((machine.rows, machine.cols), dtype=bool)
        for row, col in section.cells:
            self.mask[row, col] = True
        rows, cols = np.nonzero(self.mask)
        self.lo = (int(cols.min()), int(rows.min()))  # tile column, tile row
        self.hi = (int(cols.max()), int(rows.max()))

    @property
    def area(self) -> float:
        """Exact area: one tile per cell."""
        return len(self.section.cells) * self.size[0] * self.size[1]

    def box(self, axis: int) -> tuple[float, float]:
        """Extent along x (0) or y (1)."""
        start, size = self.origin[axis], self.size[axis]
        return start + self.lo[axis] * size, start + (self.hi[axis] + 1) * size

    def inside(self, runs: tuple[IntArray, IntArray, IntArray], grid: Grid) -> int:
        """How many samples of the runs (row j, first i, last i) of ``grid`` lie in the
        shape: per run, the masked samples before its end less those before its start."""
        row, lo, hi = runs
        nx, ny = grid.per_tile
        rows, cols = self.mask.shape
        tile = row // ny
        ok = (tile >= 0) & (tile < rows)
        mask = self.mask[tile[ok]]  # (runs, cols): the tile row of each run
        before = np.concatenate(
            [np.zeros((len(mask), 1), np.int64), np.cumsum(mask, axis=1)], axis=1
        )

        def masked_below(i: IntArray) -> IntArray:  # masked samples with index < i
            i = np.clip(i, 0, cols * nx)
            col = np.minimum(i // nx, cols - 1)
            part = i - col * nx
            k = np.arange(len(i))
            out: IntArray = nx * before[k, col] + part * mask[k, col]
            return out

        return int((masked_below(hi[ok] + 1) - masked_below(lo[ok])).sum())

    def samples(self, grid: Grid) -> int:
        """Samples of ``grid`` in the shape: the same number in every tile."""
        return len(self.section.cells) * grid.per_tile[0] * grid.per_tile[1]


def _box(values: FloatArray, pad: float) -> list[float] | None:
    return [float(values.min()) - pad, float(values.max()) + pad] if len(values) else None


def footprint(sk: SkeletonData, z: float, section: Section | None = None) -> dict[str, Any]:
    """Measured footprint at z = Z, and against the section's nominal shape when given."""
    points, free = crossing_points(sk, z)
    radius = sk.diameter / 2
    grid = Grid.of(sk.machine, sk.diameter) if radius > 0 else None
    empty = np.zeros(0, dtype=np.int64)
    runs = disc_rows(points, radius, grid) if grid is not None else (empty, empty, empty)
    area = int((runs[2] - runs[1] + 1).sum()) * grid.cell_area if grid is not None else 0.0
    out: dict[str, Any] = {
        "z": z,
        "crossings": len(points),
        "free": int(free.sum()),
        "grid": None if grid is None else [grid.hx, grid.hy],
        "measured": {
            "area": area,
            "x": _box(points[:, 0], radius),
            "y": _box(points[:, 1], radius),
        },
        "nominal": None,
        "ratio": None,
        "coverage": None,
        "outside": None,
    }
    if section is not None:
        out.update(_against(Nominal(section, sk.machine), runs, grid, area))
    return out


def _against(
    nominal: Nominal, runs: tuple[IntArray, IntArray, IntArray], grid: Grid | None, area: float
) -> dict[str, Any]:
    """Nominal shape, measured over nominal area, covered fraction, area outside it."""
    covered, coverage = 0, None
    if nominal.area > 0:
        covered = nominal.inside(runs, grid) if grid is not None else 0
        coverage = covered / nominal.samples(grid) if grid is not None else 0.0
    return {
        "nominal": {
            "section": nominal.section.spec,
            "cells": len(nominal.section.cells),
            "area": nominal.area,
            "x": list(nominal.box(0)),
            "y": list(nominal.box(1)),
        },
        "ratio": area / nominal.area if nominal.area > 0 else None,
        "coverage": coverage,
        "outside": area - covered * grid.cell_area if grid is not None else 0.0,
    }
