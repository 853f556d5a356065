"""The worked example of docs/twin.md, against the kernel and the exact reference."""

from __future__ import annotations

import math

import numpy as np

from tests.twin.conftest import WORKED_CYCLE, WORKED_FILL, WORKED_MACHINE, assert_same, run_both

GRID = 2.0**-32


def test_worked_example_counts_and_first_contact():
    twin, ref = run_both(WORKED_MACHINE, WORKED_FILL, 1.0, WORKED_CYCLE * 4)
    sk = twin.skeleton()
    assert len(sk.yarns) == 2
    assert len(sk.contacts) == 15
    assert sk.node_count == 34
    first = sk.contacts[0]
    assert (first.instruction, first.moving_yarn, first.hit_yarn) == (2, 1, 0)
    y = sk.node_positions()[first.hit_node]
    # (5, 5, 100/3) rounded once to the 2^-32 mm grid
    assert y.tolist() == [5.0, 5.0, 143165576533 * GRID]
    assert_same(twin, ref)


def test_first_contact_is_at_the_end_of_the_move():
    """t = 1: the moving yarn's free node ends where the contact line ends (the new guide)."""
    twin, _ = run_both(WORKED_MACHINE, WORKED_FILL, 1.0, WORKED_CYCLE[:2])
    sk = twin.skeleton()
    assert len(sk.contacts) == 1
    moving = sk.yarns[1]
    nodes = sk.node_positions()
    x, y = nodes[sk.contacts[0].moving_node], nodes[sk.contacts[0].hit_node]
    # Yarn 1 moves along -y (COL 0:-1) and hits yarn 0's segment from its fell (2.5, 2.5, 0)
    # to its new guide (10, 10, 100): X = round(Y - d n / |n|), n the move without its part
    # along C-D; each coordinate is within half a grid step of the exact value.
    move = np.array((0.0, -10.0, 0.0))
    axis = np.array((7.5, 7.5, 100.0)) / np.linalg.norm((7.5, 7.5, 100.0))
    n = move - (move @ axis) * axis
    assert np.abs(x - (y - n / np.linalg.norm(n))).max() <= GRID / 2 + 1e-13
    assert all(math.ldexp(v, 32).is_integer() for v in x)
    assert moving.nodes[-1].tolist() == [0.0, 0.0, 100.0]
