"""Manual moves: one stroke of a line, a take-up, a fault reset, asked for at a door.

They are taken only where nothing else moves the machine and the twin cannot be left behind:
in unit mode Manual or Maintenance, in Stopped, Idle, Aborted or Complete, the e-stop
released and the machine answering. A stroke or a take-up is refused while an axis reports
a fault, and while the loaded program has run part of the way and can still be resumed
(its twin holds where the machine stands); a stroke is predicted first on a twin filled
as the occupancy sensors read now, so a case that would leave the matrix, or land on an
occupied cell, is refused by the twin's own rule before anything moves. A fault reset
moves nothing. Every manual move is logged with who asked, journaled as an event
``manual`` and published. ``manual_refusal`` says, reading only, why none is taken now.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bwsd.controller.errors import ControllerError
from bwsd.controller.packml import State, UnitMode
from bwsd.controller.status import Event
from bwsd.errors import TwinError
from bwsd.fieldbus.axes import UM_PER_MM, Axis, axis_by_name, shift_stroke_um
from bwsd.fieldbus.base import AxisMove, FieldbusError, MachineState
from bwsd.journal import COMPLETE
from bwsd.logs import REFUSAL
from bwsd.twin import Machine, Shift, Twin

if TYPE_CHECKING:
    from bwsd.controller.facade import Controller

log = logging.getLogger("bwsd.controller")
MANUAL_MODES = frozenset({UnitMode.MANUAL, UnitMode.MAINTENANCE})
MANUAL_STATES = frozenset({State.STOPPED, State.IDLE, State.ABORTED, State.COMPLETE})
MAX_TAKEUP_MM = 50.0  # the longest manual take-up, either way


@dataclass(frozen=True)
class Stroke:
    """One stroke of a shift axis (a row, a column or a segment) by ``step`` cells (±1)."""

    axis: Axis
    step: int

    def text(self) -> str:
        return f"stroke {self.axis.name} {self.step:+d}"


@dataclass(frozen=True)
class TakeUpMove:
    """The take-up moved by ``length`` mm (negative: back)."""

    length: float

    def text(self) -> str:
        return f"take-up {self.length:+g} mm"


@dataclass(frozen=True)
class FaultReset:
    """Clear the latched faults of every axis (nothing moves)."""

    def text(self) -> str:
        return "fault reset"


ManualMove = Stroke | TakeUpMove | FaultReset


@dataclass(frozen=True)
class ManualDone(Event):
    """A manual move done: what, by whom."""

    kind: ClassVar[str] = "manual"
    what: str
    by: str

    def wire(self) -> dict[str, Any]:
        return {**super().wire(), "what": self.what, "by": self.by}


def manual_refusal(ctl: Controller) -> str | None:
    """Why no manual move is taken now (None: they are); reads only what the controller
    knows (the last read of the machine)."""
    if ctl.recovering or ctl.broken:
        return f"recovering: {ctl.recovering or ctl.broken}"
    mode, state, bus = ctl.packml.mode, ctl.packml.state, ctl.seen.status
    if mode not in MANUAL_MODES:
        return f"manual moves need unit mode Manual or Maintenance (now {mode.label})"
    if state not in MANUAL_STATES or ctl.running:
        return f"manual moves are taken in Stopped, Idle, Aborted and Complete (now {state.label})"
    if bus.estop:
        return "the emergency stop is pressed: release it first"
    if bus.connected is False:
        return f"the machine cannot be read: {bus.last_error}"
    return None


def move_refusal(ctl: Controller, move: ManualMove) -> str | None:
    """Why ``move`` is refused now, beyond ``manual_refusal`` (None: it is taken)."""
    general = manual_refusal(ctl)
    if general is not None or isinstance(move, FaultReset):
        return general
    faulted = ctl.seen.status.faulted
    if faulted:
        return f"axes {', '.join(faulted)} report a fault: reset the faults first"
    job = ctl.job
    if job is not None and job.ended != COMPLETE and (job.done or job.pending is not None):
        return (
            f"program {job.program_id} stands at instruction {job.done} of {job.count} and its "
            "twin holds where the machine stands: a stroke or a take-up would leave it behind "
            "(load a program first)"
        )
    return None


async def manual(ctl: Controller, move: ManualMove, who: str) -> MachineState:
    """Take ``move`` (the caller holds the command lock): read the machine, check, move,
    read back. ControllerError says why it is refused; a fault on the way is raised as the
    bus reports it (FieldbusError), the move cut there."""
    text = f"{move.text()} from {who or '?'}"
    log.info("manual %s", text)
    try:
        state = await ctl.read_machine()
        refused = move_refusal(ctl, move)
        if refused is not None:
            raise ControllerError(refused)
        if isinstance(move, FaultReset):
            await ctl.bus.reset_faults()
        else:
            await ctl.bus.execute(await _setpoints(ctl.machine, state, move))
    except ControllerError as exc:
        log.info("manual %s refused: %s", text, exc, extra=REFUSAL)
        raise
    except FieldbusError as exc:
        ctl.seen.failed(exc)
        log.warning("manual %s failed: %s", text, exc)
        if not exc.lost:  # the machine answers: read what the fault left
            with contextlib.suppress(ControllerError):
                await ctl.read_machine()
        raise
    after = await ctl.read_machine()
    event = ManualDone(move.text(), who)
    ctl.recorder.note(
        f"the manual {move.text()}",
        ctl.journal.log_event,
        "manual",
        {"what": move.text(), "by": who},
        event.at,
    )
    ctl.events.publish(event)
    return after


async def _setpoints(
    machine: Machine, state: MachineState, move: Stroke | TakeUpMove
) -> list[AxisMove]:
    """The set-point of a stroke (checked on the sensors' twin first) or of a take-up."""
    if isinstance(move, TakeUpMove):
        takeup = axis_by_name(machine, "takeup").index
        target = state.axes[takeup].position + round(move.length * UM_PER_MM)
        return [AxisMove(takeup, target)]
    refused = await asyncio.to_thread(stroke_refusal, machine, state.occupancy, move)
    if refused is not None:
        raise ControllerError(refused)
    return [AxisMove(move.axis.index, shift_stroke_um(machine, move.axis, move.step))]


def stroke_refusal(machine: Machine, occupancy: np.ndarray[Any, Any], move: Stroke) -> str | None:
    """The twin's refusal of ``move`` on a twin filled as ``occupancy`` reads (None: none)."""
    fill = [(int(r), int(c)) for r, c in np.argwhere(occupancy)]
    axis = move.axis
    assert axis.kind in ("row", "col") and axis.line is not None
    span = axis.span
    entry = (axis.line, move.step) if span is None else (axis.line, move.step, *span)
    try:
        Twin(machine, fill).predict(Shift("row" if axis.kind == "row" else "col", [entry]))
    except TwinError as exc:
        return f"{move.text()} is refused by the twin: {exc.reason}"
    return None
