"""Cross-section: exact crossings, the image file."""

from __future__ import annotations

import struct
from collections.abc import Iterable

import pytest
from matplotlib.patches import Circle

from bwsd.export.crossings import Crossing, crossings
from bwsd.export.errors import ExportError
from bwsd.export.slice import bands, draw_slice, slice_figure
from bwsd.twin.skeleton import SkeletonData

from .conftest import build, warp


def xy(found: Iterable[Crossing]) -> list[tuple[int, float, float]]:
    return sorted((c.yarn, round(c.x, 12), round(c.y, 12)) for c in found)


def test_crossings_of_vertical_yarns(small):
    assert xy(crossings(small, 5.0)) == [(0, 2.5, 2.5), (1, 7.5, 2.5), (2, 7.5, 7.5)]
    assert not any(c.free for c in crossings(small, 5.0))


def test_crossing_exactly_at_a_node_counts_once(small):
    found = crossings(small, 10.0)
    assert xy(found) == [(0, 2.5, 2.5), (1, 7.5, 2.5), (2, 7.5, 7.5)]
    assert [c.segment for c in found] == [0, 0, 0]


def test_free_segments_above_the_fell(small):
    found = crossings(small, 50.0)
    assert xy(found) == [(0, 1.75, 1.75), (1, 8.25, 1.75), (2, 8.25, 8.25)]
    assert all(c.free for c in found)


@pytest.mark.parametrize(("z", "count"), [(-1.0, 0), (0.0, 3), (120.0, 3), (120.5, 0)])
def test_ends(small, z, count):
    assert len(crossings(small, z)) == count


def test_inclined_yarn():
    sk = build([warp([(0, 0, 0), (4, 2, 8), (0, 0, 16), (1, 1, 100)])])
    assert xy(crossings(sk, 4.0)) == [(0, 2.0, 1.0)]
    assert xy(crossings(sk, 12.0)) == [(0, 2.0, 1.0)]
    assert [c.segment for c in crossings(sk, 12.0)] == [1]


def test_touching_yarn_meets_the_plane_once_at_the_node():
    sk = build([warp([(0, 0, 0), (4, 2, 8), (0, 0, 0.5), (1, 1, 100)])])
    found = crossings(sk, 8.0)
    assert [(c.segment, c.free) for c in found] == [(0, False), (2, True)]
    assert (found[0].x, found[0].y) == (4.0, 2.0)
    assert found[1].x == pytest.approx(7.5 / 99.5)
    assert len(crossings(sk, 4.0)) == 3


def test_yarn_lying_in_the_plane_is_not_a_crossing(small):
    assert [c.yarn for c in crossings(small, 15.0)] == [0, 1, 2]
    sk = build([warp([(0, 0, 0), (0, 0, 5), (3, 0, 5), (3, 0, 9), (1, 1, 100)])])
    assert [(c.x, c.segment) for c in crossings(sk, 5.0)] == [(0.0, 0), (3.0, 1)]


def test_weft_band(small):
    (band,) = bands(small, 15.3)
    assert band.yarn == 3
    assert (band.start, band.end) == ((-5.0, 5.0), (15.0, 5.0))
    assert band.half_width == pytest.approx(0.4)
    assert bands(small, 15.6) == []
    assert bands(small.__class__(**{**small.__dict__, "diameter": 0.0}), 15.0) == []


def png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def test_png(small, tmp_path):
    path = tmp_path / "slice.png"
    assert draw_slice(small, 15.0, path) == 3
    data = path.read_bytes()
    assert png_size(data) == (960, 960)
    assert len(data) > 5_000


@pytest.mark.slow
def test_centreline_and_empty_slices(centreline, tmp_path):
    assert draw_slice(centreline, 50.0, tmp_path / "free.png") == 3
    assert draw_slice(centreline, -5.0, tmp_path / "empty.png") == 0
    assert png_size((tmp_path / "empty.png").read_bytes()) == (960, 960)


def test_svg_by_suffix(small, tmp_path):
    draw_slice(small, 5.0, tmp_path / "slice.svg")
    text = (tmp_path / "slice.svg").read_text(encoding="utf-8")
    assert "<svg" in text
    assert "z = 5 mm" in text or "z = 5" in text


def test_bad_target(small, tmp_path):
    with pytest.raises(ExportError, match="cannot write the image"):
        draw_slice(small, 5.0, tmp_path / "slice.nope")
    with pytest.raises(ExportError, match="cannot write the image"):
        draw_slice(small, 5.0, tmp_path / "missing" / "slice.png")


def test_the_slice_shows_row_0_at_the_top(small: SkeletonData) -> None:
    """x runs to the right and y down the image, as the FILL block writes the matrix: of
    the crossings (2.5, 2.5), (7.5, 2.5) and (7.5, 7.5), the last is drawn lowest."""
    fig, count = slice_figure(small, 5.0)
    fig.canvas.draw()
    ax = fig.axes[0]
    circles = sorted(p.center for p in ax.patches if isinstance(p, Circle))
    assert count == len(circles) == 3
    (ax0, ay0), (bx, by), (cx, cy) = ax.transData.transform(circles)  # display: y up
    assert bx > ax0 + 10 and abs(by - ay0) < 1e-6  # (7.5, 2.5) right of (2.5, 2.5)
    assert cy < by - 10 and abs(cx - bx) < 1e-6  # (7.5, 7.5) below (7.5, 2.5)
