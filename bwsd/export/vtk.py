"""The skeleton as a VTK unstructured grid (.vtu) of line cells, through meshio.

Every yarn segment is its own two-point line cell. The PolyData export (.vtp, one
polyline per yarn) is written by VTK itself, in ``bwsd.export.vtp``.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from bwsd.export.errors import ExportError
from bwsd.export.families import family_codes
from bwsd.export.layout import (
    KIND_CONTACT,
    KIND_SEGMENT,
    contact_links,
    node_points,
    point_arrays,
    require_yarns,
)
from bwsd.twin.skeleton import IntArray, SkeletonData

__all__ = ["KIND_CONTACT", "KIND_SEGMENT", "skeleton_mesh", "write_vtu"]


def _segments(sk: SkeletonData, codes: dict[str, int]) -> tuple[IntArray, IntArray]:
    """Point-index pairs of every yarn segment, and (yarn, family) per segment."""
    pairs, owners = [], []
    start = 0
    for yarn in sk.yarns:
        n = len(yarn.node_ids)
        idx = np.arange(start, start + n, dtype=np.int64)
        pairs.append(np.column_stack([idx[:-1], idx[1:]]))
        owners.append(np.tile([yarn.id, codes[yarn.family]], (max(n - 1, 0), 1)))
        start += n
    return np.vstack(pairs).reshape(-1, 2), np.vstack(owners).reshape(-1, 2)


def skeleton_mesh(sk: SkeletonData) -> meshio.Mesh:
    """One point per node, one "line" cell per yarn segment and per contact link."""
    require_yarns(sk)
    codes = family_codes(sk)
    seg, seg_owner = _segments(sk, codes)
    link, link_info = contact_links(sk, codes)
    n_seg, n_link = len(seg), len(link)
    kind = np.concatenate([np.full(n_seg, KIND_SEGMENT), np.full(n_link, KIND_CONTACT)])
    cell_data = {
        "yarn": np.concatenate([seg_owner[:, 0], link_info[:, 0]]),
        "family": np.concatenate([seg_owner[:, 1], link_info[:, 1]]),
        "kind": kind.astype(np.int64),
        "instruction": np.concatenate([np.zeros(n_seg, dtype=np.int64), link_info[:, 2]]),
    }
    return meshio.Mesh(
        node_points(sk),
        [("line", np.vstack([seg, link]))],
        point_data=point_arrays(sk),
        cell_data={k: [v.astype(np.int64)] for k, v in cell_data.items()},
    )


def write_vtu(sk: SkeletonData, path: str | Path) -> None:
    """Write ``skeleton_mesh(sk)`` as a VTK XML unstructured grid (zlib-compressed)."""
    mesh = skeleton_mesh(sk)
    try:
        meshio.write(str(path), mesh, file_format="vtu")
    except OSError as exc:
        raise ExportError(f"cannot write: {exc.strerror}", path=str(path)) from exc
