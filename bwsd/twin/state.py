"""Mutable state of the twin with an undo log: nodes, yarns, segments, occupancy.

Storage is flat (``array`` and numpy) so that a long preform costs a few tens of bytes per
node. Every change goes through a method here and is logged, so a prediction can run in
place and be rolled back (``undo_to``) or kept (``forget_log``) in O(changes).

Broad phase: a sweep triangle never reaches below its apex (the moving yarn's last fixed
node), and the apexes rise with the preform. Fixed segments (both ends fixed) keep their
coordinates in numpy arrays; an *active set* holds the ids of those reaching above a floor
set below every apex, so a query's cost follows the working zone, not the preform's length.
A query whose box reaches below the floor rebuilds the set with a lower floor (exact, rare).
Each warp's free segment (last fixed node to guide) is read from the node coordinates.
"""

from __future__ import annotations

import math
from array import array
from typing import Any

import numpy as np
import numpy.typing as npt

from bwsd.twin.machine import Machine
from bwsd.twin.predicates import Vec

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class GrowArray:
    """A numpy array that grows by doubling along its first axis."""

    def __init__(self, dtype: Any, width: int = 0) -> None:
        self.data: np.ndarray[Any, Any] = np.zeros((64, width) if width else (64,), dtype=dtype)
        self.size = 0

    def append(self, value: Any) -> None:
        if self.size == len(self.data):
            grown = np.zeros((2 * len(self.data), *self.data.shape[1:]), dtype=self.data.dtype)
            grown[: self.size] = self.data[: self.size]
            self.data = grown
        self.data[self.size] = value
        self.size += 1


class State:
    """Nodes, yarns, fixed segments, occupancy, take-up, contacts."""

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
        self.seg_c = array("q")  # node ids of each fixed segment's ends
        self.seg_d = array("q")
        self.seg_xyz = GrowArray(np.float64, 6)  # cx, cy, cz, dx, dy, dz
        self.seg_yarn = GrowArray(np.int64)
        self.seg_alive = GrowArray(np.bool_)
        self.free_seg = GrowArray(np.float64, 6)  # per warp: its last fixed node, free node
        self.active = np.empty(0, dtype=np.int64)  # ids below active_from reaching the floor
        self.active_lo = np.empty((0, 3))
        self.active_hi = np.empty((0, 3))
        self.active_top = np.empty(0)
        self.active_from = 0
        self.floor = math.inf
        # an apex may dip below the last one by one diameter per contact (X = P - d n)
        self.margin = 4 * diameter + 0.1 * min(machine.pitch_x, machine.pitch_y)
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
        self.free_seg.append(np.zeros(6))
        self.n_warps += 1
        self._sync_free(yarn)
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

    def move_free(self, warp: int, xyz: Vec) -> None:
        """Move warp's free node to ``xyz``."""
        i = 3 * self.free_node[warp]
        self.log.append(("free", warp, self.pos[i], self.pos[i + 1], self.pos[i + 2]))
        self.pos[i], self.pos[i + 1], self.pos[i + 2] = xyz
        self._sync_free(warp)

    def set_last_fixed(self, warp: int, node: int) -> None:
        self.log.append(("last", warp, self.last_fixed[warp]))
        self.last_fixed[warp] = node
        self._sync_free(warp)

    def _sync_free(self, warp: int) -> None:
        self.free_seg.data[warp] = self.xyz(self.last_fixed[warp]) + self.xyz(self.free_node[warp])

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
        """Add the fixed segment c-d of ``yarn``."""
        seg = len(self.seg_c)
        self.seg_c.append(c)
        self.seg_d.append(d)
        self.seg_xyz.append(self.xyz(c) + self.xyz(d))
        self.seg_yarn.append(yarn)
        self.seg_alive.append(True)
        self.log.append(("seg",))
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
        n = len(self.seg_c)
        if self.active_from > n:
            keep = self.active < n
            self.active, self.active_lo = self.active[keep], self.active_lo[keep]
            self.active_hi, self.active_top = self.active_hi[keep], self.active_top[keep]
            self.active_from = n

    def forget_log(self) -> None:
        self.log.clear()
        self._maybe_compact()

    def _undo(self, op: tuple[Any, ...]) -> None:
        kind = op[0]
        if kind == "node":
            del self.pos[-3:]
        elif kind == "ins":
            del self.yarns[op[1]][op[2]]
        elif kind == "free":
            i = 3 * self.free_node[op[1]]
            self.pos[i], self.pos[i + 1], self.pos[i + 2] = op[2], op[3], op[4]
            self._sync_free(op[1])
        elif kind == "last":
            self.last_fixed[op[1]] = op[2]
            self._sync_free(op[1])
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
            self.seg_c.pop()
            self.seg_d.pop()
            for grow in (self.seg_xyz, self.seg_yarn, self.seg_alive):
                grow.size -= 1
        elif kind == "kill":
            self.seg_alive.data[op[1]] = True

    # ----- broad phase -----
    def refresh_active(self, floor: float, ids: IntArray | None = None) -> None:
        """Rebuild the active set from ``ids`` (all segments when None) above ``floor``.

        The set is sorted by the segments' top z, so a query scans only those reaching
        above its apex. Dead segments stay in (a prediction may be rolled back and revive
        them); queries check liveness.
        """
        n = len(self.seg_c)
        if ids is None:
            ids = np.arange(n)
        xyz = self.seg_xyz.data[ids]
        lo, hi = np.minimum(xyz[:, :3], xyz[:, 3:]), np.maximum(xyz[:, :3], xyz[:, 3:])
        order = np.argsort(hi[:, 2], kind="stable")
        order = order[hi[order, 2] >= floor]
        self.active, self.active_lo, self.active_hi = ids[order], lo[order], hi[order]
        self.active_top = self.active_hi[:, 2].copy()
        self.active_from = n
        self.floor = floor

    def _maybe_compact(self) -> None:
        """Fold the recent segments into the active set, dropping those sunk below the apexes.

        Segments below the floor stay out: a later query that reaches below the floor
        rebuilds the set from every segment.
        """
        n = len(self.seg_c)
        if n - self.active_from < max(256, len(self.active) // 4) or not self.n_warps:
            return  # the tail is still cheap to scan as it is
        pos = np.frombuffer(self.pos, dtype=np.float64)
        apex = float(pos[3 * np.frombuffer(self.last_fixed, dtype=np.int64) + 2].min())
        del pos  # release the buffer: the array may grow again
        floor = apex - self.margin
        if floor < self.floor:
            self.refresh_active(floor)
        else:
            recent = np.arange(self.active_from, n)
            self.refresh_active(floor, np.concatenate((self.active, recent)))

    def first_reaching(self, z: float) -> int:
        """Position in the active set of its first segment reaching height ``z``.

        Below the floor the set is rebuilt from every segment first, so nothing is missed.
        """
        if z < self.floor:
            self.refresh_active(z - self.margin)
        return int(np.searchsorted(self.active_top, z))

    def recent(self) -> IntArray:
        """Ids of the segments added since the active set was last built."""
        result: IntArray = np.arange(self.active_from, len(self.seg_c))
        return result

    def fixed_near(self, lo: Vec, hi: Vec) -> IntArray:
        """Ids of live fixed segments whose box meets the closed box [lo, hi]."""
        start = self.first_reaching(lo[2])
        above_lo, above_hi = self.active_lo[start:], self.active_hi[start:]
        keep = (above_hi >= lo).all(axis=1) & (above_lo <= hi).all(axis=1)
        found = self.active[start:][keep]
        n = len(self.seg_c)
        if self.active_from < n:
            tail = self.seg_xyz.data[self.active_from : n]
            found = np.concatenate((found, self.active_from + _meeting(tail, lo, hi)))
        result: IntArray = found[self.seg_alive.data[found]]
        return result

    def free_near(self, lo: Vec, hi: Vec) -> IntArray:
        """Warps whose free segment's box meets the closed box [lo, hi]."""
        return _meeting(self.free_seg.data[: self.n_warps], lo, hi)


def _meeting(segments: FloatArray, lo: Vec, hi: Vec) -> IntArray:
    """Rows of an (n, 6) array of segments whose box meets the box [lo, hi]."""
    c, d = segments[:, :3], segments[:, 3:]
    near = (np.maximum(c, d) >= lo).all(axis=1) & (np.minimum(c, d) <= hi).all(axis=1)
    result: IntArray = np.nonzero(near)[0]
    return result
