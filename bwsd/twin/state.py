"""Mutable state of the twin with an undo log: nodes, yarns, fixed segments and their grid.

Every change goes through one of the methods here and is logged, so a prediction can be run
in place and rolled back (``undo_to``) or kept (``forget_log``) in O(changes).
"""

from __future__ import annotations

import math
from array import array
from typing import Any

import numpy as np

from bwsd.twin.machine import Machine
from bwsd.twin.predicates import FloatArray

Cell = tuple[int, int, int]


class GrowArray:
    """A numpy array that grows by doubling along its first axis."""

    def __init__(self, dtype: Any, width: int = 0, capacity: int = 256) -> None:
        shape = (capacity, width) if width else (capacity,)
        self.data: np.ndarray[Any, Any] = np.zeros(shape, dtype=dtype)
        self.size = 0

    def append(self, value: Any) -> int:
        if self.size == len(self.data):
            grown = np.zeros((2 * len(self.data),) + self.data.shape[1:], dtype=self.data.dtype)
            grown[: self.size] = self.data[: self.size]
            self.data = grown
        self.data[self.size] = value
        self.size += 1
        return self.size - 1

    def view(self) -> np.ndarray[Any, Any]:
        return self.data[: self.size]


class State:
    """Nodes, yarns, fixed segments (in a uniform grid), occupancy, take-up, contacts."""

    def __init__(self, machine: Machine, diameter: float) -> None:
        self.machine = machine
        self.diameter = diameter
        self.pos = GrowArray(np.float64, 3)
        self.yarns: list[array[int]] = []  # node ids in order; a warp's last one is free
        self.yarn_angle: list[float | None] = []  # None for a warp, degrees for a weft
        self.yarn_cell: list[tuple[int, int] | None] = []  # fill cell of a warp
        self.yarn_len = GrowArray(np.float64)
        self.n_warps = 0
        self.last_fixed = GrowArray(np.int64)  # per warp: node id of B
        self.free_node = GrowArray(np.int64)  # per warp: node id of the free node
        self.warp_cell: list[tuple[int, int]] = []
        self.occupancy = np.full((machine.rows, machine.cols), -1, dtype=np.int64)
        self.takeup = 0.0
        self.contacts = GrowArray(np.int64, 5)  # instruction, moving, its node, hit, its node
        self.seg_c = GrowArray(np.int64)
        self.seg_d = GrowArray(np.int64)
        self.seg_yarn = GrowArray(np.int64)
        self.seg_alive = GrowArray(np.bool_)
        self.grid: dict[Cell, array[int]] = {}
        self.cell_size = (machine.pitch_x, machine.pitch_y, max(machine.d_mat / 8.0, 1e-3))
        self.log: list[tuple[Any, ...]] = []

    # ----- building (never undone: only used before the first instruction) -----
    def add_warp(self, row: int, col: int) -> int:
        """Fill a case into (row, col): a fixed node at the fell and a free node at the guide."""
        m = self.machine
        fx, fy = m.fell_xy(row, col)
        gx, gy = m.guide_xy(row, col)
        yarn = len(self.yarns)
        fell = self.pos.append((fx, fy, self.takeup))
        guide = self.pos.append((gx, gy, m.d_mat + self.takeup))
        self.yarns.append(array("q", [fell, guide]))
        self.yarn_angle.append(None)
        self.yarn_cell.append((row, col))
        self.yarn_len.append(self._dist(fell, guide))
        self.last_fixed.append(fell)
        self.free_node.append(guide)
        self.warp_cell.append((row, col))
        self.occupancy[row, col] = yarn
        self.n_warps += 1
        return yarn

    # ----- logged mutations -----
    def new_node(self, xyz: FloatArray) -> int:
        self.log.append(("node",))
        return self.pos.append(xyz)

    def insert_node(self, yarn: int, index: int, node: int) -> None:
        self.yarns[yarn].insert(index, node)
        self.log.append(("ins", yarn, index))

    def move_node(self, node: int, xyz: FloatArray) -> None:
        self.log.append(("pos", node, self.pos.data[node].copy()))
        self.pos.data[node] = xyz

    def set_last_fixed(self, warp: int, node: int) -> None:
        self.log.append(("last", warp, int(self.last_fixed.data[warp])))
        self.last_fixed.data[warp] = node

    def add_length(self, yarn: int, delta: float) -> None:
        self.log.append(("len", yarn, float(self.yarn_len.data[yarn])))
        self.yarn_len.data[yarn] += delta

    def place(self, warp: int, cell: tuple[int, int]) -> None:
        """Move warp's case to cell in the occupancy grid."""
        old = self.warp_cell[warp]
        self.log.append(("place", warp, old))
        if self.occupancy[old] == warp:
            self.occupancy[old] = -1
        self.occupancy[cell] = warp
        self.warp_cell[warp] = cell

    def set_takeup(self, value: float) -> None:
        self.log.append(("takeup", self.takeup))
        self.takeup = value

    def add_contact(self, record: tuple[int, int, int, int, int]) -> None:
        self.log.append(("contact",))
        self.contacts.append(record)

    def add_weft(self, start: int, end: int, angle: float) -> int:
        yarn = len(self.yarns)
        self.yarns.append(array("q", [start, end]))
        self.yarn_angle.append(angle)
        self.yarn_cell.append(None)
        self.yarn_len.append(self._dist(start, end))
        self.log.append(("weft",))
        self.add_segment(yarn, start, end)
        return yarn

    def add_segment(self, yarn: int, c: int, d: int) -> int:
        """Register the fixed segment c-d of yarn in the grid."""
        seg = self.seg_c.append(c)
        self.seg_d.append(d)
        self.seg_yarn.append(yarn)
        self.seg_alive.append(True)
        cells = self.cells_of_box(*self._box(c, d))
        for cell in cells:
            bucket = self.grid.get(cell)
            if bucket is None:
                bucket = self.grid[cell] = array("q")
            bucket.append(seg)
        self.log.append(("seg", cells))
        return seg

    def kill_segment(self, seg: int) -> None:
        self.seg_alive.data[seg] = False
        self.log.append(("kill", seg))

    # ----- undo -----
    def undo_to(self, mark: int) -> None:
        """Roll every logged change after ``mark`` back, newest first."""
        log = self.log
        while len(log) > mark:
            self._undo(log.pop())

    def forget_log(self) -> None:
        self.log.clear()

    def _undo(self, op: tuple[Any, ...]) -> None:
        kind = op[0]
        if kind == "node":
            self.pos.size -= 1
        elif kind == "ins":
            del self.yarns[op[1]][op[2]]
        elif kind == "pos":
            self.pos.data[op[1]] = op[2]
        elif kind == "last":
            self.last_fixed.data[op[1]] = op[2]
        elif kind == "len":
            self.yarn_len.data[op[1]] = op[2]
        elif kind == "place":
            self._unplace(op[1], op[2])
        elif kind == "takeup":
            self.takeup = op[1]
        elif kind == "contact":
            self.contacts.size -= 1
        elif kind == "weft":
            self.yarns.pop()
            self.yarn_angle.pop()
            self.yarn_cell.pop()
            self.yarn_len.size -= 1
        elif kind == "seg":
            self._unsegment(op[1])
        elif kind == "kill":
            self.seg_alive.data[op[1]] = True

    def _unplace(self, warp: int, old: tuple[int, int]) -> None:
        cur = self.warp_cell[warp]
        if self.occupancy[cur] == warp:
            self.occupancy[cur] = -1
        self.occupancy[old] = warp
        self.warp_cell[warp] = old

    def _unsegment(self, cells: list[Cell]) -> None:
        for cell in cells:
            self.grid[cell].pop()
        for arr in (self.seg_c, self.seg_d, self.seg_yarn, self.seg_alive):
            arr.size -= 1

    # ----- geometry helpers -----
    def _dist(self, a: int, b: int) -> float:
        p = self.pos.data
        return math.dist(p[a], p[b])

    def _box(self, c: int, d: int) -> tuple[FloatArray, FloatArray]:
        p, q = self.pos.data[c], self.pos.data[d]
        return np.minimum(p, q), np.maximum(p, q)

    def cells_of_box(self, lo: FloatArray, hi: FloatArray) -> list[Cell]:
        """Grid cells overlapping the closed box [lo, hi]."""
        hx, hy, hz = self.cell_size
        x0, x1 = math.floor(lo[0] / hx), math.floor(hi[0] / hx)
        y0, y1 = math.floor(lo[1] / hy), math.floor(hi[1] / hy)
        z0, z1 = math.floor(lo[2] / hz), math.floor(hi[2] / hz)
        return [
            (i, j, k)
            for i in range(x0, x1 + 1)
            for j in range(y0, y1 + 1)
            for k in range(z0, z1 + 1)
        ]

    def segments_near(self, lo: FloatArray, hi: FloatArray) -> np.ndarray[Any, Any]:
        """Ids of live fixed segments registered in cells overlapping [lo, hi] (deduplicated)."""
        grid = self.grid
        parts = [grid[c] for c in self.cells_of_box(lo, hi) if c in grid]
        if not parts:
            return np.empty(0, dtype=np.int64)
        ids = np.unique(np.concatenate([np.frombuffer(p, dtype=np.int64) for p in parts]))
        return ids[self.seg_alive.data[ids]]
