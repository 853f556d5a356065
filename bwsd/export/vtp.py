"""The skeleton as VTK PolyData (.vtp), written by VTK's own XML writer.

One point per node, one polyline cell per yarn and one line cell per contact link.
Only VTK's core, data-model and XML-I/O modules are loaded: no rendering, no display.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TypeVar

import numpy as np
import numpy.typing as npt
from vtkmodules.vtkCommonCore import (
    vtkDataArray,
    vtkDoubleArray,
    vtkIdTypeArray,
    vtkPoints,
    vtkTypeInt64Array,
)
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkDataObject, vtkPolyData
from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter, vtkXMLWriter

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
from bwsd.twin.skeleton import FloatArray, IntArray, SkeletonData

A = TypeVar("A", bound=vtkDataArray)


def fill(array: A, values: npt.NDArray[np.generic], name: str = "") -> A:
    """``array`` sized like ``values`` (one row per tuple) and holding a copy of them."""
    if name:
        array.SetName(name)
    array.SetNumberOfComponents(1 if values.ndim == 1 else values.shape[1])
    array.SetNumberOfTuples(values.shape[0])
    if values.size:
        np.asarray(array)[...] = values.reshape(np.asarray(array).shape)
    return array


def _lines(sk: SkeletonData, links: IntArray) -> vtkCellArray:
    """A polyline through each yarn's points in order, then a line per contact link.

    The points are laid out yarn by yarn, so yarn k's polyline is a run of point ids.
    """
    sizes = [len(y.node_ids) for y in sk.yarns] + [2] * len(links)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    n_points = sum(len(y.node_ids) for y in sk.yarns)
    connectivity = np.concatenate([np.arange(n_points, dtype=np.int64), links.reshape(-1)])
    cells = vtkCellArray()
    cells.SetData(fill(vtkIdTypeArray(), offsets), fill(vtkIdTypeArray(), connectivity))
    return cells


def _cell_arrays(sk: SkeletonData, codes: dict[str, int], info: IntArray) -> dict[str, IntArray]:
    """Per cell (yarns first, then links): yarn, family, kind, instruction."""
    n_yarn, n_link = len(sk.yarns), len(info)
    yarn = np.array([[y.id, codes[y.family]] for y in sk.yarns], dtype=np.int64).reshape(-1, 2)
    return {
        "yarn": np.concatenate([yarn[:, 0], info[:, 0]]),
        "family": np.concatenate([yarn[:, 1], info[:, 1]]),
        "kind": np.repeat(np.array([KIND_SEGMENT, KIND_CONTACT], np.int64), [n_yarn, n_link]),
        "instruction": np.concatenate([np.zeros(n_yarn, np.int64), info[:, 2]]),
    }


def skeleton_polydata(
    sk: SkeletonData, sections: Sequence[FloatArray] | None = None
) -> vtkPolyData:
    """The skeleton as a ``vtkPolyData``: points, lines, point data and cell data; with
    ``sections`` (per yarn, (nodes, 5): width, height, up vector) the point arrays
    ``section_width``, ``section_height`` and ``section_up`` too."""
    require_yarns(sk)
    codes = family_codes(sk)
    links, info = contact_links(sk, codes)
    points = vtkPoints()
    points.SetData(fill(vtkDoubleArray(), node_points(sk)))
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetLines(_lines(sk, links))
    for name, values in point_arrays(sk).items():
        poly.GetPointData().AddArray(fill(vtkTypeInt64Array(), values, name))
    for name, values in _cell_arrays(sk, codes, info).items():
        poly.GetCellData().AddArray(fill(vtkTypeInt64Array(), values, name))
    if sections is not None:
        table = np.vstack([np.asarray(t, dtype=np.float64).reshape(-1, 5) for t in sections])
        for name, values in (
            ("section_width", table[:, 0]),
            ("section_height", table[:, 1]),
            ("section_up", table[:, 2:5]),
        ):
            poly.GetPointData().AddArray(fill(vtkDoubleArray(), np.ascontiguousarray(values), name))
    return poly


def xml(writer: vtkXMLWriter, data: vtkDataObject, what: str) -> bytes:
    """``data`` as a VTK XML document by ``writer``: binary (base64), zlib-compressed arrays."""
    writer.SetInputData(data)
    writer.SetDataModeToBinary()
    writer.SetCompressorTypeToZLib()
    writer.SetHeaderTypeToUInt64()
    writer.SetWriteToOutputString(True)
    if not writer.Write():
        raise ExportError(f"VTK could not write the {what}")
    return writer.GetOutputString().encode("utf-8")


def polydata_xml(poly: vtkPolyData) -> bytes:
    """``poly`` as a VTK XML PolyData document: binary (base64), zlib-compressed arrays."""
    return xml(vtkXMLPolyDataWriter(), poly, "PolyData")


def write_file(target: Path, data: bytes) -> None:
    """Write ``data`` next to ``target`` and rename it into place: a failed write leaves any
    previous file untouched."""
    tmp = target.with_name(f".{target.name}.{os.getpid()}-{threading.get_ident()}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, target)
    except OSError as exc:
        raise ExportError(f"cannot write: {exc.strerror}", path=str(target)) from exc
    finally:
        tmp.unlink(missing_ok=True)


def write_vtp(
    sk: SkeletonData, path: str | Path, sections: Sequence[FloatArray] | None = None
) -> None:
    """Write ``skeleton_polydata(sk, sections)`` as a VTK XML PolyData file (.vtp).

    The file is written next to ``path`` and renamed into place, so a failed write
    leaves any previous file untouched.
    """
    write_file(Path(path), polydata_xml(skeleton_polydata(sk, sections)))
