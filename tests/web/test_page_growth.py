"""A large preform growing on the page: the settled image takes only what newly settled.

The 24x24 braid (624 carriers) runs for 30 cycles through `bwsd serve` on the mock loom
with the page open from the start: past 10,000 nodes and contacts the page draws the
settled part of the yarns into an off-screen image and adds to it as the run goes
(docs/preview.md, "How it stays in step").
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import matplotlib.image as mpimg
import numpy as np
import pytest

from tests.api.skeletons import yarns_of
from tests.support.fieldbus import Mock
from tests.test_daemon import Served
from tests.web.conftest import Browsing
from tests.web.serving import example, serve

pytestmark = pytest.mark.slow  # every test here is in the slow tier

CYCLES = 30

DUMP = """() => Object.fromEntries(window.bwsd.dump().map(
    y => [y.id, {node_ids: y.node_ids, nodes: y.nodes}]))"""


@pytest.fixture
def braid(tmp_path: Path) -> Iterator[tuple[Served, Mock, str, str]]:
    """`bwsd serve` on the mock 26x26 loom with the 24x24 braid loaded for CYCLES cycles."""
    text, machine = example("braid-24x24")
    assert "REPEAT 10 " in text
    text = text.replace("REPEAT 10 ", f"REPEAT {CYCLES} ", 1)
    served, mock, token = serve(tmp_path, machine, text)
    try:
        loaded = served.http.post(
            "/programs", json={"name": "braid.bws", "text": text}, timeout=300
        )
        assert loaded.status_code == 201, loaded.text
        yield served, mock, token, text
    finally:
        served.stop()
        mock.stop()


def _canvas(page: Browsing) -> np.ndarray[Any, Any]:
    png = page.page.locator("#view").screenshot()
    pixels: np.ndarray[Any, Any] = mpimg.imread(io.BytesIO(png), format="png")[..., :3]
    return pixels


def test_a_growing_preform_adds_only_the_newly_settled_segments_to_its_image(
    braid: tuple[Served, Mock, str, str], page: Browsing
):
    served, _mock, token, _text = braid
    page.page.goto(f"{served.urls['api']}/#token={token}")
    page.ready()
    served.command("reset")
    page.state("Idle")
    # One colouring throughout: yarn colours catching up with the contacts at the end of the
    # run would draw the image whole once more, by design.
    page.page.select_option("#colour-by", "family")
    box = page.page.locator("#view").bounding_box()
    assert box is not None
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.page.mouse.move(x, y)  # the operator turns the view a little: the camera stays put
    page.page.mouse.down()
    page.page.mouse.move(x + 30, y + 10, steps=5)
    page.page.mouse.up()
    page.until("() => window.bwsd.view.following === false")
    served.command("start")
    assert served.wait_for({"Complete", "Aborted", "Held"}, limit=600)["name"] == "Complete"
    skeleton = served.http.get("/skeleton").raise_for_status().json()
    page.until("n => window.bwsd.done === n", skeleton["instructions"])
    shown = {int(k): v for k, v in page.page.evaluate(DUMP).items()}
    assert shown == yarns_of(skeleton)
    assert len(skeleton["yarns"]) == 624
    # The updates paused: the tails were settled into the image, and it was all drawn.
    page.until("() => !window.bwsd.view.needsRender && !window.bwsd.view.layers.tailsLong")
    stats = page.page.evaluate("window.bwsd.view.layers.stats")
    assert page.page.evaluate("window.bwsd.view.layers.layered") is True
    # The split was made once, when the preform passed 10,000 nodes and contacts, and the
    # image drawn whole then; what settled after was added to it, never drawn whole again.
    assert stats["splits"] == 1, stats
    assert len(stats["images"]) == 1, stats
    assert stats["increments"] >= 2, stats
    added = _canvas(page)
    # The same picture drawn whole, from scratch, is the one built by additions.
    page.page.evaluate("""() => {
        const v = window.bwsd.view;
        v.invalidate(true);
    }""")
    page.until("() => !window.bwsd.view.needsRender")
    assert len(page.page.evaluate("window.bwsd.view.layers.stats.images")) == 2
    whole = _canvas(page)
    background = whole.reshape(-1, 3)[0]
    drawn = np.any(np.abs(whole - background) > 0.05, axis=2)
    assert drawn.sum() > 20_000, "the preform is drawn"
    differ = np.any(np.abs(added - whole) > 1 / 255 + 1e-6, axis=2)
    assert differ.sum() == 0, f"{differ.sum()} pixels differ of {drawn.sum()} drawn"
    assert page.errors == []
