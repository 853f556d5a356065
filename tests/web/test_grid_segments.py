"""The page's matrix on a machine with line segments: a segment move highlights its cells only.

`bwsd serve` runs on a mock loom that declares the segments (the in-process live API of the
other page tests has the 4x4 machine without any).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from bwsd.api.auth import TokenStore
from tests.support.fieldbus import BUS, Mock, start_mock, toml
from tests.test_daemon import Served
from tests.web.conftest import MS, Browsing

pytestmark = pytest.mark.slow  # every test here is in the slow tier

MACHINE = {
    "rows": 4,
    "cols": 6,
    "pitch_x": 10.0,
    "pitch_y": 10.0,
    "d_mat": 100.0,
    "c_mat": 0.5,
    "segments": ["ROW 1[0..2]", "ROW 1[3..5]", "COL 2[1..3]"],
}
FILL = "FILL row=0 col=0\n......\nX....X\n..X...\nX.....\nEND\n"
# Row 1's two segments go opposite ways while row 3 moves whole; then column 2's segment.
ROWS_FIRST = f"YARN diameter=1\n{FILL}ROW 1[0..2]:+1 1[3..5]:-1 3:+1\nCOL 2[1..3]:-1\n"
COL_FIRST = f"YARN diameter=1\n{FILL}COL 2[1..3]:-1\nCOL 2[1..3]:+1\n"

# The cells whose centre lies in a highlight, and each highlight's span as the page keeps it.
HIGHLIGHTED = """() => {
  const bands = [...document.querySelectorAll('#grid .moving')].map((r) => ({
    x: +r.getAttribute('x'), y: +r.getAttribute('y'),
    w: +r.getAttribute('width'), h: +r.getAttribute('height'),
    span: [+r.dataset.line, +r.dataset.first, +r.dataset.last]}));
  const cells = [];
  for (const cell of document.querySelectorAll('#grid .cell')) {
    const box = cell.getBBox();
    const cx = box.x + box.width / 2, cy = box.y + box.height / 2;
    if (bands.some((b) => b.x <= cx && cx <= b.x + b.w && b.y <= cy && cy <= b.y + b.h)) {
      cells.push([+cell.dataset.row, +cell.dataset.col]);
    }
  }
  return {cells, spans: bands.map((b) => b.span)};
}"""
ARROWS = """() => [...document.querySelectorAll('#grid .arrow')].map((a) => ({
  text: a.textContent.replace(a.querySelector('title')?.textContent ?? '', ''),
  title: a.querySelector('title')?.textContent ?? null}))"""


@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[Served, str]]:
    """The daemon on a segmented mock loom, and an operator token for the page."""
    mock = start_mock(tmp_path, {}, machine=MACHINE, program=FILL)
    state = tmp_path / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    daemon = Served(_config(tmp_path, mock), state, token)
    try:
        yield daemon, token
    finally:
        daemon.stop()
        mock.stop()


def _config(tmp: Path, mock: Mock) -> Path:
    path = tmp / "bwsd.toml"
    path.write_text(
        toml(
            {
                "machine": MACHINE,
                "fieldbus": {"backend": "modbus", **BUS},
                "fieldbus.modbus": {"port": mock.ports["modbus"]},
                "api": {"port": 0},
                "plc": {"port": 0},
            }
        )
    )
    return path


def _ready_with(served: Served, token: str, page: Browsing, text: str) -> dict[str, Any]:
    """Load ``text``, reset, open the page; what its matrix highlights for the first move."""
    loaded = served.http.post("/programs", json={"name": "segments.bws", "text": text})
    assert loaded.status_code == 201, loaded.text
    served.command("reset")
    page.page.goto(f"{served.urls['api']}/#token={token}")
    page.ready()
    page.state("Idle")
    page.page.wait_for_selector("#grid .moving", timeout=MS)
    shown: dict[str, Any] = page.page.evaluate(HIGHLIGHTED)
    return shown


def test_a_row_segment_move_highlights_only_the_segments_cells(served, page: Browsing):
    daemon, token = served
    shown = _ready_with(daemon, token, page, ROWS_FIRST)
    row1 = [[1, c] for c in range(6)]  # both segments of row 1: all of it, in two bands
    assert sorted(shown["cells"]) == sorted(row1 + [[3, c] for c in range(6)])
    assert shown["spans"] == [[1, 0, 2], [1, 3, 5], [3, 0, 5]]
    assert page.page.evaluate(ARROWS) == [
        {
            "text": "⇄\u2009±",
            "title": "row 1: cells 0..2 move +1, cells 3..5 move -1 along its columns",
        },
        {"text": "→\u2009+1", "title": "row 3: moves +1 along its columns"},
    ]
    assert "ROW 1[0..2]:+1 1[3..5]:-1 3:+1" in page.page.locator("#next").inner_text()
    assert page.errors == []


def test_a_column_segment_move_highlights_only_the_segments_cells(served, page: Browsing):
    daemon, token = served
    shown = _ready_with(daemon, token, page, COL_FIRST)
    assert sorted(shown["cells"]) == [[1, 2], [2, 2], [3, 2]]  # not row 0 of column 2
    assert shown["spans"] == [[2, 1, 3]]
    assert page.page.evaluate(ARROWS) == [
        {"text": "↑", "title": None},
        {"text": "-1", "title": "column 2: cells 1..3 move -1 along its rows"},
    ]
    assert page.errors == []
