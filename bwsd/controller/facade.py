"""The controller's facade: PackML, the command lock and the doors' small typed interface.

REST, the PLC tags, OPC UA and the page call ``command``, ``set_mode``, ``check``, ``load``,
``preview``, ``status`` and ``health``, and follow ``events``. Commands are taken one at a
time under the command lock, except Abort and Stop: they act at once, whatever else runs
(``acting.end_now``). The work of each acting state is in ``bwsd.controller.acting``, the run
loop in ``bwsd.controller.runloop``, what is written late in ``bwsd.controller.recorder``,
the restart and the reads at rest in ``bwsd.controller.resting``, the machine as last read in
``bwsd.controller.machine``; every long-lived task has the supervisor as its owner.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from bwsd.controller import acting, manual, resting
from bwsd.controller.errors import Busy, Cancelled, ControllerError
from bwsd.controller.job import Job, Preview
from bwsd.controller.machine import MachineView
from bwsd.controller.manual import ManualMove, manual_refusal
from bwsd.controller.packml import Command, PackML, State, UnitMode
from bwsd.controller.plan import Limits
from bwsd.controller.programs import DryRun, check_program
from bwsd.controller.recorder import Recorder
from bwsd.controller.recovery import Settle
from bwsd.controller.refusals import refusal
from bwsd.controller.runloop import RunLoop
from bwsd.controller.settling import settle_pending
from bwsd.controller.status import (
    EventStream,
    Fault,
    ModeChanged,
    ProgramLoaded,
    StateChanged,
    StatusSnapshot,
    StopCause,
)
from bwsd.controller.supervisor import Supervisor
from bwsd.errors import BwsdError
from bwsd.fieldbus.axes import Axis
from bwsd.fieldbus.base import BoolGrid, Fieldbus, FieldbusError, MachineState
from bwsd.journal import (
    COMPLETE,
    ENDED,
    EventRecord,
    Journal,
    JournalError,
    ProgramRecord,
    StateRecord,
)
from bwsd.logs import REFUSAL
from bwsd.twin import Machine, Program, Twin

log = logging.getLogger("bwsd.controller")
Publish = Callable[[dict[str, Any]], None]
_LOADABLE = frozenset({State.STOPPED, State.IDLE, State.COMPLETE, State.ABORTED})
_ENDS = frozenset({Command.ABORT, Command.STOP})


@dataclass(frozen=True)
class TwinView:
    """What the doors show of the twin: the matrix, its occupancy row by row, the take-up
    (mm) and the contacts so far."""

    rows: int
    cols: int
    occupancy: list[bool]
    takeup: float
    contacts: int


@dataclass(frozen=True)
class Settings:
    """The ``[controller]`` table's run settings (the limits are in ``Limits``), and the
    ``[journal]`` table's ``busy_timeout``."""

    max_instructions: int = 1_000_000  # a program may expand to at most this many
    snapshot_every: int = 200  # instructions between twin snapshots in the journal
    poll_interval: float = 0.5  # s between reads of the machine at rest
    journal_busy_timeout: float = 5.0  # s an urgent record waits for another process's lock


class Controller:
    """The one place that decides: PackML state, the loaded program, the run."""

    def __init__(
        self,
        machine: Machine,
        bus: Fieldbus,
        journal: Journal,
        limits: Limits | None = None,
        publish: Publish | None = None,
        settings: Settings | None = None,
    ) -> None:
        self.machine = machine
        self.bus = bus
        self.journal = journal
        self.limits = limits or Limits()
        self.settings = settings or Settings()
        self.events = EventStream()
        if publish is not None:
            self.events.subscribe(lambda event: publish(event.wire()))
        self.supervisor = Supervisor(self._task_failed)
        self.recorder = Recorder(journal, self._journal_trouble, self.settings.journal_busy_timeout)
        self.packml = PackML()
        self.packml.on_change.append(self._on_state)
        self.seen = MachineView(
            bus, self.events.publish, lambda old, new: resting.worse(self, old, new)
        )
        self.job: Job | None = None
        self.faults = 0  # runs ended by an unexpected error, tasks that failed
        self.lock = asyncio.Lock()  # one command at a time (but Abort and Stop)
        self.loop: RunLoop | None = None  # the run loop while one runs
        self.stop_cause = StopCause.NONE
        self.recovering = ""  # why commands wait (a restart is being rebuilt)
        self.broken = ""  # why the active program could not be restored ("" when it was)
        self.restoring: ProgramRecord | None = None  # the program a restart restores
        self._checking = asyncio.Lock()  # one program check at a time
        self.mode_requested = UnitMode.PRODUCTION  # the unit mode last asked for
        self.good = 0  # programs that reached Complete (the doors' production counts)
        self.defective = 0  # programs left unfinished after they ran: another loaded instead

    # ----- what the doors read -----
    @property
    def program(self) -> Program | None:
        return self.job.program if self.job else None

    @property
    def program_id(self) -> int | None:
        if self.job is not None:
            return self.job.program_id
        return self.restoring.id if self.restoring is not None else None

    @property
    def program_name(self) -> str | None:
        if self.job is not None:
            return self.job.name
        return self.restoring.name if self.restoring is not None else None

    @property
    def twin(self) -> Twin | None:
        return self.job.twin if self.job else None

    @property
    def axes(self) -> tuple[Axis, ...]:
        """The machine's axes, in the bus's order."""
        return tuple(self.bus.axes)

    @property
    def dry_run(self) -> DryRun | None:
        return self.job.dry_run if self.job else None

    @property
    def index(self) -> int:
        """Instructions done of the loaded program."""
        return self.job.done if self.job else 0

    @property
    def running(self) -> bool:
        """The run loop is moving the machine (or about to)."""
        return self.supervisor.running("run")

    def allowed(self) -> list[Command]:
        """Exactly the commands that will be accepted now (as far as the last read knows);
        ``resumable`` in the status says when Start is accepted with resume."""
        return [c for c in self.packml.allowed() if refusal(self, c) is None]

    def resumable(self) -> bool:
        """The loaded program was aborted or stopped, and Start with resume (from Idle,
        after Clear and Reset) continues it where it stopped."""
        job = self.job
        blocked = job is not None and job.pending is not None and bool(job.pending.blocked)
        return job is not None and job.ended in ENDED and not blocked

    def resume_allowed(self) -> bool:
        """Start with resume will be accepted now (as far as the last read knows)."""
        start = Command.START
        return (
            self.resumable()
            and self.packml.accepts(start)
            and refusal(self, start, resume=True) is None
        )

    def status(self) -> StatusSnapshot:
        """The controller as it stands, in one value."""
        job = self.job
        ended = job is None or bool(job.ended)
        return StatusSnapshot(
            state=self.packml.state,
            mode=self.packml.mode,
            reason=self.packml.reason,
            stop_cause=self.stop_cause,
            program_id=self.program_id,
            program_name=self.program_name,
            index=self.index,
            count=job.count if job is not None else 0,
            allowed=tuple(self.allowed()),
            bus=self.seen.status,
            recovering=self.recovering or self.broken,
            next=None if ended or job is None else job.next_step(),
            resumable=self.resumable(),
            resume_allowed=self.resume_allowed(),
            mode_requested=self.mode_requested,
            good=self.good,
            defective=self.defective,
            manual=manual_refusal(self) or "",
        )

    def next_step(self) -> dict[str, Any] | None:
        return self.job.next_step() if self.job is not None else None

    def health(self) -> dict[str, str]:
        """What is wrong with the daemon itself, by part (empty when all is well)."""
        found = {f"task {name}": why for name, why in self.supervisor.health().items()}
        if self.broken:
            found["recovery"] = self.broken
        if self.recorder.stall:
            found["journal"] = self.recorder.stall
        return found

    # ----- programs -----
    async def check(
        self, name: str, text: str, cancel: threading.Event | None = None
    ) -> tuple[Program, DryRun]:
        """Parse, validate and dry-run a program without loading it (any state), in a worker
        thread, one check at a time (``Busy`` otherwise); ``cancel`` stops it."""
        if self._checking.locked():
            raise Busy("another program is being checked: try again when it has finished")
        async with self._checking:
            try:
                return await asyncio.to_thread(
                    check_program,
                    self.machine,
                    self.limits,
                    self.settings.max_instructions,
                    name,
                    text,
                    cancel,
                )
            except Cancelled:
                log.info("check of %r cancelled", name)
                raise

    async def load(
        self, name: str, text: str, who: str = "", cancel: threading.Event | None = None
    ) -> int:
        """Check a program, then make it the one to run (in Stopped, Idle, Complete, Aborted)."""
        self._refuse_load()
        program, totals = await self.check(name, text, cancel)
        twin = await asyncio.to_thread(Twin.from_program, self.machine, program)
        async with self.lock:
            self._refuse_load()
            await self.recorder.catch_up()
            pid: int = await self.recorder.write(
                self.journal.add_program, name, text, len(program.instructions)
            )
            old = self.job
            if old is not None and old.ended != COMPLETE and (old.done or old.pending):
                self.defective += 1  # it ran and can no longer be finished
            self.job, self.restoring, self.broken = Job(program, pid, name, twin, totals), None, ""
            log.info(
                "program %d %r loaded by %s: %d instructions",
                pid,
                name,
                who or "?",
                len(program.instructions),
            )
            self.events.publish(ProgramLoaded(pid, name, len(program.instructions)))
            self.seen.compare(self.at_rest())
        return pid

    async def load_stored(self, program_id: int, who: str = "") -> int:
        """Load again a program the journal holds (its text checked against its sha256), as
        ``load`` does: the journal's new id."""
        try:
            record = await self.recorder.write(self.journal.program, program_id)
            text = await self.recorder.write(self.journal.program_text, program_id)
        except JournalError as exc:
            raise ControllerError(f"program {program_id}: {exc.reason}") from None
        return await self.load(record.name, text, who)

    async def history(self, limit: int = 50, before: int | None = None) -> list[ProgramRecord]:
        """The journal's programs, newest first (read in a worker thread)."""
        return await asyncio.to_thread(self.journal.history, limit, before)

    async def program_record(self, program_id: int) -> tuple[ProgramRecord, str] | None:
        """One program of the journal and its text; None when the journal has no such id
        (JournalError when its text no longer matches its sha256)."""
        found = await asyncio.to_thread(self.journal.history, 1, program_id + 1)
        if not found or found[0].id != program_id:
            return None
        text = await asyncio.to_thread(self.journal.program_text, program_id)
        return found[0], text

    async def records(
        self, after_state: int = 0, after_event: int = 0, limit: int = 100
    ) -> tuple[list[StateRecord], list[EventRecord]]:
        """The journal's state changes and events after the ids given, oldest first."""
        states = await asyncio.to_thread(self.journal.states, after_state, limit)
        events = await asyncio.to_thread(self.journal.events, after_event, limit)
        return states, events

    async def twin_view(self) -> TwinView:
        """The machine's size and the twin's occupancy, take-up and contacts (copied in a
        worker thread: it takes the twin's lock)."""
        twin, m = self.twin, self.machine
        if twin is None:
            return TwinView(m.rows, m.cols, [], 0.0, 0)
        occupancy = await asyncio.to_thread(lambda: twin.occupancy.ravel().tolist())
        return TwinView(m.rows, m.cols, occupancy, twin.takeup, twin.contact_count)

    def _refuse_load(self) -> None:
        if self.recovering:
            raise ControllerError(f"recovering: {self.recovering}")
        if self.packml.state not in _LOADABLE:
            raise ControllerError(f"a program cannot be loaded in state {self.packml.state.label}")

    async def preview(self) -> Preview:
        """The next instruction predicted on the controller's twin; the twin is not changed."""
        if self.job is None:
            raise ControllerError("no program is loaded")
        return await self.job.preview(self.limits)

    # ----- commands -----
    async def command(
        self, command: Command, reason: str = "", who: str = "", *, resume: bool = False
    ) -> State:
        """Apply a PackML command and run the acting state it enters to its end. Abort and
        Stop act at once, never queued behind another command; ``resume`` (with Start)
        continues a program that was aborted or stopped where it stopped."""
        if command in _ENDS:
            return await acting.end_now(self, command, reason, who)
        async with self.lock:
            return await acting.take(self, command, reason, who, resume)

    async def manual(self, move: ManualMove, who: str = "") -> MachineState:
        """A manual move (``bwsd.controller.manual``), under the command lock: the machine as
        read back after it."""
        async with self.lock:
            return await manual.manual(self, move, who)

    async def set_mode(self, mode: UnitMode, who: str = "") -> None:
        """Change the unit mode (where PackML allows it), journaled and published."""
        self.mode_requested = mode
        async with self.lock:
            old = self.packml.mode
            try:
                self.packml.set_mode(mode)
            except BwsdError as exc:
                log.info("mode %s from %s refused: %s", mode.label, who or "?", exc, extra=REFUSAL)
                raise
            if mode is not old:
                log.info("mode %s -> %s by %s", old.label, mode.label, who or "?")
                event = ModeChanged(old, mode)
                self.recorder.note(
                    f"the mode change to {mode.label}",
                    self.journal.log_event,
                    "mode",
                    {"from": old.label, "to": mode.label, "by": who},
                    event.at,
                )
                self.events.publish(event)

    async def wait(self) -> None:
        """Until the run loop and what follows its end (settling a cut instruction) stop."""
        for name in ("run", "settle"):
            await self.supervisor.wait(name)

    # ----- the machine -----
    async def read_machine(self, *, at_rest: bool = False) -> MachineState:
        """Read the machine now (connecting if needed); ControllerError when it cannot.
        ``at_rest``: once no axis moves (an axis still on its way after a hold ends its
        stroke first), as a command that moves next must see it."""
        try:
            state = await self.seen.read()
        except FieldbusError as exc:
            raise ControllerError(f"the machine cannot be read: {exc}") from exc
        if at_rest and any(axis.busy for axis in state.axes):
            moving = ", ".join(
                a.name for a, s in zip(self.bus.axes, state.axes, strict=True) if s.busy
            )
            log.info("waiting for %s to end the stroke under way", moving)
            try:
                state = await self.bus.rest()
            except FieldbusError as exc:
                raise ControllerError(
                    f"{exc}: nothing was moved; try again once they stand"
                ) from exc
        self.seen.observe(state, self.at_rest())
        return state

    async def settle(self, state: MachineState) -> Settle | None:
        """Settle the pending instruction from ``state`` (just read), then compare the
        machine with the twin again."""
        job = self.job
        if job is None:
            return None
        tolerance = self.bus.settings.position_tolerance
        every = self.settings.snapshot_every
        decision = await settle_pending(
            job, state, tolerance, self.recorder, self.events.publish, every
        )
        self.seen.observe(state, self.at_rest())
        return decision

    def at_rest(self) -> BoolGrid | None:
        """The twin's occupancy where the machine should show it now (None while moving or
        while a cut instruction is left part done)."""
        job = self.job
        if job is None or self.running or self.packml.state is State.EXECUTE:
            return None
        if job.pending is not None and job.pending.rest is not None:
            return None
        return job.twin.occupancy >= 0

    async def start(self) -> None:
        """Start the background tasks: the reads at rest and the journal's stall watch."""
        self.supervisor.start("watch", lambda: resting.watch(self), restart=True)
        self.supervisor.start("journal", self.recorder.watch, restart=True)

    def begin_recovery(self) -> str:
        """At start: restore the program the journal says was loaded (see restart.py)."""
        return resting.begin_recovery(self)

    async def recover(self) -> str:
        """Restore as at start, wait for it and settle a pending instruction if the machine
        can be read now. Says what it did."""
        return await resting.recover(self)

    # ----- what happens to the controller -----
    def _on_state(self, old: State, new: State, cause: str) -> None:
        reason = self.packml.reason
        log.info("state %s -> %s (%s)", old.label, new.label, cause)
        event = StateChanged(old, new, cause, reason)
        self.recorder.note(
            f"state {new.label}", self.journal.log_state, int(new), new.label, reason, event.at
        )
        self.events.publish(event)
        if new is State.COMPLETE and self.job is not None and self.job.complete:
            self.good += 1
        if new in (
            State.IDLE,
            State.HELD,
            State.SUSPENDED,
            State.STOPPED,
            State.COMPLETE,
            State.ABORTED,
        ):
            self.seen.compare(self.at_rest())

    def _task_failed(self, name: str, error: BaseException) -> None:
        self.faults += 1
        reason = f"task {name} failed: {type(error).__name__}: {error} (see the log)"
        self.events.publish(Fault(reason, StopCause.INTERNAL))
        acting.after_failure(self, name, reason)

    def _journal_trouble(self, what: str) -> None:
        self.events.publish(Fault(what, StopCause.JOURNAL))

    async def close(self) -> None:
        """Stop the background tasks, finish the journal's queued writes and close it."""
        await self.supervisor.close()
        await self.recorder.close()
