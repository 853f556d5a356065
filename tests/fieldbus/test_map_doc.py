"""The Modbus loom map checked against docs/fieldbus-modbus.md, maps 3 and 2.

bwsd's client and the mock loom share their constants, so a test through either cannot see
an address that moved in both. These tests read the addresses from the doc's tables, check
the shared constants against them, and drive a live mock loom with a bare pymodbus client at
the documented addresses.
"""

from __future__ import annotations

import asyncio
import dataclasses
import re
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.constants import ExcCodes

from bwsd.fieldbus import base, modbus
from bwsd.fieldbus.axes import machine_axes
from bwsd.twin.machine import Machine, Segment
from simulator_hw.control import request
from tests.doc_tables import DOCS, addresses, doc_table
from tests.support.fieldbus import MACHINE, Mock, start_mock

DOC = "fieldbus-modbus.md"
MACHINE_BLOCK = {
    r["name"]: r
    for r in doc_table(
        DOC, "address", "name", "access", after="## Holding registers: machine block"
    )
}
AXIS_BLOCK = {
    r["name"]: r
    for r in doc_table(DOC, "offset", "name", "access", after="## Holding registers: axis block")
}
FAULTS = doc_table(DOC, "code", "name", "meaning", after="## Fault codes")
IMAGE = doc_table(DOC, "address", "meaning", after="## Input registers")
AXES = doc_table(DOC, "axis", "index", "target (+0, +1)", "map", after="## Axes")
INPUTS = doc_table(DOC, "address", "meaning", after="## Discrete inputs")
ROWS, COLS = MACHINE["rows"], MACHINE["cols"]
PITCH_UM = int(MACHINE["pitch_x"] * 1000)


def first(table: dict[str, dict[str, str]], name: str, key: str = "address") -> int:
    return addresses(table[name][key])[0]


def block() -> tuple[int, int]:
    """'Axis i occupies 16 registers from `100 + 16 i`' as (base, stride)."""
    text = (DOCS / DOC).read_text()
    found = re.search(r"Axis i occupies (\d+) registers from `(\d+) \+ (\d+) i`", text)
    assert found, "the axis block's placement is not where the doc says it"
    assert found[1] == found[3]
    return int(found[2]), int(found[3])


def index_of(expression: str, **names: int) -> int:
    """An index as the Axes table writes it (``R + C + S + 3``), for the numbers ``names``."""
    terms = [term.strip() for term in expression.split("+")]
    return sum(int(t) if t.isdigit() else names[t] for t in terms)


def documented_axes(machine: Machine, version: int = 3) -> dict[int, str]:
    """Every axis of ``machine`` the Axes table places on map ``version``: {index: name}."""
    rows, cols, segs = machine.rows, machine.cols, len(machine.segments)
    found: dict[int, str] = {}
    for row in AXES:
        if int(row["map"]) > version:
            continue
        name, expression = row["axis"], row["index"]
        sizes = {"R": rows, "C": cols, "S": segs}
        if name == "row r":
            found |= {index_of(expression, r=r, **sizes): f"row{r}" for r in range(rows)}
        elif name == "col c":
            found |= {index_of(expression, c=c, **sizes): f"col{c}" for c in range(cols)}
        elif name == "segment j":
            for j, seg in enumerate(machine.segments):
                found[index_of(expression, j=j, **sizes)] = (
                    f"{seg.axis}{seg.line}[{seg.lo}..{seg.hi}]"
                )
        else:
            found[index_of(expression, **sizes)] = name
    return found


def test_the_axes_are_numbered_as_the_axes_table_says():
    corner = (Segment("row", 3, 0, 3), Segment("col", 3, 0, 3))
    segmented = Machine(8, 8, 10, 12, 100, 0.5, segments=corner)
    for machine in (segmented, Machine(**MACHINE)):
        wire = {axis.index: axis.name for axis in machine_axes(machine)}
        assert wire == documented_axes(machine)
    assert documented_axes(segmented)[21] == "weft_x"  # the doc's example
    map2 = dataclasses.replace(segmented, weft_axes=())  # map 2 has no positioning axes
    assert {a.index: a.name for a in machine_axes(map2)} == documented_axes(map2, version=2)
    absolute = [row["axis"] for row in AXES if row["target (+0, +1)"].startswith("absolute")]
    assert absolute == ["weft_angle", "takeup", "weft_x", "weft_y", "weft_z"]
    relative = {a.name for a in machine_axes(segmented) if a.relative}
    assert not relative & set(absolute) and "weft_insert" in relative


def bits(meaning: str) -> dict[str, int]:
    """'bit 0 busy, bit 1 faulted' as {'busy': 1, 'faulted': 2}."""
    return {m[2].split()[-1]: 1 << int(m[1]) for m in re.finditer(r"bit (\d+) ([^,]+)", meaning)}


def test_the_shared_constants_are_the_documented_addresses():
    assert [
        first(MACHINE_BLOCK, n)
        for n in ("map version", "axis count", "rows", "cols", "machine status", "machine command")
    ] == [
        modbus.REG_VERSION,
        modbus.REG_AXES,
        modbus.REG_ROWS,
        modbus.REG_COLS,
        modbus.REG_STATUS,
        modbus.REG_COMMAND,
    ]
    owner = addresses(MACHINE_BLOCK["owner: claim id"]["address"])
    owner += addresses(MACHINE_BLOCK["owner: pid"]["address"])
    assert owner == list(range(modbus.REG_OWNER, modbus.REG_OWNER + modbus.OWNER_WORDS))
    assert block() == (modbus.AXIS_BASE, modbus.AXIS_STRIDE)
    offsets = {name: addresses(row["offset"]) for name, row in AXIS_BLOCK.items()}
    assert offsets["target"] == [modbus.OFF_TARGET, modbus.OFF_TARGET + 1]
    assert offsets["sequence"] == [modbus.OFF_SEQ]
    assert offsets["axis status"] == [modbus.OFF_STATUS]
    assert offsets["actual position"] == [modbus.OFF_POSITION, modbus.OFF_POSITION + 1]
    assert offsets["done sequence"] == [modbus.OFF_DONE]
    assert offsets["fault code"] == [modbus.OFF_FAULT]
    assert offsets["last stroke"] == [modbus.OFF_LAST, modbus.OFF_LAST + 1]
    shape = offsets["shift kind"] + offsets["line"] + offsets["first, last cell"]
    assert shape == list(range(modbus.OFF_SHAPE, modbus.OFF_SHAPE + modbus.SHAPE_WORDS))
    assert offsets["stroke count"] == [modbus.OFF_STROKES]
    status = bits(MACHINE_BLOCK["machine status"]["meaning"])
    assert status == {
        "pressed": modbus.MACHINE_ESTOP,
        "faulted": modbus.MACHINE_FAULTED,
        "busy": modbus.MACHINE_BUSY,
    }
    axis = bits(AXIS_BLOCK["axis status"]["meaning"])
    assert axis == {
        "busy": modbus.AXIS_BUSY,
        "faulted": modbus.AXIS_FAULTED,
        "homed": modbus.AXIS_HOMED,
    }
    commands = MACHINE_BLOCK["machine command"]["meaning"]
    assert [commands.index(f"{n} ") for n in (1, 2, 3)] == sorted(
        commands.index(f"{n} ") for n in (1, 2, 3)
    )
    assert (modbus.CMD_RESET, modbus.CMD_QUICK_STOP, modbus.CMD_HOME) == (1, 2, 3)
    assert "1 reset faults, 2 quick stop, 3 home" in commands
    assert {int(r["code"]): r["name"] for r in FAULTS} == base.FAULT_NAMES
    axis_image = next(r for r in IMAGE if r["address"].startswith("1 + W"))
    assert f"{modbus.IMAGE_AXIS_WORDS} i" in axis_image["address"]


@pytest.fixture(params=[3, 2], ids=["map3", "map2"])
def any_map(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[Mock, int]]:
    version: int = request.param
    running = start_mock(tmp_path, {}, tables={"fieldbus.modbus": {"map": version}})
    yield running, version
    running.stop()


async def registers(client: AsyncModbusTcpClient, address: int, count: int) -> list[int]:
    answer = await client.read_holding_registers(address, count=count, device_id=1)
    assert not answer.isError(), (address, answer)
    return list(answer.registers)


@pytest.mark.slow
def test_a_live_loom_answers_at_the_documented_addresses(any_map):
    mock, version = any_map
    base_at, stride = block()
    axes = ROWS + COLS + (6 if version == 3 else 3)  # map 3: weft_x, weft_y, weft_z
    assert axes == len(documented_axes(Machine(**MACHINE), version))
    axis = {name: addresses(row["offset"]) for name, row in AXIS_BLOCK.items()}

    async def scenario() -> None:
        client = AsyncModbusTcpClient("127.0.0.1", port=mock.ports["modbus"], timeout=2, retries=0)
        assert await client.connect()
        try:
            head = await registers(client, 0, 4)
            assert head == [version, axes, ROWS, COLS]
            assert MACHINE_BLOCK["map version"]["meaning"].startswith(
                "3 (2 when the loom serves map 2)"
            )
            # a stroke of row 0 (no cases on it) by the documented target and sequence
            row0 = base_at
            seq = 7
            high, low = divmod(PITCH_UM, 1 << 16)
            written = await client.write_registers(
                row0 + axis["target"][0], [high, low, seq], device_id=1
            )
            assert not written.isError(), written
            deadline = time.monotonic() + 10
            while (await registers(client, row0 + axis["done sequence"][0], 1))[0] != seq:
                assert time.monotonic() < deadline, "the stroke never completed"
                await asyncio.sleep(0.01)
            whole = await registers(client, row0, stride)
            last = axis["last stroke"]
            assert (whole[last[0]] << 16) | whole[last[1]] == PITCH_UM
            assert whole[axis["fault code"][0]] == 0
            shape = axis["shift kind"] + axis["line"] + axis["first, last cell"]
            assert [whole[i] for i in shape] == [1, 0, 0, COLS - 1]  # row 0, every cell
            col0 = await registers(client, base_at + stride * ROWS, stride)
            assert [col0[i] for i in shape] == [2, 0, 0, ROWS - 1]
            assert whole[axis["stroke count"][0]] == (1 if version == 3 else 0)
            # a write to a register the doc marks R is refused
            refused = await client.write_register(first(MACHINE_BLOCK, "rows"), 9, device_id=1)
            assert refused.isError() and refused.exception_code == ExcCodes.ILLEGAL_ADDRESS
            # past the last axis block, nothing is mapped
            past = await client.read_holding_registers(
                base_at + stride * axes, count=1, device_id=1
            )
            assert past.isError() and past.exception_code == ExcCodes.ILLEGAL_ADDRESS
            claim = first(MACHINE_BLOCK, "owner: claim id")
            owner = await client.read_holding_registers(claim, count=4, device_id=1)
            assert owner.isError() is (version == 2)  # the claim is map 3's
            await check_inputs(client, mock, version, axes, whole)
            if version == 3:
                await check_weft_axes(client, mock)
        finally:
            client.close()

    asyncio.run(asyncio.wait_for(scenario(), 60))


async def check_weft_axes(client: AsyncModbusTcpClient, mock: Mock) -> None:
    """Map 3: each positioning axis at its documented block takes an absolute target and
    stays there (a stroke would go back home)."""
    base_at, stride = block()
    axis = {name: addresses(row["offset"]) for name, row in AXIS_BLOCK.items()}
    indexes = {v: k for k, v in documented_axes(Machine(**MACHINE)).items()}
    targets = [("weft_x", 36_000), ("weft_y", -8_250), ("weft_z", 30_000)]
    for seq, (name, target) in enumerate(targets, start=1):
        at = base_at + stride * indexes[name]
        written = await client.write_registers(
            at + axis["target"][0], [*modbus.int32_words(target), seq], device_id=1
        )
        assert not written.isError(), written
        deadline = time.monotonic() + 10
        while (await registers(client, at + axis["done sequence"][0], 1))[0] != seq:
            assert time.monotonic() < deadline, f"{name} never completed"
            await asyncio.sleep(0.01)
        words = await registers(client, at, stride)
        position = axis["actual position"]
        assert modbus.words_int32(words[position[0]], words[position[1]]) == target
        assert [words[i] for i in axis["shift kind"]] == [0]
        state = await request("127.0.0.1", mock.ports["control"], {"cmd": "state"})
        assert state["axes"][name]["position"] == target


async def check_inputs(
    client: AsyncModbusTcpClient, mock: Mock, version: int, axes: int, row0: list[int]
) -> None:
    """The discrete inputs and (map 3) the status image, at the documented addresses."""
    state = await request("127.0.0.1", mock.ports["control"], {"cmd": "state"})
    occupied = [bool(cell) for row in state["occupancy"] for cell in row]
    assert [r["address"] for r in INPUTS] == ["r * C + c", "R * C"]
    sensed = await client.read_discrete_inputs(0, count=ROWS * COLS + 1, device_id=1)
    assert not sensed.isError(), sensed
    assert list(sensed.bits[: ROWS * COLS]) == occupied
    assert sensed.bits[ROWS * COLS] is False  # the e-stop, not pressed
    words = -(-ROWS * COLS // 16)  # W
    image = await client.read_input_registers(0, count=1 + words + 8 * axes, device_id=1)
    if version == 2:
        assert image.isError() and image.exception_code == ExcCodes.ILLEGAL_ADDRESS
        return
    assert not image.isError(), image
    got = list(image.registers)
    status = await registers(client, first(MACHINE_BLOCK, "machine status"), 1)
    assert got[0] == status[0]
    cells = [bool(got[1 + i // 16] >> (i % 16) & 1) for i in range(ROWS * COLS)]
    assert cells == occupied
    axis = {name: addresses(row["offset"]) for name, row in AXIS_BLOCK.items()}
    named = [
        "axis status",
        "actual position",
        "done sequence",
        "fault code",
        "last stroke",
        "stroke count",
    ]
    held = [row0[i] for name in named for i in axis[name]]
    assert got[1 + words : 1 + words + 8] == held  # axis 0, as its holding registers
