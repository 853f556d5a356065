"""The page at 420, 1024 and 1600 px while a large braid runs, against `bwsd serve` on the
mock loom: the run's progress and time left in view without scrolling, the matrix growing
with the window (26x26 and 32x32 looms), the ids shown on zoom, the running matrix marking
the lines of the instruction under way and nothing else, and the default colouring telling
neighbouring yarns apart in the 3D view and the matrix.

With ``BWSD_SCREENSHOTS=DIR`` the run is saved at each size as
``DIR/preview-braid<n>-<width>.png`` (docs/preview.md shows them; ``BWSD_SCREENSHOTS=docs``).
"""

from __future__ import annotations

import io
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib.image as mpimg
import numpy as np
import pytest
from playwright.sync_api import Browser, Page

from bwsd.program.braid import braid4
from tests.api.conftest import WAIT
from tests.support.fieldbus import Mock
from tests.test_daemon import Served
from tests.web.conftest import MS, Browsing, watched
from tests.web.serving import example, serve
from tests.web.test_page_views import _neighbours

pytestmark = pytest.mark.slow  # every test here is in the slow tier

ROOT = Path(__file__).resolve().parents[2]
SIZES = {"420x800": (420, 800), "1024x768": (1024, 768), "1600x1000": (1600, 1000)}
# Strokes of 10 mm at 8 mm/s: an instruction lasts over a second, long enough to compare
# what the page marks with what the daemon runs.
SLOW = {"stroke_speed": 8.0, "takeup_speed": 40.0}


@dataclass
class Running:
    """`bwsd serve` on a mock loom of n x n cells, running a braid of (n - 2) x (n - 2)."""

    served: Served
    mock: Mock
    token: str

    def open(self, browser: Browser, width: int, height: int) -> Browsing:
        context = browser.new_context(viewport={"width": width, "height": height})
        page = watched(context.new_page())
        page.page.goto(f"{self.served.urls['api']}/#token={self.token}")
        page.ready()
        page.state("Execute")
        page.page.wait_for_selector("#grid .cell[data-yarn]", timeout=MS)
        return page


def _braid(n: int, cycles: int) -> tuple[dict[str, Any], str]:
    """The machine table and the program of a 4-step braid on an n x n loom."""
    made = braid4(n - 2, n - 2, cycles=cycles, takeup=8, d_mat=300, c_mat=0.3, diameter=0.5)
    m = made.machine
    machine = {"rows": m.rows, "cols": m.cols, "pitch_x": m.pitch_x, "pitch_y": m.pitch_y}
    return {**machine, "d_mat": m.d_mat, "c_mat": m.c_mat}, made.program


@pytest.fixture(scope="module")
def running(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Callable[[int], Running]]:
    """A braid running on an n x n loom, started at the first ask (one per size)."""
    started: dict[int, Running] = {}

    def start(n: int) -> Running:
        if n not in started:
            machine, text = _braid(n, cycles=100)
            folder = tmp_path_factory.mktemp(f"loom{n}")
            served, mock, token = serve(folder, machine, text, simulator=SLOW)
            started[n] = Running(served, mock, token)
            loaded = served.http.post("/programs", json={"name": f"braid-{n}.bws", "text": text})
            assert loaded.status_code == 201, loaded.text
            served.command("reset")
            served.command("start")
        return started[n]

    yield start
    for loom in started.values():
        loom.served.stop()
        loom.mock.stop()


# An element is seen when its box is inside the window and it is what the browser shows at
# its centre (not clipped by a scrolled panel, not under another element).
SEEN = """(e) => {
  const box = e.getBoundingClientRect();
  if (!box.width || !box.height) return false;
  const inside = box.left >= 0 && box.top >= 0 && box.right <= innerWidth
    && box.bottom <= innerHeight;
  if (!inside) return false;
  const top = document.elementFromPoint(box.left + box.width / 2, box.top + box.height / 2);
  return top !== null && (top === e || e.contains(top));
}"""
RUN_SEEN = f"""() => {{
  const seen = {SEEN};
  const bars = [...document.querySelectorAll('progress')].filter(seen)
    .map((e) => [e.value, e.max]);
  const left = [...document.querySelectorAll('body *')]
    .filter((e) => e.children.length === 0 && /^time left: about \\d/.test(e.textContent))
    .filter(seen)
    .map((e) => e.textContent);
  return {{ scrolled: [scrollX, scrollY], bars, left }};
}}"""


@pytest.mark.parametrize("size", SIZES.values(), ids=SIZES.keys())
def test_the_progress_and_time_left_are_in_view_without_scrolling(
    running: Callable[[int], Running], browser: Browser, size: tuple[int, int]
):
    loom = running(26)
    page = loom.open(browser, *size)
    try:
        page.until(
            "() => document.querySelector('#eta').textContent.startsWith('time left: about')"
        )
        shown = page.page.evaluate(RUN_SEEN)
        count = loom.served.state()["count"]
        assert shown["scrolled"] == [0, 0]
        assert [bar for bar in shown["bars"] if bar[1] == count and 0 < bar[0] <= count], shown
        assert shown["left"], shown
        _screenshot(page.page, f"braid26-{size[0]}")
        assert page.errors == []
    finally:
        page.page.context.close()


# Every cell of the page's matrix on screen, and whether its id is drawn (displayed, and
# inside its cell): [{row, col, yarn, w, h, id, fits}].
CELLS = """() => [...document.querySelectorAll('#grid .cell')].map((cell) => {
  const box = cell.querySelector('rect').getBoundingClientRect();
  const text = cell.querySelector('text');
  const ink = text.getBoundingClientRect();
  const drawn = getComputedStyle(text).display !== 'none' && ink.width > 0;
  return { row: +cell.dataset.row, col: +cell.dataset.col, yarn: cell.dataset.yarn ?? null,
    w: box.width, h: box.height, id: drawn ? text.textContent : null,
    fits: drawn && ink.left >= box.left && ink.right <= box.right,
    font: parseFloat(getComputedStyle(text).fontSize) * (box.width / 24) };
})"""


@pytest.mark.parametrize("n", [26, 32])
def test_at_1600_px_the_matrix_grows_until_its_ids_are_drawn(
    running: Callable[[int], Running], browser: Browser, n: int
):
    loom = running(n)
    page = loom.open(browser, 1600, 1000)
    try:
        cells = page.page.evaluate(CELLS)
        assert len(cells) == n * n
        smallest = min(min(c["w"], c["h"]) for c in cells)
        assert smallest >= 20, f"{n}x{n}: cells of {smallest:.1f} px at 1600 px"
        occupied = [c for c in cells if c["yarn"] is not None]
        assert occupied and all(c["id"] == c["yarn"] and c["fits"] for c in occupied)
        assert min(c["font"] for c in occupied) >= 8.5  # ids worth printing
        frame = page.page.locator("#grid .matrix-frame")
        assert page.page.evaluate(SEEN, frame.element_handle())  # the whole matrix in view
        _screenshot(page.page, f"braid{n}-1600")
        assert page.errors == []
    finally:
        page.page.context.close()


@pytest.mark.parametrize("size", [(420, 800), (1024, 768)], ids=["420x800", "1024x768"])
def test_ids_too_small_at_fit_show_when_zoomed_in(
    running: Callable[[int], Running], browser: Browser, size: tuple[int, int]
):
    loom = running(32)
    page = loom.open(browser, *size)
    try:
        assert all(c["id"] is None for c in page.page.evaluate(CELLS))  # 12 px cells: hidden
        hidden = page.page.locator("#grid .matrix-frame.ids-hidden")
        for _ in range(3):  # + zooms 1.5 times: 12 px cells, then 18, then 27
            page.page.locator("#grid button", has_text="+").click()
            page.page.evaluate("() => new Promise((done) => requestAnimationFrame(() => done()))")
            if hidden.count() == 0:
                break
        cells = page.page.evaluate(CELLS)
        assert min(c["w"] for c in cells) >= 17
        frame = page.page.locator("#grid .matrix-frame").bounding_box()
        assert frame is not None
        shown = [c for c in cells if c["yarn"] is not None and c["id"] is not None]
        assert shown and all(c["id"] == c["yarn"] and c["fits"] for c in shown)
        _screenshot(page.page, f"braid32-zoomed-{size[0]}")
        assert page.errors == []
    finally:
        page.page.context.close()


# The lines the page marks as moving: [axis, line, first, last] of each outline, the cells
# it draws calm or not, and every cell's fill.
MARKED = """() => {
  const frame = document.querySelector('#grid .matrix-frame');
  const bands = [...document.querySelectorAll('#grid .layer-highlights .moving')]
    .map((b) => [+b.dataset.line, +b.dataset.first, +b.dataset.last, b.dataset.axis
      ?? (+b.getAttribute('width') > +b.getAttribute('height') ? 'row' : 'col')]);
  const cells = [...document.querySelectorAll('#grid .cell[data-yarn]')].map((cell) => {
    const box = cell.querySelector('rect').getBoundingClientRect();
    return { row: +cell.dataset.row, col: +cell.dataset.col,
      fill: getComputedStyle(cell.querySelector('rect')).fill,
      x: box.x + box.width / 2, y: box.y + box.height / 2 };
  });
  const box = frame.getBoundingClientRect();
  return { bands, cells, frame: [box.x, box.y], scale: devicePixelRatio };
}"""


IDS_SHOWN = """(visibility) => document.querySelectorAll('#grid .cell text')
    .forEach((text) => { text.style.visibility = visibility; })"""


def _lines(instruction: dict[str, Any], n: int) -> set[tuple[str, int, int, int]]:
    """The lines a shift moves: (axis, line, first, last)."""
    moves = instruction["moves"]
    return {
        (instruction["axis"], m[0], m[2] if len(m) > 2 else 0, m[3] if len(m) > 2 else n - 1)
        for m in moves
    }


def _rgb(css: str) -> tuple[int, int, int]:
    parts = css[css.index("(") + 1 : css.index(")")].split(",")
    r, g, b = (int(float(p)) for p in parts[:3])
    return r, g, b


def test_a_running_matrix_marks_the_lines_of_the_instruction_under_way(
    running: Callable[[int], Running], browser: Browser
):
    """During Execute the outlined lines are exactly those of the instruction the daemon
    runs; every cell shows its own calm colour at its centre, nothing washed over it."""
    loom = running(26)
    page = loom.open(browser, 1600, 1000)
    try:
        checked = 0
        deadline = time.monotonic() + WAIT
        while checked < 2:
            assert time.monotonic() < deadline, "the matrix changed under every look"
            before = loom.served.state()
            page.page.wait_for_timeout(400)  # the page draws its panels at most 5 times a second
            marked = page.page.evaluate(MARKED)
            page.page.evaluate(IDS_SHOWN, "hidden")  # the pixels of the cells, not of their ids
            png = page.page.locator("#grid .matrix-frame").screenshot()
            page.page.evaluate(IDS_SHOWN, "")
            # unchanged meanwhile (a pause between two instructions may recolour a yarn)
            same = page.page.evaluate(MARKED) == marked
            after = loom.served.state()
            nxt = before["next"]
            if (
                not same
                or before["name"] != "Execute"
                or after["next"] != nxt
                or nxt["instruction"]["kind"] != "shift"
            ):
                continue
            want = _lines(nxt["instruction"], 26)
            got = {(axis, line, first, last) for line, first, last, axis in marked["bands"]}
            assert got == want, (nxt, got ^ want)
            pixels = (mpimg.imread(io.BytesIO(png), format="png")[..., :3] * 255).round()
            x0, y0 = marked["frame"]
            for cell in marked["cells"]:
                fill = np.array(_rgb(cell["fill"]))
                assert fill.min() >= 100, f"not calm: {cell}"  # light tints while running
                at = pixels[int(cell["y"] - y0), int(cell["x"] - x0)]
                assert np.abs(at - fill).max() <= 3, f"washed over: {cell} shows {at}"
            checked += 1
        assert page.errors == []
    finally:
        page.page.context.close()


def test_yarn_colouring_by_default_neighbours_apart_a_stored_choice_wins(
    tmp_path: Path, page: Browsing
):
    text, machine = example("braid-L")
    served, mock, token = serve(tmp_path, machine, text)
    try:
        assert (
            served.http.post("/programs", json={"name": "L.bws", "text": text}).status_code == 201
        )
        served.command("reset")
        page.page.goto(f"{served.urls['api']}/#token={token}")
        page.ready()
        page.page.wait_for_selector("#grid .cell[data-yarn]", timeout=MS)
        assert page.page.input_value("#colour-by") == "yarn"
        # the matrix before the first move: each case in its fill cell, touching ones apart
        fills = _fills(page.page)
        cells = {
            (c["row"], c["col"]): int(c["yarn"]) for c in page.page.evaluate(CELLS) if c["yarn"]
        }
        touching = [
            (a, b)
            for (r, c), a in cells.items()
            for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1))
            if (b := cells.get((r + dr, c + dc))) is not None
        ]
        assert touching and [(a, b) for a, b in touching if fills[a] == fills[b]] == []
        # the 3D view after the run (a page opened then colours the whole graph), contacts in
        served.command("start")
        served.wait_for({"Complete"})
        skeleton = served.http.get("/skeleton").json()
        page.page.reload()
        page.ready()
        page.until("n => window.bwsd.done === n", skeleton["instructions"])
        ids = [y["id"] for y in skeleton["yarns"]]
        shown = page.page.evaluate(
            "ids => ids.map((id) => window.bwsd.view.palette.colour(id))", ids
        )
        colours = dict(zip(ids, shown, strict=True))
        pairs = _neighbours(skeleton)
        assert any(tuple(sorted(c["yarns"])) in pairs for c in skeleton["contacts"])
        assert [(a, b) for a, b in pairs if colours[a] == colours[b]] == []
        page.page.wait_for_selector("#grid .cell[data-yarn]", timeout=MS)
        fills = _fills(page.page)
        assert fills == {y: f"#{colours[y]:06x}" for y in fills}  # the matrix's are the same
        # a choice kept in the browser wins
        page.page.evaluate("() => localStorage.setItem('bwsd.colourBy', 'family')")
        page.page.reload()
        page.ready()
        page.page.wait_for_selector("#grid .cell[data-yarn]", timeout=MS)
        assert page.page.input_value("#colour-by") == "family"
        assert page.page.evaluate("() => window.bwsd.view.palette.mode") == "family"
        assert len(set(_fills(page.page).values())) == 1  # every warp one colour
        assert page.errors == []
    finally:
        served.stop()
        mock.stop()


def test_while_it_runs_the_yarn_colours_wait_and_the_image_is_not_drawn_whole_again(
    running: Callable[[int], Running], browser: Browser
):
    """Between two instructions on a slow loom the updates pause; recolouring the yarns
    there would draw the whole preform's image again each time (the incremental drawing of
    a large preform undone). The colours catch up once the machine stands."""
    loom = running(26)
    deadline = time.monotonic() + 6 * WAIT
    loom.mock.control({"cmd": "speeds", "stroke": 0, "takeup": 0})  # instant, until then
    try:
        while loom.served.state()["index"] < 60:  # over 10,000 nodes: the settled image in use
            assert time.monotonic() < deadline
            time.sleep(0.2)
    finally:
        speeds = {"stroke": SLOW["stroke_speed"], "takeup": SLOW["takeup_speed"]}
        loom.mock.control({"cmd": "speeds", **speeds})
    page = loom.open(browser, 1024, 768)
    try:
        assert page.page.input_value("#colour-by") == "yarn"
        page.until("() => window.bwsd.view.layers.layered")
        done, drawn = page.page.evaluate(WHOLE)
        page.until("n => window.bwsd.done >= n", done + 8)  # eight pauses at least
        assert loom.served.state()["name"] == "Execute"
        assert page.page.evaluate(WHOLE)[1] - drawn <= 2
        assert page.errors == []
    finally:
        page.page.context.close()


WHOLE = "() => [window.bwsd.done, window.bwsd.view.layers.stats.images.length]"


def _fills(page: Page) -> dict[int, str]:
    """The matrix's yarns and the colours their cells are filled with ("#rrggbb")."""
    fills: list[list[Any]] = (
        page.evaluate("""() => [...document.querySelectorAll('#grid .cell[data-yarn]')]
        .map((c) => [+c.dataset.yarn, c.querySelector('rect').style.fill])""")
    )
    return {yarn: "#{:02x}{:02x}{:02x}".format(*_rgb(fill)) for yarn, fill in fills}


def _screenshot(page: Page, name: str) -> None:
    shots = os.environ.get("BWSD_SCREENSHOTS")
    if shots:
        folder = (ROOT / shots) if not Path(shots).is_absolute() else Path(shots)
        page.screenshot(path=folder / f"preview-{name}.png")
