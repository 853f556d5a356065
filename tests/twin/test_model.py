"""Twin API: predictions without side effects, commits of a record, snapshots, refusals."""

from __future__ import annotations

import itertools
import sys
import threading
from dataclasses import FrozenInstanceError
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bwsd.errors import MoveError, ShedClosedError, TwinError
from bwsd.program import parse_program
from bwsd.program.generators import braid4
from bwsd.twin import Machine, Program, Shift, Snapshot, TakeUp, Twin, Weft, replay, simulate
from bwsd.twin._kernel import Kernel
from bwsd.twin.model import Twin as TwinClass
from tests.twin.conftest import WORKED_CYCLE, WORKED_FILL, WORKED_MACHINE


def _bits(twin: Twin) -> list[object]:
    sk = twin.skeleton()
    return [(y.node_ids.tobytes(), y.nodes.tobytes()) for y in sk.yarns] + [
        sk.contacts,
        sk.occupancy.tobytes(),
        sk.takeup,
        sk.instructions,
    ]


def _worked_program(cycles: int, takeup: float = 0.0) -> Program:
    cycle = [*WORKED_CYCLE, TakeUp(takeup)] if takeup else list(WORKED_CYCLE)
    return Program(1.0, tuple(WORKED_FILL), tuple(cycle * cycles))


def test_same_input_gives_the_same_skeleton_bit_for_bit():
    program = _worked_program(6, takeup=1.5)
    assert _bits(simulate(WORKED_MACHINE, program)) == _bits(simulate(WORKED_MACHINE, program))


def test_reads_between_predict_and_commit_change_nothing_and_commit_does_not_predict_again(
    monkeypatch,
):
    """Before, a read of ``takeup`` between predict and commit rolled the prediction back and
    made commit predict the whole instruction again (on the daemon's event loop)."""
    runs = []
    original = TwinClass._run

    def counting(self, *args, **kwargs):
        runs.append(args[0])
        return original(self, *args, **kwargs)

    monkeypatch.setattr(TwinClass, "_run", counting)
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    twin.apply(WORKED_CYCLE[0])
    before = _bits(twin)
    runs.clear()
    pred = twin.predict(WORKED_CYCLE[1])
    assert len(pred.contacts) == 1
    # every read, twice: nothing moves, nothing is recomputed
    for _ in range(2):
        assert twin.takeup == 0.0 and twin.done == 1
        assert twin.occupancy.tolist() == [[-1, 0], [1, -1]]
        assert twin.contact_count == 0 and twin.node_count == 4 and twin.yarn_count == 2
        assert twin.free_node(1) == 3 and twin.yarn(0).node_ids.tolist() == [0, 1]
        assert twin.path_length(0) > 0
        assert _bits(twin) == before
    twin.commit(pred)
    assert runs == [WORKED_CYCLE[1]]  # one kernel run: the prediction's
    assert twin.done == 2 and twin.contact_count == 1


def test_commit_of_a_prediction_equals_apply_and_advance():
    a, b, c = (Twin(WORKED_MACHINE, WORKED_FILL, 1.0) for _ in range(3))
    for ins in [*WORKED_CYCLE, TakeUp(2.5), *WORKED_CYCLE, Weft(5, -30, 40, 0, 10)]:
        pred = a.predict(ins)
        a.commit(pred)
        b.apply(ins)
        c.advance(ins)
    assert _bits(a) == _bits(b) == _bits(c)


def test_a_prediction_made_on_another_state_is_refused():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    pred = twin.predict(WORKED_CYCLE[0])
    twin.apply(WORKED_CYCLE[0])
    with pytest.raises(TwinError, match="stale") as err:
        twin.commit(pred)  # made before the state moved on
    assert err.value.instruction == 1
    other = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    other.apply(WORKED_CYCLE[0])
    with pytest.raises(TwinError, match="stale"):
        other.commit(twin.predict(WORKED_CYCLE[1]))  # the same contents, another twin
    snap = twin.snapshot()
    pred = twin.predict(WORKED_CYCLE[1])
    twin.restore(snap)  # the same contents, but a state of its own
    with pytest.raises(TwinError, match="stale"):
        twin.commit(pred)
    twin.commit(twin.predict(WORKED_CYCLE[1]))
    assert twin.done == 2


def test_a_prediction_is_immutable():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    twin.apply(WORKED_CYCLE[0])
    pred = twin.predict(WORKED_CYCLE[1])
    with pytest.raises(FrozenInstanceError):
        pred.index = 3  # type: ignore[misc]  # frozen: the assignment must raise
    for table in (
        pred.occupancy,
        pred.contact_table,
        pred.node_table,
        pred.moved_table,
        pred.length_table,
    ):
        with pytest.raises(ValueError):
            table.flat[0] = 7


def test_prediction_describes_the_change():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    twin.apply(WORKED_CYCLE[0])
    pred = twin.predict(WORKED_CYCLE[1])
    assert pred.index == 2
    assert pred.cases == {0: (1, 1), 1: (0, 0)}
    assert pred.occupancy.tolist() == [[1, -1], [-1, 0]]
    contact = pred.contacts[0]
    inserted = {n.node: n for n in pred.inserted}
    assert set(inserted) == {contact.moving_node, contact.hit_node}
    assert inserted[contact.hit_node].after == 0  # Y between yarn 0's fell node and guide
    assert inserted[contact.moving_node].after == 2  # X right after yarn 1's fell node
    assert set(pred.length_change) == {0, 1} and all(
        abs(v) < 20 for v in pred.length_change.values()
    )
    twin.commit(pred)
    sk = twin.skeleton()
    assert sk.yarns[0].node_ids.tolist() == [0, contact.hit_node, 1]
    for node in pred.inserted:
        assert tuple(sk.node_positions()[node.node]) == node.xyz
    assert {w: tuple(sk.node_positions()[twin.free_node(w)]) for w in (0, 1)} == pred.free_nodes


def test_snapshot_as_bytes_resumes_to_the_identical_skeleton():
    program = _worked_program(4, takeup=2.0)
    full = simulate(WORKED_MACHINE, program)
    part = replay(WORKED_MACHINE, program, 9)
    data = part.snapshot().to_bytes()
    resumed = Twin.from_snapshot(WORKED_MACHINE, Snapshot.from_bytes(data))
    assert resumed.done == 9 and resumed.takeup_exact == part.takeup_exact
    assert _bits(resumed) == _bits(part)
    for ins in program.instructions[9:]:
        resumed.apply(ins)
    assert _bits(resumed) == _bits(full)


def test_restore_returns_to_a_snapshot_any_number_of_times():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    twin.apply(WORKED_CYCLE[0])
    snap = twin.snapshot()
    before = _bits(twin)
    for _ in range(2):
        for ins in WORKED_CYCLE[1:] + WORKED_CYCLE * 2:
            twin.apply(ins)
        assert _bits(twin) != before
        twin.restore(snap)
        assert _bits(twin) == before
        assert twin.done == 1


def test_a_damaged_or_foreign_snapshot_is_refused():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    twin.apply(WORKED_CYCLE[0])
    data = bytearray(twin.snapshot().to_bytes())
    for at in (3, 12, 40, len(data) - 9):
        broken = bytearray(data)
        broken[at] ^= 0x10
        with pytest.raises(TwinError, match="snapshot"):
            Twin.from_snapshot(WORKED_MACHINE, Snapshot.from_bytes(bytes(broken)))
    with pytest.raises(TwinError, match="snapshot"):
        Snapshot.from_bytes(bytes(data[:-5]))
    other = Machine(rows=2, cols=2, pitch_x=10, pitch_y=10, d_mat=120, c_mat=0.5)
    with pytest.raises(TwinError, match="another machine"):
        Twin(other, WORKED_FILL, 1.0).restore(Snapshot.from_bytes(bytes(data)))


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
    # row 0 moves right: both its cases land fine; row 1's case would leave the matrix.
    with pytest.raises(MoveError, match=r"leave the matrix at cell \(1, 3\)") as err:
        twin.apply(Shift("row", ((0, 1), (1, 1))))
    assert err.value.instruction == 1
    assert _bits(twin) == before
    assert twin.occupancy.tolist() == [[0, 1, -1], [-1, -1, 2]]
    with pytest.raises(MoveError, match="ROW 2 is outside the matrix"):
        twin.predict(Shift("row", ((0, 1), (2, 1))))
    assert _bits(twin) == before
    twin.apply(Shift("row", ((0, 1),)))
    assert twin.occupancy.tolist() == [[-1, 0, 1], [-1, -1, 2]]


def test_coordinates_beyond_the_grid_range_are_refused_with_the_instruction():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    before = _bits(twin)
    with pytest.raises(TwinError, match="2\\^20 mm") as err:
        twin.apply(TakeUp(2.0**20))
    assert err.value.instruction == 1 and _bits(twin) == before
    with pytest.raises(TwinError, match="2\\^20 mm"):
        twin.apply(Weft(x=2.0**20, y=0, z=10, angle=0, length=10))
    with pytest.raises(TwinError, match="2\\^20 mm"):
        Twin(Machine(2, 3, 2.0**19 + 1, 10, 100, 0.5), [(0, 0)])
    with pytest.raises(TwinError, match="diameter"):
        Twin(WORKED_MACHINE, WORKED_FILL, 1e-9)
    twin.apply(TakeUp(2.0**20 - 100 - 1))  # just below the range: fine
    assert twin.takeup == 2.0**20 - 101


def test_weft_into_a_closed_shed_is_refused():
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    # yarn 0 runs from (2.5, 2.5, 0) to (0, 0, 100): at z = 50 it passes (1.25, 1.25).
    with pytest.raises(ShedClosedError, match=r"shed closed.*yarn 0"):
        twin.apply(Weft(x=1.25, y=1.25, z=50, angle=45, length=20))
    assert twin.yarn_count == 2
    twin.apply(Weft(x=5, y=-20, z=50, angle=0, length=20))  # well clear
    assert twin.yarn_count == 3


LINE = Machine(rows=1, cols=2, pitch_x=10, pitch_y=10, d_mat=100, c_mat=1.0)


@pytest.mark.parametrize(("y", "refused"), [(1.0, False), (0.999999, True), (1.000001, False)])
def test_the_shed_check_is_exact_at_one_diameter(y, refused):
    """Warp 0 runs straight up the z axis at x = y = 0; a weft along x at distance y."""
    twin = Twin(LINE, [(0, 0)], diameter=1.0)
    weft = Weft(x=0, y=y, z=50, angle=0, length=20)
    if refused:
        with pytest.raises(ShedClosedError, match=r"0\.999999 mm from yarn 0"):
            twin.apply(weft)
    else:
        twin.apply(weft)
        assert twin.yarn_count == 2


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


def test_every_coordinate_lies_on_the_grid():
    twin = simulate(WORKED_MACHINE, _worked_program(3, takeup=0.7))
    twin.apply(Weft(x=0.1, y=-30.3, z=33.3, angle=37, length=11.1))
    for yarn in twin.skeleton().yarns:
        scaled = yarn.nodes * 2.0**32
        assert np.array_equal(scaled, np.round(scaled))


# One warp sweeping the triangle (0,0,0), (0,0,100), (10,0,100) in the plane y = 0.
@pytest.mark.slow
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
    assert y[1] == 0.0  # exactly on the swept plane
    assert y[2] == pytest.approx(z, abs=2**-32)


def _big_twin() -> tuple[Twin, Program]:
    generated = braid4(12, 12, cycles=2, takeup=3.0, pitch=10.0, d_mat=300.0, c_mat=0.3)
    program = parse_program(generated.program)
    return Twin.from_program(generated.machine, program), program


class _Spy:
    """Forwards to the kernel; says whether a thread is inside its ``shift`` right now."""

    def __init__(self, kernel: Kernel) -> None:
        self._kernel = kernel
        self.inside = False

    def __getattr__(self, name: str) -> Any:
        return getattr(self._kernel, name)

    def shift(self, *args: Any) -> Any:
        self.inside = True
        try:
            return self._kernel.shift(*args)
        finally:
            self.inside = False


def test_predict_releases_the_interpreter_while_the_kernel_runs():
    """With a switch interval far beyond the test, the main thread runs only while the
    predicting thread has released the interpreter lock: it must see the kernel running."""
    seen = 0
    done = threading.Event()
    current: list[_Spy] = []

    def predict_many() -> None:
        # On a busy machine the main thread may not be scheduled during any of a program's
        # kernel calls: the program runs again, on a fresh twin, until the main thread saw the
        # kernel running, 10 times at most. A kernel that keeps the lock is never seen.
        try:
            for _ in range(10):
                twin, program = _big_twin()
                spy = _Spy(twin._kernel)
                twin._kernel = spy  # type: ignore[assignment]  # a spy in the kernel's place
                current[:] = [spy]
                for ins in program.instructions:
                    twin.apply(ins)
                if seen:
                    return
        finally:
            done.set()

    old = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)
    try:
        worker = threading.Thread(target=predict_many)
        worker.start()
        while not done.wait(0.0002):  # waits without the lock
            seen += bool(current) and current[0].inside
        worker.join()
    finally:
        sys.setswitchinterval(old)
    assert seen > 0
