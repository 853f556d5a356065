"""A sweep on an existing Dask cluster: a scheduler and two workers, separate processes on
loopback, started here with Dask's own `dask scheduler` and `dask worker` commands."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from distributed import Client

from bwsd.sweep.candidate import evaluate
from bwsd.sweep.spec import load_spec
from tests.sweep.conftest import BRAID_SPEC, WEAVE_SPEC, bwsd, without_timing, write

pytestmark = pytest.mark.slow  # every test here is in the slow tier

DASK = str(Path(sys.executable).parent / "dask")


def _start(args: list[str], folder: Path, name: str) -> subprocess.Popen[bytes]:
    log = open(folder / f"{name}.log", "wb")  # noqa: SIM115 - the process owns it
    return subprocess.Popen(
        [DASK, *args], cwd=folder, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )


def _stop(proc: subprocess.Popen[bytes]) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=20)


def _address(path: Path, scheduler: subprocess.Popen[bytes]) -> str:
    deadline = time.monotonic() + 60
    while not path.exists() or not path.read_text().strip():
        assert scheduler.poll() is None, "the scheduler ended"
        assert time.monotonic() < deadline, "the scheduler wrote no address"
        time.sleep(0.05)
    address: str = json.loads(path.read_text())["address"]
    return address


@pytest.fixture(scope="module")
def cluster(tmp_path_factory) -> Iterator[str]:
    """The address of a scheduler with two one-thread workers, all on 127.0.0.1."""
    folder = tmp_path_factory.mktemp("dask")
    file = folder / "scheduler.json"
    procs = [
        _start(
            [
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(file),
            ],
            folder,
            "scheduler",
        )
    ]
    try:
        address = _address(file, procs[0])
        for name in ("one", "two"):
            procs.append(
                _start(
                    [
                        "worker",
                        address,
                        "--host",
                        "127.0.0.1",
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--no-dashboard",
                        "--name",
                        name,
                        "--local-directory",
                        str(folder),
                    ],
                    folder,
                    name,
                )
            )
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        assert address.startswith("tcp://127.0.0.1:")
        yield address
    finally:
        for proc in reversed(procs):
            _stop(proc)


def test_a_sweep_on_a_scheduler_runs_on_its_workers_and_equals_one_by_one(cluster, tmp_path):
    spec_path = write(tmp_path, BRAID_SPEC)
    output = tmp_path / "remote.parquet"
    run = bwsd(
        "sweep",
        str(spec_path),
        "-o",
        str(output),
        "--scheduler",
        cluster,
        "--batch",
        "1",
        cwd=tmp_path,
    )
    assert run.returncode == 0, run.stderr
    assert "20 candidates, 20 ok, 0 refused; 0 already done, 20 run now (2 workers, " in run.stdout
    rows = pq.read_table(output).to_pylist()
    candidates = load_spec(spec_path).candidates()
    assert without_timing(rows) == without_timing([evaluate(c) for c in candidates])
    with Client(cluster, timeout="30s") as client:
        ran = client.run(lambda: "bwsd.sweep.candidate" in sys.modules)
    assert sorted(ran.values()) == [True, True]  # both workers ran candidates


def test_refusals_on_a_scheduler_are_rows(cluster, tmp_path):
    output = tmp_path / "weave.parquet"
    run = bwsd(
        "sweep",
        str(write(tmp_path, WEAVE_SPEC)),
        "-o",
        str(output),
        "--scheduler",
        cluster,
        cwd=tmp_path,
    )
    assert run.returncode == 0, run.stderr
    rows = pq.read_table(output).to_pylist()
    assert [r["stage"] for r in rows] == [None, "simulate", "validate", "validate"]
