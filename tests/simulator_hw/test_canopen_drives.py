"""The mock loom's CANopen nodes, answered through the hub to a canopen RemoteNode."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import canopen
import pytest

from bwsd.fieldbus.cia402 import DRIVE_OBJECTS, IO_OBJECTS, Cia402, dictionary
from bwsd.twin import Machine
from simulator_hw.canopen_drives import CanopenLoom
from simulator_hw.loom import Loom, Speeds
from simulator_hw.socketcand_hub import SocketcandHub
from tests.timing import scaled

MACHINE = Machine(rows=2, cols=3, pitch_x=10, pitch_y=20, d_mat=100, c_mat=0.5)
ROW0, COL0, TAKEUP = 0, 2, 7
NODE_BASE, IO_NODE = 5, 64
STATUS_MASK = 0x6F


@dataclass
class Rig:
    loom: Loom
    network: canopen.Network
    heartbeats: list[tuple[int, int]] = field(default_factory=list)  # (node id, NMT state)

    def drive(self, axis: int) -> canopen.RemoteNode:
        return self.remote(NODE_BASE + axis)

    def remote(self, node_id: int) -> canopen.RemoteNode:
        node = self.network[node_id]
        assert isinstance(node, canopen.RemoteNode)  # the rig adds remote nodes only
        return node

    async def get(self, node: canopen.RemoteNode, index: int) -> Any:
        return await asyncio.to_thread(lambda: node.sdo[index].raw)

    async def set(self, node: canopen.RemoteNode, index: int, value: int) -> None:
        def write() -> None:
            node.sdo[index].raw = value

        await asyncio.to_thread(write)

    async def state(self, node: canopen.RemoteNode) -> Cia402 | None:
        return Cia402.of(await self.get(node, 0x6041))

    async def enable(self, node: canopen.RemoteNode) -> None:
        for word in (0x06, 0x07, 0x0F):
            await self.set(node, 0x6040, word)


def run(scenario: Callable[[], Awaitable[None]]) -> None:
    asyncio.run(asyncio.wait_for(scenario(), 20))


@asynccontextmanager
async def rig(speeds: Speeds | None = None) -> AsyncIterator[Rig]:
    loom = Loom(MACHINE, [(0, 0), (1, 2)], speeds or Speeds())
    hub = SocketcandHub(faults=loom.faults)
    await hub.start()
    drives = CanopenLoom(
        loom,
        hub.local_channel,
        node_base=NODE_BASE,
        io_node=IO_NODE,
        heartbeat_ms=20,
        loop=asyncio.get_running_loop(),
    )
    drives.start()
    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.05
    r = Rig(loom, network)
    for i in range(len(loom.axes)):
        network.add_node(canopen.RemoteNode(NODE_BASE + i, dictionary(DRIVE_OBJECTS)))
    network.add_node(canopen.RemoteNode(IO_NODE, dictionary(IO_OBJECTS)))
    for node_id in network:
        network.subscribe(
            0x700 + node_id, lambda cob, data, _: r.heartbeats.append((cob - 0x700, data[0]))
        )
    try:
        await asyncio.to_thread(
            network.connect, interface="socketcand", host="127.0.0.1", port=hub.port, channel="can0"
        )
        yield r
    finally:
        await asyncio.to_thread(network.disconnect)
        await asyncio.to_thread(drives.stop)
        await hub.stop()


async def until(condition: Callable[[], bool], limit: float = 5.0) -> None:
    async with asyncio.timeout(scaled(limit)):
        while not condition():
            await asyncio.sleep(0.005)


def test_objects_read_and_write_by_sdo():
    async def scenario() -> None:
        async with rig() as r:
            drive, io = r.drive(TAKEUP), r.remote(IO_NODE)
            assert await r.get(drive, 0x1017) == 20
            assert await r.get(drive, 0x6041) == 0x0440  # switch-on disabled, target reached
            await r.set(drive, 0x607A, -1234)
            assert await r.get(drive, 0x607A) == -1234
            await r.set(drive, 0x6060, 1)
            assert await r.get(drive, 0x6061) == 1
            for index in (0x6064, 0x603F, 0x2001, 0x2002, 0x2004):
                assert await r.get(drive, index) == 0
            # row-major, least significant bit first: cells 0 and 5 of six
            assert await r.get(io, 0x2000) == bytes([0b00100001])
            assert await r.get(io, 0x2005) == 0
            r.loom.press_estop(True, time.monotonic())
            assert await r.get(io, 0x2005) == 1
            with pytest.raises(canopen.SdoAbortedError):
                await r.set(drive, 0x6041, 0)  # read-only
            with pytest.raises(canopen.SdoAbortedError):
                await asyncio.to_thread(drive.sdo.upload, 0x2000, 0)  # not a drive object

    run(scenario)


def test_enable_needs_nmt_start_then_a_stroke_moves_the_cases():
    async def scenario() -> None:
        async with rig() as r:
            row0, io = r.drive(ROW0), r.remote(IO_NODE)
            await r.set(row0, 0x6060, 1)
            await r.enable(row0)
            assert await r.state(row0) is Cia402.SWITCHED_ON  # NMT still pre-operational
            await asyncio.to_thread(r.network.nmt.send_command, 0x01)
            await until(lambda: (NODE_BASE + ROW0, 0x05) in r.heartbeats)
            await r.set(row0, 0x6040, 0x0F)
            assert await r.state(row0) is Cia402.OPERATION_ENABLED
            await r.set(row0, 0x607A, 10_000)
            await r.set(row0, 0x2003, 5)
            await r.set(row0, 0x6040, 0x5F)  # new set-point, relative
            assert await r.get(row0, 0x6041) & 0x1000  # acknowledged
            await r.set(row0, 0x6040, 0x0F)
            assert not await r.get(row0, 0x6041) & 0x1000
            assert await r.get(row0, 0x2002) == 5 and await r.get(row0, 0x2001) == 10_000
            assert await r.get(io, 0x2000) == bytes([0b00100010])  # (0, 0) -> (0, 1)
            with pytest.raises(canopen.SdoAbortedError):
                await r.set(row0, 0x6040, 0x1F)  # a stroke must be relative

    run(scenario)


def test_absolute_and_relative_set_points_of_the_takeup():
    async def scenario() -> None:
        async with rig() as r:
            takeup = r.drive(TAKEUP)
            await asyncio.to_thread(r.network.nmt.send_command, 0x01)
            await r.set(takeup, 0x6060, 1)
            await r.enable(takeup)
            for seq, (word, target) in enumerate([(0x1F, 4_000), (0x5F, 500)], start=1):
                await r.set(takeup, 0x607A, target)
                await r.set(takeup, 0x2003, seq)
                await r.set(takeup, 0x6040, word)
                await r.set(takeup, 0x6040, 0x0F)
            assert await r.get(takeup, 0x6064) == 4_500
            assert await r.get(takeup, 0x2002) == 2

    run(scenario)


def test_faults_quick_stop_reset_and_homing():
    async def scenario() -> None:
        async with rig(Speeds(stroke=10)) as r:
            col0, row0 = r.drive(COL0), r.drive(ROW0)
            await asyncio.to_thread(r.network.nmt.send_command, 0x01)
            for node in (col0, row0):
                await r.set(node, 0x6060, 1)
                await r.enable(node)
            r.loom.faults.drive.add("col0")
            await r.set(col0, 0x2003, 1)
            await r.set(col0, 0x6040, 0x5F)
            assert await r.state(col0) is Cia402.FAULT
            assert (await r.get(col0, 0x603F), await r.get(col0, 0x2004)) == (0x5530, 3)
            await r.set(row0, 0x607A, 10_000)
            await r.set(row0, 0x6040, 0x5F)
            await r.set(row0, 0x6040, 0x02)  # quick stop while the stroke runs
            assert await r.state(row0) is Cia402.FAULT and await r.get(row0, 0x2004) == 2
            await r.set(row0, 0x6040, 0x80)  # fault reset clears the loom's faults
            assert await r.state(row0) is Cia402.SWITCH_ON_DISABLED
            assert await r.state(col0) is Cia402.SWITCH_ON_DISABLED
            r.loom.axes[ROW0].done_seq = 9
            await r.enable(row0)
            await r.set(row0, 0x6060, 6)
            await r.set(row0, 0x6040, 0x1F)  # start homing
            assert await r.get(row0, 0x6041) & 0x1400 == 0x1400  # homing attained, at target
            assert await r.get(row0, 0x2002) == 0 and await r.get(row0, 0x6061) == 6

    run(scenario)


def test_every_node_boots_and_sends_heartbeats():
    async def scenario() -> None:
        async with rig() as r:
            ids = set(r.network)
            await until(lambda: {node for node, _ in r.heartbeats} == ids)
            assert all(state == 0x7F for _, state in r.heartbeats)  # pre-operational
            await asyncio.to_thread(r.network.nmt.send_command, 0x01)
            await until(lambda: {n for n, state in r.heartbeats if state == 0x05} == ids)

    run(scenario)
