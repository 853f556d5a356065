"""Metrics on constructed skeletons with known section, angles and contacts."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest

from bwsd.export.angles import skeleton_angles
from bwsd.export.arrays import Arrays
from bwsd.export.errors import ExportError
from bwsd.export.metrics import contact_zone, contacts_per_cycle, metrics, section, weft_contacts
from bwsd.twin.skeleton import SkeletonData

from .conftest import Point, build, warp, weft


def inclined(
    start: Point, degrees: float, lengths: Sequence[float], azimuth: float = 0.0
) -> list[Point]:
    """Nodes of a polyline leaving ``start`` at ``degrees`` to +z, one segment per length."""
    a, b = math.radians(degrees), math.radians(azimuth)
    step = np.array([math.sin(a) * math.cos(b), math.sin(a) * math.sin(b), math.cos(a)])
    points = [np.array(start, float)]
    for length in lengths:
        points.append(points[-1] + length * step)
    return [(float(p[0]), float(p[1]), float(p[2])) for p in points]


def angles(sk: SkeletonData) -> dict[str, dict[str, Any]]:
    """The whole skeleton's angles per family."""
    return skeleton_angles(Arrays.of(sk))


def test_angles_of_thirty_degree_yarns():
    free = (100.0, -50.0, 500.0)  # far off: the free segment must not count
    sk = build(
        [
            warp([*inclined((0, 0, 0), 30, [2, 3]), free]),
            warp([*inclined((5, 0, 0), 30, [4], azimuth=135), free]),
            weft([(0, 0, 3), (10, 0, 3)]),
            weft([(0, 0, 4), (0, 10, 4)], angle=90),
        ]
    )
    result = angles(sk)
    assert list(result) == ["warp", "weft-0", "weft-90"]
    assert result["warp"]["mean"] == pytest.approx(30.0)
    assert result["warp"]["std"] == pytest.approx(0.0, abs=1e-6)
    assert result["warp"]["segments"] == 3
    assert result["warp"]["length"] == pytest.approx(9.0)
    assert result["weft-0"]["mean"] == pytest.approx(90.0)
    assert result["weft-90"]["length"] == pytest.approx(10.0)


def test_angle_mean_and_spread_are_length_weighted():
    nodes = inclined((0, 0, 0), 20, [1])
    nodes += inclined(nodes[-1], 40, [3])[1:]
    sk = build([warp([*nodes, (0, 0, 100)])])
    a = angles(sk)["warp"]
    assert a["mean"] == pytest.approx(35.0)
    assert a["std"] == pytest.approx(math.sqrt((1 * 15**2 + 3 * 5**2) / 4))


def test_downward_segments_and_zero_length_segments():
    sk = build([warp([(0, 0, 10), (0, 0, 10), *inclined((0, 0, 10), 150, [2]), (0, 0, 99)])])
    a = angles(sk)["warp"]
    assert a["mean"] == pytest.approx(30.0)
    assert a["segments"] == 1


def test_family_without_fixed_segments():
    sk = build([warp([(0, 0, 0), (0, 0, 100)])])
    assert angles(sk)["warp"] == {"segments": 0, "length": 0.0, "mean": None, "std": None}


def test_section_uses_fixed_nodes_in_the_middle_half_of_the_contact_zone():
    sk = build(
        [
            warp([(0, 0, 10), (1, 0, 14), (3, 0, 16), (-9, 9, 30), (0, 18, 19)]),
            warp([(0, 2, 0), (0, 5, 20), (50, 50, 100)]),
            weft([(-2, 1, 17), (4, 1, 17)]),
        ],
        # contact nodes: ids 0 (z 10), 3 (z 30), 5 (z 0) and 6 (z 20) -> zone [0, 30]
        [(1, 0, 0, 1, 5), (2, 1, 6, 0, 3)],
        diameter=0.5,
    )
    assert contact_zone(sk) == (0.0, 30.0)
    s = section(sk)
    assert s is not None
    assert s["z"] == [7.5, 22.5]
    # in the band: (0,0,10) (1,0,14) (3,0,16) (0,5,20) and both weft ends; not the free
    # node (0,18,19) nor (0,2,0) (-9,9,30)
    assert s["nodes"] == 6
    assert (s["x"], s["y"]) == ([-2.0, 4.0], [0.0, 5.0])
    assert s["width"] == pytest.approx(6.5)
    assert s["thickness"] == pytest.approx(5.5)


def test_no_section_without_contacts(small):
    sk = build([warp([(0, 0, 0), (0, 0, 9), (0, 0, 100)])])
    assert section(sk) is None
    assert section(small) is not None


def test_contacts_per_cycle():
    sk = build(
        [warp([(0, 0, float(z)) for z in range(9)])],
        [(i, 0, 0, 0, 1) for i in (1, 1, 2, 5, 6, 6, 6)],
        instructions=7,
    )
    c = contacts_per_cycle(sk, 2)
    assert c["counts"] == [3, 0, 4, 0]
    assert (c["cycles"], c["complete"]) == (4, 3)
    assert c["mean"] == pytest.approx(7 / 3)
    assert (c["min"], c["max"]) == (0, 4)
    assert c["per_instruction"] == [2, 1, 0, 0, 1, 3, 0]
    whole = contacts_per_cycle(sk, None)
    assert (whole["length"], whole["counts"], whole["mean"]) == (7, [7], 7.0)
    with pytest.raises(ExportError, match="at least 1"):
        contacts_per_cycle(sk, 0)


def test_no_complete_cycle():
    sk = build([warp([(0, 0, 0), (0, 0, 9)])], [(1, 0, 0, 0, 1)], instructions=3)
    c = contacts_per_cycle(sk, 4)
    assert (c["counts"], c["complete"], c["mean"], c["min"]) == ([1], 0, None, None)


def test_metrics_is_plain_json(small):
    result = metrics(small, 3)
    assert json.loads(json.dumps(result, allow_nan=False)) == result
    assert result["yarns"] == {"warp": 3, "weft": 1}
    assert (result["nodes"], result["contacts"], result["instructions"]) == (13, 2, 6)
    assert result["cycles"]["counts"] == [1, 1]
    assert result["section"]["width"] == pytest.approx(21.0)


def test_weft_contacts_name_the_loose_wefts_and_those_held_once():
    sk = build(
        [
            warp([(0, 0, 0), (0, 0, 9), (0, 0, 99)]),
            weft([(0, 0, 3), (9, 0, 3)]),
            weft([(0, 0, 5), (9, 0, 5)]),
            weft([(0, 0, 7), (9, 0, 7)], angle=30),
        ],
        [(1, 0, 0, 1, 3), (2, 0, 1, 1, 4), (3, 0, 1, 2, 5)],
    )
    found = weft_contacts(sk)
    assert found["count"] == 3 and found["per_weft"] == [2, 1, 0]
    assert (found["loose"], found["held_once"]) == ([3], [2])
    assert found["contacts"] == {"min": 0, "median": 1.0, "max": 2}
    assert weft_contacts(build([warp([(0, 0, 0), (0, 0, 9)])]))["contacts"] is None
