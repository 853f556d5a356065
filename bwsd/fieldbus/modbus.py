"""Modbus TCP backend: the register map of docs/fieldbus-modbus.md over pymodbus.

The map's constants and codecs at the top are pure and shared with the mock loom's server;
``ModbusBus`` is the client. A lost connection is reported once, as FieldbusConnectionError,
and the next call reconnects with the base class's backoff (pymodbus's own reconnect is off).
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Iterable, Sequence
from dataclasses import fields
from functools import partial
from typing import TYPE_CHECKING

from pymodbus.client import AsyncModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.pdu import ModbusPDU

from bwsd.errors import ConfigError
from bwsd.fieldbus.axes import Axis, machine_axes, moved_cells
from bwsd.fieldbus.base import (
    AxisState,
    BusSettings,
    Fieldbus,
    FieldbusConnectionError,
    FieldbusError,
    FieldbusTimeout,
    MachineState,
    poll_waits,
)
from bwsd.limits import (
    MODBUS_AXIS_BASE,
    MODBUS_AXIS_STRIDE,
    MODBUS_MAX_AXES,
    MODBUS_MAX_CELLS,
)
from bwsd.twin.machine import Machine

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from bwsd.config import Config

# ----- the register map (docs/fieldbus-modbus.md) -----
# 2: registers +10 .. +13 of a shift axis's block say which cells it moves;
# 3: the claim (6 .. 9), the stroke counter (+14) and the status image after the axis blocks
MAP_VERSION = 3
MAP_VERSIONS = (2, 3)
REG_VERSION, REG_AXES, REG_ROWS, REG_COLS, REG_STATUS, REG_COMMAND = range(6)
REG_OWNER, OWNER_WORDS = 6, 4  # claim id (2 words), pid (2 words); map 3
MACHINE_ESTOP, MACHINE_FAULTED, MACHINE_BUSY = 1, 2, 4  # bits of REG_STATUS
CMD_NONE, CMD_RESET, CMD_QUICK_STOP, CMD_HOME = 0, 1, 2, 3
AXIS_BASE, AXIS_STRIDE = MODBUS_AXIS_BASE, MODBUS_AXIS_STRIDE
OFF_TARGET, OFF_SEQ, OFF_STATUS, OFF_POSITION, OFF_DONE, OFF_FAULT, OFF_LAST = 0, 2, 3, 4, 6, 7, 8
OFF_SHAPE = 10  # +10 kind, +11 line, +12 first cell, +13 last cell (shift axes)
SHAPE_WORDS = 4
OFF_STROKES = 14  # map 3: set-points completed, mod 65536
IMAGE_AXIS_WORDS = 8  # status, position (2), done, fault, last stroke (2), strokes
SHAPE_KINDS = {"row": 1, "col": 2}  # other axes read 0 in all four
AXIS_BUSY, AXIS_FAULTED, AXIS_HOMED = 1, 2, 4  # bits of OFF_STATUS
SEQ_MAX = 0x7FFF
MAX_READ_REGISTERS = 125  # per request, by the Modbus specification
MAX_READ_BITS = 2000
MAX_CELLS, MAX_AXES = MODBUS_MAX_CELLS, MODBUS_MAX_AXES  # bwsd.limits: checked at config load
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1


def axis_address(index: int) -> int:
    """First holding register of axis ``index``'s block."""
    return AXIS_BASE + AXIS_STRIDE * index


def image_words(cells: int, axes: int) -> int:
    """Registers of the status image: machine status, occupancy, a record per axis."""
    return 1 + occupancy_words(cells) + IMAGE_AXIS_WORDS * axes


def occupancy_words(cells: int) -> int:
    """Registers of the occupancy bits in the image, 16 a register, cell 0 in bit 0."""
    return -(-cells // 16)


def map_problem(machine: Machine) -> str:
    """Why ``machine`` does not fit this map ("" when it does); the status image of map 3
    (input registers) always fits where the axis blocks do."""
    cells, axes = machine.rows * machine.cols, len(machine_axes(machine))
    if cells > MAX_CELLS:
        return (
            f"the Modbus map addresses at most {MAX_CELLS} cells, the machine has "
            f"{machine.rows} x {machine.cols}"
        )
    if axes > MAX_AXES:
        return (
            f"the Modbus map addresses at most {MAX_AXES} axes, the machine has {axes} "
            f"({machine.rows} rows, {machine.cols} cols, "
            f"{3 + len(machine.weft_axes)} weft and take-up axes, "
            f"{len(machine.segments)} segments)"
        )
    return ""


def version_problem(machine: Machine, version: int) -> str:
    """Why map ``version`` cannot serve ``machine`` ("" when it can): map 2 has no weft
    positioning axes."""
    if version < 3 and machine.weft_axes:
        return (
            f"Modbus map {version} has no weft positioning axes; the machine has weft_"
            f"{', weft_'.join(machine.weft_axes)} ([machine] weft_axes)"
        )
    return ""


def axis_shape(machine: Machine, axis: Axis) -> list[int]:
    """Registers +10 .. +13 of an axis block: kind, line, first and last cell it moves."""
    kind = SHAPE_KINDS.get(axis.kind, 0)
    if not kind or axis.line is None:
        return [0] * SHAPE_WORDS
    return [kind, axis.line, *moved_cells(machine, axis)]


def estop_input(machine: Machine) -> int:
    """Discrete input of the emergency stop (after the occupancy sensors)."""
    return machine.rows * machine.cols


def int32_words(value: int) -> tuple[int, int]:
    """A signed 32-bit value as two registers, high word first."""
    if not INT32_MIN <= value <= INT32_MAX:
        raise ValueError(f"{value} does not fit in 32 bits")
    raw = value & 0xFFFFFFFF
    return raw >> 16, raw & 0xFFFF


def words_int32(high: int, low: int) -> int:
    """Two registers, high word first, as a signed 32-bit value."""
    raw = (high << 16) | low
    return raw - (1 << 32) if raw & 0x80000000 else raw


def decode_axis(words: Sequence[int]) -> AxisState:
    """One axis block (at least 10 registers) as an AxisState."""
    return AxisState(
        position=words_int32(words[OFF_POSITION], words[OFF_POSITION + 1]),
        busy=bool(words[OFF_STATUS] & AXIS_BUSY),
        done_seq=words[OFF_DONE],
        fault=words[OFF_FAULT],
        last_stroke=words_int32(words[OFF_LAST], words[OFF_LAST + 1]),
    )


def decode_image(
    words: Sequence[int], rows: int, cols: int
) -> tuple[int, npt.NDArray[np.bool_], list[AxisState]]:
    """The status image (or its first part: the axes it covers) as machine status, the
    occupancy grid and the axes' states."""
    import numpy as np  # here, not at the top: the mock loom imports this module without it

    n = occupancy_words(rows * cols)
    packed = np.array(words[1 : 1 + n], dtype="<u2").view(np.uint8)
    bits = np.unpackbits(packed, bitorder="little")[: rows * cols].astype(np.bool_)
    axes = []
    for at in range(1 + n, len(words) - IMAGE_AXIS_WORDS + 1, IMAGE_AXIS_WORDS):
        record = words[at : at + IMAGE_AXIS_WORDS]
        axes.append(
            AxisState(
                position=words_int32(record[1], record[2]),
                busy=bool(record[0] & AXIS_BUSY),
                done_seq=record[3],
                fault=record[4],
                last_stroke=words_int32(record[5], record[6]),
                strokes=record[7],
            )
        )
    return words[0], bits.reshape(rows, cols), axes


def read_spans(start: int, count: int, limit: int) -> list[tuple[int, int]]:
    """(address, count) requests covering ``count`` items from ``start``, ``limit`` each."""
    return [(a, min(limit, start + count - a)) for a in range(start, start + count, limit)]


def _runs(indices: Iterable[int]) -> list[tuple[int, int]]:
    """Sorted indices as half-open runs of consecutive numbers."""
    runs: list[tuple[int, int]] = []
    for i in indices:
        if runs and runs[-1][1] == i:
            runs[-1] = (runs[-1][0], i + 1)
        else:
            runs.append((i, i + 1))
    return runs


# ----- the client -----
Send = Callable[[AsyncModbusTcpClient], Awaitable[ModbusPDU]]


class ModbusBus(Fieldbus):
    """The machine's actuators behind one Modbus TCP server (unit ``device_id``)."""

    def __init__(
        self,
        machine: Machine,
        settings: BusSettings,
        host: str,
        port: int,
        device_id: int,
        map_version: int = MAP_VERSION,
    ) -> None:
        if map_version not in MAP_VERSIONS:
            raise FieldbusError(f"Modbus map {map_version}: bwsd reads maps 2 and 3")
        problem = map_problem(machine) or version_problem(machine, map_version)
        if problem:
            raise FieldbusError(problem)
        super().__init__(machine, settings)
        self.host = host
        self.port = port
        self.device_id = device_id
        self.map_version = map_version
        self._client: AsyncModbusTcpClient | None = None
        self._lost = False  # the server closed the connection; not yet reported
        self._gate = asyncio.Lock()  # one request on the wire at a time (as pymodbus sends)
        self._connecting = asyncio.Lock()  # one connection attempt at a time
        self._inflight: asyncio.Future[ModbusPDU] | None = None  # the request on the wire
        self._gone: AsyncModbusTcpClient | None = None  # the last client whose link closed
        self._distrusted: AsyncModbusTcpClient | None = None  # one that left a request unanswered

    @classmethod
    def from_config(cls, config: Config) -> ModbusBus:
        """Build the bus from the tables [fieldbus] and [fieldbus.modbus]."""
        bus, modbus = config.table("fieldbus"), config.table("fieldbus.modbus")
        problem = map_problem(config.machine)
        if problem:  # its cells are checked at load: more axes than the map has blocks
            raise ConfigError(problem, path=config.path, table="machine", key="segments")
        settings = BusSettings(**{f.name: bus[f.name] for f in fields(BusSettings)})
        return cls(
            config.machine,
            settings,
            modbus["host"],
            modbus["port"],
            modbus["device_id"],
            modbus["map"],
        )

    @property
    def where(self) -> str:
        """The server, as error messages name it."""
        return f"Modbus TCP {self.host}:{self.port} unit {self.device_id}"

    # ----- hooks -----
    async def _open(self) -> None:
        self._drop()
        client = AsyncModbusTcpClient(
            self.host,
            port=self.port,
            timeout=self.settings.io_timeout,
            retries=0,
            reconnect_delay=0,  # no background reconnect: the next call reconnects
            trace_connect=lambda up: self._on_connect(client, up),
        )
        self._client = client
        if not await client.connect():
            self._client = None
            raise FieldbusConnectionError(f"{self.where}: connection refused or no answer")
        await self._check_map()

    async def _close(self) -> None:
        self._drop()

    async def _write_setpoint(self, axis: Axis, target: int, seq: int) -> None:
        try:
            high, low = int32_words(target)
        except ValueError as exc:
            raise FieldbusError(f"{self.where}: axis {axis.name}: target {exc}") from None
        address = axis_address(axis.index)
        await self._request(
            address,
            lambda c: c.write_registers(address, [high, low, seq], device_id=self.device_id),
        )

    async def _read_state(self, axes: Sequence[int] | None = None) -> MachineState:
        if self.map_version >= 3:
            return await self._read_image(axes)
        wanted = range(len(self.axes)) if axes is None else sorted(set(axes))
        groups = _runs(wanted)
        cells = self.machine.rows * self.machine.cols
        blocks = [
            await self._read_registers(axis_address(lo), AXIS_STRIDE * (hi - lo))
            for lo, hi in groups
        ]
        bits = await self._read_inputs(0, estop_input(self.machine) + 1)
        read = {
            i: decode_axis(words[(i - lo) * AXIS_STRIDE : (i - lo + 1) * AXIS_STRIDE])
            for (lo, hi), words in zip(groups, blocks, strict=True)
            for i in range(lo, hi)
        }
        import numpy as np  # as in decode_image

        grid = np.array(bits[:cells], dtype=np.bool_).reshape(self.machine.rows, self.machine.cols)
        return self._merge(read, grid, bool(bits[cells]))

    async def _read_image(self, axes: Sequence[int] | None) -> MachineState:
        """Map 3: the status image (input registers from 0) up to the last axis asked for, in
        one request where the protocol's 125 registers allow it (more, sent at once, where
        not)."""
        last = len(self.axes) - 1 if axes is None else max(axes, default=-1)
        count = image_words(self.machine.rows * self.machine.cols, last + 1)
        words: list[int] = []
        for address, n in read_spans(0, count, MAX_READ_REGISTERS):
            response = await self._request(address, self._image(address, n))
            words += response.registers[:n]
        status, grid, read = decode_image(words, self.machine.rows, self.machine.cols)
        return self._merge(dict(enumerate(read)), grid, bool(status & MACHINE_ESTOP))

    async def _claim(self, ident: int, pid: int) -> tuple[int, int] | None:
        if self.map_version < 3:
            return None  # map 2 has no claim: the state folder's lock is the only check
        words = [*divmod(ident, 0x10000), *divmod(pid, 0x10000)]
        claim = partial(self._write, REG_OWNER, words)
        response = await self._request(REG_OWNER, claim, refusals=(ExcCodes.DEVICE_BUSY,))
        if not response.isError():
            return None
        held = await self._read_registers(REG_OWNER, OWNER_WORDS)
        return (held[0] << 16) | held[1], (held[2] << 16) | held[3]

    async def _quick_stop(self) -> None:
        await self._machine_command(CMD_QUICK_STOP)

    async def _reset_faults(self) -> None:
        await self._machine_command(CMD_RESET)

    async def _home(self) -> None:
        await self._machine_command(CMD_HOME)

    # ----- requests -----
    async def _machine_command(self, code: int) -> None:
        """Write the machine command and wait until the server has acted (reads back 0)."""
        await self._request(
            REG_COMMAND, lambda c: c.write_register(REG_COMMAND, code, device_id=self.device_id)
        )
        loop = asyncio.get_running_loop()
        limit = loop.time() + self.settings.timeout
        waits = poll_waits(self.settings.poll_max)
        while (await self._read_registers(REG_COMMAND, 1))[0] != CMD_NONE:
            if loop.time() > limit:
                raise FieldbusTimeout(
                    f"{self.where}: machine command {code} was not taken", lost=False
                )
            await asyncio.sleep(next(waits))

    async def _read_registers(self, start: int, count: int) -> list[int]:
        """Holding registers, in as few requests as the protocol allows."""
        words: list[int] = []
        for address, n in read_spans(start, count, MAX_READ_REGISTERS):
            response = await self._request(address, self._holding(address, n))
            words += response.registers[:n]
        return words

    async def _read_inputs(self, start: int, count: int) -> list[bool]:
        bits: list[bool] = []
        for address, n in read_spans(start, count, MAX_READ_BITS):
            response = await self._request(address, self._inputs(address, n))
            bits += response.bits[:n]
        return bits

    def _holding(self, address: int, count: int) -> Send:
        return lambda c: c.read_holding_registers(address, count=count, device_id=self.device_id)

    def _write(
        self, address: int, words: list[int], client: AsyncModbusTcpClient
    ) -> Awaitable[ModbusPDU]:
        return client.write_registers(address, words, device_id=self.device_id)

    def _image(self, address: int, count: int) -> Send:
        return lambda c: c.read_input_registers(address, count=count, device_id=self.device_id)

    def _inputs(self, address: int, count: int) -> Send:
        return lambda c: c.read_discrete_inputs(address, count=count, device_id=self.device_id)

    async def _request(self, address: int, send: Send, refusals: tuple[int, ...] = ()) -> ModbusPDU:
        """One request, its failures mapped to our errors by phase; an exception response
        with a code of ``refusals`` is returned to the caller."""
        client = await self._ready()
        try:
            response = await self._send(client, send)
        except asyncio.CancelledError:
            task = asyncio.current_task()
            if self._lost_now(client) and (task is None or not task.cancelling()):
                self._drop()
                raise FieldbusConnectionError(f"{self.where}: connection lost") from None
            raise
        except ConnectionException as exc:
            self._drop()
            raise FieldbusConnectionError(f"{self.where}: not connected ({exc})") from None
        except ModbusIOException:
            lost = self._lost or not client.connected
            self._drop()  # a late answer must never be taken for the next request's
            if lost:
                raise FieldbusConnectionError(f"{self.where}: connection lost") from None
            raise FieldbusTimeout(
                f"{self.where}: no answer at address {address} within "
                f"{self.settings.io_timeout:g} s"
            ) from None
        except ModbusException as exc:
            raise FieldbusError(f"{self.where}: address {address}: {exc}") from None
        if response.isError() and response.exception_code not in refusals:
            raise FieldbusError(
                f"{self.where}: address {address} refused "
                f"(exception code {response.exception_code})"
            )
        return response

    async def _send(self, client: AsyncModbusTcpClient, send: Send) -> ModbusPDU:
        """Send one request on ``client`` when the one before it is answered. A caller
        cancelled meanwhile stops waiting, but a request on the wire keeps the connection
        until its answer (or its timeout): what is sent next (a quick stop after a cut
        move) follows it on the same connection, in order, and no late answer is taken
        for another request's."""
        await self._gate.acquire()
        try:
            if self._lost or client is not self._client:  # lost while this one waited
                raise ConnectionException("connection lost")
            inflight = asyncio.ensure_future(send(client))
        except BaseException:
            self._gate.release()
            raise
        self._inflight = inflight
        inflight.add_done_callback(partial(self._answered, client))
        return await asyncio.shield(inflight)

    def _answered(self, client: AsyncModbusTcpClient, inflight: asyncio.Future[ModbusPDU]) -> None:
        """The request on the wire ended: the next one may go. One whose caller had gone
        and that got no answer leaves a connection that cannot be trusted: it is dropped."""
        if self._inflight is inflight:
            self._inflight = None
        self._gate.release()
        unanswered = not inflight.cancelled() and isinstance(
            inflight.exception(), ModbusIOException
        )
        if unanswered and client is self._client:
            self._distrusted = client  # the next request connects again

    async def _ready(self) -> AsyncModbusTcpClient:
        """The connected client: report a lost connection once, else (re)connect (one
        attempt at a time: requests that wait meanwhile take its result)."""
        if self._lost:
            self._drop()
            raise FieldbusConnectionError(f"{self.where}: connection lost")
        if self._client is not None and self._client is self._distrusted:
            self._drop()
        if self._client is None or not self._client.connected:
            async with self._connecting:
                if self._client is None or not self._client.connected:
                    await self.connect()
        client = self._client
        if client is None:
            raise FieldbusConnectionError(f"{self.where}: not connected")
        return client

    def _drop(self) -> None:
        """Forget the client (and any loss it reported); never raises."""
        client, self._client = self._client, None
        self._lost = False
        if client is not None:
            client.close()

    async def _check_map(self) -> None:
        """Refuse a server whose map or machine differs from ours, segments included."""
        words = await self._read_registers(REG_VERSION, REG_COLS + 1)
        want = [self.map_version, len(self.axes), self.machine.rows, self.machine.cols]
        if words != want:
            self._drop()
            raise FieldbusError(
                f"{self.where}: map version, axes, rows, cols are {words}, expected {want}"
            )
        segments = [axis for axis in self.axes if axis.span is not None]
        if not segments:
            return
        first = segments[0].index  # the segments are the last axes, one run of blocks
        blocks = await self._read_registers(axis_address(first), AXIS_STRIDE * len(segments))
        for axis in segments:
            at = AXIS_STRIDE * (axis.index - first) + OFF_SHAPE
            got, expected = blocks[at : at + SHAPE_WORDS], axis_shape(self.machine, axis)
            if got != expected:
                self._drop()
                raise FieldbusError(
                    f"{self.where}: axis {axis.index} moves kind, line, first, last cell "
                    f"{got}, expected {expected} (segment {axis.name})"
                )

    def _on_connect(self, client: AsyncModbusTcpClient, up: bool) -> None:
        """The transport closed: the request on the wire fails now (pymodbus would wait
        for its answer until the I/O timeout), the ones waiting fail at the gate."""
        if not up and client is self._client:
            self._lost = True
            self._gone = client
            if self._inflight is not None:
                self._inflight.cancel()

    def _lost_now(self, client: AsyncModbusTcpClient) -> bool:
        """The request on ``client`` was cancelled because its connection closed."""
        return self._gone is client
