"""The fast kernel against the exact reference on random and degenerate programs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from bwsd.errors import JamError, ShedClosedError
from bwsd.twin import Machine, Shift, TakeUp, Weft
from bwsd.twin.instructions import Axis, MoveEntry
from bwsd.twin.machine import Segment
from tests.twin.conftest import BRAID_CYCLE, BRAID_FILL, assert_same, run_both
from tests.twin.reference import Jam, ShedClosed

SETTINGS = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def _valid(
    occupied: set[tuple[int, int]], machine: Machine, ins: Shift
) -> set[tuple[int, int]] | None:
    """Occupancy after ``ins``, or None if a case would leave the matrix, its segment or
    collide."""
    occ = set(occupied)
    along = 1 if ins.axis == "row" else 0
    for line, k, span in ins.moves:
        lo, hi = span if span is not None else (0, 10**6)
        on_line = sorted(
            (rc for rc in occ if rc[1 - along] == line and lo <= rc[along] <= hi),
            key=lambda rc: rc[along],
            reverse=k > 0,
        )
        for r, c in on_line:
            target = (r, c + k) if ins.axis == "row" else (r + k, c)
            if not machine.inside(*target) or target in occ or not lo <= target[along] <= hi:
                return None
            occ.remove((r, c))
            occ.add(target)
    return occ


@st.composite
def segments(draw, machine: Machine) -> Machine:
    """``machine`` with a segment on some of its lines (cells first..last along the line)."""
    found = []
    sides: list[tuple[Axis, int, int]] = [
        ("row", machine.rows, machine.cols),
        ("col", machine.cols, machine.rows),
    ]
    for axis, lines, along in sides:
        for line in range(lines):
            if draw(st.booleans()):
                lo = draw(st.integers(0, along - 2))
                found.append(Segment(axis, line, lo, draw(st.integers(lo + 1, along - 1))))
    return dataclasses.replace(machine, segments=tuple(found))


def _entry(draw, machine: Machine, axis: str, line: int) -> MoveEntry:
    """A move of ``line``: the whole line, or its segment when it has one (half the time)."""
    k = draw(st.sampled_from([-1, 1, -1, 1, -2, 2]))
    mine = [s for s in machine.segments if (s.axis, s.line) == (axis, line)]
    if mine and draw(st.booleans()):
        return (line, k, mine[0].lo, mine[0].hi)
    return (line, k)


def _fitting(machine: Machine, share: float) -> float:
    """A diameter of ``share`` of the largest that fits ``machine`` (0 below 1e-3 mm)."""
    d = share * machine.c_mat * min(machine.pitch_x, machine.pitch_y)
    return d if d >= 1e-3 else 0.0


@st.composite
def programs(draw, degenerate: bool):
    rows, cols = draw(st.integers(2, 4)), draw(st.integers(2, 4))
    if degenerate:
        pitch = draw(st.sampled_from([1.0, 2.0]))
        machine = Machine(
            rows,
            cols,
            pitch,
            pitch,
            draw(st.sampled_from([2.0, 4.0, 8.0])),
            draw(st.sampled_from([0.0, 0.5, 1.0])),
        )
        diameter = draw(st.sampled_from([0.0, 0.0, 0.25])) if machine.c_mat else 0.0
    else:
        f = st.floats(0.5, 20.0, allow_nan=False)
        machine = Machine(
            rows, cols, draw(f), draw(f), draw(st.floats(5.0, 200.0)), draw(st.floats(0.0, 1.0))
        )
        diameter = _fitting(machine, draw(st.one_of(st.just(0.0), st.floats(0.0, 0.99))))
    machine = draw(segments(machine))
    cells = [(r, c) for r in range(rows) for c in range(cols)]
    fill = sorted(
        draw(
            st.lists(
                st.sampled_from(cells), min_size=2, max_size=max(2, len(cells) // 2), unique=True
            )
        )
    )
    occupied = set(fill)
    instructions: list[Shift | TakeUp | Weft] = []
    target = draw(st.integers(2, 12))
    for _ in range(40):
        if len(instructions) >= target:
            break
        kind = draw(st.sampled_from(["row", "col"] * 4 + ["takeup", "weft"]))
        if kind == "takeup":
            instructions.append(
                TakeUp(
                    draw(st.sampled_from([1.0, 2.5])) if degenerate else draw(st.floats(0.1, 10.0))
                )
            )
            continue
        if kind == "weft":
            instructions.append(
                Weft(
                    draw(st.floats(-5, 40)),
                    draw(st.floats(-5, 40)),
                    draw(st.floats(0.1, 0.9)) * machine.d_mat,
                    draw(st.sampled_from([0.0, 90.0, 37.0])),
                    draw(st.floats(1.0, 30.0)),
                )
            )
            continue
        axis = 0 if kind == "row" else 1
        used = sorted({rc[axis] for rc in occupied})
        lines = draw(st.lists(st.sampled_from(used), min_size=1, max_size=len(used), unique=True))
        ins = Shift(kind, tuple(_entry(draw, machine, kind, line) for line in lines))
        after = _valid(occupied, machine, ins)
        if after is not None:
            occupied = after
            instructions.append(ins)
    return machine, fill, diameter, instructions


def _compare(case) -> int:
    """Kernel and reference side by side: the same refusals (a jam by the same yarns at the
    same height), then the same skeleton, up to the first jam. Returns the number of jams."""
    machine, fill, diameter, instructions = case
    twin, ref = run_both(machine, fill, diameter, [])
    jams = 0
    for ins in instructions:
        try:
            twin.apply(ins)
        except ShedClosedError:
            with pytest.raises(ShedClosed):
                ref.run(ins)
            continue
        except JamError as exc:
            with pytest.raises(Jam) as found:
                ref.run(ins)
            assert exc.yarns == (found.value.moving, found.value.hit)
            assert exc.z == math.ldexp(found.value.z, -32)
            assert exc.instruction == ref.done + 1
            jams += 1
            break  # the instructions after it were drawn as if it had moved the cases
        ref.run(ins)
    assert_same(twin, ref)
    return jams


@pytest.mark.slow
@SETTINGS
@given(programs(degenerate=False))
def test_random_programs_match_reference(case):
    _compare(case)


@pytest.mark.slow
@SETTINGS
@given(programs(degenerate=True))
def test_degenerate_programs_match_reference(case):
    _compare(case)


def test_kernel_and_reference_agree_on_a_dense_twist():
    machine = Machine(2, 2, 10.0, 10.0, 100.0, 0.5)
    cycle = [
        Shift("row", ((0, 1), (1, -1))),
        Shift("col", ((1, 1), (0, -1))),
        Shift("row", ((1, -1), (0, 1))),
        Shift("col", ((0, -1), (1, 1))),
        TakeUp(2.0),
    ]
    twin, ref = run_both(machine, [(0, 0), (1, 1)], 1.0, cycle * 6)
    assert len(ref.contacts) > 10
    assert_same(twin, ref)
    assert np.isfinite(twin.skeleton().yarns[0].nodes).all()


@st.composite
def braids(draw):
    """The 8-carrier 4-step braid (2x2 body) with random geometry and take-up."""
    integer = draw(st.booleans())
    if integer:
        pitch = draw(st.sampled_from([1.0, 2.0, 10.0]))
        machine = Machine(
            4,
            4,
            pitch,
            pitch,
            draw(st.sampled_from([4.0, 10.0, 100.0])),
            draw(st.sampled_from([0.0, 0.25, 0.5, 1.0])),
        )
        fits = [d for d in (0.0, 0.5, 1.0) if d < machine.c_mat * pitch] or [0.0]
        diameter = draw(st.sampled_from(fits))
        takeup = st.sampled_from([0.5, 1.0, 2.0])
    else:
        f = st.floats(1.0, 20.0)
        machine = Machine(
            4, 4, draw(f), draw(f), draw(st.floats(20.0, 200.0)), draw(st.floats(0.05, 0.95))
        )
        diameter = _fitting(machine, draw(st.one_of(st.just(0.0), st.floats(0.0, 0.99))))
        takeup = st.floats(0.1, 5.0)
    instructions = []
    for _ in range(draw(st.integers(1, 3))):
        instructions += [*BRAID_CYCLE, TakeUp(draw(takeup))]
    return machine, BRAID_FILL, diameter, instructions


# Found by hypothesis: two segment ends on opposite exact sides whose float plane values are
# equal, so the float ratio of the crossing point is undefined.
FLAT_CROSSING = (
    Machine(4, 4, 1.0, 8.48256361874948, 36.97948251107606, 0.875),
    BRAID_FILL,
    0.0,
    [*BRAID_CYCLE, TakeUp(2.899204154337702), *BRAID_CYCLE, TakeUp(3.5), *BRAID_CYCLE, TakeUp(1.0)],
)


@pytest.mark.slow
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(braids())
@example(FLAT_CROSSING)
def test_braids_match_reference(case):
    _compare(case)


@pytest.fixture
def kernel_path(request, monkeypatch):
    """Force one of the kernel's paths: every float filter deferring to the exact computation,
    the whole machine in one broad-phase cell, or cells of a quarter millimetre."""
    from bwsd.twin import _kernel
    from bwsd.twin.geometry import Geometry

    if request.param == "exact-only":
        _kernel.set_exact_only(True)
        request.addfinalizer(lambda: _kernel.set_exact_only(False))
    elif request.param == "one-cell":
        monkeypatch.setattr(Geometry, "cell_shift", lambda self: 60)
    else:
        monkeypatch.setattr(Geometry, "cell_shift", lambda self: 30)
    return request.param


@pytest.mark.slow
@pytest.mark.parametrize("kernel_path", ["exact-only", "one-cell", "fine-cells"], indirect=True)
@settings(
    max_examples=15,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(braids())
@example(FLAT_CROSSING)
def test_every_kernel_path_matches_reference(kernel_path, case):
    """The float filters are only a shortcut and the broad phase only a filter: forcing the
    exact computation everywhere, or another cell size, changes nothing."""
    _compare(case)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("stem", "count"),
    [
        ("twist", None),
        ("braid-2x2", None),
        ("weave-plain", None),
        ("braid-L", None),
        ("weave-U", None),
        ("braid-24x24", 5),
        ("paper-L", None),
        ("paper-U", 160),  # 5 of its 10 cycles, past the climb of the wefts
    ],
)
def test_every_example_matches_the_reference_node_for_node(stem, count):
    """The shipped examples, whole; the 24x24 braid for its first cycle (the brute-force
    reference would take hours for all ten)."""
    from pathlib import Path

    from bwsd.config import load_config
    from bwsd.program import load_program

    root = Path(__file__).resolve().parents[2]
    machine = load_config(root / "config" / f"{stem}.toml").machine
    program = load_program(root / "examples" / f"{stem}.bws", machine)
    diameter = machine.yarn_diameter if program.diameter is None else program.diameter
    twin, ref = run_both(machine, program.fill, diameter, program.instructions[:count])
    assert_same(twin, ref)
