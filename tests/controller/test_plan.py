"""From predictions to set-points, limits, and the read-back verdict."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bwsd.controller.plan import (
    Limits,
    Mismatch,
    RefusedMove,
    check_limits,
    misplaced,
    placing,
    setpoints,
    verify,
)
from bwsd.fieldbus.base import AxisMove, AxisState, MachineState
from bwsd.twin import Machine, Prediction, Shift, TakeUp, Twin, Weft

MACHINE = Machine(rows=2, cols=2, pitch_x=10, pitch_y=12.5, d_mat=100, c_mat=0.5)
FILL = [(0, 0), (1, 1)]
ROW = [Shift("row", ((0, 1), (1, -1))), Shift("col", ((1, 1), (0, -1)))]


def state(occupancy, takeup_um: int = 0) -> MachineState:
    axes = tuple(AxisState(0, False, 0, 0, 0) for _ in range(7))
    return MachineState(axes=axes, occupancy=np.array(occupancy, dtype=bool), estop=False)


def test_setpoints_of_each_kind():
    # axes: row0 row1 col0 col1 weft_angle weft_insert takeup weft_x weft_y weft_z
    assert setpoints(MACHINE, Shift("row", ((0, 1), (1, -1))), 0.0) == [
        [AxisMove(0, 10_000), AxisMove(1, -10_000)]
    ]
    assert setpoints(MACHINE, Shift("col", ((1, 2),)), 0.0) == [[AxisMove(3, 25_000)]]
    assert setpoints(MACHINE, TakeUp(2.5), 4.0) == [[AxisMove(6, 6_500)]]
    # a weft: placed (weft_x 7, weft_y 8, weft_z 9 and the angle together), then inserted
    assert setpoints(MACHINE, Weft(5, 2.5, 30, 90, 80), 0.0) == [
        [AxisMove(7, 5_000), AxisMove(8, 2_500), AxisMove(9, 30_000), AxisMove(4, 90_000)],
        [AxisMove(5, 80_000)],
    ]


def test_a_weft_is_placed_only_on_the_axes_the_machine_has():
    only_z = dataclasses.replace(MACHINE, weft_axes=("z",))  # weft_z is axis 7
    assert setpoints(only_z, Weft(5, 6.25, 30, -45, 80), 1.0) == [
        [AxisMove(7, 30_000), AxisMove(4, -45_000)],
        [AxisMove(5, 80_000)],
    ]
    none = dataclasses.replace(MACHINE, weft_axes=())
    assert placing(none, Weft(5, 6.25, 30, 0, 80)) == [AxisMove(4, 0)]


def test_misplaced_names_each_placing_axis_off_the_weft():
    weft = Weft(5, 2.5, 30, 90, 80)
    at = {7: 5_000, 8: 2_500, 9: 30_000, 4: 90_000}
    axes = [AxisState(at.get(i, 0), False, 0, 0, 0) for i in range(10)]
    placed = MachineState(tuple(axes), np.zeros((2, 2), dtype=bool), False)
    assert misplaced(MACHINE, weft, placed, 10) == ""
    axes[9] = AxisState(30_011, False, 0, 0, 0)  # z off by 11 um, beyond the tolerance
    axes[4] = AxisState(90_010, False, 0, 0, 0)  # the angle within it
    off = MachineState(tuple(axes), placed.occupancy, False)
    assert misplaced(MACHINE, weft, off, 10) == "weft_z at 30011, the weft's 30000"


def _busy_prediction() -> Prediction:
    """A prediction of the shipped 8-carrier braid that makes at least two contacts."""
    from pathlib import Path

    from bwsd.config import load_config
    from bwsd.program import load_program

    root = Path(__file__).resolve().parents[2]
    machine = load_config(root / "config/braid-2x2.toml").machine
    program = load_program(root / "examples/braid-2x2.bws", machine)
    twin = Twin.from_program(machine, program)
    for ins in program.instructions:
        pred = twin.predict(ins)
        if len(pred.contacts) >= 2:
            return pred
        twin.commit(pred)
    raise AssertionError("no instruction with two contacts")


def test_limits_refuse_with_the_reason():
    pred = _busy_prediction()
    n = len(pred.contacts)
    check_limits(pred, Limits())  # 0 disables every limit
    check_limits(pred, Limits(max_contacts=n))
    with pytest.raises(RefusedMove, match=f"{n} contacts, more than the limit of {n - 1}"):
        check_limits(pred, Limits(max_contacts=n - 1))
    biggest = max(abs(v) for v in pred.length_change.values())
    check_limits(pred, Limits(tensioner_stroke=biggest + 0.01))
    with pytest.raises(RefusedMove, match="beyond the tensioner's stroke"):
        check_limits(pred, Limits(tensioner_stroke=biggest / 2))


def test_verify_compares_occupancy_and_takeup():
    twin = Twin(MACHINE, FILL, 1.0)
    pred = twin.predict(ROW[0])
    grid = (pred.occupancy >= 0).tolist()
    verify(pred, state(grid), takeup_um=0, tolerance=10)
    with pytest.raises(Mismatch, match=r"occupancy differs from the prediction at \(0, 0\)"):
        verify(pred, state([[True, True], [False, False]]), takeup_um=0, tolerance=10)
    with pytest.raises(Mismatch, match="take-up at 50 um, predicted 0 um"):
        verify(pred, state(grid), takeup_um=50, tolerance=10)
