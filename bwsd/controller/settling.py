"""Settling the instruction a stop cut, from a fresh read-back (after a fault hold, an Abort,
a Stop or a restart): the decision is ``recovery.settle``'s, this applies it to the job."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from bwsd.controller import plan
from bwsd.controller.job import Job
from bwsd.controller.recorder import Recorder
from bwsd.controller.recovery import Before, Settle, settle
from bwsd.controller.status import Event
from bwsd.fieldbus.axes import axis_by_name
from bwsd.fieldbus.base import MachineState
from bwsd.twin import Weft

NEXT = {
    "commit": "recorded done",
    "rerun": "a resume runs it again",
    "finish": "a resume moves the rest",
    "blocked": "a resume is refused",
}


def takeup_of(job: Job, state: MachineState) -> int:
    """The take-up axis's position as the machine reports it (um)."""
    return state.axes[axis_by_name(job.twin.machine, "takeup").index].position


async def settle_pending(
    job: Job,
    state: MachineState,
    tolerance: int,
    recorder: Recorder,
    publish: Callable[[Event], None],
    snapshot_every: int,
) -> Settle | None:
    """Decide on the job's pending instruction from ``state`` (just read) and apply it:
    commit what the machine shows done, keep what is left to move, or block it with the
    reason. None when nothing is pending."""
    pending = job.pending
    if pending is None:
        return None
    pred = await job.prediction()
    before = Before(job.twin.occupancy >= 0, job.takeup_um())
    instruction = job.instruction(pending.index)
    misplaced = ""
    if isinstance(instruction, Weft):
        misplaced = plan.misplaced(job.twin.machine, instruction, state, tolerance)
    decision = settle(
        instruction,
        pred,
        state,
        takeup_of(job, state),
        before,
        job.origin or 0,
        tolerance,
        pending.strokes,
        misplaced,
    )
    if decision.kind == "commit":
        await job.commit(pred, recorder, publish, snapshot_every)
        await recorder.flush()
        return decision
    job.settled(
        replace(
            pending,
            rest=decision.rest,
            decided=decision.reason,
            blocked=decision.reason if decision.kind == "blocked" else "",
        )
    )
    return decision
