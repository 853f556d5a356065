"""Shared builders for twin tests: the worked example, and the kernel beside the reference."""

from __future__ import annotations

import numpy as np

from bwsd.twin import Machine, Shift, Twin
from bwsd.twin.instructions import Instruction
from tests.twin.reference import RefTwin

WORKED_MACHINE = Machine(rows=2, cols=2, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5)
WORKED_FILL = [(0, 0), (1, 1)]
WORKED_CYCLE: list[Instruction] = [
    Shift("row", ((0, 1), (1, -1))),
    Shift("col", ((1, 1), (0, -1))),
    Shift("row", ((1, -1), (0, 1))),
    Shift("col", ((0, -1), (1, 1))),
]

# The 8-carrier 4-step braid (2x2 body) on a 4x4 machine: its fill and the four steps.
BRAID_FILL = [(0, 1), (1, 0), (1, 1), (1, 2), (2, 1), (2, 2), (2, 3), (3, 2)]
BRAID_CYCLE: list[Instruction] = [
    Shift("row", ((1, 1), (2, -1))),
    Shift("col", ((1, 1), (2, -1))),
    Shift("row", ((1, -1), (2, 1))),
    Shift("col", ((1, -1), (2, 1))),
]


def run_both(machine: Machine, fill, diameter: float, instructions) -> tuple[Twin, RefTwin]:
    twin = Twin(machine, fill, diameter)
    ref = RefTwin(machine, list(fill), diameter)
    for ins in instructions:
        twin.apply(ins)
        ref.run(ins)
    return twin, ref


def assert_same(twin: Twin, ref: RefTwin) -> None:
    """Same yarns, same node ids in the same order, identical coordinates, same contacts."""
    sk = twin.skeleton()
    assert len(sk.yarns) == len(ref.yarns)
    for yarn, ids in zip(sk.yarns, ref.yarns, strict=True):
        assert yarn.node_ids.tolist() == ids, f"yarn {yarn.id} nodes differ"
        expected = np.array([ref.mm(i) for i in ids])
        assert np.array_equal(yarn.nodes, expected), f"yarn {yarn.id} coordinates differ"
    got = [
        (c.instruction, c.moving_yarn, c.moving_node, c.hit_yarn, c.hit_node) for c in sk.contacts
    ]
    assert got == [tuple(c) for c in ref.contacts]
    assert sk.takeup == float(ref.takeup)
