"""Between runs: a restart restores what was loaded, a recovery that cannot complete leaves an
exit, and the reads at rest outlive a journal that cannot write."""

from __future__ import annotations

import asyncio
import logging
import sqlite3

import pytest

from bwsd.config import parse_config
from bwsd.controller.errors import ControllerError
from bwsd.controller.facade import Controller, Settings
from bwsd.controller.packml import Command, State
from bwsd.controller.status import StopCause
from bwsd.journal import Journal
from tests.controller.matrix import TEXT, Rig, _refuse_writes
from tests.support.controller import controller, run, state_now
from tests.support.fieldbus import MACHINE

pytestmark = pytest.mark.slow  # every test here is in the slow tier


def test_a_restart_restores_a_loaded_program_with_its_cause(mock, tmp_path):
    async def scenario() -> None:
        first, journal, _ = await controller(mock, tmp_path)
        pid = await first.load("braid.bws", TEXT)
        await first.command(Command.RESET)
        assert first.packml.state is State.IDLE
        await first.close()  # the journal with it
        journal = Journal.open(journal.path)
        second = Controller(first.machine, first.bus, journal)
        said = await second.recover()
        assert second.packml.state is State.STOPPED and second.program_id == pid
        loaded = "is loaded (0 of 15 instructions done): Reset, then Start"
        assert said == f"restarted: program {pid} 'braid.bws' {loaded}"
        status = second.status()
        assert (status.program_name, status.count, status.stop_cause) == (
            "braid.bws",
            15,
            StopCause.RESTART,
        )
        await second.command(Command.RESET)
        await second.command(Command.START)
        await second.wait()
        assert state_now(second) is State.COMPLETE
        await second.close()
        await first.bus.close()
        journal.close()

    run(scenario())


def test_a_restart_after_an_abort_restores_it_resumable(mock, tmp_path):
    async def scenario() -> None:
        first, journal, _ = await controller(mock, tmp_path)
        await first.load("braid.bws", TEXT)
        assert first.twin is not None
        await first.command(Command.RESET)
        await first.command(Command.START)
        while first.twin.done < 3:
            await asyncio.sleep(0.001)
        await first.command(Command.ABORT, "jam cleared by hand")
        await first.wait()
        done = first.twin.done
        await first.close()
        journal = Journal.open(journal.path)
        second = Controller(first.machine, first.bus, journal)
        said = await second.recover()
        assert second.twin is not None
        assert second.packml.state is State.ABORTED and second.twin.done == done
        assert "was aborted (jam cleared by hand)" in said and "Start with resume" in said
        assert second.resumable()
        for command in (Command.CLEAR, Command.RESET):
            await second.command(command)
        await second.command(Command.START, resume=True)
        await second.wait()
        assert state_now(second) is State.COMPLETE and journal.program(1).done == 15
        await second.close()
        await first.bus.close()
        journal.close()

    run(scenario())


SMALL = {**MACHINE, "rows": 3, "cols": 3}


@pytest.mark.parametrize("damage", ["a smaller matrix", "a damaged program text"])
def test_a_recovery_that_cannot_complete_holds_with_the_fix_and_abort_ends_it(
    mock, tmp_path, damage
):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        await ctl.command(Command.RESET)
        await ctl.command(Command.START)
        while ctl.twin.done < 3:
            await asyncio.sleep(0.001)
        await ctl.command(Command.HOLD)
        held = ctl.twin.done
        await ctl.close()
        journal = Journal.open(journal.path)
        machine = ctl.machine
        if damage == "a smaller matrix":
            machine = parse_config({"machine": SMALL}).machine
            fix = "start the daemon with the config it ran with"
        else:
            other = sqlite3.connect(journal.path, isolation_level=None)
            other.execute("DROP TRIGGER programs_fixed")  # as a program that damages it would
            other.execute("UPDATE programs SET sha256 = ? WHERE id = ?", ("0" * 64, pid))
            other.close()
            fix = "restore the journal from a backup and restart"
        again = Controller(machine, ctl.bus, journal, settings=Settings(poll_interval=0.05))
        await again.start()
        said = await again.recover()
        assert again.packml.state is State.HELD and "recovery failed" in said and fix in said
        assert "Abort" in said and again.allowed() == [Command.STOP, Command.ABORT]
        assert "recovery" in again.health()  # /healthz is red
        await asyncio.sleep(0.2)
        assert again.seen.status.estop is False  # the machine is read all the same
        with pytest.raises(ControllerError, match="recovery failed"):
            await again.command(Command.UNHOLD)
        await again.command(Command.ABORT)
        assert state_now(again) is State.ABORTED and again.health() == {}
        record = journal.program(pid)
        assert (record.outcome, record.done) == ("aborted", held)  # its journal is kept
        assert [i.index for i in journal.instructions(pid)] == list(range(1, held + 1))
        await again.command(Command.CLEAR)
        assert state_now(again) is State.STOPPED
        await again.close()
        await ctl.bus.close()
        journal.close()

    run(scenario())


def test_the_reads_at_rest_outlive_a_journal_that_cannot_write_and_see_the_estop(tmp_path, caplog):
    """Held by a read-back that differs (a sensor); the journal refuses writes (its disk is
    full); the sensor reads true again: the pending instruction, which the machine shows
    done, cannot be journaled done, which is said; the reads go on and see the e-stop."""

    async def scenario() -> None:
        rig = Rig(tmp_path)
        ctl = await rig.start()
        try:
            await ctl.load("braid.bws", TEXT)
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await rig.done(1)
            await rig.control({"cmd": "fault", "kind": "sensor", "cell": [0, 0]})
            await ctl.wait()
            assert ctl.packml.state is State.HELD
            _refuse_writes(rig.journal, True)
            await rig.control({"cmd": "clear"})
            while "journal cannot record" not in ctl.packml.reason:
                await asyncio.sleep(0.02)
            assert ctl.health().get("task watch") is None and ctl.supervisor.running("watch")
            await rig.control({"cmd": "estop", "pressed": True})
            while not ctl.seen.status.estop:
                await asyncio.sleep(0.02)
            assert ctl.status().bus.estop is True
            await rig.control({"cmd": "estop", "pressed": False})
            _refuse_writes(rig.journal, False)
            await ctl.command(Command.UNHOLD)
            await ctl.wait()
            assert state_now(ctl) is State.COMPLETE
            assert rig.journal.program(1).done == 15
        finally:
            await rig.close()

    with caplog.at_level(logging.INFO, logger="bwsd"):
        run(scenario())


def test_a_blocked_instruction_is_logged_when_the_decision_changes_not_at_every_read(
    tmp_path, caplog
):
    async def scenario() -> None:
        rig = Rig(tmp_path)
        ctl = await rig.start()  # reads at rest every 0.1 s
        try:
            await ctl.load("braid.bws", TEXT)
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await rig.done(1)
            await rig.control({"cmd": "fault", "kind": "sensor", "cell": [0, 0]})
            await ctl.wait()
            assert ctl.packml.state is State.HELD
            await asyncio.sleep(1.5)  # about fifteen reads, each one deciding "blocked"
            assert "Abort ends the program" in ctl.packml.reason
        finally:
            await rig.close()

    with caplog.at_level(logging.INFO, logger="bwsd.controller"):
        run(scenario())
    lines = [
        r.getMessage() for r in caplog.records if r.getMessage().startswith("pending instruction")
    ]
    assert len(lines) == 1, lines
