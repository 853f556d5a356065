"""`bwsd sweep` on the command line: a bad request ends with one line and writes nothing."""

from __future__ import annotations

import os
import subprocess
import sys

import pyarrow.parquet as pq
import pytest

from bwsd.cli import main
from tests.sweep.conftest import ROOT, bwsd, write


def test_a_bad_spec_is_one_error_line_and_nothing_is_written(tmp_path, capsys):
    spec = write(tmp_path, '[sweep]\ngenerator = "braid4"\n[vary]\ntakeup = "1"\n')
    assert main(["sweep", str(spec), "-o", str(tmp_path / "r.parquet")]) == 2
    err = capsys.readouterr().err
    assert err == f"bwsd: error: {spec}: [vary.takeup]: must be a non-empty list of values\n"
    assert list(tmp_path.iterdir()) == [spec]


def test_workers_and_a_scheduler_together_are_refused(tmp_path, capsys):
    spec = write(tmp_path, '[sweep]\ngenerator = "twist"\n')
    args = ["sweep", str(spec), "-o", "r.parquet", "--workers", "2", "--scheduler", "tcp://x:1"]
    assert main(args) == 2
    assert "--workers sizes the local cluster" in capsys.readouterr().err


def test_csv_beside_an_output_named_csv_is_refused(tmp_path, capsys):
    spec = write(tmp_path, '[sweep]\ngenerator = "twist"\n')
    assert main(["sweep", str(spec), "-o", str(tmp_path / "r.csv"), "--csv"]) == 2
    assert "the results are Parquet (e.g. -o results.parquet)" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == [spec]


@pytest.mark.slow
def test_the_shipped_example_runs_by_name(tmp_path):
    run = bwsd(
        "sweep",
        "example:braid-angle.sweep.toml",
        "-o",
        "b.parquet",
        "--workers",
        "2",
        "--csv",
        cwd=tmp_path,
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith(
        "b.parquet: 24 candidates, 23 ok, 1 refused; 0 already done, 24 run now (2 workers, "
    )
    table = pq.read_table(tmp_path / "b.parquet")
    assert table.num_rows == 24 and (tmp_path / "b.csv").exists()
    assert sorted(set(table.column("c_mat").to_pylist())) == [0.3, 0.5, 0.7]
    assert (ROOT / "examples" / "braid-angle.sweep.toml").exists()
    missing = bwsd("sweep", "example:nothing.toml", "-o", "n.parquet", cwd=tmp_path)
    assert missing.returncode == 2
    assert "examples/nothing.toml is not shipped" in missing.stderr


@pytest.mark.slow
def test_without_the_sweep_extra_the_command_names_it_and_writes_nothing(tmp_path):
    folder = tmp_path / "site"
    folder.mkdir()
    (folder / "sitecustomize.py").write_text(
        "import sys\nfor name in ('dask', 'distributed', 'pyarrow'):\n"
        "    sys.modules[name] = None\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), str(ROOT)])}
    spec = write(tmp_path, '[sweep]\ngenerator = "twist"\n')
    for args in (
        ["sweep", str(spec), "-o", "r.parquet"],
        ["sweep", "plot", "r.parquet", "--x", "a", "--y", "b"],
    ):
        run = subprocess.run(
            [sys.executable, "-m", "bwsd.cli", *args],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        assert run.returncode == 2, run.stderr
        assert "needs " in run.stderr and "pip install 'bwsd[sweep]'" in run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site", "spec.toml"]
