"""A sweep on a local Dask cluster of processes: the same rows as the candidates run one by one."""

from __future__ import annotations

import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest

from bwsd.sweep.candidate import evaluate
from bwsd.sweep.errors import SweepError
from bwsd.sweep.runner import Options, run_sweep
from bwsd.sweep.spec import load_spec
from bwsd.sweep.store import log_path
from tests.sweep.conftest import BRAID_SPEC, WEAVE_SPEC, reference, without_timing, write


@pytest.mark.slow
def test_a_sweep_on_a_local_cluster_equals_the_candidates_run_one_by_one(tmp_path):
    spec = load_spec(write(tmp_path, BRAID_SPEC))
    output = tmp_path / "results.parquet"
    summary = run_sweep(spec, output, Options(workers=2, batch=3, csv=True))
    assert (summary.total, summary.ran, summary.resumed, summary.workers) == (20, 20, 0, 2)
    rows = pq.read_table(output).to_pylist()
    candidates = spec.candidates()
    assert [r["id"] for r in rows] == [c.id for c in candidates]
    assert without_timing(rows) == without_timing([evaluate(c) for c in candidates])
    for row, candidate in zip(rows, candidates, strict=True):
        found = reference("braid4", dict(candidate.params))
        assert row["angle_warp"] == found["angles"]["warp"]["all"]["mean"]  # bit for bit
        assert row["width"] == found["section"]["width"]
        assert row["contacts"] == found["contacts"]
    assert len({r["angle_warp"] for r in rows}) == 20  # every candidate differs
    assert not log_path(output).exists()
    assert pcsv.read_csv(tmp_path / "results.csv").column("id").to_pylist() == [
        c.id for c in candidates
    ]


@pytest.mark.slow
def test_refused_candidates_are_rows_of_the_table_not_a_failed_sweep(tmp_path):
    spec = load_spec(write(tmp_path, WEAVE_SPEC))
    output = tmp_path / "weave.parquet"
    summary = run_sweep(spec, output, Options(workers=2))
    assert (summary.total, summary.refused) == (4, 3)
    rows = pq.read_table(output).to_pylist()
    assert [r["status"] for r in rows] == ["ok", "refused", "refused", "refused"]
    assert [r["stage"] for r in rows] == [None, "simulate", "validate", "validate"]
    assert "shed closed" in rows[1]["reason"]
    assert rows[0]["contacts"] == 200 and rows[1]["contacts"] is None


def test_an_unfinished_sweep_is_not_overwritten_without_resume(tmp_path):
    spec = load_spec(write(tmp_path, BRAID_SPEC))
    output = tmp_path / "r.parquet"
    log_path(output).write_text("")
    with pytest.raises(SweepError, match=r"unfinished sweep: --resume goes on with it"):
        run_sweep(spec, output, Options(workers=1))
    assert not output.exists()
    with pytest.raises(SweepError, match=r"no such folder"):
        run_sweep(spec, tmp_path / "nowhere" / "r.parquet", Options(workers=1))


@pytest.mark.slow
def test_a_finished_sweep_resumed_runs_nothing_and_keeps_its_rows(tmp_path):
    spec = load_spec(write(tmp_path, WEAVE_SPEC))
    output = tmp_path / "w.parquet"
    run_sweep(spec, output, Options(workers=1))
    first = pq.read_table(output).to_pylist()
    summary = run_sweep(spec, output, Options(resume=True))
    assert (summary.ran, summary.resumed, summary.workers) == (0, 4, 0)
    assert pq.read_table(output).to_pylist() == first  # timings too: nothing ran again
