"""What the API reads of the controller without ever racing its run loop.

The run loop predicts in a worker thread, and a read of the twin rolls a pending prediction
back; so the API keeps its own copy of the skeleton, taken only when nothing else works on
the twin: while the machine rests (a PackML waiting state), and inside the controller's
"instruction done" event (between two instructions). Between those moments it serves the
last copy, which is the state after the last instruction done.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

import numpy as np
import numpy.typing as npt

from bwsd.controller.packml import WAITING
from bwsd.controller.runner import Controller
from bwsd.fieldbus import FieldbusConnectionError, FieldbusError, FieldbusTimeout
from bwsd.twin import SkeletonData, Twin, replay
from bwsd.twin.skeleton import ContactData, YarnData

from .models import BusHealth


class SkeletonView:
    """A read-only copy of the controller's skeleton."""

    def __init__(self, controller: Controller) -> None:
        self._ctl = controller
        self._twin: Twin | None = None
        self._copy: SkeletonData | None = None

    def refresh(self) -> SkeletonData | None:
        """Copy the skeleton now: only where no prediction can be running (see module)."""
        twin = self._ctl.twin
        self._twin, self._copy = twin, (twin.skeleton() if twin is not None else None)
        return self._copy

    async def current(self) -> SkeletonData | None:
        """The skeleton after the last instruction done; None when no program is loaded."""
        twin = self._ctl.twin
        if twin is None:
            return None
        mine = self._copy if self._twin is twin else None
        if mine is not None and mine.instructions == twin.done:
            return mine
        if self._ctl.packml.state in WAITING:
            return self.refresh()
        if mine is not None:
            return mine  # a run is between "committed" and "done": the copy is one behind
        program, done = self._ctl.program, twin.done
        assert program is not None
        aside = await asyncio.to_thread(replay, self._ctl.machine, program, done)
        return aside.skeleton()

    def after_instruction(self) -> dict[str, Any]:
        """Take the new copy (called in the "instruction done" event) and describe the change."""
        old = self._copy if self._twin is self._ctl.twin else None
        new = self.refresh()
        assert new is not None
        return skeleton_delta(old, new)


Ints = npt.NDArray[np.int64]
Floats = npt.NDArray[np.float64]


def _flat(sk: SkeletonData | None) -> tuple[Ints, Floats, Ints]:
    """Every node of every yarn: ids, positions (n, 3), owning yarn, in yarn order."""
    yarns = sk.yarns if sk is not None else ()
    if not yarns:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64)
    ids = np.concatenate([y.node_ids for y in yarns])
    pos = np.concatenate([np.asarray(y.nodes).reshape(-1, 3) for y in yarns])
    owner = np.repeat([y.id for y in yarns], [len(y.node_ids) for y in yarns])
    return ids.astype(np.int64), pos, owner.astype(np.int64)


def _previous(ids: Ints, owner: Ints) -> Ints:
    """The node before each node in its yarn (-1 for a yarn's first node)."""
    prev = np.roll(ids, 1)
    first = np.ones(len(ids), dtype=bool)
    first[1:] = owner[1:] != owner[:-1]
    prev[first] = -1
    return prev


def skeleton_delta(old: SkeletonData | None, new: SkeletonData) -> dict[str, Any]:
    """From ``old`` to ``new``: inserted nodes, moved nodes, new yarns, new contacts."""
    old_ids, old_pos, _ = _flat(old)
    ids, pos, owner = _flat(new)
    known_yarns = len(old.yarns) if old is not None else 0
    fresh = ~np.isin(ids, old_ids)
    inserted = np.flatnonzero(fresh & (owner < known_yarns))
    prev = _previous(ids, owner)
    table = np.full((int(max(old_ids.max(initial=-1), ids.max(initial=-1))) + 1, 3), np.nan)
    table[old_ids] = old_pos
    moved = np.flatnonzero(~fresh & np.any(table[ids] != pos, axis=1))
    contacts = new.contacts[len(old.contacts) if old is not None else 0 :]
    return {
        "since": old.instructions if old is not None else 0,
        "inserted": [_node(ids, pos, owner, i, int(prev[i])) for i in inserted.tolist()],
        "moved": [_node(ids, pos, owner, i, None) for i in moved.tolist()],
        "new_yarns": [yarn_dict(y) for y in new.yarns[known_yarns:]],
        "contacts": [contact_dict(c) for c in contacts],
        "takeup": new.takeup,
        "occupancy": np.asarray(new.occupancy).tolist(),
    }


def _node(ids: Ints, pos: Floats, owner: Ints, i: int, after: int | None) -> dict[str, Any]:
    out: dict[str, Any] = {"yarn": int(owner[i]), "node": int(ids[i])}
    if after is not None:
        out["after"] = after
    out["xyz"] = pos[i].tolist()
    return out


def yarn_dict(yarn: YarnData) -> dict[str, Any]:
    return {
        "id": yarn.id,
        "kind": yarn.kind,
        "cell": list(yarn.cell) if yarn.cell is not None else None,
        "angle": yarn.angle,
        "node_ids": np.asarray(yarn.node_ids).tolist(),
        "nodes": np.asarray(yarn.nodes, dtype=np.float64).tolist(),
    }


def contact_dict(contact: ContactData) -> dict[str, Any]:
    return {
        "yarns": [contact.moving_yarn, contact.hit_yarn],
        "nodes": [contact.moving_node, contact.hit_node],
        "instruction": contact.instruction,
    }


_LOST = frozenset({"FieldbusConnectionError", "FieldbusTimeout"})
_ANSWERED = frozenset({"FieldbusError", "DriveFault", "EStopError"})  # the bus did answer


class HealthTracker:
    """What the API has seen of the bus: its own reads and the instructions done."""

    def __init__(self) -> None:
        self.connected: bool | None = None
        self.last_error: str | None = None
        self.checked: float | None = None

    def ok(self) -> None:
        self.connected, self.checked = True, time.time()

    def failed(self, exc: FieldbusError) -> None:
        lost = isinstance(exc, FieldbusConnectionError | FieldbusTimeout)
        self.connected, self.last_error, self.checked = not lost, str(exc), time.time()

    def fault(self, cause: str, reason: str) -> None:
        """A fault the controller reported, by the name of its error class."""
        if cause in _LOST:
            self.connected, self.last_error, self.checked = False, reason, time.time()
        elif cause in _ANSWERED:
            self.connected, self.last_error, self.checked = True, reason, time.time()

    def out(self) -> BusHealth:
        return BusHealth(connected=self.connected, last_error=self.last_error,
                         checked=self.checked)  # fmt: skip
