"""Benchmark of the bus backends: prints the markdown tables of docs/benchmarks.md.

    python bench/fieldbus.py [--rounds 200] [--rounds-24 50]

The mock loom runs in its own process (zero travel time) on loopback. For each bus, on a
4 x 4 machine (11 axes): the round trip of one shift through the backend (command, wait
for completion, read back the machine state) beside the floor of the bare library on the
same connection (python-can's socketcand client with `tcp_tune`, as the backend opens
it), measured in the same run: a bare pymodbus register write + read, a bare
canopen SDO write + read (the floor the targets are set against) and, for information, a
bare canopen RPDO + SYNC + TPDO exchange on the mapping bwsd wrote. Then, on a 24 x 24
machine (51 axes) on each bus: one row axis alone, and the 24 row axes at once.
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import canopen
import numpy as np
from canopen.objectdictionary import INTEGER32, ObjectDictionary, ODVariable
from pymodbus.client import AsyncModbusTcpClient

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.fieldbus import AxisMove, Fieldbus, open_bus  # noqa: E402
from bwsd.fieldbus.axes import axis_by_name, shift_stroke_um  # noqa: E402
from bwsd.fieldbus.canopen_pdo import CONTROLWORD  # noqa: E402
from bwsd.fieldbus.cia402 import drive_dictionary  # noqa: E402
from tests.support.fieldbus import MACHINE, Mock, client_config, start_mock  # noqa: E402

TARGET_REGISTER = 100 + 16 * 10  # the take-up axis's target on the 4 x 4 mock (axis 10)
ROW1_NODE = 2  # node_base 1 + axis 1
M24 = {**MACHINE, "rows": 24, "cols": 24}
FILL24 = "FILL row=0 col=0\n" + "X.......................\n" * 24 + "END\n"  # a case a row


async def timed(step: Callable[[], Awaitable[object]], rounds: int) -> list[float]:
    for _ in range(5):
        await step()  # warm up
    out = []
    for _ in range(rounds):
        start = time.perf_counter()
        await step()
        out.append(time.perf_counter() - start)
    return out


async def modbus_floor(mock: Mock, rounds: int) -> list[float]:
    client = AsyncModbusTcpClient("127.0.0.1", port=mock.ports["modbus"], timeout=1.0)
    await client.connect()

    async def step() -> None:
        await client.write_registers(TARGET_REGISTER, [0, 1], device_id=1)
        await client.read_holding_registers(TARGET_REGISTER, count=2, device_id=1)

    try:
        return await timed(step, rounds)
    finally:
        client.close()


def canopen_network(mock: Mock) -> canopen.Network:
    network = canopen.Network()
    network.connect(
        interface="socketcand",
        channel="can0",
        host="127.0.0.1",
        port=mock.ports["socketcand"],
        tcp_tune=True,
    )
    return network


def sdo_floor(mock: Mock, rounds: int) -> list[float]:
    network = canopen_network(mock)
    od = ObjectDictionary()
    od.add_object(ODVariable("target", 0x607A))
    od["target"].data_type = INTEGER32
    node = network.add_node(canopen.RemoteNode(1, od))
    try:
        out = []
        for i in range(rounds + 5):
            start = time.perf_counter()
            node.sdo[0x607A].raw = 0
            _ = node.sdo[0x607A].raw
            if i >= 5:
                out.append(time.perf_counter() - start)
        return out
    finally:
        network.disconnect()


def pdo_floor(mock: Mock, rounds: int) -> list[float]:
    """An RPDO that changes nothing (controlword 0x0F), a SYNC, the drive's TPDO2 back: on
    the mapping a backend wrote (the mock loom answers every SYNC with every node's PDOs)."""
    network = canopen_network(mock)
    node = network.add_node(canopen.RemoteNode(ROW1_NODE, drive_dictionary(ROW1_NODE)))
    try:
        node.rpdo.read()
        node.tpdo.read()
        rpdo, tpdo = node.rpdo[1], node.tpdo[2]
        out = []
        for i in range(rounds + 5):
            start = time.perf_counter()
            rpdo[CONTROLWORD].raw = 0x0F
            rpdo.transmit()
            with tpdo.receive_condition:
                tpdo.is_received = False
                network.sync.transmit()
                tpdo.receive_condition.wait_for(lambda: tpdo.is_received, 1.0)
            if i >= 5:
                out.append(time.perf_counter() - start)
        return out
    finally:
        network.disconnect()


async def shifts(
    mock: Mock, backend: str, machine: dict[str, Any], rows: list[int], rounds: int
) -> list[float]:
    """Shift ``rows`` together by one cell and back, alternately: one execute a round."""
    bus: Fieldbus = open_bus(client_config(backend, mock.ports, machine=machine))
    await bus.connect()
    axes = [axis_by_name(bus.machine, f"row{r}") for r in rows]
    state = await bus.state()
    signs = [1 if state.occupancy[r, 0] else -1 for r in rows]  # at the left: go right first

    async def step() -> None:
        moves = [
            AxisMove(a.index, shift_stroke_um(bus.machine, a, k))
            for a, k in zip(axes, signs, strict=True)
        ]
        await bus.execute(moves)
        signs[:] = [-k for k in signs]

    try:
        return await timed(step, rounds)
    finally:
        await bus.close()


def row(name: str, values: list[float], base: list[float] | None) -> str:
    p50, p99 = statistics.median(values) * 1e3, float(np.percentile(values, 99)) * 1e3
    ratio = f"{statistics.median(values) / statistics.median(base):.2f}" if base else ""
    return f"| {name} | {len(values)} | {p50:.2f} | {p99:.2f} | {ratio} |"


def small(rounds: int) -> list[str]:
    rows = [
        "| round trip (4 x 4, 11 axes) | n | p50 ms | p99 ms | p50 / floor |",
        "|---|---:|---:|---:|---:|",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        mock = start_mock(Path(tmp), {})
        try:
            floor = asyncio.run(modbus_floor(mock, rounds))
            rows.append(row("bare pymodbus write + read (floor)", floor, None))
            ours = asyncio.run(shifts(mock, "modbus", MACHINE, [1], rounds))
            rows.append(row("modbus backend: shift, wait, read back", ours, floor))
            floor = sdo_floor(mock, rounds)
            rows.append(row("bare canopen SDO write + read (floor)", floor, None))
            ours = asyncio.run(shifts(mock, "canopen", MACHINE, [1], rounds))
            rows.append(row("canopen backend: shift, wait, read back", ours, floor))
            pdo = pdo_floor(mock, rounds)  # on the mapping the backend wrote
            rows.append(row("bare canopen RPDO + SYNC + TPDO (for information)", pdo, floor))
        finally:
            mock.stop()
    return rows


def large(rounds: int) -> list[str]:
    rows = [
        "| 24 x 24 (51 axes) | n | p50 ms | p99 ms | p50 / one axis |",
        "|---|---:|---:|---:|---:|",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        mock = start_mock(Path(tmp), {}, machine=M24, program=FILL24)
        try:
            for backend in ("modbus", "canopen"):
                one = asyncio.run(shifts(mock, backend, M24, [0], rounds))
                rows.append(row(f"{backend}: one row axis", one, None))
                every = asyncio.run(shifts(mock, backend, M24, list(range(24)), rounds))
                rows.append(row(f"{backend}: 24 row axes at once", every, one))
        finally:
            mock.stop()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=200)
    parser.add_argument("--rounds-24", type=int, default=50)
    args = parser.parse_args()
    print("Mock loom in its own process on loopback, zero travel time.\n")
    print("\n".join(small(args.rounds)))
    print()
    print("\n".join(large(args.rounds_24)))


if __name__ == "__main__":
    main()
