"""Yarn volume fraction of the formed zone at three heights (docs/exports.md, "fraction").

At a height Z, the yarns' cross-section area is the sum of their cuts by the plane z = Z:
an ellipse of pi d^2 / (4 cos t) for a yarn crossing it at t degrees to the z axis, and a
strip 2 sqrt((d/2)^2 - dz^2) wide along a weft lying within d/2 of the plane (between its
first and last contact). The section is the convex hull of the discs of diameter d centred
on the crossings: the hull of the centres, widened by d/2 all round. Yarns that overlap
count in full: the fraction is of yarn put there, not of space filled.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from bwsd.export.arrays import Arrays
from bwsd.export.formed import Zone
from bwsd.twin.skeleton import FloatArray

SHARES = (0.25, 0.5, 0.75)  # the heights: these shares of the way up the formed zone


def crossing_points(arrays: Arrays, z: float) -> tuple[FloatArray, FloatArray]:
    """(x, y) and angle to z (degrees) of every fixed segment crossing the plane z = Z (its
    lower end at or below it, its upper end above)."""
    za, zb = arrays.seg_p0[:, 2], arrays.seg_p1[:, 2]
    cut = np.flatnonzero(np.minimum(za, zb) <= z) if len(za) else np.zeros(0, np.int64)
    cut = cut[np.maximum(za[cut], zb[cut]) > z]
    p0, p1 = arrays.seg_p0[cut], arrays.seg_p1[cut]
    t = (z - p0[:, 2]) / (p1[:, 2] - p0[:, 2])
    xy = p0[:, :2] + t[:, None] * (p1[:, :2] - p0[:, :2])
    rise = np.abs(p1[:, 2] - p0[:, 2]) / np.linalg.norm(p1 - p0, axis=1)
    return xy, np.degrees(np.arccos(np.clip(rise, 0.0, 1.0)))


def weft_strips(arrays: Arrays, z: float) -> float:
    """Area of the cuts of weft segments between two contacts lying within d/2 of z = Z."""
    radius = arrays.sk.diameter / 2
    flat = (arrays.seg_p0[:, 2] == arrays.seg_p1[:, 2]) & (arrays.seg_family > 0)
    between = (arrays.made[arrays.seg_a] > 0) & (arrays.made[arrays.seg_b] > 0)
    dz = np.abs(arrays.seg_p0[:, 2] - z)
    near = flat & between & (dz < radius)
    width = 2 * np.sqrt(radius * radius - dz[near] ** 2)
    return float((width * arrays.seg_length[near]).sum())


def hull_area(points: FloatArray, radius: float) -> float:
    """Area of the convex hull of discs of ``radius`` centred on ``points``."""
    disc = math.pi * radius * radius
    if len(points) == 0:
        return 0.0
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):  # fewer than 3 points, or all on one line: a capsule
        end = points[np.argmax(np.linalg.norm(points - points[0], axis=1))]
        span = float(np.linalg.norm(points - end, axis=1).max())
        return 2 * span * radius + disc
    return float(hull.volume) + float(hull.area) * radius + disc  # in 2-D: area, perimeter


def at_height(arrays: Arrays, z: float) -> dict[str, Any]:
    """The yarn volume fraction of the plane z = Z."""
    d = arrays.sk.diameter
    xy, angle = crossing_points(arrays, z)
    ellipses = float((math.pi * d * d / 4 / np.cos(np.radians(angle))).sum())
    yarn = ellipses + weft_strips(arrays, z)
    section = hull_area(xy, d / 2)
    return {
        "z": z,
        "crossings": len(xy),
        "yarn_area": yarn,
        "section_area": section,
        "fraction": yarn / section if section > 0 else None,
    }


def volume_fraction(arrays: Arrays, zone: Zone) -> list[dict[str, Any]] | None:
    """At a quarter, half and three quarters of the way up the formed zone; None without
    one."""
    if zone.z is None:
        return None
    low, high = zone.z
    return [at_height(arrays, low + share * (high - low)) for share in SHARES]
