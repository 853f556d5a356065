"""`bwsd metrics` for shaped preforms: contact groups, carrier mixing."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console

from bwsd.cli import main
from bwsd.errors import ProgramError
from bwsd.export.cli import print_metrics, simulate_program
from bwsd.export.metrics import groups, unconnected
from bwsd.export.mixing import section_header

from .conftest import build, warp, weft

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


def run_json(capsys, program: str, config: str, *args: str) -> dict:
    assert main(["metrics", program, "--config", config, "--json", *args]) == 0
    return json.loads(capsys.readouterr().out)


def run_error(capsys, *args: str) -> str:
    assert main(["metrics", *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    return captured.err


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
    result = run_json(capsys, plain, config)
    assert (result["section_spec"], result["mixing"]) == (None, None)


def test_section_line_rules():
    assert section_header("YARN diameter=1\n#Section :rect:2x2  (the body)\n").line == 2
    assert section_header("  #  section: T:2x8:4x2@1,2\n").section.spec == "T:2x8:4x2"
    assert section_header("ROW 1:+1  # section: rect:1x1\n# sections: rect:1x1\n") is None
    with pytest.raises(
        ProgramError, match=r"p\.bws:3:1: a second '# section:' line \(the first is line 1\)"
    ):
        section_header("# section: rect:1x1\n\n# section: rect:2x2\n", "p.bws")
    with pytest.raises(ProgramError, match=r"p\.bws:2:12: # section: not a section: 'L:2x6'"):
        section_header("FILL\n# section: L:2x6\n", "p.bws")


def test_bad_section_text_is_one_line_from_the_console_script(braid):
    assert BWSD, "the bwsd console script is not installed beside this Python"
    done = subprocess.run([BWSD, "metrics", braid[0], "--config", braid[1], "--section", "L:2x6"],
                          capture_output=True, text=True, timeout=120, check=False)  # fmt: skip
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
    assert err == ("bwsd: error: section L:2x6:4x2 does not fit the 4 x 4 matrix of the config: "
                   "its cell (1, 4) lies outside\n")  # fmt: skip


# ----- output -----


def test_tables_show_groups_and_mixing(tmp_path, capsys):
    result = run_json(capsys, *l_program(tmp_path))
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
    ):
        assert expected in text, expected


def test_metrics_with_a_section_needs_no_extra(tmp_path, braid):
    """The console script with VTK, pytexgen and matplotlib unimportable."""
    assert BWSD, "the bwsd console script is not installed beside this Python"
    (tmp_path / "sitecustomize.py").write_text(
        "import sys\n"
        "for name in ('vtk', 'vtkmodules', 'pytexgen', 'matplotlib'):\n"
        "    sys.modules[name] = None\n"
    )
    path = os.pathsep.join(p for p in (str(tmp_path), os.environ.get("PYTHONPATH", "")) if p)
    done = subprocess.run(
        [BWSD, "metrics", braid[0], "--config", braid[1], "--section", "rect:2x2", "--json"],
        capture_output=True, text=True, timeout=120, check=False, cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": path},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["groups"]["count"] == 1
    assert result["mixing"]["k"] == 1
