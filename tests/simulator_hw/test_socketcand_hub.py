"""The socketcand hub over real loopback sockets: raw clients and python-can's client."""

from __future__ import annotations

import asyncio
import contextlib
import re
import threading
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager

import can
import pytest
from can.interfaces.socketcand.socketcand import (
    convert_ascii_message_to_can_message,
    convert_can_message_to_ascii_message,
)

from simulator_hw.loom import Faults
from simulator_hw.socketcand_hub import SocketcandHub, format_frame, parse_send
from tests.timing import scaled

FRAME = re.compile(rb"< frame ([0-9A-F]{3}|[0-9A-F]{8}) \d+\.\d{6} ([0-9A-F]*) >")


def run(scenario: Callable[[], Awaitable[None]]) -> None:
    asyncio.run(asyncio.wait_for(scenario(), 20))


async def until(condition: Callable[[], bool], limit: float = 5.0) -> None:
    async with asyncio.timeout(scaled(limit)):
        while not condition():
            await asyncio.sleep(0.005)


@asynccontextmanager
async def hub_and_local(
    faults: Faults | None = None,
) -> AsyncIterator[tuple[SocketcandHub, can.BusABC]]:
    """A running hub and a python-can bus on its in-process side."""
    hub = SocketcandHub(faults=faults)
    await hub.start()
    local = can.Bus(interface="virtual", channel=hub.local_channel)
    try:
        yield hub, local
    finally:
        local.shutdown()
        await hub.stop()


class RawClient:
    """A socketcand client written against the protocol text, one reply per read."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer, self.buffer = reader, writer, b""

    @classmethod
    async def open(cls, port: int, lag: float = 0.0) -> RawClient:
        """Connect and reach raw mode; ``lag``: a slow reader's delay before each reply."""
        client = cls(*await asyncio.open_connection("127.0.0.1", port))
        assert await client.reader.read(256) == b"< hi >"
        assert await client.command("< open can0 >", lag) == b"< ok >"
        assert await client.command("< rawmode >", lag) == b"< ok >"
        return client

    async def command(self, text: str, lag: float = 0.0) -> bytes:
        self.writer.write(text.encode())
        await asyncio.sleep(lag)
        return await self.reader.read(256)

    async def frame(self) -> can.Message:
        while b">" not in self.buffer:
            chunk = await self.reader.read(256)
            assert chunk, "connection closed"
            self.buffer += chunk
        end = self.buffer.index(b">") + 1
        text, self.buffer = self.buffer[:end], self.buffer[end:]
        assert FRAME.fullmatch(text), text
        return convert_ascii_message_to_can_message(text.decode())

    async def wait_closed(self) -> None:
        """Return once the server closed the connection (frames before that are skipped)."""
        with contextlib.suppress(ConnectionResetError):
            while await self.reader.read(256):
                pass

    def close(self) -> None:
        self.writer.close()


def test_handshake_replies_arrive_alone_even_while_frames_flow():
    async def scenario() -> None:
        async with hub_and_local() as (hub, local):
            stop = threading.Event()

            def flood() -> None:
                while not stop.wait(0.0005):
                    local.send(
                        can.Message(arbitration_id=0x181, data=b"\x01\x02", is_extended_id=False)
                    )

            thread = threading.Thread(target=flood)
            thread.start()
            try:
                clients = [await RawClient.open(hub.port, lag=0.005) for _ in range(5)]
                msg = await clients[0].frame()
                assert (msg.arbitration_id, bytes(msg.data)) == (0x181, b"\x01\x02")
            finally:
                stop.set()
                thread.join()
            for client in clients:
                client.close()

    run(scenario)


def test_frames_go_from_clients_to_the_local_bus_and_back():
    async def scenario() -> None:
        async with hub_and_local() as (hub, local):
            client = await RawClient.open(hub.port)
            client.writer.write(b"< send 601 8 40 41 60 0 0 0 0 0 >")
            got = await asyncio.to_thread(local.recv, 5.0)
            assert got is not None and got.arbitration_id == 0x601
            assert bytes(got.data) == bytes([0x40, 0x41, 0x60, 0, 0, 0, 0, 0])
            local.send(can.Message(arbitration_id=0x1ABCDEF0, data=b"", is_extended_id=True))
            local.send(can.Message(arbitration_id=0x581, data=b"\xff\x00", is_extended_id=False))
            first, second = await client.frame(), await client.frame()
            assert (first.arbitration_id, first.is_extended_id, first.dlc) == (0x1ABCDEF0, True, 0)
            assert (second.arbitration_id, bytes(second.data)) == (0x581, b"\xff\x00")
            client.close()

    run(scenario)


def test_python_can_clients_see_each_others_frames():
    async def scenario() -> None:
        async with hub_and_local() as (hub, local):

            def open_bus() -> can.BusABC:
                return can.Bus(
                    interface="socketcand", host="127.0.0.1", port=hub.port, channel="can0"
                )

            a, b = await asyncio.to_thread(open_bus), await asyncio.to_thread(open_bus)
            try:
                sent = can.Message(arbitration_id=0x123, data=[1, 2, 3], is_extended_id=False)
                await asyncio.to_thread(a.send, sent)
                got_b = await asyncio.to_thread(b.recv, 5.0)
                got_local = await asyncio.to_thread(local.recv, 5.0)
                for got in (got_b, got_local):
                    assert got is not None and got.arbitration_id == 0x123
                    assert bytes(got.data) == b"\x01\x02\x03"
                back = can.Message(arbitration_id=0x7FF, data=b"\x05", is_extended_id=False)
                await asyncio.to_thread(b.send, back)
                got_a = await asyncio.to_thread(a.recv, 5.0)
                assert got_a is not None and (got_a.arbitration_id, bytes(got_a.data)) == (
                    0x7FF,
                    b"\x05",
                )
            finally:
                a.shutdown()
                b.shutdown()

    run(scenario)


def test_mute_drops_frames_both_ways_until_cleared():
    async def scenario() -> None:
        faults = Faults()
        async with hub_and_local(faults) as (hub, local):
            client = await RawClient.open(hub.port)
            faults.mute = True
            local.send(can.Message(arbitration_id=0x701, data=b"\x05", is_extended_id=False))
            client.writer.write(b"< send 602 1 1 >")
            await until(lambda: hub.dropped == 2)
            faults.mute = False
            local.send(can.Message(arbitration_id=0x702, data=b"\x05", is_extended_id=False))
            client.writer.write(b"< send 603 1 2 >")
            assert (await client.frame()).arbitration_id == 0x702
            got = await asyncio.to_thread(local.recv, 5.0)
            assert got is not None and got.arbitration_id == 0x603
            client.close()

    run(scenario)


def test_a_drop_resets_every_client_and_new_ones_are_accepted():
    async def scenario() -> None:
        faults = Faults()
        async with hub_and_local(faults) as (hub, local):
            clients = [await RawClient.open(hub.port) for _ in range(2)]
            faults.drops += 1
            for client in clients:
                await asyncio.wait_for(client.wait_closed(), 5)
                client.close()
            assert hub.clients == 0
            again = await RawClient.open(hub.port)
            local.send(can.Message(arbitration_id=0x100, data=b"", is_extended_id=False))
            assert (await again.frame()).arbitration_id == 0x100
            assert hub.clients == 1
            again.close()

    run(scenario)


def test_wrong_channel_and_malformed_commands():
    async def scenario() -> None:
        async with hub_and_local() as (hub, local):
            reader, writer = await asyncio.open_connection("127.0.0.1", hub.port)
            assert await reader.read(256) == b"< hi >"
            writer.write(b"< open vcan9 >")
            assert (await reader.read(256)).startswith(b"< error")
            writer.write(b"< open can0 >< rawmode >")  # glued commands are taken one by one
            assert await reader.readexactly(12) == b"< ok >< ok >"
            writer.write(b"< send 12 9 1 2 3 4 5 6 7 8 9 >< send zz 1 1 >< send 101 1 7 >")
            got = await asyncio.to_thread(local.recv, 5.0)
            assert got is not None and (got.arbitration_id, bytes(got.data)) == (0x101, b"\x07")
            writer.close()

    run(scenario)


@pytest.mark.parametrize(
    "msg",
    [
        can.Message(
            arbitration_id=0x601, data=[0x40, 0x41, 0x60, 0, 0, 0, 0, 0], is_extended_id=False
        ),
        can.Message(arbitration_id=0x0, data=b"", is_extended_id=False),
        can.Message(arbitration_id=0x18FF1234, data=b"\xaa", is_extended_id=True),
    ],
)
def test_codec_agrees_with_python_can(msg):
    words = convert_can_message_to_ascii_message(msg)[1:-1].split()
    parsed = parse_send(words)
    assert parsed is not None and parsed.equals(msg, timestamp_delta=None)
    back = convert_ascii_message_to_can_message(format_frame(msg, 12.5).decode())
    assert back.equals(msg, timestamp_delta=None, check_direction=False)
    assert back.timestamp == 12.5


@pytest.mark.parametrize(
    "text",
    ["send 601", "send 601 2 1", "send 601 9 1 2 3 4 5 6 7 8 9", "send 6z1 1 1", "send 800 0"],
)
def test_malformed_sends_are_refused(text):
    assert parse_send(text.split()) is None
