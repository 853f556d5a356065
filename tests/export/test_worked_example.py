"""All exports of a skeleton the twin really computed (the worked example of the twin)."""

from __future__ import annotations

from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

from bwsd.export import export
from bwsd.export.metrics import metrics
from bwsd.export.skeleton_json import read_skeleton_json
from bwsd.export.slice import draw_slice
from bwsd.export.texgen import read_tg3
from bwsd.twin.skeleton import SkeletonData

from .conftest import MACHINE
from .test_vtk import read_vtu


def worked_example() -> SkeletonData:
    """The worked example, built without the program parser."""
    from bwsd.twin import Program, Shift, simulate

    body = (
        Shift("row", ((0, 1), (1, -1))),
        Shift("col", ((1, 1), (0, -1))),
        Shift("row", ((1, -1), (0, 1))),
        Shift("col", ((0, -1), (1, 1))),
    )
    program = Program(diameter=1.0, fill=((0, 0), (1, 1)), instructions=body * 4, cycle_length=4)
    return simulate(MACHINE, program).skeleton()


def test_all_exports_of_the_worked_example(tmp_path):
    sk = worked_example()
    assert (len(sk.yarns), len(sk.contacts), sk.node_count) == (2, 15, 34)
    for suffix in (".json", ".tg3", ".vtp", ".vtu"):
        export(sk, tmp_path / f"example{suffix}")
    back = read_skeleton_json(tmp_path / "example.json")
    assert back.contacts == sk.contacts
    tg3 = read_tg3(tmp_path / "example.tg3")
    assert [len(n) for n in tg3] == [len(y.nodes) for y in sk.yarns]
    assert all(abs(a - y.nodes).max() < 1e-9 for a, y in zip(tg3, sk.yarns, strict=True))
    mesh = read_vtu(tmp_path / "example.vtu")
    assert len(mesh.cells[0].data) == (34 - 2) + 15
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(tmp_path / "example.vtp"))
    reader.Update()
    poly = reader.GetOutput()
    assert (poly.GetNumberOfPoints(), poly.GetNumberOfLines()) == (34, 2 + 15)


def test_metrics_and_slice_of_the_worked_example(tmp_path):
    sk = worked_example()
    result = metrics(sk, 4)
    counts = result["cycles"]["counts"]
    assert (len(counts), sum(counts), result["cycles"]["complete"]) == (4, 15, 4)
    first = result["cycles"]["per_instruction"]
    assert first[0] == 0 and first[1] >= 1  # the first contact is made by instruction 2
    assert result["section"] is not None
    assert result["section"]["width"] > sk.diameter
    assert draw_slice(sk, 20.0, tmp_path / "cut.png") == 2
