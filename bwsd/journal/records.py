"""What the journal hands back: plain frozen records, and its one error class."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bwsd.errors import BwsdError

LOADED = "loaded"
RUNNING = "running"
HELD = "held"
SUSPENDED = "suspended"
COMPLETE = "complete"
ABORTED = "aborted"
STOPPED = "stopped"
ACTIVE = (RUNNING, HELD, SUSPENDED)  # at most one program at a time
FINAL = (COMPLETE, ABORTED, STOPPED)  # the run is over: complete, or ended before it
ENDED = (ABORTED, STOPPED)  # ended before complete: resumable while it is the newest program
OUTCOMES = (LOADED, *ACTIVE, *FINAL)


class JournalError(BwsdError):
    """The journal cannot be opened, refuses a write, or cannot store it.

    Names the journal file and, where one is concerned, the program and the instruction
    (1-based).
    """

    def __init__(
        self, message: str, *, path: str = "", program: int | None = None, index: int | None = None
    ) -> None:
        where = [path] if path else []
        if program is not None:
            where.append(f"program {program}")
        if index is not None:
            where.append(f"instruction {index}")
        super().__init__(f"{', '.join(where)}: {message}" if where else message)
        self.reason = message
        self.path = path
        self.program = program
        self.index = index


class JournalUnavailable(JournalError):
    """The journal cannot read or write now (its disk is full, another process holds its
    lock, the file is read-only): the same call may succeed later. Any other JournalError is
    a refusal that no retry changes."""


@dataclass(frozen=True)
class ProgramRecord:
    """One program in the history, like one print in a printer's print history.

    Times are Unix seconds; ``started`` is when it first ran, ``finished`` when it reached
    a final outcome. ``done`` of ``instructions`` instructions are done; ``reason`` says why
    it stopped (empty while it runs or when it completed).
    """

    id: int
    name: str
    sha256: str
    instructions: int
    done: int
    created: float
    started: float | None
    finished: float | None
    outcome: str
    reason: str

    @property
    def active(self) -> bool:
        """True while the program runs, is held or suspended."""
        return self.outcome in ACTIVE


@dataclass(frozen=True)
class PendingInstruction:
    """An instruction that started and is not done: complete it or report it, never guess."""

    program_id: int
    index: int
    payload: dict[str, Any]
    started: float


@dataclass(frozen=True)
class InstructionRecord:
    """One instruction of a program as journaled: what was commanded and what was found."""

    program_id: int
    index: int
    started: float
    started_payload: dict[str, Any]
    done: float | None
    done_payload: dict[str, Any] | None


@dataclass(frozen=True)
class EventRecord:
    """One event, in the order logged; ``id`` is the cursor for ``events(after_id=...)``."""

    id: int
    time: float
    kind: str
    data: dict[str, Any]


@dataclass(frozen=True)
class StateRecord:
    """One PackML state change (standard state number and name) with its reason."""

    id: int
    time: float
    state: int
    name: str
    reason: str


@dataclass(frozen=True)
class SessionRecord:
    """One opening of the journal by a writer (a daemon's start), and its clean close.

    ``closed`` is None while it is open, and stays None when the writer was killed or the
    power cut: the next opening then recovers the writes from the write-ahead log.
    """

    id: int
    opened: float
    closed: float | None
    pid: int
    version: str
