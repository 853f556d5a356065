"""What the API reads of the controller without ever racing its run loop.

A whole copy of the skeleton costs the size of the preform, so the API keeps its own copy.
It takes a whole copy in a worker thread (the twin's readers hold its lock, so the copy is
consistent even while the run loop predicts), and otherwise keeps it in step by applying
each instruction's delta, built from the instruction's prediction inside the controller's
"instruction done" event. A delta costs what the instruction changed, never the size of the
preform, and is the only skeleton work done on the event loop.
"""

from __future__ import annotations

import asyncio
from dataclasses import asdict
from typing import Any

import numpy as np

from bwsd.controller.runner import Controller
from bwsd.export.skeleton_json import contact_to_dict, yarn_to_dict
from bwsd.twin import Prediction, SkeletonData, Twin
from bwsd.twin.instructions import Instruction
from bwsd.twin.skeleton import ContactData, YarnData, index_from_end


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
    """A read-only copy of the controller's skeleton, kept in step by the instruction events.

    A whole copy is taken in a worker thread (the twin's readers take its lock, so a copy is
    consistent even while the run loop predicts); the event loop only applies deltas.
    """

    def __init__(self, controller: Controller) -> None:
        self._ctl = controller
        self._twin: Twin | None = None
        self._live: LiveSkeleton | None = None

    async def current(self) -> SkeletonData | None:
        """The skeleton after the last instruction done; None when no program is loaded."""
        twin = self._ctl.twin
        if twin is None:
            return None
        live = self._live if self._twin is twin else None
        if live is not None and live.instructions >= twin.done - 1:
            return live.data()  # one behind only between "committed" and its event
        sk = await asyncio.to_thread(twin.skeleton)
        live = self._live if self._twin is twin else None
        if live is None or live.instructions < sk.instructions:
            self._twin, self._live = twin, LiveSkeleton(sk)
            return self._live.data()
        return live.data()

    def after_instruction(self) -> dict[str, Any]:
        """The change the instruction just done made (called in its "instruction done" event).

        The copy follows by the same delta; a copy not one behind is dropped (the next read
        takes a whole one in a worker thread).
        """
        twin, pred = self._ctl.twin, self._ctl.last
        assert twin is not None and pred is not None and pred.index == twin.done
        delta = prediction_delta(twin, pred)
        live = self._live if self._twin is twin else None
        if live is not None and live.instructions == delta["since"]:
            live.apply(delta)
        elif live is None or live.instructions < twin.done:
            self._live = None
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


def wire_step(step: dict[str, Any] | None) -> dict[str, Any] | None:
    """``Controller.next_step()`` as JSON: the instruction as a dict."""
    if step is None:
        return None
    return {**step, "instruction": instruction_dict(step["instruction"])}


def _xyz(xyz: Any) -> list[float]:
    return [float(v) for v in xyz]
