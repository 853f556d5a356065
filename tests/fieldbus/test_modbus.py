"""ModbusBus against the mock loom's Modbus TCP server, over loopback sockets."""

from __future__ import annotations

import asyncio
import dataclasses
import socket
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager

import pytest

from bwsd.config import parse_config
from bwsd.fieldbus.axes import axis_by_name, machine_axes, shift_stroke_um
from bwsd.fieldbus.base import (
    FAULT_DRIVE,
    FAULT_JAM,
    FAULT_POSITION,
    FAULT_STALL,
    AxisMove,
    BusSettings,
    DriveFault,
    EStopError,
    FieldbusConnectionError,
    FieldbusError,
    FieldbusTimeout,
)
from bwsd.fieldbus.modbus import ModbusBus, int32_words, read_spans, words_int32
from bwsd.twin import Machine
from bwsd.twin.machine import Segment
from simulator_hw.loom import Loom, Speeds
from simulator_hw.modbus_server import ModbusLoomServer
from tests.timing import scaled

MACHINE = Machine(rows=3, cols=3, pitch_x=10, pitch_y=12, d_mat=100, c_mat=0.5)
MAP2 = dataclasses.replace(MACHINE, weft_axes=())  # map 2 has no weft positioning axes
SETTINGS = BusSettings(  # bounds for waiting: 1 s, the default, for one request
    timeout=scaled(2.0),
    io_timeout=scaled(1.0),
    reconnect_delay=0.01,
    reconnect_delay_max=0.05,
    reconnect_attempts=3,
    position_tolerance=10,
)
HOST = "127.0.0.1"
ROW0, ROW1, COL1 = 0, 1, 4
WEFT_ANGLE, WEFT_INSERT, TAKEUP = 6, 7, 8


def stroke(name: str, cells: int, machine: Machine = MACHINE) -> AxisMove:
    axis = axis_by_name(machine, name)
    return AxisMove(axis.index, shift_stroke_um(machine, axis, cells))


@asynccontextmanager
async def rig(
    loom: Loom, settings: BusSettings = SETTINGS, device_id: int = 1, version: int = 3
) -> AsyncIterator[tuple[ModbusBus, ModbusLoomServer]]:
    server = ModbusLoomServer(loom, HOST, 0, device_id, version)
    await server.start()
    bus = ModbusBus(loom.machine, settings, HOST, server.port, device_id, version)
    try:
        yield bus, server
    finally:
        await bus.close()
        await server.stop()


def on_loom(loom: Loom, test: Callable[[ModbusBus], Awaitable[None]]) -> None:
    async def scenario() -> None:
        async with rig(loom) as (bus, _):
            await bus.connect()
            await test(bus)

    asyncio.run(scenario())


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind((HOST, 0))
        port: int = sock.getsockname()[1]
        return port


# ----- the pure codec -----
@pytest.mark.parametrize("value", [0, 1, -1, 65535, 65536, -45_000, 2**31 - 1, -(2**31)])
def test_int32_words_round_trip(value):
    high, low = int32_words(value)
    assert 0 <= high <= 0xFFFF and 0 <= low <= 0xFFFF
    assert words_int32(high, low) == value


def test_int32_words_refuses_what_does_not_fit():
    with pytest.raises(ValueError, match="32 bits"):
        int32_words(2**31)


def test_read_spans_cover_the_range_in_protocol_sized_requests():
    assert read_spans(100, 16 * 23, 125) == [(100, 125), (225, 125), (350, 118)]
    assert read_spans(0, 10, 2000) == [(0, 10)]


# ----- moves -----
def test_shift_strokes_move_the_cases():
    async def test(bus: ModbusBus) -> None:
        state = await bus.execute([stroke("row0", 1), stroke("row1", 2)])
        assert state.occupancy.tolist() == [[0, 1, 0], [0, 0, 1], [0, 0, 0]]
        assert [state.axes[i].position for i in (ROW0, ROW1)] == [0, 0]
        assert [state.axes[i].last_stroke for i in (ROW0, ROW1)] == [10_000, 20_000]
        state = await bus.execute([stroke("col1", 2)])
        assert state.occupancy.tolist() == [[0, 0, 0], [0, 0, 1], [0, 1, 0]]
        assert state.axes[COL1].last_stroke == 24_000 and not state.estop

    on_loom(Loom(MACHINE, [(0, 0), (1, 0)], Speeds()), test)


def test_weft_and_takeup_reach_their_targets():
    async def test(bus: ModbusBus) -> None:
        moves = [AxisMove(WEFT_ANGLE, -30_000), AxisMove(WEFT_INSERT, 150_000)]
        state = await bus.execute([*moves, AxisMove(TAKEUP, 2_500)])
        assert state.axes[WEFT_ANGLE].position == -30_000
        assert state.axes[WEFT_INSERT].position == 0
        assert state.axes[WEFT_INSERT].last_stroke == 150_000
        assert state.axes[TAKEUP].position == 2_500
        assert [state.axes[i].done_seq for i in (WEFT_ANGLE, WEFT_INSERT, TAKEUP)] == [1, 1, 1]

    on_loom(Loom(MACHINE, [], Speeds(stroke=5000, takeup=100, weft=3000)), test)


def test_a_machine_of_many_axes_is_read_in_several_requests():
    big = Machine(rows=12, cols=10, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5)
    loom = Loom(big, [(11, 9)], Speeds())  # 28 axes: 448 registers

    async def test(bus: ModbusBus) -> None:
        state = await bus.execute([stroke("col9", -11, big), AxisMove(27, 7_000)])
        assert len(state.axes) == 28 and state.axes[27].position == 7_000  # weft_z
        assert state.occupancy.shape == (12, 10) and state.occupancy[0, 9]
        assert int(state.occupancy.sum()) == 1

    on_loom(loom, test)


def test_homing_and_quick_stop_through_the_bus():
    loom = Loom(MACHINE, [], Speeds(stroke=0.001))

    async def test(bus: ModbusBus) -> None:
        await bus.execute([AxisMove(WEFT_ANGLE, 45_000)])
        state = await bus.home()
        assert state.axes[WEFT_ANGLE].position == 0 and state.axes[WEFT_ANGLE].done_seq == 0
        await bus.move([stroke("row0", 1)])  # hours at this speed
        await bus.quick_stop()
        assert (await bus.state()).axes[ROW0].fault == FAULT_STALL
        await bus.reset_faults()
        assert (await bus.state()).axes[ROW0].fault == 0

    on_loom(loom, test)


def test_a_new_bus_goes_on_from_the_looms_sequences():
    loom = Loom(MACHINE, [], Speeds())

    async def scenario() -> None:
        async with rig(loom) as (first, server):
            await first.execute([AxisMove(TAKEUP, 1_000)])
            await first.execute([AxisMove(TAKEUP, 2_000)])
            second = ModbusBus(MACHINE, SETTINGS, HOST, server.port, 1)
            await second.execute([AxisMove(TAKEUP, 3_000)])
            await second.close()
        assert loom.axes[TAKEUP].done_seq == 3  # never a sequence the loom has done

    asyncio.run(scenario())


# ----- faults -----
@pytest.mark.parametrize(
    ("fault", "speeds", "move", "code"),
    [
        (None, Speeds(), stroke("row0", -1), FAULT_JAM),
        ("stall", Speeds(stroke=500), stroke("row0", 1), FAULT_STALL),
        ("drive", Speeds(), stroke("row0", 1), FAULT_DRIVE),
        ("wrong_position", Speeds(), stroke("row0", 1), FAULT_POSITION),
        ("wrong_position", Speeds(weft=1000), AxisMove(WEFT_ANGLE, 20_000), FAULT_POSITION),
    ],
)
def test_injected_faults_raise_drive_faults(fault, speeds, move, code):
    loom = Loom(MACHINE, [(0, 0)], speeds)
    name = machine_axes(MACHINE)[move.axis].name
    if fault is not None:
        getattr(loom.faults, fault).add(name)

    async def test(bus: ModbusBus) -> None:
        with pytest.raises(DriveFault) as caught:
            await bus.execute([move])
        assert caught.value.code == code and caught.value.axis.name == name

    on_loom(loom, test)


def test_the_estop_refuses_moves_and_cuts_running_ones():
    loom = Loom(MACHINE, [(0, 0)], Speeds(stroke=0.001))

    async def test(bus: ModbusBus) -> None:
        await bus.move([stroke("row0", 1)])
        loom.press_estop(True, time.monotonic())
        with pytest.raises(EStopError):
            await bus.wait([ROW0])
        with pytest.raises(EStopError):
            await bus.execute([AxisMove(TAKEUP, 1_000)])
        assert (await bus.state()).axes[TAKEUP].done_seq == 0

    on_loom(loom, test)


@pytest.mark.slow
def test_a_muted_loom_times_out_and_the_bus_recovers():
    loom = Loom(MACHINE, [], Speeds())

    async def test(bus: ModbusBus) -> None:
        loom.faults.mute = True
        with pytest.raises(FieldbusTimeout, match="no answer"):
            await bus.state()
        loom.faults.mute = False
        state = await bus.execute([AxisMove(TAKEUP, 4_000)])
        assert state.axes[TAKEUP].position == 4_000

    on_loom(loom, test)


def test_a_dropped_connection_is_reported_once_then_reconnected():
    loom = Loom(MACHINE, [], Speeds())

    async def test(bus: ModbusBus) -> None:
        await bus.state()
        loom.faults.drops += 1
        await asyncio.sleep(0.05)  # the server drops idle connections on its own
        with pytest.raises(FieldbusConnectionError, match="lost"):
            await bus.state()
        state = await bus.execute([AxisMove(TAKEUP, 5_000)])
        assert state.axes[TAKEUP].position == 5_000

    on_loom(loom, test)


def test_a_drop_during_a_request_is_a_connection_error():
    loom = Loom(MACHINE, [], Speeds())

    async def test(bus: ModbusBus) -> None:
        loom.faults.drops += 1  # the next request meets the drop
        with pytest.raises(FieldbusConnectionError):
            await bus.state()
        assert (await bus.state()).axes[TAKEUP].position == 0

    on_loom(loom, test)


def test_the_bus_reconnects_after_the_server_restarts_on_the_same_port():
    loom = Loom(MACHINE, [], Speeds())

    async def scenario() -> None:
        async with rig(loom) as (bus, server):
            await bus.execute([AxisMove(TAKEUP, 1_000)])
            await server.stop()
            with pytest.raises(FieldbusConnectionError):
                await bus.state()
            with pytest.raises(FieldbusConnectionError, match="cannot reach"):
                await bus.state()
            await server.start()
            assert server.port == bus.port
            state = await bus.execute([AxisMove(TAKEUP, 2_000)])
            assert state.axes[TAKEUP].position == 2_000

    asyncio.run(scenario())


class CountingBus(ModbusBus):
    """Counts the connection attempts (the real ones, over the socket)."""

    opened = 0

    async def _open(self) -> None:
        self.opened += 1
        await super()._open()


def test_a_closed_port_is_a_connection_error_after_the_configured_attempts():
    async def scenario() -> None:
        bus = CountingBus(MACHINE, SETTINGS, HOST, free_port(), 1)
        with pytest.raises(FieldbusConnectionError, match=f"{HOST}:{bus.port}"):
            await bus.connect()
        assert bus.opened == SETTINGS.reconnect_attempts

    asyncio.run(scenario())


def test_a_loom_of_another_machine_is_refused():
    other = Machine(rows=2, cols=3, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5)

    async def scenario() -> None:
        async with rig(Loom(other, [], Speeds())) as (_, server):
            bus = ModbusBus(MACHINE, SETTINGS, HOST, server.port, 1)
            with pytest.raises(FieldbusError, match=r"expected \[3, 12, 3, 3\]"):
                await bus.connect()

    asyncio.run(scenario())


def test_an_unknown_unit_is_an_error_naming_the_address():
    async def scenario() -> None:
        async with rig(Loom(MACHINE, [], Speeds()), device_id=3) as (_, server):
            bus = ModbusBus(MACHINE, SETTINGS, HOST, server.port, 4)
            with pytest.raises(FieldbusError, match=r"address 0 refused \(exception code 4\)"):
                await bus.connect()

    asyncio.run(scenario())


def test_from_config_takes_every_setting():
    config = parse_config(
        {
            "machine": {
                "rows": 3,
                "cols": 3,
                "pitch_x": 10,
                "pitch_y": 12,
                "d_mat": 100,
                "c_mat": 0.5,
            },
            "fieldbus": {
                "timeout": 7.0,
                "io_timeout": 0.5,
                "reconnect_delay": 0.2,
                "reconnect_delay_max": 3.0,
                "reconnect_attempts": 9,
                "position_tolerance": 25,
                "poll_max": 0.05,
                "modbus": {"host": "10.0.0.5", "port": 1502, "device_id": 17},
            },
        }
    )
    bus = ModbusBus.from_config(config)
    assert (bus.host, bus.port, bus.device_id) == ("10.0.0.5", 1502, 17)
    assert bus.settings == BusSettings(7.0, 0.5, 0.2, 3.0, 9, 25, 0.05)
    assert bus.machine == config.machine and len(bus.axes) == 12  # 9 and weft_x, weft_y, weft_z


def test_a_machine_beyond_the_input_address_space_is_refused():
    huge = Machine(rows=300, cols=300, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5)
    with pytest.raises(FieldbusError, match="at most 65535 cells"):
        ModbusBus(huge, SETTINGS, HOST, 1502, 1)


def test_a_loom_whose_segments_differ_is_refused():
    ours = Machine(
        rows=3,
        cols=3,
        pitch_x=10,
        pitch_y=12,
        d_mat=100,
        c_mat=0.5,
        segments=(Segment("row", 1, 0, 1),),
    )
    theirs = Machine(
        rows=3,
        cols=3,
        pitch_x=10,
        pitch_y=12,
        d_mat=100,
        c_mat=0.5,
        segments=(Segment("row", 1, 1, 2),),
    )

    async def scenario() -> None:
        async with rig(Loom(theirs, [], Speeds())) as (_, server):
            bus = ModbusBus(ours, SETTINGS, HOST, server.port, 1)
            with pytest.raises(
                FieldbusError,
                match=r"axis 9 moves kind, line, first, last cell "
                r"\[1, 1, 1, 2\], expected \[1, 1, 0, 1\] \(segment "
                r"row1\[0\.\.1\]\)",
            ):
                await bus.connect()
        async with rig(Loom(ours, [(1, 0)], Speeds())) as (_, server):
            bus = ModbusBus(ours, SETTINGS, HOST, server.port, 1)
            await bus.connect()
            state = await bus.execute([stroke("row1[0..1]", 1, ours)])
            assert state.occupancy[1].tolist() == [False, True, False]
            await bus.close()

    asyncio.run(scenario())


class RequestCounter:
    """A TCP relay between a client and the server that counts the Modbus requests."""

    def __init__(self, port: int) -> None:
        self.port, self.requests = port, 0
        self.server: asyncio.Server | None = None

    async def start(self) -> int:
        self.server = await asyncio.start_server(self._relay, HOST, 0)
        return int(self.server.sockets[0].getsockname()[1])

    async def _relay(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        up_reader, up_writer = await asyncio.open_connection(HOST, self.port)

        async def upstream() -> None:
            while header := await reader.readexactly(6):  # MBAP: length in bytes 4, 5
                body = await reader.readexactly(int.from_bytes(header[4:6], "big"))
                self.requests += 1
                up_writer.write(header + body)

        async def downstream() -> None:
            while data := await up_reader.read(4096):
                writer.write(data)

        try:
            await asyncio.gather(upstream(), downstream())
        except (asyncio.IncompleteReadError, ConnectionError):
            pass
        finally:
            writer.close()
            up_writer.close()


@pytest.mark.parametrize(
    ("version", "requests"), [(3, 1), (2, 3)]
)  # 2: 144 registers and the inputs
def test_map_3_reads_the_axes_occupancy_and_estop_in_one_request(version, requests):
    machine = MACHINE if version == 3 else MAP2  # map 3: with the weft's positioning axes
    loom = Loom(machine, [(0, 0), (1, 1)], Speeds())

    async def scenario() -> None:
        server = ModbusLoomServer(loom, HOST, 0, 1, version)
        await server.start()
        counter = RequestCounter(server.port)
        bus = ModbusBus(machine, SETTINGS, HOST, await counter.start(), 1, version)
        try:
            await bus.connect()
            await bus.execute([stroke("row0", 1)])
            before = counter.requests
            state = await bus.state()
            assert counter.requests - before == requests
            assert state.occupancy.tolist() == [[0, 1, 0], [0, 1, 0], [0, 0, 0]]
            assert not state.estop and state.axes[ROW0].done_seq == 1
            assert state.axes[ROW0].strokes == (1 if version == 3 else None)
            loom.press_estop(True, time.monotonic())
            assert (await bus.state()).estop
        finally:
            await bus.close()
            await server.stop()

    asyncio.run(scenario())


def test_a_map_2_loom_is_read_when_the_config_asks_for_map_2():
    async def scenario() -> None:
        async with rig(Loom(MAP2, [(0, 0)], Speeds()), version=2) as (bus, server):
            await bus.connect()
            state = await bus.execute([stroke("row0", 2)])
            assert state.occupancy[0].tolist() == [False, False, True]
            newer = ModbusBus(MAP2, SETTINGS, HOST, server.port, 1)  # map 3 by default
            with pytest.raises(FieldbusError, match=r"are \[2, 9, 3, 3\], expected \[3, 9, 3, 3\]"):
                await newer.connect()

    asyncio.run(scenario())


def test_the_map_key_is_checked_at_load():
    machine = {"rows": 3, "cols": 3, "pitch_x": 10, "pitch_y": 12, "d_mat": 100, "c_mat": 0.5}
    config = parse_config({"machine": machine, "fieldbus": {"modbus": {"map": 2}}})
    assert ModbusBus.from_config(config).map_version == 2
    assert len(ModbusBus.from_config(config).axes) == 9  # no weft positioning axes on map 2
    with pytest.raises(FieldbusError, match="Modbus map 2 has no weft positioning axes"):
        ModbusBus(MACHINE, SETTINGS, HOST, 1502, 1, 2)
    with pytest.raises(Exception, match=r"\[fieldbus\.modbus\.map\]"):
        parse_config({"machine": machine, "fieldbus": {"modbus": {"map": 1}}})
