"""Each fault in each of Idle, Execute, Held and Stopped (tests/controller/matrix.py): the
controller publishes a Fault, logs it, rests in a state with an exit, and the same program
resumes to Complete with the skeleton of an uninterrupted run."""

from __future__ import annotations

import asyncio
import random
from pathlib import Path

import pytest

from bwsd.controller.packml import Command, State
from bwsd.program import parse_program
from bwsd.twin import simulate
from tests.controller.matrix import FAULTS, STATES, TEXT, Rig, complete, resume, run_cell
from tests.support.controller import bits

pytestmark = pytest.mark.slow  # every test here is in the slow tier


@pytest.mark.parametrize("state", STATES, ids=lambda s: s.label)
@pytest.mark.parametrize("fault", FAULTS)
def test_every_fault_in_every_state_ends_with_an_exit_and_resumes(tmp_path, fault, state):
    cell = asyncio.run(asyncio.wait_for(run_cell(tmp_path, fault, state), 180))
    assert cell.faults, "a Fault event"
    assert cell.logged, "a warning or an error in the log"
    assert cell.allowed, f"{cell.ended}: no command accepted"
    assert State.ABORTING not in (cell.ended,) and cell.ended is not None
    assert cell.completed and cell.same_skeleton


CUTS = 20


@pytest.mark.slow
def test_a_run_cut_by_stop_or_abort_anywhere_resumes_to_the_same_skeleton(tmp_path):
    """Stop or Abort at random moments, mid-stroke or between strokes; Reset (Clear), then
    Start with resume: the program finishes with the skeleton of an uninterrupted run, and
    the journal holds every instruction exactly once."""
    rng = random.Random(23)

    async def once(folder: Path, command: Command, delay: float) -> None:
        rig = Rig(folder)
        ctl = await rig.start()
        try:
            await ctl.load("braid.bws", TEXT)
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await asyncio.sleep(delay)
            await ctl.command(command)
            assert ctl.packml.state in (State.STOPPED, State.ABORTED)
            await ctl.wait()
            await resume(ctl)
            await ctl.wait()
            assert complete(ctl), (command, delay, ctl.packml.state, ctl.packml.reason)
            whole = simulate(ctl.machine, parse_program(TEXT))
            assert bits(ctl.twin) == bits(whole), (command, delay)
            record = rig.journal.program(ctl.program_id or 0)
            assert (record.outcome, record.done) == ("complete", 15)
            indexes = [i.index for i in rig.journal.instructions(record.id)]
            assert indexes == list(range(1, 16)), (command, delay)
        finally:
            await rig.close()

    for n in range(CUTS):
        command = rng.choice([Command.STOP, Command.ABORT])
        folder = tmp_path / str(n)
        folder.mkdir()
        asyncio.run(asyncio.wait_for(once(folder, command, rng.uniform(0.02, 1.0)), 120))
