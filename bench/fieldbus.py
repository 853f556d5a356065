"""Benchmark of the bus backends: prints the markdown table of docs/benchmarks.md.

    python bench/fieldbus.py [--rounds 200]

The mock loom runs in its own process (zero travel time) on loopback. For each bus: the
round trip of one shift through the backend (command, wait for completion, read back the
machine state) beside the floor of the bare library on the same connection kind, measured
in the same run: a bare pymodbus register write + read, a bare canopen SDO write + read.
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

import canopen
import numpy as np
from canopen.objectdictionary import INTEGER32, ObjectDictionary, ODVariable
from pymodbus.client import AsyncModbusTcpClient

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.fieldbus import AxisMove, Fieldbus, open_bus  # noqa: E402
from bwsd.fieldbus.axes import axis_by_name, shift_stroke_um  # noqa: E402
from tests.fieldbus.conftest import Mock, client_config, start_mock  # noqa: E402

TARGET_REGISTER = 100 + 16 * 10  # the take-up axis's target on the 4 x 4 mock (axis 10)


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


def canopen_floor(mock: Mock, rounds: int) -> list[float]:
    network = canopen.Network()
    network.connect(interface="socketcand", channel="can0", host="127.0.0.1",
                    port=mock.ports["socketcand"])  # fmt: skip
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


async def backend_round_trip(mock: Mock, backend: str, rounds: int) -> list[float]:
    bus: Fieldbus = open_bus(client_config(backend, mock.ports))
    await bus.connect()
    axis = axis_by_name(bus.machine, "row1")
    strokes = [shift_stroke_um(bus.machine, axis, k) for k in (1, -1)]
    at_left = bool((await bus.state()).occupancy[1, 0])  # then the next stroke goes right
    flip = [1 if at_left else 0]

    async def step() -> None:
        flip[0] ^= 1
        await bus.execute([AxisMove(axis.index, strokes[flip[0]])])

    try:
        return await timed(step, rounds)
    finally:
        await bus.close()


def row(name: str, values: list[float], floor: list[float] | None) -> str:
    p50, p99 = statistics.median(values) * 1e3, float(np.percentile(values, 99)) * 1e3
    ratio = f"{statistics.median(values) / statistics.median(floor):.2f}" if floor else ""
    return f"| {name} | {len(values)} | {p50:.2f} | {p99:.2f} | {ratio} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=200)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        mock = start_mock(Path(tmp), {})
        try:
            rows = [
                "| round trip | n | p50 ms | p99 ms | p50 / floor |",
                "|---|---:|---:|---:|---:|",
            ]
            floor = asyncio.run(modbus_floor(mock, args.rounds))
            rows.append(row("bare pymodbus write + read (floor)", floor, None))
            ours = asyncio.run(backend_round_trip(mock, "modbus", args.rounds))
            rows.append(row("modbus backend: shift, wait, read back", ours, floor))
            floor = canopen_floor(mock, args.rounds)
            rows.append(row("bare canopen SDO write + read (floor)", floor, None))
            ours = asyncio.run(backend_round_trip(mock, "canopen", max(20, args.rounds // 4)))
            rows.append(row("canopen backend: shift, wait, read back", ours, floor))
        finally:
            mock.stop()
    print("Mock loom in its own process on loopback, 4 x 4 matrix (11 axes), zero travel time.\n")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
