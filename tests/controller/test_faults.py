"""Faults in production: every fault hold resumes, nothing moves unchecked, nothing dies silently.

The controller runs the mock loom in its own process over Modbus TCP, with a real journal
file. A fault is injected from the controller's own "instruction done" event, so it lands
exactly between two instructions.
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bwsd.controller.errors import ControllerError
from bwsd.controller.facade import Controller
from bwsd.controller.packml import Command, State
from bwsd.controller.status import Event, Fault, InstructionDone, StopCause
from bwsd.errors import BwsdError
from bwsd.fieldbus.base import BoolGrid
from bwsd.journal.writer import ROUTINE
from bwsd.program import parse_program
from bwsd.twin import simulate
from simulator_hw.control import request
from tests.support.controller import TEXT, bits, controller, run, state_now
from tests.support.fieldbus import Mock, start_mock

pytestmark = pytest.mark.slow  # every test here is in the slow tier

FILL = [[0, 0, 0, 0], [0, 1, 1, 0], [0, 1, 1, 0], [0, 0, 0, 0]]


def poke(mock: Mock, message: dict[str, Any]) -> dict[str, Any]:
    """One control request, synchronously (from inside an event subscriber)."""
    return mock.control(message)


def after(ctl: Controller, index: int, action: Any) -> None:
    """Run ``action()`` once, right after instruction ``index`` is done."""
    fired: list[bool] = []

    def hook(event: Event) -> None:
        if isinstance(event, InstructionDone) and event.index == index and not fired:
            fired.append(True)
            action()

    ctl.events.subscribe(hook)


async def machine_occupancy(mock: Mock) -> BoolGrid:
    answer = await request("127.0.0.1", mock.ports["control"], {"cmd": "state"})
    return np.array(answer["occupancy"], dtype=bool)


FAULTS: dict[str, tuple[dict[str, Any], str]] = {
    # the bus stops answering before instruction 2: it times out, nothing moved
    "mute": ({"cmd": "fault", "kind": "mute"}, "no answer"),
    # every connection drops once: the next request fails, the move did not start
    "drop": ({"cmd": "fault", "kind": "drop"}, ""),
    # a sensor reads wrong: instruction 2 moved, its read-back differs from the prediction
    "mismatch": ({"cmd": "fault", "kind": "sensor", "cell": [0, 0]}, "occupancy differs"),
}


@pytest.mark.parametrize("kind", [*FAULTS, "restarted loom"])
def test_every_fault_hold_resumes_to_complete_with_the_predicted_skeleton(mock, tmp_path, kind):
    async def scenario() -> None:
        ctl, journal, events = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        await ctl.command(Command.RESET)
        loom = [mock]
        if kind == "restarted loom":
            # killed after instruction 4 (the shifts of a cycle are back at the FILL), so the
            # restarted loom (its FILL, take-up at 0) shows the state before instruction 5
            after(ctl, 4, mock.stop)
        else:
            after(ctl, 1, lambda: poke(mock, FAULTS[kind][0]))
        await ctl.command(Command.START)
        await ctl.wait()
        assert ctl.packml.state is State.HELD, ctl.packml.reason
        assert FAULTS.get(kind, (None, ""))[1] in ctl.packml.reason
        assert journal.program(pid).outcome == "held"
        assert [e for e in events if e["event"] == "fault"], "the hold was published"
        if kind == "restarted loom":
            loom[0] = start_mock(Path(tmp_path), {}, mock.ports)
        else:
            poke(mock, {"cmd": "clear"})
        try:
            await ctl.command(Command.UNHOLD)
            await ctl.wait()
            assert state_now(ctl) is State.COMPLETE, ctl.packml.reason
            whole = simulate(ctl.machine, parse_program(TEXT))
            assert bits(ctl.twin) == bits(whole)
            record = journal.program(pid)
            assert (record.outcome, record.done) == ("complete", 15)
            assert np.array_equal(await machine_occupancy(loom[0]), ctl.twin.occupancy >= 0)
            assert ctl.status().bus.last_error is None and ctl.packml.reason == ""
        finally:
            await ctl.close()
            if loom[0] is not mock:
                loom[0].stop()

    run(scenario())


def test_a_hold_whose_fault_persists_stays_held_with_the_reason(mock, tmp_path):
    async def scenario() -> None:
        ctl, _, _ = await controller(mock, tmp_path)
        await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        await ctl.command(Command.RESET)
        after(ctl, 1, lambda: poke(mock, FAULTS["mismatch"][0]))
        await ctl.command(Command.START)
        await ctl.wait()
        assert ctl.packml.state is State.HELD
        # the sensor still reads wrong: the pending instruction is neither done nor undone
        with pytest.raises(
            ControllerError,
            match=r"cannot resume: instruction 2 started and "
            r"not done: .*occupancy differs",
        ):
            await ctl.command(Command.UNHOLD)
        assert ctl.packml.state is State.HELD and ctl.twin.done == 1
        assert "unhold" not in [c.name.lower() for c in ctl.status().allowed]
        poke(mock, {"cmd": "clear"})
        await ctl.command(Command.UNHOLD)
        await ctl.wait()
        assert state_now(ctl) is State.COMPLETE
        await ctl.close()

    run(scenario())


def test_a_journal_locked_mid_run_holds_the_part_and_unhold_finishes_it(mock, tmp_path, caplog):
    """Mid-run, another program takes the journal's write lock and keeps it (as an sqlite3
    shell left in a transaction would): the stall is published within a second, the run
    holds (nothing is lost, so nothing is aborted), and once the lock is gone Unhold runs the
    same program to Complete with the predicted skeleton."""

    async def scenario() -> None:
        ctl, journal, _events = await controller(mock, tmp_path)
        await ctl.start()
        pid = await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        await ctl.command(Command.RESET)
        other = sqlite3.connect(journal.path, isolation_level=None, check_same_thread=False)
        locked: list[float] = []

        def lock() -> None:
            other.execute("BEGIN IMMEDIATE")
            locked.append(time.monotonic())

        after(ctl, 3, lock)
        faults: list[tuple[float, Fault]] = []
        ctl.events.subscribe(
            lambda e: faults.append((time.monotonic(), e)) if isinstance(e, Fault) else None
        )
        await ctl.command(Command.START)
        await ctl.wait()
        assert ctl.packml.state is State.HELD, ctl.packml.reason
        assert "locked" in ctl.packml.reason and "then Unhold" in ctl.packml.reason
        assert ctl.stop_cause is StopCause.JOURNAL
        stall = [
            t for t, f in faults if f.cause is StopCause.JOURNAL and "not finished" in f.reason
        ]
        assert stall and stall[0] - locked[0] < 1.0, faults  # seen before the write gave up
        assert "the journal has not finished writing" in caplog.text
        assert ctl.twin.done == 3  # instruction 4 never started: its "started" met the lock
        other.execute("ROLLBACK")
        other.close()
        deadline = time.monotonic() + 2
        while "journal" in ctl.health():  # the stall ends with the lock
            assert time.monotonic() < deadline, ctl.health()
            await asyncio.sleep(0.05)
        await ctl.command(Command.UNHOLD)
        await ctl.wait()
        assert state_now(ctl) is State.COMPLETE, ctl.packml.reason
        assert bits(ctl.twin) == bits(simulate(ctl.machine, parse_program(TEXT)))
        # the state history is written behind the run, in order: wait for what is queued
        await ctl.recorder.writer.queue(ROUTINE, lambda: None)
        record = journal.program(pid)
        assert (record.outcome, record.done) == ("complete", 15) and journal.pending(pid) is None
        names = [state.name for state in journal.states()]
        assert names[-4:] == ["Unholding", "Execute", "Completing", "Complete"]
        assert "Holding" in names and "Held" in names  # every state is in the history
        await ctl.close()

    with caplog.at_level(logging.INFO, logger="bwsd"):
        run(scenario())


def test_nothing_moves_on_a_matrix_whose_cases_are_not_where_the_fill_puts_them(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        shifted = TEXT.replace("FILL row=1 col=0\n.XX.\n.XX.", "FILL row=0 col=0\nXX..\nXX..")
        pid = await ctl.load("shifted.bws", shifted)
        await ctl.command(Command.RESET)
        with pytest.raises(
            ControllerError,
            match=r"occupancy sensors differ from the twin at "
            r"\(0, 0\), \(0, 1\)",
        ):
            await ctl.command(Command.START)
        assert ctl.packml.state is State.IDLE
        assert journal.program(pid).outcome == "loaded"  # the program is not consumed
        answer = await request("127.0.0.1", mock.ports["control"], {"cmd": "state"})
        assert answer["occupancy"] == FILL
        assert all(axis["position"] == 0 for axis in answer["axes"].values())  # nothing moved
        assert "start" not in [c.name.lower() for c in ctl.status().allowed]
        await ctl.close()

    run(scenario())


def test_with_the_estop_pressed_reset_and_start_are_refused_and_nothing_is_consumed(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        control = ("127.0.0.1", mock.ports["control"])
        await request(*control, {"cmd": "estop", "pressed": True})
        with pytest.raises(ControllerError, match="emergency stop is pressed"):
            await ctl.command(Command.RESET)
        assert ctl.packml.state is State.STOPPED and ctl.status().bus.estop is True
        assert [c.name for c in ctl.status().allowed] == ["ABORT"]
        await request(*control, {"cmd": "estop", "pressed": False})
        await ctl.command(Command.RESET)
        await request(*control, {"cmd": "estop", "pressed": True})
        with pytest.raises(ControllerError, match="emergency stop is pressed"):
            await ctl.command(Command.START)
        assert state_now(ctl) is State.IDLE
        assert journal.program(pid).outcome == "loaded" and ctl.twin.done == 0
        await request(*control, {"cmd": "estop", "pressed": False})
        await ctl.command(Command.START)
        await ctl.wait()
        assert state_now(ctl) is State.COMPLETE
        await ctl.close()

    run(scenario())


def test_suspend_is_journaled_suspended_with_its_reason(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        await ctl.command(Command.RESET)
        await ctl.command(Command.START)
        while ctl.twin.done < 2:
            await asyncio.sleep(0.001)
        await ctl.command(Command.SUSPEND, "waiting for yarn")
        assert ctl.packml.state is State.SUSPENDED
        assert ctl.packml.reason == "waiting for yarn"
        record = journal.program(pid)
        assert (record.outcome, record.reason) == ("suspended", "waiting for yarn")
        assert Command.UNSUSPEND in ctl.status().allowed  # the machine shows the twin
        await ctl.command(Command.UNSUSPEND)
        await ctl.wait()
        assert state_now(ctl) is State.COMPLETE
        await ctl.close()

    run(scenario())


@pytest.mark.slow
def test_allowed_lists_exactly_the_commands_that_are_accepted(mock, tmp_path):
    """In every state a run goes through, each command is tried on a fresh controller in
    that state: those ``allowed`` lists are accepted, the others refused."""

    async def reach(path: list[Command], folder: Path) -> Controller:
        ctl, _, _ = await controller(mock, folder)
        await ctl.load("braid.bws", TEXT.replace("REPEAT 3", "REPEAT 1"))
        for command in path:
            await ctl.command(command)
            await ctl.wait()
        return ctl

    paths = [
        [],
        [Command.RESET],
        [Command.RESET, Command.START],
        [Command.RESET, Command.STOP],
        [Command.ABORT],
        [Command.RESET, Command.START, Command.RESET],
        [Command.ABORT, Command.CLEAR],
    ]

    async def scenario() -> None:
        for n, path in enumerate(paths):
            probe = await reach(path, tmp_path / f"p{n}")
            allowed = set(probe.status().allowed)
            await probe.close()
            for k, command in enumerate(Command):
                ctl = await reach(path, tmp_path / f"p{n}-{k}")
                try:
                    await ctl.command(command)
                    await ctl.wait()
                    accepted = True
                except BwsdError:  # the controller's refusal, or PackML's
                    accepted = False
                assert accepted is (command in allowed), (path, command, allowed)
                await ctl.close()
                poke(mock, {"cmd": "clear"})

    run(scenario())
