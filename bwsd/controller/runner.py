"""The controller: PackML commands, the loaded program, the twin, the run loop, recovery.

One instruction (docs/packml.md, the project's DESIGN):
1. the twin predicts it in a worker thread (the kernel runs without the interpreter lock);
   the twin or a limit refuses it: Abort with the reason, nothing moved;
2. the journal records "started" (on disk before anything moves);
3. the bus moves the actuators and waits for them; a drive fault or the e-stop aborts,
   a timeout, a lost connection or a read-back mismatch holds;
4. the twin commits, the journal records "done" (and every ``snapshot_every`` instructions
   a snapshot of the twin), an ``InstructionDone`` event is published.

Every step ends as Done, Held(cause) or Aborted(cause); anything unexpected aborts with the
error as the reason, logged, counted and published. Nothing runs before the machine has been
read: Start, Unhold and Unsuspend refuse while the e-stop is pressed, an axis reports a fault
or the occupancy sensors differ from the twin; Reset refuses while the e-stop is pressed.

An instruction journaled as started and not done (after a fault hold or a restart) is
settled from a fresh read-back (bwsd.controller.recovery) before the run resumes.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from typing import Any

from bwsd.controller.errors import Busy, Cancelled, ControllerError
from bwsd.controller.machine import MachineView
from bwsd.controller.packml import Command, PackML, State, UnitMode
from bwsd.controller.plan import Limits, Mismatch, RefusedMove, check_limits, setpoints, verify
from bwsd.controller.programs import DryRun, check_program, rebuild, step_dict
from bwsd.controller.recovery import Before, Settle, settle
from bwsd.controller.status import (
    EventStream,
    Fault,
    InstructionDone,
    ModeChanged,
    ProgramLoaded,
    StateChanged,
    StatusSnapshot,
    StopCause,
    cause_of,
)
from bwsd.controller.tasks import Tasks
from bwsd.errors import BwsdError, TwinError
from bwsd.export.skeleton_json import committed_parts, delta_from
from bwsd.fieldbus.axes import UM_PER_MM, axis_by_name
from bwsd.fieldbus.base import (
    BoolGrid,
    DriveFault,
    EStopError,
    Fieldbus,
    FieldbusError,
    MachineState,
)
from bwsd.journal import ABORTED, COMPLETE, HELD, RUNNING, STOPPED, SUSPENDED, Journal
from bwsd.journal.writer import JournalWriter
from bwsd.program import parse_program
from bwsd.twin import Machine, Prediction, Program, Shift, Twin, Weft
from bwsd.twin.instructions import Instruction

log = logging.getLogger("bwsd.controller")
Publish = Callable[[dict[str, Any]], None]
_RUNS = frozenset({Command.START, Command.UNHOLD, Command.UNSUSPEND})
_READS_FIRST = _RUNS | {Command.RESET}
_LOADABLE = frozenset({State.STOPPED, State.IDLE, State.COMPLETE, State.ABORTED})


@dataclass(frozen=True)
class Settings:
    """The ``[controller]`` table's run settings (the limits are in ``Limits``)."""

    max_instructions: int = 1_000_000  # a program may expand to at most this many
    snapshot_every: int = 200  # instructions between twin snapshots in the journal
    poll_interval: float = 0.5  # s between reads of the machine at rest


# ----- how one step ends -----
@dataclass(frozen=True)
class Done:
    index: int


@dataclass(frozen=True)
class Held:
    cause: StopCause
    reason: str


@dataclass(frozen=True)
class Aborted:
    cause: StopCause
    reason: str


Outcome = Done | Held | Aborted


@dataclass(frozen=True)
class Preview:
    """The next instruction predicted on the controller's twin (nothing committed)."""

    index: int
    line: int
    instruction: Instruction
    prediction: Prediction | None  # None when the twin refuses it
    refused: str | None
    occupancy: Any
    takeup: float


@dataclass
class Progress:
    """What the run of the loaded program carries from one instruction to the next."""

    origin: int | None = None  # take-up position (um) where the program started
    journaled: int | None = None  # an instruction journaled as started and not done
    pending: Prediction | None = None  # its prediction
    rest: Shift | None = None  # the lines of it still to move (a cut shift)
    strokes: dict[int, int] | None = None  # a weft's insert stroke count before it (journaled)
    blocked: str = ""  # why it cannot be settled (Unhold is refused)
    unjournaled: tuple[int, dict[str, Any]] | None = None  # the last "done", not yet written
    snapped: int = 0  # instructions done at the last snapshot
    finished: bool = False  # the program reached complete, aborted or stopped
    timing: dict[str, float] = field(default_factory=dict)  # the running step's, published


class Controller:
    """The one place that decides: PackML state, the loaded program, the twin, the run.

    Its doors (REST, the PLC tags, the page) call ``command``, ``set_mode``, ``check``,
    ``load``, ``preview`` and ``status``, and follow ``events``.
    """

    def __init__(self, machine: Machine, bus: Fieldbus, journal: Journal,
                 limits: Limits | None = None, publish: Publish | None = None,
                 settings: Settings | None = None) -> None:  # fmt: skip
        self.machine = machine
        self.bus = bus
        self.journal = journal
        self.limits = limits or Limits()
        self.settings = settings or Settings()
        self.events = EventStream()
        if publish is not None:
            self.events.subscribe(lambda event: publish(event.wire()))
        self.packml = PackML()
        self.packml.on_change.append(self._on_state)
        self.program: Program | None = None
        self.program_id: int | None = None
        self.program_name: str | None = None
        self.twin: Twin | None = None
        self.dry_run: DryRun | None = None  # the loaded program's (None after a restart)
        self.last: Prediction | None = None  # the instruction done last (read in its event)
        self.faults = 0  # runs ended by an unexpected error
        self.seen = MachineView(bus, self.events.publish)  # the machine as last read
        self._writer = JournalWriter(journal)
        self._tasks = Tasks(self._task_failed)
        self._stop_cause = StopCause.NONE
        self._task: asyncio.Task[None] | None = None  # the run loop
        self._lock = asyncio.Lock()  # one command at a time, whoever sends it
        self._checking = asyncio.Lock()  # one program check at a time
        self._p = Progress()  # the loaded program's run
        self._recovering = ""  # why commands wait (a restart is being recovered)
        self._unrecorded: tuple[int, str, str] | None = None  # an outcome not yet journaled

    # ----- what the doors read -----
    @property
    def index(self) -> int:
        """Instructions done of the loaded program."""
        return self.twin.done if self.twin else 0

    @property
    def stop_cause(self) -> StopCause:
        return self._stop_cause

    @property
    def recovering(self) -> str:
        return self._recovering

    def allowed(self) -> list[Command]:
        """Exactly the commands that will be accepted now (as far as the last read knows)."""
        return [c for c in self.packml.allowed() if self._refusal(c) is None]

    def status(self) -> StatusSnapshot:
        """The controller as it stands, in one value."""
        program = self.program
        return StatusSnapshot(
            state=self.packml.state, mode=self.packml.mode, reason=self.packml.reason,
            stop_cause=self._stop_cause, program_id=self.program_id,
            program_name=self.program_name, index=self.index,
            count=len(program.instructions) if program is not None else 0,
            allowed=tuple(self.allowed()), bus=self.seen.status, recovering=self._recovering,
            next=None if self._p.finished else self.next_step(),  # an ended run runs nothing
        )  # fmt: skip

    def next_step(self) -> dict[str, Any] | None:
        """The instruction the loaded program runs next, with its line; None when none is left."""
        program, done = self.program, self.index
        if program is None or done >= len(program.instructions):
            return None
        line = program.lines[done] if done < len(program.lines) else 0
        return {"index": done + 1, "line": line, "instruction": program.instructions[done]}

    # ----- programs -----
    async def check(self, name: str, text: str,
                    cancel: threading.Event | None = None) -> tuple[Program, DryRun]:  # fmt: skip
        """Parse, validate and dry-run a program without loading it (any state).

        Runs in a worker thread, one check at a time (``Busy`` otherwise); setting ``cancel``
        stops it (``Cancelled``). The configured limits are checked on every instruction.
        """
        if self._checking.locked():
            raise Busy("another program is being checked: try again when it has finished")
        async with self._checking:
            try:
                return await asyncio.to_thread(check_program, self.machine, self.limits,
                                               self.settings.max_instructions, name, text,
                                               cancel)  # fmt: skip
            except Cancelled:
                log.info("check of %r cancelled", name)
                raise

    async def load(self, name: str, text: str, who: str = "",
                   cancel: threading.Event | None = None) -> int:  # fmt: skip
        """Check a program, then make it the one to run (in Stopped, Idle, Complete, Aborted)."""
        self._refuse_load()
        program, totals = await self.check(name, text, cancel)
        twin = await asyncio.to_thread(Twin.from_program, self.machine, program)
        async with self._lock:
            self._refuse_load()
            await self._record_late()
            pid = await self._writer.run(self.journal.add_program, name, text,
                                         len(program.instructions))  # fmt: skip
            self.program, self.program_id, self.program_name = program, pid, name
            self.dry_run, self.twin, self.last = totals, twin, None
            self._p = Progress()
            log.info("program %d %r loaded by %s: %d instructions", pid, name, who or "?",
                     len(program.instructions))  # fmt: skip
            self.events.publish(ProgramLoaded(pid, name, len(program.instructions)))
            self.seen.compare(self._at_rest())
        return pid

    def _refuse_load(self) -> None:
        if self._recovering:
            raise ControllerError(f"recovering: {self._recovering}")
        if self.packml.state not in _LOADABLE:
            raise ControllerError(f"a program cannot be loaded in state {self.packml.state.label}")

    async def preview(self) -> Preview:
        """The next instruction predicted on the controller's twin; the twin is not changed."""
        program, twin = self.program, self.twin
        if program is None or twin is None:
            raise ControllerError("no program is loaded")
        while True:
            step = self.next_step()
            if step is None:
                raise ControllerError(f"all {len(program.instructions)} instructions are done")
            done, line, instruction = step["index"] - 1, step["line"], step["instruction"]
            try:
                pred = await asyncio.to_thread(twin.predict, instruction)
            except TwinError as exc:
                return Preview(done + 1, line, instruction, None, str(exc), twin.occupancy,
                               twin.takeup)  # fmt: skip
            if pred.index == done + 1:  # else the run committed meanwhile: predict again
                break
        try:
            check_limits(pred, self.limits)
            refused = None
        except RefusedMove as exc:
            refused = str(exc)
        return Preview(pred.index, line, instruction, pred, refused, pred.occupancy, pred.takeup)

    # ----- commands -----
    async def command(self, command: Command, reason: str = "", who: str = "") -> State:
        """Apply a PackML command and run the acting state it enters to its end."""
        async with self._lock:
            said = f"{command.label} from {who or '?'}" + (f": {reason}" if reason else "")
            log.info("command %s", said)
            try:
                if command is not Command.ABORT:
                    await self._record_late()
                if command in _READS_FIRST:
                    await self._prepare(command)
                refusal = self._refusal(command)
                if refusal is not None:
                    raise ControllerError(refusal)
                state = self.packml.command(command, reason)
            except BwsdError as exc:
                log.warning("command %s refused: %s", said, exc)
                raise
            if command in (Command.STOP, Command.HOLD, Command.ABORT, Command.SUSPEND):
                self._stop_cause = StopCause.OPERATOR
            elif command is Command.RESET:
                self._stop_cause = StopCause.NONE
            await self._act(state)
            return self.packml.state

    async def set_mode(self, mode: UnitMode, who: str = "") -> None:
        """Change the unit mode (where PackML allows it), journaled and published."""
        async with self._lock:
            old = self.packml.mode
            try:
                self.packml.set_mode(mode)
            except BwsdError as exc:
                log.warning("mode %s from %s refused: %s", mode.label, who or "?", exc)
                raise
            if mode is not old:
                log.info("mode %s -> %s by %s", old.label, mode.label, who or "?")
                self._journal_later(self.journal.log_event, "mode",
                                    {"from": old.label, "to": mode.label, "by": who})  # fmt: skip
                self.events.publish(ModeChanged(old, mode))

    def _refusal(self, command: Command) -> str | None:
        """Why the controller refuses ``command`` beyond PackML's own table (None: it does not)."""
        if self._recovering and (command is not Command.ABORT or self.twin is None):
            return f"recovering: {self._recovering}"  # Abort once the twin is back
        if command is Command.START:
            if self.program is None:
                return "no program is loaded"
            if self._p.finished:
                return "the loaded program has ended: load a program to start"
        if command in _READS_FIRST and self.seen.status.estop:
            return f"the emergency stop is pressed: release it before {command.label}"
        if command in _RUNS and self.packml.accepts(command):
            if self._p.blocked:
                return f"cannot resume: {self._p.blocked} (Abort ends the program)"
            if self.seen.status.connected is False:
                return f"the machine cannot be read: {self.seen.status.last_error}"
            if self.seen.status.faulted:
                return f"axes {', '.join(self.seen.status.faulted)} report a fault"
            if self.seen.status.differs and self._p.rest is None:
                return ("the occupancy sensors differ from the twin at "
                        f"{_cells(self.seen.status.differs)}: nothing is moved")  # fmt: skip
        return None

    async def _prepare(self, command: Command) -> None:
        """Read the machine before a command that may lead to motion; settle a pending one."""
        if not self.packml.accepts(command):
            return  # PackML refuses it anyway, with what it accepts
        if self._recovering and self.twin is None:
            return
        state = await self.read_machine()
        if command in (Command.UNHOLD, Command.UNSUSPEND):
            await self._settle_pending(state)

    async def _act(self, state: State) -> None:
        """The work of the acting state just entered, then "state complete"."""
        if state is State.RESETTING:
            await self._guard(self.bus.reset_faults())
        elif state in (State.STARTING, State.UNHOLDING, State.UNSUSPENDING):
            self.packml.state_complete()
            self._task = self._tasks.spawn(self._run(), "run")
            return
        elif state in (State.ABORTING, State.STOPPING):
            await self._wait_run()
            await self._guard(self.bus.quick_stop())
            await self._outcome(ABORTED if state is State.ABORTING else STOPPED)
        elif state in (State.HOLDING, State.SUSPENDING):
            await self._wait_run()
            await self._outcome(HELD if state is State.HOLDING else SUSPENDED)
        elif state is State.CLEARING:
            await self._guard(self.bus.reset_faults())
        if self.packml.state is state:  # unless a command took over meanwhile
            self.packml.state_complete()

    async def _guard(self, action: Coroutine[Any, Any, None]) -> None:
        try:
            await action
        except FieldbusError as exc:
            self.seen.failed(exc)
            self.events.publish(Fault(str(exc), cause_of(exc)))

    async def _wait_run(self) -> None:
        """Let the running instruction finish (never cut a move the twin has not seen)."""
        task, self._task = self._task, None
        if task is not None and task is not asyncio.current_task():
            await asyncio.wait({task})

    async def wait(self) -> None:
        """Until the run loop stops (the program completes, holds or aborts)."""
        while (task := self._task) is not None:
            await asyncio.wait({task})
            if self._task is task:
                break

    @property
    def running(self) -> bool:
        """The run loop is moving the machine (or about to)."""
        return self._task is not None and not self._task.done()

    # ----- the run loop -----
    async def _run(self) -> None:
        """Run instructions while in Execute; every way out is logged and published."""
        assert self.program is not None and self.twin is not None
        try:
            await self._outcome(RUNNING)
            while self.packml.state is State.EXECUTE:
                if self.twin.done >= len(self.program.instructions):
                    await self._flush()
                    self.packml.execute_done()
                    await self._outcome(COMPLETE)
                    self.packml.state_complete()
                    log.info("program %s complete", self.program_id)
                    return
                outcome = await self._step()
                if not isinstance(outcome, Done):
                    await self._end(outcome)
                    return
        except Exception as exc:  # the catch-all: never a silent death
            self.faults += 1
            reason = f"internal error: {type(exc).__name__}: {exc}"
            log.exception("the run loop failed: %s", reason)
            await self._end(Aborted(StopCause.INTERNAL, reason))
        finally:
            try:
                await self._flush()
            except Exception as exc:
                log.error("the journal cannot record the last instruction done: %s", exc)
            if self._task is asyncio.current_task():
                self._task = None

    async def _end(self, outcome: Held | Aborted) -> None:
        """Hold or abort the run from inside it (unless a command already took over)."""
        try:
            await self._flush()  # the last instruction done is journaled before the stop
        except Exception as exc:
            log.error("the journal cannot record the last instruction done: %s", exc)
        self._stop_cause = outcome.cause
        self.events.publish(Fault(outcome.reason, outcome.cause))
        command = Command.HOLD if isinstance(outcome, Held) else Command.ABORT
        log.warning("%s: %s", "hold" if command is Command.HOLD else "abort", outcome.reason)
        if self.packml.state is not State.EXECUTE:
            return  # a command is acting on the run already; it decides what follows
        if self._task is asyncio.current_task():
            self._task = None
        try:
            await self._act(self.packml.command(command, outcome.reason))
        except Exception:
            log.exception("the %s after %r failed", command.label, outcome.reason)

    async def _step(self) -> Outcome:
        """One instruction end to end.

        The prediction runs in a worker thread while the journal records "started" together
        with the previous instruction's "done": the disk costs nothing on top of the
        prediction. Nothing moves before both the prediction and "started" are in.
        """
        assert self.program is not None and self.twin is not None and self.program_id
        index = self.twin.done + 1
        instruction = self.program.instructions[index - 1]
        begun = time.perf_counter()
        try:
            origin = await self._takeup_origin()
        except FieldbusError as exc:
            self.seen.failed(exc)
            return Held(cause_of(exc), _about(index, exc))
        doing = self._p.rest if self._p.journaled == index and self._p.rest else instruction
        self._p.rest = None
        steps = setpoints(self.machine, doing, self.twin.takeup, origin)
        predicting = asyncio.ensure_future(
            asyncio.to_thread(_predict, self.twin, instruction, self.limits)
        )
        timing = self._p.timing
        try:
            if self._p.journaled != index:
                payload = {"setpoints": [[[m.axis, m.target] for m in s] for s in steps],
                           "takeup_origin": origin}  # fmt: skip
                self._p.strokes = self._stroke_trace(doing)
                if self._p.strokes is not None:
                    payload["strokes"] = {str(k): v for k, v in self._p.strokes.items()}
                await self._writer.run(self.journal.started, self.program_id, index, payload,
                                       self._p.unjournaled)  # fmt: skip
                self._p.journaled, self._p.unjournaled = index, None
            else:
                await self._flush()
            timing["started_s"] = time.perf_counter() - begun
            pred, timing["predict_s"], timing["tables_s"] = await predicting
            timing["predicted_s"] = time.perf_counter() - begun
            self._p.pending = pred
        except (TwinError, RefusedMove) as exc:
            return Aborted(StopCause.REFUSED_MOVE, str(exc))
        finally:
            if not predicting.done():  # never leave the twin to a prediction nobody awaits
                await asyncio.wait({predicting})
        moving = time.perf_counter()
        try:
            for step in steps:
                await self.bus.execute(step)
            state = await self.bus.state()
            self._p.timing["bus_s"] = time.perf_counter() - moving
            self._verify(pred, state)
            self.seen.observe(state, None)  # the latest read: what the twin is compared with
        except (DriveFault, EStopError) as exc:
            self.seen.failed(exc)
            return Aborted(cause_of(exc), _about(index, exc))
        except (FieldbusError, Mismatch) as exc:
            if isinstance(exc, FieldbusError):
                self.seen.failed(exc)
            return Held(cause_of(exc), _about(index, exc))
        self._p.timing["step_s"] = time.perf_counter() - begun
        await self._commit(pred, index)
        return Done(index)

    def _stroke_trace(self, instruction: Instruction) -> dict[int, int] | None:
        """A weft's insert stroke count before it moves, as last read (the daemon owns the
        bus: nothing else strokes the insert); None for other instructions or without a
        counter."""
        if not isinstance(instruction, Weft):
            return None
        insert = axis_by_name(self.machine, "weft_insert").index
        count = self.bus.known(insert).strokes
        return None if count is None else {insert: count}

    async def _takeup_origin(self) -> int:
        """Where the take-up stood when this program started (read once, journaled)."""
        if self._p.origin is None:
            assert self.twin is not None
            state = await self.bus.state()
            self._p.origin = self._takeup(state) - round(self.twin.takeup * UM_PER_MM)
        return self._p.origin

    def _verify(self, pred: Prediction, state: MachineState) -> None:
        tolerance = self.bus.settings.position_tolerance
        verify(pred, state, self._takeup(state) - (self._p.origin or 0), tolerance)

    def _takeup(self, state: MachineState) -> int:
        """The take-up axis's position as the machine reports it (um)."""
        return state.axes[axis_by_name(self.machine, "takeup").index].position

    async def _commit(self, pred: Prediction, index: int) -> None:
        """Commit and describe the skeleton's change in one worker thread call (the twin's lock
        is never waited on here), publish. The journal's "done" goes to the disk with the
        next instruction's "started" (one write for both); ``_flush`` writes it alone when no
        instruction follows. A snapshot, when due, is taken now."""
        assert self.twin is not None and self.program_id
        twin, pid = self.twin, self.program_id
        committing = time.perf_counter()
        delta = await asyncio.to_thread(_commit_twin, twin, pred)
        self._p.timing["commit_s"] = time.perf_counter() - committing
        self.last = pred
        self._p.journaled, self._p.pending = None, None
        self._p.unjournaled = (index, {"contacts": len(pred.contacts)})
        timing, self._p.timing = self._p.timing, {}
        step = step_dict(self.next_step())
        self.events.publish(InstructionDone(pid, index, len(pred.contacts), len(pred.inserted),
                                            timing, delta, step))  # fmt: skip
        if self.settings.snapshot_every and index - self._p.snapped >= self.settings.snapshot_every:
            await self._flush()
            await self._snapshot()

    async def _flush(self) -> None:
        """Journal the last instruction's "done" now (when no instruction follows it); if the
        journal refuses, it is kept for the next try (``_record_late``)."""
        done = self._p.unjournaled
        if done is not None:
            assert self.program_id is not None
            await self._writer.run(self.journal.done, self.program_id, *done)
            self._p.unjournaled = None

    async def _snapshot(self) -> None:
        """Journal a snapshot of the twin (restart replays only what follows it)."""
        assert self.twin is not None and self.program_id
        twin, pid = self.twin, self.program_id
        data = await asyncio.to_thread(lambda: twin.snapshot().to_bytes())
        await self._writer.run(self.journal.save_snapshot, pid, twin.done, data)
        self._p.snapped = twin.done

    async def _outcome(self, outcome: str) -> None:
        """Journal the program's outcome; an ended program's outcome never changes again.

        A journal that cannot write is logged and published; the state machine goes on.
        """
        if self.program_id is None or self._p.finished:
            return
        record = (self.program_id, outcome, self.packml.reason)
        try:
            await self._writer.run(self.journal.set_outcome, *record)
        except Exception as exc:
            if outcome == RUNNING:
                raise
            log.error("the journal cannot record %s: %s (retried at the next command)", outcome,
                      exc)  # fmt: skip
            self.events.publish(Fault(f"the journal cannot record {outcome}: {exc}",
                                      StopCause.INTERNAL))  # fmt: skip
            self._unrecorded = record
        self._p.finished = outcome in (COMPLETE, ABORTED, STOPPED)

    async def _record_late(self) -> None:
        """Write what the journal could not take when it came (a full disk, a lock): the last
        instruction's "done", then the program's outcome."""
        if self._p.unjournaled is not None and not self.running:
            try:
                await self._flush()
            except Exception as exc:
                raise ControllerError(
                    f"the journal still cannot record instruction "
                    f"{self._p.unjournaled[0]} done: {exc}"
                ) from exc
        if self._unrecorded is None:
            return
        try:
            await self._writer.run(self.journal.set_outcome, *self._unrecorded)
        except Exception as exc:
            raise ControllerError(
                f"the journal still cannot record that program "
                f"{self._unrecorded[0]} is {self._unrecorded[1]}: {exc}"
            ) from exc
        log.info("program %d recorded %s", self._unrecorded[0], self._unrecorded[1])
        self._unrecorded = None

    def _on_state(self, old: State, new: State, cause: str) -> None:
        reason = self.packml.reason
        log.info("state %s -> %s (%s)", old.label, new.label, cause)
        self._journal_later(self.journal.log_state, int(new), new.label, reason)
        self.events.publish(StateChanged(old, new, cause, reason))
        if new in (State.IDLE, State.HELD, State.SUSPENDED, State.STOPPED, State.COMPLETE,
                   State.ABORTED):  # fmt: skip
            self.seen.compare(self._at_rest())

    # ----- the machine at rest -----
    async def read_machine(self) -> MachineState:
        """Read the machine now (connecting if needed); ControllerError when it cannot."""
        try:
            state = await self.seen.read()
        except FieldbusError as exc:
            raise ControllerError(f"the machine cannot be read: {exc}") from exc
        self.seen.observe(state, self._at_rest())
        return state

    def _at_rest(self) -> BoolGrid | None:
        """The twin's occupancy where the machine should show it now (None while moving)."""
        twin = self.twin
        if twin is None or self.running or self.packml.state is State.EXECUTE:
            return None
        return twin.occupancy >= 0

    async def watch(self) -> None:
        """Read the machine at rest every ``poll_interval``: e-stop, faults, occupancy; settle
        a pending instruction once the machine can be read. Runs until cancelled."""
        while True:
            await asyncio.sleep(self.settings.poll_interval)
            if self.running or self._lock.locked():
                continue
            async with self._lock:
                if self._recovering and self.twin is None:
                    continue
                try:
                    state = await self.read_machine()
                except ControllerError:
                    continue
                if self._p.journaled is not None and self.packml.state in (
                    State.HELD,
                    State.SUSPENDED,
                ):
                    await self._settle_pending(state)

    # ----- settling a pending instruction (after a fault hold or a restart) -----
    async def _settle_pending(self, state: MachineState) -> Settle | None:
        """Decide on the instruction started and not done, from ``state`` just read."""
        index = self._p.journaled
        if index is None or self.twin is None or self.program is None:
            return None
        instruction = self.program.instructions[index - 1]
        pred = self._p.pending
        if pred is None or pred.index != index:
            pred = await asyncio.to_thread(self.twin.predict, instruction)
            self._p.pending = pred
        before = Before(self.twin.occupancy >= 0,
                        (self._p.origin or 0) + round(self.twin.takeup * UM_PER_MM))  # fmt: skip
        decision = settle(instruction, pred, state, self._takeup(state), before,
                          self._p.origin or 0, self.bus.settings.position_tolerance,
                          self._p.strokes)  # fmt: skip
        self._p.blocked, self._p.rest = "", None
        then = "resume with Unhold"
        if decision.kind == "commit":
            await self._commit(pred, index)
            await self._flush()
            self.seen.observe(state, self._at_rest())
        elif decision.kind == "rerun":
            then = "Unhold runs it"
        elif decision.kind == "finish":
            assert decision.rest is not None
            self._p.rest = decision.rest
            then = f"Unhold moves the other {len(decision.rest.moves)}"
        else:
            self._p.blocked = decision.reason
            then = "Abort ends the program"
        if self.packml.state in (State.HELD, State.SUSPENDED):
            restarted = "restarted: " if self._stop_cause is StopCause.RESTART else ""
            self.packml.reason = f"{restarted}{decision.reason}: {then}"
        if self._recovering:
            self._recovering = ""
        log.info("pending instruction %d: %s (%s)", index, decision.kind, decision.reason)
        return decision

    # ----- restart -----
    def begin_recovery(self) -> str:
        """At start: if the journal has an active program, hold and rebuild it in the
        background (commands wait, the API answers). Says what it found."""
        record = self.journal.active_program()
        if record is None:
            return "nothing to recover"
        self.packml = _held_machine(self.packml, f"restarted at instruction {record.done}")
        self._stop_cause = StopCause.RESTART
        self._recovering = (f"rebuilding the twin of program {record.id} ({record.done} of "
                            f"{record.instructions} instructions done)")  # fmt: skip
        self._recovery = self._tasks.spawn(self._recover(record.id), "recovery")
        return f"restarted with program {record.id} {record.name!r} {record.outcome}: recovering"

    async def recover(self) -> str:
        """Rebuild the twin from the journal and settle a pending instruction if the machine
        can be read now. Says what it did."""
        said = self.begin_recovery()
        if said == "nothing to recover":
            return said
        assert self._recovery is not None
        await asyncio.wait({self._recovery})
        if self._p.journaled is not None:
            async with self._lock:
                try:
                    await self._settle_pending(await self.read_machine())
                except ControllerError as exc:
                    return f"{self.packml.reason}; {exc}"
        return self.packml.reason

    async def _recover(self, program_id: int) -> None:
        run = self._writer.run
        record = await run(self.journal.program, program_id)
        text = await run(self.journal.program_text, program_id)
        program = await asyncio.to_thread(parse_program, text, record.name)
        snap = await run(self.journal.latest_snapshot, program_id)
        twin = await asyncio.to_thread(rebuild, self.machine, program, record.done, snap)
        first = await run(self.journal.instructions, program_id, 0, 1)
        pending = await run(self.journal.pending, program_id)
        self.program, self.program_id, self.program_name = program, program_id, record.name
        self.twin, self._p.snapped = twin, snap[0] if snap else 0
        self._p.origin = int(first[0].started_payload.get("takeup_origin", 0)) if first else None
        self._p.journaled = pending.index if pending is not None else None
        self._p.strokes = _strokes_of(pending.payload) if pending is not None else None
        if pending is None:
            self._recovering = ""
            self.packml.reason = f"restarted at instruction {record.done}: resume with Unhold"
        else:
            self._recovering = (f"instruction {pending.index} started and not done: reading "
                                "the machine")  # fmt: skip
            self.packml.reason = f"restarted: instruction {pending.index} pending"
        log.info("program %d rebuilt at instruction %d%s", program_id, record.done,
                 f" from the snapshot at {snap[0]}" if snap else "")  # fmt: skip
        self.seen.compare(self._at_rest())

    # ----- tasks -----
    def _task_failed(self, name: str, error: BaseException) -> None:
        self.faults += 1
        if name == "recovery":
            self._recovering = f"recovery failed: {error} (see the log)"
        self.events.publish(Fault(f"{name} failed: {error}", StopCause.INTERNAL))

    def _journal_later(self, fn: Callable[..., Any], *args: Any) -> None:
        """A journal write nobody waits for (a state or event log), in order with the rest."""

        async def write() -> None:
            try:
                await self._writer.run(fn, *args)
            except Exception as exc:
                log.error("the journal cannot record a %s: %s", getattr(fn, "__name__", fn), exc)

        self._tasks.spawn(write(), "journal")

    async def close(self) -> None:
        """Stop the background tasks, finish the journal's queued writes and close it."""
        for task in self._tasks.named("recovery"):
            task.cancel()
        pending = self._tasks.named("journal")
        if pending:
            await asyncio.wait(pending)
        await self._writer.close()


def _predict(twin: Twin, instruction: Instruction,
             limits: Limits) -> tuple[Prediction, float, float]:  # fmt: skip
    """Predict and check the limits (in a worker thread); the tables events read are built.
    Also the seconds of the twin's own predict, and of the checks and tables after it."""
    begun = time.perf_counter()
    pred = twin.predict(instruction)
    took = time.perf_counter() - begun
    check_limits(pred, limits)
    _ = pred.contacts, pred.inserted
    return pred, took, time.perf_counter() - begun - took


def _commit_twin(twin: Twin, pred: Prediction) -> dict[str, Any]:
    """Commit ``pred`` and describe the skeleton's change (in a worker thread)."""
    twin.commit(pred)
    return delta_from(pred, *committed_parts(twin, pred))


def _strokes_of(payload: dict[str, Any]) -> dict[int, int] | None:
    """The insert stroke counts a started payload holds (None: none journaled)."""
    strokes = payload.get("strokes")
    if not isinstance(strokes, dict):
        return None
    return {int(axis): int(count) for axis, count in strokes.items()}


def _cells(cells: tuple[tuple[int, int], ...]) -> str:
    if cells == ((-1, -1),):
        return "every cell (the grids differ in shape)"
    return ", ".join(f"({r}, {c})" for r, c in cells)


def _about(index: int, error: Exception) -> str:
    """The reason of a stop, naming the instruction once."""
    text = str(error)
    return text if text.startswith(f"instruction {index}:") else f"instruction {index}: {text}"


def _held_machine(current: PackML, reason: str) -> PackML:
    """A state machine in Held (a restarted run resumes by Unhold), with the same listeners."""
    machine = PackML(State.HELD, current.mode)
    machine.reason = reason
    machine.on_change.extend(current.on_change)
    return machine
