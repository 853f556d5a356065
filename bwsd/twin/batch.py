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

from bwsd.twin.predicates import BoolArray, FloatArray, IntArray, Vec
from bwsd.twin.state import State

DENSE_LIMIT = 200_000  # case x segment pairs tested densely; above it, a grid join
SLAB_FROM = 2_000  # pairs: below this the plane filter costs more than the candidates it saves
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
        """The batch for ``cases`` (warp, target of its free node); None if a warp moves twice."""
        movers = np.array([w for w, _ in cases], dtype=np.int64)
        if not cases or len(np.unique(movers)) < len(movers):
            return None  # a line listed twice: its cases move twice
        seg = state.free_seg.data[movers]
        tri = np.stack((seg[:, :3], seg[:, 3:], np.array([t for _, t in cases])))  # B, A1, A2
        scale = 1.0 + float(np.abs(tri).max())
        reach = state.diameter + 1e-9 * scale
        planes = _Planes(tri, reach, scale)
        lo, hi = tri.min(axis=0) - reach, tri.max(axis=0) + reach
        fixed = _fixed_lists(state, planes, lo, hi)
        return cls(state, fixed, _warp_lists(state, planes, movers, lo, hi))

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


class _Planes:
    """The cases' sweep planes, to drop segments lying wholly beyond reach on one side.

    Every sub-sweep of a case stays within one diameter of its first triangle's plane (a
    contact node X rests d from a point of it), so a segment whose ends both lie farther than
    that, on one side, can never be hit by the case.
    """

    def __init__(self, tri: FloatArray, reach: float, scale: float) -> None:
        b, a1, a2 = tri
        normal = np.cross(a1 - b, a2 - b)
        size = np.linalg.norm(normal, axis=1)
        usable = size > 1e-9 * scale * scale
        self.b = b
        self.normal = normal / np.where(usable, size, 1.0)[:, None]
        self.usable = usable
        self.reach = reach + 1e-7 * scale  # generous: this is a filter, exactness comes later

    def keep(self, case: IntArray, c: FloatArray, d: FloatArray) -> BoolArray:
        """False where both ends of a segment lie beyond reach on one side of the case's plane."""
        n, b = self.normal[case], self.b[case]
        sc = np.einsum("ij,ij->i", c - b, n)
        sd = np.einsum("ij,ij->i", d - b, n)
        beyond = ((sc > self.reach) & (sd > self.reach)) | ((sc < -self.reach) & (sd < -self.reach))
        result: BoolArray = ~beyond | ~self.usable[case]
        return result


def _pairs(lo: FloatArray, hi: FloatArray, item_lo: FloatArray, item_hi: FloatArray,
           cell: tuple[float, float]) -> tuple[IntArray, IntArray]:  # fmt: skip
    """(case, item) index pairs whose boxes meet, sorted by case.

    Dense when small; otherwise a join on a uniform (x, y) grid, in numpy throughout.
    """
    m, k = len(lo), len(item_lo)
    if m * k <= DENSE_LIMIT:
        meet = (item_hi[None] >= lo[:, None]).all(axis=2)
        meet &= (item_lo[None] <= hi[:, None]).all(axis=2)
        case, item = np.nonzero(meet)
        return case.astype(np.int64), item.astype(np.int64)
    case_idx, case_key = _cells(lo, hi, cell)
    item_idx, item_key = _cells(item_lo, item_hi, cell)
    order = np.argsort(item_key, kind="stable")
    keys = item_key[order]
    left = np.searchsorted(keys, case_key, "left")
    count = np.searchsorted(keys, case_key, "right") - left
    pair_case = np.repeat(case_idx, count)
    offset = np.arange(len(pair_case)) - np.repeat(np.cumsum(count) - count, count)
    pair_item = item_idx[order[np.repeat(left, count) + offset]]
    code = np.unique(pair_case * k + pair_item)
    case, item = code // k, code % k
    meet = (item_hi[item] >= lo[case]).all(axis=1) & (item_lo[item] <= hi[case]).all(axis=1)
    return case[meet], item[meet]


def _cells(lo: FloatArray, hi: FloatArray, cell: tuple[float, float]) -> tuple[IntArray, IntArray]:
    """Every (box index, cell key) of the (x, y) grid cells each box covers."""
    x0, x1 = np.floor(lo[:, 0] / cell[0]), np.floor(hi[:, 0] / cell[0])
    y0, y1 = np.floor(lo[:, 1] / cell[1]), np.floor(hi[:, 1] / cell[1])
    nx = (x1 - x0 + 1).astype(np.int64)
    per = nx * (y1 - y0 + 1).astype(np.int64)
    idx = np.repeat(np.arange(len(lo)), per)
    offset = np.arange(len(idx)) - np.repeat(np.cumsum(per) - per, per)
    cx = x0.astype(np.int64)[idx] + offset % nx[idx]
    cy = y0.astype(np.int64)[idx] + offset // nx[idx]
    return idx, (cx + (1 << 30)) * (1 << 31) + (cy + (1 << 30))


def _lists(case: IntArray, values: IntArray, m: int) -> list[list[int]]:
    """Group ``values`` by ``case`` (sorted) into one list per case."""
    bounds = np.searchsorted(case, np.arange(m + 1))
    flat = values.tolist()
    edges = bounds.tolist()
    return [flat[edges[i] : edges[i + 1]] for i in range(m)]


def _fixed_lists(state: State, planes: _Planes, lo: FloatArray, hi: FloatArray) -> list[list[int]]:
    """Per case, the live fixed segments that meet its box and reach near its plane."""
    start = state.first_reaching(float(lo[:, 2].min()))
    ids = np.concatenate((state.active[start:], state.recent()))
    ids = ids[state.seg_alive.data[ids]]
    xyz = state.seg_xyz.data[ids]
    c, d = xyz[:, :3], xyz[:, 3:]
    m = state.machine
    case, item = _pairs(lo, hi, np.minimum(c, d), np.maximum(c, d), (m.pitch_x, m.pitch_y))
    near = planes.keep(case, c[item], d[item]) if len(case) > SLAB_FROM else slice(None)
    return _lists(case[near], ids[item[near]], len(lo))


def _warp_lists(state: State, planes: _Planes, movers: IntArray, lo: FloatArray,
                hi: FloatArray) -> list[list[int]]:  # fmt: skip
    """Per case, the warps whose free segment (or, for a mover, swept region) may be hit."""
    seg = state.free_seg.data[: state.n_warps]
    c, d = seg[:, :3], seg[:, 3:]
    w_lo, w_hi = np.minimum(c, d), np.maximum(c, d)
    w_lo[movers], w_hi[movers] = lo, hi
    m = state.machine
    case, warp = _pairs(lo, hi, w_lo, w_hi, (m.pitch_x, m.pitch_y))
    moving = np.zeros(state.n_warps, dtype=np.bool_)
    moving[movers] = True
    keep = warp != movers[case]
    if len(case) > SLAB_FROM:
        keep &= moving[warp] | planes.keep(case, c[warp], d[warp])
    return _lists(case[keep], warp[keep], len(lo))
