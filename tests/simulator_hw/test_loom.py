"""The mock loom's mechanics: strokes with travel time, latching, jams and faults."""

from __future__ import annotations

import pytest

from bwsd.fieldbus.base import FAULT_DRIVE, FAULT_ESTOP, FAULT_JAM, FAULT_NONE, FAULT_STALL
from bwsd.twin import Machine
from bwsd.twin.machine import Segment
from simulator_hw.loom import WRONG_POSITION_OFFSET, Loom, Speeds

MACHINE = Machine(rows=2, cols=3, pitch_x=10, pitch_y=20, d_mat=100, c_mat=0.5)
ROW0, ROW1, COL0, COL2 = 0, 1, 2, 4
WEFT_ANGLE, WEFT_INSERT, TAKEUP = 5, 6, 7


def occupied(loom: Loom) -> set[tuple[int, int]]:
    return {(r, c) for r in range(2) for c in range(3) if loom.occupied[r][c]}


def test_a_stroke_goes_out_latches_and_comes_home():
    loom = Loom(MACHINE, [(0, 0), (1, 2)], Speeds(stroke=100))  # 10 mm at 100 mm/s: 0.1 s
    loom.command(ROW0, 10_000, 7, now=0.0)
    loom.tick(0.05)
    assert (loom.axes[ROW0].position, loom.axes[ROW0].busy) == (5000, True)
    assert occupied(loom) == {(0, 0), (1, 2)}  # not latched before the far end
    loom.tick(0.15)
    assert occupied(loom) == {(0, 1), (1, 2)}
    assert loom.axes[ROW0].done_seq == 0
    loom.tick(0.25)
    sim = loom.axes[ROW0]
    assert (sim.position, sim.busy, sim.done_seq, sim.last_stroke) == (0, False, 7, 10_000)


def test_instant_moves_complete_at_once_and_columns_move_along_y():
    loom = Loom(MACHINE, [(0, 0), (0, 2)], Speeds())
    loom.command(COL0, 20_000, 1, now=0.0)  # one cell of pitch_y = 20 mm
    assert occupied(loom) == {(1, 0), (0, 2)}
    assert loom.axes[COL0].done_seq == 1
    loom.command(TAKEUP, 4_000, 2, now=0.0)
    loom.command(WEFT_ANGLE, 90_000, 3, now=0.0)
    assert (loom.axes[TAKEUP].position, loom.axes[WEFT_ANGLE].position) == (4_000, 90_000)


def test_a_case_pushed_past_the_bound_jams_and_nothing_moves():
    loom = Loom(MACHINE, [(1, 2)], Speeds())
    loom.command(ROW1, 10_000, 1, now=0.0)
    assert loom.axes[ROW1].fault == FAULT_JAM
    assert loom.axes[ROW1].done_seq == 0
    assert occupied(loom) == {(1, 2)}
    loom.command(ROW1, -10_000, 2, now=0.0)  # ignored while faulted
    assert occupied(loom) == {(1, 2)}
    loom.reset_faults()
    loom.command(ROW1, -10_000, 3, now=0.0)
    assert occupied(loom) == {(1, 1)}


def test_injected_faults():
    loom = Loom(MACHINE, [(0, 0)], Speeds(stroke=100))
    loom.faults.stall.add("row0")
    loom.command(ROW0, 10_000, 1, now=0.0)
    loom.tick(1.0)
    assert loom.axes[ROW0].fault == FAULT_STALL
    assert loom.axes[ROW0].position == 5000 and occupied(loom) == {(0, 0)}
    loom.faults.drive.add("col0")
    loom.command(COL0, 20_000, 1, now=1.0)
    assert loom.axes[COL0].fault == FAULT_DRIVE
    loom.faults.wrong_position.add("takeup")
    loom.command(TAKEUP, 3000, 1, now=1.0)
    loom.tick(2.0)
    assert loom.axes[TAKEUP].position == 3000 + WRONG_POSITION_OFFSET
    assert loom.axes[TAKEUP].fault == FAULT_NONE


def test_estop_cuts_moving_axes_and_refuses_new_ones():
    loom = Loom(MACHINE, [(0, 0)], Speeds(stroke=10))
    loom.command(ROW0, 10_000, 1, now=0.0)
    loom.press_estop(True, now=0.5)
    assert loom.axes[ROW0].fault == FAULT_ESTOP
    loom.command(WEFT_INSERT, 5_000, 1, now=0.6)
    assert not loom.axes[WEFT_INSERT].busy and loom.axes[WEFT_INSERT].done_seq == 0
    loom.press_estop(False, now=0.7)
    loom.reset_faults()
    loom.command(WEFT_INSERT, 5_000, 2, now=0.8)
    assert loom.axes[WEFT_INSERT].busy


@pytest.mark.parametrize("kind", ["quick_stop", "home"])
def test_quick_stop_and_home(kind):
    loom = Loom(MACHINE, [(0, 0)], Speeds(stroke=10))
    loom.command(ROW0, 10_000, 1, now=0.0)
    if kind == "quick_stop":
        loom.quick_stop(now=0.2)
        assert loom.axes[ROW0].fault == FAULT_STALL and not loom.axes[ROW0].busy
    else:
        loom.tick(10.0)
        loom.home(now=10.0)
        assert (loom.axes[ROW0].done_seq, loom.axes[ROW0].position) == (0, 0)


# A 3 x 6 loom with segments of row 1 (cells 0..2) and column 4 (cells 0..1): axes 12, 13.
SEGMENTED = Machine(
    rows=3,
    cols=6,
    pitch_x=10,
    pitch_y=20,
    d_mat=100,
    c_mat=0.5,
    segments=(Segment("row", 1, 0, 2), Segment("col", 4, 0, 1)),
)
ROW1_SEGMENT, COL4_SEGMENT = 12, 13


def cells(loom: Loom) -> set[tuple[int, int]]:
    m = loom.machine
    return {(r, c) for r in range(m.rows) for c in range(m.cols) if loom.occupied[r][c]}


def test_a_segment_stroke_latches_only_the_cases_on_its_cells():
    loom = Loom(SEGMENTED, [(1, 0), (1, 1), (1, 4), (0, 4), (2, 4)], Speeds(stroke=100))
    names = [sim.axis.name for sim in loom.axes[ROW1_SEGMENT:]]
    assert names == ["row1[0..2]", "col4[0..1]", "weft_x", "weft_y", "weft_z"]
    loom.command(ROW1_SEGMENT, 10_000, 1, now=0.0)
    loom.tick(0.05)
    assert loom.axes[ROW1_SEGMENT].busy and (1, 0) in cells(loom)  # not latched mid-stroke
    loom.tick(0.25)
    sim = loom.axes[ROW1_SEGMENT]
    assert (sim.position, sim.busy, sim.done_seq, sim.last_stroke) == (0, False, 1, 10_000)
    assert cells(loom) == {(1, 1), (1, 2), (1, 4), (0, 4), (2, 4)}  # (1, 4) stayed put
    loom.command(COL4_SEGMENT, 20_000, 2, now=1.0)  # (0, 4) down to (1, 4)? occupied: a jam
    assert loom.axes[COL4_SEGMENT].fault == FAULT_JAM


@pytest.mark.parametrize(
    ("fill", "axis", "cells_"),
    [
        ([(1, 2), (1, 3)], ROW1_SEGMENT, 1),  # (1, 2) would leave the segment for the empty (1, 3)
        ([(1, 0)], ROW1_SEGMENT, -1),  # (1, 0) would leave the matrix
        ([(1, 4), (2, 4)], COL4_SEGMENT, 1),  # (1, 4) would leave it onto the case at (2, 4)
        ([(1, 4)], COL4_SEGMENT, 1),
    ],  # (1, 4) would leave it for the empty (2, 4)
)
def test_a_segment_stroke_off_its_cells_jams_and_nothing_moves(fill, axis, cells_):
    loom = Loom(SEGMENTED, fill, Speeds())
    pitch = 10_000 if axis == ROW1_SEGMENT else 20_000
    loom.command(axis, cells_ * pitch, 1, now=0.0)
    assert loom.axes[axis].fault == FAULT_JAM
    assert loom.axes[axis].done_seq == 0 and cells(loom) == set(fill)


def test_a_whole_line_stroke_carries_the_cases_of_its_segments_too():
    loom = Loom(SEGMENTED, [(1, 0), (1, 1), (1, 4)], Speeds())
    loom.command(ROW1, 10_000, 1, now=0.0)
    assert cells(loom) == {(1, 1), (1, 2), (1, 5)}


def test_new_speeds_take_a_move_on_from_where_it_is():
    loom = Loom(MACHINE, [], Speeds(takeup=10))  # 4 mm at 10 mm/s: 0.4 s
    loom.command(TAKEUP, 4_000, 1, now=0.0)
    loom.set_speeds(Speeds(takeup=100), now=0.1)  # 1 mm done, 3 mm left at 100 mm/s: 0.03 s
    assert (loom.axes[TAKEUP].position, loom.axes[TAKEUP].busy) == (1_000, True)
    loom.tick(0.12)
    assert (loom.axes[TAKEUP].position, loom.axes[TAKEUP].busy) == (3_000, True)
    loom.tick(0.131)
    assert (loom.axes[TAKEUP].position, loom.axes[TAKEUP].done_seq) == (4_000, 1)
