"""The CANopen backend against the mock loom's drives, over a real socketcand hub."""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass

import can
import numpy as np
import pytest

from bwsd.config import parse_config
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
    FieldbusTimeout,
)
from bwsd.fieldbus.canopen import CanopenBus
from bwsd.fieldbus.canopen_pdo import Pdo, configure, drive_pdos, layout, wanted_layout
from bwsd.fieldbus.cia402 import occupancy_bytes
from bwsd.twin import Machine
from simulator_hw.canopen_drives import CanopenLoom
from simulator_hw.loom import Loom, Speeds
from simulator_hw.socketcand_hub import SocketcandHub
from tests.timing import scaled

MACHINE = Machine(rows=2, cols=3, pitch_x=10, pitch_y=20, d_mat=100, c_mat=0.5)
ROW0, ROW1, COL0, COL2 = 0, 1, 2, 4
WEFT_ANGLE, WEFT_INSERT, TAKEUP = 5, 6, 7
# An SDO answer may take more than 0.3 s on a loaded machine (the hub, the drives and the
# master share this process): 1 s, the backend's default, times the machine's factor.
SETTINGS = BusSettings(
    timeout=scaled(2.0),
    io_timeout=scaled(1.0),
    reconnect_delay=0.01,
    reconnect_delay_max=0.05,
    reconnect_attempts=3,
)


@dataclass
class Rig:
    loom: Loom
    hub: SocketcandHub
    drives: CanopenLoom
    bus: CanopenBus


@asynccontextmanager
async def rig(
    fill=((0, 0), (1, 2)), speeds=None, heartbeat_ms=0, settings=SETTINGS
) -> AsyncIterator[Rig]:
    """The mock loom's drives behind a hub, and a connected CanopenBus."""
    loom = Loom(MACHINE, fill, speeds or Speeds())
    hub = SocketcandHub(faults=loom.faults)
    await hub.start()
    drives = CanopenLoom(
        loom,
        hub.local_channel,
        node_base=3,
        io_node=100,
        heartbeat_ms=20,
        loop=asyncio.get_running_loop(),
    )
    drives.start()
    bus = CanopenBus(
        MACHINE, settings, port=hub.port, node_base=3, io_node=100, heartbeat_ms=heartbeat_ms
    )
    r = Rig(loom, hub, drives, bus)
    try:
        await bus.connect()
        yield r
    finally:
        await bus.close()
        await asyncio.to_thread(drives.stop)
        await r.hub.stop()  # the test may have replaced it


def run(scenario: Callable[[], Awaitable[None]]) -> None:
    asyncio.run(asyncio.wait_for(scenario(), scaled(20)))


async def until(condition: Callable[[], bool], limit: float = 5.0) -> None:
    """Wait for ``condition`` (the limit only guards against a hang)."""
    async with asyncio.timeout(scaled(limit)):
        while not condition():
            await asyncio.sleep(0.005)


def occupied(state) -> set[tuple[int, int]]:
    return {(int(r), int(c)) for r, c in np.argwhere(state.occupancy)}


@pytest.mark.slow
def test_moves_read_back_and_shifts_move_the_cases():
    async def scenario() -> None:
        async with rig(speeds=Speeds(stroke=500, takeup=500, weft=3600)) as r:
            state = await r.bus.state()
            assert occupied(state) == {(0, 0), (1, 2)} and not state.estop
            state = await r.bus.execute([AxisMove(ROW0, 10_000), AxisMove(COL2, -20_000)])
            assert occupied(state) == {(0, 1), (0, 2)}
            assert state.axes[ROW0].last_stroke == 10_000 and state.axes[ROW0].position == 0
            assert state.axes[COL2].last_stroke == -20_000
            moves = [AxisMove(TAKEUP, 3_000), AxisMove(WEFT_ANGLE, 90_000)]
            state = await r.bus.execute(moves)
            assert state.axes[TAKEUP].position == 3_000
            assert state.axes[WEFT_ANGLE].position == 90_000
            state = await r.bus.execute([AxisMove(WEFT_INSERT, 40_000)])
            assert state.axes[WEFT_INSERT].done_seq == 1 and state.axes[ROW0].done_seq == 1
            assert occupied(state) == {(r_, c) for r_, c in np.argwhere(r.loom.occupied)}

    run(scenario)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("fault", "axis", "target", "speeds", "code", "after_reset"),
    [
        ("jam", ROW1, 10_000, Speeds(), FAULT_JAM, -10_000),  # (1, 2) would leave the matrix
        ("stall", ROW0, 10_000, Speeds(stroke=200), FAULT_STALL, 10_000),
        ("drive", COL0, 20_000, Speeds(), FAULT_DRIVE, 20_000),
        ("wrong_position", TAKEUP, 5_000, Speeds(), FAULT_POSITION, 6_000),
    ],
)
def test_each_injected_fault_is_a_drive_fault_with_its_code(
    fault, axis, target, speeds, code, after_reset
):
    async def scenario() -> None:
        async with rig(speeds=speeds) as r:
            if fault != "jam":
                getattr(r.loom.faults, fault).add(r.bus.axes[axis].name)
            with pytest.raises(DriveFault) as caught:
                await r.bus.execute([AxisMove(axis, target)])
            assert caught.value.code == code and caught.value.axis.index == axis
            assert r.bus.axes[axis].name in str(caught.value)
            # latched until a reset; then the axis moves again
            r.loom.faults.stall.clear()
            r.loom.faults.drive.clear()
            r.loom.faults.wrong_position.clear()
            if code != FAULT_POSITION:  # a read-back check, nothing latched in the drive
                with pytest.raises(DriveFault):
                    await r.bus.execute([AxisMove(axis, after_reset)], timeout=0.3)
            await r.bus.reset_faults()
            state = await r.bus.execute([AxisMove(axis, after_reset)])
            assert state.axes[axis].fault == 0
            assert state.axes[axis].done_seq == (2 if code == FAULT_POSITION else 3)

    run(scenario)


@pytest.mark.slow
def test_estop_refuses_moves_and_cuts_a_running_one():
    async def scenario() -> None:
        async with rig(speeds=Speeds(stroke=20)) as r:
            await r.bus.move([AxisMove(ROW0, 10_000)])
            assert (await r.bus.state()).axes[ROW0].busy  # the RPDO went before this SYNC
            r.loom.press_estop(True, time.monotonic())
            with pytest.raises(EStopError):
                await r.bus.wait([ROW0])
            with pytest.raises(EStopError):  # the set-point goes out; the next SYNC tells
                await r.bus.execute([AxisMove(ROW1, -10_000)])
            assert (await r.bus.state()).axes[ROW0].fault == 5
            r.loom.press_estop(False, time.monotonic())
            await r.bus.reset_faults()
            state = await r.bus.state()
            assert not state.estop and state.axes[ROW0].fault == 0

    run(scenario)


@pytest.mark.slow
def test_quick_stop_stalls_moving_axes_and_home_zeroes_the_sequences():
    async def scenario() -> None:
        async with rig(speeds=Speeds(stroke=20, takeup=1000)) as r:
            await r.bus.execute([AxisMove(TAKEUP, 2_000)])
            await r.bus.move([AxisMove(ROW0, 10_000)])
            await r.bus.quick_stop()
            state = await r.bus.state()
            assert state.axes[ROW0].fault == FAULT_STALL and not state.axes[ROW0].busy
            await r.bus.reset_faults()
            state = await r.bus.home()
            assert all(state.axes[i].done_seq == 0 for i in range(TAKEUP))
            assert state.axes[TAKEUP].position == 2_000  # the take-up keeps its position
            await r.bus.execute([AxisMove(WEFT_ANGLE, 45_000)])

    run(scenario)


@pytest.mark.slow
def test_mute_without_heartbeats_times_out_and_recovers():
    async def scenario() -> None:
        async with rig(heartbeat_ms=0) as r:
            r.loom.faults.mute = True
            with pytest.raises(FieldbusTimeout, match="no answer"):
                await r.bus.state()
            r.loom.faults.mute = False
            assert occupied(await r.bus.state()) == {(0, 0), (1, 2)}

    run(scenario)


@pytest.mark.slow
def test_mute_is_a_lost_heartbeat_once_three_periods_passed():
    async def scenario() -> None:
        async with rig(heartbeat_ms=30) as r:
            await r.bus.state()
            r.loom.faults.mute = True
            await asyncio.sleep(0.2)  # more than three periods without a heartbeat
            with pytest.raises(FieldbusConnectionError, match="heartbeat") as caught:
                await r.bus.state()
            assert "axis row0" in str(caught.value)
            r.loom.faults.mute = False
            await r.bus.execute([AxisMove(ROW0, 10_000)])  # reconnects first

    run(scenario)


@pytest.mark.slow
def test_a_dropped_connection_is_reported_once_then_reconnected():
    async def scenario() -> None:
        async with rig(heartbeat_ms=50) as r:
            await r.bus.state()
            r.loom.faults.drops += 1
            await until(lambda: r.hub.clients == 0)
            with pytest.raises(FieldbusConnectionError):
                await r.bus.state()
            state = await r.bus.execute([AxisMove(ROW0, 10_000)])
            assert occupied(state) == {(0, 1), (1, 2)}
            assert r.hub.clients == 1

    run(scenario)


@pytest.mark.slow
def test_reconnects_after_the_hub_restarts_on_the_same_port():
    async def scenario() -> None:
        async with rig() as r:
            await r.bus.state()
            await r.hub.stop()
            r.hub = SocketcandHub(
                port=r.hub.port, faults=r.loom.faults, local_channel=r.hub.local_channel
            )
            await r.hub.start()
            with pytest.raises(FieldbusConnectionError):
                await r.bus.state()
            state = await r.bus.execute([AxisMove(COL0, 20_000)])
            assert occupied(state) == {(1, 0), (1, 2)}

    run(scenario)


def test_a_closed_port_is_a_connection_error():
    async def scenario() -> None:
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        bus = CanopenBus(MACHINE, SETTINGS, port=port)
        with pytest.raises(FieldbusConnectionError, match=f"127.0.0.1:{port}"):
            await bus.connect()
        await bus.close()

    run(scenario)


@pytest.mark.slow
def test_virtual_interface_in_one_process():
    async def scenario() -> None:
        loom = Loom(MACHINE, [(0, 0)], Speeds())
        drives = CanopenLoom(loom, "bwsd-test-virtual", loop=asyncio.get_running_loop())
        drives.start()
        bus = CanopenBus(
            MACHINE,
            SETTINGS,
            interface="virtual",
            channel="bwsd-test-virtual",
            io_node=127,
            heartbeat_ms=50,
        )
        try:
            await bus.connect()
            state = await bus.execute([AxisMove(ROW0, 20_000)])
            assert occupied(state) == {(0, 2)}
            loom.faults.mute = True  # no hub here: the nodes themselves fall silent
            await asyncio.sleep(0.3)  # more than three periods without a heartbeat
            with pytest.raises(FieldbusConnectionError, match="heartbeat"):
                await bus.state()
            loom.faults.mute = False
            assert occupied(await bus.state()) == {(0, 2)}
        finally:
            await bus.close()
            await asyncio.to_thread(drives.stop)

    run(scenario)


def test_from_config_takes_both_tables():
    config = parse_config(
        {
            "machine": {
                "rows": 2,
                "cols": 3,
                "pitch_x": 10,
                "pitch_y": 20,
                "d_mat": 100,
                "c_mat": 0.5,
            },
            "fieldbus": {
                "backend": "canopen",
                "io_timeout": 0.25,
                "canopen": {"port": 4000, "node_base": 10, "io_node": 5, "heartbeat_ms": 0},
            },
        }
    )
    bus = CanopenBus.from_config(config)
    assert (bus.port, bus.io_node, bus.heartbeat_ms) == (4000, 5, 0)
    assert bus.drive_ids == list(range(10, 21)) and bus.settings.io_timeout == 0.25


def test_occupancy_bitmap_is_row_major_lsb_first():
    grid = [[True, False, False], [False, False, True]] * 2  # cells 0, 5, 6, 11
    assert occupancy_bytes(grid) == bytes([0b01100001, 0b00001000])


class Sniffer:
    """Every frame on the mock loom's side of the hub, by a plain python-can bus."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.frames: list[can.Message] = []

    def drain(self) -> list[can.Message]:
        while (msg := self.bus.recv(0)) is not None:
            self.frames.append(msg)
        frames, self.frames = self.frames, []
        return frames


@pytest.mark.slow
def test_a_shift_and_its_read_back_go_by_pdo_not_sdo():
    async def scenario() -> None:
        async with rig() as r:
            sniffer = Sniffer(r.hub.local_channel)
            try:
                await r.bus.claim()  # by SDO, renewed at most every 0.5 s: not per move
                sniffer.drain()
                state = await r.bus.execute([AxisMove(ROW0, 10_000)])
                assert occupied(state) == {(0, 1), (1, 2)}
                await asyncio.sleep(0.05)  # let the last frames reach the sniffer
                ids = [m.arbitration_id for m in sniffer.drain()]
            finally:
                sniffer.bus.shutdown()
            assert [i for i in ids if 0x580 <= i < 0x680] == []  # no SDO either way
            assert ids.count(0x200 + 3 + ROW0) == 2  # RPDO1: bit 4 low, then high
            syncs = ids.count(0x80)
            assert syncs >= 1
            assert ids.count(0x280 + 3 + ROW0) == ids.count(0x381) == syncs  # every SYNC
            assert ids.count(0x180 + 3 + ROW0) == 1  # on change: the stroke counted once
            assert ids.count(0x180 + 3 + ROW1) == 0  # row 1 did not move

    run(scenario)


@pytest.mark.slow
def test_the_mapping_is_written_at_start_and_the_drives_send_what_it_says():
    async def scenario() -> None:
        async with rig() as r:
            drive = r.drives.drives[ROW0].node
            for pdo in drive_pdos(3 + ROW0):
                pdo_map = (drive.rpdo if pdo.receive else drive.tpdo)[pdo.number]
                assert layout(pdo_map) == wanted_layout(pdo)
            master = r.bus._nodes[3 + ROW0]  # remapped as another master could
            statusword_only = Pdo(False, 1, 0x180 + 3 + ROW0, 1, ((0x6041, 0),))
            await asyncio.to_thread(configure, master.tpdo[1], statusword_only)
            sniffer = Sniffer(r.hub.local_channel)
            try:
                sniffer.drain()
                master.network.sync.transmit()
                await asyncio.sleep(scaled(0.1))
                sent = {m.arbitration_id: bytes(m.data) for m in sniffer.drain()}
            finally:
                sniffer.bus.shutdown()
            assert len(sent[0x180 + 3 + ROW0]) == 2  # the statusword alone, as mapped
            assert int.from_bytes(sent[0x180 + 3 + ROW0], "little") & 0x6F == 0x27
            assert len(sent[0x280 + 3 + ROW1]) == 8  # the others keep bwsd's mapping

    run(scenario)
