"""The skeleton as a VTK unstructured grid (.vtu) of line cells, written by VTK itself.

Every yarn segment is its own two-point line cell. The PolyData export (.vtp, one
polyline per yarn) is in ``bwsd.export.vtp``; both load only VTK's core, data-model and
XML-I/O modules.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from vtkmodules.vtkCommonCore import vtkDoubleArray, vtkIdTypeArray, vtkPoints, vtkTypeInt64Array
from vtkmodules.vtkCommonDataModel import VTK_LINE, vtkCellArray, vtkUnstructuredGrid
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

from bwsd.export.families import family_codes
from bwsd.export.layout import (
    KIND_CONTACT,
    KIND_SEGMENT,
    contact_links,
    node_points,
    point_arrays,
    require_yarns,
)
from bwsd.export.vtp import fill, write_file, xml
from bwsd.twin.skeleton import IntArray, SkeletonData

__all__ = ["KIND_CONTACT", "KIND_SEGMENT", "skeleton_grid", "write_vtu"]


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


def skeleton_grid(sk: SkeletonData) -> vtkUnstructuredGrid:
    """One point per node, one line cell (``VTK_LINE``) per yarn segment and per contact link."""
    require_yarns(sk)
    codes = family_codes(sk)
    seg, seg_owner = _segments(sk, codes)
    link, link_info = contact_links(sk, codes)
    n_seg, n_link = len(seg), len(link)
    lines = np.vstack([seg, link]).astype(np.int64)
    cell_data = {
        "yarn": np.concatenate([seg_owner[:, 0], link_info[:, 0]]),
        "family": np.concatenate([seg_owner[:, 1], link_info[:, 1]]),
        "kind": np.concatenate([np.full(n_seg, KIND_SEGMENT), np.full(n_link, KIND_CONTACT)]),
        "instruction": np.concatenate([np.zeros(n_seg, dtype=np.int64), link_info[:, 2]]),
    }
    points = vtkPoints()
    points.SetData(fill(vtkDoubleArray(), node_points(sk)))
    cells = vtkCellArray()
    offsets = np.arange(0, 2 * len(lines) + 1, 2, dtype=np.int64)
    cells.SetData(fill(vtkIdTypeArray(), offsets), fill(vtkIdTypeArray(), lines.reshape(-1)))
    grid = vtkUnstructuredGrid()
    grid.SetPoints(points)
    grid.SetCells(VTK_LINE, cells)
    for name, values in point_arrays(sk).items():
        grid.GetPointData().AddArray(fill(vtkTypeInt64Array(), values, name))
    for name, values in cell_data.items():
        grid.GetCellData().AddArray(fill(vtkTypeInt64Array(), values.astype(np.int64), name))
    return grid


def write_vtu(sk: SkeletonData, path: str | Path) -> None:
    """Write ``skeleton_grid(sk)`` as a VTK XML unstructured grid (.vtu): binary (base64),
    zlib-compressed arrays.

    The file is written next to ``path`` and renamed into place, so a failed write
    leaves any previous file untouched.
    """
    write_file(Path(path), xml(vtkXMLUnstructuredGridWriter(), skeleton_grid(sk), "grid"))
