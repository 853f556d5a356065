"""A journal whose write-ahead log was lost after a crash is refused, never read silently.

The writer (conftest.WRITER) runs a program to instruction 27 in its own process and is
killed there; the log then holds what the main file alone does not.
"""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from bwsd.api.auth import TokenStore
from bwsd.journal import SCHEMA_VERSION, Journal, JournalError
from bwsd.journal import schema as journal_schema
from bwsd.journal.files import main_file_session, wal_holds_a_commit
from bwsd.journal.schema import APPLICATION_ID
from tests.journal.conftest import DONE, TOTAL, downgrade, files
from tests.support.fieldbus import start_mock
from tests.test_daemon import LONG, Served, daemon_config

Writer = Callable[[Path, str], subprocess.Popen[str]]
LOST = (
    r"the daemon that opened this journal at .* \(pid \d+\) never closed it, and its "
    r"write-ahead log journal\.db-wal {state}: the file alone may be older than what the "
    r"loom did\. Put the journal\.db-wal of this journal back beside it and start again, or "
    r"move this journal aside and start a new one with `bwsd journal reset "
    r"--i-understand`"
)


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return tmp_path / "state" / "journal.db"


def wal(path: Path) -> Path:
    return path.with_name(path.name + "-wal")


def resumes_at_27(path: Path) -> None:
    """The journal holds what the killed writer wrote: 26 done, 27 pending."""
    with Journal.open(path) as j:
        j.check()
        program = j.active_program()
        assert program is not None and (program.outcome, program.done) == ("running", DONE)
        pending = j.pending(program.id)
        assert pending is not None and pending.index == DONE + 1


@pytest.mark.slow
def test_a_log_deleted_after_a_kill_is_refused_and_nothing_is_touched(
    path: Path, writer: Writer
) -> None:
    writer(path, "kill")
    assert wal_holds_a_commit(wal(path))
    saved = wal(path).read_bytes()
    wal(path).unlink()  # "someone deleted journal.db-wal"
    before = files(path.parent)
    with pytest.raises(JournalError, match=LOST.format(state="is missing")) as err:
        Journal.open(path)
    assert str(err.value).startswith(f"{path}: ")
    assert "\n" not in str(err.value)
    assert files(path.parent) == before  # no log made, the file not written
    with pytest.raises(JournalError, match="never closed it"):  # and again: it stays refused
        Journal.open(path)
    wal(path).write_bytes(saved)  # the advice: put the log back
    resumes_at_27(path)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["empty", "header", "zeros", "cut"])
def test_a_log_emptied_or_garbled_after_a_kill_is_refused(
    path: Path, writer: Writer, kind: str
) -> None:
    """A log SQLite would ignore counts as lost: an empty one (what any SQLite reader of the
    bare file leaves), its header alone, zeros, or cut inside its first frame."""
    writer(path, "kill")
    log = wal(path).read_bytes()
    wal(path).write_bytes(
        {"empty": b"", "header": log[:32], "zeros": bytes(len(log)), "cut": log[: 32 + 24 + 1000]}[
            kind
        ]
    )
    with pytest.raises(JournalError, match=LOST.format(state="holds no transaction")):
        Journal.open(path)


@pytest.mark.slow
def test_a_log_left_by_a_reader_of_the_bare_file_is_refused(path: Path, writer: Writer) -> None:
    """A read-only SQLite reader of the file without its log makes an empty one: still lost."""
    writer(path, "kill")
    wal(path).unlink()
    reader = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    reader.execute("SELECT count(*) FROM programs").fetchone()
    reader.close()
    assert wal(path).exists()
    with pytest.raises(JournalError, match="never closed it"):
        Journal.open(path)


@pytest.mark.slow
def test_a_kill_with_the_log_intact_recovers(path: Path, writer: Writer) -> None:
    writer(path, "kill")
    resumes_at_27(path)
    with Journal.open(path) as j:  # the killed session stays unclosed, for the record
        rows = j._live().execute("SELECT closed IS NULL FROM sessions ORDER BY id").fetchall()
    assert rows == [(1,), (0,), (1,)]  # killed, closed; this one is still open


@pytest.mark.slow
def test_a_clean_close_with_a_held_program_is_not_refused(path: Path, writer: Writer) -> None:
    writer(path, "held")
    assert not wal(path).exists()  # closing folded the log into the file and removed it
    with Journal.open(path) as j:
        program = j.active_program()
        assert program is not None and (program.outcome, program.done) == ("held", DONE + 1)
        assert program.instructions == TOTAL


@pytest.mark.slow
def test_a_writer_dying_of_an_exception_is_not_refused(path: Path, writer: Writer) -> None:
    """At exit SQLite folds the log of a connection left open into the file and removes it;
    the journal records its end first, so the next start does not take it for a lost log."""
    writer(path, "raise")
    assert not wal(path).exists()
    resumes_at_27(path)


def test_the_main_file_itself_says_open_while_a_writer_has_it(path: Path) -> None:
    with Journal.open(path) as j:
        j.add_program("p.bws", "TAKEUP 1\n", 1)
        session = main_file_session(path, APPLICATION_ID)  # the file alone, not its log
        assert session is not None and session.closed is None and session.pid == os.getpid()
    session = main_file_session(path, APPLICATION_ID)
    assert session is not None and session.closed is not None


@pytest.mark.slow
def test_a_log_folded_in_by_another_sqlite_tool_is_refused_too(path: Path, writer: Writer) -> None:
    """Documented: a writable SQLite connection to the journal after a crash folds the log
    into the file and removes it; the file cannot show it holds everything, so it is refused
    (docs/journal.md). Read it with `bwsd journal check` or `export` instead."""
    writer(path, "kill")
    other = sqlite3.connect(path)
    assert other.execute("SELECT done FROM programs").fetchone() == (DONE,)
    other.close()
    assert not wal(path).exists()
    with pytest.raises(JournalError, match=LOST.format(state="is missing")):
        Journal.open(path)


@pytest.mark.slow
def test_a_refused_open_keeps_the_log(path: Path, writer: Writer) -> None:
    """Opening reads the log; refusing the file must not fold it in (which would turn a
    crash the next start recovers into a lost log)."""
    writer(path, "kill")
    holder = sqlite3.connect(f"file:{path}?mode=ro", uri=True)  # so that no close folds it
    holder.execute("SELECT count(*) FROM programs").fetchone()
    other = sqlite3.connect(path, isolation_level=None)
    other.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")  # in the log
    other.close()
    holder.close()
    before = files(path.parent)
    with pytest.raises(JournalError, match="newer bwsd"):
        Journal.open(path)
    assert files(path.parent)[wal(path).name] == before[wal(path).name]
    assert files(path.parent)[path.name] == before[path.name]


@pytest.mark.slow
def test_a_log_without_its_journal_is_refused(path: Path, writer: Writer) -> None:
    """SQLite would replay a stray log into the new journal made in its place."""
    writer(path, "kill")
    path.rename(path.with_name("elsewhere.db"))
    stray = (
        r"is missing, but its write-ahead log journal\.db-wal is here: put the journal "
        r"back beside it, or move journal\.db-wal"
    )
    with pytest.raises(JournalError, match=stray):
        Journal.open(path)
    assert not path.exists()


def test_a_reader_in_the_way_of_the_opening_checkpoint_is_refused_clearly(
    path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    Journal.open(path).close()
    monkeypatch.setattr(journal_schema, "BUSY_TIMEOUT_MS", 50)
    reader = sqlite3.connect(path, isolation_level=None)
    reader.execute("BEGIN")
    reader.execute("SELECT count(*) FROM programs").fetchone()  # reads the file as it is
    try:
        with pytest.raises(JournalError, match="another process keeps a read transaction open"):
            Journal.open(path)
    finally:
        reader.execute("COMMIT")
        reader.close()
    with Journal.open(path) as j:
        rows = j._live().execute("SELECT closed IS NULL FROM sessions ORDER BY id").fetchall()
    assert rows == [(0,), (0,), (1,)]  # the refused opening recorded its end too


def test_a_version_2_journal_is_upgraded_and_records_sessions(path: Path) -> None:
    with Journal.open(path) as j:
        j.add_program("p.bws", "TAKEUP 1\n", 1)
    downgrade(path, 2)
    assert main_file_session(path, APPLICATION_ID) is None
    with Journal.open(path) as j:
        assert j.pragmas()["user_version"] == SCHEMA_VERSION
        j.check()
        assert [p.name for p in j.history()] == ["p.bws"]
        session = main_file_session(path, APPLICATION_ID)
        assert session is not None and (session.id, session.closed) == (1, None)


@pytest.mark.slow
def test_serve_refuses_a_journal_whose_log_was_lost_in_one_line(
    tmp_path: Path, path: Path, writer: Writer
) -> None:
    writer(path, "kill")
    wal(path).unlink()
    config = tmp_path / "bwsd.toml"
    config.write_text(
        "[machine]\nrows = 4\ncols = 4\npitch_x = 10.0\npitch_y = 10.0\n"
        "d_mat = 100.0\nc_mat = 0.5\n"
    )
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "bwsd.cli",
            "serve",
            "--config",
            str(config),
            "--state-dir",
            str(path.parent),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 2 and done.stdout == "", done.stderr
    assert "Traceback" not in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith(f"bwsd: error: {path}: the daemon that opened this journal"), last
    assert "journal.db-wal is missing" in last and "bwsd journal reset --i-understand" in last


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[tuple[Path, Path, str]]:
    """`bwsd serve` on the mock loom (see tests/test_daemon.py)."""
    mock = start_mock(tmp_path, {"stroke_speed": 400.0, "takeup_speed": 400.0})
    state = tmp_path / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    yield daemon_config(tmp_path, mock), state, token
    mock.stop()


@pytest.mark.slow
def test_a_daemon_stopped_mid_program_starts_again_and_one_killed_too(
    rig: tuple[Path, Path, str],
) -> None:
    config, state, token = rig
    served = Served(config, state, token)
    served.http.post("/programs", json={"name": "long.bws", "text": LONG}).raise_for_status()
    served.command("reset")
    served.command("start")
    while served.state()["index"] < 5:
        time.sleep(0.01)
    served.stop()  # SIGTERM: held after the current instruction, the journal closed
    assert served.proc.returncode == 0
    assert not (state / "journal.db-wal").exists()
    served = Served(config, state, token)  # not refused: the file says "closed"
    held = served.recovered()
    assert held["name"] == "Held" and held["index"] >= 5, held
    served.command("unhold")
    while served.state()["index"] < held["index"] + 5:
        time.sleep(0.01)
    served.kill()
    assert (state / "journal.db-wal").exists()
    served = Served(config, state, token)  # a crash with its log: recovered
    try:
        assert served.recovered()["name"] == "Held"
    finally:
        served.stop()
