"""Settling a pending weft from its insert's stroke counter (pure: no bus, no journal)."""

from __future__ import annotations

import pytest

from bwsd.config import parse_config
from bwsd.controller.plan import misplaced, placing
from bwsd.controller.recovery import Before, settle
from bwsd.fieldbus.axes import axis_by_name, machine_axes
from bwsd.fieldbus.base import AxisState, BoolGrid, MachineState
from bwsd.program import parse_program
from bwsd.twin import Twin, Weft
from tests.support.fieldbus import MACHINE

TEXT = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nWEFT x=15 y=-5 z=2 angle=0 length=20\n"
M = parse_config({"machine": MACHINE}).machine
INSERT = axis_by_name(M, "weft_insert").index


def machine(occupancy: BoolGrid, insert_strokes: int | None, fault: int = 0) -> MachineState:
    axes = [AxisState(0, False, 0, 0, 0, 0) for _ in range(11)]
    axes[INSERT] = AxisState(0, False, 3, fault, 20_000, insert_strokes)
    return MachineState(tuple(axes), occupancy, False)


def decide(strokes_now: int | None, journaled: dict[int, int] | None, fault: int = 0) -> str:
    program = parse_program(TEXT)
    twin = Twin(M, program.fill)
    weft = program.instructions[0]
    pred = twin.predict(weft)
    at_rest = twin.occupancy >= 0
    decision = settle(
        weft, pred, machine(at_rest, strokes_now, fault), 0, Before(at_rest, 0), 0, 10, journaled
    )
    return f"{decision.kind}: {decision.reason}"


def test_a_weft_whose_insert_never_ran_is_run_again_not_committed():
    assert decide(7, {INSERT: 7}).startswith(
        "rerun: instruction 1 started, the weft was not inserted"
    )


def test_a_weft_whose_insert_counted_one_stroke_is_committed():
    assert decide(8, {INSERT: 7}).startswith("commit")
    assert decide(0, {INSERT: 0xFFFF}).startswith("commit")  # the 16-bit counter wrapped


@pytest.mark.parametrize(
    ("now", "journaled", "fault", "reason"),
    [
        (9, {INSERT: 7}, 0, "the insert counted 2 strokes since it started, not 0 or 1"),
        (None, {INSERT: 7}, 0, "the bus reports no stroke counter (Modbus map 2)"),
        (7, None, 0, "no stroke count of the insert was journaled"),
        (7, {INSERT: 7}, 2, "the insert axis reports fault 2"),
    ],
)
def test_a_weft_that_cannot_be_told_is_blocked_for_the_operator(now, journaled, fault, reason):
    said = decide(now, journaled, fault)
    assert said.startswith("blocked: instruction 1 started and not done: ") and reason in said


def test_a_weft_inserted_with_the_inserter_off_its_place_is_blocked():
    program = parse_program(TEXT)
    twin = Twin(M, program.fill)
    weft = program.instructions[0]
    assert isinstance(weft, Weft)
    pred = twin.predict(weft)
    at_rest = twin.occupancy >= 0
    placed = {m.axis: m.target for m in placing(M, weft)}
    axes = [AxisState(placed.get(i, 0), False, 0, 0, 0, 0) for i in range(len(machine_axes(M)))]
    axes[INSERT] = AxisState(0, False, 3, 0, 20_000, 8)  # one stroke more than journaled
    state = MachineState(tuple(axes), at_rest, False)
    assert misplaced(M, weft, state, 10) == ""
    there = settle(weft, pred, state, 0, Before(at_rest, 0), 0, 10, {INSERT: 7}, "")
    assert there.kind == "commit"
    y = axis_by_name(M, "weft_y").index
    axes[y] = AxisState(placed[y] + 2_000, False, 0, 0, 0, 0)  # moved since: where did it go?
    moved = MachineState(tuple(axes), at_rest, False)
    off = misplaced(M, weft, moved, 10)
    assert off == f"weft_y at {placed[y] + 2_000}, the weft's {placed[y]}"
    decision = settle(weft, pred, moved, 0, Before(at_rest, 0), 0, 10, {INSERT: 7}, off)
    assert decision.kind == "blocked" and "the weft was inserted but the inserter stands " in (
        decision.reason
    )
    not_yet = settle(weft, pred, moved, 0, Before(at_rest, 0), 0, 10, {INSERT: 8}, off)
    assert not_yet.kind == "rerun"  # not inserted: placed again from absolute set-points
