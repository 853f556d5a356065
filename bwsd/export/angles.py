"""Yarn angles to the production axis: of the whole skeleton, and of the formed zone with
its interior and surface yarns apart (docs/exports.md, "angles")."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial import ConvexHull, QhullError

from bwsd.export.arrays import Arrays
from bwsd.export.formed import Pieces
from bwsd.twin.skeleton import FloatArray

BoolArray = npt.NDArray[np.bool_]


def segment_angles(p0: FloatArray, p1: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Length and angle to the z axis (degrees, 0..90) of each segment p0-p1."""
    seg = p1 - p0
    length = np.linalg.norm(seg, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = np.clip(np.abs(seg[:, 2]) / length, 0.0, 1.0)
    return length, np.degrees(np.arccos(np.where(length > 0, cos, 1.0)))


def summary(length: FloatArray, angle: FloatArray) -> dict[str, Any]:
    """Count, total length, length-weighted mean and spread of the segments of positive
    length; mean and spread are None without any."""
    keep = length > 0
    length, angle = length[keep], angle[keep]
    total = float(length.sum())
    if total == 0:
        return {"segments": 0, "length": 0.0, "mean": None, "std": None}
    mean = float(np.average(angle, weights=length))
    std = math.sqrt(float(np.average((angle - mean) ** 2, weights=length)))
    return {"segments": len(length), "length": total, "mean": mean, "std": std}


def skeleton_angles(arrays: Arrays) -> dict[str, dict[str, Any]]:
    """Per family, over every fixed segment of the skeleton."""
    length, angle = segment_angles(arrays.seg_p0, arrays.seg_p1)
    return {
        arrays.names[f]: summary(length[arrays.seg_family == f], angle[arrays.seg_family == f])
        for f in arrays.present()
    }


def formed_angles(arrays: Arrays, pieces: Pieces) -> dict[str, dict[str, Any]]:
    """Per family, over the yarn of the formed zone: all of it, its interior and its surface."""
    p0, p1 = pieces.points(arrays)
    length, angle = segment_angles(p0, p1)
    family = arrays.seg_family[pieces.segment.astype(np.int64)]
    surface = on_surface(arrays, (p0 + p1)[:, :2] / 2, p0, p1)
    out: dict[str, dict[str, Any]] = {}
    for f in arrays.present():
        mine = family == f
        out[arrays.names[f]] = {
            "all": summary(length[mine], angle[mine]),
            "interior": summary(length[mine & ~surface], angle[mine & ~surface]),
            "surface": summary(length[mine & surface], angle[mine & surface]),
        }
    return out


def spacing(area: float, yarns: int) -> float:
    """The yarns' spacing in a section of ``area``: the side of a square each one has."""
    return math.sqrt(area / yarns) if yarns else 0.0


def on_surface(arrays: Arrays, where: FloatArray, p0: FloatArray, p1: FloatArray) -> BoolArray:
    """Whether each point ``where`` (x, y) lies within one yarn spacing of the outline of the
    formed zone: the convex hull of its yarn in (x, y)."""
    points = np.vstack([p0[:, :2], p1[:, :2]])
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):  # too few points, or all on a line: no inside
        return np.ones(len(where), dtype=bool)
    warps = int((arrays.family == 0).sum())
    inside = -(where @ hull.equations[:, :2].T + hull.equations[:, 2])  # to each edge
    out: BoolArray = inside.min(axis=1) <= spacing(float(hull.volume), warps)
    return out
