"""VTK .vtu, written by VTK itself: points, line cells, cell and point data."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import pytest
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkCommonDataModel import VTK_LINE, vtkUnstructuredGrid
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

from bwsd.export.errors import ExportError
from bwsd.export.families import family_codes
from bwsd.export.vtk import KIND_CONTACT, KIND_SEGMENT, write_vtu

from .conftest import build, warp, weft

# VTK's arrays, as numpy_support gives them: the dtype is the VTK array's
Array = npt.NDArray[Any]


@dataclass
class Block:
    type: str
    data: Array


@dataclass
class Mesh:
    """What a .vtu holds, read back by VTK's own reader, laid out by cell block."""

    points: Array
    cells: list[Block]
    point_data: dict[str, Array]
    cell_data: dict[str, list[Array]]


def read_grid(path: Path) -> vtkUnstructuredGrid:
    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    # VTK's stubs name GetOutput's type without importing it: mypy reads Any
    return cast(vtkUnstructuredGrid, reader.GetOutput())


def read_vtu(path: Path) -> Mesh:
    grid = read_grid(path)
    types = {int(t) for t in vtk_to_numpy(grid.GetCellTypes())}
    assert types == {VTK_LINE}
    cells = grid.GetCells()
    assert (vtk_to_numpy(cells.GetOffsetsArray())[1:] % 2 == 0).all()
    lines = vtk_to_numpy(cells.GetConnectivityArray()).reshape(-1, 2)
    pd, cd = grid.GetPointData(), grid.GetCellData()
    return Mesh(
        points=vtk_to_numpy(grid.GetPoints().GetData()),
        cells=[Block("line", lines)],
        point_data={
            pd.GetArrayName(i): vtk_to_numpy(pd.GetArray(i)) for i in range(pd.GetNumberOfArrays())
        },
        cell_data={
            cd.GetArrayName(i): [vtk_to_numpy(cd.GetArray(i))]
            for i in range(cd.GetNumberOfArrays())
        },
    )


@pytest.fixture
def mesh(small, tmp_path):
    path = tmp_path / "skeleton.vtu"
    write_vtu(small, path)
    assert path.read_bytes().startswith(b"<?xml")
    return read_vtu(path)


def test_points_and_node_ids(small, mesh):
    assert np.array_equal(mesh.points, np.vstack([y.nodes for y in small.yarns]))
    assert mesh.point_data["node_id"].tolist() == list(range(13))
    assert mesh.point_data["yarn"].tolist() == [0] * 4 + [1] * 4 + [2] * 3 + [3] * 2


def test_line_cells(mesh):
    assert [block.type for block in mesh.cells] == ["line"]
    lines = mesh.cells[0].data
    # 3 + 3 + 2 + 1 yarn segments, then the 2 contact links
    assert len(lines) == 11
    assert lines[:3].tolist() == [[0, 1], [1, 2], [2, 3]]
    assert lines[8].tolist() == [11, 12]


def test_cell_data(mesh):
    data = {k: v[0].tolist() for k, v in mesh.cell_data.items()}
    assert data["kind"] == [KIND_SEGMENT] * 9 + [KIND_CONTACT] * 2
    assert data["yarn"] == [0, 0, 0, 1, 1, 1, 2, 2, 3, 1, 0]
    assert data["family"] == [0] * 8 + [1, 0, 0]
    assert data["instruction"] == [0] * 9 + [2, 5]


def test_contact_links_join_the_contact_nodes(small, mesh):
    ids = mesh.point_data["node_id"]
    links = mesh.cells[0].data[mesh.cell_data["kind"][0] == KIND_CONTACT]
    assert [tuple(ids[link]) for link in links] == [
        (c.moving_node, c.hit_node) for c in small.contacts
    ]


def test_family_codes_in_yarn_order():
    sk = build(
        [
            weft([(0, 0, 1), (1, 0, 1)], 90),
            warp([(0, 0, 0), (0, 0, 9)]),
            weft([(0, 0, 2), (0, 1, 2)], 0),
            weft([(0, 0, 3), (0, 1, 3)], 90),
        ]
    )
    assert family_codes(sk) == {"warp": 0, "weft-90": 1, "weft-0": 2}


def test_unknown_contact_node(tmp_path):
    sk = build([warp([(0, 0, 0), (0, 0, 9)])], [(1, 0, 0, 0, 99)])
    with pytest.raises(ExportError, match="99"):
        write_vtu(sk, tmp_path / "x.vtu")


def test_empty_skeleton(tmp_path):
    with pytest.raises(ExportError, match="no yarns"):
        write_vtu(build([]), tmp_path / "x.vtu")


def test_arrays_are_64_bit_integers_and_points_doubles(small, tmp_path):
    write_vtu(small, tmp_path / "x.vtu")
    grid = read_grid(tmp_path / "x.vtu")
    assert grid.GetPoints().GetData().GetDataTypeAsString() == "double"
    for data in (grid.GetPointData(), grid.GetCellData()):
        for i in range(data.GetNumberOfArrays()):
            assert data.GetArray(i).GetDataTypeSize() == 8, data.GetArrayName(i)
    text = (tmp_path / "x.vtu").read_text()
    assert 'compressor="vtkZLibDataCompressor"' in text
    assert 'header_type="UInt64"' in text


def test_failed_write_keeps_the_previous_file(small, tmp_path, monkeypatch):
    target = tmp_path / "x.vtu"
    target.write_text("previous")

    def refuse(src, dst):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(ExportError, match="Permission denied"):
        write_vtu(small, target)
    assert target.read_text() == "previous"
    assert [p.name for p in tmp_path.iterdir()] == ["x.vtu"]


def test_writes_through_vtk_without_meshio_or_rendering():
    """The .vtu comes from VTK's own XML writer: meshio is not needed any more."""
    code = (
        "import sys\n"
        "sys.modules['meshio'] = None\n"
        "import bwsd.export.vtk\n"
        "bad = sorted(m for m in sys.modules if 'Rendering' in m or m == 'vtk')\n"
        "print(bad)\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"
