"""The run loop: the loaded program's instructions, one at a time, while the facade says so.

One instruction (docs/packml.md):
1. the twin predicts it in a worker thread (the kernel runs without the interpreter lock)
   while the journal records "started" (with the last instruction's "done"); the twin or
   a limit refuses it: Aborted with the reason, nothing moved;
2. the bus moves the actuators and waits for them; a drive fault or the e-stop aborts,
   a timeout, a lost connection, a read-back mismatch, a fault of an axis placing the weft
   inserter or a journal that cannot write holds;
3. the twin commits (``Job.commit``): the journal's "done", the event, a snapshot when due.

The loop decides nothing about PackML: it returns how it ended (``Finished``, ``Held``,
``Aborted`` or ``Paused`` when the facade stopped asking for more) and the facade acts on it.
``cut`` ends it at once, mid-stroke if it is moving: whatever it waits for is cancelled,
nothing after the cut moves, and the instruction is settled later from a read-back.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from bwsd.controller.job import Job
from bwsd.controller.plan import Limits, Mismatch, RefusedMove, check_limits, setpoints, verify
from bwsd.controller.recorder import Recorder
from bwsd.controller.settling import takeup_of
from bwsd.controller.status import Event, StopCause, cause_of
from bwsd.errors import TwinError
from bwsd.fieldbus.axes import POSITIONING, UM_PER_MM, axis_by_name
from bwsd.fieldbus.base import FAULT_ESTOP, DriveFault, EStopError, Fieldbus, FieldbusError
from bwsd.journal import JournalError
from bwsd.twin import Prediction, Twin, Weft
from bwsd.twin.instructions import Instruction

log = logging.getLogger("bwsd.controller")
T = TypeVar("T")


@dataclass(frozen=True)
class Finished:
    """Every instruction is done."""


@dataclass(frozen=True)
class Paused:
    """The facade stopped asking for instructions (Hold, Suspend), or cut the run."""


@dataclass(frozen=True)
class Held:
    cause: StopCause
    reason: str


@dataclass(frozen=True)
class Aborted:
    cause: StopCause
    reason: str


Ending = Finished | Paused | Held | Aborted


class Cut(Exception):
    """The run was cut (Abort, Stop): nothing more moves."""


@dataclass(frozen=True)
class Parts:
    """What the run loop works with."""

    bus: Fieldbus
    recorder: Recorder
    limits: Limits
    snapshot_every: int
    publish: Callable[[Event], None]
    observe: Callable[[Any], None]  # a good read-back while moving (MachineView.observe)
    failed: Callable[[FieldbusError], None]  # a failed one (MachineView.failed)


class RunLoop:
    """Runs ``job`` while ``proceed()`` is true."""

    def __init__(self, job: Job, parts: Parts, proceed: Callable[[], bool]) -> None:
        self.job = job
        self.parts = parts
        self._proceed = proceed
        self._cut = False
        self._waiting: asyncio.Future[Any] | None = None

    def cut(self) -> None:
        """End the run at once: what it waits for (a stroke, a read, the journal) is
        cancelled; an instruction being committed is committed first."""
        self._cut = True
        if self._waiting is not None:
            self._waiting.cancel()

    async def run(self) -> Ending:
        try:
            while self._proceed() and not self._cut:
                if self.job.complete:
                    await self.parts.recorder.flush()
                    return Finished()
                ending = await self._step()
                if ending is not None:
                    return ending
            return Paused()
        except Cut:
            return Paused()
        except JournalError as exc:
            return Held(
                StopCause.JOURNAL,
                f"the journal cannot record: {exc}: free its disk "
                "(or end what holds its lock), then Unhold",
            )

    async def _step(self) -> Held | Aborted | None:
        """One instruction end to end; None when it is done."""
        job, parts = self.job, self.parts
        index = job.done + 1
        instruction = job.instruction(index)
        begun = time.perf_counter()
        timing: dict[str, float] = {}
        try:
            origin = await self._cuttable(self._origin())
        except FieldbusError as exc:
            parts.failed(exc)
            return Held(cause_of(exc), _about(index, exc))
        pending = job.pending if job.pending is not None and job.pending.index == index else None
        doing = pending.rest if pending is not None and pending.rest is not None else instruction
        steps = setpoints(job.twin.machine, doing, job.twin.takeup, origin)
        predicting = asyncio.ensure_future(
            asyncio.to_thread(_predict, job.twin, instruction, parts.limits)
        )
        try:
            if pending is None:
                strokes = self._strokes(instruction)
                payload = _started(steps, origin, strokes)
                await self._cuttable(parts.recorder.started(job.program_id, index, payload))
                job.start(index, strokes)
            else:
                await self._cuttable(parts.recorder.flush())
            timing["started_s"] = time.perf_counter() - begun
            pred, timing["predict_s"], timing["tables_s"] = await self._cuttable(predicting)
            timing["predicted_s"] = time.perf_counter() - begun
            job.predicted(pred)
        except (TwinError, RefusedMove) as exc:
            return Aborted(StopCause.REFUSED_MOVE, str(exc))
        except JournalError as exc:
            return Held(
                StopCause.JOURNAL,
                _about(
                    index,
                    f"the journal cannot record it: {exc}: "
                    "free its disk (or end what holds its lock), then Unhold",
                ),
            )
        finally:
            if not predicting.done():  # never leave the twin to a prediction nobody awaits
                predicting.cancel()
        moving = time.perf_counter()
        try:
            for step in steps:
                await self._cuttable(parts.bus.execute(step))
            state = await self._cuttable(parts.bus.state())
            timing["bus_s"] = time.perf_counter() - moving
            verify(
                pred,
                state,
                takeup_of(job, state) - (job.origin or 0),
                parts.bus.settings.position_tolerance,
            )
            parts.observe(state)
        except (DriveFault, EStopError) as exc:
            parts.failed(exc)
            if placing_fault(exc):
                return Held(cause_of(exc), _about(index, f"{exc}: the weft was not inserted"))
            return Aborted(cause_of(exc), _about(index, exc))
        except FieldbusError as exc:
            parts.failed(exc)
            return Held(cause_of(exc), _about(index, exc))
        except Mismatch as exc:
            return Held(StopCause.MISMATCH, _about(index, exc))
        timing["step_s"] = time.perf_counter() - begun
        await job.commit(pred, parts.recorder, parts.publish, parts.snapshot_every, timing)
        return None

    async def _cuttable(self, waited: Awaitable[T]) -> T:
        """Wait for ``waited`` unless the run is cut meanwhile (then Cut, and it is cancelled)."""
        if self._cut:
            if isinstance(waited, asyncio.Future):
                waited.cancel()
            elif asyncio.iscoroutine(waited):
                waited.close()
            raise Cut
        future = asyncio.ensure_future(waited)
        self._waiting = future
        try:
            return await future
        except asyncio.CancelledError:
            task = asyncio.current_task()
            if self._cut and (task is None or not task.cancelling()):
                raise Cut from None
            raise
        finally:
            self._waiting = None

    async def _origin(self) -> int:
        """Where the take-up stood when this program started (read once, journaled)."""
        job = self.job
        if job.origin is None:
            state = await self.parts.bus.state()
            job.origin = takeup_of(job, state) - round(job.twin.takeup * UM_PER_MM)
        return job.origin

    def _strokes(self, instruction: Instruction) -> dict[int, int] | None:
        """A weft's insert stroke count before it moves, as last read (the daemon owns the
        bus: nothing else strokes the insert); None for other instructions or without a
        counter."""
        if not isinstance(instruction, Weft):
            return None
        insert = axis_by_name(self.job.twin.machine, "weft_insert").index
        count = self.parts.bus.known(insert).strokes
        return None if count is None else {insert: count}


def placing_fault(error: FieldbusError) -> bool:
    """A fault of an axis that places the weft inserter (not the e-stop): the weft did not go
    in and no case moved, so the run holds rather than aborts, and Unhold places it again."""
    return (
        isinstance(error, DriveFault)
        and error.axis.kind in POSITIONING
        and error.code != FAULT_ESTOP
    )


def _started(steps: list[Any], origin: int, strokes: dict[int, int] | None) -> dict[str, Any]:
    """The "started" record: the set-points, the take-up origin, a weft's stroke counts."""
    payload: dict[str, Any] = {
        "setpoints": [[[m.axis, m.target] for m in s] for s in steps],
        "takeup_origin": origin,
    }
    if strokes is not None:
        payload["strokes"] = {str(k): v for k, v in strokes.items()}
    return payload


def _predict(
    twin: Twin, instruction: Instruction, limits: Limits
) -> tuple[Prediction, float, float]:
    """Predict and check the limits (in a worker thread); the tables events read are built.
    Also the seconds of the twin's own predict, and of the checks and tables after it."""
    begun = time.perf_counter()
    pred = twin.predict(instruction)
    took = time.perf_counter() - begun
    check_limits(pred, limits)
    _ = pred.contacts, pred.inserted
    return pred, took, time.perf_counter() - begun - took


def about(index: int, error: Exception | str) -> str:
    """The reason of a stop, naming the instruction once."""
    text = str(error)
    return text if text.startswith(f"instruction {index}:") else f"instruction {index}: {text}"


_about = about
