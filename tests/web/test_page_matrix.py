"""The page's machine matrix in a real browser, against `bwsd serve` on the mock loom.

End to end: a sensor fault, the e-stop or a drive fault injected through the mock loom's
control channel reaches the daemon's `/state`, the page reads it and its matrix marks the
cell, greys itself or marks the axis's line; the next weft's path; picking a cell's yarn;
zoom, pan and fit on the shipped 26x26 loom. A second grid in the panel, driven by the
test, checks what the bus does not produce on demand (every kind of axis name).
"""

from __future__ import annotations

import asyncio
import math
import threading
import time
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Browser

from bwsd.api.auth import TokenStore
from bwsd.config import load_config
from simulator_hw.control import request
from tests.api.conftest import BRAID, WAIT
from tests.support.fieldbus import BUS, MACHINE, Mock, start_mock, toml
from tests.test_daemon import Served
from tests.web.conftest import MS, Browsing

pytestmark = pytest.mark.slow  # every test here is in the slow tier

ROOT = Path(__file__).resolve().parents[2]
# A shed open from the start (rows 0 and 2 full, row 1 empty): the first instruction is a WEFT.
WEAVE = {"rows": 3, "cols": 10, "pitch_x": 10.0, "pitch_y": 8.0, "d_mat": 100.0, "c_mat": 0.5}
SHED = (
    "YARN diameter=1\nFILL row=0 col=0\nXXXXXXXXXX\n..........\nXXXXXXXXXX\nEND\n"
    "WEFT x=45 y=8 z=10.5 angle=0 length=60.775\nTAKEUP 4\n"
)
BIG = load_config(ROOT / "config" / "braid-24x24.toml").machine
LOOM26 = {
    "rows": BIG.rows,
    "cols": BIG.cols,
    "pitch_x": BIG.pitch_x,
    "pitch_y": BIG.pitch_y,
    "d_mat": BIG.d_mat,
    "c_mat": BIG.c_mat,
}
BRAID26 = (ROOT / "examples" / "braid-24x24.bws").read_text()
# The shipped L braid: its corner lines move on segments (row3[0..3] first).
BRAID_L = tomllib.loads((ROOT / "config" / "braid-L.toml").read_text())["machine"]
BRAID_L_TEXT = (ROOT / "examples" / "braid-L.bws").read_text()

# A second MatrixGrid in the Matrix panel, in place of the page's own, driven by the test
# from the daemon's answers and by hand.
UNDER_TEST = """async () => {
  const { MatrixGrid } = await import(new URL('static/grid.js', location.href));
  const own = document.getElementById('grid');
  const host = document.createElement('div');
  host.id = 'grid-under-test';
  host.className = 'matrix';
  own.after(host);
  own.hidden = true;
  const grid = new MatrixGrid(host, { colour: () => 0x2c5282 });
  window.underTest = { grid, picks: [] };
  grid.onPick = (yarn) => window.underTest.picks.push(yarn);
}"""
FEED = """async (geometry) => {
  const token = sessionStorage.getItem('bwsd.token') || localStorage.getItem('bwsd.token');
  const get = async (path) => (await fetch(`api/v1/${path}`,
    { headers: { Authorization: `Bearer ${token}` } })).json();
  const [machine, state] = [await get('machine'), await get('state')];
  const grid = window.underTest.grid;
  if (geometry) grid.setGeometry(geometry);
  grid.setOccupancy(machine.twin_occupancy);
  grid.setNext(state.next ? state.next.instruction : null);
  grid.setMachine(state.bus);
  await new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)));
  return machine.twin_occupancy;
}"""
# Every cell's box on screen, with the frame's: [{row, col, yarn, x, y, w, h}], frame.
CELLS = """(host) => {
  const frame = document.querySelector(`${host} .matrix-frame`).getBoundingClientRect();
  const cells = [...document.querySelectorAll(`${host} .cell`)].map((cell) => {
    const box = cell.querySelector('rect').getBoundingClientRect();
    return { row: +cell.dataset.row, col: +cell.dataset.col, yarn: cell.dataset.yarn ?? null,
      x: box.x, y: box.y, w: box.width, h: box.height };
  });
  return { frame: { x: frame.x, y: frame.y, w: frame.width, h: frame.height }, cells };
}"""


@dataclass
class Loom:
    """`bwsd serve` on a mock loom, one program loaded and reset."""

    served: Served
    mock: Mock
    token: str

    def control(self, message: dict[str, Any]) -> dict[str, Any]:
        """A request to the mock loom's control channel (off Playwright's event loop)."""
        answer: dict[str, Any] = {}

        def send() -> None:
            answer.update(asyncio.run(request("127.0.0.1", self.mock.ports["control"], message)))

        worker = threading.Thread(target=send)
        worker.start()
        worker.join(WAIT)
        assert answer.get("ok"), answer
        return answer

    def bus_until(self, test: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
        """The daemon's last reading of the machine (`/state`'s `bus`) once ``test`` holds."""
        deadline = time.monotonic() + WAIT
        while True:
            bus: dict[str, Any] = self.served.state()["bus"]
            if test(bus):
                return bus
            assert time.monotonic() < deadline, bus
            time.sleep(0.1)

    def open(self, page: Browsing) -> None:
        page.page.goto(f"{self.served.urls['api']}/#token={self.token}")
        page.ready()
        page.page.wait_for_selector("#grid .cell", timeout=MS)


def _serve(folder: Path, machine: dict[str, Any], text: str) -> Loom:
    folder.mkdir()
    mock = start_mock(folder, {}, machine=machine, program=text)
    state = folder / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    config = folder / "bwsd.toml"
    config.write_text(
        toml(
            {
                "machine": machine,
                "fieldbus": {"backend": "modbus", **BUS},
                "fieldbus.modbus": {"port": mock.ports["modbus"]},
                "api": {"port": 0},
                "plc": {"port": 0},
            }
        )
    )
    try:
        served = Served(config, state, token)
    except BaseException:
        mock.stop()
        raise
    loom = Loom(served, mock, token)
    loaded = served.http.post("/programs", json={"name": "matrix.bws", "text": text}, timeout=WAIT)
    assert loaded.status_code == 201, loaded.text
    served.command("reset")
    return loom


@pytest.fixture
def looms(tmp_path: Path) -> Iterator[Callable[[dict[str, Any], str], Loom]]:
    """Starts a loom for a machine and program; every one is stopped at the end."""
    started: list[Loom] = []

    def start(machine: dict[str, Any], text: str) -> Loom:
        started.append(_serve(tmp_path / f"loom{len(started)}", machine, text))
        return started[-1]

    yield start
    for loom in started:
        loom.served.stop()
        loom.mock.stop()


@pytest.fixture(scope="module")
def loom26(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Loom]:
    """The shipped 24x24 braid on its 26x26 loom (one for the module: it takes a while)."""
    loom = _serve(tmp_path_factory.mktemp("loom26") / "loom", LOOM26, BRAID26)
    yield loom
    loom.served.stop()
    loom.mock.stop()


def _under_test(page: Browsing) -> str:
    page.page.evaluate(UNDER_TEST)
    return "#grid-under-test"


def _centre(page: Browsing, host: str, row: int, col: int) -> tuple[float, float]:
    box = page.page.locator(f'{host} .cell[data-row="{row}"][data-col="{col}"] rect').bounding_box()
    assert box is not None
    return box["x"] + box["width"] / 2, box["y"] + box["height"] / 2


def _hover_text(page: Browsing, host: str, row: int, col: int) -> str:
    page.page.mouse.move(*_centre(page, host, row, col))
    label = page.page.locator(f"{host} .matrix-hover")
    label.wait_for(state="visible", timeout=MS)
    return label.inner_text()


def _marks(page: Browsing) -> list[list[Any]]:
    marks: list[list[Any]] = page.page.eval_on_selector_all(
        "#grid .differs", "ms => ms.map(m => [+m.dataset.row, +m.dataset.col, m.dataset.sensor])"
    )
    return sorted(marks)


def test_a_sensor_fault_marks_the_cell_with_what_the_sensor_reads(looms, page: Browsing):
    loom = looms(MACHINE, BRAID)
    loom.open(page)
    twin = loom.served.http.get("/machine").json()["twin_occupancy"]
    assert twin[1][1] == 0 and twin[0][0] == -1  # the braid's cases sit in the middle
    status = page.page.locator("#grid .matrix-machine")
    page.page.wait_for_function(
        "() => document.querySelector('#grid .matrix-machine').dataset.alarm === 'false'",
        timeout=MS,
    )
    assert status.inner_text() == "sensors agree with the twin"
    # The sensor of a full cell reads empty, the sensor of an empty one reads a case.
    loom.control({"cmd": "fault", "kind": "sensor", "cell": [1, 1]})
    loom.control({"cmd": "fault", "kind": "sensor", "cell": [0, 0]})
    page.page.wait_for_function(
        "() => document.querySelectorAll('#grid .differs').length === 2", timeout=MS
    )
    assert _marks(page) == [[0, 0, "case"], [1, 1, "empty"]]
    title = page.page.locator('#grid .cell[data-row="1"][data-col="1"] title').text_content()
    assert title == "row 1, col 1: yarn 0 — sensor: empty (differs from the twin)"
    assert "sensor: case" in _hover_text(page, "#grid", 0, 0)
    assert _hover_text(page, "#grid", 1, 1) == title  # ids hidden or not, the hover names it
    assert status.get_attribute("data-alarm") == "true"
    assert "sensors differ from the twin at (0, 0) case, (1, 1) empty" in status.inner_text()
    assert loom.served.state()["bus"]["differs"] == [[0, 0], [1, 1]]
    loom.control({"cmd": "clear"})
    page.page.wait_for_function("() => !document.querySelector('#grid .differs')", timeout=MS)
    assert loom.served.state()["bus"]["differs"] == []
    assert "sensors agree with the twin" in status.inner_text()
    assert page.errors == []


def test_the_estop_greys_the_matrix_under_a_sign_until_released(looms, page: Browsing):
    loom = looms(MACHINE, BRAID)
    loom.open(page)
    sign = page.page.locator("#grid .matrix-estop")
    filtered = "() => getComputedStyle(document.querySelector('#grid .matrix-svg')).filter"
    assert not sign.is_visible() and page.page.evaluate(filtered) == "none"
    loom.control({"cmd": "estop", "pressed": True})
    sign.wait_for(state="visible", timeout=MS)
    assert loom.served.state()["bus"]["estop"] is True
    assert sign.inner_text() == "E-STOP"
    assert "grayscale(1)" in page.page.evaluate(filtered)
    assert page.page.locator("#grid .matrix-machine").inner_text().startswith("E-STOP pressed")
    loom.control({"cmd": "estop", "pressed": False})
    sign.wait_for(state="hidden", timeout=MS)
    assert page.page.evaluate(filtered) == "none"
    assert page.errors == []


def _covered(page: Browsing, host: str, selector: str) -> list[list[int]]:
    """The cells whose centre lies inside a mark's box (all in the drawing's units)."""
    covered: list[list[int]] = page.page.evaluate(
        """([host, selector]) => {
          const marks = [...document.querySelectorAll(`${host} ${selector}`)];
          const boxes = marks.map((m) => m.getBBox());
          const inside = (x, y) => boxes.some((m) =>
            m.x <= x && x <= m.x + m.width && m.y <= y && y <= m.y + m.height);
          const cells = [];
          for (const cell of document.querySelectorAll(`${host} .cell`)) {
            const b = cell.querySelector('rect').getBBox();
            if (inside(b.x + b.width / 2, b.y + b.height / 2))
              cells.push([+cell.dataset.row, +cell.dataset.col]);
          }
          return cells;
        }""",
        [host, selector],
    )
    return sorted(covered)


@pytest.mark.parametrize(
    ("machine", "text", "axis", "cells"),
    [
        (MACHINE, BRAID, "row1", [[1, c] for c in range(4)]),
        (BRAID_L, BRAID_L_TEXT, "row3[0..3]", [[3, c] for c in range(4)]),
    ],
    ids=["line", "segment"],
)
def test_a_faulted_axis_marks_its_line(
    looms, page: Browsing, machine: dict[str, Any], text: str, axis: str, cells: list[list[int]]
):
    loom = looms(machine, text)
    loom.open(page)
    # The axis's drive faults on its next set-point: the first instruction moves it.
    loom.control({"cmd": "fault", "kind": "drive", "axis": axis})
    loom.served.command("start")
    bus = loom.bus_until(lambda bus: axis in bus["faulted"])
    page.page.wait_for_selector(f'#grid .faulted[data-axis="{axis}"]', timeout=MS)
    assert _covered(page, "#grid", f'.faulted[data-axis="{axis}"]') == cells
    label = f'#grid .rulers text[data-row="{cells[0][0]}"]'
    page.page.wait_for_selector(f"{label}.line-faulted", timeout=MS)  # the rulers: a frame on
    assert page.page.locator(label).get_attribute("class") == "axis line-faulted"
    status = page.page.locator("#grid .matrix-machine").inner_text()
    assert f"faulted: {', '.join(bus['faulted'])}" in status
    assert page.errors == []


def test_axis_names_mark_a_line_a_segment_or_nothing(looms, page: Browsing):
    loom = looms(MACHINE, BRAID)
    loom.open(page)
    host = _under_test(page)
    page.page.evaluate(FEED)
    page.page.evaluate(
        "window.underTest.grid.setMachine({differs: [], estop: false, "
        "faulted: ['col2', 'row3[1..2]', 'weft_insert', 'row9']})"
    )
    assert _covered(page, host, '.faulted[data-axis="col2"]') == [[r, 2] for r in range(4)]
    assert _covered(page, host, '.faulted[data-axis="row3[1..2]"]') == [[3, 1], [3, 2]]
    assert page.page.locator(f"{host} .faulted").count() == 2  # weft_insert and row9: no line
    status = page.page.locator(f"{host} .matrix-machine").inner_text()
    assert "faulted: col2, row3[1..2], weft_insert, row9" in status
    assert page.errors == []


def _weft_in_cells(weft: dict[str, float], machine: dict[str, float]) -> dict[str, list[float]]:
    """The weft's ends at the guides' scale, in cells: x' = O + (x - O) / fan."""
    fan = machine["c_mat"] + (1 - machine["c_mat"]) * weft["z"] / machine["d_mat"]
    ox = (machine["cols"] - 1) / 2 * machine["pitch_x"]
    oy = (machine["rows"] - 1) / 2 * machine["pitch_y"]
    dx = weft["length"] / 2 * math.cos(math.radians(weft["angle"]))
    dy = weft["length"] / 2 * math.sin(math.radians(weft["angle"]))

    def cells(x: float, y: float) -> list[float]:
        return [
            (ox + (x - ox) / fan) / machine["pitch_x"],
            (oy + (y - oy) / fan) / machine["pitch_y"],
        ]

    return {
        "from": cells(weft["x"] - dx, weft["y"] - dy),
        "to": cells(weft["x"] + dx, weft["y"] + dy),
    }


def test_the_next_wefts_path_is_drawn_at_the_guides_scale(looms, page: Browsing):
    loom = looms(WEAVE, SHED)
    loom.open(page)
    weft = loom.served.state()["next"]["instruction"]
    assert weft["kind"] == "weft"
    path = page.page.locator("#grid .weft-path")
    path.wait_for(timeout=MS)
    want = _weft_in_cells(weft, WEAVE)
    for end in ("from", "to"):
        drawn = [float(v) for v in (path.get_attribute(f"data-{end}") or "").split(",")]
        assert drawn == pytest.approx(want[end], abs=1e-3)
    assert want["from"][1] == want["to"][1] == 1  # along row 1, the shed's open middle
    # On screen the line runs through the middle of row 1's cells.
    line = path.locator(".weft-line").bounding_box()
    assert line is not None
    assert abs(line["y"] + line["height"] / 2 - _centre(page, "#grid", 1, 4)[1]) < 1
    status = page.page.locator("#grid .matrix-machine").inner_text()
    assert "next weft: 0°, 60.775 mm, 10.5 mm above the fell (drawn \u00d71.81" in status
    # Any angle: the same scaling along both axes about the matrix's centre.
    for angle in (30.0, 90.0, -45.0):
        other = {**weft, "angle": angle, "x": 20.0, "y": 4.0}
        ends = page.page.evaluate(
            """async ([w, m]) => {
            const url = new URL('static/matrix-geometry.js', location.href);
            const { weftInCells } = await import(url);
            const cells = weftInCells(w, m);
            return { from: cells.from, to: cells.to };
          }""",
            [other, WEAVE],
        )
        want = _weft_in_cells(other, WEAVE)
        assert ends == {"from": pytest.approx(want["from"]), "to": pytest.approx(want["to"])}
    # Once the weft is in, its path goes.
    loom.served.command("start")
    page.state("Complete")
    page.page.wait_for_selector("#grid .weft-path", state="detached", timeout=MS)
    assert page.errors == []


# The opacity of every cell: "r,c" -> opacity.
OPACITY = """() => Object.fromEntries([...document.querySelectorAll('#grid .cell')].map(
    (c) => [`${c.dataset.row},${c.dataset.col}`, +getComputedStyle(c).opacity]))"""


def test_clicking_a_cell_picks_its_yarn_and_highlight_outlines_it(looms, page: Browsing):
    loom = looms(MACHINE, BRAID)
    loom.open(page)
    twin = loom.served.http.get("/machine").json()["twin_occupancy"]
    yarn = twin[2][1]
    assert yarn >= 0 and twin[3][3] == -1
    page.page.mouse.click(*_centre(page, "#grid", 2, 1))
    page.until("y => window.bwsd.selected === y", yarn)  # the page took the grid's pick
    edge = page.page.locator("#grid .picked-edge")
    assert (edge.get_attribute("data-row"), edge.get_attribute("data-col")) == ("2", "1")
    seen = page.page.evaluate(OPACITY)
    assert seen.pop("2,1") == 1 and max(seen.values()) < 0.5  # the rest dimmed
    status = page.page.locator("#grid .matrix-machine").inner_text()
    assert f"yarn {yarn}: row 2, col 1" in status
    page.page.mouse.click(*_centre(page, "#grid", 3, 3))  # an empty cell: no yarn
    page.until("() => window.bwsd.selected === null")
    assert edge.count() == 0 and min(page.page.evaluate(OPACITY).values()) == 1
    assert page.errors == []


def test_on_pick_gets_the_yarn_or_null_and_highlight_follows_the_yarn(looms, page: Browsing):
    """The grid's own contract, on a grid the test drives: onPick, highlight."""
    loom = looms(MACHINE, BRAID)
    loom.open(page)
    host = _under_test(page)
    twin = page.page.evaluate(FEED)
    page.page.mouse.click(*_centre(page, host, 1, 2))
    page.page.mouse.click(*_centre(page, host, 0, 0))  # an empty cell
    page.page.locator(f"{host} .matrix-frame").press("Escape")
    assert page.page.evaluate("window.underTest.picks") == [twin[1][2], None, None]
    page.page.evaluate("y => window.underTest.grid.highlight(y)", twin[1][2])
    edge = page.page.locator(f"{host} .picked-edge")
    assert (edge.get_attribute("data-row"), edge.get_attribute("data-col")) == ("1", "2")
    # the case moves (ROW 1:+1): the outline goes with it
    moved = [row[:] for row in twin]
    moved[1] = [-1, *twin[1][:-1]]
    page.page.evaluate("o => window.underTest.grid.setOccupancy(o)", moved)
    assert (edge.get_attribute("data-row"), edge.get_attribute("data-col")) == ("1", "3")
    page.page.evaluate("window.underTest.grid.highlight(999)")  # a yarn with no case
    assert edge.count() == 0
    assert page.page.locator(f"{host} .matrix-frame.picking").count() == 0  # nothing dimmed
    assert page.errors == []


# ----- the shipped 26x26 loom -----


@pytest.mark.parametrize("size", [(1600, 1000), (1024, 768)], ids=["1600x1000", "1024x768"])
def test_a_26x26_loom_fits_the_panel_with_cells_of_14_px(
    loom26: Loom, browser: Browser, size: tuple[int, int]
):
    context = browser.new_context(viewport={"width": size[0], "height": size[1]})
    page = Browsing(context.new_page())
    try:
        loom26.open(page)
        shown = page.page.evaluate(CELLS, "#grid")
        frame, cells = shown["frame"], shown["cells"]
        assert len(cells) == 26 * 26
        smallest = min(min(c["w"], c["h"]) for c in cells)
        assert smallest >= 14, (
            f"cells of {smallest:.2f} px in a matrix frame {frame['w']:.0f} px wide: a 26x26 "
            "loom needs 26 x 14 px and 14 px of row numbers, a side column of 382 px or more"
        )
        for cell in cells:  # the whole matrix in view
            assert (
                frame["x"] <= cell["x"] and cell["x"] + cell["w"] <= frame["x"] + frame["w"] + 0.5
            )
            assert (
                frame["y"] <= cell["y"] and cell["y"] + cell["h"] <= frame["y"] + frame["h"] + 0.5
            )
        occupancy = loom26.served.http.get("/machine").json()["twin_occupancy"]
        yarns = {(c["row"], c["col"]): int(c["yarn"]) for c in cells if c["yarn"] is not None}
        assert yarns == {
            (r, c): y for r, row in enumerate(occupancy) for c, y in enumerate(row) if y >= 0
        }
        # 3-digit ids do not fit a 14 px cell: hidden, and named on hover. At 1600 px the
        # matrix has a column of its own, where they do.
        hidden = page.page.locator("#grid .matrix-frame.ids-hidden").count()
        assert hidden == (1 if size[0] < 1400 else 0)
        assert _hover_text(page, "#grid", 12, 7) == f"row 12, col 7: yarn {occupancy[12][7]}"
    finally:
        context.close()


BIGGER = "px => +document.querySelector('#grid .matrix-frame').dataset.cellPx > px"


def _cell_px(page: Browsing) -> float:
    """The size of a cell on screen, once the view has drawn its last change."""
    page.page.evaluate("() => new Promise((done) => requestAnimationFrame(() => done()))")
    return float(page.page.locator("#grid .matrix-frame").get_attribute("data-cell-px") or 0)


def test_zoom_pan_and_fit(loom26: Loom, page: Browsing):
    loom26.open(page)
    fit = _cell_px(page)
    x, y = _centre(page, "#grid", 10, 5)
    page.page.mouse.move(x, y)
    page.page.mouse.wheel(0, -400)  # zoom in about the pointer
    page.until(BIGGER, 1.5 * fit)
    after = _centre(page, "#grid", 10, 5)
    assert abs(after[0] - x) < 1 and abs(after[1] - y) < 1  # the cell under the pointer stays
    assert page.page.locator("#grid .matrix-frame.ids-hidden").count() == 0  # ids fit now
    # a drag pans by as much
    page.page.mouse.down()
    page.page.mouse.move(x - 60, y - 40, steps=5)
    page.page.mouse.up()
    panned = _centre(page, "#grid", 10, 5)
    assert abs(panned[0] - (x - 60)) < 1 and abs(panned[1] - (y - 40)) < 1
    # the buttons and the keys
    page.page.locator("#grid .matrix-fit").click()
    assert _cell_px(page) == pytest.approx(fit)
    assert _centre(page, "#grid", 10, 5) == pytest.approx((x, y), abs=0.5)
    page.page.locator("#grid button", has_text="+").click()
    assert _cell_px(page) == pytest.approx(1.5 * fit, rel=1e-3)
    page.page.locator("#grid .matrix-frame").press("0")
    assert _cell_px(page) == pytest.approx(fit)
    # a two-finger pinch, spreading to twice the span, zooms twice
    page.page.evaluate(
        """([x, y]) => {
        const frame = document.querySelector('#grid .matrix-frame');
        const send = (type, id, dx) => frame.dispatchEvent(new PointerEvent(type, {
          pointerId: id, pointerType: 'touch', isPrimary: id === 1, bubbles: true,
          clientX: x + dx, clientY: y }));
        send('pointerdown', 1, -20); send('pointerdown', 2, 20);
        send('pointermove', 1, -40); send('pointermove', 2, 40);
        send('pointerup', 1, -40); send('pointerup', 2, 40);
      }""",
        [x, y],
    )
    page.until(BIGGER, 1.9 * fit)
    assert _cell_px(page) == pytest.approx(2 * fit, rel=1e-3)
    assert page.errors == []
