"""The PackML tags served to the plant PLC over Modbus TCP (map and handshake: docs/plc.md).

bwsd is the server, the PLC the client, on pymodbus's public server API: a ``SimDevice``
whose action callback sees every access (a read is answered from the controller's status
as it is now, a write of a change request queues the request), and the ``trace_connect``
hook, which closes a connection from an address the allow list lacks before it is read.
One worker task takes the requests in order, outside the callback, through the gate (the
one every door uses), then writes the request register back to 0.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import weakref
from collections.abc import Iterable
from typing import Any, cast

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimAction, SimData, SimDevice

from bwsd.config import Config
from bwsd.controller.facade import Controller
from bwsd.controller.packml import Command
from bwsd.errors import BwsdError, ConfigError
from bwsd.gate import Caller, Gate
from bwsd.logs import Summary
from bwsd.plc.registers import (
    MAP_VERSION,
    REG_CMD_CHANGE_REQUEST,
    REG_CNTRL_CMD,
    REG_COUNT,
    REG_LOAD_REQUEST,
    REG_MAP_VERSION,
    REG_PROGRAM,
    REG_RESUME,
    REG_UNIT_MODE,
    REG_UNIT_MODE_CHANGE_REQUEST,
    REQUEST_REGISTERS,
    U16,
    U32,
    WRITABLE,
    Tags,
    encode,
    u32_words,
    words_u32,
)

log = logging.getLogger(__name__)

HOLDING_FUNCTIONS = frozenset({3, 6, 16, 22, 23})  # every other function code is refused
HEARTBEAT_PERIOD = 1.0  # s
PLC_REASON = "by the PLC"  # the reason given with the PLC's Stop, Hold and Abort
PLC_WHO = "plc"  # who gave a command, in the log

LOOPBACK = ("127.0.0.1", "::1")  # the default allow list
Request = tuple[int, int]  # (request register, the number asked for)
Network = ipaddress.IPv4Network | ipaddress.IPv6Network
REFUSED = Summary(log, "refused PLC connections")
READ_ONLY = Summary(log, "refused PLC writes")


class PlcError(BwsdError):
    """The PLC tag server cannot start."""


def build_device(device_id: int, action: SimAction) -> SimDevice:
    """The map as a SimDevice: the command registers writable, the rest read-only."""
    holding = [
        SimData(REG_MAP_VERSION, values=MAP_VERSION, datatype=DataType.REGISTERS, readonly=True)
    ]
    for address in range(REG_MAP_VERSION + 1, REG_COUNT):
        holding.append(
            SimData(address, datatype=DataType.REGISTERS, readonly=address not in WRITABLE)
        )
    return SimDevice(id=device_id, simdata=holding, action=action)


def networks(allow: Iterable[str]) -> tuple[Network, ...]:
    """The allow list's addresses and networks (``10.0.0.5``, ``10.0.0.0/24``, ``::1``)."""
    found = []
    for entry in allow:
        try:
            found.append(ipaddress.ip_network(entry, strict=False))
        except ValueError:
            raise ConfigError(
                f"{entry[:60]!r} is not an IP address or network", table="plc", key="allow"
            ) from None
    return tuple(found)


def admits(allow: tuple[Network, ...], host: str | None) -> bool:
    """Whether a peer's address is in the allow list (an IPv4-mapped IPv6 as its IPv4)."""
    try:
        address = ipaddress.ip_address((host or "").split("%", 1)[0])
    except ValueError:
        return False
    if address.version == 6 and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    return any(address in network for network in allow)


class PlcTags:
    """Serve a controller's PackML tags on (host, port) as unit ``device_id``; port 0: any.

    Only clients whose address is in ``allow`` (addresses or networks; loopback by default)
    are served; with ``read_only`` every write is refused (a monitoring tap).
    """

    def __init__(
        self,
        controller: Controller,
        host: str = "127.0.0.1",
        port: int = 15502,
        device_id: int = 1,
        *,
        allow: Iterable[str] = LOOPBACK,
        read_only: bool = False,
        heartbeat_period: float = HEARTBEAT_PERIOD,
        gate: Gate | None = None,
    ) -> None:
        self.controller = controller
        self.allow = networks(allow)
        self.read_only = read_only
        self.host = host
        self.port = port
        self.device_id = device_id
        self.heartbeat_period = heartbeat_period
        self._cntrl_cmd = 0
        self._unit_mode = int(controller.status().mode)
        self._resume = 0  # Command.Resume as the PLC wrote it
        self._program = 0  # Command.ProgramId as the PLC wrote it
        self.gate = gate or Gate(controller)
        # the PLC door has no users: the PLC's role is the door's (a read-only tap: viewer)
        self.caller = Caller("plc", PLC_WHO, role="viewer" if read_only else "admin")
        self._pending: set[int] = set()  # request registers whose request is not taken yet
        self._invalid = False
        self._beat = 0
        self._closing = False
        self._queue: asyncio.Queue[Request | None] = asyncio.Queue()
        self._server: ModbusTcpServer | None = None
        self._admitted: weakref.WeakSet[Any] = weakref.WeakSet()  # connections let in
        self._worker: asyncio.Task[None] | None = None
        self._beater: asyncio.Task[None] | None = None

    # ----- lifecycle -----
    async def start(self) -> None:
        """Listen (the actual port is in ``port`` afterwards), then take requests."""
        if self._server is not None:
            raise RuntimeError(f"the PLC tags on port {self.port} are already served")
        device = build_device(self.device_id, self._action)
        server = ModbusTcpServer(
            device, address=(self.host, self.port), trace_connect=self._connected
        )
        self._server = server  # the hook below reads its connections
        try:
            await server.serve_forever(background=True)
        except RuntimeError as exc:
            self._server = None
            raise PlcError(f"the PLC tags cannot listen on {self.host}:{self.port}") from exc
        sockets = getattr(server.transport, "sockets", None)
        if sockets:
            self.port = sockets[0].getsockname()[1]
        self._closing, self._queue = False, asyncio.Queue()
        self._pending.clear()
        supervisor = self.controller.supervisor
        self._worker = supervisor.start(f"plc {self.port} requests", self._work)
        self._beater = supervisor.start(f"plc {self.port} heartbeat", self._beat_forever)

    async def stop(self) -> None:
        """Close every connection; a request being taken is finished, queued ones dropped."""
        server, self._server = self._server, None
        if server is not None:
            await server.shutdown()  # type: ignore[no-untyped-call]
        beater, self._beater = self._beater, None
        if beater is not None:
            beater.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await beater
        worker, self._worker = self._worker, None
        if worker is not None:
            self._closing = True
            self._queue.put_nowait(None)
            await worker

    def _connected(self, up: bool) -> None:
        """pymodbus's ``trace_connect`` hook: a new connection is in the server's
        ``active_connections`` (with its transport) before it reads a byte; one from an
        address the allow list lacks is closed then (tests/plc/test_pymodbus_contract.py
        pins the order this relies on)."""
        server = self._server
        if not up or server is None:
            return
        for protocol in list(server.active_connections.values()):
            transport = protocol.transport
            if transport is None or protocol in self._admitted:
                continue
            peer = transport.get_extra_info("peername")
            if admits(self.allow, peer[0] if peer else None):
                self._admitted.add(protocol)
            else:
                REFUSED.note(
                    "PLC: refused a connection from %s: not in [plc] allow",
                    peer[0] if peer else "an unknown address",
                )
                transport.close()

    # ----- what the PLC reads -----
    def tags(self) -> Tags:
        """Every tag as the controller stands now."""
        st = self.controller.status()
        return Tags(
            cntrl_cmd=self._cntrl_cmd,
            cmd_change_request=int(REG_CMD_CHANGE_REQUEST in self._pending),
            unit_mode=self._unit_mode,
            unit_mode_change_request=int(REG_UNIT_MODE_CHANGE_REQUEST in self._pending),
            state_current=int(st.state),
            unit_mode_current=int(st.mode),
            cmd_invalid=int(self._invalid),
            instruction_index=st.index,
            instruction_count=st.count,
            good_count=st.good & U32,
            stop_reason=int(st.stop_cause),
            heartbeat=self._beat,
            estop=int(bool(st.bus.estop)),
            resume=self._resume,
            resumable=int(st.resumable),
            program=self._program,
            load_request=int(REG_LOAD_REQUEST in self._pending),
            program_id=st.program_id or 0,
        )

    async def _action(
        self,
        func_code: int,
        start: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """Called by pymodbus before every access, with the whole block's registers."""
        if func_code not in HOLDING_FUNCTIONS:
            return ExcCodes.ILLEGAL_FUNCTION
        if values is not None:
            if self.read_only:
                READ_ONLY.note("PLC: refused a write to register %d: [plc] read_only", address)
                return ExcCodes.ILLEGAL_FUNCTION
            return self._write(address, cast(list[int], values))
        registers[REG_MAP_VERSION - start : REG_COUNT - start] = encode(self.tags())
        return None

    # ----- what the PLC writes -----
    def _write(self, address: int, values: list[int]) -> ExcCodes | None:
        """Take the command registers, queue a change request; refuse a request but 0 or 1."""
        written = dict(zip(range(address, address + len(values)), values, strict=True))
        if any(
            written.get(register, 0) not in (0, 1) for register in (*REQUEST_REGISTERS, REG_RESUME)
        ):
            return ExcCodes.ILLEGAL_VALUE
        self._resume = written.get(REG_RESUME, self._resume)
        self._cntrl_cmd = written.get(REG_CNTRL_CMD, self._cntrl_cmd)
        self._unit_mode = written.get(REG_UNIT_MODE, self._unit_mode)
        high, low = (
            written.get(REG_PROGRAM + i, word) for i, word in enumerate(u32_words(self._program))
        )
        self._program = words_u32(high, low)
        asked = {
            REG_CMD_CHANGE_REQUEST: self._cntrl_cmd,
            REG_UNIT_MODE_CHANGE_REQUEST: self._unit_mode,
            REG_LOAD_REQUEST: self._program,
        }
        for register, number in asked.items():
            # a 1 while the same request is still pending is the same request
            if written.get(register) == 1 and register not in self._pending:
                self._pending.add(register)
                self._queue.put_nowait((register, number))
        return None

    async def _work(self) -> None:
        """Take the requests one at a time, in the order they came."""
        while (request := await self._queue.get()) is not None and not self._closing:
            register, number = request
            accepted = await self._take(register, number)
            self._invalid = not accepted
            self._pending.discard(register)

    async def _take(self, register: int, number: int) -> bool:
        """Apply one request through the gate; False when it was refused (the gate and the
        controller log why, at INFO)."""
        try:
            if register == REG_CMD_CHANGE_REQUEST:
                resume = number == Command.START and self._resume == 1
                await self.gate.command(self.caller, number, reason=PLC_REASON, resume=resume)
            elif register == REG_UNIT_MODE_CHANGE_REQUEST:
                await self.gate.set_mode(self.caller, number)
            else:
                await self.gate.load_stored(self.caller, number)
        except BwsdError:
            return False
        except Exception:  # the PLC must still see its request answered
            log.exception("PLC: the request of register %d failed", register)
            return False
        return True

    # ----- what the daemon keeps -----
    async def _beat_forever(self) -> None:
        loop = asyncio.get_running_loop()
        due = loop.time()
        while True:
            due += self.heartbeat_period
            await asyncio.sleep(max(0.0, due - loop.time()))
            self._beat = (self._beat + 1) & U16


def plc_tags(controller: Controller, config: Config, gate: Gate | None = None) -> PlcTags | None:
    """The tags of the config's ``[plc]`` table, or None when it disables them."""
    table = config.table("plc")
    if not table["enabled"]:
        return None
    return PlcTags(
        controller,
        table["host"],
        table["port"],
        table["device_id"],
        allow=table["allow"].split(),
        read_only=table["read_only"],
        gate=gate,
    )
