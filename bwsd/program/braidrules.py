"""4-step braid rules for rectangular and shaped (L, T, I) sections (pure).

A rectangle braids by the plain 4-step: every row, then every column, then both back, each
line opposite to its neighbours, one edge carrier per line. A shaped section cannot: the
cell diagonal to each inner corner (its *corner cell*) is an end cell of a row run and of
a column run, which a plain cycle needs at the same time, and holding one of those lines
walls the section into zones that never exchange carriers (docs/program.md, "Shaped
sections"). Two families of rules mix every carrier through every zone:

- **corner-multiplexed** (``multiplexed``): every line does the plain 4-step in each of N
  sub-cycles, except the *corner lines* (the row and column runs ending on a corner cell),
  which shift only at some steps of the 4N-step cycle, taking turns at the corner cell, and
  only over their own run and its two end cells: a segment of the line with an actuator of
  its own. 8 steps for an L, 12 for a T or an I.
- **whole-line** (``whole_line``): whole lines only, 8 steps; lines are grouped by role
  (through a junction, corner, arm rows and columns by index parity) and each group shifts
  at some of the steps. Rules exist for L and T sections; none is known for an I.

Whether a schedule mixes depends on the section's size, so every rule is checked for the
size asked (``carriers.check_rule``) and only a mixed one is used. The schedules tried
first (``PARTIAL`` and ``WHOLE``) were found by search and each mixes on several sizes.
"""

from __future__ import annotations

import itertools
from collections import defaultdict
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

from bwsd.program.carriers import MAX_K_CYCLES, Rule, RuleCheck, check_rule
from bwsd.program.sections import Cell, Section, shaped
from bwsd.twin.instructions import Move, Shift
from bwsd.twin.machine import Segment

Runs = dict[int, list[tuple[int, int]]]
Pattern = tuple[int, ...]  # per row step (or column step) of the cycle: 1 = the line shifts


def runs(section: Section, axis: int) -> Runs:
    """Each row's (axis 0) or column's (axis 1) runs of section cells, as (first, last)."""
    members: dict[int, list[int]] = defaultdict(list)
    for cell in section.cells:
        members[cell[axis]].append(cell[1 - axis])
    found: Runs = {}
    for line, values in members.items():
        values.sort()
        spans: list[tuple[int, int]] = []
        for v in values:
            if spans and v == spans[-1][1] + 1:
                spans[-1] = (spans[-1][0], v)
            else:
                spans.append((v, v))
        found[line] = spans
    return found


def corner_cells(section: Section) -> set[Cell]:
    """Cells outside the section at an end of both a row run and a column run."""
    ends_r = {(r, e) for r, rs in runs(section, 0).items() for a, b in rs for e in (a - 1, b + 1)}
    ends_c = {(e, c) for c, cs in runs(section, 1).items() for a, b in cs for e in (a - 1, b + 1)}
    return (ends_r & ends_c) - section.cells


def parity(line: int) -> int:
    """The plain 4-step's first move of a line: +1 on odd lines, -1 on even ones."""
    return 1 if line % 2 else -1


class _Builder:
    """Steps, start cells and track of a rule being put together."""

    def __init__(self, section: Section, steps: int) -> None:
        self.section = section
        self.steps: list[list[Move]] = [[] for _ in range(steps)]
        self.edges: list[Cell] = []
        self.track: set[Cell] = set(section.cells)
        self.segments: list[Segment] = []

    def line(
        self,
        axis: int,
        line: int,
        spans: list[tuple[int, int]],
        first: int,
        pattern: Pattern,
        partial: bool = False,
    ) -> None:
        """A line (or its one run, ``partial``) that shifts at the steps of ``pattern``,
        first by ``first``, alternating; one edge carrier per run."""
        if not any(pattern):
            return  # a held line: no edge carrier, no move
        for a, b in spans:
            ends = [(line, a - 1), (line, b + 1)] if axis == 0 else [(a - 1, line), (b + 1, line)]
            self.track.update(ends)
            self.edges.append(ends[0] if first > 0 else ends[1])
        span = (spans[0][0] - 1, spans[0][1] + 1) if partial else None
        if partial:
            self.segments.append(Segment("row" if axis == 0 else "col", line, *span))  # type: ignore[misc]
        k = first
        for j, flips in enumerate(pattern):
            if flips:
                self.steps[2 * j + axis].append(Move(line, k, span))
                k = -k

    def rule(self, name: str) -> Rule | None:
        if len(set(self.edges)) != len(self.edges):
            return None  # two runs want one edge cell
        steps = tuple(
            Shift("row" if i % 2 == 0 else "col", tuple(sorted(moves)))
            for i, moves in enumerate(self.steps)
            if moves
        )
        carriers = tuple(sorted(self.section.cells)) + tuple(self.edges)
        return Rule(name, steps, carriers, frozenset(self.track), tuple(sorted(self.segments)))


def plain(section: Section) -> Rule:
    """The plain 4-step over every line (a rectangle's rule)."""
    b = _Builder(section, 4)
    for axis in (0, 1):
        for line, spans in sorted(runs(section, axis).items()):
            b.line(axis, line, spans, parity(line), (1, 1))
    rule = b.rule("plain 4-step")
    assert rule is not None, "a section whose runs share an edge cell"
    return rule


@dataclass(frozen=True)
class Corners:
    """A section's corner lines: rows with a run ending on a corner cell (one run each),
    and column runs ending on one, keyed (column, first row); each sorted."""

    rows: list[int]
    cols: list[tuple[int, int]]


def corners(section: Section) -> Corners:
    found = corner_cells(section)
    rows = sorted(
        r
        for r, rs in runs(section, 0).items()
        if any((r, a - 1) in found or (r, b + 1) in found for a, b in rs)
    )
    cols = sorted(
        (c, a)
        for c, cs in runs(section, 1).items()
        for a, b in cs
        if (a - 1, c) in found or (b + 1, c) in found
    )
    return Corners(rows, cols)


def multiplexed(
    section: Section,
    n: int,
    rows: list[tuple[Pattern, int]],
    cols: list[tuple[Pattern, int]],
    axis: tuple[int, int],
) -> Rule | None:
    """The corner-multiplexed 4n-step rule: ``rows`` and ``cols`` give each corner row and
    corner column run (in ``corners`` order) its pattern over the 2n row (column) steps and
    its first move; the others do the plain 4-step, first move ``parity * axis``."""
    corner = corners(section)
    row_runs, col_runs = runs(section, 0), runs(section, 1)
    if len(rows) != len(corner.rows) or len(cols) != len(corner.cols):
        return None
    if any(len(row_runs[r]) != 1 for r in corner.rows):
        return None  # a corner row of several runs: not handled
    corner_cols = {c for c, _ in corner.cols}
    b = _Builder(section, 4 * n)
    plain_pattern = (1,) * (2 * n)
    for r, spans in sorted(row_runs.items()):
        if r not in corner.rows:
            b.line(0, r, spans, parity(r) * axis[0], plain_pattern)
    for c, spans in sorted(col_runs.items()):
        if c not in corner_cols:
            b.line(1, c, spans, parity(c) * axis[1], plain_pattern)
        elif any((c, a) not in corner.cols for a, _ in spans):
            return None  # a column of corner and other runs: not handled
    for r, (pattern, first) in zip(corner.rows, rows, strict=True):
        b.line(0, r, row_runs[r], first, pattern, partial=True)
    for (c, a), (pattern, first) in zip(corner.cols, cols, strict=True):
        span = next(s for s in col_runs[c] if s[0] == a)
        b.line(1, c, [span], first, pattern, partial=True)
    return b.rule(f"{4 * n}-step, corner lines on segments")


def roles(section: Section) -> tuple[dict[int, tuple[str, int]], dict[int, tuple[str, int]]]:
    """Each row's and column's role for whole-line rules: ``("long", 0)`` through a junction,
    ``("corner", rank)`` with a run ending on a corner cell, else ``("arm", index % 2)``."""
    junction = frozenset().union(
        *(cells for name, cells in section.zones.items() if "junction" in name)
    )
    corner = corners(section)
    corner_cols = sorted({c for c, _ in corner.cols})
    out: list[dict[int, tuple[str, int]]] = [{}, {}]
    for axis, ranked in ((0, corner.rows), (1, corner_cols)):
        for line, spans in runs(section, axis).items():
            cells = {
                (line, x) if axis == 0 else (x, line) for a, b in spans for x in range(a, b + 1)
            }
            if cells & junction:
                out[axis][line] = ("long", 0)
            elif line in ranked:
                out[axis][line] = ("corner", ranked.index(line))
            else:
                out[axis][line] = ("arm", line % 2)
    return out[0], out[1]


Groups = Mapping[tuple[str, str, int], tuple[Pattern, int]]  # (ROW|COL, role, i) -> schedule


def whole_line(section: Section, n: int, groups: Groups) -> Rule | None:
    """The whole-line 4n-step rule: each line's group (``roles``) gives its pattern and a
    sign on its first move (``parity * sign``); lines through a junction do the plain
    4-step in every sub-cycle."""
    row_roles, col_roles = roles(section)
    b = _Builder(section, 4 * n)
    for axis, kind, table in ((0, "ROW", row_roles), (1, "COL", col_roles)):
        for line, spans in sorted(runs(section, axis).items()):
            role = table[line]
            if role[0] == "long":
                pattern, sign = (1,) * (2 * n), 1
            else:
                pattern, sign = groups.get((kind, *role), ((0,) * (2 * n), 1))
            b.line(axis, line, spans, parity(line) * sign, pattern)
    return b.rule(f"{4 * n}-step, whole lines")


# Schedules found by search on the cell grid, tried first; each is re-checked for the size
# asked. Corner rows, then corner column runs, in ``corners`` order: (pattern, first move).
P = Pattern
PARTIAL: dict[str, list[tuple[int, list[tuple[P, int]], list[tuple[P, int]], tuple[int, int]]]] = {
    "L": [
        (2, [((1, 1, 0, 0), 1)], [((0, 0, 1, 1), 1)], (1, 1)),
        (2, [((1, 1, 0, 0), 1)], [((0, 0, 1, 1), 1)], (-1, -1)),
    ],
    "T": [
        (3, [((1, 0, 0, 1, 0, 0), 1)], [((0, 1, 1, 0, 0, 0), 1), ((0, 0, 0, 0, 1, 1), 1)], (1, -1)),
        (
            3,
            [((1, 0, 0, 1, 0, 0), 1)],
            [((1, 1, 0, 0, 0, 0), 1), ((0, 0, 0, 0, 1, 1), 1)],
            (-1, -1),
        ),
    ],
    "I": [
        (
            3,
            [((0, 0, 1, 0, 0, 1), -1), ((0, 1, 0, 0, 1, 0), -1)],
            [
                ((1, 0, 0, 0, 0, 1), -1),
                ((0, 0, 0, 0, 1, 1), -1),
                ((0, 0, 0, 1, 1, 0), 1),
                ((0, 0, 1, 1, 0, 0), -1),
            ],
            (-1, -1),
        ),
        (
            3,
            [((0, 0, 1, 0, 0, 1), -1), ((0, 0, 1, 0, 0, 1), -1)],
            [
                ((1, 0, 0, 0, 0, 1), -1),
                ((1, 1, 0, 0, 0, 0), -1),
                ((0, 0, 0, 1, 1, 0), 1),
                ((0, 0, 1, 1, 0, 0), -1),
            ],
            (1, -1),
        ),
    ],
}
WHOLE: dict[str, list[dict[tuple[str, str, int], tuple[P, int]]]] = {
    "L": [
        {
            ("COL", "arm", 0): ((0, 0, 1, 1), 1),
            ("COL", "arm", 1): ((0, 0, 1, 1), 1),
            ("COL", "corner", 0): ((1, 1, 0, 0), 1),
            ("ROW", "arm", 0): ((1, 0, 0, 1), 1),
            ("ROW", "arm", 1): ((1, 0, 0, 1), 1),
            ("ROW", "corner", 0): ((0, 1, 1, 0), -1),
        },
        {
            ("COL", "arm", 0): ((1, 0, 0, 1), 1),
            ("COL", "arm", 1): ((0, 0, 1, 1), 1),
            ("COL", "corner", 0): ((1, 1, 0, 0), 1),
            ("ROW", "arm", 0): ((1, 0, 0, 1), 1),
            ("ROW", "arm", 1): ((1, 0, 0, 1), 1),
            ("ROW", "corner", 0): ((0, 1, 1, 0), -1),
        },
    ],
    "T": [
        {
            ("COL", "arm", 0): ((1, 0, 0, 1), 1),
            ("COL", "arm", 1): ((1, 1, 0, 0), 1),
            ("COL", "corner", 0): ((0, 1, 1, 0), -1),
            ("COL", "corner", 1): ((1, 1, 0, 0), -1),
            ("ROW", "arm", 0): ((1, 0, 0, 1), 1),
            ("ROW", "arm", 1): ((1, 0, 0, 1), 1),
            ("ROW", "corner", 0): ((0, 0, 1, 1), -1),
        },
        {
            ("COL", "arm", 0): ((0, 1, 1, 0), 1),
            ("COL", "arm", 1): ((0, 1, 1, 0), 1),
            ("COL", "corner", 0): ((0, 1, 1, 0), 1),
            ("COL", "corner", 1): ((0, 1, 1, 0), -1),
            ("ROW", "arm", 0): ((1, 0, 0, 1), 1),
            ("ROW", "arm", 1): ((1, 1, 0, 0), 1),
            ("ROW", "corner", 0): ((1, 1, 0, 0), 1),
        },
    ],
}


def _axes() -> Iterator[tuple[int, int]]:
    yield from itertools.product((1, -1), repeat=2)


def _known_partial(section: Section) -> Iterator[Rule | None]:
    """The known corner-multiplexed schedules, each under the four axis signs."""
    for n, rows, cols, _ in PARTIAL.get(section.shape, []):
        for axis in _axes():
            yield multiplexed(section, n, rows, cols, axis)


def _wider_partial(section: Section) -> Iterator[Rule | None]:
    """More corner-multiplexed schedules: corner rows flipping twice a cycle, corner column
    runs into their corner cell and back at two neighbouring steps."""
    corner = corners(section)
    for n in (2, 3):
        row_patterns = [
            tuple(int(j in pair) for j in range(2 * n))
            for pair in itertools.combinations(range(2 * n), 2)
        ]
        col_patterns = [
            tuple(int(j in (i, (i + 1) % (2 * n))) for j in range(2 * n)) for i in range(2 * n)
        ]
        choices = [[(p, s) for p in row_patterns for s in (1, -1)]] * len(corner.rows)
        choices += [[(p, s) for p in col_patterns for s in (1, -1)]] * len(corner.cols)
        for combo in itertools.islice(itertools.product(*choices), SEARCH_LIMIT):
            for axis in _axes():
                yield multiplexed(
                    section,
                    n,
                    list(combo[: len(corner.rows)]),
                    list(combo[len(corner.rows) :]),
                    axis,
                )


SEARCH_LIMIT = 400  # schedules of the wider family tried per cycle length


def _whole_candidates(section: Section) -> Iterator[Rule | None]:
    for groups in WHOLE.get(section.shape, []):
        yield whole_line(section, 2, groups)


def find_rule(section: Section, segments: bool) -> tuple[Rule, RuleCheck] | None:
    """A rule that mixes ``section``: the plain 4-step for a rectangle; for a shaped section
    a corner-multiplexed rule (``segments``: the machine has the corner segments) or a
    whole-line one. None when no rule tried mixes this size."""
    if section.shape == "rect":
        rule = plain(section)
        return rule, check_rule(section, rule)
    known = _known_partial(section) if segments else _whole_candidates(section)
    checked = [(rule, check_rule(section, rule)) for rule in known if rule is not None]
    mixed = [(rule, found) for rule, found in checked if found.mixed]
    if mixed:  # the known schedule that mixes soonest
        return min(
            mixed, key=lambda pair: (pair[1].k or MAX_K_CYCLES, len(pair[0].steps), pair[1].period)
        )
    if not segments:
        return None
    for candidate in _wider_partial(section):
        if candidate is not None and (found := check_rule(section, candidate)).mixed:
            return candidate, found
    return None


def nearby_sizes(section: Section, segments: bool, limit: int = 3) -> list[str]:
    """Up to ``limit`` sections of the same shape, a cell or two bigger or smaller in a
    dimension, that a known rule mixes (nearest first)."""
    if section.shape == "rect":
        return []
    flange, web = _blocks(section)
    found: list[str] = []
    for dims in sorted(_around((*flange, *web)), key=_distance((*flange, *web))):
        try:
            other = shaped(section.shape, (dims[0], dims[1]), (dims[2], dims[3]))
        except ValueError:
            continue
        known = _known_partial(other) if segments else _whole_candidates(other)
        if any(r is not None and check_rule(other, r).mixed for r in known):
            found.append(f"flange {dims[0]}x{dims[1]} web {dims[2]}x{dims[3]}")
            if len(found) == limit:
                break
    return found


def _blocks(section: Section) -> tuple[tuple[int, int], tuple[int, int]]:
    _, flange, web = section.spec.split(":")
    a, b = flange.split("x")
    c, d = web.split("x")
    return (int(a), int(b)), (int(c), int(d))


def _around(dims: tuple[int, ...]) -> Iterator[tuple[int, ...]]:
    for delta in itertools.product(range(-2, 3), repeat=4):
        moved = tuple(v + d for v, d in zip(dims, delta, strict=True))
        if moved != dims and min(moved) >= 1:
            yield moved


def _distance(dims: tuple[int, ...]) -> Callable[[tuple[int, ...]], tuple[int, tuple[int, ...]]]:
    def key(other: tuple[int, ...]) -> tuple[int, tuple[int, ...]]:
        return sum(abs(a - b) for a, b in zip(dims, other, strict=True)), other

    return key
