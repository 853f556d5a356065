"""One candidate: its row holds `bwsd metrics`' numbers; a refusal is a row with its reason."""

from __future__ import annotations

import math

from bwsd.sweep.candidate import evaluate
from bwsd.sweep.spec import load_spec
from tests.sweep.conftest import BRAID_SPEC, WEAVE_SPEC, reference, write


def test_a_row_holds_the_metrics_of_the_candidate_run_on_its_own(tmp_path):
    candidate = load_spec(write(tmp_path, BRAID_SPEC)).candidates()[7]
    row = evaluate(candidate)
    found = reference("braid4", dict(candidate.params))
    assert row["status"] == "ok" and row["reason"] is None
    assert row["id"] == candidate.id and row["takeup"] == candidate.params["takeup"]
    assert row["formed_first_cycle"] == found["formed"]["cycles"][0] is not None
    assert row["formed_z_high"] == found["formed"]["z"][1]
    warp = found["angles"]["warp"]
    assert row["angle_warp"] == warp["all"]["mean"]
    assert row["angle_warp_std"] == warp["all"]["std"]
    assert row["angle_warp_interior"] == warp["interior"]["mean"]
    assert row["angle_warp_surface"] == warp["surface"]["mean"]
    assert row["skeleton_angle_warp"] == found["skeleton_angles"]["warp"]["mean"]
    overlap = found["interpenetration"]
    assert row["overlap"] == overlap["formed"]["all"]["share"] > 0
    assert row["overlap_worst"] == overlap["formed"]["all"]["worst"]
    assert row["skeleton_overlap_p95"] == overlap["skeleton"]["all"]["p95"]
    fractions = [h["fraction"] for h in found["volume_fraction"]]
    assert row["volume_fraction"] == sum(fractions) / 3
    assert (row["volume_fraction_min"], row["volume_fraction_max"]) == (
        min(fractions),
        max(fractions),
    )
    assert row["width"] == found["section"]["width"]
    assert row["thickness"] == found["section"]["thickness"]
    assert row["contacts"] == found["contacts"] > 0
    assert row["nodes"] == found["nodes"]
    assert row["contacts_per_cycle"] == found["cycles"]["mean"]
    assert row["groups"] == found["groups"]["count"]
    assert row["footprint_area"] == found["footprint"]["measured"]["area"] > 0
    assert row["footprint_coverage"] == found["footprint"]["coverage"]
    assert row["mixed_by_cycle"] == found["mixing"]["k"]
    assert row["section"] == "rect:3x3"
    assert math.isfinite(row["seconds"]) and row["seconds"] > 0


def test_each_refusal_is_a_row_with_its_stage_and_reason(tmp_path):
    rows = [evaluate(c) for c in load_spec(write(tmp_path, WEAVE_SPEC)).candidates()]
    by = {(r["rows"], r["pitch"]): r for r in rows}
    assert by[3, 10.0]["status"] == "ok" and by[3, 10.0]["contacts"] == 200
    twin = by[3, 5.0]
    assert (twin["status"], twin["stage"]) == ("refused", "simulate")
    assert "weave-plain.bws:" in twin["reason"] and "shed closed" in twin["reason"]
    assert "contacts" not in twin  # no metrics for a refused candidate
    for key in ((2, 10.0), (2, 5.0)):
        assert (by[key]["status"], by[key]["stage"]) == ("refused", "validate")
        assert "would leave the matrix" in by[key]["reason"]


def test_a_generator_or_config_refusal_is_a_row(tmp_path):
    spec = '[sweep]\ngenerator = "braid4"\n[fixed]\ncycles = 2\n[vary]\ntakeup = [0.0, 2.0]\n'
    rows = [evaluate(c) for c in load_spec(write(tmp_path, spec)).candidates()]
    assert [(r["status"], r["stage"]) for r in rows] == [("refused", "generate"), ("ok", None)]
    assert rows[0]["reason"] == "take-up must be positive"
    text = WEAVE_SPEC.replace("rows = [3, 2]\npitch = [10.0, 5.0]", "c_mat = [1.5]")
    (row,) = [evaluate(c) for c in load_spec(write(tmp_path, text, "w.toml")).candidates()]
    assert (row["status"], row["stage"]) == ("refused", "config")
    assert "[machine.c_mat]: must lie in [0, 1], got 1.5" in row["reason"]
