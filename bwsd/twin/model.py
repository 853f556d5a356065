"""The twin: predict, commit, snapshot, restore and replay over the sweep kernel."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from bwsd.errors import TwinError
from bwsd.twin.instructions import Instruction, Program
from bwsd.twin.machine import Machine
from bwsd.twin.moves import execute, path_length
from bwsd.twin.skeleton import ContactData, IntArray, SkeletonData, YarnData, YarnKind
from bwsd.twin.state import State
from bwsd.twin.sweep import index_from_end


@dataclass(frozen=True)
class NodeInsert:
    """A node added by an instruction: into ``yarn`` right after node ``after``."""

    yarn: int
    node: int
    after: int
    xyz: tuple[float, float, float]


@dataclass(frozen=True)
class Prediction:
    """The would-be result of one instruction, computed without touching the committed twin."""

    index: int  # 1-based instruction number
    instruction: Instruction
    contacts: tuple[ContactData, ...]
    inserted: tuple[NodeInsert, ...]  # in yarn order: each one's predecessor comes first
    free_nodes: dict[int, tuple[float, float, float]]  # yarn -> new free node position
    cases: dict[int, tuple[int, int]]  # yarn -> cell after the instruction
    occupancy: IntArray
    takeup: float
    new_yarns: tuple[int, ...]
    length_change: dict[int, float]  # moved warp -> change of its path length (mm)
    token: int = field(repr=False, default=0)


@dataclass(frozen=True)
class Snapshot:
    """A point the twin can be restored to (cheap: a mark in the change log)."""

    mark: int
    done: int
    generation: int


class Twin:
    """The geometric model of the machine (docs/twin.md).

    ``predict`` runs an instruction in place with an undo log and leaves it pending; any
    read of the state, or another ``predict``, rolls a pending prediction back first, so
    the committed state is what every caller sees. ``commit`` of the pending prediction
    only drops its log.
    """

    def __init__(
        self, machine: Machine, fill: Iterable[tuple[int, int]], diameter: float | None = None
    ) -> None:
        self.machine = machine
        self.diameter = machine.yarn_diameter if diameter is None else diameter
        self._state = State(machine, self.diameter)
        for row, col in fill:
            if not machine.inside(row, col):
                raise TwinError(f"fill cell ({row}, {col}) is outside the matrix")
            if self._state.occupancy[row][col] >= 0:
                raise TwinError(f"fill cell ({row}, {col}) is filled twice")
            self._state.add_warp(row, col)
        self.done = 0
        self._pending: Prediction | None = None
        self._pending_mark = 0
        self._token = 0
        self._snapshots: list[int] = []
        self._generation = 0

    @classmethod
    def from_program(cls, machine: Machine, program: Program) -> Twin:
        """A twin filled as the program says, before its first instruction."""
        return cls(machine, program.fill, program.diameter)

    # ----- predict / commit -----
    def predict(self, instruction: Instruction) -> Prediction:
        """The result of ``instruction`` from the committed state; raises TwinError if refused."""
        self._settle()
        st = self._state
        mark = len(st.log)
        contacts0, yarns0 = st.contact_count, len(st.yarns)
        index = self.done + 1
        try:
            before = execute(st, instruction, index)
        except BaseException:
            st.undo_to(mark)
            raise
        self._token += 1
        pred = self._describe(index, instruction, before, contacts0, yarns0)
        self._pending, self._pending_mark = pred, mark
        return pred

    def commit(self, prediction: Prediction) -> None:
        """Make ``prediction`` the committed state (it must come from this twin's state)."""
        if self._pending is not prediction:
            self._settle()
            if prediction.index != self.done + 1:
                raise TwinError(
                    "prediction is stale: the twin has moved on", instruction=prediction.index
                )
            again = self.predict(prediction.instruction)
            if again.contacts != prediction.contacts:
                raise TwinError(
                    "prediction does not match the current state", instruction=prediction.index
                )
        self._pending = None
        self.done += 1
        if not self._snapshots:
            self._state.forget_log()

    def apply(self, instruction: Instruction) -> Prediction:
        """Predict and commit in one step."""
        pred = self.predict(instruction)
        self.commit(pred)
        return pred

    def _settle(self) -> None:
        if self._pending is not None:
            self._state.undo_to(self._pending_mark)
            self._pending = None

    # ----- snapshots -----
    def snapshot(self) -> Snapshot:
        """Mark the committed state; the change log is kept until the snapshot is released."""
        self._settle()
        mark = len(self._state.log)
        self._snapshots.append(mark)
        return Snapshot(mark, self.done, self._generation)

    def restore(self, snap: Snapshot) -> None:
        """Return to ``snap`` (and release it and every later snapshot)."""
        self._settle()
        if snap.generation != self._generation or snap.mark not in self._snapshots:
            raise TwinError("snapshot is no longer valid")
        self._state.undo_to(snap.mark)
        self.done = snap.done
        self._snapshots = [m for m in self._snapshots if m < snap.mark]
        self._trim()

    def release(self, snap: Snapshot) -> None:
        """Forget ``snap`` without restoring it."""
        if snap.generation == self._generation and snap.mark in self._snapshots:
            self._snapshots.remove(snap.mark)
        self._trim()

    def _trim(self) -> None:
        if not self._snapshots:
            self._settle()
            self._state.forget_log()
            self._generation += 1

    # ----- reading -----
    @property
    def occupancy(self) -> IntArray:
        """Yarn id of the case in each cell, -1 where empty (a copy)."""
        self._settle()
        return np.array(self._state.occupancy, dtype=np.int64)

    @property
    def takeup(self) -> float:
        self._settle()
        return self._state.takeup

    @property
    def contact_count(self) -> int:
        self._settle()
        return self._state.contact_count

    @property
    def node_count(self) -> int:
        self._settle()
        return self._state.node_count

    @property
    def yarn_count(self) -> int:
        self._settle()
        return len(self._state.yarns)

    def free_node(self, warp: int) -> int:
        """The node id of a warp's free node (the one at its guide)."""
        self._settle()
        return int(self._state.free_node[warp])

    def yarn(self, yarn: int) -> YarnData:
        """A read-only copy of one yarn."""
        self._settle()
        st = self._state
        ids = np.array(st.yarns[yarn], dtype=np.int64)
        pos = np.array([st.xyz(int(n)) for n in ids], dtype=np.float64).reshape(-1, 3)
        kind: YarnKind = "warp" if yarn < st.n_warps else "weft"
        return YarnData(yarn, kind, ids, pos, st.yarn_cell[yarn], st.yarn_angle[yarn])

    def skeleton(self) -> SkeletonData:
        """A read-only copy of the whole skeleton."""
        self._settle()
        st = self._state
        pos = np.array(st.pos, dtype=np.float64).reshape(-1, 3)
        yarns = []
        for i, nodes in enumerate(st.yarns):
            ids = np.array(nodes, dtype=np.int64)
            kind: YarnKind = "warp" if i < st.n_warps else "weft"
            yarns.append(YarnData(i, kind, ids, pos[ids], st.yarn_cell[i], st.yarn_angle[i]))
        table = np.array(st.contacts, dtype=np.int64).reshape(-1, 5).tolist()
        contacts = tuple(ContactData(*row) for row in table)
        return SkeletonData(
            self.machine,
            self.diameter,
            st.takeup,
            self.done,
            tuple(yarns),
            contacts,
            self.occupancy,
        )

    def path_length(self, yarn: int) -> float:
        """Length of a yarn's polyline, free segment included."""
        self._settle()
        st = self._state
        return path_length(st, yarn) if yarn < st.n_warps else st.yarn_len[yarn]

    def _describe(self, index: int, instruction: Instruction, before: dict[int, float],
                  contacts0: int, yarns0: int) -> Prediction:  # fmt: skip
        st = self._state
        rows = np.array(st.contacts[5 * contacts0 :], dtype=np.int64).reshape(-1, 5).tolist()
        contacts = tuple(ContactData(*row) for row in rows)
        owner = {c.moving_node: c.moving_yarn for c in contacts}
        owner.update({c.hit_node: c.hit_yarn for c in contacts})
        placed = []
        for node, yarn in owner.items():
            nodes = st.yarns[yarn]
            at = index_from_end(nodes, node)
            placed.append((yarn, at, NodeInsert(yarn, node, nodes[at - 1], st.xyz(node))))
        # In yarn order, so that each node's predecessor is in place before it is inserted.
        inserted = [ins for _, _, ins in sorted(placed, key=lambda p: (p[0], p[1]))]
        free = {w: st.xyz(st.free_node[w]) for w in before}
        cases = {w: st.warp_cell[w] for w in before}
        change = {w: path_length(st, w) - length for w, length in before.items()}
        return Prediction(
            index,
            instruction,
            contacts,
            tuple(inserted),
            free,
            cases,
            np.array(st.occupancy, dtype=np.int64),
            st.takeup,
            tuple(range(yarns0, len(st.yarns))),
            change,
            self._token,
        )


ProgressFn = Callable[[int, int], None]


def simulate(machine: Machine, program: Program, progress: ProgressFn | None = None) -> Twin:
    """Run every instruction of ``program``; TwinError carries the failing instruction."""
    twin = Twin.from_program(machine, program)
    total = len(program.instructions)
    for i, instruction in enumerate(program.instructions):
        twin.apply(instruction)
        if progress is not None:
            progress(i + 1, total)
    return twin


def replay(machine: Machine, program: Program, count: int | None = None) -> Twin:
    """The twin after the first ``count`` instructions (all when None)."""
    sub = program.instructions if count is None else program.instructions[:count]
    twin = Twin.from_program(machine, program)
    for instruction in sub:
        twin.apply(instruction)
    return twin
