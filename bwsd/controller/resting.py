"""The controller between runs: the reads at rest, the restart, and settling a cut instruction.

``watch`` (a supervised task, restarted if it fails) reads the machine every poll interval
while nothing moves: the e-stop, faults and occupancy are published, a lost bus or a
pressed e-stop as a Fault once, and a fault hold's pending instruction is settled as soon as
the machine can be read. ``begin_recovery`` restores after a restart what the journal says
was loaded. ``settle_cut`` decides on an instruction an Abort or a Stop cut, from a
read-back once the run loop has ended.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

from bwsd.controller.errors import ControllerError
from bwsd.controller.packml import State as S
from bwsd.controller.restart import RecoveryFailed, restore_job, restored_state, strokes_of
from bwsd.controller.settling import NEXT
from bwsd.controller.status import BusStatus, Fault, StopCause
from bwsd.fieldbus.base import FAULT_NONE, MachineState
from bwsd.journal import ACTIVE, JournalError, ProgramRecord
from bwsd.logs import Summary
from bwsd.twin import Shift

if TYPE_CHECKING:
    from bwsd.controller.facade import Controller

log = logging.getLogger("bwsd.controller")
UNREAD = Summary(log, "failed reads of the machine at rest")


async def watch(ctl: Controller) -> None:
    """Read the machine at rest every ``poll_interval``; runs until cancelled."""
    while True:
        await asyncio.sleep(ctl.settings.poll_interval)
        if ctl.running or ctl.lock.locked():
            continue
        async with ctl.lock:
            await look(ctl)


async def look(ctl: Controller) -> None:
    """One read at rest: settle a held instruction once the machine can be read."""
    try:
        state = await ctl.read_machine()
    except ControllerError as exc:
        UNREAD.note("%s", exc)
        return
    UNREAD.reset()
    job = ctl.job
    if job is None or job.pending is None or ctl.recovering:
        return
    if ctl.packml.state in (S.HELD, S.SUSPENDED):
        await settle_held(ctl, state)


def worse(ctl: Controller, before: BusStatus, now: BusStatus) -> None:
    """The machine lost, or its e-stop pressed, outside a run (a run reports its own stop):
    one Fault, and a warning, when it happens."""
    if ctl.running:
        return
    if now.connected is False and before.connected is not False:
        log.warning("the machine cannot be read: %s", now.last_error)
        ctl.events.publish(Fault(f"the machine cannot be read: {now.last_error}", StopCause.BUS))
    if now.estop and not before.estop:
        ctl.events.publish(Fault("the emergency stop is pressed", StopCause.ESTOP))


async def settle_held(ctl: Controller, state: MachineState) -> None:
    """Settle a held program's pending instruction from ``state``; the reason says what."""
    job = ctl.job
    assert job is not None
    was = job.pending.decided if job.pending is not None else ""
    try:
        decision = await ctl.settle(state)
    except JournalError as exc:
        ctl.packml.reason = f"the journal cannot record the pending instruction: {exc}"
        ctl.events.publish(Fault(ctl.packml.reason, StopCause.JOURNAL))
        return
    if decision is None:
        return
    rest = decision.rest
    moves = f"the other {len(rest.moves)}" if isinstance(rest, Shift) else "the rest"
    then = {
        "commit": "resume with Unhold",
        "rerun": "Unhold runs it",
        "finish": f"Unhold moves {moves}",
        "blocked": "Abort ends the program",
    }
    if ctl.packml.state in (S.HELD, S.SUSPENDED):
        restarted = "restarted: " if ctl.stop_cause is StopCause.RESTART else ""
        ctl.packml.reason = f"{restarted}{decision.reason}: {then[decision.kind]}"
    if decision.reason != was:  # logged when it changes, not at every look
        log.info("pending instruction %d: %s (%s)", decision.index, decision.kind, decision.reason)


async def settle_cut(ctl: Controller, job: object) -> None:
    """After an Abort or a Stop: once the run loop has ended, ask the journal whether the
    cut instruction started, read the machine and say what a resume will do with it."""
    await ctl.supervisor.wait("run")
    async with ctl.lock:
        if ctl.job is not job or ctl.job is None:
            return
        current = ctl.job
        await ctl.recorder.flush()  # the last "done", so that the journal knows what it knows
        found = await ctl.recorder.write(ctl.journal.pending, current.program_id)
        if found is None or found.index <= current.done:
            current.settled(None)
            return
        if current.pending is None or current.pending.index != found.index:
            current.start(found.index, strokes_of(found.payload))
        try:
            state = await ctl.read_machine()
        except ControllerError as exc:
            log.warning("instruction %d was cut; %s: it is settled on resume", found.index, exc)
            return
        decision = await ctl.settle(state)
        if decision is None:
            return
        then = NEXT[decision.kind]
        log.info("cut instruction %d: %s (%s)", decision.index, decision.kind, decision.reason)
        if ctl.packml.state in (S.ABORTED, S.STOPPED) and ctl.job is current:
            ctl.packml.reason = f"{ctl.packml.reason}; {decision.reason}: {then}".lstrip("; ")


async def reset_machine(ctl: Controller) -> None:
    """Resetting: clear the drives' faults, then home the axes a cut stroke left away from
    home, so the next stroke starts where a stroke starts."""
    await ctl.bus.reset_faults()
    state = await ctl.bus.state()
    tolerance = ctl.bus.settings.position_tolerance
    away = [
        ctl.bus.axes[i].name
        for i, axis in enumerate(state.axes)
        if ctl.bus.axes[i].relative and abs(axis.position) > tolerance and axis.fault == FAULT_NONE
    ]
    if away:
        log.info("homing %s (left away from home)", ", ".join(away))
        await ctl.bus.home()


# ----- restart -----
def begin_recovery(ctl: Controller) -> str:
    """At start: take up the state the loaded program left, and rebuild its twin in the
    background (commands but Abort and Stop wait, the doors answer). Says what it found."""
    journal = ctl.journal
    record = journal.active_program() or journal.latest_program()
    if record is None:
        return "nothing to recover"
    state, reason = restored_state(record)
    ctl.packml.restore(state, reason)
    ctl.stop_cause = StopCause.RESTART
    ctl.restoring = record
    ctl.recovering = (
        f"rebuilding the twin of program {record.id} ({record.done} of "
        f"{record.instructions} instructions done)"
    )
    ctl.supervisor.start("recovery", lambda: _recover(ctl, record))
    return f"restarted with program {record.id} {record.name!r} {record.outcome}: recovering"


async def recover(ctl: Controller) -> str:
    said = begin_recovery(ctl)
    if said == "nothing to recover":
        return said
    await ctl.supervisor.wait("recovery")
    job = ctl.job
    if job is not None and job.pending is not None and ctl.packml.state is S.HELD:
        async with ctl.lock:
            try:
                await settle_held(ctl, await ctl.read_machine())
            except ControllerError as exc:
                return f"{ctl.packml.reason}; {exc}"
    return ctl.packml.reason


async def _recover(ctl: Controller, record: ProgramRecord) -> None:
    try:
        job = await restore_job(ctl.machine, ctl.recorder, record)
    except Exception as exc:
        _failed(ctl, record, exc)
        return
    finally:
        ctl.recovering = ""
    if ctl.packml.state is S.ABORTED and record.outcome in ACTIVE:
        job.ended = "aborted"  # an Abort came while it was rebuilt
    ctl.job = job
    pending = f", instruction {job.pending.index} pending" if job.pending else ""
    log.info(
        "program %d rebuilt at instruction %d%s%s",
        record.id,
        record.done,
        f" from the snapshot at {job.snapped}" if job.snapped else "",
        pending,
    )
    if ctl.packml.state is S.HELD and job.pending is not None:
        ctl.packml.reason = f"restarted: instruction {job.pending.index} pending"
    elif ctl.packml.state is S.HELD:
        ctl.packml.reason = f"restarted at instruction {record.done}: resume with Unhold"
    ctl.seen.compare(ctl.at_rest())


def _failed(ctl: Controller, record: ProgramRecord, exc: Exception) -> None:
    """A program that cannot be restored: an active one blocks everything but Abort and Stop
    (with what would fix it); any other is dropped (load a program)."""
    if not isinstance(exc, RecoveryFailed):
        log.error("recovery of program %d failed", record.id, exc_info=exc)
    reason = f"recovery failed: {exc}"
    ctl.events.publish(Fault(reason, StopCause.INTERNAL))
    log.error("%s", reason)
    if record.outcome in ACTIVE and ctl.packml.state is S.HELD:
        ctl.broken = reason
        ctl.packml.reason = reason
    else:
        ctl.restoring = None
        if ctl.packml.state in (S.STOPPED, S.ABORTED):
            ctl.packml.reason = f"{reason}; load a program"
