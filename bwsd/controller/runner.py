"""The run loop: every instruction predicted, checked, journaled, moved, verified, committed.

One instruction (docs/packml.md, the project's DESIGN):
1. the twin predicts it, off the event loop; a limit refuses it (Abort with the reason);
2. the journal records "started" (on disk before anything moves);
3. the bus moves the actuators and waits for them; a drive fault or the e-stop aborts,
   a timeout or a lost connection holds;
4. the read-back is compared with the prediction (a mismatch holds, nothing committed);
5. the twin commits, the journal records "done", an event is published.

On start ``recover`` rebuilds the twin from the journal: the done instructions are replayed;
an instruction started and not done is completed if the machine shows its predicted result,
and otherwise reported (Held, with the reason), never guessed.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from bwsd.controller.packml import Command, PackML, State, UnitMode
from bwsd.controller.plan import Limits, Mismatch, RefusedMove, check_limits, setpoints, verify
from bwsd.errors import BwsdError, TwinError
from bwsd.fieldbus.axes import UM_PER_MM, axis_by_name
from bwsd.fieldbus.base import (
    BoolGrid,
    DriveFault,
    EStopError,
    Fieldbus,
    FieldbusError,
    MachineState,
)
from bwsd.journal import ABORTED, COMPLETE, FINAL, HELD, RUNNING, STOPPED, Journal
from bwsd.program import parse_program, validate
from bwsd.twin import Machine, Prediction, Program, Shift, Twin
from bwsd.twin.instructions import Instruction

Publish = Callable[[dict[str, Any]], None]


class ControllerError(BwsdError):
    """A request the controller cannot take in its present state."""


@dataclass(frozen=True)
class DryRun:
    """What a program makes when the twin runs it to the end."""

    instructions: int
    contacts: int
    yarns: int
    nodes: int
    takeup: float  # mm


class Controller:
    """The one place that decides: PackML state, the loaded program, the twin, the run."""

    def __init__(self, machine: Machine, bus: Fieldbus, journal: Journal,
                 limits: Limits | None = None, publish: Publish | None = None) -> None:  # fmt: skip
        self.machine = machine
        self.bus = bus
        self.journal = journal
        self.limits = limits or Limits()
        self.publish = publish or (lambda event: None)
        self.packml = PackML()
        self.packml.on_change.append(self._on_state)
        self.program: Program | None = None
        self.program_id: int | None = None
        self.twin: Twin | None = None
        self.dry_run: DryRun | None = None  # the loaded program's
        self.last: Prediction | None = None  # the instruction done last (read in its event)
        self.stop_cause: str = ""  # class of the error that last stopped a run ("" operator)
        self._task: asyncio.Task[None] | None = None
        self._lock = asyncio.Lock()  # one command at a time, whoever sends it
        self._resume: int | None = None  # a journaled instruction the machine never ran
        self._remaining: Shift | None = None  # the lines of that instruction still to move
        self._blocked = ""  # why the run cannot resume (a pending instruction not settled)
        self._timing: dict[str, float] = {}  # seconds of the running instruction, published
        self._finished = False  # the loaded program reached complete, aborted or stopped
        self._origin: int | None = None  # take-up position (um) where the program started

    # ----- programs -----
    async def load(self, name: str, text: str) -> int:
        """Parse, validate and dry-run a program, then make it the one to run."""
        async with self._lock:
            return await self._load(name, text)

    async def check(self, name: str, text: str) -> tuple[Program, DryRun]:
        """Parse, validate and dry-run a program without loading it (any state)."""
        program = parse_program(text, name)
        validate(program, self.machine, name)
        return program, await asyncio.to_thread(_dry_run, self.machine, program, name)

    async def _load(self, name: str, text: str) -> int:
        if self.packml.state not in (State.STOPPED, State.IDLE, State.COMPLETE, State.ABORTED):
            raise ControllerError(f"a program cannot be loaded in state {self.packml.state.label}")
        program, totals = await self.check(name, text)
        pid = await asyncio.to_thread(self.journal.add_program, name, text,
                                      len(program.instructions))  # fmt: skip
        self.program, self.program_id, self.dry_run = program, pid, totals
        self.twin = Twin.from_program(self.machine, program)
        self._resume, self._blocked, self._finished = None, "", False
        self._origin = None
        self.publish({"event": "program", "program_id": pid, "name": name,
                      "count": len(program.instructions), "at": time.time()})  # fmt: skip
        return pid

    @property
    def index(self) -> int:
        """Instructions done of the loaded program."""
        return self.twin.done if self.twin else 0

    # ----- commands -----
    async def command(self, command: Command, reason: str = "") -> State:
        """Apply a PackML command and run the acting state it enters to its end."""
        async with self._lock:
            if command is Command.START and self.program is None:
                raise ControllerError("no program is loaded")
            if command is Command.START and self._finished:
                raise ControllerError("the loaded program has ended: load a program to start")
            if command is Command.UNHOLD and self._blocked:
                raise ControllerError(f"cannot resume: {self._blocked} (Abort ends the program)")
            if command is Command.RESET:
                self.stop_cause = ""
            state = self.packml.command(command, reason)
            await self._act(state)
            return self.packml.state

    def set_mode(self, mode: UnitMode) -> None:
        """Change the unit mode (where PackML allows it), journaled and published."""
        old = self.packml.mode
        self.packml.set_mode(mode)
        if mode is not old:
            self.journal.log_event("mode", {"from": old.label, "to": mode.label})
            self.publish({"event": "mode", "from": old.label, "to": mode.label})

    async def _act(self, state: State) -> None:
        if state is State.RESETTING:
            await self._guard(self.bus.reset_faults())
        elif state in (State.STARTING, State.UNHOLDING, State.UNSUSPENDING):
            self.packml.state_complete()
            self._task = asyncio.create_task(self._run())
            return
        elif state in (State.ABORTING, State.STOPPING):
            await self._settle()
            await self._guard(self.bus.quick_stop())
            self._outcome(ABORTED if state is State.ABORTING else STOPPED)
        elif state in (State.HOLDING, State.SUSPENDING):
            await self._settle()
            self._outcome(HELD)
        elif state is State.CLEARING:
            await self._guard(self.bus.reset_faults())
        if self.packml.state in (State.RESETTING, State.ABORTING, State.STOPPING,
                                 State.HOLDING, State.SUSPENDING, State.CLEARING):  # fmt: skip
            self.packml.state_complete()

    async def _guard(self, action: Any) -> None:
        try:
            await action
        except FieldbusError as exc:
            self.publish({"event": "fault", "reason": str(exc)})

    async def _settle(self) -> None:
        """Let the running instruction finish (never cut a move the twin has not seen)."""
        task, self._task = self._task, None
        if task is not None and task is not asyncio.current_task():
            await task

    async def wait(self) -> None:
        """Until the run loop stops (the program completes, holds or aborts)."""
        if self._task is not None:
            await self._task

    # ----- the run loop -----
    async def _run(self) -> None:
        assert self.program is not None and self.twin is not None
        self._outcome(RUNNING)
        while self.packml.state is State.EXECUTE:
            if self.twin.done >= len(self.program.instructions):
                self.packml.execute_done()
                self._outcome(COMPLETE)
                self.packml.state_complete()
                return
            if not await self._step():
                return

    async def _step(self) -> bool:
        """One instruction end to end; False when it stopped the run."""
        assert self.program is not None and self.twin is not None and self.program_id
        index = self.twin.done + 1
        instruction = self.program.instructions[index - 1]
        begun = time.perf_counter()
        try:
            pred = await asyncio.to_thread(self.twin.predict, instruction)
            self._timing = {"predict_s": time.perf_counter() - begun}
            check_limits(pred, self.limits)
        except (TwinError, RefusedMove) as exc:
            return await self._stop(Command.ABORT, str(exc), exc)
        try:
            origin = await self._takeup_origin()
        except FieldbusError as exc:
            return await self._stop(Command.HOLD, _about(index, exc), exc)
        doing = self._remaining if self._resume == index and self._remaining else instruction
        self._remaining = None
        steps = setpoints(self.machine, doing, self.twin.takeup, origin)
        payload = {"setpoints": [[[m.axis, m.target] for m in s] for s in steps],
                   "contacts": len(pred.contacts), "takeup_origin": origin}  # fmt: skip
        if self._resume == index:
            self._resume = None  # journaled as started before the restart
        else:
            await asyncio.to_thread(self.journal.started, self.program_id, index, payload)
        try:
            for step in steps:
                await self.bus.execute(step)
            state = await self.bus.state()
            self._verify(pred, state)
        except (DriveFault, EStopError) as exc:
            return await self._stop(Command.ABORT, _about(index, exc), exc)
        except (FieldbusError, Mismatch) as exc:
            return await self._stop(Command.HOLD, _about(index, exc), exc)
        self._timing["step_s"] = time.perf_counter() - begun
        await self._commit(pred, index)
        return True

    async def _takeup_origin(self) -> int:
        """Where the take-up stood when this program started (read once, journaled)."""
        if self._origin is None:
            assert self.twin is not None
            state = await self.bus.state()
            self._origin = self._takeup(state) - round(self.twin.takeup * UM_PER_MM)
        return self._origin

    def _verify(self, pred: Prediction, state: MachineState) -> None:
        tolerance = self.bus.settings.position_tolerance
        verify(pred, state, self._takeup(state) - (self._origin or 0), tolerance)

    def _takeup(self, state: MachineState) -> int:
        """The take-up axis's position as the machine reports it (um)."""
        return state.axes[axis_by_name(self.machine, "takeup").index].position

    async def _commit(self, pred: Prediction, index: int) -> None:
        assert self.twin is not None and self.program_id
        self.twin.commit(pred)
        self.last = pred
        await asyncio.to_thread(self.journal.done, self.program_id, index,
                                {"contacts": len(pred.contacts)})  # fmt: skip
        self.publish({"event": "instruction", "index": index, "contacts": len(pred.contacts),
                      "inserted": len(pred.inserted), "at": time.time(),
                      **self._timing})  # fmt: skip
        self._timing = {}

    async def _stop(self, command: Command, reason: str, error: Exception) -> bool:
        self.stop_cause = type(error).__name__
        self.publish({"event": "fault", "reason": reason, "cause": self.stop_cause})
        self._task = None
        self.packml.command(command, reason)
        await self._act(self.packml.state)
        return False

    def _outcome(self, outcome: str) -> None:
        """Journal the program's outcome; an ended program's outcome never changes again."""
        if self.program_id is None or self._finished:
            return
        self.journal.set_outcome(self.program_id, outcome, self.packml.reason)
        self._finished = outcome in FINAL

    def _on_state(self, old: State, new: State, cause: str) -> None:
        self.journal.log_state(int(new), new.label, self.packml.reason)
        self.publish({"event": "state", "from": old.label, "to": new.label, "cause": cause,
                      "at": time.time()})  # fmt: skip

    # ----- restart -----
    async def recover(self) -> str:
        """Rebuild the twin from the journal; settle a pending instruction. Says what it did."""
        record = await asyncio.to_thread(self.journal.active_program)
        if record is None:
            return "nothing to recover"
        text = await asyncio.to_thread(self.journal.program_text, record.id)
        program = parse_program(text, record.name)
        twin = Twin.from_program(self.machine, program)
        for instruction in program.instructions[: record.done]:
            await asyncio.to_thread(twin.advance, instruction)
        self.program, self.program_id, self.twin = program, record.id, twin
        first = await asyncio.to_thread(self.journal.instructions, record.id, 0, 1)
        self._origin = int(first[0].started_payload.get("takeup_origin", 0)) if first else None
        self.packml = _held_machine(self.packml)
        pending = await asyncio.to_thread(self.journal.pending, record.id)
        if pending is None:
            return self._hold(f"restarted at instruction {record.done}: resume with Unhold")
        return await self._settle_pending(program, twin, pending.index)

    def _hold(self, reason: str) -> str:
        self.packml.command(Command.HOLD, reason)
        self._outcome(HELD)
        self.packml.state_complete()
        return reason

    async def _settle_pending(self, program: Program, twin: Twin, index: int) -> str:
        """Complete a started instruction from what the machine shows, or report it.

        The machine shows the predicted result: the move happened, commit it. It shows the
        state before the move: the move never started, and Unhold runs it. Anything else is
        for the operator: Unhold is refused until the journal is settled (Abort ends it).
        """
        before = twin.occupancy >= 0, (self._origin or 0) + round(twin.takeup * UM_PER_MM)
        pred = await asyncio.to_thread(twin.predict, program.instructions[index - 1])
        state = await self.bus.state()
        instruction = program.instructions[index - 1]
        try:
            self._verify(pred, state)
        except Mismatch as exc:
            if self._shows(state, *before):
                self._resume = index
                return self._hold(f"restarted: instruction {index} started, the machine has "
                                  "not moved: Unhold runs it")  # fmt: skip
            rest = _lines_left(instruction, state.occupancy, before[0], pred.occupancy >= 0)
            if rest is not None and self._shows(state, state.occupancy, before[1]):
                self._resume, self._remaining = index, rest
                left = len(rest.moves)
                return self._hold(f"restarted: instruction {index} started, some of its lines "
                                  f"moved: Unhold moves the other {left}")  # fmt: skip
            self._blocked = f"instruction {index} started and not done: {exc}"
            return self._hold(f"restarted: {self._blocked}")
        await self._commit(pred, index)
        return self._hold(f"restarted: instruction {index} completed from the read-back")

    def _shows(self, state: MachineState, occupancy: Any, takeup_um: int) -> bool:
        """The machine shows this occupancy and take-up (within the position tolerance)."""
        tolerance = self.bus.settings.position_tolerance
        same_cells = bool((state.occupancy == occupancy).all())
        return same_cells and abs(self._takeup(state) - takeup_um) <= tolerance


def _lines_left(instruction: Instruction, machine: BoolGrid, before: BoolGrid,
                after: BoolGrid) -> Shift | None:  # fmt: skip
    """The entries of a shift whose line is still as before, when every other listed line
    shows its predicted result and no other line moved; None otherwise (or for no shift)."""
    if not isinstance(instruction, Shift):
        return None
    if instruction.axis == "col":  # work on columns as rows
        machine, before, after = machine.T, before.T, after.T
    rest = []
    for line, k in instruction.moves:
        if (machine[line] == before[line]).all():
            rest.append((line, k))
        elif not (machine[line] == after[line]).all():
            return None
    listed = {line for line, _ in instruction.moves}
    untouched = [i for i in range(machine.shape[0]) if i not in listed]
    if not (machine[untouched] == before[untouched]).all():
        return None
    return Shift(instruction.axis, tuple(rest)) if rest else None


def _about(index: int, error: Exception) -> str:
    """The reason of a stop, naming the instruction once."""
    text = str(error)
    return text if text.startswith(f"instruction {index}:") else f"instruction {index}: {text}"


def _held_machine(current: PackML) -> PackML:
    """A state machine in Execute, ready to be held (a restarted run resumes by Unhold)."""
    machine = PackML(State.EXECUTE, current.mode)
    machine.on_change.extend(current.on_change)
    return machine


def _dry_run(machine: Machine, program: Program, name: str) -> DryRun:
    from bwsd.twin import simulate

    try:
        twin = simulate(machine, program)
    except TwinError as exc:
        raise ControllerError(f"{name}: {exc}") from exc
    return DryRun(len(program.instructions), twin.contact_count, twin.yarn_count,
                  twin.node_count, twin.takeup)  # fmt: skip
