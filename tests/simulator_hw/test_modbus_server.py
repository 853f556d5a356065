"""The mock loom's Modbus TCP server, read and written by a bare pymodbus client."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager

import pytest
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusIOException

from bwsd.fieldbus.base import FAULT_DRIVE, FAULT_JAM, FAULT_STALL, FieldbusError
from bwsd.fieldbus.modbus import (
    MAP_VERSION,
    axis_address,
    decode_image,
    image_words,
    int32_words,
    words_int32,
)
from bwsd.twin import Machine
from bwsd.twin.machine import Segment
from simulator_hw.loom import Loom, Speeds
from simulator_hw.modbus_server import ModbusLoomServer
from tests.timing import scaled

# without the weft's positioning axes (as on map 2): N axes (test_weft_positioning_axes has them)
MACHINE = Machine(rows=2, cols=3, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5, weft_axes=())
N = 2 + 3 + 3
ROW0, ROW1, COL0, WEFT_ANGLE, TAKEUP = 0, 1, 2, 5, 7
CELL_UM = 10_000
ESTOP = 6  # discrete input after the 2 x 3 occupancy sensors
LIMIT = scaled(3.0)  # s: a bound for waiting, never an expected duration


@asynccontextmanager
async def serving(
    loom: Loom, device_id: int = 1, version: int = MAP_VERSION
) -> AsyncIterator[ModbusLoomServer]:
    server = ModbusLoomServer(loom, "127.0.0.1", 0, device_id, version)
    await server.start()
    try:
        yield server
    finally:
        await server.stop()


@asynccontextmanager
async def client_of(server: ModbusLoomServer) -> AsyncIterator[AsyncModbusTcpClient]:
    client = AsyncModbusTcpClient(
        "127.0.0.1", port=server.port, timeout=scaled(1.0), retries=0, reconnect_delay=0
    )
    assert await client.connect()
    try:
        yield client
    finally:
        client.close()


def on_loom(loom: Loom, test: Callable[[AsyncModbusTcpClient], Awaitable[None]]) -> None:
    """Run ``test`` with a client connected to a server of ``loom``."""

    async def scenario() -> None:
        async with serving(loom) as server, client_of(server) as client:
            await test(client)

    asyncio.run(scenario())


async def regs(client: AsyncModbusTcpClient, address: int, count: int) -> list[int]:
    response = await client.read_holding_registers(address, count=count, device_id=1)
    assert not response.isError(), response
    return list(response.registers)


async def axis(client: AsyncModbusTcpClient, index: int) -> list[int]:
    return await regs(client, axis_address(index), 16)


async def inputs(client: AsyncModbusTcpClient) -> list[bool]:
    response = await client.read_discrete_inputs(0, count=ESTOP + 1, device_id=1)
    assert not response.isError(), response
    return list(response.bits[: ESTOP + 1])


async def set_point(client: AsyncModbusTcpClient, index: int, target: int, seq: int) -> None:
    response = await client.write_registers(
        axis_address(index), [*int32_words(target), seq], device_id=1
    )
    assert not response.isError(), response


async def until(check: Callable[[], Awaitable[bool]]) -> None:
    """Poll ``check`` until it holds (fails after LIMIT)."""
    async with asyncio.timeout(LIMIT):
        while not await check():
            await asyncio.sleep(0.005)


def test_machine_block_gives_version_and_counts():
    async def test(client: AsyncModbusTcpClient) -> None:
        assert await regs(client, 0, 6) == [MAP_VERSION, N, 2, 3, 0, 0]
        blocks = await regs(client, axis_address(0), 16 * N // 2)  # several axes in one read
        assert [blocks[16 * i + 3] for i in range(N // 2)] == [4] * (N // 2)  # homed, idle

    on_loom(Loom(MACHINE, [], Speeds()), test)


def test_a_shift_stroke_moves_the_cases_and_completes():
    async def test(client: AsyncModbusTcpClient) -> None:
        assert await inputs(client) == [True, False, False, True, False, False, False]
        await set_point(client, ROW0, CELL_UM, 7)
        block = await axis(client, ROW0)
        assert block[:3] == [0, CELL_UM, 7]  # the set-point reads back
        assert block[3] & 1 == 0 and block[6] == 7 and block[7] == 0
        assert words_int32(block[4], block[5]) == 0  # back home
        assert words_int32(block[8], block[9]) == CELL_UM  # last stroke
        assert await inputs(client) == [False, True, False, True, False, False, False]

    on_loom(Loom(MACHINE, [(0, 0), (1, 0)], Speeds()), test)


def test_each_shift_axis_says_which_cells_it_moves():
    segmented = Machine(
        rows=2,
        cols=3,
        pitch_x=10,
        pitch_y=10,
        d_mat=100,
        c_mat=0.5,
        segments=(Segment("row", 1, 1, 2), Segment("col", 0, 0, 1)),
        weft_axes=(),
    )

    async def test(client: AsyncModbusTcpClient) -> None:
        assert await regs(client, 1, 1) == [N + 2]
        shapes = [(await axis(client, i))[10:16] for i in range(N + 2)]
        assert shapes[ROW1] == [1, 1, 0, 2, 0, 0]  # kind row, line 1, cells 0..2
        assert shapes[COL0] == [2, 0, 0, 1, 0, 0]  # kind col, line 0, cells 0..1
        assert shapes[WEFT_ANGLE] == shapes[TAKEUP] == [0] * 6
        assert shapes[N:] == [[1, 1, 1, 2, 0, 0], [2, 0, 0, 1, 0, 0]]  # the segments
        refused = await client.write_register(axis_address(N) + 10, 0, device_id=1)
        assert refused.isError()  # read-only
        await set_point(client, N, CELL_UM, 1)  # row1[1..2]: only (1, 1) moves, (1, 0) stays
        assert await inputs(client) == [False, False, False, True, False, True, False]

    on_loom(Loom(segmented, [(1, 0), (1, 1)], Speeds()), test)


def test_a_machine_beyond_the_map_is_refused_by_the_server():
    segments = tuple(Segment("row", r, 2 * j, 2 * j + 1) for r in range(100) for j in range(39))
    huge = Machine(rows=100, cols=100, pitch_x=1, pitch_y=1, d_mat=10, c_mat=0.5, segments=segments)
    with pytest.raises(FieldbusError, match="at most 4089 axes, the machine has 4106"):
        ModbusLoomServer(Loom(huge, [], Speeds()))


def test_absolute_axes_read_back_signed_positions():
    async def test(client: AsyncModbusTcpClient) -> None:
        await set_point(client, WEFT_ANGLE, -45_000, 1)
        await set_point(client, TAKEUP, 123_456, 1)
        weft, takeup = await axis(client, WEFT_ANGLE), await axis(client, TAKEUP)
        assert weft[4:6] == [0xFFFF, 0x10000 - 45_000]
        assert words_int32(weft[4], weft[5]) == -45_000
        assert words_int32(takeup[4], takeup[5]) == 123_456 and takeup[6] == 1

    on_loom(Loom(MACHINE, [], Speeds()), test)


@pytest.mark.slow
def test_every_read_advances_the_loom_to_now():
    async def test(client: AsyncModbusTcpClient) -> None:
        await set_point(client, ROW0, CELL_UM, 1)  # out and back, 10 mm each way at 40 mm/s
        assert (await axis(client, ROW0))[3] & 1  # busy
        assert (await regs(client, 4, 1))[0] & 4  # the machine is busy

        async def done() -> bool:
            return (await axis(client, ROW0))[6] == 1

        await until(done)
        block = await axis(client, ROW0)
        assert block[3] & 1 == 0 and words_int32(block[4], block[5]) == 0
        assert (await inputs(client))[:3] == [False, True, False]

    on_loom(Loom(MACHINE, [(0, 0)], Speeds(stroke=40)), test)


def test_a_blocked_shift_reports_a_jam():
    async def test(client: AsyncModbusTcpClient) -> None:
        await set_point(client, ROW0, -CELL_UM, 1)  # the case at column 0 would leave
        block = await axis(client, ROW0)
        assert block[7] == FAULT_JAM and block[3] & 2 and block[6] == 0
        assert (await regs(client, 4, 1))[0] == 2  # an axis is faulted
        assert (await inputs(client))[:3] == [True, False, False]  # nothing moved

    on_loom(Loom(MACHINE, [(0, 0)], Speeds()), test)


def test_machine_commands_act_and_read_back_zero():
    loom = Loom(MACHINE, [], Speeds(stroke=0.001))
    loom.faults.drive.add("col0")

    async def test(client: AsyncModbusTcpClient) -> None:
        await set_point(client, COL0, CELL_UM, 1)
        await set_point(client, ROW1, CELL_UM, 1)  # takes hours at this speed
        assert (await client.write_register(5, 2, device_id=1)).registers == [0]  # quick stop
        assert (await axis(client, ROW1))[7] == FAULT_STALL
        assert (await axis(client, COL0))[7] == FAULT_DRIVE
        await client.write_register(5, 1, device_id=1)  # reset faults
        assert [(await axis(client, i))[7] for i in (ROW1, COL0)] == [0, 0]
        await set_point(client, WEFT_ANGLE, 90_000, 3)
        await client.write_register(5, 3, device_id=1)  # home
        weft = await axis(client, WEFT_ANGLE)
        assert words_int32(weft[4], weft[5]) == 0 and weft[6] == 0
        assert (await regs(client, 5, 1)) == [0]

    on_loom(loom, test)


def test_bad_requests_get_exception_responses():
    async def test(client: AsyncModbusTcpClient) -> None:
        refused = [
            await client.write_register(5, 9, device_id=1),  # no such command
            await client.write_registers(axis_address(ROW0), [0, CELL_UM, 0], device_id=1),
            await client.write_register(axis_address(ROW0) + 3, 1, device_id=1),  # read-only
            await client.write_register(0, 2, device_id=1),  # read-only
            await client.read_holding_registers(10, count=1, device_id=1),  # between blocks
            await client.read_holding_registers(axis_address(N), count=1, device_id=1),
            await client.read_coils(0, count=1, device_id=1),
            await client.read_input_registers(image_words(16, N), count=1, device_id=1),  # past
            await client.write_registers(6, [0, 0, 0, 7], device_id=1),  # a claim without id
            await client.write_registers(6, [0, 1], device_id=1),  # half a claim
        ]
        assert [r.isError() for r in refused] == [True] * len(refused)
        assert [r.exception_code for r in refused[:2]] == [3, 3]  # illegal value
        assert (await axis(client, ROW0))[6] == 0  # the refused set-point did not start
        assert (await inputs(client))[:2] == [True, False]

    on_loom(Loom(MACHINE, [(0, 0)], Speeds()), test)


def test_the_estop_input_follows_the_loom():
    loom = Loom(MACHINE, [], Speeds())

    async def test(client: AsyncModbusTcpClient) -> None:
        assert not (await inputs(client))[ESTOP]
        loom.press_estop(True, time.monotonic())
        assert (await inputs(client))[ESTOP]
        assert (await regs(client, 4, 1))[0] & 1
        loom.press_estop(False, time.monotonic())
        assert not (await inputs(client))[ESTOP]

    on_loom(loom, test)


def test_a_configured_unit_answers():
    async def scenario() -> None:
        loom = Loom(MACHINE, [], Speeds())
        async with serving(loom, device_id=7) as server, client_of(server) as client:
            response = await client.read_holding_registers(0, count=1, device_id=7)
            assert response.registers == [MAP_VERSION] and response.dev_id == 7

    asyncio.run(scenario())


@pytest.mark.slow
def test_a_muted_loom_does_not_answer_and_keeps_the_connection():
    loom = Loom(MACHINE, [(0, 0)], Speeds())

    async def test(client: AsyncModbusTcpClient) -> None:
        loom.faults.mute = True
        with pytest.raises(ModbusIOException):
            await client.read_holding_registers(0, count=1, device_id=1)
        with pytest.raises(ModbusIOException):  # a muted write is not acted on either
            await set_point(client, ROW0, CELL_UM, 1)
        assert client.connected
        loom.faults.mute = False
        assert await regs(client, 0, 1) == [MAP_VERSION]
        assert (await axis(client, ROW0))[6] == 0 and loom.occupied[0][0]

    on_loom(loom, test)


def test_a_drop_closes_every_connection_and_new_ones_work():
    loom = Loom(MACHINE, [], Speeds())

    async def scenario() -> None:
        async with serving(loom) as server, client_of(server) as a, client_of(server) as b:
            assert await regs(a, 0, 1) == await regs(b, 0, 1) == [MAP_VERSION]
            loom.faults.drops += 1

            async def both_closed() -> bool:
                return not a.connected and not b.connected

            await until(both_closed)
            async with client_of(server) as c:
                assert await regs(c, 0, 1) == [MAP_VERSION]

    asyncio.run(scenario())


@pytest.mark.slow
def test_a_request_right_after_a_drop_is_not_answered():
    loom = Loom(MACHINE, [], Speeds())

    async def test(client: AsyncModbusTcpClient) -> None:
        loom.faults.drops += 1  # no await in between: the request meets the drop first
        with pytest.raises(ModbusIOException):
            await client.read_holding_registers(0, count=1, device_id=1)
        assert not client.connected

    on_loom(loom, test)


def test_inputs_read_one_at_a_time_are_current():
    square = Machine(rows=5, cols=5, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5)
    loom = Loom(square, [(4, 4)], Speeds())

    async def bits(client: AsyncModbusTcpClient, address: int, count: int) -> list[bool]:
        response = await client.read_discrete_inputs(address, count=count, device_id=1)
        assert not response.isError(), response
        return list(response.bits[:count])

    async def test(client: AsyncModbusTcpClient) -> None:
        assert await bits(client, 24, 2) == [True, False]  # cell (4, 4), the e-stop
        loom.press_estop(True, time.monotonic())
        assert await bits(client, 25, 1) == [True]
        assert await bits(client, 20, 4) == [False] * 4
        loom.occupied[4][3] = True
        assert await bits(client, 23, 1) == [True]

    on_loom(loom, test)


async def image(client: AsyncModbusTcpClient) -> list[int]:
    response = await client.read_input_registers(0, count=image_words(6, N), device_id=1)
    assert not response.isError(), response
    return list(response.registers)


def test_map_3_reads_axes_occupancy_and_estop_in_one_request():
    loom = Loom(MACHINE, [(0, 0), (1, 2)], Speeds())

    async def test(client: AsyncModbusTcpClient) -> None:
        assert image_words(6, N) == 1 + 1 + 8 * N  # 6 cells fit in one register
        await set_point(client, ROW0, CELL_UM, 1)
        await set_point(client, TAKEUP, 2_500, 1)
        status, grid, axes = decode_image(await image(client), 2, 3)
        assert grid.tolist() == [[False, True, False], [False, False, True]]
        assert status & 1 == 0 and len(axes) == N
        assert (axes[ROW0].done_seq, axes[ROW0].last_stroke, axes[ROW0].strokes) == (1, CELL_UM, 1)
        assert (axes[TAKEUP].position, axes[TAKEUP].strokes, axes[ROW1].strokes) == (2_500, 1, 0)
        block = await axis(client, ROW0)
        assert block[14] == 1  # the stroke counter in the axis block too
        loom.press_estop(True, time.monotonic())
        status, _, _ = decode_image(await image(client), 2, 3)
        assert status & 1 == 1

    on_loom(loom, test)


def test_homing_keeps_the_stroke_counter():
    loom = Loom(MACHINE, [(0, 0)], Speeds())

    async def test(client: AsyncModbusTcpClient) -> None:
        await set_point(client, WEFT_ANGLE + 1, 60_000, 1)  # the insert
        assert (await client.write_register(5, 3, device_id=1)).isError() is False  # home
        _, _, axes = decode_image(await image(client), 2, 3)
        assert (axes[WEFT_ANGLE + 1].done_seq, axes[WEFT_ANGLE + 1].strokes) == (0, 1)

    on_loom(loom, test)


def test_a_claim_is_refused_while_another_client_holds_the_loom():
    loom = Loom(MACHINE, [], Speeds())

    async def test(client: AsyncModbusTcpClient) -> None:
        mine, theirs = [0, 0x1234, 0, 4242], [0, 0x9999, 0, 777]
        assert not (await client.write_registers(6, mine, device_id=1)).isError()
        refused = await client.write_registers(6, theirs, device_id=1)
        assert refused.isError() and refused.exception_code == 6  # device busy
        assert await regs(client, 6, 4) == mine  # names the holder
        assert not (await client.write_registers(6, mine, device_id=1)).isError()  # renewed
        assert not (await client.write_registers(6, [0, 0x1234, 0, 0], device_id=1)).isError()
        assert await regs(client, 6, 4) == [0, 0, 0, 0]  # let go
        assert not (await client.write_registers(6, theirs, device_id=1)).isError()
        loom.owner.claimed -= 10  # the holder went silent longer than the lease
        assert not (await client.write_registers(6, mine, device_id=1)).isError()

    on_loom(loom, test)


def test_map_2_is_still_served_when_asked_for():
    async def scenario() -> None:
        async with (
            serving(Loom(MACHINE, [(0, 0)], Speeds()), version=2) as server,
            client_of(server) as client,
        ):
            assert (await regs(client, 0, 4)) == [2, N, 2, 3]
            assert (await client.read_input_registers(0, count=1, device_id=1)).isError()
            assert (await client.read_holding_registers(6, count=1, device_id=1)).isError()
            await set_point(client, ROW0, CELL_UM, 1)
            assert (await axis(client, ROW0))[14] == 0  # reserved in map 2
            assert (await inputs(client))[:3] == [False, True, False]

    asyncio.run(scenario())
