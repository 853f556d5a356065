"""Hand-built skeletons for the export tests."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal, NotRequired, TypedDict

import numpy as np
import pytest

from bwsd.twin.machine import Machine
from bwsd.twin.skeleton import ContactData, SkeletonData, YarnData

MACHINE = Machine(
    rows=2, cols=2, pitch_x=10.0, pitch_y=10.0, d_mat=100.0, c_mat=0.5, yarn_diameter=1.0
)

Point = tuple[float, float, float]


class YarnSpec(TypedDict):
    """One yarn to build: a warp has its cell, a weft its angle."""

    kind: Literal["warp", "weft"]
    nodes: Sequence[Point]
    cell: NotRequired[tuple[int, int]]
    angle: NotRequired[float]


def warp(nodes: Sequence[Point], cell: tuple[int, int] = (0, 0)) -> YarnSpec:
    return {"kind": "warp", "nodes": nodes, "cell": cell}


def weft(nodes: Sequence[Point], angle: float = 0.0) -> YarnSpec:
    return {"kind": "weft", "nodes": nodes, "angle": angle}


def build(
    yarns: Sequence[YarnSpec],
    contacts: Sequence[tuple[int, int, int, int, int]] = (),
    *,
    diameter: float = 1.0,
    takeup: float = 20.0,
    instructions: int = 6,
    occupancy: Sequence[Sequence[int]] = ((0, 1), (-1, 2)),
) -> SkeletonData:
    """A skeleton of the given yarns, node ids numbered 0, 1, ... in yarn order.

    ``contacts`` are (instruction, moving yarn, moving node, hit yarn, hit node).
    """
    out, next_id = [], 0
    for i, spec in enumerate(yarns):
        nodes = np.array(spec["nodes"], dtype=np.float64)
        ids = np.arange(next_id, next_id + len(nodes), dtype=np.int64)
        next_id += len(nodes)
        out.append(
            YarnData(
                id=i,
                kind=spec["kind"],
                node_ids=ids,
                nodes=nodes,
                cell=spec.get("cell"),
                angle=spec.get("angle"),
            )
        )
    return SkeletonData(
        machine=MACHINE,
        diameter=diameter,
        takeup=takeup,
        instructions=instructions,
        yarns=tuple(out),
        contacts=tuple(ContactData(*c) for c in contacts),
        occupancy=np.array(occupancy, dtype=np.int64),
    )


def small_skeleton(diameter: float = 1.0) -> SkeletonData:
    """Three vertical warps (free nodes at their guides, z = 120), one weft at z = 15.

    Node ids: yarn 0: 0-3, yarn 1: 4-7, yarn 2: 8-10, yarn 3 (weft): 11-12.
    """
    return build(
        [
            warp([(2.5, 2.5, 0), (2.5, 2.5, 10), (2.5, 2.5, 20), (0, 0, 120)], (0, 0)),
            warp([(7.5, 2.5, 0), (7.5, 2.5, 10), (7.5, 2.5, 20), (10, 0, 120)], (0, 1)),
            warp([(7.5, 7.5, 0), (7.5, 7.5, 20), (10, 10, 120)], (1, 1)),
            weft([(-5, 5, 15), (15, 5, 15)], 0.0),
        ],
        [(2, 1, 5, 0, 1), (5, 0, 2, 1, 6)],
        diameter=diameter,
    )


@pytest.fixture
def small() -> SkeletonData:
    return small_skeleton()


@pytest.fixture
def centreline() -> SkeletonData:
    return small_skeleton(diameter=0.0)
