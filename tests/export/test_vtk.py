"""VTK .vtu through meshio: points, line cells, cell and point data."""

from __future__ import annotations

import meshio
import numpy as np
import pytest

from bwsd.export.errors import ExportError
from bwsd.export.families import family_codes
from bwsd.export.vtk import KIND_CONTACT, KIND_SEGMENT, write_vtu

from .conftest import build, warp, weft


@pytest.fixture
def mesh(small, tmp_path):
    path = tmp_path / "skeleton.vtu"
    write_vtu(small, path)
    assert path.read_bytes().startswith(b"<?xml")
    return meshio.read(path)


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
