"""Twin API: predict without touching, commit, snapshots, replay, refusals, invariants."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bwsd.errors import MoveError, ShedClosedError, TwinError
from bwsd.twin import Machine, Program, Shift, TakeUp, Twin, Weft, replay, simulate
from tests.twin.conftest import WORKED_CYCLE, WORKED_FILL, WORKED_MACHINE


def _bits(twin: Twin) -> list:
    sk = twin.skeleton()
    return [(y.node_ids.tobytes(), y.nodes.tobytes()) for y in sk.yarns] + list(sk.contacts)


def _worked_program(cycles: int, takeup: float = 0.0) -> Program:
    cycle = [*WORKED_CYCLE, TakeUp(takeup)] if takeup else list(WORKED_CYCLE)
    return Program(1.0, tuple(WORKED_FILL), tuple(cycle * cycles))


def test_same_input_gives_the_same_skeleton_bit_for_bit():
    program = _worked_program(6, takeup=1.5)
    assert _bits(simulate(WORKED_MACHINE, program)) == _bits(simulate(WORKED_MACHINE, program))


def test_predict_leaves_the_committed_state_untouched():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    twin.apply(WORKED_CYCLE[0])
    before = _bits(twin)
    occupancy = twin.occupancy
    pred = twin.predict(WORKED_CYCLE[1])
    assert len(pred.contacts) == 1
    assert _bits(twin) == before  # reading rolls the pending prediction back
    assert np.array_equal(twin.occupancy, occupancy)
    assert twin.done == 1
    twin.commit(pred)  # a rolled-back prediction is recomputed on commit
    assert twin.done == 2
    assert twin.contact_count == 1


def test_commit_of_a_pending_prediction_equals_apply():
    a = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    b = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    for ins in WORKED_CYCLE * 2:
        a.commit(a.predict(ins))
        b.apply(ins)
    assert _bits(a) == _bits(b)


def test_a_stale_prediction_is_refused():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    pred = twin.predict(WORKED_CYCLE[0])
    twin.apply(WORKED_CYCLE[0])
    with pytest.raises(TwinError, match="stale"):
        twin.commit(pred)


def test_prediction_describes_the_change():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    twin.apply(WORKED_CYCLE[0])
    pred = twin.predict(WORKED_CYCLE[1])
    assert pred.index == 2
    assert pred.cases == {0: (1, 1), 1: (0, 0)}
    assert pred.occupancy.tolist() == [[1, -1], [-1, 0]]
    inserted = {n.node for n in pred.inserted}
    contact = pred.contacts[0]
    assert inserted == {contact.moving_node, contact.hit_node}
    assert set(pred.length_change) <= {0, 1} and pred.length_change


def test_snapshot_and_restore_return_to_the_exact_state():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    twin.apply(WORKED_CYCLE[0])
    snap = twin.snapshot()
    before = _bits(twin)
    for ins in WORKED_CYCLE[1:] + WORKED_CYCLE * 2:
        twin.apply(ins)
    assert _bits(twin) != before
    twin.restore(snap)
    assert _bits(twin) == before
    assert twin.done == 1
    with pytest.raises(TwinError):
        twin.restore(snap)  # released by the restore


def test_replay_gives_the_identical_skeleton():
    program = _worked_program(3, takeup=2.0)
    full = simulate(WORKED_MACHINE, program)
    assert _bits(replay(WORKED_MACHINE, program)) == _bits(full)
    part = replay(WORKED_MACHINE, program, 7)
    for ins in program.instructions[7:]:
        part.apply(ins)
    assert _bits(part) == _bits(full)


def test_a_refused_move_leaves_nothing_half_done():
    machine = Machine(2, 3, 10, 10, 100, 0.5)
    twin = Twin(machine, [(0, 0), (0, 1), (1, 2)], 1.0)
    before = _bits(twin)
    # row 0 moves right: the case in column 1 goes first and lands fine, then the case in
    # column 0 would too; row 1's case would leave the matrix: the whole instruction is refused.
    with pytest.raises(MoveError, match=r"leave the matrix at cell \(1, 3\)") as err:
        twin.apply(Shift("row", ((0, 1), (1, 1))))
    assert err.value.instruction == 1
    assert _bits(twin) == before
    assert twin.occupancy.tolist() == [[0, 1, -1], [-1, -1, 2]]
    twin.apply(Shift("row", ((0, 1),)))
    assert twin.occupancy.tolist() == [[-1, 0, 1], [-1, -1, 2]]


def test_weft_into_a_closed_shed_is_refused():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    # yarn 0 runs from (2.5, 2.5, 0) to (0, 0, 100): at z = 50 it passes (1.25, 1.25).
    with pytest.raises(ShedClosedError, match="shed closed"):
        twin.apply(Weft(x=1.25, y=1.25, z=50, angle=45, length=20))
    assert twin.yarn_count == 2
    twin.apply(Weft(x=5, y=-20, z=50, angle=0, length=20))  # well clear
    assert twin.yarn_count == 3


def test_fill_errors():
    with pytest.raises(TwinError, match="outside"):
        Twin(WORKED_MACHINE, [(2, 0)])
    with pytest.raises(TwinError, match="twice"):
        Twin(WORKED_MACHINE, [(0, 0), (0, 0)])


def test_a_twist_gains_contacts_further_up_as_it_winds():
    """docs/twin.md: once wound, about one contact a quarter turn, each further up."""
    twin = simulate(WORKED_MACHINE, _worked_program(12))
    sk = twin.skeleton()
    nodes = sk.node_positions()
    heights = [float(nodes[c.hit_node][2]) for c in sk.contacts]
    quarter_turns = 12 * 4
    assert len(heights) >= quarter_turns - 8
    wound = heights[4:]
    assert all(b > a for a, b in itertools.pairwise(wound))
    assert wound[-1] < WORKED_MACHINE.d_mat


# One warp sweeping the triangle (0,0,0), (0,0,100), (10,0,100) in the plane y = 0.
LINE = Machine(rows=1, cols=2, pitch_x=10, pitch_y=10, d_mat=100, c_mat=1.0)


@settings(max_examples=200, deadline=None)
@given(
    z=st.floats(1.0, 99.0),
    u=st.floats(1e-6, 0.999),
    below=st.floats(0.01, 5),
    above=st.floats(0.01, 5),
)
def test_no_pass_through_a_segment_crossing_the_swept_triangle_is_always_a_contact(
    z, u, below, above
):
    x = u * z / 10  # strictly inside the triangle at height z
    twin = Twin(LINE, [(0, 0)], diameter=0.0)
    twin.apply(Weft(x=x, y=(above - below) / 2, z=z, angle=90, length=above + below))
    contacts = twin.apply(Shift("row", ((0, 1),))).contacts
    assert len(contacts) == 1
    y = twin.skeleton().node_positions()[contacts[0].hit_node]
    assert y[1] == pytest.approx(0.0, abs=1e-12)
    assert y[2] == pytest.approx(z, rel=1e-12)
