"""The seed paper's case studies (docs/paper.md): one preform each, and what the doc states.

The counts are read from the doc's results table, so the doc cannot drift from the examples:
regenerate the table with ``python bench/paper.py`` when an example or the twin changes.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bwsd.config import load_config
from bwsd.export.metrics import contact_groups
from bwsd.program import load_program
from bwsd.twin import Program, Shift, TakeUp, Twin, Weft, simulate

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "paper.md"
PAPER = {"paper-L": 504, "paper-U": 610}  # the paper's interferences for its 10 cycles


def _results() -> dict[str, dict[str, str]]:
    """The rows of the doc's first table with a ``contacts (bwsd)`` column, by example."""
    lines = DOC.read_text(encoding="utf-8").splitlines()
    start = next(
        i for i, line in enumerate(lines) if line.startswith("|") and "contacts (bwsd)" in line
    )
    header = _cells(lines[start])
    rows = {}
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        row = dict(zip(header, _cells(line), strict=True))
        rows[row["example"]] = row
    return rows


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _run(stem: str) -> tuple[Program, Twin]:
    machine = load_config(ROOT / "config" / f"{stem}.toml").machine
    program = load_program(ROOT / "examples" / f"{stem}.bws", machine)
    return program, simulate(machine, program)


def test_the_doc_states_both_cases_with_the_papers_interferences():
    rows = _results()
    assert set(rows) == set(PAPER)
    for stem, interferences in PAPER.items():
        assert int(rows[stem]["interferences (paper)"]) == interferences


@pytest.mark.parametrize("stem", sorted(PAPER))
def test_the_example_gives_what_the_doc_states(stem):
    row = _results()[stem]
    _, twin = _run(stem)
    assert twin.contact_count == int(row["contacts (bwsd)"])
    assert twin.node_count == int(row["nodes (bwsd)"])
    assert twin.yarn_count == int(row["yarns"])
    assert twin.done == int(row["instructions"])


@pytest.mark.parametrize("stem", sorted(PAPER))
def test_the_example_is_one_preform(stem):
    _, twin = _run(stem)
    assert len(contact_groups(twin.skeleton())) == 1


def test_paper_L_runs_the_papers_ten_four_step_cycles():
    """ROW, COL, ROW, COL and a take-up, ten times: 5 cycles of the 8-step L rule."""
    program, _ = _run("paper-L")
    kinds = ["S" if isinstance(ins, Shift) else "T" for ins in program.instructions]
    assert "".join(kinds) == "SSSST" * 10
    axes = [ins.axis for ins in program.instructions if isinstance(ins, Shift)]
    assert axes == ["row", "col"] * 20


def test_paper_U_runs_ten_cycles_of_four_picks():
    """A pick opens a shed, inserts its wefts, closes it and takes up: 40 picks, 200 wefts."""
    program, _ = _run("paper-U")
    assert program.cycle_length and len(program.instructions) == 10 * program.cycle_length
    assert sum(isinstance(ins, TakeUp) for ins in program.instructions) == 40
    assert sum(isinstance(ins, Shift) for ins in program.instructions) == 80
    assert sum(isinstance(ins, Weft) for ins in program.instructions) == 200


def test_the_measured_table_sets_no_ratio_across_hardware_and_the_doc_says_what_is_open():
    """The paper's seconds (its hardware, 2013) and bwsd's (this machine) are not set
    against each other in the table of measured figures; the doc lists what the paper
    compares with manufactured preforms and its named next steps."""
    lines = DOC.read_text(encoding="utf-8").splitlines()
    header = next(line for line in lines if line.startswith("|") and "contacts (bwsd)" in line)
    assert "paper / bwsd" not in header and "paper s" not in header
    text = DOC.read_text(encoding="utf-8")
    assert "## What the paper compares, and what is still open" in text
    section = text.split("## What the paper compares, and what is still open")[1]
    for item in (
        "width and thickness",
        "braid angle",
        "relaxation",
        "tension equilibrium",
        "non-circular sections",
        "weft crimp",
    ):
        assert f"| {item}" in section, item
    assert "138.15 s" in text and "376 s" in text  # the paper's times, quoted as its own
