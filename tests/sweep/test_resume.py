"""A sweep killed (SIGKILL, a real process) and resumed: nothing finished is run again."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from bwsd.sweep.runner import Options, run_sweep
from bwsd.sweep.spec import load_spec
from bwsd.sweep.store import RowLog, log_path, read_log
from tests.sweep.conftest import bwsd, without_timing, write

# 36 candidates of a 6 x 6 braid, slow enough (about 20 ms each, one at a time on one
# worker) that the kill lands in the middle of the sweep.
SLOW_SPEC = """
[sweep]
generator = "braid4"
[fixed]
rows = 6
cols = 6
[vary]
cycles = [8, 10, 12]
takeup = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
c_mat = [0.3, 0.6]
"""


def _complete_lines(path: Path) -> int:
    try:
        return path.read_bytes().count(b"\n")
    except FileNotFoundError:
        return 0


def _kill_when_rows(proc: subprocess.Popen[bytes], log, rows: int) -> None:
    """SIGKILL the sweep once ``rows`` rows are logged, then what is left of its group."""
    deadline = time.monotonic() + 120
    while _complete_lines(log) < rows:
        assert proc.poll() is None, "the sweep ended before it could be killed"
        assert time.monotonic() < deadline, "no rows logged in time"
        time.sleep(0.005)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    with contextlib.suppress(ProcessLookupError):  # its worker processes, if any remain
        os.killpg(proc.pid, signal.SIGKILL)


@pytest.mark.slow
def test_a_killed_sweep_resumes_without_redoing_finished_candidates(tmp_path):
    spec_path = write(tmp_path, SLOW_SPEC)
    output = tmp_path / "slow.parquet"
    log = log_path(output)
    args = ["sweep", str(spec_path), "-o", str(output), "--workers", "1", "--batch", "1"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "bwsd.cli", *args],
        cwd=tmp_path,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    _kill_when_rows(proc, log, 4)
    assert proc.returncode == -signal.SIGKILL
    assert not output.exists()
    before = {row["id"]: row["seconds"] for row in read_log(log)}
    assert 4 <= len(before) < 36

    resumed = bwsd(*args[:-4], "--resume", cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(before)} already done, {36 - len(before)} run now" in resumed.stdout
    rows = pq.read_table(output).to_pylist()
    assert len(rows) == 36 and not log.exists()
    for row in rows:  # a row run again would have a timing of its own
        if row["id"] in before:
            assert row["seconds"] == before[row["id"]]

    whole = tmp_path / "whole.parquet"
    run_sweep(load_spec(spec_path), whole, Options(workers=2))
    assert without_timing(rows) == without_timing(pq.read_table(whole).to_pylist())


def test_a_row_cut_short_by_a_kill_is_dropped_and_run_again(tmp_path):
    log = tmp_path / "r.parquet.rows.jsonl"
    whole = json.dumps({"id": "a", "seconds": 0.5}) + "\n"
    log.write_text(whole + '{"id": "b", "seco')
    assert [row["id"] for row in read_log(log)] == ["a"]
    with RowLog(log) as rows:
        rows.append([{"id": "c", "seconds": 1.0}])
    assert log.read_text() == whole + json.dumps({"id": "c", "seconds": 1.0}) + "\n"
    assert [row["id"] for row in read_log(log)] == ["a", "c"]
