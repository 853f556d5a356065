"""Exact reference of the whole twin (docs/twin.md), the test oracle of the kernel.

Written independently of ``bwsd.twin``: only the plain input data classes (``Machine``,
``Shift``, ``TakeUp``, ``Weft``) are imported. Brute force by design: every decision and every
number is exact, in Python ints and Fractions, with no float filter. Its only shortcut is an
exact one, on the grid's ints: a segment whose bounding box lies apart from the triangle's
(or further than a diameter from the weft's) cannot touch it, and is not computed.

Number conventions (decided for the project):

- An input number is an ``int`` or a Python ``float``; a float stands for the decimal it prints
  as (``exact(2.54) == Fraction(254, 100)``).
- Coordinates live on a grid of 2^-32 mm and are held as ints q meaning q * 2^-32 mm. A real
  value is rounded to the grid once, to the nearest grid point, ties to even.
- Any coordinate of magnitude 2^20 mm or more (|q| >= 2^52) is an error (``ValueError``).

Model conventions (where docs/twin.md leaves the choice to the implementation):

- Yarn ids: warps in fill order, then wefts in insertion order.
- Node ids are global, allocated in this order: at fill, for each warp its fell node then its
  free node; at each contact Y (the hit yarn's new node) then X (the moving yarn's); a weft its
  start node then its end node. A warp's free node keeps its id and moves with its guide.
- A contact is recorded as (instruction, moving yarn, X node, hit yarn, Y node), in the order
  made; instructions count from 1.
- The guides' height during a TAKEUP is the one it moves them to: the take-up so far includes
  its own length (the guides are at their new height when its sweeps run).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction
from typing import overload

from bwsd.twin.instructions import Shift, TakeUp, Weft
from bwsd.twin.machine import Machine

SCALE = 1 << 32  # grid points per mm
LIMIT = 1 << 52  # |q| >= LIMIT (2^20 mm) is refused
MAX_CONTACTS_PER_SWEEP = 100_000  # a guard against a sweep that never ends (not a model rule)

Point = tuple[int, int, int]
FPoint = tuple[Fraction, Fraction, Fraction]
# What run() saves and restores: nodes, yarns, contacts, take-up, cell_of and case_at.
_State = tuple[
    list[Point],
    list[list[int]],
    list[tuple[int, int, int, int, int]],
    Fraction,
    dict[int, tuple[int, int]],
    dict[tuple[int, int], int],
]


class ShedClosed(ValueError):
    """A weft would pass closer than the yarn diameter to another yarn: the shed is not open."""


class MoveRefused(ValueError):
    """A case would leave the matrix or land on an occupied cell (nothing has moved)."""


class Jam(ValueError):
    """A contact node would lie within one diameter of the guide plane, or above it: the
    yarns would lock at the guides (nothing of the instruction is applied)."""

    def __init__(self, moving: int, hit: int, z: int) -> None:
        super().__init__(f"jam: yarn {moving} on yarn {hit} at z = {math.ldexp(z, -32)!r} mm")
        self.moving, self.hit, self.z = moving, hit, z


# --- numbers ------------------------------------------------------------------------------


def exact(x: int | float | Fraction) -> Fraction:
    """The exact value of an input number: an int as is, a float as the decimal it prints as."""
    if isinstance(x, Fraction):
        return x
    if isinstance(x, int):
        return Fraction(x)
    if isinstance(x, float):
        return Fraction(repr(x))  # raises ValueError for nan and inf
    raise TypeError(f"not a number: {x!r}")


def _checked(q: int) -> int:
    if abs(q) >= LIMIT:
        raise ValueError(
            f"coordinate {math.ldexp(q, -32)!r} mm is beyond the model's range (2^20 mm)"
        )
    return q


def _round_units(v: Fraction) -> int:
    """A value in grid units to the nearest grid point, ties to even, range-checked."""
    return _checked(round(v))


def round_grid(v: Fraction | int) -> int:
    """A value in mm to the grid (units of 2^-32 mm): nearest, ties to even, range-checked."""
    return _round_units(Fraction(v) * SCALE)


def _sub(a: Sequence[int], b: Sequence[int]) -> Point:
    return a[0] - b[0], a[1] - b[1], a[2] - b[2]


@overload
def _dot(a: Sequence[int], b: Sequence[int]) -> int: ...
@overload
def _dot(a: Sequence[int | Fraction], b: Sequence[int | Fraction]) -> int | Fraction: ...
def _dot(a: Sequence[int | Fraction], b: Sequence[int | Fraction]) -> int | Fraction:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: Sequence[int], b: Sequence[int]) -> Point:
    return (
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    )


def _sign(v: int | Fraction) -> int:
    return (v > 0) - (v < 0)


def _round_shifted(y: int, c: Fraction, n2: int) -> int:
    """round(y - c / sqrt(n2)), ties to even, exactly; y an int, c rational, n2 a positive int.

    With c = p / q (q > 0): |2c / sqrt(n2)| = A / sqrt(B), A = 2|p|, B = q^2 n2, whose floor
    is isqrt(floor(A^2 / B)) and which is an integer j exactly when j^2 B == A^2.
    """
    a = 2 * abs(c.numerator)
    b = c.denominator * c.denominator * n2
    j = math.isqrt(a * a // b)
    whole = j * j * b == a * a  # |2c / sqrt(n2)| == j exactly
    # floor(2v), v = y - c / sqrt(n2) = y - s |c| / sqrt(n2), s the sign of c.
    ceil = j if whole else j + 1  # ceil(|2c / sqrt(n2)|)
    f = 2 * y - ceil if c >= 0 else 2 * y + j
    if not whole:
        return (f + 1) // 2  # 2v strictly between f and f + 1: no tie
    if f % 2 == 0:
        return f // 2  # v is an integer
    lo, hi = (f - 1) // 2, (f + 1) // 2  # v is exactly halfway: ties to even
    return lo if lo % 2 == 0 else hi


def rest_point(y: Sequence[int], m: Sequence[int], u: Sequence[int], d: Fraction) -> Point:
    """X = round(Y - d n / |n|), n = m - (m.u / u.u) u; Y on the grid, m and u integer vectors.

    ``d`` is in mm (exact); ``y`` in grid units. X = Y when d = 0 or n is the zero vector.
    The direction of n is taken from the integer vector (u.u) m - (m.u) u (the same direction,
    scaled by u.u > 0); with u = 0 there is nothing to remove and n = m.
    """
    y = tuple(int(v) for v in y)
    uu = _dot(u, u)
    if uu == 0:
        n = tuple(int(v) for v in m)
    else:
        mu = _dot(m, u)
        n = tuple(uu * m[k] - mu * u[k] for k in range(3))
    n2 = _dot(n, n)
    d = exact(d)
    if d == 0 or n2 == 0:
        return _checked(y[0]), _checked(y[1]), _checked(y[2])
    dd = d * SCALE  # d in grid units
    x0, x1, x2 = (_checked(_round_shifted(y[k], dd * n[k], n2)) for k in range(3))
    return x0, x1, x2


def restart_point(a1: Point, a2: Point, t: Fraction) -> Point:
    """round(A1 + t (A2 - A1)): where the free node restarts after a contact at time t."""
    if t == 1:
        return a2
    return (
        _round_units(a1[0] + t * (a2[0] - a1[0])),
        _round_units(a1[1] + t * (a2[1] - a1[1])),
        _round_units(a1[2] + t * (a2[2] - a1[2])),
    )


# --- exact predicates ---------------------------------------------------------------------


def crossing(b: Point, a1: Point, a2: Point, c: Point, d: Point) -> tuple[Fraction, FPoint] | None:
    """The contact of segment C-D with the swept triangle (B, A1, A2): (t, P) or None.

    Sides by the sign of det[A1-B, A2-B, X-B], zero counting as positive; C and D must lie on
    opposite sides. P, the exact crossing of C-D with the triangle's plane, must have
    barycentric weights (wB, wA1, wA2) with wB and wA2 nonzero of one sign and wA1 of that
    sign or zero; then t = wA2 / (wA1 + wA2). All points on the grid (ints).
    """
    e1, e2 = _sub(a1, b), _sub(a2, b)
    normal = _cross(e1, e2)
    sc = _dot(normal, _sub(c, b))
    sd = _dot(normal, _sub(d, b))
    if (sc >= 0) == (sd >= 0):
        return None  # same side (a degenerate triangle puts every point on the zero side)
    # sc and sd differ (one is negative, the other not): P = C + sc / (sc - sd) (D - C).
    lam = Fraction(sc, sc - sd)
    px, py, pz = (c[k] + lam * (d[k] - c[k]) for k in range(3))
    p = (px, py, pz)
    # Barycentric weights: solve P - B = wA1 e1 + wA2 e2 in the coordinate plane where the
    # triangle's projection is largest (drop the axis of the largest normal component).
    drop = max(range(3), key=lambda k: abs(normal[k]))
    i, j = [k for k in range(3) if k != drop]
    det = e1[i] * e2[j] - e1[j] * e2[i]
    pi, pj = p[i] - b[i], p[j] - b[j]
    w_a1 = (pi * e2[j] - pj * e2[i]) / det
    w_a2 = (e1[i] * pj - e1[j] * pi) / det
    w_b = 1 - w_a1 - w_a2
    sign = _sign(w_b)
    if sign == 0 or _sign(w_a2) != sign or _sign(w_a1) not in (0, sign):
        return None
    return w_a2 / (w_a1 + w_a2), p


def _point_segment_distance2(p: Sequence[int], q0: Sequence[int], q1: Sequence[int]) -> Fraction:
    """Exact squared distance from point p to segment q0-q1 (clamped 1-D minimum)."""
    v = _sub(q1, q0)
    w = _sub(p, q0)
    vv, wv = _dot(v, v), _dot(w, v)
    if vv == 0 or wv <= 0:  # the nearest point is q0
        return Fraction(_dot(w, w))
    if wv >= vv:  # q1
        r = _sub(p, q1)
        return Fraction(_dot(r, r))
    # at s = wv / vv inside: |w - s v|^2 = |vv w - wv v|^2 / vv^2, in ints until the division
    inside = tuple(vv * w[k] - wv * v[k] for k in range(3))
    return Fraction(_dot(inside, inside), vv * vv)


def segment_distance2(p0: Point, p1: Point, q0: Point, q1: Point) -> Fraction:
    """Exact squared distance between segments p0-p1 and q0-q1 (grid units squared).

    The minimum of the convex quadratic |p0 + s u - q0 - t v|^2 over [0, 1]^2: the interior
    critical point when it exists and lies inside, else the least of the four edge minima.
    """
    u, v, w0 = _sub(p1, p0), _sub(q1, q0), _sub(p0, q0)
    a, bb, c = _dot(u, u), _dot(u, v), _dot(v, v)
    dd, e = _dot(u, w0), _dot(v, w0)
    det = a * c - bb * bb
    if det != 0:  # not parallel (nor degenerate): a unique critical point
        s = Fraction(bb * e - c * dd, det)
        t = Fraction(a * e - bb * dd, det)
        if 0 <= s <= 1 and 0 <= t <= 1:
            r = tuple(w0[k] + s * u[k] - t * v[k] for k in range(3))
            return Fraction(_dot(r, r))
    return min(
        _point_segment_distance2(p0, q0, q1),
        _point_segment_distance2(p1, q0, q1),
        _point_segment_distance2(q0, p0, p1),
        _point_segment_distance2(q1, p0, p1),
    )


def _direction(angle: int | float) -> tuple[Fraction, Fraction]:
    """(cos a, sin a): exact for a multiple of 90 degrees, else float64 values taken as exact."""
    a = exact(angle)
    if a % 90 == 0:
        return [
            (Fraction(1), Fraction(0)),
            (Fraction(0), Fraction(1)),
            (Fraction(-1), Fraction(0)),
            (Fraction(0), Fraction(-1)),
        ][int(a // 90) % 4]
    r = math.radians(float(angle))
    return Fraction(math.cos(r)), Fraction(math.sin(r))


# --- the twin -----------------------------------------------------------------------------


class RefTwin:
    """The exact reference: one machine, its warps, and the instructions run one at a time."""

    def __init__(
        self, machine: Machine, fill: Sequence[tuple[int, int]], diameter: float | int
    ) -> None:
        self.machine = machine
        self.pitch_x = exact(machine.pitch_x)
        self.pitch_y = exact(machine.pitch_y)
        self.d_mat = exact(machine.d_mat)
        self.c_mat = exact(machine.c_mat)
        self.diameter = exact(diameter)
        if self.diameter < 0:
            raise ValueError("yarn diameter must not be negative")
        if self.diameter != 0 and self.diameter >= self.c_mat * min(self.pitch_x, self.pitch_y):
            raise ValueError("yarns of this diameter overlap where they start at the fell")
        self.origin = (
            Fraction(machine.cols - 1, 2) * self.pitch_x,
            Fraction(machine.rows - 1, 2) * self.pitch_y,
        )
        self.nodes: list[Point] = []
        self.yarns: list[list[int]] = []
        self.contacts: list[tuple[int, int, int, int, int]] = []
        self.takeup = Fraction(0)
        self.done = 0
        self.cell_of: dict[int, tuple[int, int]] = {}  # warp yarn id -> its case's cell
        self.case_at: dict[tuple[int, int], int] = {}  # cell -> warp yarn id
        # Every guide must be on the model's grid range.
        self._guide(machine.rows - 1, machine.cols - 1)
        for r, c in fill:
            if not (0 <= r < machine.rows and 0 <= c < machine.cols):
                raise ValueError(f"fill cell ({r}, {c}) is outside the matrix")
            if (r, c) in self.case_at:
                raise ValueError(f"fill cell ({r}, {c}) is filled twice")
            guide = self._guide(r, c)
            fell = (
                round_grid(
                    self.origin[0] + self.c_mat * (Fraction(guide[0], SCALE) - self.origin[0])
                ),
                round_grid(
                    self.origin[1] + self.c_mat * (Fraction(guide[1], SCALE) - self.origin[1])
                ),
                round_grid(self.takeup),
            )
            yarn = len(self.yarns)
            self.yarns.append([self._new_node(fell), self._new_node(guide)])
            self.cell_of[yarn] = (r, c)
            self.case_at[(r, c)] = yarn
        self.warps = len(self.yarns)

    # -- helpers

    def _guide_z(self) -> int:
        return round_grid(self.d_mat + self.takeup)

    def _guide(self, r: int, c: int) -> Point:
        return round_grid(c * self.pitch_x), round_grid(r * self.pitch_y), self._guide_z()

    def _new_node(self, p: Point) -> int:
        self.nodes.append(p)
        return len(self.nodes) - 1

    def mm(self, node: int) -> tuple[float, float, float]:
        """Coordinates of a node in mm (exact floats: every grid value is a float64)."""
        x, y, z = self.nodes[node]
        return math.ldexp(x, -32), math.ldexp(y, -32), math.ldexp(z, -32)

    def _state(self) -> _State:
        return (
            list(self.nodes),
            [list(y) for y in self.yarns],
            list(self.contacts),
            self.takeup,
            dict(self.cell_of),
            dict(self.case_at),
        )

    def _restore(self, state: _State) -> None:
        (
            self.nodes,
            self.yarns,
            self.contacts,
            self.takeup,
            self.cell_of,
            self.case_at,
        ) = state

    # -- instructions

    def run(self, instruction: Shift | TakeUp | Weft) -> None:
        """Run one instruction; on any error the reference is left exactly as it was."""
        index = self.done + 1
        saved = self._state()
        try:
            if isinstance(instruction, Shift):
                self._shift(instruction, index)
            elif isinstance(instruction, TakeUp):
                self._take_up(instruction, index)
            elif isinstance(instruction, Weft):
                self._weft(instruction)
            else:
                raise TypeError(f"not an instruction: {instruction!r}")
        except BaseException:
            self._restore(saved)
            raise
        self.done = index

    def _shift(self, shift: Shift, index: int) -> None:
        rows, cols = self.machine.rows, self.machine.cols
        if shift.axis not in ("row", "col"):
            raise MoveRefused(f"unknown axis {shift.axis!r}")
        # Resolve every move first, on a copy of the occupancy.
        occupied = dict(self.case_at)
        moves: list[tuple[int, tuple[int, int], tuple[int, int]]] = []
        for line, k, span in shift.moves:
            size = rows if shift.axis == "row" else cols
            if not 0 <= line < size:
                raise MoveRefused(f"{shift.axis} {line} is outside the matrix")
            if span is not None and self.machine.segment(shift.axis, line, span) is None:
                raise MoveRefused(f"{shift.axis} {line}{list(span)} is not a declared segment")
            lo, hi = span if span is not None else (0, (cols if shift.axis == "row" else rows) - 1)
            along = 1 if shift.axis == "row" else 0  # the coordinate that changes
            cells = sorted(
                (cell for cell in occupied if cell[1 - along] == line and lo <= cell[along] <= hi),
                key=lambda c: c[along],
            )
            if k > 0:
                cells.reverse()  # the leading case first
            for cell in cells:
                r, c = cell
                target = (r, c + k) if shift.axis == "row" else (r + k, c)
                if not (0 <= target[0] < rows and 0 <= target[1] < cols):
                    raise MoveRefused(
                        f"{shift.axis} {line}:{k:+d}: the case in cell {cell} would leave "
                        "the matrix"
                    )
                if not lo <= target[along] <= hi:
                    raise MoveRefused(
                        f"{shift.axis} {line}:{k:+d}: the case in cell {cell} would leave "
                        "its segment"
                    )
                yarn = occupied.pop(cell)
                if target in occupied:  # unreachable with the leading case first; kept as a guard
                    raise MoveRefused(
                        f"{shift.axis} {line}:{k:+d}: the case in cell {cell} would land on the "
                        f"occupied cell {target}"
                    )
                occupied[target] = yarn
                moves.append((yarn, cell, target))
        for yarn, cell, target in moves:
            del self.case_at[cell]
            self.case_at[target] = yarn
            self.cell_of[yarn] = target
            self._sweep(yarn, self._guide(*target), index)

    def _take_up(self, take_up: TakeUp, index: int) -> None:
        self.takeup += exact(take_up.length)
        z = self._guide_z()
        for yarn in range(self.warps):
            x, y, _ = self.nodes[self.yarns[yarn][-1]]
            self._sweep(yarn, (x, y, z), index)

    def _weft(self, weft: Weft) -> None:
        cx, cy = exact(weft.x), exact(weft.y)
        cz = self.takeup + exact(weft.z)
        half = exact(weft.length) / 2
        cos, sin = _direction(weft.angle)
        start = (round_grid(cx - half * cos), round_grid(cy - half * sin), round_grid(cz))
        end = (round_grid(cx + half * cos), round_grid(cy + half * sin), round_grid(cz))
        dd = self.diameter * SCALE
        limit = dd * dd
        lo = tuple(min(start[k], end[k]) for k in range(3))
        hi = tuple(max(start[k], end[k]) for k in range(3))
        for yarn, ids in enumerate(self.yarns):
            near = []  # segments whose box is within dd of the weft's along every axis: a
            for i in range(len(ids) - 1):  # gap of dd or more along one is a distance of as much
                c, d = self.nodes[ids[i]], self.nodes[ids[i + 1]]
                if all(
                    min(c[k], d[k]) - hi[k] < dd and lo[k] - max(c[k], d[k]) < dd for k in range(3)
                ):
                    near.append(segment_distance2(start, end, c, d))
            best = min(near, default=limit)
            if best < limit:
                distance = math.sqrt(best) / SCALE
                raise ShedClosed(
                    f"shed closed: the weft would pass {distance:.12g} mm from yarn {yarn}, "
                    f"closer than the yarn diameter {float(self.diameter):g} mm"
                )
        ids = [self._new_node(start), self._new_node(end)]
        self.yarns.append(ids)

    # -- the sweep

    def _first_contact(
        self, moving: int, b: Point, a1: Point, a2: Point, skip: tuple[int, int]
    ) -> tuple[Fraction, FPoint, int, int] | None:
        """The first contact of triangle (B, A1, A2): (t, P, hit yarn, segment index) or None."""
        lx, ly, lz = (min(b[k], a1[k], a2[k]) for k in range(3))
        hx, hy, hz = (max(b[k], a1[k], a2[k]) for k in range(3))
        best: tuple[Fraction, FPoint, int, int] | None = None
        for yarn, ids in enumerate(self.yarns):
            if yarn == moving:
                continue
            for i in range(len(ids) - 1):
                if yarn == skip[0] and skip[1] in (ids[i], ids[i + 1]):
                    continue
                c, d = self.nodes[ids[i]], self.nodes[ids[i + 1]]
                if (
                    (c[0] < lx and d[0] < lx)
                    or (c[0] > hx and d[0] > hx)
                    or (c[1] < ly and d[1] < ly)
                    or (c[1] > hy and d[1] > hy)
                    or (c[2] < lz and d[2] < lz)
                    or (c[2] > hz and d[2] > hz)
                ):
                    continue  # boxes apart: P would lie in both
                hit = crossing(b, a1, a2, c, d)
                if hit is not None and (best is None or hit[0] < best[0]):
                    best = (hit[0], hit[1], yarn, i)
        return best

    def _sweep(self, moving: int, a2: Point, index: int) -> None:
        """Sweep the free node of warp ``moving`` from where it is to A2, recording contacts."""
        ids = self.yarns[moving]
        free = ids[-1]
        a1 = self.nodes[free]
        b = self.nodes[ids[-2]]
        skip = (-1, -1)  # (hit yarn, Y node): segments of that yarn ending at Y are skipped
        for _ in range(MAX_CONTACTS_PER_SWEEP):
            hit = self._first_contact(moving, b, a1, a2, skip)
            if hit is None:
                self.nodes[free] = a2
                return
            t, p, yarn, i = hit
            hit_ids = self.yarns[yarn]
            c, d = self.nodes[hit_ids[i]], self.nodes[hit_ids[i + 1]]
            y = (_round_units(p[0]), _round_units(p[1]), _round_units(p[2]))
            x = rest_point(y, _sub(a2, a1), _sub(d, c), self.diameter)
            top = max(y[2], x[2])
            if top >= self._guide_z() - self.diameter * SCALE:
                raise Jam(moving, yarn, top)
            y_id = self._new_node(y)
            hit_ids.insert(i + 1, y_id)
            x_id = self._new_node(x)
            ids.insert(len(ids) - 1, x_id)
            self.contacts.append((index, moving, x_id, yarn, y_id))
            skip = (yarn, y_id)
            b = x
            a1 = restart_point(a1, a2, t)
        raise RuntimeError(
            f"instruction {index}: more than {MAX_CONTACTS_PER_SWEEP} contacts in one sweep"
        )
