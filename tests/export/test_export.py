"""export(): dispatch on the suffix."""

from __future__ import annotations

import json

import pytest
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

from bwsd.errors import BwsdError
from bwsd.export import FORMATS, ExportError, export
from bwsd.export.texgen import read_tg3

from .test_vtk import read_vtu


def test_json(small, tmp_path):
    export(small, tmp_path / "s.JSON")
    assert json.loads((tmp_path / "s.JSON").read_text())["schema"] == "bwsd-skeleton"


def test_tg3(small, tmp_path):
    export(small, tmp_path / "s.tg3")
    assert len(read_tg3(tmp_path / "s.tg3")) == 4


def test_vtu(small, tmp_path):
    export(small, str(tmp_path / "s.vtu"))
    assert len(read_vtu(tmp_path / "s.vtu").points) == 13


def test_vtp(small, tmp_path):
    export(small, tmp_path / "s.VTP")
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(tmp_path / "s.VTP"))
    reader.Update()
    poly = reader.GetOutput()
    # one polyline per yarn and one line per contact, not one cell per segment
    assert (poly.GetNumberOfPoints(), poly.GetNumberOfLines()) == (13, 4 + 2)


def test_formats_listed():
    assert set(FORMATS) == {".json", ".tg3", ".vtp", ".vtu"}


@pytest.mark.parametrize("name", ["s.obj", "s", "s.vtk"])
def test_unknown_suffix(small, tmp_path, name):
    with pytest.raises(ExportError, match="unknown export format") as info:
        export(small, tmp_path / name)
    assert isinstance(info.value, BwsdError)
    assert all(suffix in str(info.value) for suffix in (".json", ".tg3", ".vtp", ".vtu"))
    assert list(tmp_path.iterdir()) == []
