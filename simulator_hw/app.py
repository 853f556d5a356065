"""The whole mock loom: mechanics, Modbus server, socketcand hub with CANopen drives, control."""

from __future__ import annotations

import asyncio
import importlib.util
import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from bwsd.config import Config
from bwsd.errors import ConfigError, ExtraMissingError
from bwsd.extras import CANOPEN, missing_message
from bwsd.fieldbus.axes import machine_axes
from simulator_hw.control import ControlServer
from simulator_hw.loom import Loom, Speeds
from simulator_hw.modbus_server import ModbusLoomServer

if TYPE_CHECKING:
    from simulator_hw.canopen_drives import CanopenLoom
    from simulator_hw.socketcand_hub import SocketcandHub

CANOPEN_PART = "the CANopen side of the mock loom"


def canopen_installed() -> bool:
    """Whether the libraries of the CANopen drives (the ``canopen`` extra) can be imported."""
    try:
        return all(importlib.util.find_spec(name) is not None for name in CANOPEN.modules)
    except (ImportError, ValueError):  # a module blocked in sys.modules, or a broken one
        return False


def canopen_ids_problem(config: Config) -> str:
    """Why the node ids of ``[fieldbus.canopen]`` cannot give every axis a drive ("" if they
    can): a machine driven over Modbus may have more axes than CANopen has node ids."""
    can = config.table("fieldbus.canopen")
    base, io_node = can["node_base"], can["io_node"]
    last = base + len(machine_axes(config.machine)) - 1
    if last > 127 or base <= io_node <= last:
        return (
            f"the drives of its {last - base + 1} axes (nodes {base}..{last}) and the "
            f"I/O node {io_node} do not fit CANopen node ids 1..127"
        )
    return ""


def keep_mechanics(loom: Loom, path: Path) -> None:
    """Power on with the mechanics saved in ``path`` (if it exists, else the FILL), and save
    them there at every change: a killed mock loom comes back as a loom after a power cut,
    its cases where they were."""
    if path.exists():
        try:
            loom.restore(json.loads(path.read_text()))
        except (OSError, ValueError, TypeError, AttributeError) as exc:
            raise ConfigError(
                f"{path}: not the saved state of this machine ({exc})",
                table="simulator",
                key="state_file",
            ) from None

    def save() -> None:
        new = path.with_name(path.name + ".new")
        new.write_text(json.dumps(loom.mechanics()))
        os.replace(new, path)

    loom.on_change = save
    save()


class MockLoom:
    """Every part of the mock loom on the ``[simulator]`` addresses of a config.

    The CANopen node ids and the Modbus unit id are those of ``[fieldbus.canopen]`` and
    ``[fieldbus.modbus]``, so the daemon and the mock loom read the same config.

    ``canopen``: serve the socketcand hub with the CANopen drives. ``None`` (the default)
    does as ``[simulator] canopen`` says: ``"auto"`` serves them when their libraries (the
    package's ``canopen`` extra) are installed and the node ids hold a drive per axis,
    ``"off"`` never (an error when ``[fieldbus] backend = "canopen"`` asks for them);
    ``True`` requires them (``ExtraMissingError`` without, ``ConfigError`` when the ids do
    not fit); ``False`` serves Modbus only.
    """

    def __init__(
        self, config: Config, fill: Iterable[tuple[int, int]], *, canopen: bool | None = None
    ) -> None:
        sim = config.table("simulator")
        speeds = Speeds(
            sim["stroke_speed"], sim["takeup_speed"], sim["weft_speed"], sim["weft_travel_speed"]
        )
        self.config = config
        self.loom = Loom(config.machine, fill, speeds)
        if sim["state_file"]:
            keep_mechanics(self.loom, Path(config.path).parent / sim["state_file"])
        host = sim["host"]
        modbus = config.table("fieldbus.modbus")
        self.modbus = ModbusLoomServer(
            self.loom, host, sim["modbus_port"], modbus["device_id"], modbus["map"]
        )
        ids = canopen_ids_problem(config)
        wanted = sim["canopen"]
        if wanted == "off" and (canopen or config.table("fieldbus")["backend"] == "canopen"):
            raise ConfigError(
                'is "off", but the CANopen drives are asked for ([fieldbus] backend = "canopen")',
                path=config.path,
                table="simulator",
                key="canopen",
            )
        if canopen is None:
            canopen = wanted != "off" and canopen_installed() and not ids
        elif canopen and not canopen_installed():
            raise ExtraMissingError(missing_message(CANOPEN_PART, CANOPEN))
        elif canopen and ids:
            raise ConfigError(ids, path=config.path, table="fieldbus.canopen", key="node_base")
        self.hub: SocketcandHub | None = None
        if canopen:  # imported only here: python-can and canopen are an extra
            from simulator_hw.socketcand_hub import SocketcandHub

            self.hub = SocketcandHub(host, sim["socketcand_port"], faults=self.loom.faults)
        self.control = ControlServer(self.loom, host, sim["control_port"])
        self.drives: CanopenLoom | None = None

    async def start(self) -> None:
        can = self.config.table("fieldbus.canopen")
        sim = self.config.table("simulator")
        await self.modbus.start()
        if self.hub is not None:
            from simulator_hw.canopen_drives import CanopenLoom

            await self.hub.start()
            self.drives = CanopenLoom(
                self.loom,
                self.hub.local_channel,
                node_base=can["node_base"],
                io_node=can["io_node"],
                heartbeat_ms=sim["heartbeat_ms"],
                loop=asyncio.get_running_loop(),
            )
            self.drives.start()
        await self.control.start()

    async def stop(self) -> None:
        await self.control.stop()
        if self.drives is not None:
            await asyncio.to_thread(self.drives.stop)
            self.drives = None
        if self.hub is not None:
            await self.hub.stop()
        await self.modbus.stop()

    @property
    def ports(self) -> dict[str, int]:
        """The ports actually listened on (a configured 0 picks a free one); ``socketcand``
        only when the CANopen drives are served."""
        ports = {"modbus": self.modbus.port}
        if self.hub is not None:
            ports["socketcand"] = self.hub.port
        ports["control"] = self.control.port
        return ports
