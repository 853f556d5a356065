"""Exact reference of the whole twin (docs/twin.md), written independently of bwsd.twin.

Brute force, no broad phase, no filter: every decision (sides, barycentric signs, the order
of contacts) is taken in exact rational arithmetic on the float64 coordinates. Constructions
(new node coordinates, the restart point) use the same float formulas, in the same operation
order, as the documented contract of the kernel, so both produce identical floats wherever
they take identical decisions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

from bwsd.twin.instructions import Shift, TakeUp, Weft

Vec = tuple[float, float, float]
PARALLEL = 1e-12


def _fr(v: Vec) -> tuple[Fraction, Fraction, Fraction]:
    return Fraction(v[0]), Fraction(v[1]), Fraction(v[2])


def orient_exact(p0: Vec, p1: Vec, p2: Vec, p3: Vec) -> Fraction:
    o, a, b, c = _fr(p0), _fr(p1), _fr(p2), _fr(p3)
    a = (a[0] - o[0], a[1] - o[1], a[2] - o[2])
    b = (b[0] - o[0], b[1] - o[1], b[2] - o[2])
    c = (c[0] - o[0], c[1] - o[1], c[2] - o[2])
    return (
        a[0] * (b[1] * c[2] - b[2] * c[1])
        - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
    )


def orient_float(p0: Vec, p1: Vec, p2: Vec, p3: Vec) -> float:
    """The kernel's float formula: minors of (p1-p0, p2-p0) dotted with p3-p0, in order."""
    ax, ay, az = p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]
    bx, by, bz = p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]
    cx, cy, cz = p3[0] - p0[0], p3[1] - p0[1], p3[2] - p0[2]
    n0, n1, n2 = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    return cx * n0 + cy * n1 + cz * n2


def edge_float(c: Vec, d: Vec, q: Vec, r: Vec) -> float:
    """The kernel's float formula for orient(c, d, q, r) (same form as orient_float)."""
    return orient_float(c, d, q, r)


def _sign(v: Fraction) -> int:
    return (v > 0) - (v < 0)


@dataclass
class Contact:
    instruction: int
    moving_yarn: int
    moving_node: int
    hit_yarn: int
    hit_node: int


@dataclass
class RefTwin:
    rows: int
    cols: int
    pitch_x: float
    pitch_y: float
    d_mat: float
    c_mat: float
    diameter: float
    nodes: list[Vec] = field(default_factory=list)
    yarns: list[list[int]] = field(default_factory=list)
    n_warps: int = 0
    cell: dict[int, tuple[int, int]] = field(default_factory=dict)
    takeup: float = 0.0
    contacts: list[Contact] = field(default_factory=list)
    done: int = 0

    def fill(self, cells: list[tuple[int, int]]) -> None:
        ox = (self.cols - 1) / 2 * self.pitch_x
        oy = (self.rows - 1) / 2 * self.pitch_y
        for r, c in cells:
            gx, gy = c * self.pitch_x, r * self.pitch_y
            fell = (ox + self.c_mat * (gx - ox), oy + self.c_mat * (gy - oy), self.takeup)
            self.nodes.append(fell)
            self.nodes.append((gx, gy, self.d_mat + self.takeup))
            self.yarns.append([len(self.nodes) - 2, len(self.nodes) - 1])
            self.cell[len(self.yarns) - 1] = (r, c)
        self.n_warps = len(self.yarns)

    # ----- instructions -----
    def run(self, instruction: Shift | TakeUp | Weft) -> None:
        self.done += 1
        if isinstance(instruction, Shift):
            self._shift(instruction)
        elif isinstance(instruction, TakeUp):
            self.takeup = self.takeup + instruction.length
            for w in range(self.n_warps):
                a = self.nodes[self.yarns[w][-1]]
                self.sweep(w, (a[0] + 0.0, a[1] + 0.0, a[2] + instruction.length))
        else:
            self._weft(instruction)

    def _shift(self, ins: Shift) -> None:
        z = self.d_mat + self.takeup
        for line, k in ins.moves:
            on_line = [
                (w, rc)
                for w, rc in self.cell.items()
                if (rc[0] if ins.axis == "row" else rc[1]) == line
            ]
            key = (lambda e: e[1][1]) if ins.axis == "row" else (lambda e: e[1][0])
            on_line.sort(key=key, reverse=k > 0)
            for w, (r, c) in on_line:
                r2, c2 = (r, c + k) if ins.axis == "row" else (r + k, c)
                assert 0 <= r2 < self.rows and 0 <= c2 < self.cols, "move out of the matrix"
                assert (r2, c2) not in self.cell.values(), "move onto an occupied cell"
                self.cell[w] = (r2, c2)
                self.sweep(w, (c2 * self.pitch_x, r2 * self.pitch_y, z))

    def _weft(self, ins: Weft) -> None:
        rad = math.radians(ins.angle)
        ax, ay = math.cos(rad), math.sin(rad)
        half = ins.length / 2
        cz = self.takeup + ins.z
        self.nodes.append((ins.x - half * ax, ins.y - half * ay, cz - half * 0.0))
        self.nodes.append((ins.x + half * ax, ins.y + half * ay, cz + half * 0.0))
        self.yarns.append([len(self.nodes) - 2, len(self.nodes) - 1])

    # ----- the sweep -----
    def _segments(self, moving: int) -> list[tuple[int, int, int, int]]:
        """(yarn, index along the yarn, node c, node d) of every other yarn."""
        out = []
        for y, ids in enumerate(self.yarns):
            if y != moving:
                out.extend((y, i, ids[i], ids[i + 1]) for i in range(len(ids) - 1))
        return out

    def _first(self, w: int, b: Vec, a1: Vec, a2: Vec, skip: set[tuple[int, int]]):  # type: ignore[no-untyped-def]
        best = None
        for y, i, c, d in self._segments(w):
            if (c, d) in skip:
                continue
            pc, pd = self.nodes[c], self.nodes[d]
            sc, sd = _sign(orient_exact(b, a1, a2, pc)), _sign(orient_exact(b, a1, a2, pd))
            if (sc >= 0) == (sd >= 0):
                continue
            wb = orient_exact(pc, pd, a1, a2)
            w1 = orient_exact(pc, pd, a2, b)
            w2 = orient_exact(pc, pd, b, a1)
            if wb == 0 or _sign(w2) != _sign(wb) or (w1 != 0 and _sign(w1) != _sign(wb)):
                continue
            key = (w2 / (w1 + w2), y, i)
            if best is None or key < best[0]:
                best = (key, y, c, d, sc, sd, w1 == 0)
        return best

    def sweep(self, w: int, a2: Vec) -> None:
        ids = self.yarns[w]
        a1 = self.nodes[ids[-1]]
        skip: set[tuple[int, int]] = set()
        while True:
            b = self.nodes[ids[-2]]
            hit = self._first(w, b, a1, a2, skip)
            if hit is None:
                self.nodes[ids[-1]] = a2
                return
            _, y, c, d, sc, sd, t_is_one = hit
            pc, pd = self.nodes[c], self.nodes[d]
            p = self._crossing(pc, pd, b, a1, a2, sc, sd)
            self.nodes.append(p)
            yid = len(self.nodes) - 1
            hit_ids = self.yarns[y]
            hit_ids.insert(hit_ids.index(d), yid)
            self.nodes.append(self._rest(p, pc, pd, a1, a2))
            xid = len(self.nodes) - 1
            ids.insert(len(ids) - 1, xid)
            self.contacts.append(Contact(self.done, w, xid, y, yid))
            skip = {(c, yid), (yid, d)}
            if t_is_one:
                a1 = a2
            else:
                v1, v2 = edge_float(pc, pd, a2, b), edge_float(pc, pd, b, a1)
                exact = float(hit[0][0])
                t = min(max(v2 / (v1 + v2), 0.0), 1.0) if v1 + v2 != 0 else exact
                a1 = (
                    a1[0] + t * (a2[0] - a1[0]),
                    a1[1] + t * (a2[1] - a1[1]),
                    a1[2] + t * (a2[2] - a1[2]),
                )

    @staticmethod
    def _crossing(pc: Vec, pd: Vec, b: Vec, a1: Vec, a2: Vec, sc: int, sd: int) -> Vec:
        if sc == 0:
            return pc
        if sd == 0:
            return pd
        oc, od = orient_float(b, a1, a2, pc), orient_float(b, a1, a2, pd)
        if oc != od:
            s = min(max(oc / (oc - od), 0.0), 1.0)
        else:
            ec, ed = orient_exact(b, a1, a2, pc), orient_exact(b, a1, a2, pd)
            s = float(ec / (ec - ed))
        return (
            pc[0] + s * (pd[0] - pc[0]),
            pc[1] + s * (pd[1] - pc[1]),
            pc[2] + s * (pd[2] - pc[2]),
        )

    def _rest(self, p: Vec, pc: Vec, pd: Vec, a1: Vec, a2: Vec) -> Vec:
        if self.diameter == 0:
            return p
        mx, my, mz = a2[0] - a1[0], a2[1] - a1[1], a2[2] - a1[2]
        ax, ay, az = pd[0] - pc[0], pd[1] - pc[1], pd[2] - pc[2]
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        ax, ay, az = ax / norm, ay / norm, az / norm
        along = mx * ax + my * ay + mz * az
        nx, ny, nz = mx - along * ax, my - along * ay, mz - along * az
        size = math.sqrt(nx * nx + ny * ny + nz * nz)
        if size <= PARALLEL * math.sqrt(mx * mx + my * my + mz * mz):
            return p
        k = self.diameter / size
        return (p[0] - k * nx, p[1] - k * ny, p[2] - k * nz)
