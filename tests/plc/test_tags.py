"""A bare pymodbus client plays the PLC over loopback; the controller runs the mock loom."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from types import SimpleNamespace
from typing import Any

import pytest
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from bwsd.config import parse_config
from bwsd.controller.facade import Controller
from bwsd.controller.packml import State, UnitMode
from bwsd.controller.plan import Limits
from bwsd.errors import ConfigError
from bwsd.fieldbus import open_bus
from bwsd.journal import Journal
from bwsd.plc import REG_COUNT, PlcError, PlcTags, StopReason, Tags, decode, plc_tags
from bwsd.plc.registers import (
    REG_CMD_CHANGE_REQUEST,
    REG_CNTRL_CMD,
    REG_PROGRAM,
    REG_RESUME,
    REG_STATE_CURRENT,
    REG_UNIT_MODE,
    REG_UNIT_MODE_CHANGE_REQUEST,
)
from simulator_hw.control import request
from tests.support.fieldbus import MACHINE, client_config

# The mock loom's fill: cases at (1, 1), (1, 2), (2, 1), (2, 2); 15 instructions.
CYCLE = "ROW 1:+1 2:-1\nCOL 1:+1 2:-1\nROW 1:-1 2:+1\nCOL 1:-1 2:+1\nTAKEUP 2\n"
TEXT = f"YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 3\n{CYCLE}END\n"
RESET, START, STOP, HOLD, UNHOLD, CLEAR = 1, 2, 3, 4, 5, 9
DEVICE = 3


def run(scenario: Any) -> Any:
    return asyncio.run(asyncio.wait_for(scenario, 60))


class Plc:
    """The PLC's side of the handshake, as a plant PLC would do it."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)

    async def tags(self) -> Tags:
        answer = await self.client.read_holding_registers(0, count=REG_COUNT, device_id=DEVICE)
        assert not answer.isError(), answer
        return decode(answer.registers)

    async def write(self, address: int, values: list[int]) -> bool:
        """True when the write was taken, False on an exception response."""
        answer = await self.client.write_registers(address, values, device_id=DEVICE)
        return not answer.isError()

    async def until(self, done: Callable[[Tags], bool], seconds: float = 10.0) -> Tags:
        deadline = time.monotonic() + seconds
        while not done(tags := await self.tags()):
            assert time.monotonic() < deadline, f"still {tags}"
            await asyncio.sleep(0.01)
        return tags

    async def command(self, number: int) -> Tags:
        """Write CntrlCmd, then CmdChangeRequest = 1; wait until the daemon clears it."""
        assert await self.write(REG_CNTRL_CMD, [number])
        assert await self.write(REG_CMD_CHANGE_REQUEST, [1])
        return await self.until(lambda t: t.cmd_change_request == 0)

    async def mode(self, number: int) -> Tags:
        assert await self.write(REG_UNIT_MODE, [number])
        assert await self.write(REG_UNIT_MODE_CHANGE_REQUEST, [1])
        return await self.until(lambda t: t.unit_mode_change_request == 0)


@asynccontextmanager
async def rig(mock, tmp_path, **kw) -> AsyncIterator[tuple[Controller, Journal, Plc]]:
    """A controller on the mock loom with its tags served, and a connected PLC."""
    config = client_config("modbus", mock.ports)
    bus = open_bus(config)
    await bus.connect()
    journal = Journal.open(tmp_path / "journal.db")
    doors = {key: kw.pop(key) for key in ("allow", "read_only") if key in kw}
    ctl = Controller(config.machine, bus, journal, **kw)
    tags = PlcTags(ctl, port=0, device_id=DEVICE, **doors)
    await tags.start()
    plc = Plc(tags.port)
    assert await plc.client.connect()
    try:
        yield ctl, journal, plc
    finally:
        plc.client.close()
        await tags.stop()
        await ctl.wait()
        await bus.close()
        journal.close()


@pytest.mark.slow
def test_the_handshake_runs_a_program_from_stopped_to_complete(slow_mock, tmp_path):
    async def scenario() -> None:
        async with rig(slow_mock, tmp_path) as (ctl, journal, plc):
            pid = await ctl.load("braid.bws", TEXT)
            first = await plc.tags()
            assert (first.state_current, first.instruction_index) == (State.STOPPED, 0)
            assert (first.instruction_count, first.unit_mode_current) == (15, UnitMode.PRODUCTION)
            idle = await plc.command(RESET)
            assert (idle.state_current, idle.cmd_invalid) == (State.IDLE, 0)
            running = await plc.command(START)
            assert running.state_current == State.EXECUTE and running.cmd_invalid == 0
            seen: list[tuple[int, int]] = []

            def complete(t: Tags) -> bool:
                seen.append((t.state_current, t.instruction_index))
                return t.state_current == State.COMPLETE

            end = await plc.until(complete)
            indices = [index for _, index in seen]
            assert indices == sorted(indices)  # the index only moves forward
            assert any(s == State.EXECUTE and 0 < i < 15 for s, i in seen)
            assert (end.instruction_index, end.instruction_count, end.good_count) == (15, 15, 1)
            assert end.stop_reason == StopReason.NONE
            assert journal.program(pid).outcome == "complete"

    run(scenario())


@pytest.mark.slow
def test_a_refused_command_sets_cmd_invalid_and_leaves_the_state(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, _, plc):
            assert (await plc.command(RESET)).state_current == State.IDLE
            for refused in (UNHOLD, 42, 0, 0xFFFF, START):  # 0xFFFF: an INT -1; Start: no program
                after = await plc.command(refused)
                assert (after.state_current, after.cmd_invalid) == (State.IDLE, 1), refused
                assert ctl.packml.state is State.IDLE
            # command and request in one write; the next accepted request clears CmdInvalid
            assert await plc.write(REG_CNTRL_CMD, [STOP, 1])
            stopped = await plc.until(lambda t: t.cmd_change_request == 0)
            assert (stopped.state_current, stopped.cmd_invalid) == (State.STOPPED, 0)
            assert stopped.stop_reason == StopReason.OPERATOR
            assert ctl.packml.reason == "by the PLC"

    run(scenario())


@pytest.mark.slow
def test_status_registers_and_bad_requests_are_refused_on_the_wire(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, _, plc):
            assert not await plc.write(REG_STATE_CURRENT, [State.EXECUTE])
            assert not await plc.write(REG_CNTRL_CMD, [RESET, 2])  # a request is 0 or 1
            assert not await plc.write(REG_CNTRL_CMD, [RESET, 1, 1, 1, 0])  # runs into status
            await asyncio.sleep(0.05)
            tags = await plc.tags()
            assert (tags.state_current, tags.cmd_change_request) == (State.STOPPED, 0)
            assert ctl.packml.state is State.STOPPED
            coils = await plc.client.read_coils(0, count=1, device_id=DEVICE)
            assert coils.isError()

    run(scenario())


@pytest.mark.slow
def test_unit_mode_changes_in_idle_and_is_refused_in_execute(slow_mock, tmp_path):
    async def scenario() -> None:
        async with rig(slow_mock, tmp_path) as (ctl, journal, plc):
            await ctl.load("braid.bws", TEXT)
            await plc.command(RESET)
            changed = await plc.mode(UnitMode.MAINTENANCE)
            assert (changed.unit_mode_current, changed.cmd_invalid) == (UnitMode.MAINTENANCE, 0)
            assert ctl.packml.mode is UnitMode.MAINTENANCE
            for _ in range(500):  # the journal's writer records it, in order, soon after
                if mode := [e for e in journal.events(0, 100) if e.kind == "mode"]:
                    break
                await asyncio.sleep(0.01)
            assert [e.data for e in mode] == [
                {"from": "Production", "to": "Maintenance", "by": "plc"}
            ]
            assert (await plc.command(START)).state_current == State.EXECUTE
            refused = await plc.mode(UnitMode.PRODUCTION)
            assert (refused.unit_mode_current, refused.cmd_invalid) == (UnitMode.MAINTENANCE, 1)
            assert refused.state_current == State.EXECUTE
            unknown = await plc.mode(9)
            assert (unknown.unit_mode_current, unknown.cmd_invalid) == (UnitMode.MAINTENANCE, 1)
            held = await plc.command(HOLD)
            assert (held.state_current, held.cmd_invalid) == (State.HELD, 0)
            assert held.stop_reason == StopReason.OPERATOR

    run(scenario())


@pytest.mark.slow
def test_a_pressed_estop_reads_1_and_refuses_reset_and_start(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, journal, plc):
            pid = await ctl.load("braid.bws", TEXT)
            control = ("127.0.0.1", mock.ports["control"])
            assert (await plc.tags()).estop == 0
            await request(*control, {"cmd": "estop", "pressed": True})
            refused = await plc.command(RESET)
            assert (refused.state_current, refused.cmd_invalid, refused.estop) == (
                State.STOPPED,
                1,
                1,
            )
            await request(*control, {"cmd": "estop", "pressed": False})
            idle = await plc.command(RESET)
            assert (idle.state_current, idle.cmd_invalid, idle.estop) == (State.IDLE, 0, 0)
            await request(*control, {"cmd": "estop", "pressed": True})
            again = await plc.command(START)
            assert (again.state_current, again.cmd_invalid, again.estop) == (State.IDLE, 1, 1)
            assert journal.program(pid).outcome == "loaded"  # the program is not consumed
            await request(*control, {"cmd": "estop", "pressed": False})

    run(scenario())


@pytest.mark.slow
def test_the_heartbeat_advances_every_second(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (_, _, plc):
            first = (await plc.tags()).heartbeat
            second = (await plc.until(lambda t: t.heartbeat != first, 2.5)).heartbeat
            started = time.monotonic()
            third = (await plc.until(lambda t: t.heartbeat != second, 2.5)).heartbeat
            assert (second - first, third - second) == (1, 1)
            assert time.monotonic() - started > 0.5  # once a second, not faster

    run(scenario())


@pytest.mark.slow
def test_a_drive_fault_reads_stop_reason_2_until_reset(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, _, plc):
            await ctl.load("braid.bws", TEXT)
            await plc.command(RESET)
            control = ("127.0.0.1", mock.ports["control"])
            await request(*control, {"cmd": "fault", "kind": "drive", "axis": "col2"})
            await plc.command(START)
            aborted = await plc.until(lambda t: t.state_current == State.ABORTED)
            assert aborted.stop_reason == StopReason.DRIVE_FAULT
            assert (aborted.instruction_index, aborted.good_count) == (1, 0)
            assert "drive fault" in ctl.packml.reason
            await request(*control, {"cmd": "clear"})
            cleared = await plc.command(CLEAR)
            assert (cleared.state_current, cleared.stop_reason) == (State.STOPPED, 2)
            again = await plc.command(RESET)
            assert (again.state_current, again.stop_reason) == (State.IDLE, StopReason.NONE)

    run(scenario())


@pytest.mark.slow
def test_a_refused_move_reads_stop_reason_1(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, _, plc):
            await ctl.load("braid.bws", TEXT)
            ctl.limits = Limits(tensioner_stroke=0.001)  # tightened after the load's dry run
            await plc.command(RESET)
            await plc.command(START)
            aborted = await plc.until(lambda t: t.state_current == State.ABORTED)
            assert aborted.stop_reason == StopReason.REFUSED_MOVE

    run(scenario())


@pytest.mark.slow
def test_a_restart_reads_stop_reason_7(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, journal, plc):
            pid = await ctl.load("braid.bws", TEXT)
            journal.set_outcome(pid, "running")  # as a daemon that died while running leaves it
            said = await ctl.recover()
            held = await plc.tags()
            assert held.state_current == State.HELD and "resume with Unhold" in said
            assert held.stop_reason == StopReason.RESTART
            late = PlcTags(ctl, port=0)  # started after the recovery, as the daemon does
            await late.start()
            assert late.tags().stop_reason == StopReason.RESTART
            await late.stop()
            done = await plc.command(UNHOLD)
            assert done.cmd_invalid == 0
            end = await plc.until(lambda t: t.state_current == State.COMPLETE)
            assert (end.instruction_index, end.good_count) == (15, 1)

    run(scenario())


def test_plc_tags_follow_the_config_table(tmp_path):
    config = parse_config({"machine": MACHINE, "plc": {"port": 0, "device_id": 7}})
    journal = Journal.open(tmp_path / "journal.db")
    controller = Controller(config.machine, open_bus(config), journal)  # not connected: unused
    tags = plc_tags(controller, config)
    assert isinstance(tags, PlcTags)
    assert (tags.host, tags.port, tags.device_id) == ("127.0.0.1", 0, 7)
    off = parse_config({"machine": MACHINE, "plc": {"enabled": False}})
    assert plc_tags(controller, off) is None
    journal.close()


@pytest.mark.slow
def test_a_port_in_use_is_a_plc_error_naming_it(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, _, plc):
            taken = plc.port
            second = PlcTags(ctl, port=taken)
            with pytest.raises(PlcError, match=f"cannot listen on 127.0.0.1:{taken}"):
                await second.start()
            assert (await plc.tags()).state_current == State.STOPPED  # the first one still serves

    run(scenario())


# ----- the doors -----
@pytest.mark.slow
def test_an_address_outside_the_allow_list_is_not_served(mock, tmp_path):
    """The tag server took writes from anyone who could reach it: a write did a Reset."""

    async def scenario() -> None:
        async with rig(mock, tmp_path, allow=["127.0.0.1"]) as (ctl, _, plc):
            stranger = AsyncModbusTcpClient(
                "127.0.0.2", port=plc.port, timeout=1, retries=0, source_address=("127.0.0.2", 0)
            )
            await stranger.connect()
            answer = None
            with contextlib.suppress(ModbusException):
                answer = await stranger.write_registers(REG_CNTRL_CMD, [RESET, 1], device_id=DEVICE)
            stranger.close()
            assert answer is None or answer.isError()
            await asyncio.sleep(0.2)
            assert ctl.packml.state is State.STOPPED  # nothing was done
            assert (await plc.command(RESET)).state_current == State.IDLE  # the PLC is served

    run(scenario())


@pytest.mark.slow
def test_a_network_in_the_allow_list_admits_its_addresses(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path, allow=["127.0.0.0/30"]) as (_, _, plc):
            other = AsyncModbusTcpClient(
                "127.0.0.1", port=plc.port, timeout=2, retries=0, source_address=("127.0.0.2", 0)
            )
            assert await other.connect()
            answer = await other.read_holding_registers(0, count=REG_COUNT, device_id=DEVICE)
            other.close()
            assert not answer.isError()

    run(scenario())


@pytest.mark.slow
def test_read_only_tags_refuse_every_write_and_still_answer_reads(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path, read_only=True) as (ctl, _, plc):
            answer = await plc.client.write_registers(REG_CNTRL_CMD, [RESET, 1], device_id=DEVICE)
            assert answer.isError() and answer.exception_code == 1  # illegal function
            await asyncio.sleep(0.2)
            tags = await plc.tags()
            assert (tags.state_current, tags.cntrl_cmd, tags.cmd_change_request) == (
                State.STOPPED,
                0,
                0,
            )
            assert ctl.packml.state is State.STOPPED

    run(scenario())


@pytest.mark.slow
def test_a_bad_allow_entry_is_a_config_error_naming_the_key(mock, tmp_path):
    config = parse_config({"machine": MACHINE, "plc": {"allow": "127.0.0.1 plc-3"}}, "bwsd.toml")
    with pytest.raises(ConfigError, match=r"\[plc\.allow\]: 'plc-3' is not an IP address"):
        # no controller: the config is refused before one is needed
        plc_tags(SimpleNamespace(), config)  # type: ignore[arg-type]


ABORT = 8


@pytest.mark.slow
def test_an_aborted_part_resumes_from_the_plc_with_command_resume(slow_mock, tmp_path):
    async def scenario() -> None:
        async with rig(slow_mock, tmp_path) as (ctl, journal, plc):
            pid = await ctl.load("braid.bws", TEXT)
            await plc.command(RESET)
            await plc.command(START)
            await plc.until(lambda t: t.instruction_index >= 2)
            aborted = await plc.command(ABORT)
            assert aborted.state_current == State.ABORTED and aborted.resumable == 1
            await plc.command(CLEAR)
            await plc.command(RESET)
            plain = await plc.command(START)  # a plain Start does not run an ended program
            assert (plain.state_current, plain.cmd_invalid) == (State.IDLE, 1)
            assert not await plc.write(REG_RESUME, [2])  # 0 or 1 only
            assert await plc.write(REG_RESUME, [1])
            resumed = await plc.command(START)
            assert resumed.cmd_invalid == 0 and resumed.resume == 1 and resumed.resumable == 0
            end = await plc.until(lambda t: t.state_current == State.COMPLETE)
            assert end.instruction_index == 15 and journal.program(pid).outcome == "complete"

    run(scenario())


LOADED = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nTAKEUP 1\n"


@pytest.mark.slow
def test_the_plc_loads_a_stored_program_by_its_id_and_is_refused_as_rest_is(slow_mock, tmp_path):
    async def scenario() -> None:
        async with rig(slow_mock, tmp_path) as (ctl, journal, plc):
            first = await ctl.load("first.bws", LOADED)
            second = await ctl.load("second.bws", TEXT)
            assert (await plc.tags()).program_id == second

            async def load(number: int) -> Tags:
                high, low = number >> 16, number & 0xFFFF
                assert await plc.write(REG_PROGRAM, [high, low, 1])
                return await plc.until(lambda t: t.load_request == 0)

            picked = await load(first)
            assert picked.cmd_invalid == 0 and picked.program == first
            assert picked.program_id not in (0, first, second)  # a load is a new record
            assert journal.program(picked.program_id).name == "first.bws"
            assert (picked.instruction_index, picked.instruction_count) == (0, 1)
            for refused in (0, 9999):  # 0 is out of range; 9999 is not in the journal
                after = await load(refused)
                assert after.cmd_invalid == 1 and after.program_id == picked.program_id
            # the same refusal REST gives: no load while a program runs
            assert (await plc.command(RESET)).state_current == State.IDLE
            await ctl.load("slow.bws", TEXT)
            await plc.command(START)
            running = await load(first)
            assert (
                running.cmd_invalid == 1 and journal.program(running.program_id).name == "slow.bws"
            )
            await plc.command(ABORT)

    run(scenario())


@pytest.mark.slow
def test_a_read_only_tap_cannot_load(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path, read_only=True) as (ctl, _, plc):
            first = await ctl.load("first.bws", LOADED)
            second = await ctl.load("second.bws", LOADED)
            assert not await plc.write(REG_PROGRAM, [0, first, 1])
            await asyncio.sleep(0.05)
            assert (await plc.tags()).program_id == second == ctl.status().program_id

    run(scenario())
