"""The one gate every door goes through (bwsd.gate), on a controller driving the mock loom.

Each door's own tests send its wire types (tests/api, tests/plc, tests/opcua); here the
gate's rules themselves: what it takes for a command, a mode, a load, what it refuses, and
that a refusal changes nothing and is logged at INFO, never as a warning or an error.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

from bwsd.controller.facade import Controller
from bwsd.controller.packml import Command, State, UnitMode
from bwsd.errors import BwsdError
from bwsd.fieldbus import open_bus
from bwsd.gate import Caller, Gate, Refused, command_of, mode_of, number_of
from bwsd.journal import Journal
from bwsd.tokens import TokenStore
from tests.support.fieldbus import client_config, mock

__all__ = ["mock"]  # the mock loom fixture

TEXT = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nTAKEUP 1\n"


def run(scenario: Any) -> Any:
    return asyncio.run(asyncio.wait_for(scenario, 60))


@asynccontextmanager
async def rig(mock: Any, tmp_path: Any) -> AsyncIterator[tuple[Controller, Gate, TokenStore]]:
    config = client_config("modbus", mock.ports)
    bus = open_bus(config)
    await bus.connect()
    journal = Journal.open(tmp_path / "journal.db")
    ctl = Controller(config.machine, bus, journal)
    tokens = TokenStore.load(tmp_path / "tokens.json")
    try:
        yield ctl, Gate(ctl, tokens), tokens
    finally:
        await ctl.wait()
        await bus.close()
        journal.close()


@pytest.mark.parametrize(
    ("wire", "command"),
    [
        (1, Command.RESET),
        (Command.STOP, Command.STOP),
        ("start", Command.START),
        (" Abort ", Command.ABORT),
        ("CLEAR", Command.CLEAR),
        (9, Command.CLEAR),
    ],
)
def test_a_command_is_taken_as_itself_its_number_or_its_name(wire: Any, command: Command):
    assert command_of(wire) is command


@pytest.mark.parametrize(
    ("wire", "kind"),
    [
        (0, "range"),
        (10, "range"),
        (-1, "range"),
        (65535, "range"),
        (2.0, "type"),
        (True, "type"),
        (None, "type"),
        ("2", "range"),
        ("go", "range"),
        (b"start", "type"),
        ([2], "type"),
    ],
)
def test_a_command_of_a_wrong_type_or_out_of_range_is_refused(wire: Any, kind: str):
    with pytest.raises(Refused) as refused:
        command_of(wire)
    assert refused.value.kind == kind and refused.value.field == "command"
    with pytest.raises(Refused) as mode:
        mode_of(wire if wire != 10 else 4)
    assert mode.value.kind == kind and mode.value.field == "mode"


@pytest.mark.slow
def test_refusals_change_nothing_and_are_logged_at_info(mock, tmp_path, caplog):
    caplog.set_level(logging.DEBUG)

    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, gate, tokens):
            operator = Caller("rest", "op", tokens.add("op", "operator"))
            viewer = Caller("rest", "eye", tokens.add("eye", "viewer"))
            plc = Caller("plc", "plc", role="admin")
            before = ctl.status()
            refusals: list[Any] = [
                gate.command(operator, 2.0),
                gate.command(operator, True),
                gate.command(operator, "reset", reason=3),
                gate.command(operator, "reset", resume=1),
                gate.command(operator, "reset", resume=True),  # resume goes with start only
                gate.command(operator, "reset", reason="x" * 501),
                gate.command(viewer, "reset"),
                gate.set_mode(operator, "maintenance"),  # a mode needs admin
                gate.set_mode(plc, 2.0),
                gate.load(viewer, "a.bws", TEXT),
                gate.load(operator, "", TEXT),
                gate.load(operator, "a.bws", None),
                gate.load_stored(operator, 0),
                gate.load_stored(operator, "1"),
                gate.command(Caller("opcua", "ghost", "no-such-token"), "reset"),
                gate.command(Caller("plc", "plc"), "reset"),  # neither a token nor a role
                # the controller's own refusals come back through the gate as they are
                gate.command(operator, "start"),  # no program loaded
                gate.command(operator, "unhold"),  # not from Stopped
                gate.load_stored(operator, 42),  # not in the journal
                gate.load(operator, "bad.bws", "ROW 9:+1\n"),
            ]
            for request in refusals:
                with pytest.raises(BwsdError):
                    await request
            after = ctl.status()
            assert after.state is State.STOPPED and after.mode is UnitMode.PRODUCTION
            assert after.program_id is None
            assert after == before
            assert await ctl.history() == []
            loud = [r for r in caplog.records if r.levelno >= logging.WARNING]
            assert loud == [], [r.getMessage() for r in loud]
            said = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
            assert len(said) >= len(refusals) - 1, said  # the bad program: its own line

    run(scenario())


@pytest.mark.slow
def test_a_role_is_the_tokens_role_now_not_at_login(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, gate, tokens):
            token = tokens.add("shift", "operator")
            caller = Caller("opcua", "shift", token)
            assert await gate.command(caller, "reset") is State.IDLE
            tokens.remove("shift")
            with pytest.raises(Refused) as gone:
                await gate.command(caller, "stop")
            assert gone.value.kind == "who"
            again = tokens.add("shift", "viewer")  # the same name, a new token, a lower role
            with pytest.raises(Refused) as old:
                await gate.command(caller, "stop")
            assert old.value.kind == "who"  # the old token does not come back with the name
            with pytest.raises(Refused) as low:
                await gate.command(Caller("opcua", "shift", again), "stop")
            assert low.value.kind == "role"
            assert ctl.status().state is State.IDLE
            assert gate.role(Caller("opcua", "shift", again)) == "viewer"

    run(scenario())


@pytest.mark.slow
def test_a_load_through_the_gate_is_a_load_and_its_caller_is_journaled(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, gate, tokens):
            caller = Caller("opcua", "eng", tokens.add("eng", "operator"))
            first = await gate.load(caller, "a.bws", TEXT)
            again = await gate.load_stored(caller, first)
            assert again > first and ctl.status().program_id == again
            assert [r.name for r in await ctl.history()] == ["a.bws", "a.bws"]
            assert caller.who == "opcua:eng"

    run(scenario())


@pytest.mark.parametrize(
    ("wire", "kind"),
    [(True, "type"), ("1", "type"), (None, "type"), (50.5, "range"), (float("nan"), "range")],
)
def test_a_number_of_a_wrong_type_or_out_of_range_is_refused(wire: Any, kind: str):
    with pytest.raises(Refused) as refused:
        number_of(wire, "length", -50.0, 50.0)
    assert (refused.value.kind, refused.value.field) == (kind, "length")


def test_a_number_is_taken_as_a_float():
    assert number_of(-50, "length", -50.0, 50.0) == -50.0
    assert number_of(2.5, "length", -50.0, 50.0) == 2.5
