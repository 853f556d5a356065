"""braid-weave: a 4-step braid with layers of wefts, each through an open shed, caught."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.errors import ShedClosedError
from bwsd.export.metrics import weft_contacts
from bwsd.program import parse_program, validate
from bwsd.program.braidweave import ANGLES, braid_weave, opening, sheds
from bwsd.program.layers import HELD
from bwsd.program.layers import _try as try_layer
from bwsd.program.render import Generated
from bwsd.program.sections import parse_section
from bwsd.program.wefts import Placer, Shed
from bwsd.twin import Program, Twin, Weft, simulate
from tests.program.occupancy import contact_groups, cycle_states

BWSD = shutil.which("bwsd", path=str(Path(sys.executable).parent))


def _parsed(gen: Generated) -> Program:
    program = parse_program(gen.program)
    validate(program, gen.machine)
    return program


def caught_and_connected(gen: Generated) -> list[Weft]:
    """Simulate the program (every weft passes the exact shed check, or it raises) and check
    every weft has a contact and the yarns form one preform; the wefts."""
    program = _parsed(gen)
    sk = simulate(gen.machine, program).skeleton()
    touched = {c.moving_yarn for c in sk.contacts} | {c.hit_yarn for c in sk.contacts}
    wefts = [y.id for y in sk.yarns if y.kind == "weft"]
    assert wefts and set(wefts) <= touched, "a weft without any contact"
    assert contact_groups(sk) == [list(range(len(sk.yarns)))]
    return [i for i in program.instructions if isinstance(i, Weft)]


@pytest.mark.slow
def test_every_angle_goes_in_caught_and_the_braid_stays_one_preform():
    gen = braid_weave(3, 3, cycles=8, weft_every=2)
    wefts = caught_and_connected(gen)
    assert {w.angle for w in wefts} == set(ANGLES)
    assert "# a layer of wefts every 2 cycles, at 0, 90, 45, -45 degrees" in gen.program
    program = _parsed(gen)
    states = cycle_states(program, gen.machine)  # the braid's cycle is untouched by wefts
    assert all(state == states[0] for state in states)


@pytest.mark.slow
@pytest.mark.parametrize(("shape", "flange", "web"), [("L", (2, 6), (4, 2)), ("T", (2, 8), (4, 2))])
def test_shaped_braid_weaves_take_wefts_across_the_junction(shape, flange, web):
    gen = braid_weave(shape=shape, flange=flange, web=web, cycles=4, weft_every=2, angles=(0, 90))
    wefts = caught_and_connected(gen)
    assert {w.angle for w in wefts} == {0, 90}
    assert gen.machine.segments  # the corner lines' segments


def _layers(program: Program) -> list[tuple[int, list[Weft]]]:
    """Each run of consecutive WEFTs (a layer): its first instruction's index and the wefts."""
    found: list[tuple[int, list[Weft]]] = []
    items = program.instructions
    for i, item in enumerate(items):
        if isinstance(item, Weft):
            if i and isinstance(items[i - 1], Weft):
                found[-1][1].append(item)
            else:
                found.append((i, [item]))
    return found


@pytest.mark.slow
def test_each_layer_lies_at_one_height_and_each_weft_is_held_twice():
    """A weaver's layer: one plane, every weft held by at least two contacts. Before this
    rule the median weft had one contact and the wefts of a layer spread over 14 mm."""
    gen = braid_weave(3, 3, cycles=8, weft_every=2)
    program = _parsed(gen)
    layers = _layers(program)
    assert len(layers) == 4
    for _, wefts in layers:
        assert len({w.z for w in wefts}) == 1, wefts
    sk = simulate(gen.machine, program).skeleton()
    held = weft_contacts(sk)
    assert held["count"] == sum(len(w) for _, w in layers)
    assert held["contacts"]["min"] >= HELD
    assert held["loose"] == held["held_once"] == []


def _shed_of(gen: Generated, placer: Placer, weft: Weft) -> Shed:
    """The generator's shed for ``weft``: the one of its angle whose line lies nearest."""
    section = parse_section(
        next(
            line.split(": ", 1)[1]
            for line in gen.program.splitlines()
            if line.startswith("# section: ")
        )
    )
    options = sheds(section, weft.angle)
    lines = [
        (abs(c.x - weft.x) + abs(c.y - weft.y), s)
        for s in options
        for c in placer.candidates(s, weft.z)
    ]
    return min(lines, key=lambda pair: pair[0])[1]


@pytest.mark.slow
def test_each_layer_sits_at_the_lowest_height_that_holds_it():
    """Replayed on a twin: one grid step lower, some weft of the layer is not let in, a
    closing move jams, or some weft is held fewer than twice."""
    gen = braid_weave(3, 3, cycles=4, weft_every=2, angles=(0, 90))
    program = _parsed(gen)
    placer = Placer(gen.machine, program.fill)
    step = placer.heights[0]
    items = list(program.instructions)
    checked = 0
    for i, item in enumerate(items):
        if isinstance(item, Weft) and not isinstance(items[i - 1], Weft):
            count = next(k for k, w in enumerate(items[i:]) if not isinstance(w, Weft))
            wefts = [w for w in items[i : i + count] if isinstance(w, Weft)]
            sheds_ = [_shed_of(gen, placer, w) for w in wefts]
            closing = [x for x in items[i + len(wefts) :] if not isinstance(x, Weft)][:8]
            lower = item.z - step
            if lower >= min(placer.lowest_fixed(s) for s in sheds_):
                before = placer.twin.snapshot()
                tried = try_layer(placer, sheds_, closing, lower)
                placer.twin.restore(before)
                assert tried.held is None or min(tried.held) < HELD, (i, tried)
                checked += 1
        placer.twin.apply(item)
    assert checked >= 1


@pytest.mark.slow
def test_any_angle_goes_in():
    gen = braid_weave(3, 3, cycles=6, weft_every=2, angles=(30, -30, 60))
    program = _parsed(gen)
    assert {w.angle for _, ws in _layers(program) for w in ws} == {30, -30, 60}
    assert "--angles=30,-30,60" in gen.command
    held = weft_contacts(simulate(gen.machine, program).skeleton())
    assert held["contacts"]["min"] >= HELD


def test_the_lines_of_an_angle():
    """0, 90 and 45 keep their rows, columns and diagonals; another angle has lines one row
    (or column) apart across it, and opens after the step nearer to it."""
    section = parse_section("rect:3x3")
    assert len(sheds(section, 0)) == len(sheds(section, 90)) == 2
    thirty = sheds(section, 30)
    assert thirty and all(shed.angle == 30 for shed in thirty)
    assert (opening(30), opening(-30), opening(60), opening(120), opening(45)) == (
        "row",
        "row",
        "col",
        "col",
        "row",
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: braid_weave(cycles=5, weft_every=2), "must be a multiple of weft-every"),
        (lambda: braid_weave(angles=(float("nan"),)), "a finite number of degrees"),
        (lambda: braid_weave(2, 2, cycles=4, angles=(45,)), "no two neighbouring lines"),
        (
            lambda: braid_weave(3, 3, cycles=2, diameter=6.0),
            "a yarn diameter of 6 mm does not fit: it must be less than c_mat x the smaller",
        ),
        # the L sizes whose diagonal layer used to be refused as a bare shed error: now the
        # generator names the weft whose shed no height opens
        (
            lambda: braid_weave(shape="L"),
            r"layer 3, 45 degree weft between lines -4 and -3 "
            r"\(cells \(4, 1\) to \(6, 2\)\): no height below the guides lets the whole 45 "
            "degree layer in: this weft's shed is closed",
        ),
        (
            lambda: braid_weave(shape="L", flange=(3, 7), web=(7, 3)),
            "45 degree weft between "
            "lines -8 and -7 .*: no height below the guides lets the whole 45 degree layer in",
        ),
    ],
)
def test_what_cannot_be_woven_is_refused_saying_why(call, message):
    with pytest.raises(ValueError, match=message):
        call()


@pytest.mark.slow
def test_a_weft_the_twin_refuses_is_never_written():
    """Every WEFT of a generated program passes the exact shed check on its own twin."""
    gen = braid_weave(3, 3, cycles=4, weft_every=2, angles=(45, -45))
    program = _parsed(gen)
    twin = Twin.from_program(gen.machine, program)
    for item in program.instructions:
        try:
            twin.apply(item)
        except ShedClosedError as exc:  # pragma: no cover - the assertion is the point
            pytest.fail(f"{item}: {exc}")


@pytest.mark.slow
def test_the_command_line_prints_what_the_generator_makes(tmp_path):
    assert BWSD
    done = subprocess.run(
        [
            BWSD,
            "program",
            "braid-weave",
            "--cycles",
            "4",
            "--angles",
            "0,90",
            "--config-out",
            str(tmp_path / "c.toml"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == braid_weave(cycles=4, angles=(0, 90)).program
    bad = subprocess.run(
        [BWSD, "program", "braid-weave", "--angles", "0,x"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert bad.returncode == 2 and "expected angles in degrees" in bad.stderr
