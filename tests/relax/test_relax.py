"""The relaxed preform (docs/relax.md): one test per limit of the paper's model that the
relaxation lifts, and the targets that can be checked on every run."""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from bwsd.errors import BwsdError
from bwsd.export.formed import takeups_of
from bwsd.export.metrics import metrics
from bwsd.program.generators import GENERATORS
from bwsd.program.parser import parse_program
from bwsd.relax import Options, crimp, relax
from bwsd.relax.document import relaxed_to_dict
from bwsd.relax.solver import Layout
from bwsd.relax.state import Chains
from bwsd.relax.topology import contact_sides
from bwsd.twin import Machine, Shift, TakeUp, Twin, simulate
from bwsd.twin.skeleton import FloatArray, SkeletonData
from tests.relax.conftest import EXAMPLES, metrics_of, overlap_share, relaxed_of, twin_of
from tests.relax.passes import passes_through
from tests.twin.test_against_reference import _fitting, braids

TWIST_MACHINE = Machine(rows=2, cols=2, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5)
TURN = [
    Shift("row", ((0, 1), (1, -1))),
    Shift("col", ((1, 1), (0, -1))),
    Shift("row", ((1, -1), (0, 1))),
    Shift("col", ((0, -1), (1, 1))),
]


def _undo(ins: Shift) -> Shift:
    return Shift(ins.axis, tuple(m._replace(k=-m.k) for m in ins.moves))


def twisted(turns: int, back: int) -> SkeletonData:
    """Two yarns twisted ``turns`` times, then untwisted ``back`` times (after 2 mm of
    take-up, so that both yarns leave the fell before they cross)."""
    twin = Twin(TWIST_MACHINE, [(0, 0), (1, 1)], 1.0)
    twin.apply(TakeUp(2.0))
    for ins in TURN * turns + [_undo(i) for i in reversed(TURN)] * back:
        twin.apply(ins)
    return twin.skeleton()


def straight_length(sk: SkeletonData) -> float:
    """The tension-weighted length of the yarns pulled straight between their fixed ends
    (tension 1): the least any relaxation can reach."""
    return sum(float(np.linalg.norm(np.subtract(y.nodes[-1], y.nodes[0]))) for y in sk.yarns)


# --- Why: "braid-2x2 has 50 % of its yarn length within one diameter of another yarn" -----


@pytest.mark.slow
@pytest.mark.parametrize("name", EXAMPLES)
def test_relaxed_examples_have_no_interpenetration(name: str) -> None:
    """The share of yarn length within d less 1 % of d of another yarn, by the metrics' own
    measure, is 0 after relaxation; before, the twin's skeleton overlaps (braid-2x2: half)."""
    before = overlap_share(twin_of(name), 1.0)
    after = overlap_share(relaxed_of(name).skeleton, 0.99)
    assert before > (0.4 if name == "braid-2x2" else 0.0)
    assert after == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("name", EXAMPLES)
def test_worst_overlap_is_within_one_percent_of_d(name: str) -> None:
    """The solver's own figure agrees with the metrics: no pair closer than 0.99 d."""
    summary = relaxed_of(name).summary()
    assert summary["worst_overlap_share"] < 0.01


# --- Why: "paper-L's section is 60.9 x 85.7 mm ... yarn fills 0.9 % of its bounding box" ---


@pytest.mark.slow
def test_relaxed_paper_l_is_tighter() -> None:
    """Width, thickness and the formed zone's section area shrink, the volume fraction rises
    (the full compaction to the fell's 28 x 40 mm is not reached: docs/relax.md, "Limits")."""
    before = metrics_of("paper-L", twin_of("paper-L"))
    after = metrics_of("paper-L", relaxed_of("paper-L").skeleton)
    assert after["section"]["width"] < before["section"]["width"]
    assert after["section"]["thickness"] < before["section"]["thickness"]
    area = [np.mean([h["section_area"] for h in m["volume_fraction"]]) for m in (before, after)]
    share = [np.mean([h["fraction"] for h in m["volume_fraction"]]) for m in (before, after)]
    assert area[1] < 0.9 * area[0]
    assert share[1] > share[0]


# --- Why: "Wefts are straight lines" ----------------------------------------------------


@pytest.mark.slow
def test_relaxed_wefts_are_crimped() -> None:
    """The twin's wefts are straight (crimp 0); relaxed, every weft held by warps bends round
    them, and the reported crimp is (length - span) / span of the written nodes."""
    assert crimp(twin_of("weave-U"))["max"] == pytest.approx(0.0, abs=1e-12)
    relaxed = relaxed_of("weave-U")
    document = json.loads(json.dumps(relaxed_to_dict(relaxed)))
    wefts = [y for y in document["yarns"] if y["kind"] == "weft"]
    expected = []
    for yarn in wefts:
        nodes = np.array(yarn["nodes"], dtype=np.float64)
        span = math.dist(nodes[0], nodes[-1])
        length = sum(math.dist(p, q) for p, q in itertools.pairwise(nodes))
        expected.append((length - span) / span)
    found = document["crimp"]
    assert found["per_weft"] == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert found["mean"] == pytest.approx(sum(expected) / len(expected))
    assert found["mean"] > 1e-4
    held = {c.moving_yarn for c in twin_of("weave-U").contacts} | {
        c.hit_yarn for c in twin_of("weave-U").contacts
    }
    ids = [y["id"] for y in wefts]
    assert all(c > 0 for c, i in zip(expected, ids, strict=True) if i in held)


# --- Why: "Untwisting a twist adds contacts instead of removing them" --------------------


def test_untwisted_yarns_come_apart() -> None:
    """Twisted twice and untwisted twice, the twin keeps every contact (12, each at d); the
    relaxed yarns come apart (no crossing within 1.05 d) and pull straight (the tension x
    length within 0.1 % of the straight yarns'). A twist not undone stays wound."""
    undone = twisted(2, 2)
    _, _, gap_twin = contact_sides(undone)
    assert len(undone.contacts) >= 8 and np.all(gap_twin < 1.0001)
    relaxed = relax(undone, Options(max_steps=4000))
    _, _, gap = contact_sides(relaxed.skeleton)
    assert np.all(gap > 1.05)
    assert relaxed.figures.energy <= 1.001 * straight_length(undone)
    wound = relax(twisted(2, 0), Options(max_steps=4000))
    _, _, gap = contact_sides(wound.skeleton)
    assert np.median(gap) < 1.05
    assert wound.figures.energy > 1.01 * straight_length(undone)


# --- Targets -------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("name", EXAMPLES)
def test_every_contact_keeps_its_side(name: str) -> None:
    """Each contact's crossing keeps its sign (over or under) from the twin to the relaxed
    preform, wherever the two yarns still cross near it."""
    before, _, _ = contact_sides(twin_of(name))
    after, _, apart = contact_sides(relaxed_of(name).skeleton)
    told = (before != 0) & (after != 0) & (apart < 2 * twin_of(name).diameter)
    assert told.sum() >= 0.7 * len(before)
    assert np.array_equal(before[told], after[told])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["twist", "braid-2x2"])
def test_no_step_passes_a_yarn_through_another(name: str) -> None:
    """An independent continuous check of every step's straight-line motion."""
    found: list[int] = []

    def trace(old: FloatArray, new: FloatArray, chains: Chains) -> None:
        lay = Layout.of(chains)
        found.append(passes_through(old, new, lay.a, lay.b, lay.yarn))

    relax(twin_of(name), Options(max_steps=150), trace=trace)
    assert len(found) > 20
    assert sum(found) == 0


def test_the_continuous_check_sees_a_pass_through() -> None:
    """The check itself: a segment moved straight through another is found."""
    old = np.array([[0, 0, -1], [0, 0, 1], [-1, 1, 0], [1, 1, 0]], dtype=np.float64)
    new = old.copy()
    new[2:, 1] = -1
    a, b, yarn = np.array([0, 2]), np.array([1, 3]), np.array([0, 1])
    assert passes_through(old, new, a, b, yarn) == 1
    new[2:, 1] = 0.5
    assert passes_through(old, new, a, b, yarn) == 0


@pytest.mark.parametrize("name", ["twist", "braid-2x2", "weave-U"])
def test_the_tension_weighted_length_never_rises(name: str) -> None:
    """Step after step of the tightening, and it ends below the twin's."""
    relaxed = relaxed_of(name)
    energies = np.array(relaxed.figures.energies)
    assert len(energies) > 10
    assert np.all(np.diff(energies) <= 0.0)
    assert relaxed.figures.energy < relaxed.figures.energy_twin


@pytest.mark.slow
def test_the_same_input_gives_the_same_bytes() -> None:
    sk = twin_of("braid-2x2")
    one = relaxed_to_dict(relax(sk))
    two = relaxed_to_dict(relax(sk))
    for doc in (one, two):
        doc["relaxed"].pop("seconds")
    assert json.dumps(one) == json.dumps(two)


def test_fixed_ends_stay_and_weft_ends_slide_in_z_only() -> None:
    twin, relaxed = twin_of("weave-U"), relaxed_of("weave-U").skeleton
    for y0, y1 in zip(twin.yarns, relaxed.yarns, strict=True):
        first0, last0 = np.asarray(y0.nodes[0]), np.asarray(y0.nodes[-1])
        first1, last1 = np.asarray(y1.nodes[0]), np.asarray(y1.nodes[-1])
        if y0.kind == "warp":
            assert np.array_equal(first0, first1) and np.array_equal(last0, last1)
        else:
            assert np.array_equal(first0[:2], first1[:2]) and np.array_equal(last0[:2], last1[:2])


def test_only_the_tension_ratio_matters() -> None:
    sk = twin_of("twist")
    one = relax(sk, Options(warp_tension=1.0, weft_tension=1.0))
    ten = relax(sk, Options(warp_tension=10.0, weft_tension=10.0))
    for y1, y10 in zip(one.skeleton.yarns, ten.skeleton.yarns, strict=True):
        assert np.allclose(y1.nodes, y10.nodes, atol=1e-9)


def braid_metrics(takeup: float, relaxed: bool) -> dict[str, Any]:
    """``bwsd metrics`` of a 3 x 3 rectangular 4-step braid (0.5 mm yarn, 20 cycles), of
    the twin's skeleton or the relaxed one."""
    generated = GENERATORS["braid4"](3, 3, cycles=20, takeup=takeup, diameter=0.5)
    program = parse_program(generated.program)
    sk = simulate(generated.machine, program).skeleton()
    if relaxed:
        sk = relax(sk).skeleton
    return metrics(sk, program.cycle_length, takeups=takeups_of(program))


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="missed: 6.0 against 4.5 mm (docs/relax.md, Results)")
def test_the_one_over_h_law_holds_after_relaxation() -> None:
    """tan(braid angle) x take-up per cycle of the formed zone stays constant within 10 %
    after relaxation, as for the twin (tests/export/test_formed.py)."""
    law = []
    for h in (4.0, 16.0):
        found = braid_metrics(h, relaxed=True)
        law.append(math.tan(math.radians(found["angles"]["warp"]["all"]["mean"])) * h)
    assert max(law) / min(law) - 1 <= 0.10, law


def test_a_centreline_only_model_is_left_as_it_is() -> None:
    """d = 0: no reach to move in without risking a pass-through; the skeleton stays."""
    sk = replace(twisted(1, 0), diameter=0.0)
    relaxed = relax(sk)
    for y0, y1 in zip(sk.yarns, relaxed.skeleton.yarns, strict=True):
        assert np.array_equal(y0.nodes, y1.nodes)


# --- Deliverable: sections from contacts, to TexGen and back ---------------------------


def test_sections_are_flattened_and_read_back_from_texgen(tmp_path: Path) -> None:
    """Pressed nodes flatten (area kept: width x height = d^2), and the .tg3 gives back each
    node's ellipse and up vector."""
    pytest.importorskip("pytexgen")
    from bwsd.export.texgen import read_tg3_sections, write_tg3

    relaxed = relaxed_of("twist")
    d = relaxed.skeleton.diameter
    table = np.vstack(relaxed.sections)
    assert np.allclose(table[:, 0] * table[:, 1], d * d)
    assert (table[:, 1] < 0.99 * d).any()
    assert np.allclose(np.linalg.norm(table[:, 2:], axis=1), 1.0)
    path = tmp_path / "relaxed.tg3"
    write_tg3(relaxed.skeleton, path, sections=relaxed.sections)
    back = read_tg3_sections(path)
    for mine, theirs in zip(relaxed.sections, back, strict=True):
        assert theirs.shape == mine.shape
        assert np.allclose(theirs[:, :2], mine[:, :2], rtol=1e-6)
        assert np.allclose(theirs[:, 2:], mine[:, 2:], atol=1e-6)


@pytest.mark.slow
@settings(
    max_examples=20,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(braids(), st.floats(0.2, 0.9))
def test_small_random_programs_relax_without_a_pass_through_or_a_side_flipped(
    case, share: float
) -> None:
    """Hypothesis-drawn small programs (the twin's own strategy: the 8-carrier braid of 1 to
    3 cycles with any pitch, convergence and take-up; a yarn of a random share of the largest
    diameter that fits): no step of the relaxation passes a yarn through another, and every
    contact still told keeps its side."""
    machine, fill, _, instructions = case
    twin = Twin(machine, fill, _fitting(machine, share))  # a yarn with a section
    for ins in instructions:
        try:
            twin.apply(ins)
        except BwsdError:
            break  # refused (a jam, a closed shed): the program ends there
    sk = twin.skeleton()
    if sk.diameter == 0:
        event("centreline only")
        return  # a centreline-only model is left as it is (tested above)
    event("3 contacts or more" if len(sk.contacts) >= 3 else "fewer than 3 contacts")
    found: list[int] = []

    def trace(old: FloatArray, new: FloatArray, chains: Chains) -> None:
        lay = Layout.of(chains)
        found.append(passes_through(old, new, lay.a, lay.b, lay.yarn))

    relaxed = relax(sk, Options(max_separate=100, max_steps=100), trace=trace)
    assert sum(found) == 0
    before, _, _ = contact_sides(sk)
    after, _, apart = contact_sides(relaxed.skeleton)
    told = (before != 0) & (after != 0) & (apart < 2 * sk.diameter)
    event("sides told" if told.any() else "no side told")
    assert np.array_equal(before[told], after[told])


def test_a_skeleton_without_yarns_relaxes_to_itself() -> None:
    """A program whose fill holds no case (the API's fuzzing loaded one): nothing to relax."""
    sk = Twin(Machine(4, 4, 10.0, 10.0, 100.0, 0.5), [], 1.0).skeleton()
    relaxed = relax(sk)
    assert relaxed.skeleton is sk and relaxed.sections == ()
    document = relaxed_to_dict(relaxed)
    assert document["yarns"] == [] and document["crimp"]["per_weft"] == []
