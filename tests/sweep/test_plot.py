"""`bwsd sweep plot`: a PNG with one line per hue value, through the points of the table."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from matplotlib.image import imread

from bwsd.sweep.errors import SweepError
from bwsd.sweep.plot import figure, plot, read_rows
from bwsd.sweep.runner import Options, run_sweep
from bwsd.sweep.spec import load_spec
from tests.sweep.conftest import BRAID_SPEC, bwsd, write


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plot")
    output = folder / "braid.parquet"
    run_sweep(load_spec(write(folder, BRAID_SPEC)), output, Options(workers=2))
    return output


def _rows(**change: Any) -> dict[str, Any]:
    base = {"status": "ok", "takeup": 1.0, "c_mat": 0.3, "angle_warp": 10.0}
    return {**base, **change}


def test_one_line_per_hue_value_through_the_mean_of_each_point():
    rows = [
        _rows(takeup=1.0, angle_warp=10.0),
        _rows(takeup=2.0, angle_warp=8.0),
        _rows(takeup=2.0, angle_warp=6.0),
        _rows(c_mat=0.6, angle_warp=12.0),
        _rows(c_mat=0.6, takeup=3.0, angle_warp=None),
        _rows(c_mat=0.9, status="refused", angle_warp=None),
    ]
    fig = figure(rows, "takeup", "angle_warp", "c_mat")
    lines = fig.axes[0].get_lines()
    assert [line.get_label() for line in lines] == ["0.3", "0.6"]  # refused: no line
    assert lines[0].get_xydata().tolist() == [[1.0, 10.0], [2.0, 7.0]]
    assert lines[1].get_xydata().tolist() == [[1.0, 12.0]]
    assert "mean of up to 2 candidates" in fig.axes[0].get_title()
    assert (fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel()) == (
        "takeup (mm)",
        "angle_warp (degrees)",
    )


@pytest.mark.slow
def test_the_png_has_a_line_of_each_colour(results, tmp_path):
    png = tmp_path / "angle.png"
    assert plot(results, png, "takeup", "angle_warp", "c_mat") == 2
    image = imread(png)[..., :3]
    fig = figure(read_rows(results), "takeup", "angle_warp", "c_mat")
    for line in fig.axes[0].get_lines():
        colour = np.array(to_rgb(line.get_color()))
        drawn = np.all(np.abs(image - colour) < 0.02, axis=-1).sum()
        assert drawn > 500, f"too few pixels of {line.get_label()}'s colour: {drawn}"
    assert len(fig.axes[0].get_lines()) == 2


@pytest.mark.slow
def test_plot_command_and_its_errors(results, tmp_path):
    run = bwsd(
        "sweep",
        "plot",
        str(results),
        "--x",
        "takeup",
        "--y",
        "contacts",
        "--hue",
        "cycles",
        "-o",
        str(tmp_path / "c.png"),
        cwd=tmp_path,
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == f"{tmp_path / 'c.png'}: contacts against takeup, 2 lines"
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = bwsd(
        "sweep",
        "plot",
        str(results),
        "--x",
        "take_up",
        "--y",
        "contacts",
        "-o",
        str(tmp_path / "d.png"),
        cwd=tmp_path,
    )
    assert bad.returncode == 2
    assert "bwsd: error: --x take_up: no such column (columns: id, index, rows" in bad.stderr
    assert not (tmp_path / "d.png").exists()
    with pytest.raises(SweepError, match=r"--y section: the column holds no numbers"):
        figure([_rows(section="rect:2x2")], "takeup", "section")
