"""What to do with an instruction journaled as started and not done (pure).

After a restart, and on Unhold after any fault hold, the machine is read and compared with
the state before the instruction and with its prediction:

- it shows the prediction: the move happened, **commit** it;
- it shows the state before: the move never started, **rerun** it;
- a shift shows some of its lines moved and the rest as before, nothing else moved:
  **finish** the other lines;
- anything else is **blocked**, with the difference, for the operator (Abort ends it).

Nothing here reads the bus or the journal: the caller brings the read-back.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from bwsd.controller.plan import Mismatch, verify
from bwsd.fieldbus.base import BoolGrid, MachineState
from bwsd.twin import Prediction, Shift
from bwsd.twin.instructions import Instruction

Kind = Literal["commit", "rerun", "finish", "blocked"]


@dataclass(frozen=True)
class Settle:
    """The decision for one pending instruction."""

    kind: Kind
    index: int
    reason: str  # what the machine showed, in words
    rest: Shift | None = None  # for "finish": the lines still to move


@dataclass(frozen=True)
class Before:
    """The committed state before the pending instruction (occupancy, take-up in um)."""

    occupancy: BoolGrid
    takeup_um: int


def settle(instruction: Instruction, pred: Prediction, machine: MachineState, takeup_um: int,
           before: Before, origin_um: int, tolerance: int) -> Settle:  # fmt: skip
    """Decide from the read-back ``machine`` (its take-up axis at ``takeup_um``)."""
    index = pred.index
    try:
        verify(pred, machine, takeup_um - origin_um, tolerance)
    except Mismatch as exc:
        difference = str(exc)
    else:
        return Settle("commit", index, f"instruction {index} completed from the read-back")
    if _shows(machine, takeup_um, before.occupancy, before.takeup_um, tolerance):
        return Settle("rerun", index, f"instruction {index} started, the machine has not moved")
    rest = lines_left(instruction, machine.occupancy, before.occupancy, pred.occupancy >= 0)
    if rest is not None and _shows(machine, takeup_um, machine.occupancy, before.takeup_um,
                                   tolerance):  # fmt: skip
        return Settle("finish", index, f"instruction {index} started, some of its lines moved",
                      rest)  # fmt: skip
    return Settle("blocked", index, f"instruction {index} started and not done: {difference}")


def _shows(machine: MachineState, takeup_um: int, occupancy: BoolGrid, want_um: int,
           tolerance: int) -> bool:  # fmt: skip
    same = machine.occupancy.shape == occupancy.shape and bool(
        np.array_equal(machine.occupancy, occupancy)
    )
    return same and abs(takeup_um - want_um) <= tolerance


def lines_left(instruction: Instruction, machine: BoolGrid, before: BoolGrid,
               after: BoolGrid) -> Shift | None:  # fmt: skip
    """The entries of a shift whose line (or segment) is still as before, when every other
    entry shows its predicted result and nothing else moved; None otherwise (or for no
    shift). Each entry is its own actuator, so a cut shift stops between entries."""
    if not isinstance(instruction, Shift) or machine.shape != before.shape:
        return None
    if instruction.axis == "col":  # work on columns as rows
        machine, before, after = machine.T, before.T, after.T
    rest = []
    covered = np.zeros(machine.shape, dtype=bool)
    for move in instruction.moves:
        lo, hi = move.span if move.span is not None else (0, machine.shape[1] - 1)
        cells = (move.line, slice(lo, hi + 1))
        covered[cells] = True
        if (machine[cells] == before[cells]).all():
            rest.append(move)
        elif not (machine[cells] == after[cells]).all():
            return None
    if not (machine[~covered] == before[~covered]).all():
        return None
    return Shift(instruction.axis, tuple(rest)) if rest else None


def differing_cells(machine: BoolGrid, twin: BoolGrid, limit: int = 8) -> list[tuple[int, int]]:
    """Cells where the occupancy sensors and the twin disagree (at most ``limit``)."""
    if machine.shape != twin.shape:
        return []
    return [(int(r), int(c)) for r, c in np.argwhere(machine != twin)[:limit].tolist()]
