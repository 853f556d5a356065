"""What the controller refuses beyond PackML's own table: the machine, the program and the
journal's state say no. Read only: a refusal changes nothing, and ``allowed`` asks the same
question for every command."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bwsd.controller.packml import Command as C
from bwsd.journal import COMPLETE, ENDED

if TYPE_CHECKING:
    from bwsd.controller.facade import Controller

RUNS = frozenset({C.START, C.UNHOLD, C.UNSUSPEND})
READS_FIRST = RUNS | {C.RESET, C.CLEAR}


def refusal(ctl: Controller, command: C, resume: bool = False) -> str | None:
    """Why ``command`` is refused beyond PackML's own table (None: it is not). Reads only
    what the controller knows: the status of the last read, the job, the journal's state."""
    if command in (C.ABORT, C.STOP):
        return None  # an exit from every state: recovering, broken or not
    if ctl.recovering:
        return f"recovering: {ctl.recovering}"
    if ctl.broken:
        return f"{ctl.broken} (Abort ends it)"
    job, bus = ctl.job, ctl.seen.status
    if command is C.START and (why := _start_refused(ctl, resume)) is not None:
        return why
    if command in READS_FIRST and bus.estop:
        return f"the emergency stop is pressed: release it before {command.label}"
    if command in RUNS and ctl.packml.accepts(command):
        if job is not None and job.pending is not None and job.pending.blocked:
            return f"cannot resume: {job.pending.blocked} (Abort ends the program)"
        if bus.connected is False:
            return f"the machine cannot be read: {bus.last_error}"
        if bus.faulted:
            route = "Clear and Reset" if command is C.START else "Abort, Clear and Reset"
            return (
                f"axes {', '.join(bus.faulted)} report a fault: {route} clear it, then "
                "Start with resume continues the program"
            )
        if bus.differs and not (job is not None and job.pending is not None and job.pending.rest):
            return (
                "the occupancy sensors differ from the twin at "
                f"{_cells(bus.differs)}: nothing is moved"
            )
    return None


def _start_refused(ctl: Controller, resume: bool) -> str | None:
    job = ctl.job
    if job is None:
        return "no program is loaded"
    if job.ended == COMPLETE:
        return "the loaded program is complete: load a program to start"
    if job.ended in ENDED and not resume and (job.done or job.pending is not None):
        return (
            f"program {job.program_id} was {job.ended} at instruction {job.done}: Start "
            "with resume continues it, or load a program"
        )
    return None


def _cells(cells: tuple[tuple[int, int], ...]) -> str:
    if cells == ((-1, -1),):
        return "every cell (the grids differ in shape)"
    return ", ".join(f"({r}, {c})" for r, c in cells)
