"""The PDOs of the CANopen map (docs/fieldbus-canopen.md): which objects travel in which
PDO, the dictionaries' PDO records, and the master's SYNC sampler.

SYNC-driven: a SYNC makes every node sample at one instant and send its transmit PDOs,
so the occupancy and the drives' done sequences never come from two moments (an
event-driven occupancy could arrive after the drive's "done" and make a finished stroke
look like a mismatch). What changes at every stroke (statusword, position, done sequence,
the occupancy, the e-stop) is of transmission type 1, sent on every SYNC; what changes
once a stroke (fault code, last stroke, stroke count) is of type 0, sent at a SYNC only
when it changed, ahead of the node's type-1 PDO. The receive PDO of a drive (controlword,
target, set-point sequence) is event-driven (type 255): a drive acts on it when it
arrives. bwsd writes the mapping by SDO when it connects (docs/fieldbus-canopen.md,
"PDOs"); the dictionaries here are the only copy of it in code, used by bwsd and by the
mock loom's drives alike.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import can
from canopen import Network, ObjectDictionary
from canopen.objectdictionary import ODArray, ODRecord, ODVariable
from canopen.objectdictionary.datatypes import UNSIGNED8, UNSIGNED32
from canopen.pdo import PdoMap

from bwsd.fieldbus.base import FieldbusTimeout

# objects (the rest of the map is in bwsd.fieldbus.canopen)
CONTROLWORD, STATUSWORD, TARGET, POSITION = 0x6040, 0x6041, 0x607A, 0x6064
LAST_STROKE, DONE_SEQ, SETPOINT_SEQ, FAULT_CODE, ESTOP, STROKES = range(0x2001, 0x2007)
OCCUPANCY_WORDS = 0x2100  # I/O node: the occupancy bits, 32 a sub-index (cell 0: bit 0 of 1)

RPDO_COM, RPDO_MAP, TPDO_COM, TPDO_MAP = 0x1400, 0x1600, 0x1800, 0x1A00
COB_INVALID = 0x80000000  # bit 31 of a COB-ID: the PDO is off
SYNC_EVERY = 1  # transmission type: on every SYNC
SYNC_ON_CHANGE = 0  # transmission type: at a SYNC, when a mapped object changed
ON_ARRIVAL = 255  # transmission type of a receive PDO: acted on when it arrives
BITS = {
    CONTROLWORD: 16,
    STATUSWORD: 16,
    TARGET: 32,
    POSITION: 32,
    DONE_SEQ: 16,
    SETPOINT_SEQ: 16,
    FAULT_CODE: 8,
    LAST_STROKE: 32,
    STROKES: 16,
    ESTOP: 8,
    OCCUPANCY_WORDS: 32,
}

Entry = tuple[int, int]  # object index, sub-index


@dataclass(frozen=True)
class Pdo:
    """One PDO as bwsd maps it: receive or transmit, its number (1-based), COB-ID,
    transmission type and objects in order."""

    receive: bool
    number: int
    cob_id: int
    trans_type: int
    entries: tuple[Entry, ...]

    @property
    def key(self) -> tuple[bool, int]:
        return self.receive, self.number


def occupancy_words(cells: int) -> int:
    """Sub-indexes of the occupancy words of the I/O node (0x2100)."""
    return max(1, -(-cells // 32))


def drive_pdos(node_id: int) -> tuple[Pdo, ...]:
    """RPDO1 in; TPDO1 (fault code, last stroke, stroke count: on change) and TPDO2
    (statusword, position, done sequence: every SYNC) out. TPDO1's lower COB-ID wins the
    bus first, so a change always arrives before the sample it belongs to ends."""
    return (
        Pdo(
            True, 1, 0x200 + node_id, ON_ARRIVAL, ((CONTROLWORD, 0), (TARGET, 0), (SETPOINT_SEQ, 0))
        ),
        Pdo(
            False,
            1,
            0x180 + node_id,
            SYNC_ON_CHANGE,
            ((FAULT_CODE, 0), (LAST_STROKE, 0), (STROKES, 0)),
        ),
        Pdo(False, 2, 0x280 + node_id, SYNC_EVERY, ((STATUSWORD, 0), (POSITION, 0), (DONE_SEQ, 0))),
    )


def io_pdos(cells: int) -> tuple[Pdo, ...]:
    """The I/O node's TPDOs: the e-stop and occupancy word 1, then two words a PDO. Their
    COB-IDs are 0x380 + k for TPDO k (the drives use TPDO1, TPDO2 and RPDO1 only)."""
    words = [(OCCUPANCY_WORDS, sub) for sub in range(1, occupancy_words(cells) + 1)]
    groups = [((ESTOP, 0), words[0])] + [tuple(words[i : i + 2]) for i in range(1, len(words), 2)]
    return tuple(
        Pdo(False, k, 0x380 + k, SYNC_EVERY, tuple(group))
        for k, group in enumerate(groups, start=1)
    )


def add_occupancy_words(od: ObjectDictionary, cells: int) -> None:
    """0x2100 of the I/O node: the occupancy as 32-bit words a PDO can carry."""
    array = ODArray("occupancy words", OCCUPANCY_WORDS)
    array.add_member(
        _variable("number of words", OCCUPANCY_WORDS, 0, UNSIGNED8, "ro", occupancy_words(cells))
    )
    for sub in range(1, occupancy_words(cells) + 1):
        array.add_member(
            _variable(f"occupancy word {sub}", OCCUPANCY_WORDS, sub, UNSIGNED32, "ro", 0)
        )
    od.add_object(array)


def add_pdo_records(od: ObjectDictionary, pdos: Iterable[Pdo]) -> None:
    """The communication and mapping records (0x1400/0x1600, 0x1800/0x1A00 + n - 1) of
    ``pdos``, each off until a master writes its mapping."""
    for pdo in pdos:
        com = (RPDO_COM if pdo.receive else TPDO_COM) + pdo.number - 1
        mapping = (RPDO_MAP if pdo.receive else TPDO_MAP) + pdo.number - 1
        record = ODRecord(f"PDO {pdo.number} communication", com)
        record.add_member(_variable("highest sub-index", com, 0, UNSIGNED8, "ro", 2))
        record.add_member(_variable("COB-ID", com, 1, UNSIGNED32, "rw", pdo.cob_id | COB_INVALID))
        record.add_member(_variable("transmission type", com, 2, UNSIGNED8, "rw", pdo.trans_type))
        od.add_object(record)
        entries = ODRecord(f"PDO {pdo.number} mapping", mapping)
        entries.add_member(_variable("number of entries", mapping, 0, UNSIGNED8, "rw", 0))
        for sub in range(1, 9):
            entries.add_member(_variable(f"entry {sub}", mapping, sub, UNSIGNED32, "rw", 0))
        od.add_object(entries)


def _variable(
    name: str, index: int, sub: int, data_type: int, access: str, default: int
) -> ODVariable:
    var = ODVariable(name, index, sub)
    var.data_type, var.access_type, var.default = data_type, access, default
    return var


def layout(pdo_map: PdoMap) -> tuple[int, int, tuple[tuple[int, int, int], ...]]:
    """What a PDO of a node is set to: COB-ID (with its off bit), transmission type, and
    its entries as (index, sub-index, bits)."""
    cob = (pdo_map.cob_id or 0) | (0 if pdo_map.enabled else COB_INVALID)
    entries = tuple((v.index, v.subindex, v.length) for v in pdo_map.map if v.length)
    return cob, pdo_map.trans_type or 0, entries


def wanted_layout(pdo: Pdo) -> tuple[int, int, tuple[tuple[int, int, int], ...]]:
    return pdo.cob_id, pdo.trans_type, tuple((i, s, BITS[i]) for i, s in pdo.entries)


def configure(pdo_map: PdoMap, pdo: Pdo) -> None:
    """Write ``pdo``'s mapping to the node by SDO (blocking) and listen to it."""
    pdo_map.clear()
    for index, sub in pdo.entries:
        pdo_map.add_variable(index, sub, BITS[index])
    pdo_map.cob_id, pdo_map.trans_type, pdo_map.enabled = pdo.cob_id, pdo.trans_type, True
    pdo_map.save()


Key = tuple[int, int]  # node id, TPDO number


class SyncSampler:
    """The master's side of the transmit PDOs: sends SYNC, keeps each TPDO's last values,
    and tells apart those that answered a given SYNC. The PDOs arrive in canopen's receive
    thread; a sample is awaited on the event loop."""

    def __init__(self, network: Network) -> None:
        self.network = network
        self._lock = threading.Lock()
        self._count = 0
        self._seen: dict[Key, tuple[int, dict[Entry, int]]] = {}
        self._waiters: list[_Waiter] = []
        self._broken: Exception | None = None  # the link's end, once it has ended

    def listen(self, node_id: int, number: int, pdo_map: PdoMap) -> None:
        pdo_map.add_callback(lambda m: self._arrived((node_id, number), m))

    def seed(self, key: Key, values: dict[Entry, int]) -> None:
        """Values of an on-change TPDO read by SDO, until the TPDO itself comes."""
        with self._lock:
            self._seen.setdefault(key, (0, values))

    def _arrived(self, key: Key, pdo_map: PdoMap) -> None:
        values = {(v.index, v.subindex): _int(v.raw) for v in pdo_map.map if v.length}
        with self._lock:
            self._seen[key] = (self._count, values)
            done = [w for w in self._waiters if w.complete(self._seen)]
            for waiter in done:
                self._waiters.remove(waiter)
        for waiter in done:
            waiter.loop.call_soon_threadsafe(_resolve, waiter.future)

    def fail(self, error: Exception) -> None:
        """The link is gone: every sample waiting, and every later one, ends with ``error``
        now, not at its timeout (any thread)."""
        with self._lock:
            self._broken = error
            waiters, self._waiters = self._waiters, []
        for waiter in waiters:
            waiter.loop.call_soon_threadsafe(_reject, waiter.future, error)

    async def sample(
        self, every: Sequence[Key], kept: Sequence[Key], timeout: float
    ) -> dict[Key, dict[Entry, int]]:
        """Send one SYNC; wait for the TPDOs ``every`` it makes the nodes send; with them
        the last values of the on-change TPDOs ``kept``."""
        loop = asyncio.get_running_loop()
        future: asyncio.Future[None] = loop.create_future()
        with self._lock:
            if self._broken is not None:
                raise can.CanOperationError(f"the CAN link is gone: {self._broken}")
            self._count += 1
            waiter = _Waiter(self._count, tuple(every), loop, future)
            self._waiters.append(waiter)
        try:
            self.network.sync.transmit()
            await asyncio.wait_for(future, timeout)
        except TimeoutError:
            with self._lock:
                late = [k for k in every if self._seen.get(k, (0, {}))[0] < waiter.count]
            missing = sorted({node for node, _ in late})
            raise FieldbusTimeout(
                f"no answer to SYNC within {timeout:g} s: no PDO from nodes "
                f"{', '.join(map(str, missing))}"
            ) from None
        finally:
            with self._lock:
                if waiter in self._waiters:
                    self._waiters.remove(waiter)
        with self._lock:
            lacking = [k for k in kept if k not in self._seen]
            if lacking:
                raise FieldbusTimeout(f"no values yet of the PDOs {lacking}")
            return {k: self._seen[k][1] for k in (*every, *kept)}


@dataclass(eq=False)
class _Waiter:
    count: int
    keys: tuple[Key, ...]
    loop: asyncio.AbstractEventLoop
    future: asyncio.Future[None]

    def complete(self, seen: dict[Key, tuple[int, dict[Entry, int]]]) -> bool:
        return all(seen.get(k, (0, {}))[0] >= self.count for k in self.keys)


def _resolve(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


def _reject(future: asyncio.Future[None], error: Exception) -> None:
    if not future.done():
        future.set_exception(can.CanOperationError(f"the CAN link is gone: {error}"))


def _int(value: Any) -> int:
    return int(value) if isinstance(value, int | bool) else 0
