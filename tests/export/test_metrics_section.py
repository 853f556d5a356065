"""`bwsd metrics` for shaped preforms: contact groups, carrier mixing, footprint at a height."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rich.console import Console

from bwsd.cli import main
from bwsd.errors import ProgramError
from bwsd.export.cli import simulate_program
from bwsd.export.footprint import Grid, disc_samples, footprint
from bwsd.export.metrics import groups, metrics, section, unconnected
from bwsd.export.mixing import section_header
from bwsd.export.tables import print_metrics
from bwsd.program.sections import parse_section

from .conftest import MACHINE, build, warp, weft

ROOT = Path(__file__).resolve().parents[2]
BWSD = shutil.which("bwsd", path=str(Path(sys.executable).parent))

# The 4-step braid of a 2 x 2 body (bwsd program braid4 --rows 2 --cols 2 as of this
# writing), kept here so that the numbers measured on it stay those of this program.
BRAID_CONFIG = """\
[machine]
rows = 4
cols = 4
pitch_x = 10.0
pitch_y = 10.0
d_mat = 150.0
c_mat = 0.4

[yarn]
diameter = 1.5
"""
BRAID_PROGRAM = """\
YARN diameter=1.5
FILL row=0 col=0
.X..
XXX.
.XXX
..X.
END
REPEAT 10
    ROW 1:+1 2:-1
    COL 1:+1 2:-1
    ROW 1:-1 2:+1
    COL 1:-1 2:+1
    TAKEUP 3
END
"""

# A 5 x 5 matrix whose column 1 has a segment over rows 1..2 with an actuator of its own.
L_CONFIG = """\
[machine]
rows = 5
cols = 5
pitch_x = 10.0
pitch_y = 10.0
d_mat = 100.0
c_mat = 0.5
segments = ["COL 1[1..2]"]

[yarn]
diameter = 1.0
"""

# The L:1x3:2x1 section: flange (1,2) (1,3), junction (1,1), web (2,1) (3,1). Yarns 0 and
# 1 twist round the square (1,1) (1,2) (2,2) (2,1), one turn per 4 instructions:
#   yarn 0: (1,1) junction -> (1,2) flange -> (2,2) outside -> (2,1) web -> (1,1)
#   yarn 1: (2,2) outside -> (2,1) web -> (1,1) junction -> (1,2) flange -> (2,2)
# so both have visited flange and web after instruction 3. Column 1 moves only over its
# segment [1..2]: yarn 2, filled at (3,1) in the web, never moves.
L_PROGRAM = """\
# Two carriers twisting through the corner of an L{rest}
{header}FILL row=0 col=0
.....
.X...
..X..
.{third}...
.....
END
REPEAT 2
    ROW 1:+1 2:-1
    COL 2:+1 1[1..2]:-1
    ROW 2:-1 1:+1
    COL 1[1..2]:-1 2:+1
END
"""


@pytest.fixture(scope="module")
def braid(tmp_path_factory) -> tuple[str, str]:
    """The 2 x 2 braid's program and config files."""
    folder = tmp_path_factory.mktemp("braid")
    (folder / "braid.bws").write_text(BRAID_PROGRAM, encoding="utf-8")
    (folder / "braid.toml").write_text(BRAID_CONFIG, encoding="utf-8")
    return str(folder / "braid.bws"), str(folder / "braid.toml")


def l_program(tmp_path: Path, *, header: str = "# section: L:1x3:2x1\n", third: bool = True):
    rest = ", a third resting in its web" if third else ""
    text = L_PROGRAM.format(rest=rest, header=header, third="X" if third else ".")
    (tmp_path / "l.toml").write_text(L_CONFIG, encoding="utf-8")
    (tmp_path / "l.bws").write_text(text, encoding="utf-8")
    return str(tmp_path / "l.bws"), str(tmp_path / "l.toml")


def run_json(
    capsys: pytest.CaptureFixture[str], program: str, config: str, *args: str
) -> dict[str, Any]:
    assert main(["metrics", program, "--config", config, "--json", *args]) == 0
    result: dict[str, Any] = json.loads(capsys.readouterr().out)
    return result


def run_error(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    assert main(["metrics", *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    return captured.err


def disc(d: float) -> float:
    return math.pi * d * d / 4


# ----- contact groups -----


def test_groups_of_a_hand_built_skeleton():
    line = [(0.0, 0.0, 0.0), (0.0, 0.0, 9.0)]
    sk = build(
        [warp(line), warp(line), warp(line), warp(line), weft(line), warp(line), warp(line)],
        # (instruction, moving yarn, its node, hit yarn, its node); node ids are 2 per yarn
        [(1, 2, 4, 1, 2), (2, 0, 0, 1, 3), (3, 3, 6, 4, 8), (4, 6, 12, 4, 9)],
    )
    assert groups(sk) == {"count": 3, "sizes": [3, 3, 1], "members": [[0, 1, 2], [3, 4, 6], [5]]}
    assert unconnected(sk) == {"count": 1, "ids": [5]}
    alone = build([warp(line), warp(line)])
    assert groups(alone)["members"] == [[0], [1]]
    assert unconnected(alone) == {"count": 2, "ids": [0, 1]}


@pytest.mark.parametrize("stem", ["braid-2x2", "twist", "weave-plain"])
def test_a_shipped_preform_is_one_group(stem):
    sk, _ = simulate_program(
        str(ROOT / "config" / f"{stem}.toml"), str(ROOT / "examples" / f"{stem}.bws")
    )
    found = groups(sk)
    assert (found["count"], found["sizes"]) == (1, [len(sk.yarns)])
    assert unconnected(sk) == {"count": 0, "ids": []}


@pytest.mark.parametrize("stem", ["braid-L", "paper-L"])
def test_metrics_say_a_shipped_shaped_braid_is_one_preform_of_mixed_carriers(capsys, stem):
    """From the program's own '# section:' line: one group, and (braid-L runs its K cycles)
    every carrier through flange and web; paper-L runs the paper's 10 cycles, fewer than K."""
    result = run_json(
        capsys, str(ROOT / "examples" / f"{stem}.bws"), str(ROOT / "config" / f"{stem}.toml")
    )
    assert result["groups"]["count"] == 1 and result["unconnected"]["count"] == 0
    mixing = result["mixing"]
    assert (result["section_spec"]["shape"], result["section_spec"]["source"]) == ("L", "header")
    if stem == "braid-L":
        assert mixing["incomplete"] == 0 and mixing["complete"] == mixing["carriers"] == 32
        assert mixing["k"] == 11
    else:
        assert 0 < mixing["complete"] < mixing["carriers"] and mixing["k"] is None


# ----- carrier mixing -----


def test_a_carrier_resting_in_the_web_never_mixes(tmp_path, capsys):
    result = run_json(capsys, *l_program(tmp_path))
    assert result["section_spec"] == {
        "spec": "L:1x3:2x1",
        "shape": "L",
        "source": "header",
        "line": 2,
    }
    mixing = result["mixing"]
    assert (mixing["carriers"], mixing["edge"], mixing["empty_body_cells"]) == (3, 1, 3)
    assert mixing["zones"] == [
        {"name": "flange", "cells": 2, "required": True, "carriers": 2},
        {"name": "junction", "cells": 1, "required": False, "carriers": 2},
        {"name": "web", "cells": 2, "required": True, "carriers": 3},
    ]
    assert (mixing["complete"], mixing["incomplete"]) == (2, 1)
    assert mixing["missing"] == [{"yarn": 2, "cell": [3, 1], "zones": ["flange"]}]
    assert (mixing["instruction"], mixing["k"], mixing["cycle_length"]) == (None, None, 4)
    # the resting yarn is never reached either: a group of its own, without contacts
    assert result["unconnected"] == {"count": 1, "ids": [2]}
    assert result["groups"]["sizes"] == [2, 1]


@pytest.mark.parametrize(("length", "k"), [(None, 1), ("4", 1), ("2", 2), ("1", 3), ("8", 1)])
def test_k_is_the_first_cycle_after_which_all_have_mixed(tmp_path, capsys, length, k):
    program, config = l_program(tmp_path, third=False)
    args = [] if length is None else ["--cycle-length", length]
    mixing = run_json(capsys, program, config, *args)["mixing"]
    assert (mixing["complete"], mixing["incomplete"], mixing["missing"]) == (2, 0, [])
    assert (mixing["instruction"], mixing["k"]) == (3, k)


def test_a_rect_braid_mixes_in_its_first_cycle(capsys, braid):
    # Step 1 shifts every body row, taking each row's edge carrier into the body; step 2
    # does the same for the columns: every carrier has sat in the body after instruction 2.
    mixing = run_json(capsys, *braid, "--section", "rect:2x2")["mixing"]
    assert (mixing["carriers"], mixing["edge"], mixing["empty_body_cells"]) == (8, 4, 0)
    assert (mixing["complete"], mixing["instruction"], mixing["k"]) == (8, 2, 1)


def test_the_option_overrides_the_section_line_and_neither_is_fine(tmp_path, capsys):
    program, config = l_program(tmp_path)
    result = run_json(capsys, program, config, "--section", "rect:3x3")
    assert result["section_spec"] == {
        "spec": "rect:3x3",
        "shape": "rect",
        "source": "option",
        "line": None,
    }
    assert result["mixing"]["zones"][0]["cells"] == 9
    plain, _ = l_program(tmp_path, header="")
    result = run_json(capsys, plain, config, "--z", "10")
    assert (result["section_spec"], result["mixing"]) == (None, None)
    assert result["footprint"]["nominal"] is None
    assert result["footprint"]["crossings"] == 3


def test_section_line_rules():
    header = section_header("YARN diameter=1\n#Section :rect:2x2  (the body)\n")
    assert header is not None and header.line == 2
    named = section_header("  #  section: T:2x8:4x2@1,2\n")
    assert named is not None and named.section.spec == "T:2x8:4x2"
    assert section_header("ROW 1:+1  # section: rect:1x1\n# sections: rect:1x1\n") is None
    with pytest.raises(
        ProgramError, match=r"p\.bws:3:1: a second '# section:' line \(the first is line 1\)"
    ):
        section_header("# section: rect:1x1\n\n# section: rect:2x2\n", "p.bws")
    with pytest.raises(ProgramError, match=r"p\.bws:2:12: # section: not a section: 'L:2x6'"):
        section_header("FILL\n# section: L:2x6\n", "p.bws")


@pytest.mark.slow
def test_bad_section_text_is_one_line_from_the_console_script(braid):
    assert BWSD, "the bwsd console script is not installed beside this Python"
    done = subprocess.run(
        [BWSD, "metrics", braid[0], "--config", braid[1], "--section", "L:2x6"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.startswith("bwsd: error: --section: not a section: 'L:2x6' (expected ")
    assert done.stderr.count("\n") == 1
    assert "Traceback" not in done.stderr


def test_other_section_faults_end_with_one_line(tmp_path, capsys, braid):
    program, config = l_program(tmp_path, header="# section: L:2x6\n")
    assert run_error(capsys, program, "--config", config).startswith(
        f"bwsd: error: {program}:2:12: # section: not a section: 'L:2x6'"
    )
    err = run_error(capsys, braid[0], "--config", braid[1], "--section", "L:2x6:4x2")
    assert err == (
        "bwsd: error: section L:2x6:4x2 does not fit the 4 x 4 matrix of the config: "
        "its cell (1, 4) lies outside\n"
    )
    for command in ("metrics", "slice"):  # argparse's usage, then one line naming --z
        with pytest.raises(SystemExit) as stop:
            main(
                [command, braid[0], "--config", braid[1], "--z", "nan", "-o", "x.png"][
                    : 6 if command == "metrics" else 8
                ]
            )
        assert stop.value.code == 2
        err = capsys.readouterr().err
        assert err.endswith(
            f"bwsd {command}: error: argument --z: must be a finite height in mm, got 'nan'\n"
        )


# ----- footprint -----


def test_inscribed_discs_cover_pi_over_four_of_their_tiles():
    # MACHINE: 2 x 2 cells, pitch 10, c_mat 0.5: tiles of 5 x 5 mm centred on the fell
    # points (2.5 | 7.5, 2.5 | 7.5). A vertical yarn of diameter 5 on each fell point
    # fills the disc inscribed in its tile; a fifth one lies one tile beyond the shape.
    centres = [(2.5, 2.5), (7.5, 2.5), (2.5, 7.5), (7.5, 7.5), (12.5, 2.5)]
    sk = build([warp([(x, y, 0.0), (x, y, 10.0), (x, y, 100.0)]) for x, y in centres], diameter=5.0)
    result = footprint(sk, 5.0, parse_section("rect:2x2@0,0"))
    assert result["nominal"] == {
        "section": "rect:2x2",
        "cells": 4,
        "area": 100.0,
        "x": [0.0, 10.0],
        "y": [0.0, 10.0],
    }
    assert result["grid"] == [5 / 64, 5 / 64]  # 64 steps of a tile of 5 mm: d / 64
    assert (result["crossings"], result["free"]) == (5, 0)
    assert result["coverage"] == pytest.approx(math.pi / 4, rel=0.01)
    assert result["measured"]["area"] == pytest.approx(5 * disc(5.0), rel=0.01)
    assert result["ratio"] == pytest.approx(5 * disc(5.0) / 100, rel=0.01)
    assert result["outside"] == pytest.approx(disc(5.0), rel=0.01)
    assert (result["measured"]["x"], result["measured"]["y"]) == ([0.0, 15.0], [0.0, 10.0])


def test_a_rect_braid_at_its_start_edge(capsys, braid):
    # At z = 0 every crossing is a fill node, at the centre of its cell's tile (4 x 4 mm
    # here): the 4 body yarns' discs lie inside the nominal square of 8 x 8 mm, the 4 edge
    # carriers' discs in the tiles around it.
    result = run_json(capsys, *braid, "--section", "rect:2x2", "--z", "0")["footprint"]
    d = 1.5
    assert result["crossings"] == 8
    assert result["nominal"]["area"] == 64.0
    assert (result["nominal"]["x"], result["nominal"]["y"]) == ([11.0, 19.0], [11.0, 19.0])
    assert result["coverage"] == pytest.approx(4 * disc(d) / 64, rel=0.01)
    assert result["outside"] == pytest.approx(4 * disc(d), rel=0.01)
    assert result["ratio"] == pytest.approx(8 * disc(d) / 64, rel=0.01)


def test_a_rect_braid_fills_more_of_its_square_where_it_is_formed(braid):
    """In a 4-step braid every carrier passes through the body, so in the formed preform
    the edge carriers' yarns lie inside the nominal square too: at every height of the
    measuring band of ``section`` (the middle half of the contact zone) the covered area
    exceeds that of 5 of the 8 yarn discs (measured: 5.4 at least, 6.5 on average), where
    the start edge has exactly the 4 body yarns inside."""
    sk, _ = simulate_program(braid[1], braid[0])
    shape = parse_section("rect:2x2")
    band = section(sk)
    assert band is not None
    low, high = band["z"]
    for z in np.linspace(low, high, 33):
        result = footprint(sk, float(z), shape)
        covered = result["coverage"] * result["nominal"]["area"]
        assert covered > 5 * disc(sk.diameter), z
        assert result["coverage"] <= result["ratio"] + 1e-12  # covered area <= measured area
        assert result["ratio"] <= 8 * disc(sk.diameter) / 64 * 1.01  # the union <= 8 discs


def test_one_disc_is_sampled_within_one_percent():
    rng = np.random.default_rng(7)
    for d in (0.7, 1.0, 1.5, 3.0):
        grid = Grid.of(MACHINE, d)
        centres = [rng.uniform(-20, 20, size=2) for _ in range(100)] + [MACHINE.fell_xy(1, 0)]
        for centre in centres:
            ix, _ = disc_samples(np.array([centre]), d / 2, grid)
            assert len(ix) * grid.cell_area == pytest.approx(disc(d), rel=0.01)


def test_centrelines_have_no_footprint(centreline):
    result = footprint(centreline, 15.0, parse_section("rect:2x2@0,0"))
    assert result["crossings"] == 3
    assert (result["grid"], result["measured"]["area"]) == (None, 0.0)
    assert (result["coverage"], result["ratio"], result["outside"]) == (0.0, 0.0, 0.0)


# ----- output -----


def test_tables_show_groups_mixing_and_footprint(tmp_path, capsys, braid):
    result = run_json(capsys, *l_program(tmp_path), "--z", "10")
    console = Console(record=True, width=140)
    print_metrics(result, console)
    text = console.export_text()
    for expected in (
        "Contact graph",
        "2, 1",
        "Carrier mixing, section L:1x3:2x1 (from program line 2)",
        "yarn 2 (filled at 3, 1)",
        "missed flange",
        "never within the program",
        "Footprint at z = 10 mm",
        "nominal covered",
    ):
        assert expected in text, expected
    assert metrics(simulate_program(braid[1], braid[0])[0], None)["footprint"] is None


@pytest.mark.slow
def test_metrics_with_section_and_height_needs_no_extra(tmp_path, braid):
    """The console script with VTK, pytexgen and matplotlib unimportable."""
    assert BWSD, "the bwsd console script is not installed beside this Python"
    (tmp_path / "sitecustomize.py").write_text(
        "import sys\n"
        "for name in ('vtk', 'vtkmodules', 'pytexgen', 'matplotlib'):\n"
        "    sys.modules[name] = None\n"
    )
    path = os.pathsep.join(p for p in (str(tmp_path), os.environ.get("PYTHONPATH", "")) if p)
    done = subprocess.run(
        [
            BWSD,
            "metrics",
            braid[0],
            "--config",
            braid[1],
            "--section",
            "rect:2x2",
            "--z",
            "100",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": path},
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["groups"]["count"] == 1
    assert result["mixing"]["k"] == 1
    assert 0 < result["footprint"]["coverage"] < 1
