"""Generators: valid programs, occupancy restored every cycle, carrier counts, open sheds."""

from __future__ import annotations

import itertools
import re
import tomllib

import pytest

from bwsd.config import parse_config
from bwsd.program import parse_program, validate
from bwsd.program.braid import section
from bwsd.program.braidrules import PARTIAL, WHOLE, find_rule, multiplexed, whole_line
from bwsd.program.carriers import check_rule
from bwsd.program.generators import (
    Generated,
    braid4,
    twist,
    weave_3d,
    weave_plain,
)
from bwsd.twin import simulate
from bwsd.twin.instructions import Program, Shift, Weft
from tests.program.occupancy import contact_groups, cycle_states, positions

CASES = {
    "twist-1": lambda: twist(1),
    "twist-4": lambda: twist(4),
    "braid-1x1": lambda: braid4(1, 1, cycles=3),
    "braid-1x4": lambda: braid4(1, 4, cycles=3),
    "braid-3x5": lambda: braid4(3, 5, cycles=3),
    "braid-L": lambda: braid4(shape="L", flange=(2, 6), web=(4, 2), cycles=3),
    "braid-L-whole": lambda: braid4(shape="L", flange=(2, 6), web=(4, 2), cycles=3, segments=False),
    "braid-T": lambda: braid4(shape="T", flange=(2, 8), web=(4, 2), cycles=3),
    "braid-T-whole": lambda: braid4(
        shape="T", flange=(3, 11), web=(6, 3), cycles=3, segments=False
    ),
    "braid-I": lambda: braid4(shape="I", flange=(2, 8), web=(4, 2), cycles=3),
    "twist-takeup": lambda: twist(2, takeup=2.5),
    "weave-plain-2": lambda: weave_plain(2, cycles=2),
    "weave-plain-11": lambda: weave_plain(11, cycles=2),
    "weave-3d": lambda: weave_3d(3, 4, cycles=2),
    "weave-3d-2x2": lambda: weave_3d(2, 2, cycles=2),
    "weave-U": lambda: weave_3d(5, 6, cycles=2, shape="U", leg=2, base=2),
}


def _parsed(gen: Generated) -> Program:
    program = parse_program(gen.program)
    validate(program, gen.machine)
    return program


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_valid_and_occupancy_restored_every_cycle(name: str):
    gen = CASES[name]()
    program = _parsed(gen)
    assert program.cycle_length
    assert len(program.instructions) % program.cycle_length == 0
    states = cycle_states(program, gen.machine)
    assert len(states) == len(program.instructions) // program.cycle_length + 1
    assert all(state == states[0] for state in states)


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_config_text_loads_back_to_the_machine(name: str):
    gen = CASES[name]()
    text = gen.config_toml()
    assert parse_config(tomllib.loads(text)).machine == gen.machine
    keys = [line for line in text.splitlines() if "=" in line and not line.startswith("#")]
    assert len(keys) == 7 + bool(gen.machine.segments)
    assert all("# " in line for line in keys if not line.startswith("segments"))


def test_twist_is_the_worked_example():
    program = _parsed(twist(4))
    cycle = [
        Shift("row", ((0, 1), (1, -1))),
        Shift("col", ((1, 1), (0, -1))),
        Shift("row", ((1, -1), (0, 1))),
        Shift("col", ((0, -1), (1, 1))),
    ]
    assert program.fill == ((0, 0), (1, 1))
    assert program.instructions == tuple(cycle * 4)
    assert program.diameter == 1.0


@pytest.mark.parametrize(("m", "n"), [(1, 1), (1, 3), (2, 2), (3, 2), (4, 5), (24, 24)])
def test_rectangular_braid_carriers_and_alternation(m: int, n: int):
    gen = braid4(m, n, cycles=1)
    program = _parsed(gen)
    assert (gen.machine.rows, gen.machine.cols) == (m + 2, n + 2)
    assert len(program.fill) == m * n + m + n
    body = {(r, c) for r in range(1, m + 1) for c in range(1, n + 1)}
    assert body <= set(program.fill)
    rows, cols, back_rows, back_cols = program.instructions[:4]
    assert isinstance(rows, Shift) and isinstance(cols, Shift)
    assert [m.line for m in rows.moves] == list(range(1, m + 1))
    assert [m.line for m in cols.moves] == list(range(1, n + 1))
    for step in (rows, cols):
        signs = [m.k for m in step.moves]
        assert all(a == -b for a, b in itertools.pairwise(signs))
    assert back_rows == Shift("row", tuple((i, -k) for i, k, _ in rows.moves))
    assert back_cols == Shift("col", tuple((i, -k) for i, k, _ in cols.moves))


def test_braid_moves_yarns_to_new_cells_each_cycle():
    gen = braid4(2, 2, cycles=1)
    program = _parsed(gen)
    after = positions(program, gen.machine, len(program.instructions))
    start = dict(enumerate(program.fill))
    assert sum(after[y] != start[y] for y in start) >= len(start) // 2


# Carriers, period P and cycles K to mix every carrier through every zone, for the sizes
# of the cell-grid study of shaped sections (an independent checker gave the same numbers).
SECTIONS = [
    ("L", (2, 6), (4, 2), True, 32, 20, 11),
    ("L", (3, 10), (7, 3), True, 71, 71, 13),
    ("T", (2, 8), (4, 2), True, 38, 297, 7),
    ("I", (2, 8), (4, 2), True, 62, 31, 20),
    ("L", (2, 6), (4, 2), False, 32, 175, 7),
    ("L", (3, 10), (7, 3), False, 71, 575, 11),
    ("T", (2, 8), (4, 2), False, 38, 36, 17),
    ("T", (3, 11), (6, 3), False, 71, 6138, 16),
]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("shape", "flange", "web", "segments", "carriers", "period", "k"), SECTIONS
)
def test_shaped_rules_mix_every_carrier_through_every_zone(
    shape, flange, web, segments, carriers, period, k
):
    sec = section(shape, flange=flange, web=web)
    found = find_rule(sec, segments)
    assert found is not None
    rule, check = found
    assert (len(rule.carriers), check.legal, check.periodic) == (carriers, True, True)
    assert check.mixed and (check.period, check.k) == (period, k)
    assert rule.partial == segments
    gen = braid4(shape=shape, flange=flange, web=web, segments=segments, cycles=k)
    program = _parsed(gen)
    assert len(program.fill) == carriers
    assert f"every carrier in every zone by cycle {k} (period {period})" in gen.program
    states = cycle_states(program, gen.machine)
    assert all(state == states[0] for state in states)
    # Independently of the rule checker: replay the program and see each yarn's zones.
    visited: list[set[str]] = [set() for _ in program.fill]
    for upto in range(len(program.instructions) + 1):
        for yarn, cell in positions(program, gen.machine, upto).items():
            zone = sec.zone_of(cell)
            if zone is not None:
                visited[yarn].add(zone)
    assert all(set(sec.required) <= zones for zones in visited)


STUDY = [  # (shape, flange, web, schedule, axis or None for whole lines, P, K)
    ("L", (2, 6), (4, 2), 0, (1, 1), 20, 11),
    ("L", (3, 10), (7, 3), 1, (-1, -1), 525, 13),
    ("T", (2, 8), (4, 2), 0, (1, -1), 297, 7),
    ("T", (3, 11), (6, 3), 1, (-1, -1), 71, 19),
    ("I", (2, 8), (4, 2), 0, (-1, -1), 31, 20),
    ("I", (3, 9), (5, 3), 1, (1, -1), 95, 23),
    ("L", (2, 6), (4, 2), 0, None, 175, 7),
    ("L", (3, 10), (7, 3), 1, None, 575, 11),
    ("T", (2, 8), (4, 2), 0, None, 36, 17),
    ("T", (3, 11), (6, 3), 1, None, 6138, 16),
]


@pytest.mark.parametrize(("shape", "flange", "web", "which", "axis", "period", "k"), STUDY)
def test_the_known_schedules_give_the_numbers_of_the_cell_grid_study(
    shape, flange, web, which, axis, period, k
):
    """Each schedule on the size it was found for, as an independent checker counted it."""
    sec = section(shape, flange=flange, web=web)
    if axis is None:
        rule = whole_line(sec, 2, WHOLE[shape][which])
    else:
        n, rows, cols, _ = PARTIAL[shape][which]
        rule = multiplexed(sec, n, rows, cols, axis)
    assert rule is not None
    check = check_rule(sec, rule)
    assert check.mixed and (check.period, check.k) == (period, k)


def test_holding_the_corner_lines_walls_the_section_and_the_checker_says_so():
    """The plain 4-step with the corner row and column held (what a whole-line machine
    falls back to): legal and periodic, but some carriers never leave their zone."""
    sec = section("L", flange=(2, 6), web=(4, 2))
    held = {(kind, "corner", 0): ((0, 0), 1) for kind in ("ROW", "COL")}
    arms = {(kind, "arm", i): ((1, 1), 1) for kind in ("ROW", "COL") for i in (0, 1)}
    rule = whole_line(sec, 1, {**held, **arms})
    assert rule is not None and len(rule.carriers) == 30
    check = check_rule(sec, rule)
    assert check.legal and check.periodic, check.reason
    assert (check.period, check.orbits, check.mixed_orbits) == (44, 4, 2)
    assert not check.mixed and check.k is None


@pytest.mark.parametrize("segments", [True, False])
@pytest.mark.parametrize(
    ("shape", "flange", "web"),
    [("L", (2, 6), (4, 2)), ("T", (2, 8), (4, 2)), ("I", (2, 8), (4, 2))],
)
def test_every_shaped_braid_is_one_preform_by_its_k_cycles(shape, flange, web, segments):
    if shape == "I" and not segments:
        with pytest.raises(ValueError, match="an I section needs a machine with corner segments"):
            braid4(shape=shape, flange=flange, web=web, segments=False)
        return
    found = find_rule(section(shape, flange=flange, web=web), segments)
    assert found is not None
    k = found[1].k
    assert k is not None  # find_rule answers rules that mix
    gen = braid4(shape=shape, flange=flange, web=web, segments=segments, cycles=k)
    sk = simulate(gen.machine, _parsed(gen)).skeleton()
    assert contact_groups(sk) == [list(range(len(sk.yarns)))]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("shape", "flange", "web", "segments", "message"),
    [
        ("L", (1, 4), (3, 2), True, "nearby sizes that mix"),
        ("L", (2, 4), (2, 1), True, "nearby sizes that mix"),
        ("I", (1, 6), (3, 2), True, "nearby sizes that mix: flange 2x6 web 3x2"),
        ("I", (2, 8), (4, 2), False, "an I section needs a machine with corner segments"),
        ("X", (2, 8), (3, 2), True, "unknown shape"),
        ("L", (0, 6), (3, 2), True, "at least 1 x 1"),
        ("L", (2, 2), (3, 2), True, "flange wider than its web"),
        ("T", (2, 7), (3, 2), True, "even number"),
    ],
)
def test_sizes_no_rule_mixes_are_refused_naming_sizes_that_do(
    shape, flange, web, segments, message
):
    with pytest.raises(ValueError) as refused:
        braid4(shape=shape, flange=flange, web=web, segments=segments)
    text = str(refused.value)
    if message:
        assert message in text
    for found in re.findall(r"flange (\d+)x(\d+) web (\d+)x(\d+)", text):
        f, w = (int(found[0]), int(found[1])), (int(found[2]), int(found[3]))
        assert _parsed(braid4(shape=shape, flange=f, web=w, segments=segments, cycles=1))


@pytest.mark.parametrize(
    "call",
    [
        lambda: twist(0),
        lambda: braid4(cycles=0),
        lambda: braid4(takeup=0),
        lambda: weave_plain(1),
        lambda: weave_3d(cycles=0),
        lambda: weave_3d(shape="U", leg=3),
        lambda: weave_3d(shape="U", base=3),
        lambda: weave_3d(1, 4),
        lambda: weave_3d(4, 1),
        lambda: weave_3d(5, 7, shape="U", leg=1),
        lambda: weave_3d(5, 7, shape="U", base=1),
        lambda: braid4(c_mat=1.5),
    ],
)
def test_bad_parameters_are_refused(call):
    with pytest.raises(ValueError):
        call()


@pytest.mark.slow
def test_every_weft_is_caught_and_each_weave_is_one_preform():
    """Each weft passed the exact shed check where the generator put it (else simulate
    raises) and the move closing its shed caught it."""
    for name in ("weave-plain-2", "weave-plain-11", "weave-3d", "weave-3d-2x2", "weave-U"):
        gen = CASES[name]()
        sk = simulate(gen.machine, _parsed(gen)).skeleton()
        touched = {c.moving_yarn for c in sk.contacts} | {c.hit_yarn for c in sk.contacts}
        assert {y.id for y in sk.yarns if y.kind == "weft"} <= touched, name
        assert contact_groups(sk) == [list(range(len(sk.yarns)))], name


@pytest.mark.slow
def test_every_warp_line_sheds_in_every_pick():
    gen = weave_3d(3, 4, cycles=1)
    program = _parsed(gen)
    items = program.instructions
    opens = [s for s, nxt in itertools.pairwise(items) if isinstance(nxt, Weft)]
    sheds = [s for s in opens if isinstance(s, Shift)]
    assert len(sheds) == 4
    warp_rows = {r for r, _ in program.fill}
    warp_cols = {c for _, c in program.fill}
    for shed in sheds:
        lines = {m.line for m in shed.moves}
        assert lines == (warp_rows if shed.axis == "row" else warp_cols)


@pytest.mark.slow
def test_u_section_wefts_stop_at_the_opening():
    gen = weave_3d(5, 6, cycles=1, shape="U", leg=2, base=2)
    wefts = [w for w in _parsed(gen).instructions if isinstance(w, Weft)]
    # Leg levels (first three layers) get one weft per leg, the base levels one each.
    along_x = [w for w in wefts if w.angle == 0]
    assert len(along_x) == 2 * (3 * 2 + 2)
    middle = gen.machine.convergence_xy()[0]
    spans = [(w.x - w.length / 2, w.x + w.length / 2) for w in along_x]
    across = [lo < middle < hi for lo, hi in spans]
    assert across.count(True) == 2 * 2 and across.count(False) == 2 * 3 * 2


def test_a_yarn_too_thick_for_the_machine_is_refused_by_the_generator():
    """Warps start c_mat x pitch (5 mm here) apart at the fell: a 10 mm yarn cannot fit,
    which the generator says (it used to search for an open shed and report none)."""
    with pytest.raises(
        ValueError,
        match=r"a yarn diameter of 10 mm does not fit: it must be "
        r"less than c_mat x the smaller pitch \(5 mm\)",
    ):
        weave_plain(4, cycles=1, diameter=10.0)


def test_twist_takes_up_after_every_turn():
    gen = twist(3, takeup=2.5)
    program = _parsed(gen)
    takeups = [i for i in program.instructions if not isinstance(i, Shift)]
    assert [t.length for t in takeups] == [2.5] * 3
    assert program.cycle_length == 5
    assert "--takeup 2.5" in gen.command
    assert simulate(gen.machine, program).skeleton().takeup == 7.5
    assert twist(4).program == twist(4, takeup=0).program  # the worked example unchanged
