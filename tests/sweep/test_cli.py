"""`bwsd sweep` on the command line: a bad request ends with one line and writes nothing."""

from __future__ import annotations

import pyarrow.parquet as pq

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


def test_the_shipped_example_runs_by_name(tmp_path):
    run = bwsd("sweep", "example:braid-angle.sweep.toml", "-o", "b.parquet", "--workers", "2",
               "--csv", cwd=tmp_path)  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == ("b.parquet: 24 candidates, 24 ok, 0 refused; 0 already done, "
                                  "24 run now (2 workers)")  # fmt: skip
    table = pq.read_table(tmp_path / "b.parquet")
    assert table.num_rows == 24 and (tmp_path / "b.csv").exists()
    assert sorted(set(table.column("c_mat").to_pylist())) == [0.3, 0.5, 0.7]
    assert (ROOT / "examples" / "braid-angle.sweep.toml").exists()
    missing = bwsd("sweep", "example:nothing.toml", "-o", "n.parquet", cwd=tmp_path)
    assert missing.returncode == 2
    assert "examples/nothing.toml is not shipped" in missing.stderr
