"""After a restart: the program the journal says was loaded, restored with its twin.

``restored_state`` says in which PackML state the daemon comes back, and why, from the
program's outcome alone (nothing to read). ``restore_job`` rebuilds the job in worker
threads: the program text (checked against its sha256), parsed and validated against this
config, the twin from the newest intact snapshot and the instructions done after it, where
the take-up started and the instruction left pending. A rebuild that cannot succeed raises
``RecoveryFailed`` saying what would fix it; the program's journal is left as it is.
"""

from __future__ import annotations

import asyncio

from bwsd.controller.errors import ControllerError
from bwsd.controller.job import Job
from bwsd.controller.packml import State
from bwsd.controller.programs import rebuild
from bwsd.controller.recorder import Recorder
from bwsd.errors import BwsdError
from bwsd.journal import ABORTED, ACTIVE, COMPLETE, ENDED, JournalError, ProgramRecord
from bwsd.program import parse_program, validate
from bwsd.twin import Machine, Program, Twin

ENDING = "or Abort to end the program here (its journal is kept)"


class RecoveryFailed(ControllerError):
    """The loaded program cannot be restored; the message says what would fix it."""


def restored_state(record: ProgramRecord) -> tuple[State, str]:
    """Where a restart leaves the machine with ``record`` loaded, and the reason shown."""
    where = f"program {record.id} {record.name!r}"
    at = f"{record.done} of {record.instructions} instructions done"
    if record.outcome in ACTIVE:
        return State.HELD, f"restarted at instruction {record.done}"
    if record.outcome in ENDED:
        state = State.ABORTED if record.outcome == ABORTED else State.STOPPED
        resume = "Clear, Reset, " if state is State.ABORTED else "Reset, "
        why = f" ({record.reason})" if record.reason else ""
        return state, (
            f"restarted: {where} was {record.outcome}{why}, {at}: {resume}then "
            "Start with resume continues it"
        )
    if record.outcome == COMPLETE:
        return State.STOPPED, f"restarted: {where} is complete ({at})"
    return State.STOPPED, f"restarted: {where} is loaded ({at}): Reset, then Start"


async def restore_job(machine: Machine, recorder: Recorder, record: ProgramRecord) -> Job:
    """The job of ``record`` as the journal has it (RecoveryFailed when it cannot be)."""
    write, journal = recorder.write, recorder.journal
    try:
        text = await write(journal.program_text, record.id)
    except JournalError as exc:
        raise RecoveryFailed(
            f"{exc}: restore the journal from a backup and restart, {ENDING}"
        ) from exc
    program = await asyncio.to_thread(_program, machine, record, text)
    snap = await write(journal.latest_snapshot, record.id)
    twin = await asyncio.to_thread(_twin, machine, record, program, snap)
    job = Job(program, record.id, record.name, twin)
    first = await write(journal.instructions, record.id, 0, 1)
    job.origin = int(first[0].started_payload.get("takeup_origin", 0)) if first else None
    job.snapped = snap[0] if snap else 0
    pending = await write(journal.pending, record.id)
    if pending is not None:
        job.start(pending.index, strokes_of(pending.payload))
    job.ended = record.outcome if record.outcome in (*ENDED, COMPLETE) else ""
    return job


def _program(machine: Machine, record: ProgramRecord, text: str) -> Program:
    """The program parsed and checked against this config (in a worker thread)."""
    try:
        program = parse_program(text, record.name)
        validate(program, machine, record.name)
    except BwsdError as exc:
        raise RecoveryFailed(
            f"program {record.id} {record.name!r} does not fit this config "
            f"({exc}): start the daemon with the config it ran with, "
            f"{ENDING}"
        ) from exc
    return program


def _twin(
    machine: Machine, record: ProgramRecord, program: Program, snap: tuple[int, bytes] | None
) -> Twin:
    """The twin after the instructions done (in a worker thread)."""
    try:
        return rebuild(machine, program, record.done, snap)
    except BwsdError as exc:
        raise RecoveryFailed(
            f"program {record.id} {record.name!r}: its twin cannot be rebuilt "
            f"with this config ({exc}): start the daemon with the config it "
            f"ran with, {ENDING}"
        ) from exc


def strokes_of(payload: dict[str, object]) -> dict[int, int] | None:
    """The insert stroke counts a started payload holds (None: none journaled)."""
    strokes = payload.get("strokes")
    if not isinstance(strokes, dict):
        return None
    return {int(axis): int(count) for axis, count in strokes.items()}
