"""The work of the PackML commands and acting states, for the facade (``Controller``).

A command is refused (``refusal``) beyond PackML's own table when the machine, the program
or the journal says so; nothing changes then. Abort and Stop (``end_now``) take no lock:
the state changes at once, a run is cut mid-stroke, the axes are quick-stopped, the outcome
goes to the journal without being waited for, and the cut instruction is settled from a
read-back afterwards (``resting.settle_cut``). Every other command runs under the command
lock (``take``). The run loop's end (``run``) turns into the state that follows: Complete,
Held or Aborted.
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

from bwsd.controller import resting
from bwsd.controller.errors import ControllerError
from bwsd.controller.packml import ACTING, InvalidCommand
from bwsd.controller.packml import Command as C
from bwsd.controller.packml import State as S
from bwsd.controller.recorder import Outcome
from bwsd.controller.refusals import READS_FIRST, refusal
from bwsd.controller.runloop import Aborted, Ending, Finished, Held, Parts, RunLoop
from bwsd.controller.status import Fault, StopCause, cause_of
from bwsd.errors import BwsdError
from bwsd.fieldbus.axes import POSITIONING
from bwsd.fieldbus.base import FieldbusError, MachineState
from bwsd.journal import ABORTED, COMPLETE, HELD, RUNNING, STOPPED, SUSPENDED, JournalError
from bwsd.logs import REFUSAL

if TYPE_CHECKING:
    from bwsd.controller.facade import Controller

log = logging.getLogger("bwsd.controller")
QUICK_STOP_WAIT = 1.0  # s an Abort or Stop waits for the bus to confirm its quick stop
OUTCOME_WAIT = 0.5  # s an Abort or Stop waits for the journal to record it (then goes on)
START_WAIT = 1.0  # s a run waits for the journal to record that it starts (else it holds)


def said(command: C, reason: str, who: str, resume: bool = False) -> str:
    what = f"{command.label}{' (resume)' if resume else ''} from {who or '?'}"
    return what + (f": {reason}" if reason else "")


async def take(ctl: Controller, command: C, reason: str, who: str, resume: bool) -> S:
    """A command other than Abort and Stop, under the command lock. An error nothing
    expects is logged, published as a Fault and answered as a refusal; a machine it left
    in an acting state is aborted (an exit, not a wedge)."""
    try:
        return await _take(ctl, command, reason, who, resume)
    except BwsdError:
        raise
    except Exception as exc:
        ctl.faults += 1
        why = f"{command.label} failed: {type(exc).__name__}: {exc}"
        log.exception("command %s", why)
        ctl.events.publish(Fault(why, StopCause.INTERNAL))
        if ctl.packml.state in ACTING and ctl.packml.accepts(C.ABORT):
            await end_now(ctl, C.ABORT, why, "the controller", StopCause.INTERNAL)
        raise ControllerError(f"{why} (see the log)") from exc


async def _take(ctl: Controller, command: C, reason: str, who: str, resume: bool) -> S:
    text = said(command, reason, who, resume)
    log.info("command %s", text)
    try:
        if not ctl.running:
            await ctl.recorder.catch_up()
        if command in READS_FIRST and ctl.packml.accepts(command):
            await _prepare(ctl, command, resume)
        refused = refusal(ctl, command, resume)
        if refused is not None:
            raise ControllerError(refused)
        state = ctl.packml.command(command, reason)
    except BwsdError as exc:  # a refusal is routine (INFO); a bus or journal fault is not
        failed = isinstance(exc, FieldbusError | JournalError)
        level, extra = (logging.ERROR, None) if failed else (logging.INFO, REFUSAL)
        log.log(level, "command %s refused: %s", text, exc, extra=extra)
        raise
    if command in (C.HOLD, C.SUSPEND):
        ctl.stop_cause = StopCause.OPERATOR
    elif command is C.RESET:
        ctl.stop_cause = StopCause.NONE
    await _act(ctl, state, resume)
    return ctl.packml.state


async def _prepare(ctl: Controller, command: C, resume: bool) -> None:
    """Read the machine before a command that may lead to motion; settle a pending one."""
    if ctl.recovering or ctl.broken:
        return
    state = await ctl.read_machine(at_rest=True)
    if command is C.UNHOLD and await _clear_placing(ctl, state):
        state = await ctl.read_machine(at_rest=True)
    job = ctl.job
    if job is None or job.pending is None:
        return
    if command in (C.UNHOLD, C.UNSUSPEND) or (command is C.START and resume):
        decision = await ctl.settle(state)  # a blocked one is refused below
        if decision is not None:
            log.info(
                "pending instruction %d: %s (%s)", decision.index, decision.kind, decision.reason
            )


async def _clear_placing(ctl: Controller, state: MachineState) -> bool:
    """Unhold after a fault of the axes that place the weft inserter (and of no other):
    clear it, since no case rides on them and the weft is placed again from absolute
    set-points. True when it was cleared."""
    faulted = [ctl.bus.axes[i] for i, axis in enumerate(state.axes) if axis.fault]
    if state.estop or not faulted or any(a.kind not in POSITIONING for a in faulted):
        return False
    log.info("clearing the fault of %s to place the weft again", ", ".join(a.name for a in faulted))
    await ctl.bus.reset_faults()
    return True


async def _act(ctl: Controller, state: S, resume: bool = False) -> None:
    """The work of the acting state just entered, then "state complete"."""
    if state is S.RESETTING:
        await _guard(ctl, resting.reset_machine(ctl))
    elif state in (S.STARTING, S.UNHOLDING, S.UNSUSPENDING):
        await _begin_run(ctl, state)
        return
    elif state in (S.HOLDING, S.SUSPENDING):
        await ctl.supervisor.wait("run")
        await record(ctl, HELD if state is S.HOLDING else SUSPENDED)
    elif state is S.CLEARING:
        await _guard(ctl, ctl.bus.reset_faults())
    if ctl.packml.state is state:  # unless a command took over meanwhile
        ctl.packml.state_complete()


async def _begin_run(ctl: Controller, state: S) -> None:
    """Record the program as running (a resumed one too), then run it."""
    job = ctl.job
    assert job is not None
    job.ended = ""  # from here on it runs, or is held: a resumed program too
    problem = await ctl.recorder.outcome_within(Outcome(job.program_id, RUNNING, ""), START_WAIT)
    if problem:
        why = f"the journal cannot record that program {job.program_id} runs: {problem}"
        await _hold(ctl, StopCause.JOURNAL, f"{why}: free its disk, then Unhold")
        return
    if ctl.packml.state is not state:
        return  # an Abort or a Stop came meanwhile
    ctl.packml.state_complete()
    parts = Parts(
        ctl.bus,
        ctl.recorder,
        ctl.limits,
        ctl.settings.snapshot_every,
        ctl.events.publish,
        lambda s: ctl.seen.observe(s, None),
        ctl.seen.failed,
    )
    loop = RunLoop(job, parts, lambda: ctl.packml.state is S.EXECUTE)
    ctl.loop = loop
    ctl.supervisor.start("run", lambda: run(ctl, loop))


async def run(ctl: Controller, loop: RunLoop) -> None:
    """The run loop's task: the loop, then the state its end leads to."""
    try:
        ending: Ending = await loop.run()
    except Exception as exc:  # the catch-all: never a silent death
        ctl.faults += 1
        reason = f"internal error: {type(exc).__name__}: {exc}"
        log.exception("the run loop failed: %s", reason)
        ending = Aborted(StopCause.INTERNAL, reason)
    finally:
        if ctl.loop is loop:
            ctl.loop = None
    await _after(ctl, ending)


async def _after(ctl: Controller, ending: Ending) -> None:
    """Hold, abort or complete after the run loop ended (unless a command already acts)."""
    if isinstance(ending, Finished):
        if ctl.packml.state is S.EXECUTE:
            completing = ctl.packml.execute_done()
            await record(ctl, COMPLETE)
            if ctl.packml.state is completing:
                ctl.packml.state_complete()
            log.info("program %s complete", ctl.program_id)
        return
    if not isinstance(ending, Held | Aborted):
        return
    ctl.stop_cause = ending.cause
    ctl.events.publish(Fault(ending.reason, ending.cause))
    log.warning("%s: %s", "hold" if isinstance(ending, Held) else "abort", ending.reason)
    if ctl.packml.state is not S.EXECUTE:
        return  # a command is acting on the run already; it decides what follows
    if isinstance(ending, Held):
        await _hold(ctl, ending.cause, ending.reason)
    else:
        await end_now(ctl, C.ABORT, ending.reason, "the run", ending.cause)


async def _hold(ctl: Controller, cause: StopCause, reason: str) -> None:
    """Hold from inside (a fault that loses nothing): Holding, the outcome, Held."""
    ctl.stop_cause = cause
    try:
        await _act(ctl, ctl.packml.command(C.HOLD, reason))
    except BwsdError as exc:
        log.warning("the hold after %r was refused: %s", reason, exc)


async def end_now(
    ctl: Controller, command: C, reason: str, who: str, cause: StopCause = StopCause.OPERATOR
) -> S:
    """Abort or Stop at once: the state, the cut, the quick stop, the outcome, the end."""
    text = said(command, reason, who)
    log.info("command %s", text)
    try:
        state = ctl.packml.command(command, reason)
    except InvalidCommand as exc:
        log.info("command %s refused: %s", text, exc, extra=REFUSAL)
        raise
    ctl.stop_cause = cause
    loop = ctl.loop
    if loop is not None:
        loop.cut()  # what it waits for is cancelled now; it moves nothing more
    await _quick_stop(ctl)
    job, pid = ctl.job, ctl.program_id
    outcome = ABORTED if command is C.ABORT else STOPPED
    if job is not None and not job.ended and not job.complete:  # an ended one keeps its own
        job.ended = outcome
        await ctl.recorder.outcome_soon(
            Outcome(job.program_id, outcome, ctl.packml.reason), OUTCOME_WAIT
        )
    elif job is None and pid is not None and ctl.broken:  # a program that cannot be restored
        await ctl.recorder.outcome_soon(Outcome(pid, outcome, ctl.packml.reason), OUTCOME_WAIT)
    if ctl.broken and job is None:
        ctl.broken, ctl.restoring = "", None  # ended: nothing is left to restore
    if ctl.packml.state is state:
        ctl.packml.state_complete()
    if job is not None and (loop is not None or job.pending is not None):
        ctl.supervisor.start("settle", lambda: resting.settle_cut(ctl, job))
    return ctl.packml.state


async def _quick_stop(ctl: Controller) -> None:
    """Stop every axis now; a bus that does not confirm within QUICK_STOP_WAIT is reported."""
    try:
        await asyncio.wait_for(ctl.bus.quick_stop(), QUICK_STOP_WAIT)
    except FieldbusError as exc:
        ctl.seen.failed(exc)
        ctl.events.publish(Fault(f"the quick stop failed: {exc}", cause_of(exc)))
    except TimeoutError:
        log.error("the quick stop was not confirmed within %g s", QUICK_STOP_WAIT)
        ctl.events.publish(
            Fault(f"the quick stop was not confirmed within {QUICK_STOP_WAIT:g} s", StopCause.BUS)
        )


async def record(ctl: Controller, outcome: str) -> None:
    """Journal the program's outcome, waiting for it at most OUTCOME_WAIT: a journal that
    cannot write is reported by the recorder (stall, failure) and the outcome written again
    before the next command; the state machine goes on."""
    job = ctl.job
    if job is None or job.ended:
        return
    await ctl.recorder.outcome_soon(
        Outcome(job.program_id, outcome, ctl.packml.reason), OUTCOME_WAIT
    )
    if outcome == COMPLETE:
        job.ended = COMPLETE


async def _guard(ctl: Controller, action: object) -> None:
    """Run a bus action; a failure is published, not raised (the state machine goes on)."""
    try:
        await action  # type: ignore[misc]
    except FieldbusError as exc:
        ctl.seen.failed(exc)
        ctl.events.publish(Fault(str(exc), cause_of(exc)))


def after_failure(ctl: Controller, name: str, reason: str) -> None:
    """A supervised task failed: a moving machine goes to a state with an exit."""
    if ctl.packml.state is S.EXECUTE or (
        name == "run" and ctl.packml.state in (S.COMPLETING, S.HOLDING, S.SUSPENDING)
    ):
        command = C.ABORT if name == "run" else C.HOLD
        ctl.supervisor.start(
            f"{command.label.lower()} after {name}",
            lambda: ctl.command(command, reason, "the supervisor"),
        )
