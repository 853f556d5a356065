"""Mutable state of the twin with an undo log: nodes, yarns, segments and their grids.

Storage is flat (``array``) so that a long preform costs a few tens of bytes per node. Every
change goes through a method here and is logged, so a prediction can run in place and be
rolled back (``undo_to``) or kept (``forget_log``) in O(changes).

Two uniform grids select the segments near a sweep: fixed segments (both ends fixed) are
registered once in every 3-D cell their box touches, so a query never looks below the
moving yarn's last fixed node, however long the preform; each warp's free segment (last
fixed node to guide) is registered in the 2-D (x, y) cells its box touches and re-registered
when it changes.
"""

from __future__ import annotations

import math
from array import array
from typing import Any

from bwsd.twin.machine import Machine
from bwsd.twin.predicates import Vec

Cell3 = tuple[int, int, int]
Cell2 = tuple[int, int]


class State:
    """Nodes, yarns, fixed and free segments, occupancy, take-up, contacts."""

    def __init__(self, machine: Machine, diameter: float) -> None:
        self.machine = machine
        self.diameter = diameter
        self.pos = array("d")  # x, y, z of node i at 3i .. 3i+2
        self.yarns: list[array[int]] = []  # node ids in order; a warp's last one is free
        self.yarn_angle: list[float | None] = []  # None for a warp, degrees for a weft
        self.yarn_cell: list[tuple[int, int] | None] = []  # fill cell of a warp
        self.yarn_len = array("d")  # polyline length of the fixed part of each yarn
        self.n_warps = 0
        self.last_fixed = array("q")  # per warp: node id of its last fixed node (B)
        self.free_node = array("q")  # per warp: node id of its free node
        self.warp_cell: list[tuple[int, int]] = []
        self.occupancy = [[-1] * machine.cols for _ in range(machine.rows)]
        self.takeup = 0.0
        self.contacts = array("q")  # instruction, moving, its node, hit, its node (5 a row)
        self.seg_c = array("q")
        self.seg_d = array("q")
        self.seg_yarn = array("q")
        self.seg_alive = bytearray()
        self.grid: dict[Cell3, array[int]] = {}
        self.free_grid: dict[Cell2, set[int]] = {}
        self.free_cells: list[list[Cell2]] = []
        side = max(machine.pitch_x, machine.pitch_y)
        self.cell = (machine.pitch_x, machine.pitch_y, side)
        self.log: list[tuple[Any, ...]] = []

    # ----- reading -----
    def xyz(self, node: int) -> Vec:
        p = self.pos
        i = 3 * node
        return p[i], p[i + 1], p[i + 2]

    @property
    def node_count(self) -> int:
        return len(self.pos) // 3

    @property
    def contact_count(self) -> int:
        return len(self.contacts) // 5

    # ----- building (before the first instruction; never undone) -----
    def add_warp(self, row: int, col: int) -> int:
        """Fill a case into (row, col): a fixed node at the fell and a free node at the guide."""
        m = self.machine
        fx, fy = m.fell_xy(row, col)
        gx, gy = m.guide_xy(row, col)
        yarn = len(self.yarns)
        fell = self._append_node((fx, fy, self.takeup))
        guide = self._append_node((gx, gy, m.d_mat + self.takeup))
        self.yarns.append(array("q", [fell, guide]))
        self.yarn_angle.append(None)
        self.yarn_cell.append((row, col))
        self.yarn_len.append(0.0)
        self.last_fixed.append(fell)
        self.free_node.append(guide)
        self.warp_cell.append((row, col))
        self.occupancy[row][col] = yarn
        self.free_cells.append([])
        self.n_warps += 1
        self._set_free_cells(yarn, [], self.cells2(self.xyz(fell), self.xyz(guide)))
        return yarn

    def _append_node(self, xyz: Vec) -> int:
        self.pos.extend(xyz)
        return len(self.pos) // 3 - 1

    # ----- logged mutations -----
    def new_node(self, xyz: Vec) -> int:
        self.log.append(("node",))
        return self._append_node(xyz)

    def insert_node(self, yarn: int, index: int, node: int) -> None:
        self.yarns[yarn].insert(index, node)
        self.log.append(("ins", yarn, index))

    def move_node(self, node: int, xyz: Vec) -> None:
        i = 3 * node
        self.log.append(("pos", i, self.pos[i], self.pos[i + 1], self.pos[i + 2]))
        self.pos[i], self.pos[i + 1], self.pos[i + 2] = xyz

    def set_last_fixed(self, warp: int, node: int) -> None:
        self.log.append(("last", warp, self.last_fixed[warp]))
        self.last_fixed[warp] = node

    def add_length(self, yarn: int, delta: float) -> None:
        self.log.append(("len", yarn, self.yarn_len[yarn]))
        self.yarn_len[yarn] += delta

    def place(self, warp: int, cell: tuple[int, int]) -> None:
        """Move warp's case to ``cell`` in the occupancy grid."""
        old = self.warp_cell[warp]
        self.log.append(("place", warp, old))
        self._move_case(warp, old, cell)

    def _move_case(self, warp: int, old: tuple[int, int], new: tuple[int, int]) -> None:
        if self.occupancy[old[0]][old[1]] == warp:
            self.occupancy[old[0]][old[1]] = -1
        self.occupancy[new[0]][new[1]] = warp
        self.warp_cell[warp] = new

    def set_takeup(self, value: float) -> None:
        self.log.append(("takeup", self.takeup))
        self.takeup = value

    def add_contact(self, record: tuple[int, int, int, int, int]) -> None:
        self.log.append(("contact",))
        self.contacts.extend(record)

    def add_weft(self, start: int, end: int, angle: float) -> int:
        yarn = len(self.yarns)
        self.yarns.append(array("q", [start, end]))
        self.yarn_angle.append(angle)
        self.yarn_cell.append(None)
        self.yarn_len.append(math.dist(self.xyz(start), self.xyz(end)))
        self.log.append(("weft",))
        self.add_segment(yarn, start, end)
        return yarn

    def add_segment(self, yarn: int, c: int, d: int) -> int:
        """Register the fixed segment c-d of ``yarn`` in the 3-D grid."""
        seg = len(self.seg_c)
        self.seg_c.append(c)
        self.seg_d.append(d)
        self.seg_yarn.append(yarn)
        self.seg_alive.append(1)
        cells = self.cells3(self.xyz(c), self.xyz(d))
        grid = self.grid
        for cell in cells:
            bucket = grid.get(cell)
            if bucket is None:
                bucket = grid[cell] = array("q")
            bucket.append(seg)
        self.log.append(("seg", cells))
        return seg

    def kill_segment(self, seg: int) -> None:
        self.seg_alive[seg] = 0
        self.log.append(("kill", seg))

    def register_free(self, warp: int) -> None:
        """(Re-)register warp's free segment in the 2-D grid."""
        old = self.free_cells[warp]
        new = self.cells2(self.xyz(self.last_fixed[warp]), self.xyz(self.free_node[warp]))
        if new == old:
            return
        self._set_free_cells(warp, old, new)
        self.log.append(("free", warp, old, new))

    def _set_free_cells(self, warp: int, old: list[Cell2], new: list[Cell2]) -> None:
        grid = self.free_grid
        for cell in old:
            grid[cell].discard(warp)
        for cell in new:
            bucket = grid.get(cell)
            if bucket is None:
                bucket = grid[cell] = set()
            bucket.add(warp)
        self.free_cells[warp] = new

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
            del self.pos[-3:]
        elif kind == "ins":
            del self.yarns[op[1]][op[2]]
        elif kind == "pos":
            i = op[1]
            self.pos[i], self.pos[i + 1], self.pos[i + 2] = op[2], op[3], op[4]
        elif kind == "last":
            self.last_fixed[op[1]] = op[2]
        elif kind == "len":
            self.yarn_len[op[1]] = op[2]
        elif kind == "place":
            self._move_case(op[1], self.warp_cell[op[1]], op[2])
        elif kind == "takeup":
            self.takeup = op[1]
        elif kind == "contact":
            del self.contacts[-5:]
        elif kind == "weft":
            self.yarns.pop()
            self.yarn_angle.pop()
            self.yarn_cell.pop()
            self.yarn_len.pop()
        elif kind == "seg":
            self._unsegment(op[1])
        elif kind == "kill":
            self.seg_alive[op[1]] = 1
        elif kind == "free":
            self._set_free_cells(op[1], op[3], op[2])

    def _unsegment(self, cells: list[Cell3]) -> None:
        for cell in cells:
            self.grid[cell].pop()
        self.seg_c.pop()
        self.seg_d.pop()
        self.seg_yarn.pop()
        self.seg_alive.pop()

    # ----- grid cells -----
    def cells3(self, *points: Vec) -> list[Cell3]:
        """3-D grid cells overlapping the box of ``points``."""
        hx, hy, hz = self.cell
        xs, ys, zs = zip(*points, strict=True)
        return [
            (i, j, k)
            for i in range(math.floor(min(xs) / hx), math.floor(max(xs) / hx) + 1)
            for j in range(math.floor(min(ys) / hy), math.floor(max(ys) / hy) + 1)
            for k in range(math.floor(min(zs) / hz), math.floor(max(zs) / hz) + 1)
        ]

    def cells2(self, *points: Vec) -> list[Cell2]:
        """2-D (x, y) grid cells overlapping the box of ``points``."""
        hx, hy, _ = self.cell
        xs, ys, _ = zip(*points, strict=True)
        return [
            (i, j)
            for i in range(math.floor(min(xs) / hx), math.floor(max(xs) / hx) + 1)
            for j in range(math.floor(min(ys) / hy), math.floor(max(ys) / hy) + 1)
        ]

    def fixed_near(self, b: Vec, a1: Vec, a2: Vec) -> set[int]:
        """Live fixed segments registered in cells overlapping the box of the triangle."""
        grid = self.grid
        alive = self.seg_alive
        found: set[int] = set()
        for cell in self.cells3(b, a1, a2):
            bucket = grid.get(cell)
            if bucket is not None:
                found.update(bucket)
        return {s for s in found if alive[s]}

    def free_near(self, b: Vec, a1: Vec, a2: Vec) -> set[int]:
        """Warps whose free segment is registered in cells overlapping the triangle's box."""
        grid = self.free_grid
        found: set[int] = set()
        for cell in self.cells2(b, a1, a2):
            bucket = grid.get(cell)
            if bucket:
                found.update(bucket)
        return found
