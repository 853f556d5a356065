"""VTK .vtp through VTK's XML writer, read back with VTK's XML reader."""

from __future__ import annotations

import dataclasses
import errno
import os
import subprocess
import sys
from typing import cast

import numpy as np
import pytest
from vtkmodules.vtkCommonDataModel import VTK_LINE, VTK_POLY_LINE, vtkPolyData
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

from bwsd.export.errors import ExportError
from bwsd.export.layout import KIND_CONTACT, KIND_SEGMENT
from bwsd.export.vtp import write_vtp
from bwsd.twin.skeleton import ContactData, SkeletonData

from .conftest import build, warp, weft


def read_vtp(path) -> vtkPolyData:
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    # VTK's stubs name GetOutput's type without importing it: mypy reads Any
    poly = cast(vtkPolyData, reader.GetOutput())
    assert poly.GetNumberOfPoints() > 0, f"nothing read from {path}"
    return poly


def cell_ids(poly: vtkPolyData, cell: int) -> list[int]:
    ids = poly.GetCell(cell).GetPointIds()
    return [ids.GetId(j) for j in range(ids.GetNumberOfIds())]


def arrays(data) -> dict[str, list[int]]:
    """Every array of a vtkPointData / vtkCellData by name, as Python ints."""
    out = {}
    for i in range(data.GetNumberOfArrays()):
        array = data.GetArray(i)
        assert array.GetDataTypeSize() == 8 and array.GetNumberOfComponents() == 1
        out[data.GetArrayName(i)] = np.asarray(array).astype(np.int64).tolist()
    return out


def renumbered(sk: SkeletonData) -> SkeletonData:
    """The same skeleton with node ids that are not point indices (1000 - id)."""
    yarns = tuple(dataclasses.replace(y, node_ids=1000 - y.node_ids) for y in sk.yarns)
    contacts = tuple(
        dataclasses.replace(c, moving_node=1000 - c.moving_node, hit_node=1000 - c.hit_node)
        for c in sk.contacts
    )
    return dataclasses.replace(sk, yarns=yarns, contacts=contacts)


@pytest.fixture
def sk(small) -> SkeletonData:
    return renumbered(small)


@pytest.fixture
def poly(sk, tmp_path) -> vtkPolyData:
    path = tmp_path / "skeleton.vtp"
    write_vtp(sk, path)
    head = path.read_bytes()[:300]
    assert head.startswith(b"<?xml") and b'type="PolyData"' in head
    assert [p.name for p in tmp_path.iterdir()] == ["skeleton.vtp"]
    return read_vtp(path)


def test_points(sk, poly):
    assert poly.GetNumberOfPoints() == 13
    points = np.array([poly.GetPoint(i) for i in range(13)])
    assert np.array_equal(points, np.vstack([y.nodes for y in sk.yarns]))


def test_point_data(poly):
    data = arrays(poly.GetPointData())
    assert set(data) == {"node_id", "yarn"}
    assert data["node_id"] == [1000 - i for i in range(13)]
    assert data["yarn"] == [0] * 4 + [1] * 4 + [2] * 3 + [3] * 2


def test_one_polyline_per_yarn_then_one_line_per_link(sk, poly):
    # 4 yarns, then 2 contact links; no vertices, polygons or strips
    assert poly.GetNumberOfCells() == poly.GetNumberOfLines() == 6
    assert poly.GetNumberOfVerts() == poly.GetNumberOfPolys() == poly.GetNumberOfStrips() == 0
    # PolyData keeps only the connectivity: a two-node yarn (the weft) reads back as a line
    types = [poly.GetCellType(i) for i in range(6)]
    assert types == [VTK_POLY_LINE] * 3 + [VTK_LINE] * 3


def test_polylines_run_through_each_yarns_nodes_in_order(sk, poly):
    node_id = arrays(poly.GetPointData())["node_id"]
    for cell, yarn in enumerate(sk.yarns):
        assert [node_id[p] for p in cell_ids(poly, cell)] == yarn.node_ids.tolist()
    assert cell_ids(poly, 1) == [4, 5, 6, 7]


def test_links_join_the_contact_nodes(sk, poly):
    node_id = arrays(poly.GetPointData())["node_id"]
    links = [[node_id[p] for p in cell_ids(poly, cell)] for cell in (4, 5)]
    assert links == [[995, 999], [998, 994]]
    assert links == [[c.moving_node, c.hit_node] for c in sk.contacts]


def test_cell_data(poly):
    data = arrays(poly.GetCellData())
    assert set(data) == {"yarn", "family", "kind", "instruction"}
    assert data["kind"] == [KIND_SEGMENT] * 4 + [KIND_CONTACT] * 2
    assert data["yarn"] == [0, 1, 2, 3, 1, 0]
    assert data["family"] == [0, 0, 0, 1, 0, 0]
    assert data["instruction"] == [0, 0, 0, 0, 2, 5]


def test_weft_families_and_moving_yarn_of_a_link(tmp_path):
    sk = build(
        [
            warp([(0, 0, 0), (0, 0, 5), (0, 0, 9)]),
            weft([(-1, 0, 1), (1, 0, 1)], 90),
            weft([(0, -1, 2), (0, 1, 2)], 0),
        ],
        [(3, 2, 6, 0, 1)],
    )
    write_vtp(sk, tmp_path / "f.vtp")
    poly = read_vtp(tmp_path / "f.vtp")
    data = arrays(poly.GetCellData())
    assert data["family"] == [0, 1, 2, 2]
    assert data["yarn"] == [0, 1, 2, 2]
    assert data["instruction"] == [0, 0, 0, 3]
    assert cell_ids(poly, 3) == [6, 1]


def test_without_contacts(tmp_path):
    sk = build([warp([(0, 0, 0), (0, 0, 5), (0, 0, 9)]), weft([(-1, 0, 1), (1, 0, 1)])])
    write_vtp(sk, tmp_path / "n.vtp")
    poly = read_vtp(tmp_path / "n.vtp")
    assert poly.GetNumberOfCells() == 2
    assert arrays(poly.GetCellData())["kind"] == [KIND_SEGMENT] * 2
    assert cell_ids(poly, 1) == [3, 4]


def test_unknown_contact_node(tmp_path):
    sk = build([warp([(0, 0, 0), (0, 0, 9)])], [(1, 0, 0, 0, 99)])
    with pytest.raises(ExportError, match="99"):
        write_vtp(sk, tmp_path / "x.vtp")
    assert list(tmp_path.iterdir()) == []


def test_unknown_moving_yarn(tmp_path):
    sk = dataclasses.replace(
        build([warp([(0, 0, 0), (0, 0, 9)])]), contacts=(ContactData(1, 7, 0, 0, 1),)
    )
    with pytest.raises(ExportError, match="7"):
        write_vtp(sk, tmp_path / "x.vtp")


def test_empty_skeleton(tmp_path):
    with pytest.raises(ExportError, match="no yarns"):
        write_vtp(build([]), tmp_path / "x.vtp")


def test_missing_directory(small, tmp_path):
    target = tmp_path / "absent" / "x.vtp"
    with pytest.raises(ExportError, match="cannot write") as info:
        write_vtp(small, target)
    assert info.value.path == str(target)
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_the_previous_file(small, tmp_path, monkeypatch):
    target = tmp_path / "x.vtp"
    target.write_text("previous")

    def refuse(src, dst):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(ExportError, match="Permission denied"):
        write_vtp(small, target)
    assert target.read_text() == "previous"
    assert [p.name for p in tmp_path.iterdir()] == ["x.vtp"]
    monkeypatch.undo()
    write_vtp(small, target)
    assert read_vtp(target).GetNumberOfPoints() == 13


def test_loads_no_rendering_module():
    code = (
        "import sys, bwsd.export.vtp\n"
        "bad = sorted(m for m in sys.modules if 'Rendering' in m or m == 'vtk')\n"
        "assert 'vtkmodules.vtkIOXML' in sys.modules\n"
        "print(bad)\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[]"
