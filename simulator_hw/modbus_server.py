"""The mock loom behind a Modbus TCP server (map: docs/fieldbus-modbus.md).

Served by pymodbus's ``SimDevice``; its action callback runs on every access: a read first
advances the loom to now and refreshes the registers it covers, a write of an axis's
sequence register starts that set-point, a machine command acts and reads back 0. The
injected faults ``mute`` (requests are dropped unanswered) and ``drops`` (every connection
is closed) act on the connections.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Sequence
from typing import cast

from pymodbus.constants import ExcCodes
from pymodbus.pdu import ModbusPDU
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimAction, SimData, SimDevice

from bwsd.fieldbus.base import FieldbusError
from bwsd.fieldbus.modbus import (
    AXIS_BASE,
    AXIS_BUSY,
    AXIS_FAULTED,
    AXIS_HOMED,
    AXIS_STRIDE,
    CMD_HOME,
    CMD_NONE,
    CMD_QUICK_STOP,
    CMD_RESET,
    MACHINE_BUSY,
    MACHINE_ESTOP,
    MACHINE_FAULTED,
    MAP_VERSION,
    MAP_VERSIONS,
    OFF_LAST,
    OFF_SEQ,
    OFF_SHAPE,
    OFF_STATUS,
    OFF_STROKES,
    OFF_TARGET,
    OWNER_WORDS,
    REG_COMMAND,
    REG_OWNER,
    REG_STATUS,
    SEQ_MAX,
    SHAPE_WORDS,
    axis_address,
    axis_shape,
    image_words,
    int32_words,
    map_problem,
    version_problem,
    words_int32,
)
from simulator_hw.loom import AxisSim, Loom

READ_INPUTS = 2  # function code: read discrete inputs
READ_IMAGE = 4  # function code: read input registers (the status image of map 3)
COIL_FUNCTIONS = (1, 5, 15)  # the loom has no coils
DROP_POLL = 0.01  # s between looks at the drop counter


def axis_words(sim: AxisSim) -> list[int]:
    """Registers +3 .. +9 of an axis block (status to last stroke)."""
    status = (
        (AXIS_BUSY if sim.busy else 0)
        | (AXIS_FAULTED if sim.fault else 0)
        | (AXIS_HOMED if sim.homed else 0)
    )
    return [
        status,
        *int32_words(sim.position),
        sim.done_seq,
        sim.fault,
        *int32_words(sim.last_stroke),
    ]


def status_image(loom: Loom) -> list[int]:
    """The whole status image (map 3): machine status, occupancy bits (16 a register, cell 0
    in bit 0, bits past the last cell 0), then each axis's record."""
    cells = [v for row in loom.sensed() for v in row]
    occupancy = [
        sum(1 << j for j, v in enumerate(cells[at : at + 16]) if v)
        for at in range(0, len(cells), 16)
    ]
    return [
        machine_status(loom),
        *occupancy,
        *(w for sim in loom.axes for w in (*axis_words(sim), sim.strokes)),
    ]


def machine_status(loom: Loom) -> int:
    status = MACHINE_ESTOP if loom.estop else 0
    if any(sim.fault for sim in loom.axes):
        status |= MACHINE_FAULTED
    if any(sim.busy for sim in loom.axes):
        status |= MACHINE_BUSY
    return status


def input_words(loom: Loom, first: int, count: int) -> list[int]:
    """Registers [first, first + count) of the discrete inputs, 16 a register, bit 0 first."""
    cols, cells = loom.machine.cols, loom.machine.rows * loom.machine.cols

    def bit(i: int) -> bool:
        return loom.sensor(i // cols, i % cols) if i < cells else i == cells and loom.estop

    return [
        sum(1 << j for j in range(16) if bit(16 * word + j)) for word in range(first, first + count)
    ]


def build_device(
    loom: Loom, device_id: int, action: SimAction, version: int = MAP_VERSION
) -> SimDevice:
    """The map (``version`` 2 or 3) as a SimDevice: read-only registers marked, gaps left
    invalid."""
    m = loom.machine
    holding = [
        SimData(
            0,
            values=[version, len(loom.axes), m.rows, m.cols, 0],
            datatype=DataType.REGISTERS,
            readonly=True,
        ),
        SimData(REG_COMMAND, values=CMD_NONE, datatype=DataType.REGISTERS),
    ]
    if version >= 3:
        holding.append(SimData(REG_OWNER, count=OWNER_WORDS, datatype=DataType.REGISTERS))
    for i, sim in enumerate(loom.axes):
        base = axis_address(i)
        # status .. last stroke are refreshed on every read; the shape never changes
        read_only = [0] * (OFF_SHAPE - OFF_STATUS) + axis_shape(m, sim.axis)
        read_only += [0] * (AXIS_STRIDE - OFF_SHAPE - SHAPE_WORDS)
        holding.append(SimData(base, count=OFF_STATUS, datatype=DataType.REGISTERS))
        holding.append(
            SimData(base + OFF_STATUS, values=read_only, datatype=DataType.REGISTERS, readonly=True)
        )
    inputs = [SimData(0, count=m.rows * m.cols + 1, values=False, datatype=DataType.BITS)]
    coils = [SimData(0, values=False, datatype=DataType.BITS, readonly=True)]
    image = [
        SimData(0, count=image_words(m.rows * m.cols, len(loom.axes)), datatype=DataType.REGISTERS)
    ]
    if version < 3:
        image = [SimData(0, datatype=DataType.INVALID)]  # map 2 has no input registers
    return SimDevice(id=device_id, simdata=(coils, inputs, holding, image), action=action)


class ModbusLoomServer:
    """Serve ``loom`` over Modbus TCP on (host, port) as unit ``device_id``; port 0 picks one.

    A machine the map cannot address (too many cells or axes) is a FieldbusError.
    """

    def __init__(
        self,
        loom: Loom,
        host: str = "127.0.0.1",
        port: int = 15020,
        device_id: int = 1,
        version: int = MAP_VERSION,
    ) -> None:
        problem = map_problem(loom.machine)
        if version not in MAP_VERSIONS:
            problem = f"Modbus map {version}: the mock loom serves maps 2 and 3"
        problem = problem or version_problem(loom.machine, version)
        if problem:
            raise FieldbusError(problem)
        self.version = version
        self.loom = loom
        self.host = host
        self.port = port
        self.device_id = device_id
        self._server: ModbusTcpServer | None = None
        self._watcher: asyncio.Task[None] | None = None
        self._drops_seen = loom.faults.drops

    async def start(self) -> None:
        """Listen (the actual port is in ``port`` afterwards) and watch the drop counter."""
        if self._server is not None:
            raise RuntimeError(f"the Modbus server on port {self.port} is already running")
        device = build_device(self.loom, self.device_id, self._action, self.version)
        trace = cast(Callable[[bool, ModbusPDU], ModbusPDU], self._trace_pdu)
        server = ModbusTcpServer(device, address=(self.host, self.port), trace_pdu=trace)
        try:
            await server.serve_forever(background=True)
        except RuntimeError as exc:
            raise OSError(f"Modbus server cannot listen on {self.host}:{self.port}") from exc
        self._server = server
        sockets = getattr(server.transport, "sockets", None)
        if sockets:
            self.port = sockets[0].getsockname()[1]
        self._drops_seen = self.loom.faults.drops
        self._watcher = asyncio.create_task(self._watch_drops())

    async def stop(self) -> None:
        """Stop listening and close every connection."""
        watcher, self._watcher = self._watcher, None
        if watcher is not None:
            watcher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watcher
        server, self._server = self._server, None
        if server is not None:
            await server.shutdown()  # type: ignore[no-untyped-call]

    # ----- faults on the connections -----
    def _trace_pdu(self, sending: bool, pdu: ModbusPDU) -> ModbusPDU | None:
        """Every received request passes here: None drops it unanswered (pymodbus skips it)."""
        if sending:
            return pdu
        if self._check_drops() or self.loom.faults.mute:
            return None
        return pdu

    def _check_drops(self) -> bool:
        """Close every connection when the drop counter moved; True if it did."""
        if self.loom.faults.drops == self._drops_seen or self._server is None:
            return False
        self._drops_seen = self.loom.faults.drops
        for connection in list(self._server.active_connections.values()):
            connection.close()
        return True

    async def _watch_drops(self) -> None:
        while True:
            await asyncio.sleep(DROP_POLL)
            self._check_drops()

    # ----- the registers -----
    async def _action(
        self,
        func_code: int,
        start: int,
        address: int,
        count: int,
        registers: list[int],
        values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """Called by pymodbus before every access to a block, with the block's registers."""
        if func_code in COIL_FUNCTIONS:
            return ExcCodes.ILLEGAL_ADDRESS
        now = time.monotonic()
        if values is not None:
            return self._write(start, address, registers, cast(list[int], values), now)
        self.loom.tick(now)
        if func_code == READ_IMAGE:
            registers[:] = status_image(self.loom)
        elif func_code == READ_INPUTS:  # bit addresses; count is in registers here
            registers[address // 16 - start : address // 16 - start + count] = input_words(
                self.loom, address // 16, count
            )
        else:
            self._refresh(start, address, count, registers)
        return None

    def _refresh(self, start: int, address: int, count: int, registers: list[int]) -> None:
        """Rewrite the read-only registers in [address, address + count) from the loom."""
        if address <= REG_STATUS < address + count:
            registers[REG_STATUS - start] = machine_status(self.loom)
        for i in self._axes_in(address, address + count):
            at = axis_address(i) + OFF_STATUS - start
            registers[at : at + OFF_LAST + 2 - OFF_STATUS] = axis_words(self.loom.axes[i])
            if self.version >= 3:
                registers[at + OFF_STROKES - OFF_STATUS] = self.loom.axes[i].strokes

    def _write(
        self, start: int, address: int, registers: list[int], values: list[int], now: float
    ) -> ExcCodes | None:
        """Act on a write before it lands; refuse it whole when a value is out of range."""
        end = address + len(values)

        def word(at: int) -> int:
            return values[at - address] if address <= at < end else registers[at - start]

        starts: list[tuple[int, int, int]] = []
        for i in self._axes_in(address, end):
            base = axis_address(i)
            if address <= base + OFF_SEQ < end:
                seq = word(base + OFF_SEQ)
                if not 1 <= seq <= SEQ_MAX:
                    return ExcCodes.ILLEGAL_VALUE
                target = words_int32(word(base + OFF_TARGET), word(base + OFF_TARGET + 1))
                starts.append((i, target, seq))
        if address < REG_OWNER + OWNER_WORDS and end > REG_OWNER:  # the write touches the claim
            return self._claim(address, values, now)
        if address <= REG_COMMAND < end:
            if not self._machine_command(values[REG_COMMAND - address], now):
                return ExcCodes.ILLEGAL_VALUE
            values[REG_COMMAND - address] = CMD_NONE  # acted: reads back 0
        for i, target, seq in starts:
            self.loom.command(i, target, seq, now)
        return None

    def _claim(self, address: int, values: list[int], now: float) -> ExcCodes | None:
        """A claim is the four registers written at once: claim id, pid (0: let go)."""
        if address != REG_OWNER or len(values) != OWNER_WORDS:
            return ExcCodes.ILLEGAL_VALUE
        ident, pid = (values[0] << 16) | values[1], (values[2] << 16) | values[3]
        if not ident:
            return ExcCodes.ILLEGAL_VALUE
        if self.loom.claim(ident, pid, now) is not None:
            return ExcCodes.DEVICE_BUSY  # the claim registers keep the holder's
        if not pid:
            values[:] = [0] * OWNER_WORDS  # let go: they read 0 again
        return None

    def _machine_command(self, code: int, now: float) -> bool:
        if code == CMD_RESET:
            self.loom.reset_faults()
        elif code == CMD_QUICK_STOP:
            self.loom.quick_stop(now)
        elif code == CMD_HOME:
            self.loom.home(now)
        return code in (CMD_NONE, CMD_RESET, CMD_QUICK_STOP, CMD_HOME)

    def _axes_in(self, low: int, high: int) -> Sequence[int]:
        """Axes whose block overlaps the addresses [low, high)."""
        first = max(0, (low - AXIS_BASE) // AXIS_STRIDE)
        last = min(len(self.loom.axes), -(-(high - AXIS_BASE) // AXIS_STRIDE))
        return range(first, last)
