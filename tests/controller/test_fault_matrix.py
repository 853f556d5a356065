"""Each fault in each of Idle, Execute, Held and Stopped (tests/controller/matrix.py): the
controller publishes a Fault, logs it, rests in a state with an exit, and the same program
resumes to Complete with the skeleton of an uninterrupted run."""

from __future__ import annotations

import asyncio

import pytest

from bwsd.controller.packml import State
from tests.controller.matrix import FAULTS, STATES, run_cell


@pytest.mark.parametrize("state", STATES, ids=lambda s: s.label)
@pytest.mark.parametrize("fault", FAULTS)
def test_every_fault_in_every_state_ends_with_an_exit_and_resumes(tmp_path, fault, state):
    cell = asyncio.run(asyncio.wait_for(run_cell(tmp_path, fault, state), 180))
    assert cell.faults, "a Fault event"
    assert cell.logged, "a warning or an error in the log"
    assert cell.allowed, f"{cell.ended}: no command accepted"
    assert State.ABORTING not in (cell.ended,) and cell.ended is not None
    assert cell.completed and cell.same_skeleton
