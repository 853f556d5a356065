"""The daemon's durable record: programs, instructions, twin snapshots, events and states
(docs/journal.md).

SQLite in WAL mode with ``synchronous=FULL``: a write returns once it is on disk. The
journal records "instruction i started" before the actuators move and "instruction i done"
after the twin commits; on restart the twin is rebuilt from the program text, its newest
snapshot if any and the done instructions after it, and the one pending instruction, if
any, is completed or reported.
"""

from bwsd.journal.records import (
    ABORTED,
    ACTIVE,
    COMPLETE,
    ENDED,
    FINAL,
    HELD,
    LOADED,
    OUTCOMES,
    RUNNING,
    STOPPED,
    SUSPENDED,
    EventRecord,
    InstructionRecord,
    JournalError,
    JournalUnavailable,
    PendingInstruction,
    ProgramRecord,
    StateRecord,
)
from bwsd.journal.schema import SCHEMA_VERSION
from bwsd.journal.store import Journal
from bwsd.journal.writer import JournalWriter

__all__ = [
    "ABORTED",
    "ACTIVE",
    "COMPLETE",
    "ENDED",
    "FINAL",
    "HELD",
    "LOADED",
    "OUTCOMES",
    "RUNNING",
    "SCHEMA_VERSION",
    "STOPPED",
    "SUSPENDED",
    "EventRecord",
    "InstructionRecord",
    "Journal",
    "JournalError",
    "JournalUnavailable",
    "JournalWriter",
    "PendingInstruction",
    "ProgramRecord",
    "StateRecord",
]
