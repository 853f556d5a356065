"""Interpenetration (docs/exports.md): exact on hand-built yarns, and on every example of
docs/exports.md as a brute-force computation finds it."""

from __future__ import annotations

import math
import re
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bwsd.config import load_config
from bwsd.export.arrays import Arrays
from bwsd.export.formed import Pieces, Zone, find_zone, guide_heights, pieces, takeups_of
from bwsd.export.overlap import interpenetration
from bwsd.program import load_program
from bwsd.twin import simulate
from bwsd.twin.skeleton import FloatArray, SkeletonData

from .brute import percentile, sample_depths
from .conftest import build, warp, weft

ROOT = Path(__file__).resolve().parents[2]
NONE = Pieces(np.zeros(0), np.zeros(0), np.zeros(0))


def _whole(sk: SkeletonData) -> dict[str, Any]:
    whole: dict[str, Any] = interpenetration(Arrays.of(sk), NONE)["skeleton"]
    return whole


def test_two_parallel_yarns_half_a_diameter_apart_overlap_along_their_common_length():
    sk = build(
        [warp([(0, 0, 0), (0, 0, 10), (0, 0, 99)]), warp([(0.5, 0, 4), (0.5, 0, 20), (9, 9, 99)])]
    )
    found = _whole(sk)
    # yarn 0 is within d = 1 of yarn 1 from z = 4 - sqrt(0.75) to 10, yarn 1 from 4 to 10.866
    near = 6 + math.sqrt(0.75)
    assert found["all"]["overlapping"] == pytest.approx(2 * near)
    assert found["all"]["share"] == pytest.approx(2 * near / 26)
    assert found["all"]["worst"] == pytest.approx(0.5)
    assert found["all"]["p95"] == pytest.approx(0.5, abs=0.01)


def test_two_yarns_crossing_at_right_angles_overlap_by_a_full_diameter():
    sk = build([warp([(-5, 0, 0), (5, 0, 0), (0, 0, 99)]), weft([(0, -5, 0), (0, 5, 0)], angle=90)])
    found = _whole(sk)
    assert found["all"]["overlapping"] == pytest.approx(4.0)  # 2 d on each
    assert found["all"]["worst"] == pytest.approx(1.0)
    assert found["warp"]["overlapping"] == found["weft-90"]["overlapping"] == pytest.approx(2.0)
    # depth d - |s| over s in (-1, 1): 95 % of the length is no deeper than 0.95; sampled
    # 16 times a diameter, the percentile is good to d / 40
    assert found["all"]["p95"] == pytest.approx(0.95, abs=1 / 40)


def test_a_yarn_never_overlaps_itself_and_centrelines_overlap_nothing():
    sk = build([warp([(0, 0, 0), (0, 0, 10), (0.2, 0, 0), (0, 0, 99)])])
    assert _whole(sk)["all"]["overlapping"] == 0.0
    crossing = build(
        [warp([(-5, 0, 0), (5, 0, 0), (0, 0, 99)]), weft([(0, -5, 0), (0, 5, 0)], angle=90)],
        diameter=0.0,
    )
    assert _whole(crossing)["all"] == {
        "length": 20.0,
        "overlapping": 0.0,
        "share": 0.0,
        "worst": 0.0,
        "p95": 0.0,
    }


def _table() -> dict[str, dict[str, str]]:
    """The interpenetration table of docs/exports.md, by example."""
    text = (ROOT / "docs" / "exports.md").read_text()
    head = re.search(r"^\| example \| d mm \| yarn mm \|.*$", text, re.MULTILINE)
    assert head is not None
    names = [c.strip() for c in head[0].strip("|").split("|")]
    rows = {}
    for line in text[head.end() :].splitlines()[2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows[cells[0]] = dict(zip(names, cells, strict=True))
    return rows


@cache
def _example(stem: str) -> tuple[SkeletonData, Zone, dict[str, Any]]:
    machine = load_config(ROOT / "config" / f"{stem}.toml").machine
    program = load_program(ROOT / "examples" / f"{stem}.bws", machine)
    assert program.cycle_length is not None  # every example declares its cycle
    sk = simulate(machine, program).skeleton()
    arrays = Arrays.of(sk)
    zone = find_zone(
        arrays, program.cycle_length, guide_heights(machine.d_mat, takeups_of(program))
    )
    return sk, zone, interpenetration(arrays, pieces(arrays, zone))


def test_the_docs_list_every_example_but_the_largest():
    stems = sorted(p.stem for p in (ROOT / "examples").glob("*.bws"))
    assert sorted(_table()) == [s for s in stems if s != "braid-24x24"]


@pytest.mark.slow
@pytest.mark.parametrize("stem", sorted(_table()))
def test_each_example_overlaps_as_the_docs_say_and_brute_force_finds(stem):
    """The figures of docs/exports.md are what the metric gives; a brute-force computation
    (the distance of points every d/32 along the yarn to every segment of every other yarn)
    agrees on the share to 0.2 %, on the worst overlap to d/32, on p95 to d/40; the formed
    zone likewise, sampled on its slab."""
    sk, zone, found = _example(stem)
    d, row = sk.diameter, _table()[stem]
    whole, formed = found["skeleton"]["all"], found["formed"]["all"]
    assert row["within d of another yarn"] == f"{100 * whole['share']:.1f} %"
    assert (row["worst mm"], row["p95 mm"]) == (f"{whole['worst']:.3f}", f"{whole['p95']:.3f}")
    weight, depth, _ = sample_depths(sk, d / 32)
    _agree(whole, weight, depth, d)
    if zone.z is None:
        assert row["formed: within d"] == "" and formed["length"] == 0
        return
    assert row["formed: within d"] == f"{100 * formed['share']:.1f} %"
    weight, depth, _ = sample_depths(sk, d / 32, *zone.z, between=True)
    assert weight.sum() == pytest.approx(formed["length"], rel=1e-3)
    _agree(formed, weight, depth, d)


def _agree(found: dict[str, Any], weight: FloatArray, depth: FloatArray, d: float) -> None:
    over = depth > 0
    assert found["share"] == pytest.approx(weight[over].sum() / weight.sum(), abs=0.002)
    assert depth.max() - 1e-9 <= found["worst"] <= depth.max() + d / 32
    assert found["p95"] == pytest.approx(percentile(depth[over], weight[over], 0.95), abs=d / 40)
