"""The journal on real SQLite files: every method, order refused, reopen, durability settings."""

from __future__ import annotations

import asyncio
import hashlib
import itertools
import sqlite3
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bwsd.journal import SCHEMA_VERSION, Journal, JournalError, PendingInstruction
from bwsd.journal.schema import APPLICATION_ID

TEXT = "FILL row=0 col=0\nXX\nEND\nROW 0 1\nCOL 1 -1\nTAKEUP 1.5\n"


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return tmp_path / "var" / "journal.sqlite"


@pytest.fixture
def journal(path: Path) -> Iterator[Journal]:
    ticks = itertools.count(1000.0)
    with Journal.open(path, clock=lambda: next(ticks)) as j:
        yield j


def running(journal: Journal, instructions: int = 3) -> int:
    pid = journal.add_program("part.bws", TEXT, instructions)
    journal.set_outcome(pid, "running")
    return pid


def dump(path: Path) -> list[str]:
    """Everything in the file, read through a separate read-only connection."""
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        return list(conn.iterdump())
    finally:
        conn.close()


def raw(path: Path) -> sqlite3.Connection:
    return sqlite3.connect(path, isolation_level=None)


def test_open_creates_folders_and_sets_durability(path: Path) -> None:
    with Journal.open(path) as j:
        assert path.is_file()
        assert j.path == path
        assert j.pragmas() == {
            "journal_mode": "wal",
            "synchronous": 2,  # FULL
            "foreign_keys": 1,
            "user_version": SCHEMA_VERSION,
            "application_id": APPLICATION_ID,
        }
    conn = raw(path)
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"  # kept in the file
    assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    assert conn.execute("PRAGMA application_id").fetchone()[0] == APPLICATION_ID
    conn.close()


def test_one_writer_at_a_time(path: Path) -> None:
    with Journal.open(path), pytest.raises(JournalError, match="another writer") as err:
        Journal.open(path)
    assert str(path) in str(err.value)
    j = Journal.open(path)  # the lock went with the first writer
    j.close()
    j.close()
    with pytest.raises(JournalError, match="closed"):
        j.history()


FOREIGN_BYTES = {
    "text": b"[machine]\nrows = 4\n",
    "binary": bytes(range(256)) * 32,
    "header": b"SQLite format 3\x00" + b"\xff" * 200,
}
FOREIGN_SQL = {
    "sqlite": "CREATE TABLE moves (x)",
    "unknown": "PRAGMA user_version = 0",
    "newer": f"PRAGMA user_version = {SCHEMA_VERSION + 1}",
}


def _write_foreign(path: Path, kind: str) -> None:
    """A file at ``path`` that is not a journal this bwsd may write."""
    path.parent.mkdir(parents=True)
    if kind in FOREIGN_BYTES:
        path.write_bytes(FOREIGN_BYTES[kind])
        return
    if kind != "sqlite":
        Journal.open(path).close()
    conn = raw(path)
    conn.execute(FOREIGN_SQL[kind])
    conn.close()


@pytest.mark.parametrize(
    ("kind", "message"),
    [
        ("text", "file is not a database"),
        ("binary", "file is not a database"),
        ("header", "file is not a database"),
        ("sqlite", r"not a bwsd journal \(application id 0x0, tables: moves\)"),
        ("newer", rf"newer bwsd \(schema version {SCHEMA_VERSION + 1}"),
        ("unknown", "unknown schema version 0"),
    ],
)
def test_other_files_are_refused_untouched(path: Path, kind: str, message: str) -> None:
    _write_foreign(path, kind)
    before = path.read_bytes()
    with pytest.raises(JournalError, match=message) as err:
        Journal.open(path)
    assert str(path) in str(err.value)
    assert path.read_bytes() == before  # not switched to WAL or otherwise touched


def test_folder_or_unmakeable_path_is_refused(tmp_path: Path) -> None:
    with pytest.raises(JournalError, match="is a folder"):
        Journal.open(tmp_path)
    (tmp_path / "file").write_text("x")
    with pytest.raises(JournalError, match="cannot create its folder") as err:
        Journal.open(tmp_path / "file" / "journal.sqlite")
    assert "journal.sqlite" in str(err.value)


def test_add_program_stores_text_and_sha256(journal: Journal) -> None:
    pid = journal.add_program("part.bws", TEXT, 3)
    rec = journal.program(pid)
    assert (rec.id, rec.name, rec.instructions, rec.done) == (pid, "part.bws", 3, 0)
    assert rec.sha256 == hashlib.sha256(TEXT.encode()).hexdigest()
    assert (rec.outcome, rec.reason, rec.started, rec.finished) == ("loaded", "", None, None)
    assert rec.created == 1000.0
    assert journal.program_text(pid) == TEXT
    assert not rec.active


@pytest.mark.parametrize(("name", "count"), [("", 1), ("p", -1), ("p", 1.5), ("p", True)])
def test_add_program_refuses_bad_arguments(journal: Journal, path: Path, name, count) -> None:
    before = dump(path)
    with pytest.raises(JournalError):
        journal.add_program(name, TEXT, count)
    assert dump(path) == before


def test_unknown_program_is_named(journal: Journal) -> None:
    for call in (journal.program, journal.program_text, journal.done_count, journal.pending):
        with pytest.raises(JournalError, match="program 42: no such program"):
            call(42)
    for write in (journal.started, journal.done):
        with pytest.raises(JournalError, match="program 9, instruction 1: no such program"):
            write(9, 1, {})


def test_program_text_must_match_its_sha256(journal: Journal, path: Path) -> None:
    pid = journal.add_program("p", TEXT, 1)
    conn = raw(path)
    conn.execute("DROP TRIGGER programs_fixed")
    conn.execute("UPDATE programs SET text = 'ROW 0 9' WHERE id = ?", (pid,))
    conn.close()
    with pytest.raises(JournalError, match="does not match its sha256"):
        journal.program_text(pid)


def test_history_newest_first_with_paging(journal: Journal) -> None:
    ids = [journal.add_program(f"p{i}", TEXT, i) for i in range(5)]
    assert [r.id for r in journal.history()] == ids[::-1]
    assert [r.id for r in journal.history(limit=2)] == ids[:-3:-1]
    assert [r.id for r in journal.history(limit=2, before_id=ids[3])] == [ids[2], ids[1]]
    assert [r.name for r in journal.history(limit=1)] == ["p4"]
    with pytest.raises(JournalError, match="limit"):
        journal.history(limit=0)


def test_outcomes_through_a_run(journal: Journal) -> None:
    pid = journal.add_program("p", TEXT, 1)
    assert journal.active_program() is None
    journal.set_outcome(pid, "running")
    rec = journal.program(pid)
    assert rec.outcome == "running" and rec.started is not None and rec.active
    journal.set_outcome(pid, "held", "occupancy mismatch at (1, 2)")
    held = journal.active_program()
    assert held is not None and held.outcome == "held"
    assert held.reason == "occupancy mismatch at (1, 2)"
    journal.set_outcome(pid, "running")
    assert journal.program(pid).started == rec.started  # the first start is kept
    journal.started(pid, 1, {})
    journal.done(pid, 1, {})
    journal.set_outcome(pid, "complete")
    rec = journal.program(pid)
    assert (rec.outcome, rec.done, rec.reason) == ("complete", 1, "")
    assert rec.started is not None and rec.finished is not None
    assert rec.finished > rec.started
    assert journal.active_program() is None


def test_stopped_program_keeps_its_reason(journal: Journal) -> None:
    pid = running(journal)
    journal.set_outcome(pid, "aborted", "case would leave the matrix")
    [rec] = journal.history()
    assert (rec.outcome, rec.reason, rec.done, rec.instructions) == (
        "aborted",
        "case would leave the matrix",
        0,
        3,
    )


@pytest.mark.parametrize(
    ("setup", "outcome", "message"),
    [
        ("complete", "running", "already complete"),
        ("aborted", "stopped", "already aborted"),
        ("running", "complete", "0 of 2 instructions done"),
        ("loaded", "loaded", "unknown outcome 'loaded'"),
        ("loaded", "paused", "unknown outcome 'paused'"),
        ("other", "running", "program 1 is running: one program is active"),
        ("other", "held", "program 1 is running: one program is active"),
    ],
)
def test_set_outcome_refusals(journal: Journal, path: Path, setup, outcome, message) -> None:
    other = journal.add_program("first", TEXT, 0)
    pid = journal.add_program("second", TEXT, 2 if setup != "complete" else 0)
    if setup == "other":
        journal.set_outcome(other, "running")
    elif setup != "loaded":
        journal.set_outcome(pid, "running")
        if setup != "running":
            journal.set_outcome(pid, setup)
    before = dump(path)
    with pytest.raises(JournalError, match=message) as err:
        journal.set_outcome(pid, outcome)
    assert f"program {pid}" in str(err.value)
    assert dump(path) == before


def test_started_and_done_in_order(journal: Journal) -> None:
    pid = running(journal)
    assert (journal.done_count(pid), journal.pending(pid)) == (0, None)
    journal.started(pid, 1, {"targets": [10, -20], "contacts": 2})
    assert journal.pending(pid) == PendingInstruction(
        pid, 1, {"targets": [10, -20], "contacts": 2}, journal.instructions(pid)[0].started
    )
    assert journal.done_count(pid) == 0
    journal.done(pid, 1, {"contacts": 2, "nodes": 5})
    assert (journal.done_count(pid), journal.pending(pid)) == (1, None)
    journal.started(pid, 2, {"targets": []})
    [one, two] = journal.instructions(pid)
    assert (one.index, one.started_payload, one.done_payload) == (
        1,
        {"targets": [10, -20], "contacts": 2},
        {"contacts": 2, "nodes": 5},
    )
    assert one.done is not None and one.done > one.started
    assert (two.index, two.done, two.done_payload) == (2, None, None)
    assert [r.index for r in journal.instructions(pid, after=1)] == [2]
    assert [r.index for r in journal.instructions(pid, limit=1)] == [1]


def test_done_while_held_completes_the_pending_instruction(journal: Journal) -> None:
    pid = running(journal)
    journal.started(pid, 1, {})
    journal.set_outcome(pid, "held", "axis row2 stalled")
    with pytest.raises(JournalError, match="instructions start only while it runs"):
        journal.started(pid, 2, {})
    journal.done(pid, 1, {"completed": "after hold"})
    assert journal.done_count(pid) == 1


@pytest.mark.parametrize("outcome", ["aborted", "stopped"])
def test_an_instruction_cut_by_an_abort_or_a_stop_is_recorded_done_later(
    journal: Journal, outcome: str
) -> None:
    pid = journal.add_program("p", TEXT, 3)
    journal.set_outcome(pid, "running")
    journal.started(pid, 1, {})
    journal.set_outcome(pid, outcome, "operator")
    journal.done(pid, 1, {"completed": "from the read-back"})  # the machine showed it done
    assert journal.done_count(pid) == 1 and journal.pending(pid) is None
    assert journal.program(pid).outcome == outcome


def _violations() -> list[tuple[str, list[tuple[str, int]], tuple[str, int], str]]:
    """(outcome, steps before, the refused step, message) on a running 3-instruction program."""
    return [
        ("running", [], ("started", 2), "instruction 1 is not done"),
        ("running", [("started", 1)], ("started", 2), "instruction 1 is started and not done"),
        ("running", [("started", 1)], ("started", 1), "already started"),
        ("running", [("started", 1), ("done", 1)], ("started", 1), "already started and done"),
        ("running", [("started", 1), ("done", 1)], ("started", 3), "instruction 2 is not done"),
        ("running", [], ("started", 0), "out of range"),
        ("running", [], ("started", 4), "out of range: the program has 3"),
        ("running", [], ("done", 1), "not started"),
        ("running", [("started", 1), ("done", 1)], ("done", 1), "already done"),
        ("running", [("started", 1)], ("done", 2), "not started"),
        ("loaded", [], ("started", 1), "the program is loaded"),
        ("aborted", [("started", 1)], ("started", 2), "the program is aborted"),
        ("aborted", [("started", 1)], ("done", 2), "not started"),
        ("stopped", [], ("started", 1), "the program is stopped"),
        (
            "complete",
            [("started", 1), ("done", 1), ("started", 2), ("done", 2), ("started", 3), ("done", 3)],
            ("started", 3),
            "the program is complete",
        ),
    ]


@pytest.mark.parametrize(("outcome", "steps", "step", "message"), _violations())
def test_out_of_order_is_refused_and_nothing_written(
    journal: Journal, path: Path, outcome, steps, step, message
) -> None:
    pid = journal.add_program("p", TEXT, 3)
    if outcome != "loaded":
        journal.set_outcome(pid, "running")
    for kind, index in steps:
        getattr(journal, kind)(pid, index, {"i": index})
    if outcome not in ("loaded", "running"):
        journal.set_outcome(pid, outcome, "operator")
    before = dump(path)
    kind, index = step
    with pytest.raises(JournalError, match=message) as err:
        getattr(journal, kind)(pid, index, {"i": index})
    assert f"program {pid}, instruction {index}:" in str(err.value)
    assert (err.value.program, err.value.index) == (pid, index)
    assert dump(path) == before
    journal.check()


@pytest.mark.parametrize(
    ("payload", "message"),
    [
        ([1, 2], "must be a dict"),
        ({"x": float("nan")}, "not JSON"),
        ({"x": {1, 2}}, "not JSON"),
        ({1: "x"}, "keys must be strings"),
    ],
)
def test_payload_must_be_a_json_object(journal: Journal, path: Path, payload, message) -> None:
    pid = running(journal)
    before = dump(path)
    with pytest.raises(JournalError, match=message):
        journal.started(pid, 1, payload)
    with pytest.raises(JournalError, match=message):
        journal.log_event("fault", payload)
    assert dump(path) == before


def test_failed_write_leaves_no_transaction_open(path: Path) -> None:
    calls = itertools.count()

    def flaky() -> float:
        if next(calls) == 2:
            raise RuntimeError("clock failed")
        return 1.0

    with Journal.open(path, clock=flaky) as j:
        pid = j.add_program("p", TEXT, 2)  # clock call 0
        j.set_outcome(pid, "running")  # clock call 1
        before = dump(path)
        with pytest.raises(RuntimeError):
            j.started(pid, 1, {})  # clock call 2 fails inside the transaction
        assert dump(path) == before
        j.started(pid, 1, {})
        assert j.pending(pid) is not None


def test_schema_refuses_what_the_api_refuses(journal: Journal, path: Path) -> None:
    """The triggers hold the order even for a writer that bypasses the API."""
    pid = running(journal)
    journal.started(pid, 1, {})
    journal.done(pid, 1, {})
    journal.started(pid, 2, {})
    journal.close()
    conn = raw(path)
    bad = [
        f"INSERT INTO instructions (program_id, idx, started, started_payload) "
        f"VALUES ({pid}, 3, 0, '{{}}')",
        "UPDATE instructions SET done = 1, done_payload = '{}' WHERE idx = 1",
        "UPDATE instructions SET started_payload = '{}' WHERE idx = 2",
        "DELETE FROM instructions",
        f"UPDATE programs SET outcome = 'complete' WHERE id = {pid}",
        "INSERT INTO programs (name, text, sha256, instructions, created, outcome) "
        f"VALUES ('q', '', '{'0' * 64}', 0, 0, 'held')",
    ]
    before = dump(path)
    for statement in bad:
        with pytest.raises(sqlite3.IntegrityError):
            conn.execute(statement)
    conn.close()
    assert dump(path) == before


def test_check_finds_a_broken_journal(journal: Journal, path: Path) -> None:
    pid = running(journal)
    journal.started(pid, 1, {})
    journal.done(pid, 1, {})
    journal.check()
    conn = raw(path)
    conn.execute("DROP TRIGGER instructions_in_order")
    conn.execute(
        "INSERT INTO instructions (program_id, idx, started, started_payload) "
        f"VALUES ({pid}, 3, 0, '{{}}')"
    )
    conn.close()
    with pytest.raises(JournalError, match=r"indexes are not 1\.\.3") as err:
        journal.check()
    assert str(path) in str(err.value)


def test_events_page_by_id(journal: Journal) -> None:
    ids = [journal.log_event("move", {"n": n, "axes": ["row0"]}) for n in range(5)]
    assert ids == sorted(ids) and len(set(ids)) == 5
    events = journal.events()
    assert [e.data["n"] for e in events] == [0, 1, 2, 3, 4]
    assert events[0].kind == "move" and events[0].data["axes"] == ["row0"]
    assert [e.id for e in journal.events(after_id=ids[2])] == ids[3:]
    assert [e.id for e in journal.events(after_id=ids[0], limit=2)] == ids[1:3]
    with pytest.raises(JournalError, match="needs a kind"):
        journal.log_event("", {})


def test_states_and_last_state(journal: Journal) -> None:
    assert journal.last_state() is None
    first = journal.log_state(4, "Idle", "")
    journal.log_state(6, "Execute", "operator start")
    last = journal.log_state(11, "Held", "occupancy mismatch")
    assert [(s.state, s.name) for s in journal.states()] == [
        (4, "Idle"),
        (6, "Execute"),
        (11, "Held"),
    ]
    assert [s.id for s in journal.states(after_id=first, limit=1)] == [first + 1]
    state = journal.last_state()
    assert state is not None and (state.id, state.reason) == (last, "occupancy mismatch")
    with pytest.raises(JournalError, match="state must be an integer"):
        journal.log_state(-1, "x", "")
    with pytest.raises(JournalError, match="limit"):
        journal.states(limit=-5)


def test_reopen_keeps_everything(path: Path) -> None:
    with Journal.open(path) as j:
        done = j.add_program("done.bws", TEXT, 1)
        j.set_outcome(done, "running")
        j.started(done, 1, {"a": 1})
        j.done(done, 1, {"b": 2})
        j.set_outcome(done, "complete")
        pid = running(j)
        j.started(pid, 1, {"targets": [1]})
        j.log_event("fault", {"axis": "col1"})
        j.log_state(11, "Held", "stall")
        history, events, states = j.history(), j.events(), j.states()
        instructions = j.instructions(done)
    with Journal.open(path) as j:
        assert j.history() == history
        assert j.events() == events and j.states() == states
        assert j.instructions(done) == instructions
        assert j.active_program() == history[0]
        pending = j.pending(pid)
        assert pending is not None and (pending.index, pending.payload) == (1, {"targets": [1]})
        j.done(pid, 1, {})  # writing resumes where it stopped
        j.check()


def test_usable_from_worker_threads(journal: Journal) -> None:
    async def main() -> list[int]:
        calls = [asyncio.to_thread(journal.log_event, "tick", {"n": n}) for n in range(20)]
        return list(await asyncio.gather(*calls))

    ids = asyncio.run(main())
    assert len(set(ids)) == 20
    assert sorted(e.data["n"] for e in journal.events()) == list(range(20))


# -- the order rules against a model ---------------------------------------------------------

STEPS = st.lists(st.tuples(st.sampled_from(["started", "done"]), st.integers(0, 6)), max_size=25)


@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(steps=STEPS)
def test_accepts_exactly_the_ordered_steps(steps: list[tuple[str, int]]) -> None:
    """A step is accepted iff it keeps each instruction journaled once, in order."""
    with tempfile.TemporaryDirectory() as folder, Journal.open(Path(folder) / "j") as j:
        pid = running(j, instructions=5)
        done, pending = 0, 0
        for kind, index in steps:
            ok = (kind == "started" and not pending and index == done + 1 <= 5) or (
                kind == "done" and 0 < pending == index
            )
            if ok:
                getattr(j, kind)(pid, index, {})
                done, pending = (done, index) if kind == "started" else (index, 0)
            else:
                with pytest.raises(JournalError):
                    getattr(j, kind)(pid, index, {})
            assert j.done_count(pid) == done
            assert (p.index if (p := j.pending(pid)) else 0) == pending
        j.check()
