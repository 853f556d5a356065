"""A program too big for the loom is refused at its place, naming the matrix it needs."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from bwsd.config import load_config
from bwsd.controller.plan import Limits
from bwsd.controller.programs import check_program
from bwsd.errors import ProgramError
from tests.api.conftest import Live

ROOT = Path(__file__).resolve().parents[2]
LOOM = load_config(ROOT / "config/loom.toml").machine
NEEDS = re.compile(r"it needs a matrix of at least (\d+) x (\d+); this loom has (\d+) x (\d+)")


def _header_size(text: str) -> tuple[int, int]:
    """The machine an example was generated for (its ``# machine: R x C cells`` line)."""
    found = re.search(r"^# machine: (\d+) x (\d+) cells", text, re.MULTILINE)
    assert found, "the example names its machine"
    return int(found[1]), int(found[2])


def _too_big(path: Path) -> bool:
    rows, cols = _header_size(path.read_text())
    return rows > LOOM.rows or cols > LOOM.cols


TOO_BIG = [p.name for p in sorted((ROOT / "examples").glob("*.bws")) if _too_big(p)]


def test_some_shipped_examples_are_too_big_for_the_shipped_loom():
    assert "braid-24x24.bws" in TOO_BIG and "braid-2x2.bws" not in TOO_BIG


@pytest.mark.parametrize("name", TOO_BIG)
def test_a_shipped_example_too_big_for_the_loom_names_its_x_and_the_size_it_needs(name):
    text = (ROOT / "examples" / name).read_text()
    with pytest.raises(ProgramError) as info:
        check_program(LOOM, Limits(), 1_000_000, name, text, None)
    err = info.value
    assert err.line > 0 and err.column > 0, err
    assert text.split("\n")[err.line - 1][err.column - 1] in "Xx"  # the cell that leaves
    needs = NEEDS.search(err.reason)
    assert needs, err.reason
    rows, cols, loom_rows, loom_cols = map(int, needs.groups())
    assert (loom_rows, loom_cols) == (LOOM.rows, LOOM.cols)
    assert rows > LOOM.rows or cols > LOOM.cols
    header_rows, header_cols = _header_size(text)
    assert rows <= header_rows and cols <= header_cols  # it fits the machine it was made for


@pytest.mark.slow
def test_the_api_answers_the_line_column_and_size_of_a_fill_too_big(live: Live):
    """The 24 x 24 braid on the 4 x 4 loom: refused at its first X outside, both as a check
    and as a load, naming the 26 x 26 matrix it needs; nothing is loaded."""
    operator = live.client("operator")
    text = (ROOT / "examples/braid-24x24.bws").read_text()
    for params in ({"dry_run": "true"}, {}):
        answer = operator.post(
            "/programs", params=params, json={"name": "braid-24x24.bws", "text": text}
        )
        assert answer.status_code == 422, answer.text
        body = answer.json()
        assert (body["line"], body["column"]) == (7, 6), body  # row 0's X in column 5
        assert body["error"] == (
            "fill cell (0, 5) is outside the 4 x 4 matrix: the program fills cells up to row 25, "
            "column 25, so it needs a matrix of at least 26 x 26; this loom has 4 x 4"
        )
    assert live.controller.program is None


@pytest.mark.slow
def test_a_line_past_the_matrix_says_how_many_lines_the_program_needs(live: Live):
    operator = live.client("operator")
    text = "FILL row=1 col=0\n.XX.\nEND\nROW 1:+1\nCOL 0:+1 6:-1\n"
    body = operator.post("/programs", json={"name": "c.bws", "text": text}).json()
    assert (body["line"], body["column"]) == (5, 10), body  # the entry "6:-1"
    assert body["error"] == (
        "instruction 2: col 6 is outside the matrix (0 to 3): the program "
        "needs at least 7 columns; this loom has 4"
    )


def test_a_program_too_long_names_the_repeat_that_passes_the_limit():
    """Two top-level REPEATs, each within the limit, together past it: the second is named."""
    cycle = "ROW 1:+1 2:-1\nROW 1:-1 2:+1\n"
    text = f"FILL row=1 col=0\n.XX.\nEND\nREPEAT 30\n{cycle}END\nREPEAT 30\n{cycle}END\n"
    with pytest.raises(ProgramError) as info:
        check_program(LOOM, Limits(), 100, "long.bws", text, None)
    assert (info.value.line, info.value.column) == (8, 1)
    assert info.value.reason == (
        "the program expands to more than 100 instructions "
        "([controller] max_instructions): 120 in all"
    )
