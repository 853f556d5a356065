"""What bwsd's Modbus servers (the PLC tags, the mock loom) rely on in pymodbus's server, pinned.

Both are built on pymodbus's public server API: a ``ModbusTcpServer`` serving ``SimDevice``s
whose ``action`` callback sees every access, and the ``trace_connect`` and ``trace_pdu``
hooks. No class of pymodbus is subclassed. A pymodbus upgrade that changes one of these
behaviours fails here, naming it, before a door misbehaves (docs/plc.md, "pymodbus").
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any, cast

import pymodbus
import pytest
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.pdu import ModbusPDU
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

UNIT = 5
Calls = list[tuple[int, int, int, int, list[int] | None]]


def run(scenario: Any) -> Any:
    return asyncio.run(asyncio.wait_for(scenario, 30))


@asynccontextmanager
async def serving(action: Any, **hooks: Any) -> AsyncIterator[tuple[ModbusTcpServer, int]]:
    """A server of one device: registers 0..9 writable, 10..19 read-only, nothing beyond."""
    holding = [
        SimData(0, count=10, datatype=DataType.REGISTERS),
        SimData(10, count=10, datatype=DataType.REGISTERS, readonly=True),
    ]
    device = SimDevice(id=UNIT, simdata=holding, action=action)
    server = ModbusTcpServer(device, address=("127.0.0.1", 0), **hooks)
    await server.serve_forever(background=True)
    sockets = getattr(server.transport, "sockets", None)  # where a port of 0 was bound
    assert sockets, "pymodbus no longer exposes its listener's sockets on .transport"
    try:
        yield server, sockets[0].getsockname()[1]
    finally:
        await server.shutdown()  # type: ignore[no-untyped-call]  # unannotated in pymodbus


async def client(port: int) -> AsyncModbusTcpClient:
    made = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=1, retries=0, reconnect_delay=0)
    assert await made.connect()
    return made


def test_the_pinned_version_is_the_one_these_behaviours_were_checked_on():
    assert pymodbus.__version__.startswith("3.16."), pymodbus.__version__


def test_the_action_sees_reads_and_writes_and_answers_them():
    calls: Calls = []

    async def action(
        func_code: int,
        start: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | None,
    ) -> ExcCodes | None:
        calls.append((func_code, start, address, count, None if values is None else list(values)))
        if values is None:
            registers[address - start] = 1234  # a read answers what the action puts there
        return ExcCodes.DEVICE_BUSY if address == 7 else None

    async def scenario() -> None:
        async with serving(action) as (_, port):
            c = await client(port)
            read = await c.read_holding_registers(2, count=1, device_id=UNIT)
            assert read.registers == [1234]
            assert not (await c.write_registers(3, [5, 6], device_id=UNIT)).isError()
            busy = await c.write_register(7, 1, device_id=UNIT)
            assert busy.isError() and busy.exception_code == ExcCodes.DEVICE_BUSY
            c.close()
        assert calls[0][:4] == (3, 0, 2, 1) and calls[0][4] is None  # func, block start, ...
        assert calls[1] == (16, 0, 3, 2, [5, 6])
        assert calls[2][0] == 6 and calls[2][2] == 7

    run(scenario())


def test_read_only_registers_gaps_and_other_units_are_refused_before_the_action():
    calls: Calls = []

    async def action(*args: Any) -> None:
        calls.append(args)

    async def scenario() -> None:
        async with serving(action) as (_, port):
            c = await client(port)
            readonly = await c.write_register(12, 1, device_id=UNIT)
            assert readonly.isError() and readonly.exception_code == ExcCodes.ILLEGAL_ADDRESS
            beyond = await c.read_holding_registers(20, count=1, device_id=UNIT)
            assert beyond.isError() and beyond.exception_code == ExcCodes.ILLEGAL_ADDRESS
            other = await c.read_holding_registers(0, count=1, device_id=UNIT + 1)
            assert other.isError() and other.exception_code == ExcCodes.DEVICE_FAILURE
            c.close()
        assert calls == []

    run(scenario())


def test_trace_connect_runs_with_the_new_connection_listed_before_it_is_read():
    """The PLC door's allow list: in ``trace_connect(True)`` the new connection is already in
    ``active_connections``, with its transport; closing that transport there answers
    nothing of what the client sent."""
    seen: list[tuple[bool, list[Any]]] = []
    box: dict[str, ModbusTcpServer] = {}

    def connected(up: bool) -> None:
        protocols = list(box["server"].active_connections.values())
        seen.append((up, [p.transport for p in protocols]))
        if up:
            for protocol in protocols:
                if protocol.transport is not None:
                    protocol.transport.close()

    async def action(*args: Any) -> None:
        raise AssertionError("a request of a closed connection reached the device")

    async def scenario() -> None:
        hooks = {"trace_connect": connected}
        async with serving(action, **hooks) as (server, port):
            box["server"] = server
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            request = bytes.fromhex("000100000006") + bytes([UNIT]) + bytes.fromhex("0300000001")
            writer.write(request)
            assert await reader.read(100) == b""  # closed, unanswered
            writer.close()
        up = [transports for flag, transports in seen if flag]
        assert up and all(t is not None for t in up[0])

    run(scenario())


@pytest.mark.slow
def test_trace_pdu_returning_none_leaves_a_request_unanswered():
    """The mock loom's mute: a received request whose trace returns None gets no answer."""

    def trace(sending: bool, pdu: ModbusPDU) -> ModbusPDU | None:
        return pdu if sending or pdu.address != 4 else None

    async def action(*args: Any) -> None:
        return None

    async def scenario() -> None:
        hooks = {"trace_pdu": cast(Callable[[bool, ModbusPDU], ModbusPDU], trace)}
        async with serving(action, **hooks) as (_, port):
            c = await client(port)
            assert not (await c.read_holding_registers(3, count=1, device_id=UNIT)).isError()
            with pytest.raises(pymodbus.exceptions.ModbusIOException):
                await c.read_holding_registers(4, count=1, device_id=UNIT)
            c.close()

    run(scenario())


def test_active_connections_close_and_shutdown_ends_every_connection():
    """The mock loom's drop: closing each of ``active_connections``; and ``shutdown``."""

    async def action(*args: Any) -> None:
        return None

    async def scenario() -> None:
        async with serving(action) as (server, port):
            c = await client(port)
            assert not (await c.read_holding_registers(0, count=1, device_id=UNIT)).isError()
            for connection in list(server.active_connections.values()):
                connection.close()
            await asyncio.sleep(0.1)
            assert not c.connected
            c.close()
            other = await client(port)
        await asyncio.sleep(0.1)
        assert not other.connected  # shutdown closed it
        other.close()

    run(scenario())
