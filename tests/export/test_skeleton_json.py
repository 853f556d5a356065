"""Skeleton JSON: schema, values, round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bwsd.errors import BwsdError
from bwsd.export.errors import ExportError
from bwsd.export.skeleton_json import (
    read_skeleton_json,
    skeleton_from_dict,
    skeleton_to_dict,
    write_skeleton_json,
)
from bwsd.twin.skeleton import SkeletonData

from .conftest import MACHINE, build, weft


def assert_same(a: SkeletonData, b: SkeletonData) -> None:
    assert a.machine == b.machine
    assert (a.diameter, a.takeup, a.instructions) == (b.diameter, b.takeup, b.instructions)
    assert a.contacts == b.contacts
    assert np.array_equal(a.occupancy, b.occupancy)
    assert len(a.yarns) == len(b.yarns)
    for ya, yb in zip(a.yarns, b.yarns, strict=True):
        assert (ya.id, ya.kind, ya.cell, ya.angle) == (yb.id, yb.kind, yb.cell, yb.angle)
        assert np.array_equal(ya.node_ids, yb.node_ids)
        assert np.array_equal(ya.nodes, yb.nodes)  # bit for bit


def test_top_level_fields(small):
    d = skeleton_to_dict(small)
    assert d["schema"] == "bwsd-skeleton"
    assert d["version"] == 1
    assert (d["frame"], d["units"]) == ("preform", "mm")
    assert d["machine"] == {
        "rows": 2,
        "cols": 2,
        "pitch_x": 10.0,
        "pitch_y": 10.0,
        "d_mat": 100.0,
        "c_mat": 0.5,
        "yarn_diameter": 1.0,
    }
    assert (d["diameter"], d["takeup"], d["instructions"]) == (1.0, 20.0, 6)
    assert d["occupancy"] == [[0, 1], [-1, 2]]


def test_yarn_fields(small):
    yarns = skeleton_to_dict(small)["yarns"]
    assert [y["id"] for y in yarns] == [0, 1, 2, 3]
    assert [y["kind"] for y in yarns] == ["warp", "warp", "warp", "weft"]
    assert [y["family"] for y in yarns] == ["warp", "warp", "warp", "weft-0"]
    assert yarns[0]["cell"] == [0, 0] and yarns[0]["angle"] is None
    assert yarns[3]["cell"] is None and yarns[3]["angle"] == 0.0
    assert yarns[0]["node_ids"] == [0, 1, 2, 3]
    assert yarns[0]["nodes"] == [[2.5, 2.5, 0], [2.5, 2.5, 10], [2.5, 2.5, 20], [0, 0, 120]]
    assert yarns[3]["nodes"] == [[-5, 5, 15], [15, 5, 15]]


def test_contact_fields(small):
    contacts = skeleton_to_dict(small)["contacts"]
    assert contacts == [
        {"yarns": [1, 0], "nodes": [5, 1], "instruction": 2},
        {"yarns": [0, 1], "nodes": [2, 6], "instruction": 5},
    ]


def test_dict_is_plain_json(small):
    text = json.dumps(skeleton_to_dict(small), allow_nan=False)
    assert json.loads(text) == skeleton_to_dict(small)


def test_round_trip_through_text_is_exact():
    sk = build([weft([(1 / 3, 2 / 7, 0.1 + 0.2), (1e-17, -3.5e5, 1 / 9)], angle=-37.25)])
    back = skeleton_from_dict(json.loads(json.dumps(skeleton_to_dict(sk))))
    assert_same(sk, back)


def test_file_round_trip(small, tmp_path):
    path = tmp_path / "skeleton.json"
    write_skeleton_json(small, path)
    assert_same(small, read_skeleton_json(path))


def test_machine_override(small):
    other = MACHINE.__class__(rows=2, cols=2, pitch_x=1.0, pitch_y=1.0, d_mat=5.0, c_mat=1.0)
    assert skeleton_from_dict(skeleton_to_dict(small), other).machine == other


@pytest.mark.parametrize(
    "patch",
    [
        {"schema": "other"},
        {"version": 2},
        {"yarns": [{"id": 0, "kind": "knot", "node_ids": [], "nodes": []}]},
        {"yarns": [{"id": 0, "kind": "weft", "node_ids": [0], "nodes": [[0, 0, 0], [1, 1, 1]]}]},
        {"contacts": [{"yarns": [0], "nodes": [1, 2], "instruction": 1}]},
    ],
)
def test_malformed_document_is_refused(small, patch):
    d = skeleton_to_dict(small) | patch
    with pytest.raises(ExportError, match="malformed skeleton document"):
        skeleton_from_dict(d)


def test_unreadable_files(tmp_path):
    with pytest.raises(BwsdError, match="cannot read"):
        read_skeleton_json(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{", encoding="utf-8")
    with pytest.raises(ExportError, match="not valid JSON"):
        read_skeleton_json(bad)


def test_write_into_missing_directory(small, tmp_path):
    with pytest.raises(ExportError, match="cannot write"):
        write_skeleton_json(small, tmp_path / "nowhere" / "s.json")
