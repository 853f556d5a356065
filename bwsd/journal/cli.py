"""`bwsd journal`: check, export or reset the daemon's journal, for support.

    bwsd journal check  [WHERE]                  a short report; exit 0 sound, 1 a problem
    bwsd journal export [WHERE] [-o FILE]        JSON lines: sessions, programs, ...
    bwsd journal reset --i-understand [WHERE]    move it aside (kept) for a new one

WHERE is ``--config F`` and ``--state-dir D`` (the journal is found as `bwsd serve` finds
it: the config's ``[journal] path``, journal.db without a config, from the state folder
when relative: ``--state-dir``, else the config's ``[daemon] state_dir``), or ``--journal
FILE``. ``check`` and ``export`` read a private copy of the journal and its log
(files.private_copy), so they never change either, daemon running or not. ``reset`` refuses
while a daemon has the journal open (its lock), and never deletes a file.
"""

from __future__ import annotations

import argparse
import json
import os
import sqlite3
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bwsd import __version__
from bwsd.config import SCHEMA as CONFIG_SCHEMA
from bwsd.config import Text, load_config
from bwsd.errors import BwsdError
from bwsd.journal.check import integrity, invariants, records
from bwsd.journal.files import (
    LOCK,
    SHM,
    WAL,
    beside,
    lost_wal,
    main_file_session,
    private_copy,
    stamp,
    wal_holds_a_commit,
    writer_running,
)
from bwsd.journal.records import ACTIVE, JournalError
from bwsd.journal.schema import APPLICATION_ID, SCHEMA_VERSION, identify, lock, sync_folder, upgrade
from bwsd.paths import journal_file, state_folder

_EMPTY = (
    "is empty (0 bytes), where a journal was expected: restore the journal, or move this "
    "file away to start a new one"
)


def configure(sub: Any) -> None:
    """Register `bwsd journal` and its commands."""
    journal = sub.add_parser("journal", help="check, export or reset the daemon's journal")
    cmds = journal.add_subparsers(dest="journal_command", required=True)
    check = cmds.add_parser(
        "check", help="is the journal sound? a short report (exit 1 if not); changes nothing"
    )
    check.set_defaults(handler=_check_cmd)
    export = cmds.add_parser("export", help="the journal as JSON lines; changes nothing")
    export.add_argument(
        "-o", "--output", metavar="FILE", help="write to FILE (default: standard output)"
    )
    export.set_defaults(handler=_export_cmd)
    reset = cmds.add_parser(
        "reset",
        help="move the journal aside (renamed, kept) so that the "
        "daemon's next start creates a new one",
    )
    reset.add_argument(
        "--i-understand",
        action="store_true",
        help="do it: the new journal knows none of the old one's programs",
    )
    reset.set_defaults(handler=_reset_cmd)
    for parser in (check, export, reset):
        parser.add_argument(
            "--config",
            help="the daemon's config (TOML), for its [journal] path (default: journal.db)",
        )
        parser.add_argument(
            "--state-dir",
            help="the daemon's state folder (default: the config's [daemon] state_dir)",
        )
        parser.add_argument(
            "--journal",
            metavar="FILE",
            help="the journal file itself, instead of --config and --state-dir",
        )


def locate(args: argparse.Namespace) -> Path:
    """The journal file the command is about, found as `bwsd serve` finds it."""
    if args.journal:
        if args.config or args.state_dir:
            raise BwsdError(
                "--journal names the file itself: give it without --config and --state-dir"
            )
        return Path(args.journal)
    if args.config:
        config = load_config(args.config)
        return journal_file(config, state_folder(config, args.state_dir, create=False))
    if not args.state_dir:
        raise BwsdError(
            "which journal? give --config (the daemon's config), --state-dir or --journal"
        )
    folder = Path(args.state_dir)
    default = CONFIG_SCHEMA["journal"]["path"]
    assert isinstance(default, Text) and default.default is not None
    return folder / default.default


@contextmanager
def _reading(path: Path) -> Iterator[None]:
    """File errors as one-line errors naming the journal."""
    try:
        yield
    except BrokenPipeError:
        raise  # the reader went away (`| head`): bwsd.cli ends quietly
    except OSError as exc:
        raise JournalError(f"cannot read: {exc.strerror or exc}", path=str(path)) from exc


# -- check ----------------------------------------------------------------------------------


@dataclass
class Report:
    """What `bwsd journal check` found: facts, and the problems (none: the journal is sound)."""

    facts: list[tuple[str, str]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def check_journal(path: Path) -> Report:
    """Check the journal at ``path`` on a private copy: the file, its log, its invariants."""
    report = Report()
    wal = beside(path, WAL)
    if path.is_dir():
        raise JournalError("is a folder, not a journal file", path=str(path))
    if not path.exists():
        if not wal_holds_a_commit(wal):
            raise JournalError(
                "no journal here (the daemon creates one at its first start)", path=str(path)
            )
        report.problems.append(
            f"is missing, but its write-ahead log {wal.name} is here: put "
            f"the journal back beside it, or move {wal.name} (and "
            f"{path.name}{SHM}) away to start a new one"
        )
        return report
    log = _size(wal.stat().st_size) if wal.exists() else "none"
    report.facts.append(
        ("journal", f"{path} ({_size(path.stat().st_size)}; write-ahead log: {log})")
    )
    if path.stat().st_size == 0:
        report.problems.append(_EMPTY)
        return report
    running = writer_running(path)
    report.facts.append(
        (
            "daemon",
            {
                True: "running (it holds the journal's lock): this report is of a copy taken now",
                False: "not running",
                None: f"unknown (cannot read {path.name}{LOCK})",
            }[running],
        )
    )
    with tempfile.TemporaryDirectory(prefix="bwsd-journal-") as tmp:
        copy = private_copy(path, Path(tmp))
        lost = _check_log(report, copy, running)
        conn = sqlite3.connect(copy, isolation_level=None)
        try:
            _check_file(report, conn, str(path), lost)
        finally:
            conn.close()
    return report


def _check_log(report: Report, copy: Path, running: bool | None) -> bool:
    """The lost-log condition, as the daemon's start judges it (files.lost_wal); True if
    the log is lost, and the copy is then the main file alone."""
    if running:
        session = main_file_session(copy, APPLICATION_ID)
        if session and session.closed is None and not wal_holds_a_commit(beside(copy, WAL)):
            report.problems.append(
                f"the daemon runs but its write-ahead log {copy.name}{WAL} is gone: what it "
                "wrote since its start is only in a deleted file it still holds. Stop it "
                "cleanly (SIGTERM), which folds that into the journal; killed, it would lose it"
            )
            return True
    elif problem := lost_wal(copy, APPLICATION_ID):
        report.problems.append(problem)
        return True
    return False


def _check_file(report: Report, conn: sqlite3.Connection, where: str, lost: bool) -> None:
    try:
        version = identify(conn, where)
    except JournalError as exc:
        report.problems.append(exc.reason)
        return
    except sqlite3.DatabaseError as exc:
        report.problems.append(f"not a usable journal: {exc}")
        return
    if version == 0:
        report.facts.append(
            (
                "schema",
                "none: an empty SQLite file, which the daemon makes a journal at its next start",
            )
        )
        return
    later = "" if version == SCHEMA_VERSION else f" (the daemon upgrades it to {SCHEMA_VERSION})"
    report.facts.append(("schema", f"version {version}{later}"))
    try:
        if broken := integrity(conn):
            report.problems.extend(f"damaged: SQLite integrity check: {line}" for line in broken)
            return
        report.facts.append(("integrity", "ok (SQLite integrity_check)"))
        if version < SCHEMA_VERSION:
            upgrade(conn, version, where)  # the private copy only: the checks read this schema
        if found := invariants(conn):
            report.problems.extend(f"inconsistent: {line}" for line in found)
        else:
            report.facts.append(("consistency", "ok (the journal's invariants)"))
        if found := records(conn):
            report.problems.extend(f"damaged row: {line}" for line in found)
        else:
            report.facts.append(
                ("rows", "ok (program texts and snapshots match their sha256, payloads are JSON)")
            )
        alone = " (as the file alone says, without its lost log)" if lost else ""
        report.facts.append(("sessions", _sessions(conn) + alone))
        report.facts.append(("programs", _programs(conn) + alone))
    except JournalError as exc:  # the upgrade of the copy
        report.problems.append(exc.reason)
    except sqlite3.DatabaseError as exc:
        report.problems.append(f"damaged: {exc}")


def _sessions(conn: sqlite3.Connection) -> str:
    count, unclosed = conn.execute(
        "SELECT count(*), count(*) - count(closed) FROM sessions"
    ).fetchone()
    if not count:
        return "none recorded"
    _, opened, closed, pid, version = conn.execute(
        "SELECT id, opened, closed, pid, version FROM sessions ORDER BY id DESC LIMIT 1"
    ).fetchone()
    end = "not closed" if closed is None else f"closed {stamp(closed)}"
    return (
        f"{count} ({unclosed} not closed: a crash, a kill or a power cut, or running); "
        f"the last opened {stamp(opened)} by pid {pid} (bwsd {version}), {end}"
    )


def _programs(conn: sqlite3.Connection) -> str:
    count = conn.execute("SELECT count(*) FROM programs").fetchone()[0]
    marks = ", ".join("?" for _ in ACTIVE)
    row = conn.execute(
        f"SELECT id, name, outcome, done, instructions FROM programs WHERE outcome IN ({marks}) "
        "ORDER BY id DESC LIMIT 1",
        ACTIVE,
    ).fetchone()
    if row is None:
        return f"{count}, none active"
    pid, name, outcome, done, total = row
    pending = conn.execute(
        "SELECT idx FROM instructions WHERE program_id = ? AND done IS NULL", (pid,)
    ).fetchone()
    started = f"; instruction {pending[0]} started, not done" if pending else ""
    return f"{count}; active: program {pid} {name!r}, {outcome}, {done} of {total} done{started}"


def _size(size: int) -> str:
    if size < 1000:
        return f"{size} bytes"
    return f"{size / 1000:.1f} kB" if size < 1_000_000 else f"{size / 1_000_000:.1f} MB"


def _check_cmd(args: argparse.Namespace) -> int:
    path = locate(args)
    with _reading(path):
        report = check_journal(path)
    for label, text in report.facts:
        print(f"{label + ':':<13}{text}")
    for problem in report.problems:
        print(f"{'problem:':<13}{problem}")
    verdict = "ok" if not report.problems else f"{len(report.problems)} problem(s)"
    print(f"{'result:':<13}{verdict}")
    return 1 if report.problems else 0


# -- export ---------------------------------------------------------------------------------

_PROGRAMS = (
    "SELECT id, name, sha256, instructions, done, created, started, finished, outcome, "
    "reason, text FROM programs ORDER BY id"
)
_INSTRUCTIONS = (
    "SELECT program_id, idx, started, started_payload, done, done_payload "
    "FROM instructions WHERE program_id = ? ORDER BY idx"
)
_SNAPSHOTS = (
    "SELECT program_id, idx, length(data), sha256, created FROM snapshots "
    "WHERE program_id = ? ORDER BY idx"
)


def export_journal(path: Path, write: Callable[[str], object]) -> int:
    """Write the journal at ``path`` as JSON lines through ``write``; how many lines.

    Read from a private copy. One JSON object a line, each with its ``kind``: ``journal``
    (first), ``session``, ``program`` (each followed by its ``instruction`` and ``snapshot``
    lines; a snapshot's bytes are left out), ``event``, ``state``.
    """
    with tempfile.TemporaryDirectory(prefix="bwsd-journal-") as tmp:
        copy = private_copy(path, Path(tmp))
        conn = sqlite3.connect(copy, isolation_level=None)
        try:
            return _export(conn, str(path), write)
        except sqlite3.DatabaseError as exc:
            raise JournalError(f"cannot export: {exc}", path=str(path)) from exc
        finally:
            conn.close()


def _export(conn: sqlite3.Connection, where: str, write: Callable[[str], object]) -> int:
    version = identify(conn, where)
    if version == 0:
        raise JournalError("an empty SQLite file, not a journal yet: nothing to export", path=where)
    if version < SCHEMA_VERSION:
        upgrade(conn, version, where)  # the private copy only
    lines = 0

    def line(kind: str, **fields: Any) -> None:
        nonlocal lines
        try:
            text = json.dumps({"kind": kind, **fields}, allow_nan=False, separators=(",", ":"))
        except ValueError as exc:
            raise JournalError(f"cannot export a {kind}: {exc}", path=where) from exc
        write(text + "\n")
        lines += 1

    line("journal", path=where, schema_version=version, exported=time.time(), bwsd=__version__)
    for sid, opened, closed, pid, bwsd in conn.execute(
        "SELECT id, opened, closed, pid, version FROM sessions ORDER BY id"
    ):
        line("session", id=sid, opened=opened, closed=closed, pid=pid, bwsd=bwsd)
    for (
        pid,
        name,
        sha,
        total,
        done,
        created,
        started,
        finished,
        outcome,
        reason,
        text,
    ) in conn.execute(_PROGRAMS):
        line(
            "program",
            id=pid,
            name=name,
            sha256=sha,
            instructions=total,
            done=done,
            created=created,
            started=started,
            finished=finished,
            outcome=outcome,
            reason=reason,
            text=text,
        )
        for _, idx, t0, p0, t1, p1 in conn.execute(_INSTRUCTIONS, (pid,)):
            line(
                "instruction",
                program_id=pid,
                index=idx,
                started=t0,
                started_payload=_payload(p0),
                done=t1,
                done_payload=_payload(p1),
            )
        for _, idx, size, sha, created in conn.execute(_SNAPSHOTS, (pid,)):
            line("snapshot", program_id=pid, index=idx, bytes=size, sha256=sha, created=created)
    for eid, at, kind, data in conn.execute("SELECT id, time, kind, data FROM events ORDER BY id"):
        line("event", id=eid, time=at, event=kind, data=_payload(data))
    for sid, at, state, name, reason in conn.execute(
        "SELECT id, time, state, name, reason FROM states ORDER BY id"
    ):
        line("state", id=sid, time=at, state=state, name=name, reason=reason)
    return lines


def _payload(text: str | None) -> Any:
    """A stored JSON payload as its value; one that does not parse (damage), as its text."""
    if text is None:
        return None
    try:
        return json.loads(text)
    except ValueError:
        return text


def _export_cmd(args: argparse.Namespace) -> int:
    path = locate(args)
    with _reading(path):
        if not path.is_file():
            raise JournalError("no journal here", path=str(path))
        if args.output is None:
            export_journal(path, sys.stdout.write)
            return 0
        out = Path(args.output)
        ours = {beside(path, suffix).resolve() for suffix in ("", WAL, SHM, LOCK)}
        if out.resolve() in ours:
            raise BwsdError(f"{out}: is one of the journal's own files: choose another")
        part = out.with_name(out.name + ".part")
        try:
            with part.open("w", encoding="utf-8") as fh:
                count = export_journal(path, fh.write)
            part.replace(out)
        finally:
            part.unlink(missing_ok=True)
    print(f"{out}: {count} lines", file=sys.stderr)
    return 0


# -- reset ----------------------------------------------------------------------------------


def reset_journal(path: Path, confirmed: bool) -> list[tuple[Path, Path]]:
    """Move the journal and its -wal and -shm aside, renamed with a time, never deleted.

    Refuses unless ``confirmed`` (saying what it would do), and while a daemon (or another
    writer) holds the journal's lock, which is held meanwhile so that none starts. The log
    moves first: cut short, what stays is a journal without its log, which the daemon
    refuses if it was not closed, not a log beside a new journal.
    """
    where = str(path)
    files = [f for f in (beside(path, WAL), beside(path, SHM), path) if f.exists()]
    if not files:
        raise JournalError("no journal here: nothing to reset", path=where)
    base = _aside(path)
    moves = [(f, path.with_name(base + f.name[len(path.name) :])) for f in files]
    if not confirmed:
        raise JournalError(
            f"reset would move {', '.join(f.name for f in files)} aside (renamed {base}..., "
            "kept), and the daemon's next start would create a new, empty journal that knows "
            "none of this one's programs, nor the one the loom may be in the middle of: add "
            "--i-understand to do it",
            path=where,
        )
    try:
        fd = lock(path)
    except JournalError as exc:
        if "another writer" not in exc.reason:
            raise
        raise JournalError(
            "in use: a daemon (or another writer) has it open; stop it first", path=where
        ) from exc
    try:
        for source, target in moves:
            source.rename(target)
        sync_folder(path.parent)
    finally:
        os.close(fd)
    return moves


def _aside(path: Path) -> str:
    """A name for the journal moved aside that none of its files has yet."""
    base = f"{path.name}.reset-{time.strftime('%Y%m%dT%H%M%S')}"
    name, n = base, 1
    while any(path.with_name(name + suffix).exists() for suffix in ("", WAL, SHM)):
        n += 1
        name = f"{base}-{n}"
    return name


def _reset_cmd(args: argparse.Namespace) -> int:
    path = locate(args)
    with _reading(path):
        moves = reset_journal(path, args.i_understand)
    for source, target in moves:
        print(f"moved {source} -> {target}")
    kept = moves[-1][1] if moves[-1][0] == path else None
    reads = f"; the old one is kept: `bwsd journal check --journal {kept}` reads it"
    print("the daemon's next start creates a new journal" + (reads if kept else ""))
    return 0
