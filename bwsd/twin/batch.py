"""Candidates for every sweep of one instruction, found in one vectorised pass.

Each case of an instruction sweeps a triangle (B, A1, A2); everything its sweep can ever
meet lies in the triangle's box grown by one yarn diameter (a contact node X rests at most d
from the triangle) and a rounding margin. At the start of the instruction one pass finds,
per case, the fixed segments and the warps whose geometry meets that box: for a warp that
moves in the same instruction its whole swept region counts, since it may have moved before
or after. During the instruction the geometry only changes by contacts; the batch is told
of every segment a contact splits (its pieces replace it) and of every segment a yarn gains
(they join that yarn's free segment). So the list of a case is a superset of what its sweep
can hit, and the exact narrow phase decides as it would over every segment.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from bwsd.twin.predicates import FloatArray, IntArray, Vec
from bwsd.twin.state import State

DENSE_LIMIT = 400_000  # case x segment pairs tested at once; above it, per-sweep queries
Box = tuple[float, float, float, float, float, float]  # lo x, y, z, hi x, y, z
Candidate = tuple[int, int, Vec, Vec, Box]  # yarn, reference (segment or -(warp + 1)), c, d, box
Row = tuple[int, Vec, Vec, Box]  # a fixed segment's yarn, ends and box (they never change)


class Batch:
    """Candidate lists of the cases of one instruction (cases in execution order)."""

    def __init__(self, state: State, fixed: list[list[int]], warps: list[list[int]]) -> None:
        self.state = state
        self.fixed = fixed
        self.warps = warps
        self.rows: dict[int, Row] = {}
        self.free_rows: dict[int, Row] = {}
        self._remember({s for ids in fixed for s in ids})
        self.children: dict[int, tuple[int, ...]] = {}
        self.gained: defaultdict[int, list[int]] = defaultdict(list)

    @classmethod
    def plan(cls, state: State, cases: list[tuple[int, Vec]]) -> Batch | None:
        """The batch for ``cases`` (warp, target of its free node), or None when too large."""
        n = len(state.seg_c)
        if not cases or (len(state.active) + n - state.active_from) * len(cases) > DENSE_LIMIT:
            return None
        movers = np.array([w for w, _ in cases], dtype=np.int64)
        if len(np.unique(movers)) < len(movers):
            return None  # a line listed twice: its cases move twice
        seg = state.free_seg.data[movers]
        a2 = np.array([t for _, t in cases])
        pts = np.stack((seg[:, :3], seg[:, 3:], a2))
        scale = 1.0 + float(np.abs(pts).max())
        grow = state.diameter + 1e-9 * scale
        lo, hi = pts.min(axis=0) - grow, pts.max(axis=0) + grow
        fixed = _fixed_lists(state, lo, hi)
        return cls(state, fixed, _warp_lists(state, movers, lo, hi))

    def _remember(self, ids: set[int]) -> None:
        """Cache yarn, ends and box of fixed segments (read in one vectorised pass)."""
        st = self.state
        order = np.fromiter(ids, dtype=np.int64, count=len(ids))
        xyz = st.seg_xyz.data[order]
        lo, hi = np.minimum(xyz[:, :3], xyz[:, 3:]), np.maximum(xyz[:, :3], xyz[:, 3:])
        table = np.concatenate((xyz, lo, hi), axis=1).tolist()
        for s, yarn, r in zip(order.tolist(), st.seg_yarn.data[order].tolist(), table, strict=True):
            box = (r[6], r[7], r[8], r[9], r[10], r[11])
            self.rows[s] = (yarn, (r[0], r[1], r[2]), (r[3], r[4], r[5]), box)

    def _row(self, s: int) -> Row:
        st = self.state
        c, d = st.xyz(st.seg_c[s]), st.xyz(st.seg_d[s])
        box = (min(c[0], d[0]), min(c[1], d[1]), min(c[2], d[2]),
               max(c[0], d[0]), max(c[1], d[1]), max(c[2], d[2]))  # fmt: skip
        row = self.rows[s] = (int(st.seg_yarn.data[s]), c, d, box)
        return row

    # ----- told by the sweep -----
    def split(self, seg: int, pieces: tuple[int, ...]) -> None:
        """Fixed segment ``seg`` was replaced by ``pieces``."""
        self.children[seg] = pieces

    def gain(self, yarn: int, seg: int) -> None:
        """``yarn`` gained the fixed segment ``seg`` during this instruction."""
        self.gained[yarn].append(seg)
        self.free_rows.pop(yarn, None)

    def moved(self, warp: int) -> None:
        """``warp``'s free segment changed."""
        self.free_rows.pop(warp, None)

    # ----- asked by the sweep -----
    def candidates(
        self, case: int, w: int, skip: tuple[int, ...], skip_warp: int, lo: Vec, hi: Vec
    ) -> list[Candidate]:
        """Segments case ``case`` (warp ``w``) may hit whose box meets [lo, hi].

        Its own yarn's and the skipped segments are left out.
        """
        out: list[Candidate] = []
        bounds = (*lo, *hi)
        for s in self.fixed[case]:
            self._add_fixed(s, w, skip, bounds, out)
        for j in self.warps[case]:
            if j == w:
                continue
            if j != skip_warp:
                row = self.free_rows.get(j)
                if row is None:
                    row = self.free_rows[j] = self._free_row(j)
                if _meets(row[3], bounds):
                    out.append((j, -j - 1, row[1], row[2], row[3]))
            for s in self.gained.get(j, ()):
                self._add_fixed(s, w, skip, bounds, out)
        return out

    def _free_row(self, warp: int) -> Row:
        st = self.state
        c, d = st.xyz(st.last_fixed[warp]), st.xyz(st.free_node[warp])
        box = (min(c[0], d[0]), min(c[1], d[1]), min(c[2], d[2]),
               max(c[0], d[0]), max(c[1], d[1]), max(c[2], d[2]))  # fmt: skip
        return warp, c, d, box

    def _add_fixed(self, s: int, w: int, skip: tuple[int, ...], bounds: Box,
                   out: list[Candidate]) -> None:  # fmt: skip
        pieces = self.children.get(s)
        if pieces is not None:
            for piece in pieces:
                self._add_fixed(piece, w, skip, bounds, out)
            return
        row = self.rows.get(s) or self._row(s)
        if row[0] != w and _meets(row[3], bounds) and s not in skip:
            out.append((row[0], s, row[1], row[2], row[3]))


def _meets(box: Box, bounds: Box) -> bool:
    """Closed boxes (lo x, y, z, hi x, y, z) meet."""
    return (
        box[0] <= bounds[3] and box[3] >= bounds[0] and box[1] <= bounds[4]
        and box[4] >= bounds[1] and box[2] <= bounds[5] and box[5] >= bounds[2]
    )  # fmt: skip


def _fixed_lists(state: State, lo: FloatArray, hi: FloatArray) -> list[list[int]]:
    """Per case, the live fixed segments whose box meets the case's box."""
    floor = float(lo[:, 2].min())
    if floor < state.floor:
        state.refresh_active(floor - state.margin)
    start = int(np.searchsorted(state.active_top, floor))
    ids = state.active[start:]
    seg_lo, seg_hi = state.active_lo[start:], state.active_hi[start:]
    n = len(state.seg_c)
    if state.active_from < n:
        tail = state.seg_xyz.data[state.active_from : n]
        ids = np.concatenate((ids, np.arange(state.active_from, n)))
        seg_lo = np.concatenate((seg_lo, np.minimum(tail[:, :3], tail[:, 3:])))
        seg_hi = np.concatenate((seg_hi, np.maximum(tail[:, :3], tail[:, 3:])))
    live = state.seg_alive.data[ids]
    ids, seg_lo, seg_hi = ids[live], seg_lo[live], seg_hi[live]
    meet = (seg_hi[None] >= lo[:, None]).all(axis=2) & (seg_lo[None] <= hi[:, None]).all(axis=2)
    return [ids[row].tolist() for row in meet]


def _warp_lists(state: State, movers: IntArray, lo: FloatArray, hi: FloatArray) -> list[list[int]]:
    """Per case, the warps whose free segment (or, for a mover, swept region) meets its box."""
    seg = state.free_seg.data[: state.n_warps]
    w_lo, w_hi = np.minimum(seg[:, :3], seg[:, 3:]), np.maximum(seg[:, :3], seg[:, 3:])
    w_lo[movers], w_hi[movers] = lo, hi
    meet = (w_hi[None] >= lo[:, None]).all(axis=2) & (w_lo[None] <= hi[:, None]).all(axis=2)
    meet[np.arange(len(movers)), movers] = False
    return [np.nonzero(row)[0].tolist() for row in meet]
