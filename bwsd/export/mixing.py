"""Carrier mixing of a shaped braid: which zones of its section each carrier has sat in.

A carrier is a warp's case. After the fill and after every ROW and COL, the twin's
occupancy says where each case is; a case on a cell of a zone has visited that zone. A
braid mixes when every carrier has visited every required zone of the section
(docs/exports.md, "mixing"); otherwise some yarns are walled into part of the preform.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from bwsd.errors import ProgramError
from bwsd.export.errors import ExportError
from bwsd.program.sections import Section, parse_section
from bwsd.twin.instructions import Program, Shift
from bwsd.twin.machine import Machine
from bwsd.twin.model import Twin
from bwsd.twin.skeleton import IntArray

Cell = tuple[int, int]
SHOWN_MISSING = 10  # carriers listed with the zones they missed
# A whole-line comment "# section: SPEC [remark]": the section the program braids.
_HEADER = re.compile(r"[ \t]*#[ \t]*section[ \t]*:[ \t]*(\S*)", re.IGNORECASE)


@dataclass(frozen=True)
class NamedSection:
    """A section and where it was named: ``--section`` or the program's header line."""

    section: Section
    source: str  # "option" or "header"
    line: int = 0  # the header's line, 1-based


def section_option(text: str) -> NamedSection:
    """The section of ``--section TEXT``; a malformed one is an ExportError."""
    try:
        return NamedSection(parse_section(text), "option")
    except ValueError as exc:
        raise ExportError(f"--section: {exc}") from None


def section_header(text: str, source: str = "<program>") -> NamedSection | None:
    """The section of the program's ``# section: SPEC`` line, None without one.

    Only whole-line comments count. Two such lines, or a malformed SPEC, are a ProgramError
    naming the line.
    """
    found: list[tuple[int, int, str]] = []
    for number, line in enumerate(text.split("\n"), start=1):  # lines as the parser counts
        match = _HEADER.match(line)
        if match is not None:
            found.append((number, match.start(1) + 1, match[1]))
    if not found:
        return None
    number, column, spec = found[0]
    if len(found) > 1:
        raise ProgramError(
            f"a second '# section:' line (the first is line {number})",
            line=found[1][0],
            column=1,
            source=source,
        )
    try:
        return NamedSection(parse_section(spec), "header", number)
    except ValueError as exc:
        raise ProgramError(f"# section: {exc}", line=number, column=column, source=source) from None


def check_fits(section: Section, machine: Machine) -> None:
    """Refuse a section with a cell outside the machine's matrix."""
    outside = sorted(cell for cell in section.cells if not machine.inside(*cell))
    if outside:
        raise ExportError(
            f"section {section.spec} does not fit the {machine.rows} x "
            f"{machine.cols} matrix of the config: its cell {outside[0]} "
            "lies outside"
        )


class ZoneVisits:
    """Which zones each carrier has sat in, fed the occupancy after each instruction."""

    def __init__(self, section: Section, fill: Sequence[Cell], shape: Cell) -> None:
        self.section = section
        self.fill = tuple(fill)
        self.names = list(section.zones)
        self.required = [self.names.index(name) for name in section.required]
        self._zone = np.full(shape, -1, dtype=np.int64)
        for index, name in enumerate(self.names):
            for row, col in section.zones[name]:
                self._zone[row, col] = index
        self.visited: npt.NDArray[np.bool_] = np.zeros((len(fill), len(self.names)), bool)
        self.mixed_at: int | None = None  # the first instruction after which all had mixed

    def record(self, instruction: int, occupancy: IntArray) -> None:
        """Note where every case is after ``instruction`` (0: the fill)."""
        held = occupancy >= 0
        zones = self._zone[held]
        inside = zones >= 0
        self.visited[occupancy[held][inside], zones[inside]] = True
        if self.mixed_at is None and self.visited[:, self.required].all():
            self.mixed_at = instruction

    def summary(self, cycle_length: int) -> dict[str, Any]:
        """The mixing numbers of docs/exports.md as JSON-ready builtins."""
        cells = self.section.cells
        missed = ~self.visited[:, self.required]
        incomplete = np.flatnonzero(missed.any(axis=1)).tolist()
        shown = [
            {
                "yarn": yarn,
                "cell": list(self.fill[yarn]),
                "zones": [self.section.required[j] for j in np.flatnonzero(missed[yarn])],
            }
            for yarn in incomplete[:SHOWN_MISSING]
        ]
        return {
            "section": self.section.spec,
            "carriers": len(self.fill),
            "edge": sum(1 for cell in self.fill if cell not in cells),
            "empty_body_cells": len(cells - set(self.fill)),
            "zones": [
                {
                    "name": name,
                    "cells": len(self.section.zones[name]),
                    "required": name in self.section.required,
                    "carriers": int(self.visited[:, j].sum()),
                }
                for j, name in enumerate(self.names)
            ],
            "complete": len(self.fill) - len(incomplete),
            "incomplete": len(incomplete),
            "missing": shown,
            "cycle_length": cycle_length,
            "instruction": self.mixed_at,
            "k": None if self.mixed_at is None else math.ceil(self.mixed_at / cycle_length),
        }


def simulate_with_visits(
    machine: Machine, program: Program, section: Section
) -> tuple[Twin, ZoneVisits]:
    """Run the program on the twin, noting the carriers' zones after the fill and each shift."""
    twin = Twin.from_program(machine, program)
    visits = ZoneVisits(section, program.fill, (machine.rows, machine.cols))
    visits.record(0, twin.occupancy)
    for index, instruction in enumerate(program.instructions, start=1):
        twin.advance(instruction)
        if isinstance(instruction, Shift):  # only ROW and COL move cases
            visits.record(index, twin.occupancy)
    return twin, visits
