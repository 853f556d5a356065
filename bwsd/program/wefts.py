"""Wefts near the fell: each at the lowest height where its shed is open, by the twin.

A generator describes a weft by its line in the matrix (``WeftLine``: a centre and a length
in guide coordinates, and an angle). Between the fell and the guides the warps fan out
from ``c_mat`` of the matrix's size to all of it, so at height z above the fell the line is
that of the matrix scaled about the convergence point by ``fan(z)``. ``Placer`` runs the
program being generated on a twin and puts each weft at the lowest height of a grid of
half a yarn diameter where the twin's exact shed check lets it in: the woven or braided
section forms at the fell's scale, as on a loom (docs/program.md, "Where the wefts go").
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from bwsd.errors import JamError, ShedClosedError
from bwsd.program import render
from bwsd.program.render import num
from bwsd.twin import Program, Twin
from bwsd.twin.instructions import Instruction, Shift, TakeUp, Weft
from bwsd.twin.machine import Machine
from bwsd.twin.skeleton import FloatArray

Cell = tuple[int, int]

GRID = 0.5  # heights tried: multiples of this many yarn diameters above the fell
GRID_CENTRELINE = 0.05  # ... of this many pitches when the yarns have no diameter


@dataclass(frozen=True)
class Shed:
    """Where a weft goes: between the warps of one side and those of the other (their cells
    once the shed is open), at ``angle`` degrees; ``name`` says which weft it is."""

    angle: float
    one: tuple[Cell, ...]
    other: tuple[Cell, ...]
    name: str


def fan(machine: Machine, z: float) -> float:
    """The warps' spread at height ``z`` above the fell, as a fraction of the matrix's:
    ``c_mat`` at the fell, 1 at the guides."""
    return machine.c_mat + (1 - machine.c_mat) * z / machine.d_mat


def _grid(value: float) -> float:
    """A coordinate written with at most 4 decimals (a program's numbers stay readable)."""
    return float(num(round(value, 4)))


def heights(machine: Machine) -> list[float]:
    """The heights tried, lowest first, up to one yarn diameter below the guides (a contact
    any closer would jam)."""
    step = GRID * machine.yarn_diameter or GRID_CENTRELINE * min(machine.pitch_x, machine.pitch_y)
    count = int(machine.d_mat / step)
    found = (round(step * j, 6) for j in range(1, count))
    return [z for z in found if z < machine.d_mat - machine.yarn_diameter]


class Placer:
    """A twin that follows the program as it is generated and places its wefts."""

    def __init__(self, machine: Machine, fill: tuple[tuple[int, int], ...]) -> None:
        self.machine = machine
        self.twin = Twin.from_program(machine, Program(machine.yarn_diameter, fill, ()))
        self.heights = heights(machine)

    def run(self, instruction: Instruction) -> None:
        """Apply a shift or take-up the program makes."""
        self.twin.apply(instruction)

    def place(self, shed: Shed, closing: Sequence[Instruction], above: float = 0.0) -> Weft:
        """Insert the weft of ``shed`` at the lowest height where it is open and caught: the
        twin's exact shed check lets it in, and the moves ``closing`` (those that follow it
        in its cycle) make a contact with it; a weft below the warps' last
        contacts would stay loose. It lies on the warps' cone (where they would run without
        contacts) if it can, else through the middle of the shed. ValueError if no height
        below the guides will do. Only heights over ``above`` are tried."""
        lowest = max(self.lowest_fixed(shed), above + 1e-9)
        for z in self.heights:
            if z < lowest:
                continue  # below every warp's last fixed node: no move can catch it
            for weft in self.candidates(shed, z):
                if self._inserted(weft, closing):
                    return weft
        raise ValueError(
            f"{shed.name}: no height between the fell and the guides where the "
            "shed is open and its closing catches the weft (raise the take-up or "
            "the pitch)"
        )

    def lowest_fixed(self, shed: Shed) -> float:
        """The lowest last fixed node of the shed's warps, above the fell: a move that closes
        the shed sweeps them across the weft, each in a triangle from that node up."""
        one, other = self._free_segments(shed)
        return float(min(one[:, 0, 2].min(), other[:, 0, 2].min())) - self.twin.takeup

    def candidates(self, shed: Shed, z: float) -> list[Weft]:
        """The wefts tried at height ``z``: on the warps' cone, then through the shed's
        middle."""
        cone = (self._guides(shed.one), self._guides(shed.other))
        return [self._weft(shed, ends, z) for ends in (cone, self._free_segments(shed))]

    def loose(self, yarns: Sequence[int], closing: Sequence[Instruction]) -> list[int]:
        """Those of ``yarns`` that none of the moves ``closing`` touches; the twin is left as
        it was."""
        before = self.twin.snapshot()
        left = set(yarns)
        for move in closing:
            table = self.twin.apply(move).contact_table
            left -= set(table[:, 1].tolist()) | set(table[:, 3].tolist())
            if not left:
                break
        self.twin.restore(before)
        return sorted(left)

    def would_catch(self, weft: Weft, closing: Sequence[Instruction]) -> bool:
        """Whether ``weft`` passes the shed check and one of ``closing`` catches it; the
        twin is left as it was."""
        before = self.twin.snapshot()
        caught = self._inserted(weft, closing)
        self.twin.restore(before)
        return caught

    def insert(self, weft: Weft) -> int | None:
        """Insert ``weft`` and give its yarn id, or None (and nothing inserted) where the
        shed is closed."""
        try:
            inserted = self.twin.predict(weft)
        except ShedClosedError:
            return None
        self.twin.commit(inserted)
        return inserted.new_yarns[0]

    def _inserted(self, weft: Weft, closing: Sequence[Instruction]) -> bool:
        """Insert ``weft`` if the shed lets it in and one of ``closing`` catches it."""
        try:
            inserted = self.twin.predict(weft)
        except (ShedClosedError, JamError):
            return False
        before = self.twin.snapshot()
        self.twin.commit(inserted)
        yarn = inserted.new_yarns[0]
        after = self.twin.snapshot()
        for move in closing:
            try:
                moved = self.twin.predict(move)
            except JamError:
                break
            table = moved.contact_table
            if ((table[:, 1] == yarn) | (table[:, 3] == yarn)).any():
                self.twin.restore(after)
                return True
            self.twin.commit(moved)
        self.twin.restore(before)
        return False

    def _guides(self, cells: tuple[Cell, ...]) -> FloatArray:
        """The cone of the warps of ``cells`` as (fell point, guide) pairs: where they would
        run without contacts, scaled about the convergence point from c_mat to 1."""
        m = self.machine
        top = m.d_mat + self.twin.takeup
        pairs = [[(*m.fell_xy(r, c), self.twin.takeup), (*m.guide_xy(r, c), top)] for r, c in cells]
        return np.asarray(pairs, dtype=np.float64).reshape(-1, 2, 3)

    def _free_segments(self, shed: Shed) -> tuple[FloatArray, FloatArray]:
        """Each side's warps: their last fixed node and their guide, (n, 2, 3) each."""
        occupancy = self.twin.occupancy
        sides = []
        for cells in (shed.one, shed.other):
            ends = []
            for r, c in cells:
                warp = int(occupancy[r, c])
                if warp < 0:
                    raise ValueError(f"{shed.name}: no case in cell ({r}, {c})")
                ends.append(self.twin.yarn(warp).nodes[-2:])
            sides.append(np.asarray(ends, dtype=np.float64).reshape(-1, 2, 3))
        return sides[0], sides[1]

    def _weft(self, shed: Shed, free: tuple[FloatArray, FloatArray], z: float) -> Weft:
        """The weft at height ``z`` above the fell: on the line at its angle halfway between
        the two sides' warps at that height, one warp spacing past the last warp each way."""
        level = self.twin.takeup + z
        u = np.array([math.cos(math.radians(shed.angle)), math.sin(math.radians(shed.angle))])
        n = np.array([-u[1], u[0]])
        below, above = (_at(side, level) for side in free)
        if (below @ n).mean() > (above @ n).mean():
            below, above = above, below
        offset = (float((below @ n).max()) + float((above @ n).min())) / 2
        along = np.concatenate([below @ u, above @ u])
        margin = fan(self.machine, z) * min(self.machine.pitch_x, self.machine.pitch_y)
        lo, hi = float(along.min()) - margin, float(along.max()) + margin
        centre = offset * n + (lo + hi) / 2 * u
        return Weft(_grid(centre[0]), _grid(centre[1]), z, shed.angle, _grid(hi - lo))


def _at(ends: FloatArray, level: float) -> FloatArray:
    """Where each segment (fixed node, guide) passes the height ``level``, (n, 2); a warp
    whose fixed node lies above it counts at that node."""
    b, g = ends[:, 0], ends[:, 1]
    t = np.clip((level - b[:, 2]) / np.maximum(g[:, 2] - b[:, 2], 1e-12), 0.0, 1.0)
    out: FloatArray = b[:, :2] + t[:, None] * (g[:, :2] - b[:, :2])
    return out


Item = Instruction | Shed  # a move, or a weft to place


Cycle = list[Item]


Pick = list[tuple[int, Shed]]  # the wefts of one pick, with their places in the cycle
PlacePick = Callable[[Placer, Pick, Sequence[Instruction]], list[str]]


def woven(
    machine: Machine,
    fill: tuple[tuple[int, int], ...],
    cycles: Sequence[Cycle | Sequence[Cycle]],
    comment: str,
    place: PlacePick | None = None,
    unit: str = "cycle",
) -> list[str]:
    """The program lines of ``cycles`` (their moves and wefts), each pick's wefts placed on
    the twin by ``place`` (default: each weft at its own lowest open height); identical
    consecutive cycles share one REPEAT. Errors name a cycle as ``unit`` and its number.

    A cycle may be given as alternatives (a sequence of cycles): the first one whose every
    weft can be placed is used; when none can, the error of the first is raised.
    """
    placer = Placer(machine, fill)
    bodies = []
    for n, given in enumerate(cycles, start=1):
        options = [given] if given and not isinstance(given[0], list) else given
        bodies.append(
            _first_that_places(
                placer,
                f"{unit} {n}",
                options,  # type: ignore[arg-type]
                place or _place_pick,
            )
        )
    lines: list[str] = []
    for count, body in group_cycles(bodies):
        lines += render.repeat(count, body, comment)
    return lines


def _first_that_places(
    placer: Placer, n: str, options: Sequence[Cycle], place: PlacePick
) -> list[str]:
    start = placer.twin.snapshot()
    failure: ValueError | None = None
    for cycle in options:
        try:
            return _place_cycle(placer, n, cycle, place)
        except ValueError as exc:
            failure = failure or exc
            placer.twin.restore(start)
    assert failure is not None
    raise failure


def _place_cycle(placer: Placer, n: str, cycle: Cycle, place: PlacePick) -> list[str]:
    """The cycle's lines, its wefts placed, pick by pick (a run of wefts between moves); a
    move that jams refuses the cycle (ValueError)."""
    closing = _closing(cycle)
    body: list[str] = []
    i = 0
    while i < len(cycle):
        item = cycle[i]
        if not isinstance(item, Shed):
            try:
                placer.run(item)
            except JamError as exc:
                raise ValueError(f"{n}: {exc}") from None
            body.append(item.text() if isinstance(item, Shift) else text(item))
            i += 1
            continue
        end = next((j for j in range(i, len(cycle)) if not isinstance(cycle[j], Shed)), len(cycle))
        pick = [
            (j, replace(s, name=f"{n}, {s.name}"))
            for j, s in enumerate(cycle[i:end], i)
            if isinstance(s, Shed)
        ]
        body += place(placer, pick, closing[end - 1])
        i = end
    return body


def _place_pick(placer: Placer, pick: Pick, closing: Sequence[Instruction]) -> list[str]:
    """Place a pick's wefts one after the other; then the moves that close the shed must catch
    each of them. A weft a later one shields from those moves goes in again, higher, with
    the rest of its pick."""
    start = placer.twin.snapshot()
    above: dict[int, float] = {}
    while True:
        placed = []
        for j, shed in pick:
            yarn = placer.twin.yarn_count
            placed.append((j, yarn, placer.place(shed, closing, above.get(j, 0.0))))
        loose = placer.loose([yarn for _, yarn, _ in placed], closing)
        if not loose:
            return [render.weft(w.x, w.y, w.z, w.angle, w.length) for _, _, w in placed]
        j, _, weft = next(p for p in placed if p[1] == loose[0])
        above[j] = weft.z
        placer.twin.restore(start)


def _closing(cycle: list[Item]) -> dict[int, list[Instruction]]:
    """For each weft of the cycle, the moves after it up to the next weft of another pick
    (or the end of the cycle): one of them must catch it, before anything else comes in."""
    found: dict[int, list[Instruction]] = {}
    for i, item in enumerate(cycle):
        if isinstance(item, Shed):
            moves: list[Instruction] = []
            for later in cycle[i + 1 :]:
                if isinstance(later, Shed):
                    if moves:
                        break
                    continue  # the rest of its own pick
                moves.append(later)
            found[i] = moves
    return found


def text(instruction: Instruction) -> str:
    """A take-up or weft as a program line."""
    if isinstance(instruction, TakeUp):
        return f"TAKEUP {num(instruction.length)}"
    assert isinstance(instruction, Weft)
    w = instruction
    return render.weft(w.x, w.y, w.z, w.angle, w.length)


def group_cycles(cycles: list[list[str]]) -> list[tuple[int, list[str]]]:
    """Runs of identical consecutive cycles, as (count, body): one REPEAT each."""
    runs: list[tuple[int, list[str]]] = []
    for body in cycles:
        if runs and runs[-1][1] == body:
            runs[-1] = (runs[-1][0] + 1, body)
        else:
            runs.append((1, body))
    return runs
