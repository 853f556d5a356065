"""The whole mock loom: mechanics, Modbus server, socketcand hub with CANopen drives, control."""

from __future__ import annotations

import asyncio
from collections.abc import Iterable

from bwsd.config import Config
from simulator_hw.canopen_drives import CanopenLoom
from simulator_hw.control import ControlServer
from simulator_hw.loom import Loom, Speeds
from simulator_hw.modbus_server import ModbusLoomServer
from simulator_hw.socketcand_hub import SocketcandHub


class MockLoom:
    """Every part of the mock loom on the ``[simulator]`` addresses of a config.

    The CANopen node ids and the Modbus unit id are those of ``[fieldbus.canopen]`` and
    ``[fieldbus.modbus]``, so the daemon and the mock loom read the same config.
    """

    def __init__(self, config: Config, fill: Iterable[tuple[int, int]]) -> None:
        sim = config.table("simulator")
        speeds = Speeds(sim["stroke_speed"], sim["takeup_speed"], sim["weft_speed"])
        self.config = config
        self.loom = Loom(config.machine, fill, speeds)
        host = sim["host"]
        unit = config.table("fieldbus.modbus")["device_id"]
        self.modbus = ModbusLoomServer(self.loom, host, sim["modbus_port"], unit)
        self.hub = SocketcandHub(host, sim["socketcand_port"], faults=self.loom.faults)
        self.control = ControlServer(self.loom, host, sim["control_port"])
        self.drives: CanopenLoom | None = None

    async def start(self) -> None:
        can = self.config.table("fieldbus.canopen")
        sim = self.config.table("simulator")
        await self.modbus.start()
        await self.hub.start()
        self.drives = CanopenLoom(self.loom, self.hub.local_channel, node_base=can["node_base"],
                                  io_node=can["io_node"], heartbeat_ms=sim["heartbeat_ms"],
                                  loop=asyncio.get_running_loop())  # fmt: skip
        self.drives.start()
        await self.control.start()

    async def stop(self) -> None:
        await self.control.stop()
        if self.drives is not None:
            await asyncio.to_thread(self.drives.stop)
            self.drives = None
        await self.hub.stop()
        await self.modbus.stop()

    @property
    def ports(self) -> dict[str, int]:
        """The ports actually listened on (a configured 0 picks a free one)."""
        return {"modbus": self.modbus.port, "socketcand": self.hub.port,
                "control": self.control.port}  # fmt: skip
