"""What the API reads of the controller without ever racing its run loop.

The run loop predicts in a worker thread, holding the twin's lock while the kernel runs, and
a whole copy of the skeleton costs the size of the preform; so the API keeps its own copy. It
takes a whole copy only when nothing else works on the twin (while the machine rests in a
PackML waiting state, or when it has no copy yet), and otherwise keeps its copy in step by
applying each instruction's delta, built from the instruction's prediction inside the
controller's "instruction done" event. A delta costs what the instruction changed, never the
size of the preform.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import asdict
from typing import Any

import numpy as np

from bwsd.controller.packml import WAITING
from bwsd.controller.runner import Controller
from bwsd.export.skeleton_json import contact_to_dict, yarn_to_dict
from bwsd.fieldbus import FieldbusConnectionError, FieldbusError, FieldbusTimeout
from bwsd.twin import Prediction, SkeletonData, Twin, replay
from bwsd.twin.instructions import Instruction
from bwsd.twin.skeleton import ContactData, YarnData, index_from_end

from .models import BusHealth


class LiveSkeleton:
    """A skeleton kept in step by applying instruction deltas, as a client of the events does."""

    def __init__(self, sk: SkeletonData) -> None:
        self.machine, self.diameter = sk.machine, sk.diameter
        self.takeup, self.instructions = sk.takeup, sk.instructions
        self.occupancy = np.array(sk.occupancy, dtype=np.int64)
        self.contacts = list(sk.contacts)
        self._meta = [(y.id, y.kind, y.cell, y.angle) for y in sk.yarns]
        self._ids = [y.node_ids.tolist() for y in sk.yarns]
        self._pos = [[tuple(p) for p in y.nodes.tolist()] for y in sk.yarns]
        self._data: SkeletonData | None = sk

    def apply(self, delta: dict[str, Any]) -> None:
        """One instruction's delta (see ``prediction_delta``): it must follow this copy."""
        if delta["since"] != self.instructions:
            raise ValueError(f"a delta since {delta['since']} on a copy at {self.instructions}")
        for node in delta["inserted"]:
            ids = self._ids[node["yarn"]]
            at = 0 if node["after"] == -1 else index_from_end(ids, node["after"]) + 1
            ids.insert(at, node["node"])
            self._pos[node["yarn"]].insert(at, tuple(node["xyz"]))
        for node in delta["moved"]:
            ids = self._ids[node["yarn"]]
            self._pos[node["yarn"]][index_from_end(ids, node["node"])] = tuple(node["xyz"])
        for yarn in delta["new_yarns"]:
            cell = tuple(yarn["cell"]) if yarn["cell"] is not None else None
            self._meta.append((yarn["id"], yarn["kind"], cell, yarn["angle"]))
            self._ids.append(list(yarn["node_ids"]))
            self._pos.append([tuple(p) for p in yarn["nodes"]])
        n = self.instructions + 1
        self.contacts.extend(ContactData(n, c["yarns"][0], c["nodes"][0], c["yarns"][1],
                                         c["nodes"][1]) for c in delta["contacts"])  # fmt: skip
        self.takeup, self.instructions = delta["takeup"], n
        self.occupancy = np.array(delta["occupancy"], dtype=np.int64)
        self._data = None

    def data(self) -> SkeletonData:
        """The copy as skeleton data (built once per instruction, when asked for)."""
        if self._data is None:
            rows = zip(self._meta, self._ids, self._pos, strict=True)
            yarns = tuple(
                YarnData(i, kind, np.array(ids, dtype=np.int64),
                         np.array(pos, dtype=np.float64).reshape(-1, 3), cell, angle)
                for (i, kind, cell, angle), ids, pos in rows
            )  # fmt: skip
            self._data = SkeletonData(self.machine, self.diameter, self.takeup,
                                      self.instructions, yarns, tuple(self.contacts),
                                      self.occupancy.copy())  # fmt: skip
        return self._data


class SkeletonView:
    """A read-only copy of the controller's skeleton."""

    def __init__(self, controller: Controller) -> None:
        self._ctl = controller
        self._twin: Twin | None = None
        self._live: LiveSkeleton | None = None

    def refresh(self) -> SkeletonData | None:
        """Copy the skeleton now: only where no prediction can be running (see module)."""
        twin = self._ctl.twin
        self._twin = twin
        self._live = LiveSkeleton(twin.skeleton()) if twin is not None else None
        return self._live.data() if self._live is not None else None

    async def current(self) -> SkeletonData | None:
        """The skeleton after the last instruction done; None when no program is loaded."""
        twin = self._ctl.twin
        if twin is None:
            return None
        live = self._live if self._twin is twin else None
        if live is not None and live.instructions == twin.done:
            return live.data()
        if self._ctl.packml.state in WAITING:
            return self.refresh()
        if live is not None:
            return live.data()  # a run is between "committed" and "done": the copy is one behind
        program, done = self._ctl.program, twin.done
        assert program is not None
        aside = await asyncio.to_thread(replay, self._ctl.machine, program, done)
        return aside.skeleton()

    def after_instruction(self) -> dict[str, Any]:
        """The change the instruction just done made (called in its "instruction done" event).

        The copy follows by the same delta, or is taken whole when it is not one behind.
        """
        twin, pred = self._ctl.twin, self._ctl.last
        assert twin is not None and pred is not None and pred.index == twin.done
        delta = prediction_delta(twin, pred)
        live = self._live if self._twin is twin else None
        if live is not None and live.instructions == delta["since"]:
            live.apply(delta)
        else:
            self.refresh()
        return delta


def prediction_delta(twin: Twin, pred: Prediction) -> dict[str, Any]:
    """The skeleton's change by ``pred``, just committed to ``twin`` (nothing predicted since).

    ``inserted`` nodes come in yarn order, so each one's ``after`` is in place before it.
    """
    first_new = min(pred.new_yarns, default=twin.yarn_count)
    return {
        "since": pred.index - 1,
        "inserted": [
            {"yarn": n.yarn, "node": n.node, "after": n.after, "xyz": _xyz(n.xyz)}
            for n in pred.inserted
            if n.yarn < first_new
        ],
        "moved": [
            {"yarn": w, "node": twin.free_node(w), "xyz": _xyz(xyz)}
            for w, xyz in sorted(pred.free_nodes.items())
            if w < first_new
        ],
        "new_yarns": [yarn_to_dict(twin.yarn(i)) for i in pred.new_yarns],
        "contacts": [contact_to_dict(c) for c in pred.contacts],
        "takeup": float(pred.takeup),
        "occupancy": pred.occupancy.tolist(),
    }


def instruction_dict(instruction: Instruction) -> dict[str, Any]:
    """``{"kind": "shift" | "takeup" | "weft", ...its fields}``."""
    return {"kind": type(instruction).__name__.lower(), **asdict(instruction)}


def next_step(controller: Controller) -> dict[str, Any] | None:
    """The instruction the loaded program runs next, with its line; None when none is left."""
    program, done = controller.program, controller.index
    if program is None or done >= len(program.instructions):
        return None
    line = program.lines[done] if done < len(program.lines) else 0
    return {"index": done + 1, "line": line,
            "instruction": instruction_dict(program.instructions[done])}  # fmt: skip


def _xyz(xyz: Any) -> list[float]:
    return [float(v) for v in xyz]


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
