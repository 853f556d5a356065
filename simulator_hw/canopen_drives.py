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
import contextlib
import threading
import time
from collections.abc import Callable
from functools import partial
from typing import Any, TypeVar

from canopen import LocalNode, Network, ObjectDictionary, SdoAbortedError
from canopen.network import PeriodicMessageTask
from canopen.objectdictionary import ODVariable
from canopen.pdo import PdoMap

from bwsd.fieldbus.canopen_pdo import (
    CONTROLWORD,
    DONE_SEQ,
    ESTOP,
    FAULT_CODE,
    LAST_STROKE,
    OCCUPANCY_WORDS,
    POSITION,
    RPDO_COM,
    SETPOINT_SEQ,
    STATUSWORD,
    STROKES,
    SYNC_EVERY,
    SYNC_ON_CHANGE,
    TARGET,
    TPDO_COM,
    TPDO_MAP,
    Entry,
)
from bwsd.fieldbus.cia402 import (
    CW_FAULT_RESET,
    CW_NEW_SETPOINT,
    CW_RELATIVE,
    ERROR_CODE,
    ERROR_CODES,
    MODE,
    MODE_DISPLAY,
    MODE_HOMING,
    MODE_PROFILE_POSITION,
    OCCUPANCY,
    OWNER,
    OWNER_PID,
    SW_SETPOINT_ACK,
    SW_TARGET_REACHED,
    Cia402,
    drive_dictionary,
    io_dictionary,
    occupancy_bytes,
    occupancy_word_values,
)
from simulator_hw.loom import AxisSim, Faults, Loom

T = TypeVar("T")
LOOM_CALL_TIMEOUT = 2.0  # s an access may wait for the loom's event loop
ABORT_DEVICE_STATE = 0x08000022  # SDO abort: not possible in the present device state
NMT_BOOT, NMT_PRE_OPERATIONAL = 0x81, 0x80  # reset node (sends boot-up), enter pre-operational
SYNC = 0x80  # COB-ID of the SYNC message
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
        node.rpdo[1].add_callback(self.on_rpdo)

    def on_read(self, index: int, subindex: int, od: ODVariable) -> int | None:
        live = (
            STATUSWORD,
            MODE_DISPLAY,
            POSITION,
            ERROR_CODE,
            LAST_STROKE,
            DONE_SEQ,
            FAULT_CODE,
            STROKES,
        )
        return self.owner.call(self._live, index) if index in live else None

    def on_rpdo(self, pdo_map: PdoMap) -> None:
        """A receive PDO: its objects as if written one by one, the controlword last."""
        values = {var.index: int(var.raw) for var in pdo_map.map if var.length}
        self.target = values.get(TARGET, self.target)
        self.seq = values.get(SETPOINT_SEQ, self.seq)
        word = values.get(CONTROLWORD)
        if word is None:
            return
        if self._drops_setpoint_bit(word):
            self.controlword, self.ack = word, False  # nothing else changes: no loom access
            return
        with contextlib.suppress(SdoAbortedError):  # refused: no acknowledgement comes
            self.owner.call(self._controlword, word)

    def _drops_setpoint_bit(self, word: int) -> bool:
        """``word`` only lowers bit 4 (and 6) of the controlword in "operation enabled"."""
        bits = CW_NEW_SETPOINT | CW_RELATIVE
        return (
            self.state is S.OPERATION_ENABLED
            and not word & CW_NEW_SETPOINT
            and word | bits == self.controlword | bits
        )

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
        now = time.monotonic()
        self.owner.loom.tick(now)
        return self.values(now)[(index, 0)]

    def values(self, now: float) -> dict[Entry, int]:
        """Every live object of the drive at time ``now`` (the caller advanced the loom to it:
        a SYNC's sample advances it once for all the drives)."""
        sim = self._follow()
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
        return {(index, 0): value for index, value in values.items()}

    def _sync(self) -> AxisSim:
        """Advance the loom to now, and follow it."""
        self.owner.loom.tick(time.monotonic())
        return self._follow()

    def _follow(self) -> AxisSim:
        """The drive's axis as the loom has it: the drive is in FAULT exactly while its axis
        is faulted."""
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
        self._sent: dict[tuple[int, int], bytes] = {}  # (node, COB-ID): the last PDO sent
        self._beater: threading.Thread | None = None

    def start(self) -> None:
        """Connect the nodes, send their boot-up messages and start their heartbeats."""
        ids = [self.node_base + sim.axis.index for sim in self.loom.axes]
        nodes = [
            self._node(node_id, drive_dictionary(node_id, self.heartbeat_ms)) for node_id in ids
        ]
        self.drives = [_Drive(self, i, node) for i, node in enumerate(nodes)]
        cells = self.loom.machine.rows * self.loom.machine.cols
        io = self._node(self.io_node, io_dictionary(cells, self.heartbeat_ms))
        io.add_read_callback(self._io_read)  # type: ignore[no-untyped-call]
        io.add_write_callback(self._io_write)  # type: ignore[no-untyped-call]
        self._io = io
        self.network.subscribe(SYNC, self._on_sync)
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

    def _node(self, node_id: int, od: ObjectDictionary) -> LocalNode:
        node = LocalNode(node_id, od)
        self.network.add_node(node)
        node.add_write_callback(partial(self._follow_mapping, node))  # type: ignore[no-untyped-call]
        return node

    # ----- PDOs -----
    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """SYNC: every operational node sends its TPDOs of type 1, from one sample of the
        loom (the occupancy and the drives' state of one instant)."""
        nodes = [d.node for d in self.drives] + [self._io]
        live = [node for node in nodes if node.nmt.state == "OPERATIONAL"]
        if not live:
            return
        samples = self.call(self._sample, {node.id or 0 for node in live})
        for node in live:
            maps = sorted(node.tpdo.values(), key=lambda m: m.trans_type != SYNC_ON_CHANGE)
            for pdo_map in maps:  # on-change PDOs first: they belong to this sample
                if not pdo_map.enabled or pdo_map.trans_type not in (SYNC_EVERY, SYNC_ON_CHANGE):
                    continue
                for var in pdo_map.map:
                    if var.length:
                        var.raw = _value(node, (var.index, var.subindex), samples[node.id or 0])
                key, sent = (node.id or 0, pdo_map.cob_id or 0), bytes(pdo_map.data)
                if pdo_map.trans_type == SYNC_EVERY or self._sent.get(key) != sent:
                    pdo_map.transmit()
                    self._sent[key] = sent

    def _follow_mapping(
        self, node: LocalNode, index: int, subindex: int, od: ODVariable, data: bytes
    ) -> None:
        """A PDO's COB-ID written by a master makes its mapping (written before) take effect;
        an on-change PDO is sent at the next SYNC whatever it holds."""
        if subindex != 1 or not (RPDO_COM <= index < TPDO_COM or TPDO_COM <= index < TPDO_MAP):
            return
        node.data_store.setdefault(index, {})[subindex] = bytes(data)  # read() below must see it
        (node.rpdo if index < TPDO_COM else node.tpdo).read()  # type: ignore[no-untyped-call]
        self._sent = {k: v for k, v in self._sent.items() if k[0] != node.id}

    def _sample(self, ids: set[int]) -> dict[int, dict[Entry, int]]:
        now = time.monotonic()
        self.loom.tick(now)
        samples = {d.node.id or 0: d.values(now) for d in self.drives if d.node.id in ids}
        words = occupancy_word_values(self.loom.sensed())
        io = {(OCCUPANCY_WORDS, sub): word for sub, word in enumerate(words, start=1)}
        samples[self.io_node] = {(ESTOP, 0): int(self.loom.estop), **io}
        return samples

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
            if not value:  # no claimer has id 0: refused before the loom is asked
                raise SdoAbortedError(ABORT_DEVICE_STATE)
            if self.call(self.loom.claim, value, self._pid, time.monotonic()) is not None:
                raise SdoAbortedError(ABORT_DEVICE_STATE)

    def _beat(self) -> None:
        while not self._stopping.wait(self.network.beat(time.monotonic())):
            pass


def _value(node: LocalNode, key: Entry, sample: dict[Entry, int]) -> int:
    """A mapped object's value: live from the sample, else what the node stores."""
    if key in sample:
        return sample[key]
    od = node.object_dictionary[key[0]]
    if not isinstance(od, ODVariable):
        od = od[key[1]]
    return int(od.decode_raw(node.get_data(*key)))


def _running_in(loop: asyncio.AbstractEventLoop) -> bool:
    try:
        return asyncio.get_running_loop() is loop
    except RuntimeError:
        return False
