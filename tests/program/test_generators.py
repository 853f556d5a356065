"""Generators: valid programs, occupancy restored every cycle, carrier counts, open sheds."""

from __future__ import annotations

import itertools
import tomllib

import pytest

from bwsd.config import parse_config
from bwsd.program import parse_program, validate
from bwsd.program.generators import (
    Generated,
    braid4,
    shed_clearance,
    twist,
    weave_3d,
    weave_plain,
)
from bwsd.twin.instructions import Program, Shift, Weft
from tests.program.occupancy import cycle_states, positions

CASES = {
    "twist-1": lambda: twist(1),
    "twist-4": lambda: twist(4),
    "braid-1x1": lambda: braid4(1, 1, cycles=3),
    "braid-1x4": lambda: braid4(1, 4, cycles=3),
    "braid-3x5": lambda: braid4(3, 5, cycles=3),
    "braid-L": lambda: braid4(shape="L", flange=(2, 6), web=(4, 2), cycles=3),
    "braid-L-thin": lambda: braid4(shape="L", flange=(1, 3), web=(2, 1), cycles=3),
    "braid-T": lambda: braid4(shape="T", flange=(2, 7), web=(3, 3), cycles=3),
    "braid-I": lambda: braid4(shape="I", flange=(1, 6), web=(3, 2), cycles=3),
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


@pytest.mark.parametrize("name", CASES)
def test_valid_and_occupancy_restored_every_cycle(name: str):
    gen = CASES[name]()
    program = _parsed(gen)
    assert program.cycle_length
    assert len(program.instructions) % program.cycle_length == 0
    states = cycle_states(program, gen.machine)
    assert len(states) == len(program.instructions) // program.cycle_length + 1
    assert all(state == states[0] for state in states)


@pytest.mark.parametrize("name", CASES)
def test_config_text_loads_back_to_the_machine(name: str):
    gen = CASES[name]()
    text = gen.config_toml()
    assert parse_config(tomllib.loads(text)).machine == gen.machine
    keys = [line for line in text.splitlines() if "=" in line and not line.startswith("#")]
    assert len(keys) == 7
    assert all("# " in line for line in keys)


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


# Carrier counts derived by hand: one edge carrier per run of every shifted line.
SECTIONS = [
    ("L", (2, 6), (4, 2), 4 * 2 + 2 * 6 + (4 + 2 - 1) + (6 - 1)),
    ("L", (1, 4), (3, 1), 3 * 1 + 1 * 4 + (3 + 1 - 1) + (4 - 1)),
    ("T", (2, 6), (4, 2), 2 * 6 + 4 * 2 + (2 + 4 - 1) + (6 - 2)),
    ("T", (1, 7), (2, 3), 1 * 7 + 2 * 3 + (1 + 2 - 1) + (7 - 2)),
    ("I", (2, 6), (4, 2), 2 * 2 * 6 + 4 * 2 + (2 * 2 + 4 - 2) + 2 + 2 * (6 - 2 - 2)),
    ("I", (1, 8), (3, 3), 2 * 1 * 8 + 3 * 3 + (2 * 1 + 3 - 2) + 3 + 2 * (8 - 3 - 2)),
]


@pytest.mark.parametrize(("shape", "flange", "web", "carriers"), SECTIONS)
def test_section_carriers_and_restoration(shape, flange, web, carriers):
    gen = braid4(shape=shape, flange=flange, web=web, cycles=2)
    program = _parsed(gen)
    assert len(program.fill) == carriers
    states = cycle_states(program, gen.machine)
    assert states[0] == states[1] == states[2]


@pytest.mark.parametrize(
    ("shape", "flange", "web"),
    [
        ("L", (2, 3), (3, 2)),
        ("L", (2, 6), (1, 2)),
        ("T", (2, 5), (3, 2)),
        ("T", (2, 8), (1, 2)),
        ("I", (2, 8), (2, 2)),
        ("X", (2, 8), (3, 2)),
        ("L", (0, 6), (3, 2)),
    ],
)
def test_sections_too_thin_or_unknown_are_refused(shape, flange, web):
    with pytest.raises(ValueError):
        braid4(shape=shape, flange=flange, web=web)


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


def _shed_is_open(program: Program, gen: Generated) -> int:
    """Check every weft's line of cells is empty and has cases on both sides; count wefts."""
    pitch = gen.machine.pitch_x
    count = 0
    for i, item in enumerate(program.instructions):
        if not isinstance(item, Weft):
            continue
        cells = set(positions(program, gen.machine, i).values())
        along_x = item.angle == 0
        level = round((item.y if along_x else item.x) / pitch)
        centre = (item.x if along_x else item.y) / pitch
        span = range(
            round(centre - item.length / 2 / pitch), round(centre + item.length / 2 / pitch) + 1
        )
        line = [(level, j) if along_x else (j, level) for j in span]
        assert not cells & set(line), f"instruction {i + 1}: a case sits in the weft's line"
        for side in (-1, 1):
            near = [(level + side, j) if along_x else (j, level + side) for j in span]
            assert cells & set(near), f"instruction {i + 1}: nothing on one side of the weft"
        count += 1
    return count


@pytest.mark.parametrize("name", ["weave-plain-2", "weave-plain-11", "weave-3d", "weave-U"])
def test_wefts_go_through_an_open_shed(name: str):
    gen = CASES[name]()
    program = _parsed(gen)
    assert _shed_is_open(program, gen) > 0


def test_every_warp_line_sheds_in_every_pick():
    gen = weave_3d(3, 4, cycles=1)
    program = _parsed(gen)
    items = program.instructions
    opens = [s for s, nxt in itertools.pairwise(items) if isinstance(nxt, Weft)]
    opens = [s for s in opens if isinstance(s, Shift)]
    assert len(opens) == 4
    warp_rows = {r for r, _ in program.fill}
    warp_cols = {c for _, c in program.fill}
    for shed in opens:
        lines = {m.line for m in shed.moves}
        assert lines == (warp_rows if shed.axis == "row" else warp_cols)


def test_u_section_wefts_stop_at_the_opening():
    program = _parsed(weave_3d(5, 6, cycles=1, shape="U", leg=2, base=2))
    wefts = [w for w in program.instructions if isinstance(w, Weft)]
    # Leg levels (first three layers) get one weft per leg, the base levels one each.
    along_x = [w for w in wefts if w.angle == 0]
    assert len(along_x) == 2 * (3 * 2 + 2)
    assert {w.length for w in along_x} == {40.0, 120.0}


def test_shed_clearance_grows_with_takeup_and_small_takeup_is_refused():
    machine = weave_plain().machine
    values = [shed_clearance(machine, t, 90.0, 0.0) for t in (1.0, 2.0, 4.0, 8.0)]
    assert values == sorted(values)
    assert values[0] < machine.yarn_diameter < values[-1]
    with pytest.raises(ValueError, match="shed"):
        weave_plain(takeup=1.0)
    with pytest.raises(ValueError, match="shed"):
        weave_3d(5, 6, shape="U", leg=2, base=2, takeup=3.0)
