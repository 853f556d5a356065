"""What the controller says about itself: why it stopped, its status, and its events (pure).

A stop's cause is decided once, where the error is caught (``cause_of``), and travels with
the stop: in the status, in the fault event, in the PLC's stop reason register. The status
is one frozen value, read by every door (REST, the PLC tags, the page). The events are one
typed stream every subscriber (the API, the metrics, the PLC tags) follows.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, ClassVar

from bwsd.controller.packml import Command, State, UnitMode
from bwsd.controller.plan import Mismatch, RefusedMove
from bwsd.errors import TwinError
from bwsd.fieldbus.base import FAULT_ESTOP, DriveFault, EStopError, FieldbusError
from bwsd.journal.records import JournalError

log = logging.getLogger("bwsd.controller")


class StopCause(IntEnum):
    """Why the machine last stopped, held or aborted (also the PLC's stop reason code)."""

    NONE = 0
    REFUSED_MOVE = 1  # the twin or a limit refused the next instruction
    DRIVE_FAULT = 2  # an axis reported a fault (stall, jam, wrong position)
    ESTOP = 3  # the emergency stop is pressed
    BUS = 4  # the bus was lost or timed out
    MISMATCH = 5  # the read-back differs from the prediction
    OPERATOR = 6  # a command from REST, the PLC or the page
    RESTART = 7  # the daemon restarted with a program active
    INTERNAL = 8  # an error nothing expected (a task that failed, a bug): see the log
    JOURNAL = 9  # the journal cannot write (its disk is full, another process holds its lock)

    @property
    def label(self) -> str:
        return self.name.lower()


def cause_of(error: BaseException) -> StopCause:
    """The cause of a stop by the error that made it."""
    if isinstance(error, EStopError):
        return StopCause.ESTOP
    if isinstance(error, DriveFault):
        return StopCause.ESTOP if error.code == FAULT_ESTOP else StopCause.DRIVE_FAULT
    if isinstance(error, FieldbusError):
        return StopCause.BUS
    if isinstance(error, RefusedMove | TwinError):
        return StopCause.REFUSED_MOVE
    if isinstance(error, Mismatch):
        return StopCause.MISMATCH
    if isinstance(error, JournalError):
        return StopCause.JOURNAL
    return StopCause.INTERNAL


@dataclass(frozen=True)
class BusStatus:
    """What the controller last saw of the machine over the bus."""

    connected: bool | None = None  # None: not tried yet
    last_error: str | None = None  # the last failure, cleared by the next good read
    checked: float | None = None  # when (epoch seconds)
    estop: bool | None = None  # the emergency stop, as last read
    faulted: tuple[str, ...] = ()  # axes reporting a fault, as last read
    differs: tuple[tuple[int, int], ...] = ()  # cells where sensors and twin disagree (at rest)


@dataclass(frozen=True)
class StatusSnapshot:
    """The controller as it stands, in one consistent value."""

    state: State
    mode: UnitMode
    reason: str
    stop_cause: StopCause
    program_id: int | None
    program_name: str | None
    index: int  # instructions done
    count: int  # instructions of the loaded program
    allowed: tuple[Command, ...]  # exactly the commands that will be accepted now
    bus: BusStatus
    recovering: str  # why commands wait ("" when they do not)
    next: dict[str, Any] | None  # the instruction that runs next, with its line
    resumable: bool = False  # Start with resume continues the program where it stopped
    resume_allowed: bool = False  # and Start with resume is accepted now
    mode_requested: UnitMode = UnitMode.PRODUCTION  # the unit mode last asked for
    good: int = 0  # programs that reached Complete, since the daemon started
    defective: int = 0  # programs left unfinished after they ran (another loaded instead)
    manual: str = ""  # why no manual move is taken now ("" when they are)


# ----- the event stream -----
@dataclass(frozen=True)
class Event:
    """One thing that happened; ``wire()`` is its JSON form (docs/api.md, WebSocket)."""

    kind: ClassVar[str] = ""
    at: float = field(default_factory=time.time, kw_only=True)

    def wire(self) -> dict[str, Any]:
        return {"event": self.kind, "at": self.at}


@dataclass(frozen=True)
class StateChanged(Event):
    kind: ClassVar[str] = "state"
    old: State
    new: State
    cause: str  # the command or event that made the change
    reason: str

    def wire(self) -> dict[str, Any]:
        return {
            **super().wire(),
            "from": self.old.label,
            "to": self.new.label,
            "cause": self.cause,
            "state": int(self.new),
            "reason": self.reason,
        }


@dataclass(frozen=True)
class ProgramLoaded(Event):
    kind: ClassVar[str] = "program"
    program_id: int
    name: str
    count: int

    def wire(self) -> dict[str, Any]:
        return {
            **super().wire(),
            "program_id": self.program_id,
            "name": self.name,
            "count": self.count,
        }


@dataclass(frozen=True)
class InstructionDone(Event):
    kind: ClassVar[str] = "instruction"
    program_id: int
    index: int
    contacts: int
    inserted: int
    timing: dict[str, float]
    skeleton: dict[str, Any]  # the skeleton's change (bwsd.export.skeleton_json.delta_to_dict)
    next: dict[str, Any] | None  # the instruction that runs next, with its line

    def wire(self) -> dict[str, Any]:
        return {
            **super().wire(),
            "program_id": self.program_id,
            "index": self.index,
            "contacts": self.contacts,
            "inserted": self.inserted,
            **self.timing,
            "skeleton": self.skeleton,
            "next": self.next,
        }


@dataclass(frozen=True)
class Fault(Event):
    kind: ClassVar[str] = "fault"
    reason: str
    cause: StopCause

    def wire(self) -> dict[str, Any]:
        return {**super().wire(), "reason": self.reason, "cause": self.cause.label}


@dataclass(frozen=True)
class ModeChanged(Event):
    kind: ClassVar[str] = "mode"
    old: UnitMode
    new: UnitMode

    def wire(self) -> dict[str, Any]:
        return {**super().wire(), "from": self.old.label, "to": self.new.label}


@dataclass(frozen=True)
class BusChanged(Event):
    kind: ClassVar[str] = "bus"
    bus: BusStatus

    def wire(self) -> dict[str, Any]:
        b = self.bus
        return {
            **super().wire(),
            "connected": b.connected,
            "last_error": b.last_error,
            "estop": b.estop,
            "faulted": list(b.faulted),
            "differs": [list(c) for c in b.differs],
        }


Subscriber = Callable[[Event], None]


class EventStream:
    """The controller's events, handed to every subscriber in order.

    A subscriber that raises is logged and skipped: a lost event never stops a run.
    """

    def __init__(self) -> None:
        self._subscribers: list[Subscriber] = []

    def subscribe(self, subscriber: Subscriber) -> None:
        self._subscribers.append(subscriber)

    def unsubscribe(self, subscriber: Subscriber) -> None:
        if subscriber in self._subscribers:
            self._subscribers.remove(subscriber)

    def publish(self, event: Event) -> None:
        for subscriber in list(self._subscribers):
            try:
                subscriber(event)
            except Exception:
                log.exception("a subscriber failed on the %s event", event.kind)
