"""The formed zone and its braid angle (docs/exports.md, "formed" and "angles")."""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np
import pytest

from bwsd.export.arrays import Arrays
from bwsd.export.formed import MIN_CYCLES, find_zone, guide_heights, pieces, takeups_of
from bwsd.export.metrics import metrics
from bwsd.program.generators import EXAMPLES, GENERATORS
from bwsd.program.parser import parse_program
from bwsd.twin import simulate

TAKEUPS = (2.0, 4.0, 8.0, 16.0)


@cache
def braid(takeup: float, cycles: int, rows: int = 3) -> dict[str, Any]:
    """``bwsd metrics`` of a rectangular 4-step braid with a 0.5 mm yarn."""
    generated = GENERATORS["braid4"](rows, rows, cycles=cycles, takeup=takeup, diameter=0.5)
    program = parse_program(generated.program)
    sk = simulate(generated.machine, program).skeleton()
    return metrics(sk, program.cycle_length, takeups=takeups_of(program))


def test_the_one_over_h_law_holds_in_the_formed_zone():
    """tan(braid angle) x take-up per cycle is a length of the braid's geometry (the
    carriers' sideways travel in a cycle): it must not change with the take-up. The old
    whole-skeleton angle gave 1.8 to 6.1 mm over these take-ups."""
    law = [
        math.tan(math.radians(braid(h, 20)["angles"]["warp"]["all"]["mean"])) * h for h in TAKEUPS
    ]
    assert max(law) / min(law) - 1 <= 0.10, law
    old = [
        math.tan(math.radians(braid(h, 20)["skeleton_angles"]["warp"]["mean"])) * h for h in TAKEUPS
    ]
    assert max(old) / min(old) - 1 > 0.5  # the flaw: it mixed in the cone still forming


@pytest.mark.parametrize("takeup", TAKEUPS)
def test_the_formed_angle_does_not_depend_on_how_long_the_braid_runs(takeup):
    """20 and 40 cycles of one braid: the formed zone's angle within 1 degree; the old
    whole-skeleton angle moves by 3 to 13 degrees here (16.8 to 60.3 at 1 mm a cycle)."""
    short, long = braid(takeup, 20), braid(takeup, 40)
    assert short["formed"]["found"] and long["formed"]["found"]
    assert short["formed"]["cycles"][0] == long["formed"]["cycles"][0]  # the same climb
    formed = [m["angles"]["warp"]["all"]["mean"] for m in (short, long)]
    assert abs(formed[1] - formed[0]) <= 1.0
    if takeup <= 4:
        skeleton = [m["skeleton_angles"]["warp"]["mean"] for m in (short, long)]
        assert abs(skeleton[1] - skeleton[0]) > 3.0


def test_surface_yarns_run_at_a_smaller_angle_than_interior_ones():
    """As in every 4-step braid: the surface yarns turn at the edges (textbooks give the
    interior angle as the larger)."""
    warp = braid(4.0, 20, rows=6)["angles"]["warp"]
    assert warp["interior"]["mean"] > warp["surface"]["mean"] + 3
    total = warp["interior"]["length"] + warp["surface"]["length"]
    assert total == pytest.approx(warp["all"]["length"])


def _zone(stem: str):
    generated = EXAMPLES[stem]()
    program = parse_program(generated.program)
    assert program.cycle_length is not None  # the generated examples repeat a cycle
    sk = simulate(generated.machine, program).skeleton()
    arrays = Arrays.of(sk)
    guides = guide_heights(generated.machine.d_mat, takeups_of(program))
    return arrays, find_zone(arrays, program.cycle_length, guides), program, guides


def test_the_formed_zone_lies_below_the_cycle_still_forming_and_above_the_climb():
    arrays, zone, program, _ = _zone("braid-L")
    low, high = zone.z
    length = program.cycle_length
    last = arrays.made > (zone.complete - 1) * length  # nodes of the cycle still forming
    assert high == arrays.pos[last, 2].min()
    first = (arrays.made - 1) // length + 1 == zone.cycles[0]
    assert low == arrays.pos[first & (arrays.made > 0), 2].min()
    assert zone.cycles == (3, zone.complete - 1)
    depths = np.array(zone.depths)
    assert depths[0] > 1.25 * np.median(depths[len(depths) // 2 :])  # cycle 1 still climbed
    found = pieces(arrays, zone)
    p0, p1 = found.points(arrays)
    assert low <= min(p0[:, 2].min(), p1[:, 2].min())
    assert max(p0[:, 2].max(), p1[:, 2].max()) <= high
    assert (arrays.made[arrays.seg_a[found.segment.astype(int)]] > 0).all()  # contact to contact


def test_a_run_too_short_has_no_formed_zone_and_names_the_cycles_it_needs():
    short = braid(4.0, MIN_CYCLES - 1)
    assert not short["formed"]["found"] and short["angles"] is None
    assert short["formed"]["needs_cycles"] == MIN_CYCLES
    assert "too short: 3 complete cycles" in short["formed"]["reason"]
    assert short["volume_fraction"] is None
    assert short["interpenetration"]["formed"]["all"]["length"] == 0


def test_a_run_still_climbing_says_so():
    """braid-2x2 (10 cycles of 3 mm): its contacts are still climbing towards the guides."""
    _, zone, _, _ = _zone("braid-2x2")
    assert zone.z is None and zone.needs == 20
    assert "have not settled at one depth below the guides within 10 complete cycles" in (
        zone.reason or ""
    )
    assert all(a > b for a, b in zip(zone.depths, zone.depths[1:], strict=False))


def test_a_twist_without_take_up_never_forms():
    _, zone, _, _ = _zone("twist")
    assert zone.z is None


def test_without_the_guides_heights_there_is_no_formed_zone():
    generated = EXAMPLES["braid-L"]()
    program = parse_program(generated.program)
    sk = simulate(generated.machine, program).skeleton()
    found = metrics(sk, program.cycle_length)
    assert not found["formed"]["found"] and "not known" in found["formed"]["reason"]
