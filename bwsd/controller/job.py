"""The loaded program: its text, its twin and where its run stands.

A ``Job`` is what the controller has loaded, run, stopped or restored from the journal; the
run loop, the settling of a cut instruction and a restart change it only through its
methods, and ``commit`` is the one place an instruction becomes done (the twin commits, the
journal is told, the event is published).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from bwsd.controller.errors import ControllerError
from bwsd.controller.plan import Limits, RefusedMove, check_limits
from bwsd.controller.programs import DryRun, step_dict
from bwsd.controller.recorder import Recorder
from bwsd.controller.status import Event, InstructionDone
from bwsd.errors import TwinError
from bwsd.export.skeleton_json import committed_parts, delta_from
from bwsd.fieldbus.axes import UM_PER_MM
from bwsd.twin import Prediction, Program, Twin
from bwsd.twin.instructions import Instruction


@dataclass(frozen=True)
class Pending:
    """An instruction journaled as started and not done, and what is known of it."""

    index: int
    strokes: dict[int, int] | None = None  # a weft's insert stroke counts before it
    rest: Instruction | None = None  # what is still to move: a cut shift's lines, a take-up
    blocked: str = ""  # why it cannot be settled (a resume is refused)
    decided: str = ""  # what the last read-back showed, in words


@dataclass(frozen=True)
class Preview:
    """The next instruction predicted on the job's twin (nothing committed)."""

    index: int
    line: int
    instruction: Instruction
    prediction: Prediction | None  # None when the twin refuses it
    refused: str | None
    occupancy: Any
    takeup: float


class Job:
    """One loaded program and its run."""

    def __init__(
        self,
        program: Program,
        program_id: int,
        name: str,
        twin: Twin,
        dry_run: DryRun | None = None,
    ) -> None:
        self.program = program
        self.program_id = program_id
        self.name = name
        self.twin = twin
        self.dry_run = dry_run  # the check's totals (None after a restart)
        self.origin: int | None = None  # take-up position (um) where the program started
        self.snapped = 0  # instructions done at the last snapshot
        self.ended = ""  # the journal's outcome once the run is over (complete, aborted...)
        self.pending: Pending | None = None
        self._prediction: Prediction | None = None  # the pending instruction's, once made

    @property
    def done(self) -> int:
        return self.twin.done

    @property
    def count(self) -> int:
        return len(self.program.instructions)

    @property
    def complete(self) -> bool:
        return self.done >= self.count

    def instruction(self, index: int) -> Instruction:
        """Instruction ``index`` (1-based)."""
        return self.program.instructions[index - 1]

    def next_step(self) -> dict[str, Any] | None:
        """The instruction that runs next, with its line; None when none is left."""
        done = self.done
        if done >= self.count:
            return None
        return {
            "index": done + 1,
            "line": self.program.line_of(done + 1),
            "instruction": self.program.instructions[done],
        }

    def takeup_um(self) -> int:
        """Where the take-up axis stands when the twin's take-up is done (um)."""
        return (self.origin or 0) + round(self.twin.takeup * UM_PER_MM)

    def start(self, index: int, strokes: dict[int, int] | None) -> None:
        """Instruction ``index`` is journaled as started."""
        self.pending = Pending(index, strokes)
        self._prediction = None

    def settled(self, pending: Pending | None) -> None:
        """What a read-back decided about the pending instruction."""
        self.pending = pending

    def predicted(self, prediction: Prediction) -> None:
        """The pending instruction's prediction (kept for its settling)."""
        self._prediction = prediction

    async def prediction(self) -> Prediction:
        """The pending instruction's prediction on the committed twin (made once)."""
        assert self.pending is not None
        pred = self._prediction
        if pred is None or pred.index != self.pending.index or pred.index != self.done + 1:
            instruction = self.instruction(self.pending.index)
            pred = await asyncio.to_thread(self.twin.predict, instruction)
            self._prediction = pred
        return pred

    async def preview(self, limits: Limits) -> Preview:
        """The next instruction predicted on the twin (in a worker thread), the limits
        checked; the twin is not changed. ControllerError when none is left."""
        while True:
            step = self.next_step()
            if step is None:
                raise ControllerError(f"all {self.count} instructions are done")
            index, line, instruction = step["index"], step["line"], step["instruction"]
            try:
                pred = await asyncio.to_thread(self.twin.predict, instruction)
            except TwinError as exc:
                twin = self.twin
                return Preview(
                    index, line, instruction, None, str(exc), twin.occupancy, twin.takeup
                )
            if pred.index == index:  # else the run committed meanwhile: predict again
                break
        try:
            check_limits(pred, limits)
            refused = None
        except RefusedMove as exc:
            refused = str(exc)
        return Preview(pred.index, line, instruction, pred, refused, pred.occupancy, pred.takeup)

    async def commit(
        self,
        pred: Prediction,
        recorder: Recorder,
        publish: Callable[[Event], None],
        snapshot_every: int,
        timing: dict[str, float] | None = None,
    ) -> None:
        """Instruction ``pred.index`` is done: the twin commits it and describes its change (in
        one worker thread call), the journal gets "done" (with the next "started", or by
        the next flush), the event goes out, and a snapshot is taken when due."""
        committing = time.perf_counter()
        delta = await asyncio.to_thread(_commit_twin, self.twin, pred)
        timing = dict(timing or {}, commit_s=time.perf_counter() - committing)
        index = pred.index
        self.pending, self._prediction = None, None
        recorder.done(self.program_id, index, {"contacts": len(pred.contacts)})
        publish(
            InstructionDone(
                self.program_id,
                index,
                len(pred.contacts),
                len(pred.inserted),
                timing,
                delta,
                step_dict(self.next_step()),
            )
        )
        if snapshot_every and not self.ended and index - self.snapped >= snapshot_every:
            await recorder.flush()
            await self.snapshot(recorder)

    async def snapshot(self, recorder: Recorder) -> None:
        """Journal a snapshot of the twin (a restart replays only what follows it)."""
        twin = self.twin
        data = await asyncio.to_thread(lambda: twin.snapshot().to_bytes())
        await recorder.write(recorder.journal.save_snapshot, self.program_id, twin.done, data)
        self.snapped = twin.done


def _commit_twin(twin: Twin, pred: Prediction) -> dict[str, Any]:
    """Commit ``pred`` and describe the skeleton's change (in a worker thread)."""
    twin.commit(pred)
    return delta_from(pred, *committed_parts(twin, pred))
