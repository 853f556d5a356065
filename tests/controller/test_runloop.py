"""The run loop against the mock loom in its own process, with a real journal file."""

from __future__ import annotations

import asyncio
import logging
import threading

import numpy as np
import pytest

from bwsd.controller.errors import Busy, Cancelled, ControllerError
from bwsd.controller.facade import Controller, Settings
from bwsd.controller.packml import Command, State
from bwsd.controller.plan import Limits
from bwsd.controller.recovery import lines_left
from bwsd.controller.status import Event, InstructionDone
from bwsd.errors import ProgramError
from bwsd.fieldbus import AxisMove
from bwsd.program import parse_program
from bwsd.twin import replay, simulate
from simulator_hw.control import request
from tests.support.controller import TEXT, bits, controller, run, state_now
from tests.support.fieldbus import client_config

pytestmark = pytest.mark.slow  # every test here is in the slow tier


def test_a_program_runs_to_complete_and_matches_simulate(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, events = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        await ctl.command(Command.RESET)
        assert ctl.packml.state is State.IDLE
        await ctl.command(Command.START)
        await ctl.wait()
        assert state_now(ctl) is State.COMPLETE
        program = parse_program(TEXT)
        assert bits(ctl.twin) == bits(
            simulate(client_config("modbus", mock.ports).machine, program)
        )
        record = journal.program(pid)
        assert (record.outcome, record.done, record.instructions) == ("complete", 15, 15)
        assert [e["index"] for e in events if e["event"] == "instruction"] == list(range(1, 16))
        state = await ctl.bus.state()
        assert np.array_equal(state.occupancy, ctl.twin.occupancy >= 0)
        await ctl.bus.close()
        journal.close()

    run(scenario())


def test_a_limit_refuses_the_program_at_load_and_a_move_at_run(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path, limits=Limits(tensioner_stroke=0.001))
        with pytest.raises(ControllerError, match=r"instruction 1: .* beyond the tensioner"):
            await ctl.load("braid.bws", TEXT)  # the limits are checked by the dry run
        assert ctl.program is None and journal.history() == []
        ctl.limits = Limits()
        pid = await ctl.load("braid.bws", TEXT)
        ctl.limits = Limits(tensioner_stroke=0.001)  # and again before every move
        await ctl.command(Command.RESET)
        await ctl.command(Command.START)
        await ctl.wait()
        assert ctl.packml.state is State.ABORTED
        assert "beyond the tensioner's stroke" in ctl.packml.reason
        record = journal.program(pid)  # journaled as begun (with the prediction), never moved:
        assert (record.done, record.outcome) == (0, "aborted")  # the program ended there
        answer = await request("127.0.0.1", mock.ports["control"], {"cmd": "state"})
        assert answer["occupancy"] == [[0, 0, 0, 0], [0, 1, 1, 0], [0, 1, 1, 0], [0, 0, 0, 0]]
        await ctl.bus.close()
        journal.close()

    run(scenario())


def test_a_drive_fault_aborts_without_committing(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        await ctl.command(Command.RESET)
        await request(
            "127.0.0.1", mock.ports["control"], {"cmd": "fault", "kind": "drive", "axis": "col2"}
        )
        await ctl.command(Command.START)
        await ctl.wait()
        assert ctl.packml.state is State.ABORTED
        assert "instruction 2: axis col2: drive fault" in ctl.packml.reason
        assert ctl.twin.done == 1  # the faulted instruction was not committed
        await request("127.0.0.1", mock.ports["control"], {"cmd": "clear"})
        await ctl.bus.close()
        journal.close()

    run(scenario())


def test_restart_resumes_to_the_same_skeleton(mock, tmp_path):
    async def scenario() -> None:
        first, journal, _ = await controller(mock, tmp_path)
        await first.load("braid.bws", TEXT)
        assert first.twin is not None
        await first.command(Command.RESET)
        await first.command(Command.START)
        while first.twin.done < 7:
            await asyncio.sleep(0)
        await first.command(Command.HOLD, "operator")
        assert Command.UNHOLD in first.status().allowed  # compared with the last read-back
        done = first.twin.done
        await first.bus.close()
        journal.close()
        second, journal, _ = await controller(mock, tmp_path)
        said = await second.recover()
        assert second.twin is not None
        assert "resume with Unhold" in said and second.packml.state is State.HELD
        assert second.twin.done == done
        await second.command(Command.UNHOLD)
        await second.wait()
        assert state_now(second) is State.COMPLETE
        whole = simulate(client_config("modbus", mock.ports).machine, parse_program(TEXT))
        assert bits(second.twin) == bits(whole)
        assert journal.program(1).done == 15
        await second.bus.close()
        journal.close()

    run(scenario())


def test_restart_settles_a_pending_instruction_from_the_read_back(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        # the daemon journaled "started" for instruction 1 and died before the move
        journal.set_outcome(pid, "running")
        journal.started(pid, 1, {})
        said = await ctl.recover()
        assert "instruction 1 started, the machine has not moved: Unhold runs it" in said
        assert ctl.packml.state is State.HELD and ctl.twin.done == 0
        # the move happens now (the actuators finished it) and the daemon restarts again
        from bwsd.controller.plan import setpoints

        program = parse_program(TEXT)
        for step in setpoints(ctl.machine, program.instructions[0], 0.0):
            await ctl.bus.execute(step)
        again = Controller(ctl.machine, ctl.bus, journal)
        said = await again.recover()
        assert again.twin is not None
        assert "instruction 1 completed from the read-back" in said
        assert again.twin.done == 1 and journal.pending(pid) is None
        await again.command(Command.UNHOLD)
        await again.wait()
        assert again.packml.state is State.COMPLETE
        await ctl.bus.close()
        journal.close()

    run(scenario())


def test_a_pending_instruction_the_machine_never_ran_runs_on_unhold(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        journal.set_outcome(pid, "running")
        journal.started(pid, 1, {})
        await ctl.recover()
        await ctl.command(Command.UNHOLD)
        await ctl.wait()
        assert ctl.packml.state is State.COMPLETE
        assert [i.index for i in journal.instructions(pid)] == list(range(1, 16))
        whole = simulate(ctl.machine, parse_program(TEXT))
        assert bits(ctl.twin) == bits(whole)
        await ctl.bus.close()
        journal.close()

    run(scenario())


def test_a_machine_in_neither_state_blocks_unhold(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        journal.set_outcome(pid, "running")
        journal.started(pid, 1, {})
        takeup = 10  # the take-up somewhere unexpected: neither before nor after
        await ctl.bus.execute([AxisMove(takeup, 7_000)])
        said = await ctl.recover()
        assert "instruction 1 started and not done" in said
        with pytest.raises(ControllerError, match="cannot resume"):
            await ctl.command(Command.UNHOLD)
        assert ctl.packml.state is State.HELD
        await ctl.command(Command.ABORT, "operator")
        assert journal.program(pid).outcome == "aborted"
        await ctl.bus.close()
        journal.close()

    run(scenario())


def test_a_silent_bus_refuses_start_and_consumes_nothing(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        await ctl.command(Command.RESET)
        await request("127.0.0.1", mock.ports["control"], {"cmd": "fault", "kind": "mute"})
        with pytest.raises(ControllerError, match=r"the machine cannot be read: .*no answer"):
            await ctl.command(Command.START)
        assert ctl.packml.state is State.IDLE
        assert journal.program(pid).outcome == "loaded" and journal.pending(pid) is None
        bus = ctl.status().bus
        assert bus.connected is False and bus.last_error is not None
        assert "no answer" in bus.last_error
        await request("127.0.0.1", mock.ports["control"], {"cmd": "clear"})
        await ctl.command(Command.START)
        await ctl.wait()
        assert state_now(ctl) is State.COMPLETE
        assert ctl.status().bus.last_error is None  # cleared once the machine answered again
        await ctl.close()

    run(scenario())


def test_after_a_program_ends_every_command_still_lands_in_a_waiting_state(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        await ctl.command(Command.RESET)
        await ctl.command(Command.START)
        await ctl.wait()
        assert ctl.packml.state is State.COMPLETE
        assert await ctl.command(Command.STOP) is State.STOPPED
        assert await ctl.command(Command.ABORT) is State.ABORTED
        assert await ctl.command(Command.CLEAR) is State.STOPPED
        assert await ctl.command(Command.RESET) is State.IDLE
        with pytest.raises(ControllerError, match="is complete: load a program"):
            await ctl.command(Command.START)
        assert state_now(ctl) is State.IDLE
        assert journal.program(pid).outcome == "complete"  # an ended program stays ended
        await ctl.load("again.bws", TEXT.replace("REPEAT 3", "REPEAT 1"))
        await ctl.command(Command.START)
        await ctl.wait()
        assert ctl.packml.state is State.COMPLETE
        await ctl.bus.close()
        journal.close()

    run(scenario())


@pytest.mark.parametrize(
    ("fault", "state", "words"),
    [
        ({"cmd": "fault", "kind": "stall", "axis": "col1"}, State.ABORTED, "axis col1: stall"),
        ({"cmd": "fault", "kind": "drive", "axis": "col1"}, State.ABORTED, "drive fault"),
        (
            {"cmd": "fault", "kind": "wrong_position", "axis": "col1"},
            State.ABORTED,
            "wrong position",
        ),
        ({"cmd": "estop", "pressed": True}, State.ABORTED, "emergency stop"),
        ({"cmd": "fault", "kind": "mute"}, State.HELD, "instruction 2: "),
        ({"cmd": "fault", "kind": "drop"}, State.HELD, "instruction 2: "),
    ],
)
def test_every_injected_fault_stops_with_its_reason_and_no_unpredicted_move(
    slow_mock, tmp_path, fault, state, words
):
    """After one instruction a fault is injected; the second instruction (COL) meets it."""

    async def scenario() -> None:
        ctl, journal, _ = await controller(slow_mock, tmp_path)
        await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        await ctl.command(Command.RESET)
        seen: list[int] = []

        def inject(event: Event) -> None:
            if isinstance(event, InstructionDone):
                seen.append(event.index)

        ctl.events.subscribe(inject)
        await ctl.command(Command.START)
        while not seen:
            await asyncio.sleep(0.001)
        await request("127.0.0.1", slow_mock.ports["control"], fault)
        await ctl.wait()
        assert ctl.packml.state is state
        assert words in ctl.packml.reason
        committed = ctl.twin.occupancy >= 0
        predicted = ctl.twin.predict(parse_program(TEXT).instructions[ctl.twin.done])
        answer = await request("127.0.0.1", slow_mock.ports["control"], {"cmd": "state"})
        machine = np.array(answer["occupancy"], dtype=bool)
        instruction = parse_program(TEXT).instructions[ctl.twin.done]
        after = predicted.occupancy >= 0
        assert (
            np.array_equal(machine, committed)
            or np.array_equal(machine, after)
            or lines_left(instruction, machine, committed, after) is not None
        )  # where the twin is, where it predicted, or a shift cut between its lines (each
        # line as before or as predicted): no unpredicted move
        await ctl.bus.close()
        journal.close()

    run(scenario())


def test_a_shift_cut_between_its_lines_is_completed_line_by_line(mock, tmp_path):
    """Killed after row 1 moved and before row 2 did: Unhold moves row 2 only."""

    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path)
        pid = await ctl.load("braid.bws", TEXT)
        assert ctl.twin is not None
        journal.set_outcome(pid, "running")
        journal.started(pid, 1, {})
        from bwsd.controller.plan import setpoints

        first = parse_program(TEXT).instructions[0]  # ROW 1:+1 2:-1
        row1, _row2 = setpoints(ctl.machine, first, 0.0)[0]
        await ctl.bus.execute([row1])
        said = await ctl.recover()
        assert "some of its lines moved: Unhold moves the other 1" in said
        await ctl.command(Command.UNHOLD)
        await ctl.wait()
        assert ctl.packml.state is State.COMPLETE
        assert bits(ctl.twin) == bits(simulate(ctl.machine, parse_program(TEXT)))
        answer = await request("127.0.0.1", mock.ports["control"], {"cmd": "state"})
        assert np.array_equal(np.array(answer["occupancy"], dtype=bool), ctl.twin.occupancy >= 0)
        await ctl.bus.close()
        journal.close()

    run(scenario())


def test_a_program_beyond_the_instruction_limit_is_refused_at_check(mock, tmp_path):
    async def scenario() -> None:
        ctl, journal, _ = await controller(mock, tmp_path, settings=Settings(max_instructions=10))
        limit = r"braid.bws:6:1: the program expands to more than 10 instructions \(\["
        with pytest.raises(ProgramError, match=limit + r"controller\] max_instructions\)"):
            await ctl.check("braid.bws", TEXT)  # at the REPEAT, before it is expanded
        assert journal.history() == []
        await ctl.close()

    run(scenario())


def test_max_contacts_is_checked_by_the_dry_run(mock, tmp_path):
    async def scenario() -> None:
        most = simulate(client_config("modbus", mock.ports).machine, parse_program(TEXT))
        assert most.contact_count > 0
        ctl, journal, _ = await controller(mock, tmp_path, limits=Limits(max_contacts=1))
        with pytest.raises(
            ControllerError,
            match=r"instruction \d+: \d+ contacts, more than "
            r"the limit of 1",
        ):
            await ctl.load("braid.bws", TEXT)
        assert ctl.program is None and journal.history() == []
        await ctl.close()

    run(scenario())


def test_one_check_at_a_time_and_a_cancelled_one_stops(mock, tmp_path):
    async def scenario() -> None:
        ctl, _, _ = await controller(mock, tmp_path)
        long = TEXT.replace("REPEAT 3", "REPEAT 100000")  # 500,000 instructions
        cancel = threading.Event()
        first = asyncio.create_task(ctl.check("long.bws", long, cancel))
        await asyncio.sleep(0.05)
        with pytest.raises(Busy, match="another program is being checked"):
            await ctl.check("braid.bws", TEXT)
        cancel.set()
        with pytest.raises(Cancelled, match=r"long\.bws: the check was cancelled"):
            await first
        _, totals = await ctl.check("braid.bws", TEXT)  # free again
        assert totals.instructions == 15
        await ctl.close()

    run(scenario())


def test_a_restart_replays_only_what_follows_the_last_snapshot(mock, tmp_path, caplog):
    async def scenario() -> None:
        every = Settings(snapshot_every=4)
        first, journal, _ = await controller(mock, tmp_path, settings=every)
        pid = await first.load("braid.bws", TEXT)
        assert first.twin is not None
        await first.command(Command.RESET)
        await first.command(Command.START)
        while first.twin.done < 10:
            await asyncio.sleep(0)
        await first.command(Command.HOLD, "operator")
        done = first.twin.done
        snap = journal.latest_snapshot(pid)
        assert snap is not None and snap[0] == done - done % 4
        await first.close()
        second, journal, _ = await controller(mock, tmp_path, settings=every)
        with caplog.at_level(logging.INFO, logger="bwsd.controller"):
            await second.recover()
        assert f"rebuilt at instruction {done} from the snapshot at {snap[0]}" in caplog.text
        replayed = replay(second.machine, parse_program(TEXT), done)
        assert bits(second.twin) == bits(replayed)  # restored + replayed = replayed whole
        await second.command(Command.UNHOLD)
        await second.wait()
        assert second.packml.state is State.COMPLETE
        assert bits(second.twin) == bits(simulate(second.machine, parse_program(TEXT)))
        assert journal.latest_snapshot(pid) is None  # dropped once the program ended
        await second.close()

    run(scenario())
