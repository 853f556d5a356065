"""A program with segment moves, run by the controller on the mock loom over both buses.

The machine is an 8 x 8 matrix whose row 3 and column 3 each have a separately actuated
segment on cells 0..3. The program is a 4-step braid of an L section (flange rows 1-2 x
cols 1-6, web rows 3-6 x cols 1-2, and twelve edge carriers): line 3 moves by its segments
only, so the cases of row 3 and column 3 outside cells 0..3 stay where they are.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from bwsd.controller.facade import Controller
from bwsd.controller.packml import Command, State
from bwsd.controller.plan import setpoints
from bwsd.fieldbus import open_bus
from bwsd.journal import Journal
from bwsd.program import parse_program
from bwsd.twin import Shift, simulate
from tests.controller.test_faults import after, machine_occupancy, poke
from tests.support.controller import bits, run, state_now
from tests.support.fieldbus import Mock, client_config, start_mock, wants_canopen

pytestmark = pytest.mark.slow  # every test here is in the slow tier

MACHINE = {
    "rows": 8,
    "cols": 8,
    "pitch_x": 10.0,
    "pitch_y": 10.0,
    "d_mat": 100.0,
    "c_mat": 0.5,
    "segments": ["ROW 3[0..3]", "COL 3[0..3]"],
}
CYCLE = """\
ROW 1:+1 2:-1 3[0..3]:+1 4:-1 5:+1 6:-1
COL 1:+1 2:-1 4:-1 5:+1 6:-1
ROW 1:-1 2:+1 3[0..3]:-1 4:+1 5:-1 6:+1
COL 1:-1 2:+1 4:+1 5:-1 6:+1
ROW 1:+1 2:-1 4:-1 5:+1 6:-1
COL 1:+1 2:-1 3[0..3]:+1 4:-1 5:+1 6:-1
ROW 1:-1 2:+1 4:+1 5:-1 6:+1
COL 1:-1 2:+1 3[0..3]:-1 4:+1 5:-1 6:+1
TAKEUP 2
"""
# 32 carriers: the section's 20 cells and the edge carriers at (0, 1), (0, 3), (0, 5),
# (1, 0), (2, 7), (3, 0), (3, 4), (3, 6), (4, 3), (5, 0), (6, 3), (7, 2): the cells the
# section's carriers pass through, so one cycle brings the matrix back to this FILL
FILL = """\
.X.X.X..
XXXXXXX.
.XXXXXXX
XXX.X.X.
.XXX....
XXX.....
.XXX....
..X.....
"""
TEXT = f"YARN diameter=1\nFILL row=0 col=0\n{FILL}END\nREPEAT 2\n{CYCLE}END\n"
COUNT = 18


@pytest.fixture
def segment_mock(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Mock]:
    canopen = wants_canopen(request)
    running = start_mock(tmp_path, {}, machine=MACHINE, program=TEXT, canopen=canopen)
    yield running
    running.stop()


async def segment_controller(mock: Mock, folder: Path, backend: str) -> tuple[Controller, Journal]:
    config = client_config(backend, mock.ports, machine=MACHINE)
    bus = open_bus(config)
    await bus.connect()
    journal = Journal.open(folder / "journal.db")
    return Controller(config.machine, bus, journal), journal


@pytest.mark.parametrize("backend", ["modbus", "canopen"])
def test_a_program_with_segment_moves_runs_to_complete(segment_mock, tmp_path, backend):
    async def scenario() -> None:
        ctl, journal = await segment_controller(segment_mock, tmp_path, backend)
        try:
            pid = await ctl.load("l-section.bws", TEXT)
            assert ctl.twin is not None
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await ctl.wait()
            assert ctl.packml.state is State.COMPLETE, ctl.packml.reason
            record = journal.program(pid)
            assert (record.outcome, record.done) == ("complete", COUNT)
            assert bits(ctl.twin) == bits(simulate(ctl.machine, parse_program(TEXT)))
            twin = ctl.twin.occupancy >= 0
            assert np.array_equal((await ctl.bus.state()).occupancy, twin)
            assert np.array_equal(await machine_occupancy(segment_mock), twin)
            assert np.count_nonzero(twin) == 32  # a whole cycle: the FILL again
        finally:
            await ctl.bus.close()
            journal.close()

    run(scenario())


def test_a_shift_cut_before_its_segment_moved_finishes_with_the_segment_alone(
    segment_mock, tmp_path, caplog
):
    """The bus goes silent before instruction 3 (ROW 1:-1 2:+1 3[0..3]:-1 4:+1 5:-1 6:+1);
    the whole rows move, the segment does not (as a fault between their strokes leaves
    them); Unhold moves only the segment and the program runs to Complete."""

    async def scenario() -> None:
        ctl, journal = await segment_controller(segment_mock, tmp_path, "modbus")
        try:
            pid = await ctl.load("l-section.bws", TEXT)
            assert ctl.twin is not None
            await ctl.command(Command.RESET)
            after(ctl, 2, lambda: poke(segment_mock, {"cmd": "fault", "kind": "mute"}))
            await ctl.command(Command.START)
            await ctl.wait()
            assert ctl.packml.state is State.HELD and "no answer" in ctl.packml.reason
            poke(segment_mock, {"cmd": "clear"})
            cut = parse_program(TEXT).instructions[2]
            assert isinstance(cut, Shift) and cut.text() == CYCLE.splitlines()[2]
            lines = Shift("row", tuple(m for m in cut.moves if m.span is None))
            for step in setpoints(ctl.machine, lines, ctl.twin.takeup):
                await ctl.bus.execute(step)
            await ctl.command(Command.UNHOLD)
            await ctl.wait()
            assert state_now(ctl) is State.COMPLETE, ctl.packml.reason
            assert "pending instruction 3: finish" in caplog.text
            assert (journal.program(pid).outcome, journal.program(pid).done) == ("complete", COUNT)
            assert bits(ctl.twin) == bits(simulate(ctl.machine, parse_program(TEXT)))
            assert np.array_equal(await machine_occupancy(segment_mock), ctl.twin.occupancy >= 0)
        finally:
            await ctl.bus.close()
            journal.close()

    with caplog.at_level(logging.INFO, logger="bwsd"):
        run(scenario())
