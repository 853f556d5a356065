"""A journal writer in its own process, killed or stopped the ways a daemon is."""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

DONE = 26  # instructions done when the writer is ready; the next one is started, not done
TOTAL = 100

# Opens the journal, runs a program to instruction 27 (started, not done), then per mode:
# "kill" and "wait" say ready and wait to be killed; "held" finishes 27, holds the program
# and closes (a daemon's SIGTERM); "raise" dies of an exception with the journal open (a
# bug); "busy" says ready and writes on until killed, big events past the program's end, so
# that SQLite checkpoints and restarts the log again and again.
WRITER = f"""
import sys, time
from bwsd.journal import Journal

path, mode = sys.argv[1], sys.argv[2]
j = Journal.open(path)
pid = j.add_program("part.bws", "FILL\\nX\\nEND\\n", {TOTAL})
j.set_outcome(pid, "running")
j.log_event("loaded", {{"name": "part.bws"}})
j.log_state(6, "Execute", "start")
for i in range(1, {DONE} + 1):
    j.started(pid, i, {{"i": i}})
    j.done(pid, i, {{"i": i}})
j.started(pid, {DONE} + 1, {{"i": {DONE} + 1}})
if mode == "held":
    j.done(pid, {DONE} + 1, {{"i": {DONE} + 1}})
    j.set_outcome(pid, "held", "daemon stopping")
    j.close()
    sys.exit(0)
if mode == "raise":
    raise RuntimeError("a bug, with the journal open")
print("ready", flush=True)
if mode == "busy":
    for i in range({DONE} + 1, {TOTAL} + 1):
        if i > {DONE} + 1:
            j.started(pid, i, {{"i": i}})
        j.done(pid, i, {{"i": i}})
    j.set_outcome(pid, "complete")
    n = 0
    while True:
        j.log_event("filler", {{"n": n, "pad": "x" * 6000}})
        n += 1
        time.sleep(0.001)
time.sleep(600)
"""


def files(folder: Path) -> dict[str, bytes]:
    """Every file of the folder and its bytes: to show that nothing changed."""
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture
def writer() -> Iterator[Callable[[Path, str], subprocess.Popen[str]]]:
    """Run the writer on a journal: "kill" returns once it was SIGKILLed mid-program,
    "held" and "raise" once it ended; "wait" and "busy" return it alive, journal open."""
    alive: list[subprocess.Popen[str]] = []

    def run(path: Path, mode: str) -> subprocess.Popen[str]:
        proc = subprocess.Popen(
            [sys.executable, "-c", WRITER, str(path), mode],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
        )
        alive.append(proc)
        assert proc.stdout is not None and proc.stderr is not None
        if mode in ("held", "raise"):
            proc.wait(timeout=60)
            errors = proc.stderr.read()
            assert (proc.returncode, "a bug" in errors) == (
                {"held": 0, "raise": 1}[mode],
                mode == "raise",
            ), errors
            return proc
        assert proc.stdout.readline() == "ready\n", proc.stderr.read()
        if mode == "kill":
            proc.send_signal(signal.SIGKILL)
            assert proc.wait(timeout=60) == -signal.SIGKILL
        return proc

    yield run
    for proc in alive:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()


# What each schema version added, undone: a current journal made to look as an older bwsd
# wrote it (version 4 let an ended program resume; 3 added sessions; 2 snapshots).
_UNDO = {
    4: "DROP TRIGGER programs_resumed; DROP TRIGGER programs_final; "
    "DROP TRIGGER instructions_done_once; "
    "CREATE TRIGGER instructions_done_once BEFORE UPDATE OF done, done_payload ON instructions "
    "WHEN OLD.done IS NOT NULL OR NEW.done IS NULL OR (SELECT outcome FROM programs WHERE "
    "id = NEW.program_id) NOT IN ('running', 'held', 'suspended') "
    "BEGIN SELECT RAISE(ABORT, 'instruction done twice or outside a run'); END; "
    "CREATE TRIGGER programs_final BEFORE UPDATE ON programs "
    "WHEN OLD.outcome IN ('complete', 'aborted', 'stopped') "
    "BEGIN SELECT RAISE(ABORT, 'a finished program never changes'); END;",
    3: "DROP TABLE sessions;",
    2: "DROP TABLE snapshots;",
}


def downgrade(path: Path, version: int) -> None:
    """Make the journal at ``path`` (of this schema) one of schema ``version``."""
    import sqlite3

    from bwsd.journal import SCHEMA_VERSION

    undo = " ".join(_UNDO[v] for v in range(SCHEMA_VERSION, version, -1))
    conn = sqlite3.connect(path, isolation_level=None)
    conn.executescript(f"BEGIN; {undo} PRAGMA user_version = {version}; COMMIT;")
    conn.close()
