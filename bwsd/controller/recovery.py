"""What to do with an instruction journaled as started and not done (pure).

After a restart, and on Unhold after any fault hold, the machine is read and compared with
the state before the instruction and with its prediction:

- it shows the prediction: the move happened, **commit** it;
- it shows the state before: the move never started, **rerun** it;
- a shift shows some of its lines moved and the rest as before, nothing else moved:
  **finish** the other lines; a take-up stopped between its start and its target, the
  cases as before: **finish** it (its set-point is absolute);
- a weft leaves no trace in the occupancy or the take-up: its insert axis's stroke counter,
  journaled before the move, says whether the insert ran (one stroke more: commit if the
  inserter's positioning axes, x, y, z and angle, read back the weft's place and the rest
  shows the prediction) or not (the same count: rerun, its set-points are absolute);
  anything else, or no counter, is blocked;
- anything else is **blocked**, with the difference, for the operator (Abort ends it).

Nothing here reads the bus or the journal: the caller brings the read-back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from bwsd.controller.plan import Mismatch, verify
from bwsd.fieldbus.axes import UM_PER_MM
from bwsd.fieldbus.base import STROKES_WRAP, BoolGrid, MachineState
from bwsd.twin import Prediction, Shift, TakeUp, Weft
from bwsd.twin.instructions import Instruction

Kind = Literal["commit", "rerun", "finish", "blocked"]


@dataclass(frozen=True)
class Settle:
    """The decision for one pending instruction."""

    kind: Kind
    index: int
    reason: str  # what the machine showed, in words
    rest: Instruction | None = None  # for "finish": a shift's lines still to move, a take-up


@dataclass(frozen=True)
class Before:
    """The committed state before the pending instruction (occupancy, take-up in um)."""

    occupancy: BoolGrid
    takeup_um: int


def settle(
    instruction: Instruction,
    pred: Prediction,
    machine: MachineState,
    takeup_um: int,
    before: Before,
    origin_um: int,
    tolerance: int,
    strokes: Mapping[int, int] | None = None,
    misplaced: str = "",
) -> Settle:
    """Decide from the read-back ``machine`` (its take-up axis at ``takeup_um``);
    ``strokes``: the stroke counters of a weft's insert axes before it started (axis: count);
    ``misplaced``: where the inserter's positioning axes read back off the weft's place."""
    index = pred.index
    if isinstance(instruction, Weft):
        ran = inserted(machine, strokes)
        if isinstance(ran, str):
            return Settle("blocked", index, f"instruction {index} started and not done: {ran}")
        if ran and misplaced:
            return Settle(
                "blocked",
                index,
                f"instruction {index} started and not done: the weft was inserted but the "
                f"inserter stands off its place ({misplaced}): where it went cannot be told",
            )
        if not ran:
            if _shows(machine, takeup_um, before.occupancy, before.takeup_um, tolerance):
                return Settle(
                    "rerun",
                    index,
                    f"instruction {index} started, the weft was not "
                    "inserted (the insert's stroke count is unchanged)",
                )
            return Settle(
                "blocked",
                index,
                f"instruction {index} started and not done: the "
                "weft was not inserted and the machine moved",
            )
    try:
        verify(pred, machine, takeup_um - origin_um, tolerance)
    except Mismatch as exc:
        difference = str(exc)
    else:
        return Settle("commit", index, f"instruction {index} completed from the read-back")
    if _shows(machine, takeup_um, before.occupancy, before.takeup_um, tolerance):
        return Settle("rerun", index, f"instruction {index} started, the machine has not moved")
    if (
        isinstance(instruction, TakeUp)
        and _between(takeup_um, before.takeup_um, pred, origin_um, tolerance)
        and _same(machine.occupancy, before.occupancy)
    ):
        stopped = f"the take-up stopped at {takeup_um - origin_um} um on its way"
        return Settle("finish", index, f"instruction {index} started, {stopped}", instruction)
    rest = lines_left(instruction, machine.occupancy, before.occupancy, pred.occupancy >= 0)
    if rest is not None and _shows(
        machine, takeup_um, machine.occupancy, before.takeup_um, tolerance
    ):
        return Settle(
            "finish", index, f"instruction {index} started, some of its lines moved", rest
        )
    return Settle("blocked", index, f"instruction {index} started and not done: {difference}")


def inserted(machine: MachineState, strokes: Mapping[int, int] | None) -> bool | str:
    """Whether the insert ran, from its stroke counters before and now: True (one stroke
    more), False (the same count), or why it cannot be told."""
    if not strokes:
        return (
            "no stroke count of the insert was journaled before it started: whether the "
            "weft was inserted cannot be told"
        )
    counts = set()
    for axis, was in strokes.items():
        now = machine.axes[axis]
        if now.strokes is None:
            return (
                "the bus reports no stroke counter (Modbus map 2): whether the weft was "
                "inserted cannot be told"
            )
        if now.fault:
            return f"the insert axis reports fault {now.fault}: the stroke may be cut"
        counts.add((now.strokes - was) % STROKES_WRAP)
    if counts == {0}:
        return False
    if counts == {1}:
        return True
    return (
        f"the insert counted {', '.join(map(str, sorted(counts)))} strokes since it "
        "started, not 0 or 1"
    )


def _between(
    takeup_um: int, before_um: int, pred: Prediction, origin_um: int, tolerance: int
) -> bool:
    """The take-up stands strictly on its way from ``before_um`` to the predicted position."""
    target = origin_um + round(pred.takeup * UM_PER_MM)
    lo, hi = sorted((before_um, target))
    return lo + tolerance < takeup_um < hi - tolerance


def _shows(
    machine: MachineState, takeup_um: int, occupancy: BoolGrid, want_um: int, tolerance: int
) -> bool:
    return _same(machine.occupancy, occupancy) and abs(takeup_um - want_um) <= tolerance


def _same(a: BoolGrid, b: BoolGrid) -> bool:
    return a.shape == b.shape and bool(np.array_equal(a, b))


def lines_left(
    instruction: Instruction, machine: BoolGrid, before: BoolGrid, after: BoolGrid
) -> Shift | None:
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
