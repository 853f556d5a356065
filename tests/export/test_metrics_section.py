"""`bwsd metrics` for shaped preforms: contact groups."""

from __future__ import annotations

from pathlib import Path

import pytest

from bwsd.export.cli import simulate_program
from bwsd.export.metrics import groups, unconnected

from .conftest import build, warp, weft

ROOT = Path(__file__).resolve().parents[2]


# ----- contact groups -----


def test_groups_of_a_hand_built_skeleton():
    line = [(0.0, 0.0, 0.0), (0.0, 0.0, 9.0)]
    sk = build(
        [warp(line), warp(line), warp(line), warp(line), weft(line), warp(line), warp(line)],
        # (instruction, moving yarn, its node, hit yarn, its node); node ids are 2 per yarn
        [(1, 2, 4, 1, 2), (2, 0, 0, 1, 3), (3, 3, 6, 4, 8), (4, 6, 12, 4, 9)],
    )
    assert groups(sk) == {"count": 3, "sizes": [3, 3, 1], "members": [[0, 1, 2], [3, 4, 6], [5]]}
    assert unconnected(sk) == {"count": 1, "ids": [5]}
    alone = build([warp(line), warp(line)])
    assert groups(alone)["members"] == [[0], [1]]
    assert unconnected(alone) == {"count": 2, "ids": [0, 1]}


@pytest.mark.parametrize("stem", ["braid-2x2", "twist", "weave-plain"])
def test_a_shipped_preform_is_one_group(stem):
    sk, _ = simulate_program(
        str(ROOT / "config" / f"{stem}.toml"), str(ROOT / "examples" / f"{stem}.bws")
    )
    found = groups(sk)
    assert (found["count"], found["sizes"]) == (1, [len(sk.yarns)])
    assert unconnected(sk) == {"count": 0, "ids": []}
