"""`bwsd serve` with all three doors: OPC UA, the Modbus PLC tags and REST show one state.

The doors are read one after the other while a program runs; whenever REST reads the same
state and instruction before and after the other two were read, the other two must say
exactly that too (nothing happened in between that could excuse a difference).
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

import httpx
import pytest
from pymodbus.client import AsyncModbusTcpClient

from bwsd.api.auth import TokenStore
from bwsd.controller.packml import Command, State
from bwsd.controller.status import StopCause
from bwsd.plc import REG_COUNT, Tags, decode
from bwsd.plc.registers import REG_CNTRL_CMD
from tests.opcua.conftest import TEXT, client_cert, loom, run, session, trust, var
from tests.support.fieldbus import BUS, MACHINE, start_mock, toml
from tests.test_daemon import Served

pytestmark = pytest.mark.slow  # every test here is in the slow tier

READ = (
    "Status/StateCurrent",
    "Status/UnitModeCurrent",
    "Status/InstructionsDone",
    "Status/InstructionCount",
    "Admin/StopReason/ID",
    "Machine/EStop",
)


def served_config(tmp: Path, modbus_port: int, **api: Any) -> Path:
    path = tmp / "bwsd.toml"
    path.write_text(
        toml(
            {
                "machine": MACHINE,
                "fieldbus": {"backend": "modbus", **BUS},
                "fieldbus.modbus": {"port": modbus_port},
                "api": {"port": 0, **api},
                "plc": {"port": 0},
                "opcua": {"enabled": True, "port": 0},
            }
        )
    )
    return path


async def rest(http: httpx.AsyncClient) -> tuple[int, int, int, int, int, int]:
    s = (await http.get("/state")).raise_for_status().json()
    cause = StopCause[s["stop_cause"].upper()]
    return (s["state"], s["mode"], s["index"], s["count"], int(cause), int(bool(s["bus"]["estop"])))


async def modbus(client: AsyncModbusTcpClient) -> Tags:
    answer = await client.read_holding_registers(0, count=REG_COUNT, device_id=1)
    assert not answer.isError(), answer
    return decode(answer.registers)


@pytest.mark.slow
def test_opcua_modbus_and_rest_always_agree_during_a_run(tmp_path):
    mock = start_mock(tmp_path, {"stroke_speed": 100.0, "takeup_speed": 100.0})
    state = tmp_path / "state"
    state.mkdir()
    tokens = TokenStore.load(state / "tokens.json")
    token = tokens.add("line", "operator")
    cert = client_cert(tmp_path / "client")
    trust(state / "opcua", cert)
    served = Served(served_config(tmp_path, mock.ports["modbus"]), state, token)
    try:
        run(_agree(served, cert, token))
    finally:
        served.stop()
        mock.stop()


async def _agree(served: Served, cert: Any, token: str) -> None:
    urls = served.urls
    port = int(urls["plc"].rsplit(":", 1)[1])
    plc = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=2, retries=0)
    assert await plc.connect()
    headers = {"Authorization": f"Bearer {token}"}
    async with (
        httpx.AsyncClient(base_url=urls["api"] + "/api/v1", headers=headers, timeout=30) as http,
        session(urls["opcua"], cert, "line", token) as ua_client,
    ):
        nodes = [await var(ua_client, path) for path in READ]

        async def sample() -> tuple[Any, ...] | None:
            """All three views, or None when REST saw a change while the others were read."""
            before = await rest(http)
            tags = await modbus(plc)
            seen = tuple(await ua_client.read_values(nodes))
            after = await rest(http)
            if before != after:
                return None
            plc_view = (
                tags.state_current,
                tags.unit_mode_current,
                tags.instruction_index,
                tags.instruction_count,
                tags.stop_reason,
                tags.estop,
            )
            assert plc_view == before, f"Modbus {plc_view} != REST {before}"
            assert (*seen[:5], int(seen[5])) == before, f"OPC UA {seen} != REST {before}"
            return before

        loaded = await http.post("/programs", json={"name": "braid.bws", "text": TEXT})
        assert loaded.status_code == 201, loaded.text
        idx = await ua_client.get_namespace_index("urn:bwsd:packml")
        await (await loom(ua_client)).call_method(f"{idx}:Reset")  # OPC UA resets,
        await plc.write_registers(
            REG_CNTRL_CMD, [int(Command.START), 1], device_id=1
        )  # Modbus starts
        compared: list[tuple[Any, ...]] = []
        deadline = time.monotonic() + 90
        while not compared or compared[-1][0] != State.COMPLETE:
            assert time.monotonic() < deadline, f"no Complete: {compared[-1:]}"
            if (agreed := await sample()) is not None:
                compared.append(agreed)
            await asyncio.sleep(0.005)
        running = [c for c in compared if c[0] == State.EXECUTE and 0 < c[2] < 15]
        assert len(running) >= 3, compared  # they agreed while instructions ran, not only at rest
        assert compared[-1][2:4] == (15, 15)
        assert (await modbus(plc)).good_count == 1
        assert await (await var(ua_client, "Admin/ProdGoodCount")).read_value() == 1
        (await http.post("/commands/reset", json={})).raise_for_status()  # REST resets
        while (agreed := await sample()) is None or agreed[0] != State.IDLE:
            await asyncio.sleep(0.01)
    plc.close()


def test_the_daemons_log_says_where_opcua_listens_without_the_librarys_start_up(tmp_path):
    """asyncua logs a line at INFO for every node of the standard address space it builds:
    with OPC UA on, a start wrote over a thousand lines to the journal."""
    mock = start_mock(tmp_path, {})
    state = tmp_path / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("line", "operator")
    served = Served(served_config(tmp_path, mock.ports["modbus"]), state, token)
    try:
        assert served.state()["name"]
    finally:
        served.stop()
        mock.stop()
    lines = served.log.read_text().splitlines()
    assert any("bwsd.opcua.server: OPC UA on opc.tcp://" in line for line in lines), lines[-5:]
    assert [line for line in lines if " INFO asyncua." in line] == []
    assert len(lines) < 50, len(lines)
