"""A sweep with ``relax = true``: each row measures the candidate's relaxed preform, as
`bwsd metrics --relaxed` does, and adds the solver's figures; without it nothing changes."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest

from bwsd.program.generators import GENERATORS
from bwsd.sweep.candidate import evaluate, flatten, relaxed_columns
from bwsd.sweep.runner import Options, run_sweep
from bwsd.sweep.spec import load_spec
from tests.sweep.conftest import (
    BRAID_SPEC,
    TIMINGS,
    WEAVE,
    WEAVE_CONFIG,
    bwsd,
    without_timing,
    write,
)

pytestmark = pytest.mark.slow  # every test here is in the slow tier

# Two small braids, each long enough for a formed zone once relaxed.
BRAID_RELAX = """
[sweep]
generator = "braid4"
relax = true
[fixed]
rows = 2
cols = 2
cycles = 8
diameter = 0.5
[vary]
takeup = [6.0, 8.0]
"""

# Wefts under a quarter of the warps' tension: the tensions' ratio shapes the relaxed weave.
WEFT_TENSION = 0.25


def _weave_config(folder: Path, c_mat: float | None = None) -> Path:
    """The plain weave's config with [yarn] tensions set (and its convergence changed)."""
    text = WEAVE_CONFIG.read_text(encoding="utf-8")
    text = re.sub(
        r"^diameter = .*$",
        f"diameter = 1.0\ntension = 1.0\nweft_tension = {WEFT_TENSION}",
        text,
        flags=re.M,
    )
    if c_mat is not None:
        text = re.sub(r"^c_mat = .*$", f"c_mat = {c_mat}", text, flags=re.M)
    name = "weave.toml" if c_mat is None else f"weave-{c_mat}.toml"
    return write(folder, text, name)


def _metrics_relaxed(program: Path, config: Path, z: float | None, cwd: Path) -> dict[str, Any]:
    """`bwsd metrics --relaxed --json` of one program, run as the command is."""
    args = ["metrics", str(program), "--config", str(config), "--relaxed", "--json"]
    if z is not None:
        args += ["--z", repr(z)]
    done = bwsd(*args, cwd=cwd)
    assert done.returncode == 0, done.stderr
    found: dict[str, Any] = json.loads(done.stdout)
    return found


def _as_row(found: dict[str, Any], z: float | None) -> dict[str, Any]:
    """The command's output as a sweep row's metric columns."""
    return {**flatten(found, z), **relaxed_columns(found)}


def _metric_columns(row: dict[str, Any]) -> dict[str, Any]:
    skip = {"id", "index", "status", "stage", "reason", *TIMINGS}
    return {k: v for k, v in row.items() if k not in skip}


def _same_metrics(row: dict[str, Any], found: dict[str, Any], params: set[str]) -> None:
    mine = {k: v for k, v in _metric_columns(row).items() if k not in params}
    theirs = {k: v for k, v in _as_row(found, row["footprint_z"]).items() if k not in TIMINGS}
    # a parquet table has every column of every row: a column another row has is None here
    assert {k: v for k, v in mine.items() if v is not None} == {
        k: v for k, v in theirs.items() if v is not None
    }
    assert set(theirs) <= set(mine)


def test_a_relaxed_sweep_of_braids_on_a_local_cluster_equals_metrics_relaxed(tmp_path):
    spec = load_spec(write(tmp_path, BRAID_RELAX))
    assert spec.relax
    output = tmp_path / "relaxed.parquet"
    summary = run_sweep(spec, output, Options(workers=2))
    assert (summary.total, summary.ran, summary.refused, summary.workers) == (2, 2, 0, 2)
    rows = pq.read_table(output).to_pylist()
    unrelaxed = write(tmp_path, BRAID_RELAX.replace("relax = true", "relax = false"), "t.toml")
    twins = [evaluate(c) for c in load_spec(unrelaxed).candidates()]
    for row, candidate, twin in zip(rows, spec.candidates(), twins, strict=True):
        assert row["status"] == "ok" and row["id"] == candidate.id
        generated = GENERATORS["braid4"](**candidate.params)
        program = write(tmp_path, generated.program, f"braid-{row['takeup']}.bws")
        config = write(tmp_path, generated.config_toml(), f"braid-{row['takeup']}.toml")
        found = _metrics_relaxed(program, config, row["footprint_z"], tmp_path)
        _same_metrics(row, found, set(candidate.columns))
        # the numbers that matter, spelled out: the relaxed preform's, not the twin's
        assert row["formed_first_cycle"] == found["formed"]["cycles"][0] is not None
        assert row["angle_warp"] == found["angles"]["warp"]["all"]["mean"]
        fractions = [h["fraction"] for h in found["volume_fraction"]]
        assert row["volume_fraction"] == sum(fractions) / 3 > 0
        assert row["width"] == found["section"]["width"]
        assert row["relax_steps"] == found["relaxed"]["steps"] > 0
        assert row["relax_separate_steps"] == found["relaxed"]["separate_steps"]
        assert row["relax_force_residual"] == found["relaxed"]["force_residual"]
        assert row["relax_worst_overlap"] == found["relaxed"]["worst_overlap"]
        assert row["relax_seconds"] > 0
        # no interpenetration left, in the formed zone and along the whole skeleton
        assert row["overlap"] == 0.0 and row["overlap_worst"] == 0.0
        assert row["skeleton_overlap"] == 0.0 and row["skeleton_overlap_worst"] == 0.0
        # ... where the twin's skeleton of the same candidate had some
        assert twin["skeleton_overlap"] > 0 and "relax_steps" not in twin


def test_a_relaxed_sweep_of_a_program_takes_the_tensions_of_its_config(tmp_path):
    config = _weave_config(tmp_path)
    text = (
        f'[sweep]\nprogram = "{WEAVE}"\nconfig = "{config}"\nrelax = true\n'
        "[vary]\nc_mat = [0.5, 0.4]\n"
    )
    spec = load_spec(write(tmp_path, text))
    output = tmp_path / "weave.parquet"
    run_sweep(spec, output, Options(workers=2))
    rows = pq.read_table(output).to_pylist()
    assert [r["status"] for r in rows] == ["ok", "ok"]
    for row in rows:
        config = _weave_config(tmp_path, row["c_mat"])
        found = _metrics_relaxed(WEAVE, config, row["footprint_z"], tmp_path)
        _same_metrics(row, found, {"c_mat"})
        assert row["weft_crimp"] == found["crimp"]["mean"] > 0
        # what overlap is left lies within the solver's tolerance, 0.5 % of d (1 mm here)
        assert row["skeleton_overlap_worst"] <= 0.005 and row["relax_worst_overlap"] <= 0.005
        assert row["skeleton_overlap"] < 1e-4
    # the tensions came from the config: the same program under equal tensions crimps less
    equal = _metrics_relaxed(WEAVE, WEAVE_CONFIG, None, tmp_path)
    assert rows[0]["weft_crimp"] > equal["crimp"]["mean"] > 0


def test_without_relax_ids_columns_and_values_are_as_before(tmp_path):
    plain = load_spec(write(tmp_path, BRAID_SPEC)).candidates()[:3]
    said = BRAID_SPEC.replace('generator = "braid4"', 'generator = "braid4"\nrelax = false')
    unrelaxed = load_spec(write(tmp_path, said, "false.toml")).candidates()[:3]
    relaxed = load_spec(write(tmp_path, said.replace("false", "true"), "true.toml")).candidates()
    for candidate in plain:  # the id hashes the generator and the parameters only, as before
        key = {"source": {"generator": "braid4"}, "params": dict(candidate.columns)}
        text = json.dumps(key, sort_keys=True, allow_nan=False)
        assert candidate.id == hashlib.sha256(text.encode()).hexdigest()[:16]
        assert not candidate.relax
    assert [c.id for c in unrelaxed] == [c.id for c in plain]
    assert {c.id for c in relaxed}.isdisjoint(c.id for c in plain)  # a relaxed row is another
    rows = [evaluate(c) for c in plain]
    assert without_timing(rows) == without_timing([evaluate(c) for c in unrelaxed])
    for row in rows:
        assert not [k for k in row if k.startswith(("relax_", "weft_crimp"))]
    # relaxed, a candidate (6 mm a cycle: a formed zone either way) has the same columns and
    # the solver's after them
    twin, tight = (
        evaluate(load_spec(write(tmp_path, BRAID_SPEC, "b.toml")).candidates()[12]),
        evaluate(relaxed[12]),
    )
    assert relaxed[12].params["takeup"] == 6.0
    extra = [k for k in tight if k not in twin]
    assert extra == list(relaxed_columns_names())
    assert [k for k in tight if k in twin] == [k for k in twin if k != "seconds"] + ["seconds"]
    assert tight["angle_warp"] != twin["angle_warp"]  # measured on the relaxed preform


def relaxed_columns_names() -> list[str]:
    """The columns a relaxed row adds, in order (docs/sweeps.md)."""
    return [
        "relax_separate_steps",
        "relax_steps",
        "relax_rejected_steps",
        "relax_added_nodes",
        "relax_tension_length_twin",
        "relax_tension_length",
        "relax_worst_overlap",
        "relax_worst_overlap_share",
        "relax_force_residual",
        "relax_sides_kept",
        "relax_sides_told",
        "relax_seconds",
        "weft_crimp",
        "weft_crimp_max",
    ]
