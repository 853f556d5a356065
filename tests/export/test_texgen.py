"""TexGen .tg3: round trip through real pytexgen, quiet stdout, registry clean-up."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import pytexgen.Core as tg

from bwsd.export.errors import ExportError
from bwsd.export.texgen import ZERO_DIAMETER_SECTION, read_tg3, up_vectors, write_tg3

from .conftest import build, warp, weft


def test_round_trip_nodes(small, tmp_path):
    path = tmp_path / "model.tg3"
    write_tg3(small, path)
    back = read_tg3(path)
    assert len(back) == len(small.yarns)
    for yarn, nodes in zip(small.yarns, back, strict=True):
        assert nodes.shape == yarn.nodes.shape
        assert np.allclose(nodes, yarn.nodes, rtol=0, atol=1e-9)


def test_round_trip_awkward_coordinates(tmp_path):
    rng = np.random.default_rng(7)
    nodes = rng.uniform(-500, 500, size=(9, 3))
    sk = build([warp([tuple(p) for p in nodes]), weft([(1 / 3, 2 / 3, 1 / 7), (-1 / 3, 5, 1 / 7)])])
    path = tmp_path / "awkward.tg3"
    write_tg3(sk, path)
    back = read_tg3(path)
    assert [len(b) for b in back] == [9, 2]
    assert np.max(np.abs(back[0] - nodes)) < 1e-9


def test_file_content(small, tmp_path):
    path = tmp_path / "model.tg3"
    write_tg3(small, path, name="preform")
    root = ET.parse(path).getroot()
    (textile,) = root.iter("Textile")
    assert textile.get("name") == "preform"
    yarns = list(textile.iter("Yarn"))
    assert len(yarns) == 4
    for y in yarns:
        interpolation = y.find("Interpolation")
        assert interpolation is not None
        assert interpolation.get("Periodic") == "0"
        assert interpolation.get("type") == "CInterpolationLinear"
        section = y.find("YarnSection/Section")
        assert section is not None
        assert section.get("type") == "CSectionEllipse"
        assert float(section.attrib["Width"]) == float(section.attrib["Height"]) == 1.0


def test_zero_diameter_gets_a_tiny_section(centreline, tmp_path):
    path = tmp_path / "line.tg3"
    write_tg3(centreline, path)
    widths = {float(s.attrib["Width"]) for s in ET.parse(path).getroot().iter("Section")}
    assert widths == {ZERO_DIAMETER_SECTION}


def test_registry_left_clean(small, tmp_path):
    path = tmp_path / "model.tg3"
    write_tg3(small, path)
    read_tg3(path)
    assert "bwsd" not in list(tg.GetTextiles())


def test_nothing_on_stdout(small, tmp_path, capfd):
    path = tmp_path / "model.tg3"
    write_tg3(small, path)
    read_tg3(path)
    assert capfd.readouterr().out == ""


@pytest.mark.slow
def test_nothing_on_piped_stdout(tmp_path):
    """With stdout a pipe the C library buffers fully: the chatter must not leak later."""
    script = (
        "import sys\n"
        "from tests.export.conftest import small_skeleton\n"
        "from bwsd.export.texgen import read_tg3, write_tg3\n"
        f"write_tg3(small_skeleton(), {str(tmp_path / 'm.tg3')!r})\n"
        f"print(len(read_tg3({str(tmp_path / 'm.tg3')!r})))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    assert done.stdout == "4\n"


def test_sections_of_vertical_yarns_are_not_degenerate(small, tmp_path, capfd):
    """TexGen's default up vector (+z) cannot orient a yarn along z; ours can."""
    path = tmp_path / "model.tg3"
    write_tg3(small, path)
    assert tg.ReadFromXML(str(path))
    try:
        yarn = tg.GetTextile("bwsd").GetYarns()[0]
        node = list(yarn.GetSlaveNodes(tg.CYarn.SURFACE))[3]
        points = np.array([(p.x, p.y, p.z) for p in node.GetSectionPoints()])
    finally:
        tg.DeleteTextile("bwsd")
    radii = np.linalg.norm(points[:, :2] - [2.5, 2.5], axis=1)
    assert np.allclose(radii, 0.5, atol=1e-2)  # TexGen smooths tangents a little
    assert "up vector" not in capfd.readouterr().err


def test_up_vectors_are_unit_and_normal():
    nodes = np.array([(0, 0, 0), (0, 0, 5), (3, 0, 9), (3, 4, 9), (3, 4, 9), (3, 4, 0)], float)
    ups = up_vectors(nodes)
    assert np.allclose(np.linalg.norm(ups, axis=1), 1.0)
    seg = np.diff(nodes, axis=0)
    for i, s in enumerate(seg):
        if np.linalg.norm(s) > 0:
            assert abs(np.dot(ups[i], s)) / np.linalg.norm(s) < 1 - 1e-3


def test_name_already_loaded(small, tmp_path):
    assert tg.AddTextile("taken", tg.CTextile())
    try:
        with pytest.raises(ExportError, match="already loaded"):
            write_tg3(small, tmp_path / "m.tg3", name="taken")
    finally:
        tg.DeleteTextile("taken")
    assert not (tmp_path / "m.tg3").exists()
    assert list(tmp_path.iterdir()) == []


def test_missing_directory(small, tmp_path):
    with pytest.raises(ExportError, match="directory does not exist"):
        write_tg3(small, tmp_path / "no" / "m.tg3")


def test_read_missing_or_broken(tmp_path):
    with pytest.raises(ExportError, match="no such file"):
        read_tg3(tmp_path / "none.tg3")
    broken = tmp_path / "broken.tg3"
    broken.write_text("<TexGenModel>", encoding="utf-8")
    with pytest.raises(ExportError, match="could not read"):
        read_tg3(broken)
