"""`bwsd journal check | export | reset` on real journals: killed, lost, damaged, in use."""

from __future__ import annotations

import json
import random
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from bwsd.cli import main
from bwsd.journal import SCHEMA_VERSION, Journal
from tests.journal.conftest import DONE, TOTAL, downgrade, files

Writer = Callable[[Path, str], subprocess.Popen[str]]


@pytest.fixture(autouse=True)
def _no_state_directory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return tmp_path / "state" / "journal.db"


def wal(path: Path) -> Path:
    return path.with_name(path.name + "-wal")


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    status = main(["journal", *args])
    out, err = capsys.readouterr()
    return status, out, err


def report(out: str) -> dict[str, list[str]]:
    """The check report's lines by label."""
    found: dict[str, list[str]] = {}
    for line in out.splitlines():
        label, _, text = line.partition(":")
        found.setdefault(label, []).append(text.strip())
    return found


def no_nan(name: str) -> Any:
    raise AssertionError(f"{name} in the export")


# -- check ------------------------------------------------------------------------------------


@pytest.mark.slow
def test_check_of_a_killed_writer_reads_the_log_and_changes_nothing(
    capsys: pytest.CaptureFixture[str], path: Path, writer: Writer
) -> None:
    writer(path, "kill")
    before = files(path.parent)
    assert {"journal.db", "journal.db-wal", "journal.db-shm"} <= set(before)
    status, out, _ = run(capsys, "check", "--state-dir", str(path.parent))
    assert status == 0, out
    lines = report(out)
    assert lines["result"] == ["ok"]
    assert lines["daemon"] == ["not running"]
    assert lines["integrity"] == ["ok (SQLite integrity_check)"]
    assert lines["consistency"] == ["ok (the journal's invariants)"]
    assert lines["programs"] == [
        f"1; active: program 1 'part.bws', running, {DONE} of {TOTAL} "
        f"done; instruction {DONE + 1} started, not done"
    ]
    assert "not closed" in lines["sessions"][0]
    assert files(path.parent) == before  # the file, its log and its index: byte for byte
    with Journal.open(path) as j:  # and the next start still recovers from the log
        program = j.active_program()
        assert program is not None and program.done == DONE


@pytest.mark.slow
def test_check_finds_a_lost_log(
    capsys: pytest.CaptureFixture[str], path: Path, writer: Writer
) -> None:
    writer(path, "kill")
    wal(path).unlink()
    before = files(path.parent)
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 1
    [problem] = report(out)["problem"]
    assert "never closed it, and its write-ahead log journal.db-wal is missing" in problem
    assert "bwsd journal reset --i-understand" in problem
    assert report(out)["result"] == ["1 problem(s)"]
    assert report(out)["programs"] == [
        "0, none active (as the file alone says, without its lost log)"
    ]
    assert files(path.parent) == before


@pytest.mark.slow
def test_check_of_a_clean_journal_with_a_held_program(
    capsys: pytest.CaptureFixture[str], path: Path, writer: Writer
) -> None:
    writer(path, "held")
    before = files(path.parent)
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 0, out
    assert "held, 27 of 100 done" in report(out)["programs"][0]
    assert "closed" in report(out)["sessions"][0]
    assert files(path.parent) == before


def test_check_of_an_older_journal_upgrades_only_its_copy(
    capsys: pytest.CaptureFixture[str], path: Path
) -> None:
    with Journal.open(path) as j:
        j.add_program("p.bws", "TAKEUP 1\n", 1)
    downgrade(path, 2)
    before = files(path.parent)
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 0, out
    assert report(out)["schema"] == [f"version 2 (the daemon upgrades it to {SCHEMA_VERSION})"]
    assert report(out)["sessions"] == ["none recorded"]
    assert files(path.parent) == before


@pytest.mark.slow
def test_check_reports_a_damaged_file(capsys: pytest.CaptureFixture[str], path: Path) -> None:
    with Journal.open(path) as j:
        pid = j.add_program("part.bws", "TAKEUP 1\n", 400)
        j.set_outcome(pid, "running")
        for i in range(1, 301):
            j.started(pid, i, {"targets": list(range(100))})
            j.done(pid, i, {"contacts": i})
    data = bytearray(path.read_bytes())
    middle = len(data) // 2 // 4096 * 4096
    data[middle : middle + 4096] = random.Random(1).randbytes(4096)
    path.write_bytes(bytes(data))
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 1
    refused = ("damaged: ", "not a usable journal: ")
    assert all(p.startswith(refused) for p in report(out)["problem"])


def test_check_reports_broken_invariants(capsys: pytest.CaptureFixture[str], path: Path) -> None:
    with Journal.open(path) as j:
        pid = j.add_program("part.bws", "TAKEUP 1\n", 10)
        j.set_outcome(pid, "running")
    conn = sqlite3.connect(path, isolation_level=None)
    conn.execute("DROP TRIGGER snapshots_within_done")
    conn.execute("INSERT INTO snapshots VALUES (1, 5, x'00', ?, 0)", ("0" * 64,))
    conn.close()
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 1
    assert report(out)["problem"] == [
        "inconsistent: program 1: snapshot at instruction 5 of 0 done",
        "damaged row: program 1: the snapshot at instruction 5 does not match its sha256 (a "
        "restart skips it)",
    ]


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (b"", "is empty (0 bytes)"),
        (b"[machine]\nrows = 4\n", "not a usable journal: file is not a database"),
    ],
)
def test_check_reports_a_file_that_is_no_journal(
    capsys: pytest.CaptureFixture[str], path: Path, content: bytes, problem: str
) -> None:
    path.parent.mkdir()
    path.write_bytes(content)
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 1
    assert report(out)["problem"][0].startswith(problem)
    assert path.read_bytes() == content


@pytest.mark.slow
def test_check_of_a_journal_in_use_says_so_and_reset_refuses(
    capsys: pytest.CaptureFixture[str], path: Path, writer: Writer
) -> None:
    proc = writer(path, "wait")  # alive, the journal open
    before = files(path.parent)
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 0, out
    assert report(out)["daemon"][0].startswith("running (it holds the journal's lock)")
    assert f"{DONE} of {TOTAL} done" in report(out)["programs"][0]
    status, _, err = run(capsys, "reset", "--i-understand", "--journal", str(path))
    assert status == 2
    assert err == (
        f"bwsd: error: {path}: in use: a daemon (or another writer) has it open; stop it first\n"
    )
    assert files(path.parent) == before
    assert proc.poll() is None


@pytest.mark.slow
def test_check_of_a_journal_whose_log_is_deleted_while_in_use(
    capsys: pytest.CaptureFixture[str], path: Path, writer: Writer
) -> None:
    writer(path, "wait")
    wal(path).unlink()
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 1
    [problem] = report(out)["problem"]
    assert problem.startswith("the daemon runs but its write-ahead log journal.db-wal is gone")
    assert "Stop it cleanly (SIGTERM)" in problem


@pytest.mark.slow
def test_check_and_export_of_a_journal_being_written_see_one_sound_state(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, path: Path, writer: Writer
) -> None:
    """The private copy is taken while the writer commits, checkpoints and restarts its log."""
    proc = writer(path, "busy")
    out = tmp_path / "export.jsonl"
    first = restarts(path)
    deadline = time.monotonic() + 120
    rounds = 0
    while rounds < 10 or restarts(path) < first + 3:  # across several restarts of the log
        assert time.monotonic() < deadline, f"{rounds} rounds, {restarts(path) - first} restarts"
        status, text, _ = run(capsys, "check", "--journal", str(path))
        assert status == 0, text
        assert run(capsys, "export", "--journal", str(path), "-o", str(out))[0] == 0
        events = [json.loads(line) for line in out.read_text().splitlines()]
        numbers = [e["data"]["n"] for e in events if e["kind"] == "event" and "n" in e["data"]]
        assert numbers == list(range(len(numbers)))  # a prefix of what was written, no gap
        rounds += 1
    assert proc.poll() is None


def restarts(path: Path) -> int:
    """The log's checkpoint sequence number: one more at each restart of the log."""
    return int.from_bytes(wal(path).read_bytes()[12:16], "big")


# -- export -----------------------------------------------------------------------------------


@pytest.mark.slow
def test_export_writes_json_lines_of_everything_and_changes_nothing(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, path: Path, writer: Writer
) -> None:
    writer(path, "kill")
    before = files(path.parent)
    out = tmp_path / "journal.jsonl"
    status, stdout, err = run(capsys, "export", "--journal", str(path), "-o", str(out))
    assert status == 0 and stdout == "", err
    lines = [json.loads(line, parse_constant=no_nan) for line in out.read_text().splitlines()]
    assert err == f"{out}: {len(lines)} lines\n"
    kinds = [line["kind"] for line in lines]
    assert kinds[0] == "journal" and lines[0]["schema_version"] == SCHEMA_VERSION
    assert kinds.count("session") == 1 and kinds.count("program") == 1
    assert kinds.count("instruction") == DONE + 1 and kinds.count("event") == 1
    assert kinds.count("state") == 1
    [program] = [line for line in lines if line["kind"] == "program"]
    assert (program["name"], program["done"], program["outcome"]) == ("part.bws", DONE, "running")
    assert program["text"] == "FILL\nX\nEND\n"
    steps = [line for line in lines if line["kind"] == "instruction"]
    assert [s["index"] for s in steps] == list(range(1, DONE + 2))
    assert steps[0]["started_payload"] == {"i": 1} and steps[0]["done_payload"] == {"i": 1}
    assert steps[-1]["done"] is None and steps[-1]["done_payload"] is None
    [event] = [line for line in lines if line["kind"] == "event"]
    assert (event["event"], event["data"]) == ("loaded", {"name": "part.bws"})
    assert files(path.parent) == before
    assert not out.with_name(out.name + ".part").exists()


def test_export_to_standard_output(capsys: pytest.CaptureFixture[str], path: Path) -> None:
    with Journal.open(path) as j:
        j.log_event("note", {"text": "ünïcode"})
    status, out, _ = run(capsys, "export", "--journal", str(path))
    assert status == 0
    lines = [json.loads(line) for line in out.splitlines()]
    assert [line["kind"] for line in lines] == ["journal", "session", "event"]
    assert lines[2]["data"] == {"text": "ünïcode"}


def test_export_never_writes_over_the_journal(
    capsys: pytest.CaptureFixture[str], path: Path
) -> None:
    Journal.open(path).close()
    before = path.read_bytes()
    status, _, err = run(capsys, "export", "--journal", str(path), "-o", str(path))
    assert status == 2 and err.startswith("bwsd: error: ") and "journal's own files" in err
    assert path.read_bytes() == before


# -- reset ------------------------------------------------------------------------------------


@pytest.mark.slow
def test_reset_without_i_understand_says_what_it_would_do(
    capsys: pytest.CaptureFixture[str], path: Path, writer: Writer
) -> None:
    writer(path, "kill")
    before = files(path.parent)
    status, out, err = run(capsys, "reset", "--state-dir", str(path.parent))
    assert status == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith(
        f"bwsd: error: {path}: reset would move "
        "journal.db-wal, journal.db-shm, journal.db "
        "aside (renamed journal.db.reset-"
    )
    assert "add --i-understand to do it" in err
    assert files(path.parent) == before


@pytest.mark.slow
def test_reset_moves_the_journal_aside_and_the_next_start_makes_a_new_one(
    capsys: pytest.CaptureFixture[str], path: Path, writer: Writer
) -> None:
    writer(path, "kill")
    wal(path).unlink()  # the lost log: refused at start until reset
    before = files(path.parent)
    status, out, err = run(capsys, "reset", "--i-understand", "--journal", str(path))
    assert status == 0, err
    moved = {
        line.split(" -> ")[0][6:]: Path(line.split(" -> ")[1])
        for line in out.splitlines()
        if line.startswith("moved ")
    }
    assert set(moved) == {str(path), f"{path}-shm"}
    aside = moved[str(path)]
    assert aside.name.startswith("journal.db.reset-")
    assert moved[f"{path}-shm"] == Path(f"{aside}-shm")
    assert aside.read_bytes() == before["journal.db"]  # kept as it was
    assert not path.exists() and not Path(f"{path}-shm").exists()
    assert f"`bwsd journal check --journal {aside}` reads it" in out
    with Journal.open(path) as j:  # the next start: a new journal
        assert j.history() == []
    status, out, _ = run(capsys, "check", "--journal", str(aside))  # the old one, still lost
    assert status == 1 and "journal.db.reset-" in report(out)["problem"][0]


def test_reset_twice_keeps_both(capsys: pytest.CaptureFixture[str], path: Path) -> None:
    for _ in range(2):
        Journal.open(path).close()
        assert run(capsys, "reset", "--i-understand", "--journal", str(path))[0] == 0
    kept = sorted(p.name for p in path.parent.iterdir() if ".reset-" in p.name)
    assert len(kept) == 2 and kept[0] != kept[1]


def test_reset_of_nothing_is_an_error(capsys: pytest.CaptureFixture[str], path: Path) -> None:
    status, _, err = run(capsys, "reset", "--i-understand", "--journal", str(path))
    assert (status, err) == (2, f"bwsd: error: {path}: no journal here: nothing to reset\n")


# -- finding the journal, errors --------------------------------------------------------------


def test_the_journal_is_found_as_serve_finds_it(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = tmp_path / "etc" / "bwsd.toml"
    config.parent.mkdir()
    config.write_text(
        "[machine]\nrows = 4\ncols = 4\npitch_x = 10.0\npitch_y = 10.0\n"
        "d_mat = 100.0\nc_mat = 0.5\n[journal]\npath = 'loom.db'\n"
    )
    Journal.open(tmp_path / "sd" / "loom.db").close()
    Journal.open(tmp_path / "given" / "journal.db").close()
    Journal.open(tmp_path / "etc" / "state" / "loom.db").close()
    Journal.open(tmp_path / "state" / "loom.db").close()  # where the current folder's would be
    monkeypatch.chdir(tmp_path)
    assert run(capsys, "check", "--config", str(config), "--state-dir", "sd")[0] == 0
    status, out, _ = run(capsys, "check", "--config", str(config))  # beside the config
    assert status == 0 and report(out)["journal"][0].startswith(f"{tmp_path}/etc/state/loom.db (")
    status, out, _ = run(capsys, "check", "--state-dir", "given")  # journal.db by default
    assert status == 0 and report(out)["journal"][0].startswith("given/journal.db (")
    monkeypatch.setenv("STATE_DIRECTORY", str(tmp_path / "sd"))  # systemd gives another one
    status, _, err = run(capsys, "check", "--config", str(config))
    assert status == 2 and f"[daemon.state_dir]: the state folder would be {tmp_path}/etc" in err
    assert f'set state_dir = "{tmp_path}/sd"' in err
    monkeypatch.delenv("STATE_DIRECTORY")
    status, _, err = run(capsys, "check")
    assert status == 2 and "which journal? give --config" in err
    assert not (tmp_path / "etc" / "state" / "loom.db-wal").exists()


def test_journal_with_config_is_an_error(capsys: pytest.CaptureFixture[str], path: Path) -> None:
    status, _, err = run(capsys, "check", "--journal", str(path), "--state-dir", "x")
    assert status == 2 and err.startswith("bwsd: error: --journal names the file itself")


@pytest.mark.slow
def test_errors_are_one_line_without_a_traceback(tmp_path: Path) -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "bwsd.cli",
            "journal",
            "check",
            "--journal",
            str(tmp_path / "none.db"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr == (
        f"bwsd: error: {tmp_path}/none.db: no journal here (the daemon "
        "creates one at its first start)\n"
    )
    assert not (tmp_path / "none.db").exists()


# The rows a restart could not use, each damaged as a tool outside bwsd would (its triggers
# dropped first): check names the row and exits 1; it said "result: ok" before.
DAMAGE = {
    "text": (
        "DROP TRIGGER programs_fixed; UPDATE programs SET text = 'TAKEUP 2\n' WHERE id = 1;",
        "program 1: its text does not match its sha256",
    ),
    "payload": (
        "DROP TRIGGER instructions_fixed; UPDATE instructions SET started_payload = "
        "'not json' WHERE idx = 1;",
        "program 1, instruction 1: its started payload is not a JSON object",
    ),
    "snapshot": (
        "UPDATE snapshots SET data = x'00' WHERE idx = 1;",
        "program 1: the snapshot at instruction 1 does not match its sha256",
    ),
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_check_names_each_row_a_restart_could_not_use(
    capsys: pytest.CaptureFixture[str], path: Path, damage: str
) -> None:
    with Journal.open(path) as j:
        pid = j.add_program("part.bws", "TAKEUP 1\nTAKEUP 1\n", 2)
        j.set_outcome(pid, "running")
        j.started(pid, 1, {"setpoints": []})
        j.done(pid, 1, {})
        j.save_snapshot(pid, 1, b"twin after 1")
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 0 and report(out)["rows"][0].startswith("ok"), out
    sql, problem = DAMAGE[damage]
    conn = sqlite3.connect(path, isolation_level=None)
    conn.executescript(f"BEGIN; {sql} COMMIT;")
    conn.close()
    status, out, _ = run(capsys, "check", "--journal", str(path))
    assert status == 1, out
    assert [p for p in report(out)["problem"] if problem in p], out
    assert report(out)["result"] == ["1 problem(s)"]
