"""The rows of a sweep on disk: an append-only row log while it runs, Parquet at the end.

Each finished candidate's row is appended to ``OUTPUT.rows.jsonl`` (one JSON object a line,
flushed at once) as its batch comes back, so a sweep killed at any point keeps every row
written before; a line cut short by the kill is dropped on reading. At the end the rows are
merged, in candidate order, into OUTPUT (Parquet, written to a temporary file and renamed)
and the log is removed. Floats go through JSON as their shortest repr, which reads back to
the same float: the numbers in the table are the twin's, bit for bit.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import IO, Any

from bwsd.extras import needs
from bwsd.sweep.candidate import HEAD, STATUS, Candidate, Row
from bwsd.sweep.errors import PYARROW, SweepError


def log_path(output: Path) -> Path:
    """Where the rows of a sweep writing ``output`` are logged while it runs."""
    return output.with_name(output.name + ".rows.jsonl")


def read_log(path: Path) -> list[Row]:
    """The complete rows of a log (none when it does not exist); a cut last line is dropped."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return []
    rows = []
    for line in data.split(b"\n"):
        try:
            row = json.loads(line)
        except ValueError:
            continue  # empty, or cut short by a kill (only the last line can be)
        if isinstance(row, dict) and "id" in row:
            rows.append(row)
    return rows


class RowLog:
    """The append-only log of one sweep (a context manager)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file: IO[bytes] | None = None

    def __enter__(self) -> RowLog:
        self._drop_cut_tail()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._file is not None:
            self._file.close()

    def _drop_cut_tail(self) -> None:
        """Cut a last line without its newline (a kill mid-write) before appending."""
        try:
            data = self.path.read_bytes()
        except FileNotFoundError:
            return
        keep = data.rfind(b"\n") + 1
        if keep != len(data):
            with open(self.path, "r+b") as fh:
                fh.truncate(keep)

    def append(self, rows: Iterable[Row]) -> None:
        """Write the rows and flush: a kill after this keeps them."""
        if self._file is None:  # opened on the first rows: a sweep that never ran leaves no log
            self._file = open(self.path, "ab")  # noqa: SIM115 - closed in __exit__
        text = "".join(json.dumps(r, allow_nan=False) + "\n" for r in rows)
        self._file.write(text.encode())
        self._file.flush()


def read_table_rows(path: Path) -> list[Row]:
    """The rows of an earlier sweep's Parquet output."""
    with needs(PYARROW, "reading sweep results", SweepError):
        import pyarrow.parquet as pq
    try:
        rows: list[Row] = pq.read_table(path).to_pylist()
    except (OSError, ValueError) as exc:
        raise SweepError(f"{path}: cannot read it as sweep results: {exc}") from None
    return rows


def columns(rows: Sequence[Row], params: Sequence[str]) -> list[str]:
    """The table's columns: id, index, the parameters, status, the metrics, seconds."""
    order = [*HEAD, *params, *STATUS]
    seen = set(order) | {"seconds"}
    for row in rows:
        for key in row:
            if key not in seen:
                seen.add(key)
                order.append(key)
    return [*order, "seconds"]


def merged(candidates: Sequence[Candidate], rows: Iterable[Row]) -> list[Row]:
    """One row per candidate, in candidate order; rows of other candidates are left out."""
    by_id = {row["id"]: row for row in rows}
    out = []
    for candidate in candidates:
        row = by_id.get(candidate.id)
        if row is not None:
            out.append({**row, "index": candidate.index})
    return out


def write_table(rows: Sequence[Row], params: Sequence[str], output: Path, csv: bool) -> None:
    """Write the rows as Parquet (and CSV beside it), each through a temporary file."""
    with needs(PYARROW, "writing sweep results", SweepError):
        import pyarrow as pa
        import pyarrow.csv as pcsv
        import pyarrow.parquet as pq
    names = columns(rows, params)
    table = pa.table({name: _array(pa, [row.get(name) for row in rows]) for name in names})
    _replace(output, lambda tmp: pq.write_table(table, tmp))
    if csv:
        _replace(output.with_suffix(".csv"), lambda tmp: pcsv.write_csv(table, tmp))


def _array(pa: Any, values: list[Any]) -> Any:
    """A column; integers among floats are floats (a metric that is 0 once stays a float)."""
    if any(isinstance(v, float) for v in values):
        values = [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in values]
    return pa.array(values)


def _replace(target: Path, write: Any) -> None:
    tmp = target.with_name(target.name + ".tmp")
    try:
        write(str(tmp))
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise SweepError(f"cannot write {target}: {exc.strerror or exc}") from None
