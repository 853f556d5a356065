"""The mock loom's CANopen nodes: a CiA 402 drive per axis and the I/O node.

Object map and state machine as in docs/fieldbus-canopen.md, all driven by one ``Loom``.
The nodes are canopen ``LocalNode``s on a python-can bus (usually the in-process side of a
``SocketcandHub``); canopen runs them in its receive thread. Every access to the loom goes
through ``CanopenLoom.call``: when the loom belongs to an event loop (the other servers of
the mock loom run there) the access is handed to that loop, so the loom never sees two
threads at once.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

from canopen import LocalNode, Network, SdoAbortedError
from canopen.network import PeriodicMessageTask
from canopen.objectdictionary import ODVariable

from bwsd.fieldbus.canopen import (
    CONTROLWORD,
    CW_FAULT_RESET,
    CW_NEW_SETPOINT,
    CW_RELATIVE,
    DONE_SEQ,
    DRIVE_OBJECTS,
    ERROR_CODE,
    ERROR_CODES,
    ESTOP,
    FAULT_CODE,
    IO_OBJECTS,
    LAST_STROKE,
    MODE,
    MODE_DISPLAY,
    MODE_HOMING,
    MODE_PROFILE_POSITION,
    OCCUPANCY,
    OWNER,
    OWNER_PID,
    POSITION,
    SETPOINT_SEQ,
    STATUSWORD,
    STROKES,
    SW_SETPOINT_ACK,
    SW_TARGET_REACHED,
    TARGET,
    Cia402,
    dictionary,
    occupancy_bytes,
)
from simulator_hw.loom import AxisSim, Faults, Loom

T = TypeVar("T")
LOOM_CALL_TIMEOUT = 2.0  # s an access may wait for the loom's event loop
ABORT_DEVICE_STATE = 0x08000022  # SDO abort: not possible in the present device state
NMT_BOOT, NMT_PRE_OPERATIONAL = 0x81, 0x80  # reset node (sends boot-up), enter pre-operational
S = Cia402


class _Heartbeat(PeriodicMessageTask):
    """A heartbeat the nodes' network sends through ``send_message``, so that mute stops it."""

    def __init__(self, network: _DriveNetwork, can_id: int, data: bytes, period: float) -> None:
        self.network, self.can_id, self.data = network, can_id, bytes(data)
        self.period = period
        self.due = time.monotonic() + period

    def stop(self) -> None:
        self.network.heartbeats.discard(self)

    def update(self, data: bytes) -> None:
        self.data = bytes(data)


class _DriveNetwork(Network):
    """The nodes' network: silent while ``faults.mute``; heartbeats from one thread."""

    def __init__(self, faults: Faults) -> None:
        super().__init__()
        self.NOTIFIER_CYCLE = 0.05  # how long disconnect() waits for the receive thread
        self.faults = faults
        self.heartbeats: set[_Heartbeat] = set()

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        if not self.faults.mute:
            super().send_message(can_id, data, remote)

    def send_periodic(
        self, can_id: int, data: bytes, period: float, remote: bool = False
    ) -> PeriodicMessageTask:
        task = _Heartbeat(self, can_id, data, period)
        self.heartbeats.add(task)
        return task

    def beat(self, now: float) -> float:
        """Send the heartbeats that are due; the time until the next one."""
        wait = 0.05
        for task in list(self.heartbeats):
            if now >= task.due:
                self.send_message(task.can_id, task.data)
                task.due = max(task.due + task.period, now)
            wait = min(wait, task.due - now)
        return max(wait, 0.001)


class _Drive:
    """The CiA 402 drive of one axis."""

    def __init__(self, owner: CanopenLoom, index: int, node: LocalNode) -> None:
        self.owner, self.index, self.node = owner, index, node
        self.state = S.SWITCH_ON_DISABLED
        self.controlword = 0
        self.mode = self.target = self.seq = 0
        self.ack = False
        node.add_read_callback(self.on_read)  # type: ignore[no-untyped-call]
        node.add_write_callback(self.on_write)  # type: ignore[no-untyped-call]

    def on_read(self, index: int, subindex: int, od: ODVariable) -> int | None:
        live = (STATUSWORD, MODE_DISPLAY, POSITION, ERROR_CODE, LAST_STROKE, DONE_SEQ, FAULT_CODE,
                STROKES)  # fmt: skip
        return self.owner.call(self._live, index) if index in live else None

    def on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        value = int(od.decode_raw(data))
        if index == MODE:
            self.mode = value
        elif index == TARGET:
            self.target = value
        elif index == SETPOINT_SEQ:
            self.seq = value
        elif index == CONTROLWORD:
            self.owner.call(self._controlword, value)

    def _live(self, index: int) -> int:
        sim = self._sync()
        values = {
            STATUSWORD: self.statusword(),
            MODE_DISPLAY: self.mode,
            POSITION: sim.position,
            ERROR_CODE: ERROR_CODES.get(sim.fault, 0),
            LAST_STROKE: sim.last_stroke,
            DONE_SEQ: sim.done_seq,
            FAULT_CODE: sim.fault,
            STROKES: sim.strokes,
        }
        return values[index]

    def _sync(self) -> AxisSim:
        """Advance the loom; the drive is in FAULT exactly while its axis is faulted."""
        self.owner.loom.tick(time.monotonic())
        sim = self.owner.loom.axes[self.index]
        if sim.fault:
            self.state = S.FAULT
        elif self.state is S.FAULT:
            self.state = S.SWITCH_ON_DISABLED
        return sim

    def statusword(self) -> int:
        sim = self.owner.loom.axes[self.index]
        word = int(self.state) | (0 if sim.busy else SW_TARGET_REACHED)
        homed = self.mode == MODE_HOMING and sim.homed
        if homed or (self.mode == MODE_PROFILE_POSITION and self.ack):
            word |= SW_SETPOINT_ACK
        return word

    def _controlword(self, word: int) -> None:
        previous, self.controlword = self.controlword, word
        self._sync()
        if word & ~previous & CW_FAULT_RESET and self.state is S.FAULT:
            self.owner.loom.reset_faults()
            self.state = S.SWITCH_ON_DISABLED
            return
        self.state = self._next_state(word)
        if not word & CW_NEW_SETPOINT:
            self.ack = False
        elif not previous & CW_NEW_SETPOINT and self.state is S.OPERATION_ENABLED:
            self._new_setpoint(word)

    def _next_state(self, word: int) -> Cia402:
        state, loom = self.state, self.owner.loom
        if state is S.FAULT:
            return state
        if not word & 0x02:  # disable voltage
            return S.SWITCH_ON_DISABLED
        if not word & 0x04:  # quick stop
            if state is S.OPERATION_ENABLED:
                loom.quick_stop(time.monotonic())
                self._sync()
                return S.FAULT if self.state is S.FAULT else S.QUICK_STOP_ACTIVE
            return state if state is S.QUICK_STOP_ACTIVE else S.SWITCH_ON_DISABLED
        if word & 0x07 == 0x06:  # shutdown
            keep = state in (S.READY_TO_SWITCH_ON, S.QUICK_STOP_ACTIVE)
            return state if keep else S.READY_TO_SWITCH_ON
        if word & 0x0F == 0x07:  # switch on (or disable operation)
            ok = state in (S.READY_TO_SWITCH_ON, S.OPERATION_ENABLED)
            return S.SWITCHED_ON if ok else state
        if word & 0x0F == 0x0F and state in (S.SWITCHED_ON, S.QUICK_STOP_ACTIVE):
            operational = self.node.nmt.state == "OPERATIONAL"
            return S.OPERATION_ENABLED if operational else state
        return state

    def _new_setpoint(self, word: int) -> None:
        loom, now = self.owner.loom, time.monotonic()
        if self.mode == MODE_HOMING:
            loom.home(now)
            return
        if self.mode != MODE_PROFILE_POSITION:
            return
        sim, target, seq = loom.axes[self.index], self.target, self.seq
        if sim.axis.relative and not word & CW_RELATIVE:
            raise SdoAbortedError(ABORT_DEVICE_STATE)  # a stroke is relative by nature
        if word & CW_RELATIVE and not sim.axis.relative:
            target += sim.position
        loom.command(self.index, target, seq, now)
        self.ack = sim.seq == seq and not sim.fault
        self._sync()


class CanopenLoom:
    """The loom's CANopen nodes on a python-can bus (``interface``, ``channel``).

    ``loop``: the event loop that owns the loom; without it the nodes touch the loom from
    canopen's receive thread, which is only safe when nothing else does. From a coroutine of
    that loop, run ``stop`` in a thread (``asyncio.to_thread``): it waits for the nodes.
    """

    def __init__(
        self,
        loom: Loom,
        channel: str,
        interface: str = "virtual",
        node_base: int = 1,
        io_node: int = 127,
        heartbeat_ms: int = 100,
        loop: asyncio.AbstractEventLoop | None = None,
    ) -> None:
        self.loom = loom
        self.channel, self.interface = channel, interface
        self.node_base, self.io_node, self.heartbeat_ms = node_base, io_node, heartbeat_ms
        self.loop = loop
        self.network = _DriveNetwork(loom.faults)
        self.drives: list[_Drive] = []
        self._stopping = threading.Event()
        self._pid = 0  # the pid of the claim being made
        self._beater: threading.Thread | None = None

    def start(self) -> None:
        """Connect the nodes, send their boot-up messages and start their heartbeats."""
        ids = [self.node_base + sim.axis.index for sim in self.loom.axes]
        nodes = [self._node(node_id, DRIVE_OBJECTS) for node_id in ids]
        self.drives = [_Drive(self, i, node) for i, node in enumerate(nodes)]
        io = self._node(self.io_node, IO_OBJECTS)
        io.add_read_callback(self._io_read)  # type: ignore[no-untyped-call]
        io.add_write_callback(self._io_write)  # type: ignore[no-untyped-call]
        self.network.connect(interface=self.interface, channel=self.channel)
        for node in [*nodes, io]:
            node.nmt.send_command(NMT_BOOT)
            node.nmt.send_command(NMT_PRE_OPERATIONAL)
        self._stopping.clear()
        self._beater = threading.Thread(target=self._beat, name="canopen heartbeats", daemon=True)
        self._beater.start()

    def stop(self) -> None:
        self._stopping.set()
        if self._beater is not None:
            self._beater.join()
            self._beater = None
        if self.network.bus is not None:
            self.network.disconnect()

    def call(self, fn: Callable[..., T], *args: Any) -> T:
        """``fn(*args)`` where the loom lives: on its event loop, if it has one."""
        loop = self.loop
        if loop is None or _running_in(loop):
            return fn(*args)
        result: concurrent.futures.Future[T] = concurrent.futures.Future()

        def run() -> None:
            try:
                result.set_result(fn(*args))
            except BaseException as exc:
                result.set_exception(exc)

        loop.call_soon_threadsafe(run)
        return result.result(timeout=LOOM_CALL_TIMEOUT)

    def _node(self, node_id: int, objects: dict[int, tuple[str, int, str]]) -> LocalNode:
        node = LocalNode(node_id, dictionary(objects, self.heartbeat_ms))
        self.network.add_node(node)
        return node

    def _io_read(self, index: int, subindex: int, od: ODVariable) -> bytes | int | None:
        if index == OCCUPANCY:
            return self.call(lambda: occupancy_bytes(self.loom.sensed()))
        if index == ESTOP:
            return self.call(lambda: int(self.loom.estop))
        if index in (OWNER, OWNER_PID):
            owner = self.call(lambda: self.loom.owner)
            return owner.ident if index == OWNER else owner.pid
        return None

    def _io_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        """The claim: 0x2011 takes the claimer's pid, 0x2010 its id (refused: SDO abort)."""
        value = int(od.decode_raw(data))
        if index == OWNER_PID:
            self._pid = value
        elif index == OWNER:
            held = self.call(self.loom.claim, value, self._pid, time.monotonic())
            if held is not None or not value:
                raise SdoAbortedError(ABORT_DEVICE_STATE)

    def _beat(self) -> None:
        while not self._stopping.wait(self.network.beat(time.monotonic())):
            pass


def _running_in(loop: asyncio.AbstractEventLoop) -> bool:
    try:
        return asyncio.get_running_loop() is loop
    except RuntimeError:
        return False
