"""Crash anywhere: a writer process is killed (SIGKILL) at random moments and resumes.

After every kill the journal must reopen sound (indexes 1..n, done ones first, at most one
pending), hold every write the writer reported committed, and let the next writer carry on
exactly where the last one stopped. At the end every instruction is journaled exactly once.
"""

from __future__ import annotations

import os
import random
import select
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from bwsd.journal import Journal

pytestmark = pytest.mark.slow  # every test here is in the slow tier

TOTAL = 1000
KILLS = 30
REACH = 25  # a killed writer pauses after this many instructions: KILLS * REACH < TOTAL
SEED = 20250611
SILENCE_LIMIT = 60.0  # seconds without output before a writer counts as hung

# The writer: resumes the latest program, completes a pending instruction, then writes
# started/done pairs, printing each after its commit. With a stall index it stops right
# after that instruction started, with a stop index after that one is done; either way it
# then waits to be killed.
WRITER = """
import sys, time
from bwsd.journal import Journal

def started(i): return {"targets": [i % 5, -(i % 3)], "contacts": i % 7}
def done(i): return {"contacts": i % 7, "nodes": 2 * i}
def say(*words): print(*words, flush=True)

path, total, stall, stop = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
with Journal.open(path) as j:
    latest = j.history(1)
    pid = latest[0].id if latest else j.add_program("crash.bws", "FILL\\nX\\nEND\\n", total)
    if j.program(pid).outcome == "loaded":
        j.set_outcome(pid, "running")
    pending = j.pending(pid)
    first = j.done_count(pid) + 1
    say("resume", pending.index if pending else first)
    if pending:
        j.done(pid, pending.index, done(pending.index))
        say("done", pending.index)
        first += 1
    for i in range(first, total + 1):
        j.started(pid, i, started(i))
        say("started", i)
        if i == stall:
            say("stalled")
            time.sleep(600)
        j.done(pid, i, done(i))
        say("done", i)
        if i == stop:
            say("paused")
            time.sleep(600)
    if j.program(pid).outcome == "running":
        j.set_outcome(pid, "complete")
    say("finished")
"""


def started_payload(i: int) -> dict[str, Any]:
    return {"targets": [i % 5, -(i % 3)], "contacts": i % 7}


def done_payload(i: int) -> dict[str, Any]:
    return {"contacts": i % 7, "nodes": 2 * i}


@dataclass
class Writer:
    """A writer process and what it has said so far."""

    proc: subprocess.Popen[bytes]
    stderr: Path
    lines: list[str] = field(default_factory=list)
    buffer: bytes = b""

    def read_until(self, enough: Callable[[list[str]], bool]) -> None:
        """Read output lines until ``enough`` holds; fail if the writer ends or hangs first."""
        assert self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        while not enough(self.lines):
            ready, _, _ = select.select([fd], [], [], SILENCE_LIMIT)
            assert ready, f"writer silent for {SILENCE_LIMIT} s: {self.errors()}"
            chunk = os.read(fd, 65536)
            assert chunk, f"writer ended early ({self.proc.wait()}): {self.errors()}"
            self._take(chunk)

    def kill(self) -> None:
        """SIGKILL, then collect what it printed before dying."""
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()
        assert self.proc.stdout is not None
        self._take(self.proc.stdout.read())

    def last(self, word: str) -> int:
        """The last index printed after ``word`` (0 if none)."""
        found = [int(line.split()[1]) for line in self.lines if line.startswith(word + " ")]
        return found[-1] if found else 0

    def progress(self) -> int:
        return sum(1 for line in self.lines if line.startswith(("started ", "done ")))

    def errors(self) -> str:
        return self.stderr.read_text()

    def _take(self, chunk: bytes) -> None:
        self.buffer += chunk
        *complete, self.buffer = self.buffer.split(b"\n")
        self.lines.extend(line.decode() for line in complete)


@pytest.fixture
def spawn(tmp_path: Path) -> Iterator[Callable[[Path, int, int], Writer]]:
    """Start writers; any still alive at the end are killed."""
    writers: list[Writer] = []

    def start(journal: Path, stall: int, stop: int) -> Writer:
        stderr = tmp_path / f"writer{len(writers)}.err"
        with stderr.open("wb") as err:
            proc = subprocess.Popen(
                [sys.executable, "-c", WRITER, str(journal), str(TOTAL), str(stall), str(stop)],
                stdout=subprocess.PIPE,
                stderr=err,
            )
        writers.append(Writer(proc, stderr))
        return writers[-1]

    yield start
    for writer in writers:
        if writer.proc.poll() is None:
            writer.proc.kill()
            writer.proc.wait()
        if writer.proc.stdout is not None:
            writer.proc.stdout.close()


@dataclass(frozen=True)
class Seen:
    """The journal as found after a kill."""

    program: int  # 0: none yet
    done: int
    pending: int  # 0: none


def inspect(path: Path) -> Seen:
    """Reopen, check the invariants both through the API and with plain SQL."""
    with Journal.open(path) as j:
        j.check()
        history = j.history()
        assert len(history) <= 1
        if not history:
            return Seen(0, 0, 0)
        pid = history[0].id
        records = j.instructions(pid, limit=TOTAL)
        pending = j.pending(pid)
        done = j.done_count(pid)
    assert [r.index for r in records] == list(range(1, len(records) + 1))
    assert [r.started_payload for r in records] == [started_payload(r.index) for r in records]
    finished = [r for r in records if r.done is not None]
    assert [r.done_payload for r in finished] == [done_payload(r.index) for r in finished]
    assert [r.index for r in finished] == list(range(1, done + 1))
    assert len(records) - done <= 1
    assert (pending.index if pending else 0) == (len(records) if len(records) > done else 0)
    _check_plain_sql(path, pid, len(records), done)
    return Seen(pid, done, pending.index if pending else 0)


def _check_plain_sql(path: Path, pid: int, rows: int, done: int) -> None:
    """The same facts read with SQL alone, not through the code under test."""
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        got = conn.execute(
            "SELECT idx, started IS NOT NULL, done IS NOT NULL FROM instructions "
            "WHERE program_id = ? ORDER BY idx",
            (pid,),
        ).fetchall()
    finally:
        conn.close()
    assert [row[0] for row in got] == list(range(1, rows + 1))
    assert all(row[1] for row in got), "done without started"
    assert [row[2] for row in got] == [True] * done + [False] * (rows - done)


def kill_plan(rng: random.Random) -> list[str]:
    """Where each writer dies: at a random time after start, after a random amount of
    progress (and a random sliver of time), or stalled between started and done."""
    plan = ["early", "progress", "stall"] * (KILLS // 3)
    rng.shuffle(plan)
    return plan


def run_and_kill(writer: Writer, mode: str, rng: random.Random) -> None:
    if mode == "early":
        time.sleep(rng.uniform(0.0, 0.12))
    elif mode == "progress":
        target = rng.randint(1, 2 * REACH - 1)  # lines before the pause: at least 2 * REACH - 1
        writer.read_until(lambda lines: writer.progress() >= target or "paused" in lines)
        time.sleep(rng.uniform(0.0, 0.002))
    else:
        writer.read_until(lambda lines: "stalled" in lines)
    writer.kill()
    assert writer.proc.returncode == -signal.SIGKILL, writer.errors()


@pytest.mark.slow
def test_killed_writers_resume_exactly(
    tmp_path: Path, spawn: Callable[[Path, int, int], Writer]
) -> None:
    path = tmp_path / "state" / "journal.sqlite"
    rng = random.Random(SEED)
    seen = Seen(0, 0, 0)
    stalls = 0
    for mode in kill_plan(rng):
        stall = seen.done + 1 + rng.randint(1, REACH - 1) if mode == "stall" else 0
        writer = spawn(path, stall, seen.done + REACH)
        run_and_kill(writer, mode, rng)
        after = inspect(path)
        _check_resume(writer, seen, after)
        if mode == "stall":
            assert after.pending == stall
            stalls += 1
        seen = after
    assert stalls == KILLS // 3
    assert 0 < seen.done < TOTAL  # the kills all landed mid-run
    _finish(spawn(path, 0, 0), path)


def _check_resume(writer: Writer, before: Seen, after: Seen) -> None:
    """What the writer reported committed is there, and nothing beyond its next write."""
    if writer.lines:
        expected = before.pending or before.done + 1
        assert writer.lines[0] == f"resume {expected}", writer.lines[:3]
    assert after.done >= max(before.done, writer.last("done"))
    started = max(after.pending, after.done)
    assert started >= writer.last("started")
    # each write is one commit, printed right after it: at most one more than printed
    assert after.done <= max(before.done, writer.last("done")) + 1
    assert started <= max(before.pending, before.done, writer.last("started")) + 1


def _finish(writer: Writer, path: Path) -> None:
    writer.read_until(lambda lines: "finished" in lines)
    assert writer.proc.wait(timeout=SILENCE_LIMIT) == 0, writer.errors()
    final = inspect(path)
    assert (final.done, final.pending) == (TOTAL, 0)
    with Journal.open(path) as j:
        [program] = j.history()
        assert (program.outcome, program.done, program.instructions) == ("complete", TOTAL, TOTAL)
        assert len(j.instructions(program.id, limit=TOTAL + 1)) == TOTAL
