"""An occupancy dry-run for the tests, written apart from bwsd.program.validate.

Moves every case of a line at once (the machine's own view of a shift) instead of one
case at a time, and follows which yarn sits where.
"""

from __future__ import annotations

from bwsd.twin.instructions import Program, Shift
from bwsd.twin.machine import Machine

Cell = tuple[int, int]


def apply(cases: dict[int, Cell], shift: Shift, machine: Machine) -> dict[int, Cell]:
    """Yarn -> cell after one ROW/COL; AssertionError on a case outside or a clash."""
    out = dict(cases)
    axis = 0 if shift.axis == "row" else 1
    for index, k, span in shift.moves:
        lo, hi = span if span is not None else (0, max(machine.rows, machine.cols))
        for yarn, cell in cases.items():
            if cell[axis] == index and lo <= cell[1 - axis] <= hi:
                moved = (cell[0], cell[1] + k) if axis == 0 else (cell[0] + k, cell[1])
                assert machine.inside(*moved), f"{cell} leaves the matrix"
                assert lo <= moved[1 - axis] <= hi, f"{cell} leaves its segment"
                out[yarn] = moved
    assert len(set(out.values())) == len(out), "two cases in one cell"
    return out


def cycle_states(program: Program, machine: Machine) -> list[set[Cell]]:
    """The occupied cells at the start and after each full cycle of the program."""
    cases = dict(enumerate(program.fill))
    assert program.cycle_length, "program has no cycle"
    states = [set(cases.values())]
    for i, instruction in enumerate(program.instructions, start=1):
        if isinstance(instruction, Shift):
            cases = apply(cases, instruction, machine)
        if i % program.cycle_length == 0:
            states.append(set(cases.values()))
    return states


def positions(program: Program, machine: Machine, upto: int) -> dict[int, Cell]:
    """Yarn -> cell after the first ``upto`` instructions."""
    cases = dict(enumerate(program.fill))
    for instruction in program.instructions[:upto]:
        if isinstance(instruction, Shift):
            cases = apply(cases, instruction, machine)
    return cases


def contact_groups(sk) -> list[list[int]]:
    """Yarns joined by contacts, as sorted groups (union-find, apart from bwsd.export)."""
    parent = list(range(len(sk.yarns)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for c in sk.contacts:
        parent[root(c.moving_yarn)] = root(c.hit_yarn)
    groups: dict[int, list[int]] = {}
    for i in range(len(sk.yarns)):
        groups.setdefault(root(i), []).append(i)
    return sorted(groups.values())
