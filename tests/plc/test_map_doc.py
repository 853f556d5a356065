"""The PLC tag server checked against docs/plc.md's map, address by address, over Modbus.

The addresses come from the doc, not from the code's constants: an address moved in the
code and not in the doc fails here.
"""

from __future__ import annotations

import pytest
from pymodbus.constants import ExcCodes

from bwsd.controller.packml import State, UnitMode
from tests.doc_tables import addresses, doc_table
from tests.plc.test_tags import DEVICE, TEXT, Plc, rig, run

pytestmark = pytest.mark.slow  # every test here is in the slow tier

MAP = doc_table("plc.md", "address", "tag", "type", "access", after="## The map")
ADDRESS = {row["tag"].removesuffix(" (bwsd)"): addresses(row["address"]) for row in MAP}
REFUSALS = doc_table("plc.md", "request", "answer", after="### Refused requests")
SIZE = sum(len(at) for at in ADDRESS.values())


async def read_all(plc: Plc) -> list[int]:
    """Every documented register, in one request."""
    answer = await plc.client.read_holding_registers(0, count=SIZE, device_id=DEVICE)
    assert not answer.isError(), answer
    return list(answer.registers)


def word(registers: list[int], tag: str) -> int:
    """A tag's value read at its documented address (two words: high word first)."""
    at = ADDRESS[tag]
    return registers[at[0]] if len(at) == 1 else (registers[at[0]] << 16) | registers[at[1]]


def test_a_live_server_serves_every_tag_at_its_documented_address(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, _, plc):
            pid = await ctl.load("braid.bws", TEXT)
            got = await read_all(plc)
            assert word(got, "Admin.MapVersion") == int(MAP[0]["meaning"].split(";")[0])
            assert word(got, "Status.StateCurrent") == State.STOPPED
            assert word(got, "Status.UnitModeCurrent") == UnitMode.PRODUCTION
            assert word(got, "Status.InstructionCount") == 15
            assert word(got, "Status.ProgramId") == pid
            past = await plc.client.read_holding_registers(SIZE, count=1, device_id=DEVICE)
            assert past.isError() and past.exception_code == ExcCodes.ILLEGAL_ADDRESS
            # the PLC selects the program by its documented registers: ProgramId, LoadRequest
            high, low = divmod(pid, 1 << 16)
            assert await plc.write(ADDRESS["Command.ProgramId"][0], [high, low])
            assert await plc.write(ADDRESS["Command.LoadRequest"][0], [1])
            loaded = await plc.until(lambda t: t.load_request == 0 and t.program_id != pid)
            assert loaded.cmd_invalid == 0 and ctl.status().program_id == loaded.program_id
            again = await read_all(plc)
            assert word(again, "Status.ProgramId") == loaded.program_id
            assert word(again, "Command.ProgramId") == pid  # reads what was written

    run(scenario())


def test_every_documented_read_only_register_refuses_a_write_and_keeps_its_value(mock, tmp_path):
    refusal = next(r for r in REFUSALS if r["request"].startswith("a write to a read-only"))
    spans = refusal["request"].split("(")[1].split(")")[0].split(",")
    listed = sorted({n for part in spans for n in _span(part)})
    read_only = sorted(a for row in MAP if row["access"] == "R" for a in addresses(row["address"]))
    assert listed == read_only, "the refusals table and the map disagree"

    async def scenario() -> None:
        async with rig(mock, tmp_path) as (ctl, _, plc):
            before = await read_all(plc)
            for address in read_only:
                answer = await plc.client.write_register(address, 1, device_id=DEVICE)
                assert answer.isError() and answer.exception_code == ExcCodes.ILLEGAL_ADDRESS, (
                    address
                )
            after = await plc.tags()
            assert (after.state_current, after.cmd_invalid) == (State.STOPPED, 0)
            now = await read_all(plc)
            heartbeat = ADDRESS["Status.Heartbeat"][0]
            assert [w for i, w in enumerate(now) if i != heartbeat] == [
                w for i, w in enumerate(before) if i != heartbeat
            ]
            assert ctl.status().state == State.STOPPED

    run(scenario())


def _span(text: str) -> range:
    """``5 .. 16`` or ``18`` as the addresses it names."""
    numbers = [int(n) for n in text.replace("..", " ").split()]
    return range(numbers[0], numbers[-1] + 1)
