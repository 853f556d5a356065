"""Cross-section of the skeleton at one height z of the preform frame, drawn with matplotlib."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon

from bwsd.export.crossings import Crossing, crossings
from bwsd.export.errors import ExportError
from bwsd.export.families import family_codes
from bwsd.twin.skeleton import SkeletonData


@dataclass(frozen=True)
class Band:
    """A horizontal segment (a weft) lying within half a diameter of the plane.

    Its yarn cuts the plane in a strip of half-width ``half_width`` along the segment.
    """

    yarn: int
    family: str
    start: tuple[float, float]
    end: tuple[float, float]
    half_width: float


def bands(sk: SkeletonData, z: float) -> list[Band]:
    """Horizontal segments whose round section reaches the plane z = Z."""
    radius = sk.diameter / 2
    out = []
    for yarn in sk.yarns:
        nodes = np.asarray(yarn.nodes, dtype=np.float64)
        for a, b in itertools.pairwise(nodes):
            dz = abs(float(a[2]) - z)
            if a[2] == b[2] and dz < radius:
                half = math.sqrt(radius * radius - dz * dz)
                start, end = (float(a[0]), float(a[1])), (float(b[0]), float(b[1]))
                out.append(Band(yarn.id, yarn.family, start, end, half))
    return out


def _band_polygon(band: Band) -> list[tuple[float, float]]:
    (x0, y0), (x1, y1) = band.start, band.end
    length = math.hypot(x1 - x0, y1 - y0) or 1.0
    nx, ny = -(y1 - y0) / length * band.half_width, (x1 - x0) / length * band.half_width
    return [(x0 + nx, y0 + ny), (x1 + nx, y1 + ny), (x1 - nx, y1 - ny), (x0 - nx, y0 - ny)]


def _draw(ax: Axes, sk: SkeletonData, found: list[Crossing], strips: list[Band]) -> None:
    codes = family_codes(sk)
    radius = sk.diameter / 2
    for band in strips:
        ax.add_patch(Polygon(_band_polygon(band), color=f"C{codes[band.family] % 10}", alpha=0.6))
    for c in found:
        colour = f"C{codes[c.family] % 10}"
        if radius > 0:
            edge = colour if c.free else "black"  # a dark rim tells touching yarns apart
            circle = Circle(
                (c.x, c.y), radius, edgecolor=edge, facecolor=colour, fill=not c.free, linewidth=0.6
            )
            ax.add_patch(circle)
        else:
            ax.plot([c.x], [c.y], marker="x" if c.free else "o", color=colour, markersize=4)
    _legend(ax, codes, found, strips, "o" if radius > 0 else "x")


def _legend(
    ax: Axes, codes: dict[str, int], found: list[Crossing], strips: list[Band], free_marker: str
) -> None:
    present = sorted({c.family for c in found} | {b.family for b in strips}, key=codes.__getitem__)
    handles = [
        Line2D([], [], marker="o", linestyle="", color=f"C{codes[f] % 10}", label=f)
        for f in present
    ]
    if any(c.free for c in found):
        handles.append(
            Line2D(
                [],
                [],
                marker=free_marker,
                linestyle="",
                color="grey",
                markerfacecolor="none",
                label="free segment",
            )
        )
    if handles:
        ax.figure.legend(
            handles=handles,
            loc="outside lower center",
            ncols=min(len(handles), 5),
            fontsize="small",
        )


def _limits(ax: Axes, sk: SkeletonData, found: list[Crossing], strips: list[Band]) -> None:
    pad = max(sk.diameter, 1.0)
    xs = [c.x for c in found] + [p[0] for b in strips for p in (b.start, b.end)]
    ys = [c.y for c in found] + [p[1] for b in strips for p in (b.start, b.end)]
    if not xs:  # nothing cut: show the footprint of the matrix at the fell
        m = sk.machine
        (x0, y0), (x1, y1) = m.fell_xy(0, 0), m.fell_xy(m.rows - 1, m.cols - 1)
        xs, ys = [x0, x1], [y0, y1]
    half = max(max(xs) - min(xs), max(ys) - min(ys)) / 2 + pad  # a square view, equal axes
    cx, cy = (max(xs) + min(xs)) / 2, (max(ys) + min(ys)) / 2
    ax.set_xlim(cx - half, cx + half)
    ax.set_ylim(cy + half, cy - half)  # y down: matrix row 0 at the top, as the FILL block
    ax.set_aspect("equal", adjustable="box")


def slice_figure(sk: SkeletonData, z: float) -> tuple[Figure, int]:
    """The cross-section at z = Z (preform frame) as a figure, and its crossings.

    x to the right, y down (matrix row 0 at the top, column 0 on the left: the matrix as
    the program's FILL block writes it). Filled circles of the yarn diameter: fixed
    segments; open circles: warps' free segments; strips: wefts lying within half a
    diameter of the plane.
    """
    found, strips = crossings(sk, z), bands(sk, z)
    fig = Figure(figsize=(6.4, 6.4), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    _draw(ax, sk, found, strips)
    _limits(ax, sk, found, strips)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm] (down)")
    ax.set_title(f"z = {z:g} mm (preform frame, take-up {sk.takeup:g} mm): {len(found)} crossings")
    ax.grid(True, linewidth=0.3)
    return fig, len(found)


def draw_slice(sk: SkeletonData, z: float, path: str | Path) -> int:
    """Draw the cross-section at z = Z (``slice_figure``) to ``path``; returns the crossings.

    The image format follows the suffix (.png, .svg, .pdf, ...).
    """
    fig, count = slice_figure(sk, z)
    try:
        fig.savefig(str(path), dpi=150)
    except (OSError, ValueError) as exc:
        raise ExportError(f"cannot write the image: {exc}", path=str(path)) from exc
    return count
