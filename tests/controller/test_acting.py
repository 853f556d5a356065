"""Abort and Stop at once, an exit from every state: against the mock loom in its own process,
with strokes slow enough to be cut half way (1 s out, 1 s back)."""

from __future__ import annotations

import asyncio
import sqlite3
from pathlib import Path
from typing import Any

import pytest

from bwsd.controller.errors import ControllerError
from bwsd.controller.packml import Command, State
from bwsd.controller.status import Fault, StopCause
from bwsd.fieldbus.base import FAULT_ESTOP, FAULT_STALL
from bwsd.journal.writer import ROUTINE
from bwsd.program import parse_program
from bwsd.twin import simulate
from simulator_hw.control import request
from tests.controller.matrix import Rig, complete, resume
from tests.support.controller import bits, run, state_now

pytestmark = pytest.mark.slow  # every test here is in the slow tier

SLOW = {"stroke_speed": 10.0, "takeup_speed": 10.0}  # a 10 mm stroke: 1 s out, 1 s back
SHIFTS = "ROW 1:+1 2:-1\nCOL 1:+1 2:-1\nROW 1:-1 2:+1\nCOL 1:-1 2:+1\n"
TEXT = f"YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\n{SHIFTS}"
FILL = [[0, 0, 0, 0], [0, 1, 1, 0], [0, 1, 1, 0], [0, 0, 0, 0]]


def slow(tmp: Path) -> Rig:
    return Rig(tmp, SLOW)


async def loom(rig: Rig) -> dict[str, Any]:
    answer: dict[str, Any] = await request("127.0.0.1", rig.mock.ports["control"], {"cmd": "state"})
    return answer


async def half_way(rig: Rig) -> None:
    """Until row1's first stroke is under way (well before its far end)."""
    while not (await loom(rig))["axes"]["row1"]["busy"]:
        await asyncio.sleep(0.01)
    await asyncio.sleep(0.3)


@pytest.mark.slow
@pytest.mark.parametrize("command", [Command.ABORT, Command.STOP])
def test_abort_and_stop_cut_the_stroke_at_once_and_the_part_resumes(tmp_path, command):
    async def scenario() -> None:
        rig = slow(tmp_path)
        ctl = await rig.start()
        try:
            await ctl.load("shifts.bws", TEXT)
            assert ctl.twin is not None
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await half_way(rig)
            await ctl.command(command, "by the test")
            assert ctl.packml.state is (
                State.ABORTED if command is Command.ABORT else State.STOPPED
            )
            row1 = (await loom(rig))["axes"]["row1"]
            # cut on its way out: stopped where it was, the cases not carried yet
            assert row1["fault"] == FAULT_STALL and 0 < row1["position"] < 10_000, row1
            assert (await loom(rig))["occupancy"] == FILL
            await ctl.wait()
            assert "instruction 1 started, the machine has not moved" in ctl.packml.reason
            assert ctl.resumable() and ctl.twin.done == 0
            await resume(ctl)
            await ctl.wait()
            assert complete(ctl)
            assert bits(ctl.twin) == bits(simulate(ctl.machine, parse_program(TEXT)))
            record = rig.journal.program(1)
            assert (record.outcome, record.done) == ("complete", 4)
        finally:
            await rig.close()

    run(scenario())


def test_an_abort_is_not_queued_behind_a_hold_that_waits_for_its_stroke(tmp_path):
    async def scenario() -> None:
        rig = slow(tmp_path)
        ctl = await rig.start()
        try:
            await ctl.load("shifts.bws", TEXT)
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await half_way(rig)
            holding = asyncio.ensure_future(ctl.command(Command.HOLD, "operator"))
            await asyncio.sleep(0.05)
            assert ctl.packml.state is State.HOLDING and not holding.done()
            await ctl.command(Command.ABORT, "by the PLC", "plc")  # the Hold holds the lock
            assert state_now(ctl) is State.ABORTED
            row1 = (await loom(rig))["axes"]["row1"]
            assert row1["fault"] == FAULT_STALL and 0 < row1["position"] < 10_000, row1
            await holding  # the Hold ends too, where the Abort led
            assert state_now(ctl) is State.ABORTED
        finally:
            await rig.close()

    run(scenario())


def test_abort_reaches_aborted_while_another_process_holds_the_journal(tmp_path):
    async def scenario() -> None:
        rig = Rig(tmp_path)
        ctl = await rig.start()
        try:
            await ctl.load("braid.bws", TEXT)
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await rig.done(1)
            other = sqlite3.connect(rig.journal.path, isolation_level=None)
            other.execute("BEGIN IMMEDIATE")
            while not any("has not finished writing" in f for f in rig.faults_since(0)):
                await asyncio.sleep(0.02)  # the stall is seen (and published) first
            await ctl.command(Command.ABORT)
            assert ctl.packml.state is State.ABORTED
            assert other.in_transaction  # the journal is still locked: nothing waited for it
            other.execute("ROLLBACK")
            other.close()
            await ctl.wait()
            await ctl.command(Command.CLEAR)  # the outcome is written before it, at the latest
            assert rig.journal.program(1).outcome == "aborted"
            # the state history is written behind the commands, in order: wait for the queue
            await ctl.recorder.writer.queue(ROUTINE, lambda: None)
            names = [s.name for s in rig.journal.states()]
            assert "Aborting" in names and "Aborted" in names  # the history misses nothing
        finally:
            await rig.close()

    run(scenario())


@pytest.mark.slow
def test_clear_is_refused_while_the_estop_is_pressed_and_no_drive_is_reset(tmp_path):
    async def scenario() -> None:
        rig = slow(tmp_path)
        ctl = await rig.start()
        try:
            await ctl.load("shifts.bws", TEXT)
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await half_way(rig)
            await rig.control({"cmd": "estop", "pressed": True})
            await ctl.wait()
            assert ctl.packml.state is State.ABORTED and ctl.stop_cause is StopCause.ESTOP
            with pytest.raises(ControllerError, match="emergency stop is pressed"):
                await ctl.command(Command.CLEAR)
            assert ctl.packml.state is State.ABORTED and Command.CLEAR not in ctl.allowed()
            assert (await loom(rig))["axes"]["row1"]["fault"] == FAULT_ESTOP  # not reset
            await rig.control({"cmd": "estop", "pressed": False})
            await resume(ctl)
            assert complete(ctl)
            faults = [e for _, e in rig.events if isinstance(e, Fault)]
            assert any(f.cause is StopCause.ESTOP for f in faults)
        finally:
            await rig.close()

    run(scenario())
