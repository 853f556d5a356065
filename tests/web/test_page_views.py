"""The 3D view's textile tools in a real browser: axes, preset views, the section, colours,
contacts, picking; against `bwsd serve` on the mock loom running the shipped examples.

Each example runs once per module to Complete; the page then shows its final skeleton,
which the tests compare with what Python computes from the daemon's `/skeleton`.
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from bwsd.export.crossings import crossings
from bwsd.export.skeleton_json import skeleton_from_dict
from bwsd.program.sections import parse_section
from tests.support.fieldbus import Mock
from tests.test_daemon import Served
from tests.web.conftest import Browsing
from tests.web.serving import example, serve

pytestmark = pytest.mark.slow  # every test here is in the slow tier

SHOTS = os.environ.get("BWSD_SCREENSHOTS")  # a directory: write preview-view-*.png there


@dataclass
class Run:
    """An example run to Complete by `bwsd serve` on the mock loom."""

    stem: str
    served: Served
    mock: Mock
    token: str
    text: str
    skeleton: dict[str, Any] = field(default_factory=dict)

    @property
    def url(self) -> str:
        return f"{self.served.urls['api']}/#token={self.token}"


class Runs:
    """The examples' runs, started when first asked for, stopped with the module."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.runs: dict[str, Run] = {}

    def __call__(self, stem: str) -> Run:
        if stem not in self.runs:
            self.runs[stem] = self._start(stem)
        return self.runs[stem]

    def _start(self, stem: str) -> Run:
        tmp = self.folder / stem
        tmp.mkdir()
        text, machine = example(stem)
        served, mock, token = serve(tmp, machine, text)
        run = Run(stem, served, mock, token, text)
        loaded = served.http.post("/programs", json={"name": f"{stem}.bws", "text": text})
        assert loaded.status_code == 201, loaded.text
        served.command("reset")
        served.command("start")
        assert served.wait_for({"Complete", "Aborted", "Held"}, limit=600)["name"] == "Complete"
        run.skeleton = served.http.get("/skeleton").raise_for_status().json()
        return run

    def close(self) -> None:
        for run in self.runs.values():
            run.served.stop()
            run.mock.stop()


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Runs]:
    started = Runs(tmp_path_factory.mktemp("runs"))
    try:
        yield started
    finally:
        started.close()


def _open(page: Browsing, run: Run) -> None:
    """The page on the run's daemon, its whole skeleton shown."""
    page.page.goto(run.url)
    page.ready()
    page.until("n => window.bwsd.done === n", run.skeleton["instructions"])


def _view(page: Browsing, script: str, arg: Any = None) -> Any:
    """Evaluate ``script``, a function of the PreformView (and ``arg``), in the page."""
    return page.page.evaluate(f"([arg]) => ({script})(window.bwsd.view, arg)", [arg])


def _camera(page: Browsing) -> dict[str, Any]:
    info: dict[str, Any] = _view(page, "v => v.rig.info()")
    return info


def _project(page: Browsing, points: list[list[float]]) -> list[list[float]]:
    shown: list[list[float]] = _view(page, "(v, p) => v.project(p)", points)
    return shown


def _mm_per_px(page: Browsing, at: list[float]) -> float:
    """Millimetres per CSS pixel along x at a point, from two projected points 10 mm apart."""
    a, b = _project(page, [at, [at[0] + 10.0, at[1], at[2]]])
    return 10.0 / math.hypot(b[0] - a[0], b[1] - a[1])


def _preset(page: Browsing, name: str) -> None:
    page.page.click(f'[data-view="{name}"]')
    page.until("p => window.bwsd.view.rig.preset === p", name)
    page.until("() => !window.bwsd.view.needsRender")  # drawn so


# ----- axes and scale -----


def test_axes_and_a_millimetre_scale_with_sensible_labels(runs: Runs, page: Browsing):
    run = runs("braid-L")
    _open(page, run)
    machine = run.skeleton["machine"]
    labels = _view(page, "v => v.axes.describe()")
    titles = {e["axis"]: e for e in labels if e["title"]}
    assert {k: v["text"] for k, v in titles.items()} == {"x": "x mm", "y": "y mm", "z": "z mm"}
    assert all(t["shown"] for t in titles.values())  # the 3D view sees every axis
    for axis, extent in (
        ("x", (machine["cols"] - 1) * machine["pitch_x"]),
        ("y", (machine["rows"] - 1) * machine["pitch_y"]),
        ("z", machine["d_mat"] + run.skeleton["takeup"]),
    ):
        ticks = [float(e["text"]) for e in labels if e["axis"] == axis and not e["title"]]
        steps = {round(b - a, 9) for a, b in itertools.pairwise(ticks)}
        assert len(steps) == 1, (axis, ticks)  # evenly spaced, a round step
        step = steps.pop()
        assert step / 10 ** math.floor(math.log10(step)) in (1, 2, 5)
        assert ticks[0] <= step and ticks[-1] >= extent, (axis, ticks)  # the whole machine
        assert 3 <= len(ticks) <= 15
    shown = page.page.locator(".view-labels .axis-label:not([hidden])")
    assert shown.count() >= 10
    assert page.page.locator(".view-scale").is_hidden()  # no scale in perspective

    _preset(page, "top")
    assert page.page.locator(".view-scale").is_visible()
    text = page.page.locator(".scale-text").inner_text()
    length = float(text.removesuffix(" mm"))
    assert length / 10 ** math.floor(math.log10(length)) in (1, 2, 5)
    bar = page.page.locator(".scale-bar").bounding_box()
    assert bar is not None  # it is visible
    width = bar["width"]
    mm = _mm_per_px(page, [20.0, 20.0, 50.0])
    assert abs(width * mm - length) < 0.02 * length, (width, mm, length)
    z_ticks = [e for e in _view(page, "v => v.axes.describe()") if e["axis"] == "z"]
    assert not any(e["shown"] for e in z_ticks)  # z is seen end-on from the top
    assert page.errors == []


# ----- preset views and the projection -----

DIRECTIONS = {"top": (0, 0, 1), "front": (0, 1, 0), "side": (-1, 0, 0)}


def test_each_preset_view_sets_the_camera(runs: Runs, page: Browsing):
    run = runs("braid-L")
    _open(page, run)
    assert _camera(page)["type"] == "PerspectiveCamera"
    for name, direction in DIRECTIONS.items():
        _preset(page, name)
        info = _camera(page)
        assert info["type"] == "OrthographicCamera" and info["orthographic"], name
        assert math.dist(info["direction"], direction) < 1e-3, (name, info["direction"])
        assert page.page.locator(f'[data-view="{name}"]').get_attribute("aria-pressed") == "true"
        assert page.page.locator("#ortho").is_checked()
        # Without pixels: the frame's axes on screen (y down): x right in top and front, y
        # down in top (row 0 at the top, as the matrix) and right in side, z up in front and
        # side.
        o, x, y, z = _project(
            page, [[30.0, 30.0, 40.0], [40.0, 30.0, 40.0], [30.0, 40.0, 40.0], [30.0, 30.0, 50.0]]
        )
        right = {"top": x, "front": x, "side": y}[name]
        up = {"top": o, "front": z, "side": z}[name]  # what lies above o on screen
        below = {"top": y, "front": o, "side": o}[name]
        assert right[0] - o[0] > 5 and abs(right[1] - o[1]) < 0.5, name
        assert below[1] - up[1] > 5 and abs(up[0] - below[0]) < 0.5, name
    _preset(page, "3d")
    info = _camera(page)
    assert info["type"] == "PerspectiveCamera"
    assert info["direction"][2] < -0.2  # from above, looking down a little
    assert page.errors == []


def test_the_orthographic_toggle_keeps_the_view(runs: Runs, page: Browsing):
    run = runs("braid-L")
    _open(page, run)
    before = _camera(page)
    target = before["target"]
    scale = _mm_per_px(page, target)
    page.page.check("#ortho")
    after = _camera(page)
    assert after["type"] == "OrthographicCamera"
    assert math.dist(after["direction"], before["direction"]) < 1e-9
    assert abs(_mm_per_px(page, target) - scale) < 0.01 * scale  # the same size at the target
    page.page.uncheck("#ortho")
    assert _camera(page)["type"] == "PerspectiveCamera"
    _preset(page, "side")
    assert page.page.locator("#ortho").is_checked()
    page.page.uncheck("#ortho")
    info = _camera(page)
    assert info["type"] == "PerspectiveCamera" and info["preset"] == "side"
    assert math.dist(info["direction"], DIRECTIONS["side"]) < 1e-3
    assert page.errors == []


# ----- the section -----


def _heights(skeleton: dict[str, Any]) -> list[float]:
    """Heights to cut at: the start, a node's own height, inside the preform, the guides."""
    takeup, d_mat = skeleton["takeup"], skeleton["machine"]["d_mat"]
    contact = skeleton["contacts"][len(skeleton["contacts"]) // 2]["nodes"][1]
    nodes = {
        i: p for y in skeleton["yarns"] for i, p in zip(y["node_ids"], y["nodes"], strict=True)
    }
    node_z = nodes[contact][2]
    return [0.0, node_z, takeup / 2, takeup + 0.3 * d_mat, d_mat + takeup, d_mat + takeup + 1]


@pytest.mark.parametrize("stem", ["braid-L", "weave-U"])
def test_the_section_equals_bwsd_slice_crossings(runs: Runs, page: Browsing, stem: str):
    run = runs(stem)
    _open(page, run)
    sk = skeleton_from_dict(run.skeleton)
    for z in _heights(run.skeleton):
        want = crossings(sk, z)
        got = page.page.evaluate("z => window.bwsd.section(z)", z)
        assert len(got) == len(want), z
        for g, w in zip(got, want, strict=True):
            assert g["yarn"] == w.yarn and g["free"] == w.free, (z, g, w)
            assert abs(g["x"] - w.x) <= 1e-9 and abs(g["y"] - w.y) <= 1e-9, (z, g, w)
    assert any(len(crossings(sk, z)) > 0 for z in _heights(run.skeleton))
    # The section shown: the slider's height, the 2D view's crossings.
    page.page.check("#show-section")
    assert page.page.locator("#section-pane").is_visible()
    z = _heights(run.skeleton)[2]
    page.page.fill("#section-z-value", str(z))
    shown = page.until(
        """z => { const s = window.bwsd.view.tools.sectionView.shown;
        return s && s.z === z && s.found.length; }""",
        z,
    )
    assert shown == len(crossings(sk, z))
    assert page.errors == []


# ----- colours -----


def _per_yarn(page: Browsing, expression: str) -> dict[int, Any]:
    """``expression`` (of ``v``, the view, and ``id``) for every yarn shown."""
    script = f"v => Object.fromEntries([...v.yarns.keys()].map(id => [id, {expression}]))"
    return {int(k): value for k, value in _view(page, script).items()}


def _colours(page: Browsing) -> dict[int, int]:
    return _per_yarn(page, "v.palette.colour(id)")


def _neighbours(skeleton: dict[str, Any]) -> set[tuple[int, int]]:
    """Yarns sharing a contact; warps whose fill cells touch or face each other across
    empty cells of a row or a column."""
    pairs = {tuple(sorted(c["yarns"])) for c in skeleton["contacts"]}
    cells = {tuple(y["cell"]): y["id"] for y in skeleton["yarns"] if y["kind"] == "warp"}
    for (r, c), a in cells.items():
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                b = cells.get((r + dr, c + dc))
                if b is not None and b != a:
                    pairs.add((min(a, b), max(a, b)))
    for axis in (0, 1):
        lines: dict[int, list[tuple[int, int]]] = {}
        for cell, yarn in cells.items():
            lines.setdefault(cell[axis], []).append((cell[1 - axis], yarn))
        for line in lines.values():
            line.sort()
            pairs |= {(min(a, b), max(a, b)) for (_, a), (_, b) in itertools.pairwise(line)}
    return {p for p in pairs if p[0] != p[1]}


@pytest.mark.parametrize("stem", ["braid-2x2", "braid-L"])
def test_the_yarn_palette_has_no_repeat_among_neighbours(runs: Runs, page: Browsing, stem: str):
    run = runs(stem)
    _open(page, run)
    page.page.select_option("#colour-by", "yarn")
    page.until("() => window.bwsd.view.palette.mode === 'yarn'")
    colours = _colours(page)
    assert set(colours) == {y["id"] for y in run.skeleton["yarns"]}
    pairs = _neighbours(run.skeleton)
    assert pairs
    same = [(a, b) for a, b in pairs if colours[a] == colours[b]]
    assert same == []
    assert len(set(colours.values())) >= min(len(colours), 8)  # the hues are spread
    assert page.errors == []


def test_colouring_by_zone_uses_the_sections_zones(runs: Runs, page: Browsing):
    run = runs("braid-L")
    _open(page, run)
    page.page.select_option("#colour-by", "zone")
    # the section line is read from the program's text
    page.until("() => window.bwsd.view.palette.section?.spec === 'L:2x6:4x2'")
    section = parse_section("L:2x6:4x2")
    zones = _per_yarn(page, "v.palette.zone(id)")
    colours = _colours(page)
    by_zone: dict[str, set[int]] = {}
    for yarn in run.skeleton["yarns"]:
        want = section.zone_of(tuple(yarn["cell"])) or "edge"
        assert zones[yarn["id"]] == want, yarn["id"]
        by_zone.setdefault(want, set()).add(colours[yarn["id"]])
    assert set(by_zone) == {"flange", "junction", "web", "edge"}
    assert all(len(c) == 1 for c in by_zone.values())  # one colour per zone
    assert len({next(iter(c)) for c in by_zone.values()}) == len(by_zone)  # and each its own
    legend = [name for name, _ in _view(page, "v => v.palette.legend()")]
    assert legend == [*section.zones, "edge carrier"]
    _view(page, "v => v.setSection(null)")
    assert _view(page, "v => v.palette.legend()")[0][0] == "no section line"
    assert page.errors == []


def test_colouring_by_contact_count_is_sequential(runs: Runs, page: Browsing):
    run = runs("braid-L")
    _open(page, run)
    page.page.select_option("#colour-by", "contacts")
    page.until("() => window.bwsd.view.palette.mode === 'contacts'")
    counts = _contact_counts(run.skeleton)
    colours = _colours(page)
    fewest, most = min(counts, key=counts.__getitem__), max(counts, key=counts.__getitem__)
    assert colours[fewest] != colours[most]
    legend = _view(page, "v => v.palette.legend()")  # the fewest to the most
    assert legend[0][0] == str(counts[fewest]) and legend[-1][0] == f"{counts[most]} contacts"
    assert legend[0][1] == colours[fewest] and legend[-1][1] == colours[most]
    assert page.errors == []


def _contact_counts(skeleton: dict[str, Any]) -> dict[int, int]:
    counts = {y["id"]: 0 for y in skeleton["yarns"]}
    for contact in skeleton["contacts"]:
        for yarn in contact["yarns"]:
            counts[yarn] += 1
    return counts


# ----- contacts -----


def test_contact_points_exist_sized_by_the_diameter(runs: Runs, page: Browsing):
    run = runs("braid-L")
    _open(page, run)
    page.page.check("#show-contacts")
    page.until("n => window.bwsd.view.contactPoints?.shown === n", len(run.skeleton["contacts"]))
    nodes = {
        i: p for y in run.skeleton["yarns"] for i, p in zip(y["node_ids"], y["nodes"], strict=True)
    }
    shown = _view(page, "v => Array.from(v.contactPoints.array.subarray(0, 6))")
    for k, contact in enumerate(run.skeleton["contacts"][:2]):
        a, b = (nodes[n] for n in contact["nodes"])
        mid = [(a[i] + b[i]) / 2 for i in range(3)]
        assert math.dist(shown[3 * k : 3 * k + 3], mid) < 1e-3  # midway between X and Y
    d = run.skeleton["diameter"]
    assert _view(page, "v => v.contactMaterial.userData.diameter") == d == 1.0
    _preset(page, "front")
    # zoomed in 6x (as the wheel does), so that the points are well above their 3 px floor
    _view(page, "v => { v.camera.zoom = 6; v.rig.applySoft(); v.invalidate(true); }")
    page.until("() => !window.bwsd.view.needsRender")
    size = _view(page, "v => v.contactMaterial.size")  # CSS px in an orthographic view
    assert size > 6
    assert abs(size * _mm_per_px(page, [30.0, 30.0, 80.0]) - d) < 0.01 * d
    assert page.errors == []


# ----- picking -----


def _clear_spot(page: Browsing, skeleton: dict[str, Any]) -> tuple[int, list[float]]:
    """A point of a yarn (a segment's middle) that projects at least 9 px from every other
    yarn (a click picks within 6 px), inside the canvas."""
    yarns = skeleton["yarns"]
    screen = _project(page, [p for y in yarns for p in y["nodes"]])
    segments: list[tuple[int, list[float], list[float]]] = []
    for yarn in yarns:
        pts, screen = screen[: len(yarn["nodes"])], screen[len(yarn["nodes"]) :]
        segments += [(yarn["id"], a, b) for a, b in itertools.pairwise(pts)]
    box = page.page.locator("#view").bounding_box()
    assert box is not None
    for yarn, a, b in segments:
        p = [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2]
        if not (20 < p[0] < box["width"] - 20 and 20 < p[1] < box["height"] - 20):
            continue
        if all(_to_segment(p, c, d) >= 9 for other, c, d in segments if other != yarn):
            return yarn, p
    raise AssertionError("no yarn stands clear of the others on screen")


def _to_segment(p: list[float], a: list[float], b: list[float]) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    length2 = dx * dx + dy * dy
    along = ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2 if length2 else 0.0
    t = max(0.0, min(1.0, along))
    return math.hypot(a[0] + t * dx - p[0], a[1] + t * dy - p[1])


def test_clicking_a_yarn_picks_it_and_highlight_dims_the_others(runs: Runs, page: Browsing):
    run = runs("braid-2x2")  # few yarns: some stand clear of the others on screen
    _open(page, run)
    page.page.evaluate(
        "() => { window.picks = []; window.bwsd.view.onPick = (id) => picks.push(id); }"
    )
    yarn, (x, y) = _clear_spot(page, run.skeleton)
    box = page.page.locator("#view").bounding_box()
    assert box is not None
    page.page.mouse.click(box["x"] + x, box["y"] + y)
    page.page.mouse.click(box["x"] + 4, box["y"] + 4)  # empty space, in a corner
    page.page.mouse.move(box["x"] + 200, box["y"] + 200)
    page.page.mouse.down()
    page.page.mouse.move(box["x"] + 260, box["y"] + 230, steps=5)  # a drag orbits: no pick
    page.page.mouse.up()
    assert page.page.evaluate("window.picks") == [yarn, None]

    _view(page, "(v, id) => v.highlight(id)", yarn)
    page.until("() => !window.bwsd.view.needsRender")
    colours = _colours(page)
    shown = _per_yarn(page, "v.shownColour(id)")
    background = 0xF3F4F6
    assert shown[yarn] == colours[yarn]  # it keeps its colour
    for other, colour in colours.items():
        if other != yarn:
            assert _distance(shown[other], background) < 0.3 * _distance(colour, background)
    drawn = _view(page, "v => v.layers.highlightYarn.vertices")
    assert drawn == len(next(y for y in run.skeleton["yarns"] if y["id"] == yarn)["nodes"])
    _view(page, "v => v.highlight(null)")
    assert _view(page, "(v, id) => v.shownColour(id)", 0) == colours[0]
    assert page.errors == []


def _distance(a: int, b: int) -> float:
    return math.dist([(a >> s) & 255 for s in (16, 8, 0)], [(b >> s) & 255 for s in (16, 8, 0)])


@pytest.mark.parametrize("stem", ["braid-L", "weave-U"])
def test_yarn_info_equals_the_skeleton(runs: Runs, page: Browsing, stem: str):
    run = runs(stem)
    _open(page, run)
    counts = _contact_counts(run.skeleton)
    infos = _view(page, "v => [...v.yarns.keys()].map(id => v.yarnInfo(id))")
    assert len(infos) == len(run.skeleton["yarns"])
    for info, yarn in zip(sorted(infos, key=lambda i: i["id"]), run.skeleton["yarns"], strict=True):
        nodes = yarn["nodes"]
        length = sum(math.dist(a, b) for a, b in itertools.pairwise(nodes))
        assert info["id"] == yarn["id"] and info["kind"] == yarn["kind"]
        assert info["family"] == yarn["family"]
        assert info["contacts"] == counts[yarn["id"]]
        assert abs(info["length"] - length) <= 1e-9 * max(length, 1.0)
    assert _view(page, "v => v.yarnInfo(100000)") is None
    assert page.errors == []


# ----- pictures -----

VIEWS = ("3d", "top", "front", "side")
COLOURINGS = ("family", "zone", "contacts")


def _weft_height(skeleton: dict[str, Any]) -> float | None:
    """Just above the middle weft's plane (within half a diameter: its strip shows)."""
    wefts = [y for y in skeleton["yarns"] if y["kind"] == "weft"]
    if not wefts:
        return None
    return float(wefts[len(wefts) // 2]["nodes"][0][2]) + 0.2 * float(skeleton["diameter"])


def _pixels(png: bytes) -> Any:
    import io

    import matplotlib.image as mpimg

    return mpimg.imread(io.BytesIO(png), format="png")[..., :3]


@pytest.mark.parametrize("stem", ["braid-L", "weave-U"])
def test_pictures_of_each_view_and_colouring(runs: Runs, page: Browsing, stem: str):
    """Every view and colouring draws something of its own; with BWSD_SCREENSHOTS=DIR the
    pictures are written to DIR/preview-view-<stem>-<name>.png (docs/preview.md shows them)."""
    run = runs(stem)
    _open(page, run)
    page.page.select_option("#colour-by", "yarn")
    height = _weft_height(run.skeleton)
    if height is not None:
        _view(page, "(v, z) => v.setSectionHeight(z)", height)
    pane = page.page.locator("section.view-pane")
    shots: dict[str, bytes] = {}
    for name in VIEWS:
        _preset(page, name)
        shots[name] = pane.screenshot()
    page.page.check("#show-section")  # the top preset's section is put back when it is left
    page.until("() => window.bwsd.view.tools.sectionView.shown !== null")
    shots["section"] = page.page.locator("#section-pane").screenshot()
    page.page.uncheck("#show-section")
    _preset(page, "3d")
    for mode in COLOURINGS:
        page.page.select_option("#colour-by", mode)
        page.until("m => window.bwsd.view.palette.mode === m", mode)
        page.until("() => !window.bwsd.view.needsRender")
        shots[mode] = pane.screenshot()
    pictures = {name: _pixels(png) for name, png in shots.items()}
    for name, picture in pictures.items():
        flat = picture.reshape(-1, 3)
        assert (abs(flat - flat[0]).max(axis=1) > 0.05).sum() > 2000, f"{name} is blank"
    names = list(pictures)
    for i, a in enumerate(names):  # each its own picture
        for b in names[i + 1 :]:
            if pictures[a].shape == pictures[b].shape:
                assert abs(pictures[a] - pictures[b]).max() > 0.02, (a, b)
    if SHOTS:
        for name, png in shots.items():
            (Path(SHOTS) / f"preview-view-{stem}-{name}.png").write_bytes(png)
    assert page.errors == []
