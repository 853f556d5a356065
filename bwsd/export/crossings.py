"""Where yarn centrelines cross a plane z = Z of the preform frame (numpy only).

The rule `bwsd slice` draws and `bwsd metrics` measures the footprint with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bwsd.twin.skeleton import FloatArray, IntArray, SkeletonData, YarnData

__all__ = ["Crossing", "crossings"]


@dataclass(frozen=True)
class Crossing:
    """A point where a yarn's centreline meets the plane z = Z.

    ``segment`` is the index i of the segment (node i to i + 1) the point lies on; for a
    point at a node, the segment ending there (0 for the first node).
    """

    yarn: int
    family: str
    segment: int
    x: float
    y: float
    free: bool  # the warp's free segment, from its last fixed node to its guide


def _on_plane(dz: FloatArray) -> IntArray:
    """Nodes on the plane with at least one neighbour off it (so not lying in the plane)."""
    off = dz != 0
    neighbour_off = np.zeros_like(off)
    neighbour_off[1:] |= off[:-1]
    neighbour_off[:-1] |= off[1:]
    return np.flatnonzero(~off & neighbour_off)


def _yarn_crossings(yarn: YarnData, z: float) -> list[Crossing]:
    nodes = np.asarray(yarn.nodes, dtype=np.float64)
    dz = nodes[:, 2] - z
    free_from = len(nodes) - 2 if yarn.kind == "warp" else len(nodes)
    side = np.sign(dz)
    hits: list[tuple[float, Crossing]] = []
    for i in _on_plane(dz).tolist():
        x, y = nodes[i, :2]
        crossing = Crossing(yarn.id, yarn.family, max(i - 1, 0), float(x), float(y), i > free_from)
        hits.append((i, crossing))
    for i in np.flatnonzero(side[:-1] * side[1:] < 0).tolist():
        a, b = nodes[i], nodes[i + 1]
        x, y = a[:2] + (z - a[2]) / (b[2] - a[2]) * (b[:2] - a[:2])
        hits.append(
            (i + 0.5, Crossing(yarn.id, yarn.family, i, float(x), float(y), i >= free_from))
        )
    return [c for _, c in sorted(hits, key=lambda h: h[0])]


def crossings(sk: SkeletonData, z: float) -> list[Crossing]:
    """Every point where a yarn centreline meets the plane z = Z, by yarn, then along it.

    A node on the plane counts once, unless the yarn lies in the plane on both sides of it.
    """
    return [c for yarn in sk.yarns for c in _yarn_crossings(yarn, z)]
