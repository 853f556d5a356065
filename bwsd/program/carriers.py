"""Carriers on the cell grid: a braid rule's steps run without geometry, and checked (pure).

A braid rule is one machine cycle of ROW and COL steps (``Shift``, with segment spans where
a line moves over part of its length only) and the carriers' start cells. ``check_rule``
runs it on the cell grid exactly as the machine and the twin do (entries in order, the
leading case first; a span's cases stay on it) and says whether it can be braided and
whether the yarns form one preform:

- **legal**: no case leaves the matrix or its segment, or lands on another; every case
  stays on the rule's track cells; after every step the section's cells are all full;
- **periodic**: one cycle brings every cell's occupancy back, and the carriers' permutation
  has period P (cycles until each carrier is back where it started);
- **mixed**: every orbit of that permutation passes through every required zone of the
  section (intermediate steps count), so no carrier is walled into a part of it;
- **K**: the cycles from the start until every carrier has sat on a cell of every
  required zone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from bwsd.program.sections import Cell, Section
from bwsd.twin.instructions import Shift
from bwsd.twin.machine import Segment

MAX_K_CYCLES = 5000  # K is searched up to this many cycles


class Illegal(Exception):
    """A step the machine could not make, or that leaves the section part empty."""


@dataclass(frozen=True)
class Rule:
    """One cycle of a braid: its steps, start cells, track and the segments it needs."""

    name: str
    steps: tuple[Shift, ...]
    carriers: tuple[Cell, ...]
    track: frozenset[Cell]
    segments: tuple[Segment, ...] = ()

    @property
    def partial(self) -> bool:
        """True when a step moves a line over part of its length (a segment)."""
        return any(m.span is not None for step in self.steps for m in step.moves)


@dataclass(frozen=True)
class RuleCheck:
    """What ``check_rule`` found; ``reason`` says why a rule fails, else ``"ok"``."""

    legal: bool
    periodic: bool
    reason: str
    period: int = 0
    orbits: int = 0
    mixed_orbits: int = 0
    k: int | None = None

    @property
    def mixed(self) -> bool:
        """Legal, periodic, and every orbit meets every required zone."""
        return self.legal and self.periodic and self.orbits > 0 and self.mixed_orbits == self.orbits


def step(cells: list[Cell], shift: Shift, rows: int, cols: int) -> list[Cell]:
    """The carriers' cells after ``shift`` (carrier i at ``cells[i]``); Illegal if it cannot
    be made: a case leaving the matrix or its segment, or landing on another."""
    at = {cell: i for i, cell in enumerate(cells)}
    out = list(cells)
    row = shift.axis == "row"
    along = cols if row else rows
    for line, k, span in shift.moves:
        lo, hi = span if span is not None else (0, along - 1)
        order = range(hi, lo - 1, -1) if k > 0 else range(lo, hi + 1)
        for pos in order:
            src = (line, pos) if row else (pos, line)
            i = at.pop(src, None)
            if i is None:
                continue
            dst = (line, pos + k) if row else (pos + k, line)
            if not lo <= pos + k <= hi:
                raise Illegal(
                    f"{shift.text()}: the case in {src} would leave "
                    f"{'its segment' if span else 'the matrix'}"
                )
            if dst in at:
                raise Illegal(f"{shift.text()}: the case in {src} would land on {dst}")
            at[dst] = i
            out[i] = dst
    return out


def _visit(visits: list[set[str]], cells: Sequence[Cell], section: Section) -> None:
    for i, cell in enumerate(cells):
        zone = section.zone_of(cell)
        if zone is not None:
            visits[i].add(zone)


def _cycle(
    cells: list[Cell], rule: Rule, section: Section, size: tuple[int, int], visits: list[set[str]]
) -> list[Cell]:
    body = section.cells
    for shift in rule.steps:
        cells = step(cells, shift, *size)
        off = [c for c in cells if c not in rule.track]
        if off:
            raise Illegal(f"{shift.text()}: a case leaves the track, to {off[0]}")
        empty = body - set(cells)
        if empty:
            raise Illegal(f"{shift.text()}: leaves section cell {min(empty)} empty")
        _visit(visits, cells, section)
    return cells


def check_rule(section: Section, rule: Rule, size: tuple[int, int] | None = None) -> RuleCheck:
    """Run one cycle of ``rule`` on ``section`` (in a matrix of ``size``, default the
    section's) and check it; K is searched when every orbit is mixed."""
    size = size or section.size
    start = list(rule.carriers)
    if len(set(start)) != len(start) or not section.cells <= set(start):
        return RuleCheck(False, False, "the carriers do not fill the section, one to a cell")
    need = set(section.required)
    visits: list[set[str]] = [set() for _ in start]
    _visit(visits, start, section)
    try:
        after = _cycle(list(start), rule, section, size, visits)
    except Illegal as exc:
        return RuleCheck(False, False, str(exc))
    if set(after) != set(start):
        return RuleCheck(True, False, "one cycle does not bring the occupancy back")
    index = {cell: i for i, cell in enumerate(start)}
    perm = [index[cell] for cell in after]
    orbits = _orbits(perm)
    period = math.lcm(*(len(o) for o in orbits))
    mixed = sum(1 for o in orbits if need <= set().union(*(visits[i] for i in o)))
    k = _k(after, rule, section, size, visits, need) if mixed == len(orbits) else None
    return RuleCheck(True, True, "ok", period, len(orbits), mixed, k)


def _orbits(perm: list[int]) -> list[list[int]]:
    seen = [False] * len(perm)
    found = []
    for i in range(len(perm)):
        orbit = []
        j = i
        while not seen[j]:
            seen[j] = True
            orbit.append(j)
            j = perm[j]
        if orbit:
            found.append(orbit)
    return found


def _k(
    cells: list[Cell],
    rule: Rule,
    section: Section,
    size: tuple[int, int],
    visits: list[set[str]],
    need: set[str],
) -> int | None:
    cycles = 1
    while not all(need <= v for v in visits):
        if cycles >= MAX_K_CYCLES:
            return None
        cells = _cycle(cells, rule, section, size, visits)
        cycles += 1
    return cycles
