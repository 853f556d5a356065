"""Programs off the event loop: the check before a load, the twin rebuilt after a restart.

Both run in a worker thread and touch no controller state: ``check_program`` parses,
validates, bounds and dry-runs a program (cancellable between instructions, the configured
limits checked on each); ``rebuild`` restores the twin from the journal's latest snapshot
and replays the instructions after it.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import asdict, dataclass
from typing import Any

from bwsd.controller.errors import Cancelled, ProgramRefused
from bwsd.controller.plan import Limits, RefusedMove, check_limits
from bwsd.errors import BwsdError, TwinError
from bwsd.program import parse_program_with_positions, validate
from bwsd.program.parser import SourceMap
from bwsd.twin import Machine, Program, Snapshot, Twin
from bwsd.twin.instructions import Instruction, Shift

log = logging.getLogger("bwsd.controller")


@dataclass(frozen=True)
class DryRun:
    """What a program makes when the twin runs it to the end."""

    instructions: int
    contacts: int
    yarns: int
    nodes: int
    takeup: float  # mm


def instruction_dict(instruction: Instruction) -> dict[str, Any]:
    """``{"kind": "shift" | "takeup" | "weft", ...its fields}``."""
    if isinstance(instruction, Shift):  # a move: [line, k], or [line, k, first, last] on a segment
        moves = [[m.line, m.k, *(m.span or ())] for m in instruction.moves]
        return {"kind": "shift", "axis": instruction.axis, "moves": moves}
    return {"kind": type(instruction).__name__.lower(), **asdict(instruction)}


def step_dict(step: dict[str, Any] | None) -> dict[str, Any] | None:
    """``Controller.next_step()`` as JSON (the instruction as a dict); None stays None."""
    if step is None:
        return None
    return {**step, "instruction": instruction_dict(step["instruction"])}


def rebuild(machine: Machine, program: Program, done: int, snap: tuple[int, bytes] | None) -> Twin:
    """The twin after ``done`` instructions: from the snapshot if there is one, then replay."""
    twin = None
    if snap is not None and snap[0] <= done:
        try:
            twin = Twin.from_snapshot(machine, Snapshot.from_bytes(snap[1]))
        except (BwsdError, ValueError) as exc:
            log.warning("snapshot at %d not usable (%s): replaying from the start", snap[0], exc)
    if twin is None:
        twin = Twin.from_program(machine, program)
    for instruction in program.instructions[twin.done : done]:
        twin.advance(instruction)
    return twin


def check_program(
    machine: Machine,
    limits: Limits,
    most: int,
    name: str,
    text: str,
    cancel: threading.Event | None,
) -> tuple[Program, DryRun]:
    """Parse, validate, bound and dry-run a program (in a worker thread)."""
    program, positions = parse_program_with_positions(text, name, most)
    validate(program, machine, name, positions)  # a refusal names its line and column
    twin = Twin.from_program(machine, program)
    predict = bool(limits.max_contacts or limits.tensioner_stroke)
    try:
        for instruction in program.instructions:
            if cancel is not None and cancel.is_set():
                raise Cancelled(f"{name}: the check was cancelled")
            if predict:
                pred = twin.predict(instruction)
                check_limits(pred, limits)
                twin.commit(pred)
            else:
                twin.advance(instruction)
    except TwinError as exc:
        raise _refused(str(exc), exc.instruction, program, positions, name) from exc
    except RefusedMove as exc:
        raise _refused(str(exc), pred.index, program, positions, name) from exc
    count = len(program.instructions)
    return program, DryRun(count, twin.contact_count, twin.yarn_count, twin.node_count, twin.takeup)


def _refused(
    message: str, index: int, program: Program, positions: SourceMap, name: str
) -> ProgramRefused:
    """A refusal of instruction ``index`` at the line and column of its keyword."""
    i = index - 1
    column = positions.keywords[i] if 0 <= i < len(positions.keywords) else 0
    return ProgramRefused(
        message, instruction=index, line=program.line_of(index), column=column, source=name
    )
