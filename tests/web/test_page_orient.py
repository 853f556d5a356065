"""One orientation: the Matrix panel, the top view, the section and `bwsd slice` show an L
and a U the same way round, the way the program's FILL block writes them (x to the right,
y down: row 0 at the top); and views that keep their word.

Each shape is read back from what is drawn: the matrix's occupied cells on screen, the
coloured pixels of the 3D view and of the section's canvas, the circles of the slice's
figure. Runs are braid-L and weave-U to Complete through `bwsd serve` on the mock loom.
"""

from __future__ import annotations

import io
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.image import imread
from matplotlib.patches import Circle

from bwsd.export.crossings import crossings
from bwsd.export.skeleton_json import skeleton_from_dict
from bwsd.export.slice import slice_figure
from bwsd.program.sections import parse_section
from tests.web.conftest import Browsing
from tests.web.serving import example, serve
from tests.web.test_page_views import Run, Runs, _open, _preset, _view

pytestmark = pytest.mark.slow  # every test here is in the slow tier

Points = list[tuple[float, float]]
TIMES = "\u00d7"  # the multiplication sign the page writes


def glyph(points: Points) -> str:
    """The letter a set of points on screen (x right, y down) reads as: L, Γ, U, ∩...

    The points' bounding box is cut in 3 x 3 cells. An L-like shape leaves one corner
    empty (its notch): the bottom right for Γ, the top right for L, and so on; a U-like
    shape fills the four corners and leaves the middle of one side empty: the top for U,
    the bottom for ∩. Anything else reads as "?".
    """
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    x0, y0 = min(xs), min(ys)
    w, h = (max(xs) - x0) or 1.0, (max(ys) - y0) or 1.0
    counts = [[0] * 3 for _ in range(3)]
    for x, y in points:
        counts[min(int(3 * (y - y0) / h), 2)][min(int(3 * (x - x0) / w), 2)] += 1
    empty = {(r, c) for r in range(3) for c in range(3) if counts[r][c] <= 0.02 * len(points)}
    corners = {(0, 0): "⅃", (0, 2): "L", (2, 0): "ꓶ", (2, 2): "Γ"}
    notches = [letter for cell, letter in corners.items() if cell in empty]
    if len(notches) == 1:
        return notches[0]
    if not notches and ((0, 1) in empty) != ((2, 1) in empty):
        return "U" if (0, 1) in empty else "∩"
    return "?"


def _fill_cells(text: str) -> Points:
    """(col, row) of every X of the program's FILL blocks: the shape as written."""
    cells: Points = []
    lines = iter(text.splitlines())
    for line in lines:
        if not line.startswith("FILL"):
            continue
        fields = dict(f.split("=") for f in line.split()[1:])
        row, col = int(fields["row"]), int(fields["col"])
        for body in lines:
            if body.strip() == "END":
                break
            if body.lstrip().startswith("#"):
                continue
            cells += [(col + c, row) for c, ch in enumerate(body) if ch in "Xx"]
            row += 1
    return cells


def _matrix_cells(page: Browsing) -> Points:
    """The centres on screen of the Matrix panel's occupied cells."""
    centres: Points = page.page.evaluate(
        """() => [...document.querySelectorAll('#grid g.cell[data-yarn]')].map((g) => {
             const r = g.getBoundingClientRect();
             return [r.x + r.width / 2, r.y + r.height / 2];
           })"""
    )
    return [(float(x), float(y)) for x, y in centres]


def _coloured(rgb: np.ndarray[Any, Any], exclude: tuple[int, ...] = ()) -> Points:
    """The pixels of an RGB image (0..1) in a saturated colour: the yarns, not the grey
    ink, grid and shading (nor the colours ``exclude``s, 0xRRGGBB, that are no yarn's)."""
    rgb = rgb[..., :3]
    saturated = rgb.max(axis=2) - rgb.min(axis=2) > 0.25
    for colour in exclude:
        other = np.array([colour >> 16, (colour >> 8) & 0xFF, colour & 0xFF]) / 255
        saturated &= np.abs(rgb - other).max(axis=2) > 0.08
    ys, xs = np.nonzero(saturated)
    return [(float(x), float(y)) for x, y in zip(xs[::3], ys[::3], strict=True)]


def _canvas_pixels(page: Browsing, selector: str, exclude: tuple[int, ...] = ()) -> Points:
    """The coloured pixels of a canvas as the screen shows it."""
    page.page.evaluate("() => new Promise((done) => requestAnimationFrame(() => done()))")
    shot = page.page.locator(selector).screenshot()
    return _coloured(imread(io.BytesIO(shot), format="png"), exclude)


def _slice_circles(run: Run, z: float) -> Points:
    """The centres of the circles `bwsd slice` draws at z, in its image (x right, y down)."""
    fig, count = slice_figure(skeleton_from_dict(run.skeleton), z)
    fig.canvas.draw()
    ax = fig.axes[0]
    height = fig.bbox.height
    circles = [p for p in ax.patches if isinstance(p, Circle)]
    assert len(circles) == count > 0
    shown = ax.transData.transform([c.center for c in circles])
    return [(float(x), float(height - y)) for x, y in shown]


def _mid_height(run: Run) -> float:
    """Half way up the finished preform: inside it, below every free segment."""
    return round(float(run.skeleton["takeup"]) / 2, 1)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Runs]:
    started = Runs(tmp_path_factory.mktemp("runs"))
    try:
        yield started
    finally:
        started.close()


# The 3D view's colours that are no yarn's: the section plane's outline, the fell's.
MARKS = (0x3182CE, 0xB7791F)


@pytest.mark.parametrize(("stem", "letter"), [("braid-L", "Γ"), ("weave-U", "U")])
def test_matrix_top_view_section_and_slice_read_the_shape_alike(
    runs: Runs, page: Browsing, stem: str, letter: str
):
    run = runs(stem)
    written = glyph(_fill_cells(run.text))
    assert written == letter  # braid-L's flange is on rows 1-2, its web below; U's base below
    _open(page, run)
    assert glyph(_matrix_cells(page)) == written

    z = _mid_height(run)
    assert glyph(_slice_circles(run, z)) == written

    page.page.uncheck("#show-axes")
    page.page.check("#show-section")
    page.page.fill("#section-z-value", str(z))
    page.until("z => window.bwsd.view.tools.sectionView.shown?.z === z", z)
    assert glyph(_canvas_pixels(page, "#section-view")) == written

    _preset(page, "top")
    assert _view(page, "v => v.tools.cut") is True
    assert glyph(_canvas_pixels(page, "#view", exclude=MARKS)) == written
    assert page.errors == []


# ----- views that keep their word -----


def _extent(points: Points) -> tuple[float, float, float, float]:
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    return min(xs), min(ys), max(xs), max(ys)


def test_top_then_3d_shows_the_whole_preform_again(runs: Runs, page: Browsing):
    run = runs("braid-L")
    _open(page, run)
    page.page.uncheck("#show-axes")
    _preset(page, "3d")
    whole = _extent(_canvas_pixels(page, "#view", exclude=MARKS))
    _preset(page, "top")
    assert _view(page, "v => v.tools.cut") is True
    _preset(page, "3d")
    again = _extent(_canvas_pixels(page, "#view", exclude=MARKS))
    assert again == pytest.approx(whole, abs=2)  # the top of the preform is drawn again
    assert _view(page, "v => [v.tools.shown, v.tools.cut]") == [False, False]
    assert not page.page.locator("#section-cut").is_checked()
    assert page.errors == []


def test_the_top_preset_cuts_at_the_same_height_whenever_the_page_is_opened(
    tmp_path: Path, page: Browsing
):
    text, machine = example("braid-L")
    served, mock, token = serve(tmp_path, machine, text, simulator={"stroke_speed": 100.0})
    try:
        assert served.http.post("/programs", json={"name": "L.bws", "text": text}).is_success
        served.command("reset")
        served.command("start")
        url = f"{served.urls['api']}/#token={token}"

        def preset_height() -> tuple[str, str]:
            page.page.goto(url)
            page.ready()
            done = served.state()["index"]
            page.until("n => window.bwsd.done >= n", done)
            _preset(page, "top")
            page.until("() => window.bwsd.view.tools.sectionView.shown !== null")
            field = page.page.locator("#section-z-value")
            label = page.page.locator("label.section-value").inner_text()
            return field.input_value(), label

        while served.state()["index"] < 12:
            time.sleep(0.05)
        early = preset_height()
        mock.control({"cmd": "speeds", "stroke": 0, "takeup": 0})  # on to the end at once
        served.wait_for({"Complete"}, limit=600)
        late = preset_height()
        assert early == late
        assert float(early[0]) == float(machine["d_mat"]) / 2  # type: ignore[arg-type]
        assert early[1].strip().startswith("z") and early[1].strip().endswith("mm")
        assert page.errors == []
    finally:
        served.stop()
        mock.stop()


def test_the_reference_section_names_its_height_and_the_yarns_spread(runs: Runs, page: Browsing):
    run = runs("braid-L")
    _open(page, run)
    page.page.check("#show-section")
    page.until("() => window.bwsd.view.tools.sectionView.key.length === 3")
    z = float(page.page.locator("#section-z-value").input_value())
    key: list[str] = _view(page, "v => v.tools.sectionView.key")
    takeup = float(run.skeleton["takeup"])
    assert f"L:2x6:4x2's cells at the fell, z = {takeup:g} mm (c_mat 0.4 {TIMES} pitch)" in key[1]
    # The spread, from the daemon's skeleton: the crossings' extent over the cells' at the fell.
    sk = skeleton_from_dict(run.skeleton)
    found = crossings(sk, z)
    cells = parse_section("L:2x6:4x2").cells
    fell = [sk.machine.fell_xy(r, c) for r, c in cells]

    def extent(points: list[tuple[float, float]]) -> float:
        xs, ys = [p[0] for p in points], [p[1] for p in points]
        return max(xs) - min(xs) + max(ys) - min(ys)

    k = extent([(c.x, c.y) for c in found]) / extent(fell)
    assert k > 1.5  # the yarns here lie far outside the shaded cells: the key says by how much
    spread = f"the same {TIMES}{k:.2f} about the matrix centre, as the yarns spread at z = {z:g} mm"
    assert spread in key[2]
    assert f"({k * 0.4:.2f} of the guides' spread)" in key[2]
    assert page.errors == []


RELAXED = 0xD53F8C  # the relaxed preform's colour in the 3D view


def _pixels(page: Browsing) -> np.ndarray[Any, Any]:
    page.page.evaluate("() => new Promise((done) => requestAnimationFrame(() => done()))")
    return np.asarray(imread(io.BytesIO(page.page.locator("#view").screenshot()), format="png"))


def _of_colour(rgb: np.ndarray[Any, Any], colour: int) -> int:
    want = np.array([colour >> 16, (colour >> 8) & 0xFF, colour & 0xFF]) / 255
    return int((np.abs(rgb[..., :3] - want).max(axis=2) < 0.06).sum())


def test_the_relaxed_toggle_draws_the_relaxed_preform_and_turns_off_cleanly(
    runs: Runs, page: Browsing
):
    run = runs("braid-L")
    # the first relaxation takes a while; the daemon keeps it for the page
    relaxed = run.served.http.get("/skeleton", params={"relaxed": "true"}, timeout=600)
    relaxed.raise_for_status()
    nodes = {y["id"]: y["nodes"] for y in relaxed.json()["yarns"]}
    predicted = {y["id"]: y["nodes"] for y in run.skeleton["yarns"]}
    assert nodes.keys() == predicted.keys() and nodes != predicted  # another skeleton
    _open(page, run)
    page.page.uncheck("#show-axes")
    before = _pixels(page)
    assert _of_colour(before, RELAXED) == 0
    page.page.check("#show-relaxed")
    page.until("() => window.bwsd.view.tools.relaxed.nodes > 0")
    assert _view(page, "v => v.tools.relaxed.nodes") == sum(len(n) for n in nodes.values())
    drawn = _pixels(page)
    assert _of_colour(drawn, RELAXED) > 500  # drawn, in its own colour
    page.page.uncheck("#show-relaxed")
    page.until("() => window.bwsd.view.tools.relaxed.nodes === 0")
    after = _pixels(page)
    assert _of_colour(after, RELAXED) == 0
    assert np.abs(after - before).max() < 0.02  # the picture as it was
    assert page.errors == []
