"""A socketcand hub: the mock loom's CAN bus over TCP.

Speaks the raw mode of the socketcand protocol to any number of clients: the hub greets
``< hi >``, answers ``< open CHANNEL >`` and ``< rawmode >`` with ``< ok >``, takes
``< send ID DLC B0 B1 ... >`` and delivers ``< frame ID SECONDS.MICROS DATAHEX >``. Every frame
a client sends goes to every other client and to an in-process python-can bus (interface
``virtual``, channel ``local_channel``) where the simulated nodes live; every frame on that
bus goes to every client. Faults come from a ``Faults`` object: ``mute`` silences the hub
both ways, a rise of ``drops`` resets every client connection.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import struct
import time
import uuid

import can

from simulator_hw.loom import Faults

log = logging.getLogger(__name__)

# Frames wait this long after the rawmode ack: python-can reads the ack with one recv and
# compares it whole, so nothing may arrive glued to it.
GRACE = 0.05  # s
DROP_POLL = 0.01  # s between looks at faults.drops
MAX_PENDING_TEXT = 4096  # characters of a command without its closing '>'


def parse_send(words: list[str]) -> can.Message | None:
    """The frame of a ``send ID DLC B0 ...`` command split into words (None: malformed)."""
    try:
        ident, dlc = int(words[1], 16), int(words[2], 16)
        data = bytes(int(b, 16) for b in words[3 : 3 + dlc])
    except (IndexError, ValueError):
        return None
    extended = len(words[1]) > 3
    if len(data) != dlc or dlc > 8 or ident > (0x1FFFFFFF if extended else 0x7FF):
        return None
    return can.Message(arbitration_id=ident, is_extended_id=extended, data=data)


def format_frame(msg: can.Message, now: float) -> bytes:
    """A frame as the hub delivers it."""
    ident = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
    return f"< frame {ident} {now:.6f} {bytes(msg.data).hex().upper()} >".encode("ascii")


class _Client(asyncio.Protocol):
    """One TCP client of the hub."""

    def __init__(self, hub: SocketcandHub) -> None:
        self.hub = hub
        self.transport: asyncio.Transport | None = None
        self.text = ""
        self.opened = False
        self.raw = False
        self.live = False  # frames go out (rawmode, and the grace after its ack is over)
        self.pending: list[bytes] = []

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.hub._clients.add(self)
        transport.write(b"< hi >")

    def connection_lost(self, exc: Exception | None) -> None:
        self.hub._clients.discard(self)

    def data_received(self, data: bytes) -> None:
        self.text += data.decode("ascii", "replace")
        while (end := self.text.find(">")) >= 0:
            start = self.text.find("<")
            words = self.text[start + 1 : end].split() if 0 <= start < end else []
            self.text = self.text[end + 1 :]
            if words:
                self._command(words)
        if len(self.text) > MAX_PENDING_TEXT:
            self.text = ""

    def _command(self, words: list[str]) -> None:
        verb = words[0]
        if verb == "open" and not self.opened:
            self.opened = words[1:] == [self.hub.channel]
            self._write(b"< ok >" if self.opened else b"< error could not open bus >")
        elif verb == "rawmode" and self.opened and not self.raw:
            self.raw = True
            self._write(b"< ok >")
            asyncio.get_running_loop().call_later(GRACE, self._go_live)
        elif verb == "send" and self.opened:
            msg = parse_send(words)
            if msg is None:
                log.debug("malformed send: %s", " ".join(words))
            else:
                self.hub._from_client(self, msg)
        else:
            log.debug("ignored: %s", " ".join(words))

    def _go_live(self) -> None:
        self.live = True
        for frame in self.pending:
            self._write(frame)
        self.pending.clear()

    def deliver(self, frame: bytes) -> None:
        if self.live:
            self._write(frame)
        elif self.raw:
            self.pending.append(frame)

    def _write(self, data: bytes) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(data)

    def reset(self) -> None:
        """Close the connection with a TCP reset, as a pulled cable would end it."""
        if self.transport is None:
            return
        sock = self.transport.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        self.transport.abort()


class SocketcandHub:
    """The hub on (host, port); ``port`` 0 picks a free one (read it after ``start``)."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        faults: Faults | None = None,
        channel: str = "can0",
        local_channel: str | None = None,
    ) -> None:
        self.host = host
        self._port = port
        self.faults = faults if faults is not None else Faults()
        self.channel = channel
        self.local_channel = local_channel or f"socketcand-hub-{uuid.uuid4().hex}"
        self._clients: set[_Client] = set()
        self._server: asyncio.Server | None = None
        self._bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None
        self._watch: asyncio.Task[None] | None = None
        self.dropped = 0  # frames not relayed because of mute

    @property
    def port(self) -> int:
        return self._port

    @property
    def clients(self) -> int:
        """How many TCP clients are connected."""
        return len(self._clients)

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        self._bus = can.Bus(interface="virtual", channel=self.local_channel)
        self._notifier = can.Notifier(self._bus, [self._from_local], timeout=0.05, loop=loop)
        self._server = await loop.create_server(lambda: _Client(self), self.host, self._port)
        self._port = self._server.sockets[0].getsockname()[1]
        self._watch = asyncio.create_task(self._watch_drops(self.faults.drops))

    async def stop(self) -> None:
        if self._watch is not None:
            self._watch.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._watch
        if self._server is not None:
            self._server.close()
            self.drop_clients()
            await self._server.wait_closed()
        if self._notifier is not None:
            await asyncio.to_thread(self._notifier.stop, 1.0)
        if self._bus is not None:
            self._bus.shutdown()
        self._server, self._notifier, self._bus, self._watch = None, None, None, None

    def drop_clients(self) -> None:
        """Reset every client connection at once."""
        for client in list(self._clients):
            client.reset()

    async def _watch_drops(self, seen: int) -> None:
        while True:
            await asyncio.sleep(DROP_POLL)
            if self.faults.drops > seen:
                self.drop_clients()
            seen = self.faults.drops

    def _from_client(self, sender: _Client, msg: can.Message) -> None:
        if self.faults.mute:
            self.dropped += 1
            return
        frame = format_frame(msg, time.time())
        for client in self._clients:
            if client is not sender:
                client.deliver(frame)
        if self._bus is not None:
            self._bus.send(msg)

    def _from_local(self, msg: can.Message) -> None:
        if self.faults.mute:
            self.dropped += 1
            return
        frame = format_frame(msg, time.time())
        for client in self._clients:
            client.deliver(frame)
