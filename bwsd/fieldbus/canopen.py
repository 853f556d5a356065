"""CANopen backend: CiA 402 drives in profile position mode and an I/O node.

The object map is docs/fieldbus-canopen.md; its objects and dictionaries are in
bwsd.fieldbus.cia402 (the mock loom's drives use them too). Motion and the read-back go by PDO
(bwsd.fieldbus.canopen_pdo: a set-point is one receive PDO pair, a read-back one SYNC);
SDO is left to configuration (heartbeat, mode, the PDO mapping), the CiA 402 state walk,
homing, quick stop, fault reset and the claim. canopen is synchronous: SDO exchanges and
the wait for a SYNC's answers run in worker threads, so the event loop never blocks.
"""

from __future__ import annotations

import asyncio
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from typing import Any

import can
import numpy as np
from canopen import Network, RemoteNode, SdoAbortedError, SdoCommunicationError

from bwsd.config import Config
from bwsd.fieldbus import settings_from_config
from bwsd.fieldbus.axes import Axis
from bwsd.fieldbus.base import (
    FAULT_DRIVE,
    AxisState,
    BusSettings,
    DriveFault,
    Fieldbus,
    FieldbusConnectionError,
    FieldbusError,
    FieldbusTimeout,
    MachineState,
)
from bwsd.fieldbus.canlink import LinkWatch, Socketcand, shutdown
from bwsd.fieldbus.canopen_pdo import (
    CONTROLWORD,
    DONE_SEQ,
    ESTOP,
    FAULT_CODE,
    LAST_STROKE,
    OCCUPANCY_WORDS,
    POSITION,
    SETPOINT_SEQ,
    STATUSWORD,
    STROKES,
    SYNC_ON_CHANGE,
    TARGET,
    Entry,
    Pdo,
    SyncSampler,
    configure,
    drive_pdos,
    io_pdos,
    layout,
    wanted_layout,
)
from bwsd.fieldbus.cia402 import (
    CW_DISABLE_VOLTAGE,
    CW_ENABLE,
    CW_NEW_SETPOINT,
    CW_QUICK_STOP,
    CW_RELATIVE,
    HEARTBEAT,
    MODE,
    MODE_HOMING,
    MODE_PROFILE_POSITION,
    NMT_START,
    OWNER,
    OWNER_PID,
    SW_TARGET_REACHED,
    WALK,
    Cia402,
    drive_dictionary,
    io_dictionary,
)
from bwsd.twin.machine import Machine


class CanopenBus(Fieldbus):
    """The machine's actuators as CANopen nodes, reached through python-can."""

    def __init__(
        self,
        machine: Machine,
        settings: BusSettings,
        interface: str = "socketcand",
        channel: str = "can0",
        host: str = "127.0.0.1",
        port: int = 29536,
        node_base: int = 1,
        io_node: int = 127,
        heartbeat_ms: int = 100,
    ) -> None:
        super().__init__(machine, settings)
        self.interface, self.channel, self.host, self.port = interface, channel, host, port
        self.drive_ids = [node_base + axis.index for axis in self.axes]
        self.io_node = io_node
        self.heartbeat_ms = heartbeat_ms
        self._network: Network | None = None
        self._sampler: SyncSampler | None = None
        self._nodes: dict[int, RemoteNode] = {}
        self._locks = {i: threading.Lock() for i in [*self.drive_ids, io_node]}
        self._seen: dict[int, float] = {}
        self._watch: LinkWatch | None = None
        self._io_pdos = io_pdos(machine.rows * machine.cols)
        self._statusword: dict[int, int] = {}  # each drive's, at the last SYNC

    @classmethod
    def from_config(cls, config: Config) -> CanopenBus:
        """The bus of ``[fieldbus]`` and ``[fieldbus.canopen]``."""
        settings = settings_from_config(config)
        return cls(config.machine, settings, **config.table("fieldbus.canopen"))

    # ----- hooks -----
    async def _open(self) -> None:
        await asyncio.to_thread(self._connect_network)
        try:
            await self._each(self._init_node, [*self.drive_ids, self.io_node])
        except FieldbusTimeout as exc:
            await self._teardown()
            raise FieldbusConnectionError(str(exc)) from exc
        except FieldbusError:
            await self._teardown()
            raise
        self._seen = dict.fromkeys(self._locks, time.monotonic())

    async def _close(self) -> None:
        await self._teardown()

    async def _write_setpoint(self, axis: Axis, target: int, seq: int) -> None:
        """A set-point by RPDO: controlword 0x0F, then 0x1F (0x5F relative) with the target
        and sequence, so bit 4 rises; ``wait`` sees it taken (or refused) at the next SYNC."""
        await self._ready()
        node = self.drive_ids[axis.index]
        state = Cia402.of(self._statusword.get(node, 0))
        if state is not Cia402.OPERATION_ENABLED and state is not Cia402.FAULT:
            await self._gather([partial(self._enable, node, False)])
        rpdo = self._nodes[node].rpdo[1]
        start = CW_ENABLE | CW_NEW_SETPOINT | (CW_RELATIVE * axis.relative)
        try:
            for word in (CW_ENABLE, start):
                rpdo[CONTROLWORD].raw, rpdo[TARGET].raw, rpdo[SETPOINT_SEQ].raw = word, target, seq
                rpdo.transmit()
        except (can.CanError, OSError) as exc:
            await self._teardown()
            raise FieldbusConnectionError(f"{self._name(node)}: CAN bus lost: {exc}") from exc
        except (ValueError, struct.error) as exc:
            raise FieldbusError(f"axis {axis.name}: target {target} does not fit: {exc}") from None

    async def _read_state(self, axes: Sequence[int] | None = None) -> MachineState:
        """One SYNC: the TPDOs of the axes asked for and of the I/O node, sampled together."""
        await self._ready()
        sampler = self._sampler
        assert sampler is not None
        wanted = list(range(len(self.axes))) if axes is None else sorted(set(axes))
        every = [(self.drive_ids[i], 2) for i in wanted]
        every += [(self.io_node, pdo.number) for pdo in self._io_pdos]
        kept = [(self.drive_ids[i], 1) for i in wanted]
        try:
            got = await sampler.sample(every, kept, self.settings.io_timeout)
        except FieldbusTimeout as exc:
            problem = self._link_problem()
            if problem:
                await self._teardown()
                raise FieldbusConnectionError(f"{problem} ({exc})") from exc
            raise
        except (can.CanError, OSError) as exc:
            await self._teardown()
            raise FieldbusConnectionError(f"CAN bus lost: {exc}") from exc
        read = {}
        for i in wanted:
            values = got[(self.drive_ids[i], 1)] | got[(self.drive_ids[i], 2)]
            self._statusword[self.drive_ids[i]] = values[(STATUSWORD, 0)]
            read[i] = self._axis_state(values)
        io: dict[Entry, int] = {}
        for pdo in self._io_pdos:
            io |= got[(self.io_node, pdo.number)]
        return self._merge(read, self._occupancy(io), bool(io[(ESTOP, 0)]))

    async def _quick_stop(self) -> None:
        await self._ready()
        await self._each(lambda node: self._set(node, CONTROLWORD, CW_QUICK_STOP), self.drive_ids)

    async def _reset_faults(self) -> None:
        await self._ready()
        await self._each(lambda node: self._enable(node, reset=True), self.drive_ids)

    async def _claim(self, ident: int, pid: int) -> tuple[int, int] | None:
        await self._ready()
        result: tuple[int, int] | None = await asyncio.to_thread(self._claim_io, ident, pid)
        return result

    async def _home(self) -> None:
        await self._ready()
        homed = [self.drive_ids[a.index] for a in self.axes if a.kind != "takeup"]
        await self._each(self._home_drive, homed)

    # ----- connection -----
    def _connect_network(self) -> None:
        """Open python-can and add the nodes (blocking)."""
        network = Network()
        network.NOTIFIER_CYCLE = 0.1  # how long disconnect() waits for the receive thread
        watch = LinkWatch(network)
        self._nodes = {i: self._add_node(network, i) for i in self._locks}
        try:
            network.bus = self._socketcand() if self.interface == "socketcand" else None
            network.connect(interface=self.interface, channel=self.channel)
            if network.notifier is not None:
                network.notifier.add_listener(watch)
        except (can.CanError, OSError, ValueError) as exc:
            shutdown(network)
            raise FieldbusConnectionError(f"cannot open the CAN bus: {exc}") from exc
        self._network, self._watch = network, watch
        self._sampler = SyncSampler(network)
        watch.on_lost = self._sampler.fail  # a sample waiting for the dead link ends now

    def _socketcand(self) -> can.BusABC:
        where = f"socketcand at {self.host}:{self.port}"
        try:  # python-can retries a refused connection for 10 s: ask once first
            socket.create_connection((self.host, self.port), self.settings.io_timeout).close()
        except OSError as exc:
            raise FieldbusConnectionError(f"cannot reach {where}: {exc}") from exc
        try:
            return Socketcand(  # type: ignore[no-untyped-call]
                channel=self.channel, host=self.host, port=self.port, tcp_tune=True
            )
        except (can.CanError, OSError) as exc:
            raise FieldbusConnectionError(f"{where}: {exc}") from exc

    def _add_node(self, network: Network, node_id: int) -> RemoteNode:
        cells = self.machine.rows * self.machine.cols
        od = io_dictionary(cells) if node_id == self.io_node else drive_dictionary(node_id)
        node = RemoteNode(node_id, od)
        node.sdo.RESPONSE_TIMEOUT = self.settings.io_timeout
        network.add_node(node)
        network.subscribe(0x700 + node_id, self._on_heartbeat)
        return node

    def _on_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        self._seen[can_id - 0x700] = time.monotonic()

    async def _ready(self) -> None:
        """Reconnect after a loss; raise when the link or a node's heartbeat is gone."""
        if self._network is None:
            await self.connect()
        problem = self._link_problem()
        if problem:
            await self._teardown()
            raise FieldbusConnectionError(problem)

    def _lost(self) -> Exception | None:
        """The receive error that ended the link, if any."""
        return self._watch.error if self._watch is not None else None

    def _link_problem(self) -> str:
        if self._lost() is not None:
            return f"connection to the CAN bus lost: {self._lost()}"
        if self.heartbeat_ms <= 0:
            return ""
        now, limit = time.monotonic(), 3 * self.heartbeat_ms / 1000
        for node_id, seen in self._seen.items():
            if now - seen > limit:
                return f"{self._name(node_id)}: no heartbeat for {now - seen:.2f} s"
        return ""

    async def _teardown(self) -> None:
        network, self._network = self._network, None
        if network is not None:
            await asyncio.to_thread(shutdown, network)

    # ----- running SDO work off the event loop -----
    async def _each(self, fn: Callable[[int], object], items: Iterable[int]) -> None:
        """``fn(item)`` for every item, in parallel worker threads."""
        await self._gather([partial(fn, item) for item in items])

    async def _gather(self, calls: Sequence[Callable[[], Any]]) -> list[Any]:
        """Run the calls in parallel worker threads; the worst error is raised after all end."""
        threads = [asyncio.to_thread(call) for call in calls]
        results = await asyncio.gather(*threads, return_exceptions=True)
        errors = [r for r in results if isinstance(r, BaseException)]
        if errors:
            lost = [e for e in errors if isinstance(e, FieldbusConnectionError)]
            if lost:
                await self._teardown()
            raise (lost or errors)[0]
        return list(results)

    # ----- blocking work, in worker threads -----
    def _sdo(self, node_id: int, index: int, value: int | None = None) -> Any:
        """Read (or write ``value`` to) object ``index`` of a node; errors by phase."""
        node = self._nodes[node_id]
        try:
            with self._locks[node_id]:
                if value is None:
                    return node.sdo[index].raw
                node.sdo[index].raw = value
                return None
        except SdoCommunicationError as exc:
            what = f"{self._name(node_id)}: no answer to SDO 0x{index:04X} ({exc})"
            if self._lost() is not None:
                raise FieldbusConnectionError(f"{what}; link lost: {self._lost()}") from exc
            raise FieldbusTimeout(what) from exc
        except SdoAbortedError as exc:
            raise FieldbusError(f"{self._name(node_id)}: SDO 0x{index:04X} refused: {exc}") from exc
        except (can.CanError, OSError, RuntimeError) as exc:
            raise FieldbusConnectionError(f"{self._name(node_id)}: CAN bus lost: {exc}") from exc

    def _get(self, node_id: int, index: int) -> int:
        value = self._sdo(node_id, index)
        if not isinstance(value, int):
            raise FieldbusError(f"{self._name(node_id)}: 0x{index:04X} is not a number")
        return value

    def _set(self, node_id: int, index: int, value: int) -> None:
        self._sdo(node_id, index, value)

    def _init_node(self, node_id: int) -> None:
        """Heartbeat, the PDO mapping (written only where it differs: another master's
        PDOs go on undisturbed), NMT start; a drive: profile position, operation enabled."""
        self._set(node_id, HEARTBEAT, self.heartbeat_ms)
        drive = node_id != self.io_node
        for pdo in drive_pdos(node_id) if drive else self._io_pdos:
            self._map_pdo(node_id, pdo)
        self._nodes[node_id].nmt.send_command(NMT_START)
        if drive:
            self._set(node_id, MODE, MODE_PROFILE_POSITION)
            self._enable(node_id, reset=False)

    def _map_pdo(self, node_id: int, pdo: Pdo) -> None:
        node = self._nodes[node_id]
        pdo_map = (node.rpdo if pdo.receive else node.tpdo)[pdo.number]
        try:
            with self._locks[node_id]:
                pdo_map.read()
                if layout(pdo_map) != wanted_layout(pdo):
                    configure(pdo_map, pdo)
        except SdoCommunicationError as exc:
            raise FieldbusTimeout(
                f"{self._name(node_id)}: no answer while mapping its PDOs ({exc})"
            ) from exc
        except SdoAbortedError as exc:
            raise FieldbusError(
                f"{self._name(node_id)}: its PDO mapping was refused: {exc}"
            ) from exc
        if not pdo.receive and self._sampler is not None:
            self._sampler.listen(node_id, pdo.number, pdo_map)
            if pdo.trans_type == SYNC_ON_CHANGE:  # no PDO until it changes: read it now
                values = {(i, s): self._get(node_id, i) for i, s in pdo.entries}
                self._sampler.seed((node_id, pdo.number), values)

    def _enable(self, node_id: int, reset: bool) -> None:
        """Walk a drive to "operation enabled"; a faulted drive is left alone unless ``reset``."""
        for _ in range(8):
            statusword = self._get(node_id, STATUSWORD)
            state = Cia402.of(statusword)
            if state is Cia402.OPERATION_ENABLED or (state is Cia402.FAULT and not reset):
                self._statusword[node_id] = statusword
                return
            if state is Cia402.FAULT:
                self._set(node_id, CONTROLWORD, CW_DISABLE_VOLTAGE)  # bit 7 acts on its rise
            self._set(node_id, CONTROLWORD, WALK[state])
        axis = self.axes[self.drive_ids.index(node_id)]
        raise DriveFault(axis, FAULT_DRIVE, f"stays at statusword 0x{statusword:04X}, not enabled")

    def _claim_io(self, ident: int, pid: int) -> tuple[int, int] | None:
        """The claim on the I/O node: its pid, then its id (refused by SDO abort)."""
        self._set(self.io_node, OWNER_PID, pid)
        try:
            self._set(self.io_node, OWNER, ident)
        except FieldbusError as exc:
            if not isinstance(exc.__cause__, SdoAbortedError):
                raise
            return self._get(self.io_node, OWNER), self._get(self.io_node, OWNER_PID)
        return None

    def _home_drive(self, node_id: int) -> None:
        self._enable(node_id, reset=False)
        self._set(node_id, CONTROLWORD, CW_ENABLE)  # bit 4 low (a set-point's RPDO left it high)
        self._set(node_id, MODE, MODE_HOMING)
        self._set(node_id, CONTROLWORD, CW_ENABLE | CW_NEW_SETPOINT)  # bit 4 starts homing
        self._set(node_id, CONTROLWORD, CW_ENABLE)
        self._set(node_id, MODE, MODE_PROFILE_POSITION)

    # ----- decoding a SYNC's sample -----
    def _axis_state(self, values: dict[Entry, int]) -> AxisState:
        statusword = values[(STATUSWORD, 0)]
        fault = values[(FAULT_CODE, 0)]
        if not fault and Cia402.of(statusword) is Cia402.FAULT:
            fault = FAULT_DRIVE  # faulted for a reason of the drive's own
        return AxisState(
            position=values[(POSITION, 0)],
            busy=not statusword & SW_TARGET_REACHED,
            done_seq=values[(DONE_SEQ, 0)],
            fault=fault,
            last_stroke=values[(LAST_STROKE, 0)],
            strokes=values[(STROKES, 0)],
        )

    def _occupancy(self, io: dict[Entry, int]) -> np.ndarray[Any, np.dtype[np.bool_]]:
        rows, cols = self.machine.rows, self.machine.cols
        words = [io[k] for k in sorted(k for k in io if k[0] == OCCUPANCY_WORDS)]
        data = b"".join(w.to_bytes(4, "little") for w in words)
        bits = np.unpackbits(np.frombuffer(data, dtype=np.uint8), bitorder="little")
        return bits[: rows * cols].astype(np.bool_).reshape(rows, cols)

    def _name(self, node_id: int) -> str:
        if node_id == self.io_node:
            return f"I/O node (node {node_id})"
        return f"axis {self.axes[self.drive_ids.index(node_id)].name} (node {node_id})"
