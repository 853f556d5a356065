"""braid-weave: a 4-step braid with layers of wefts, each through an open shed, caught."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.errors import ShedClosedError
from bwsd.program import parse_program, validate
from bwsd.program.braidweave import ANGLES, braid_weave, sheds
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


def test_every_angle_goes_in_caught_and_the_braid_stays_one_preform():
    gen = braid_weave(3, 3, cycles=8, weft_every=2)
    wefts = caught_and_connected(gen)
    assert {w.angle for w in wefts} == set(ANGLES)
    assert "# a layer of wefts every 2 cycles, at 0, 90, 45, -45 degrees" in gen.program
    program = _parsed(gen)
    states = cycle_states(program, gen.machine)  # the braid's cycle is untouched by wefts
    assert all(state == states[0] for state in states)


@pytest.mark.parametrize(("shape", "flange", "web"), [("L", (2, 6), (4, 2)), ("T", (2, 8), (4, 2))])
def test_shaped_braid_weaves_take_wefts_across_the_junction(shape, flange, web):
    gen = braid_weave(shape=shape, flange=flange, web=web, cycles=4, weft_every=2,
                      angles=(0, 90))  # fmt: skip
    wefts = caught_and_connected(gen)
    assert {w.angle for w in wefts} == {0, 90}
    assert gen.machine.segments  # the corner lines' segments


def test_each_weft_sits_at_the_lowest_height_where_it_is_open_and_caught():
    """Replayed on a twin: one grid step lower, every candidate line is closed or loose."""
    gen = braid_weave(3, 3, cycles=4, weft_every=2, angles=(0, 90))
    program = _parsed(gen)
    placer = Placer(gen.machine, program.fill)
    step = placer.heights[0]
    items = list(program.instructions)
    checked = 0
    for i, item in enumerate(items):
        if isinstance(item, Weft) and item.z - step >= placer.heights[0]:
            shed = _shed_of(gen, placer, item)
            closing = [x for x in items[i + 1 :] if not isinstance(x, Weft)][:8]
            lower = item.z - step
            for weft in placer.candidates(shed, lower):
                assert not placer.would_catch(weft, closing), (i, weft)
            checked += 1
        placer.twin.apply(item)
    assert checked >= 2


def _shed_of(gen: Generated, placer: Placer, weft: Weft) -> Shed:
    """The generator's shed for ``weft``: the one of its angle whose line lies nearest."""
    section = parse_section(next(line.split(": ", 1)[1] for line in gen.program.splitlines()
                                 if line.startswith("# section: ")))  # fmt: skip
    options = sheds(section, int(weft.angle))
    lines = [(abs(c.x - weft.x) + abs(c.y - weft.y), s)
             for s in options for c in placer.candidates(s, weft.z)]  # fmt: skip
    return min(lines, key=lambda pair: pair[0])[1]


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: braid_weave(cycles=5, weft_every=2), "must be a multiple of weft-every"),
        (lambda: braid_weave(angles=(30,)), "weft angles are among 0, 90, 45, -45"),
        (lambda: braid_weave(2, 2, cycles=4, angles=(45,)), "no two neighbouring lines"),
        (lambda: braid_weave(3, 3, cycles=2, diameter=6.0),
         "no height between the fell and the guides where the shed is open"),
    ],
)  # fmt: skip
def test_what_cannot_be_woven_is_refused_saying_why(call, message):
    with pytest.raises(ValueError, match=message):
        call()


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


def test_the_command_line_prints_what_the_generator_makes(tmp_path):
    assert BWSD
    done = subprocess.run([BWSD, "program", "braid-weave", "--cycles", "4", "--angles", "0,90",
                           "--config-out", str(tmp_path / "c.toml")], capture_output=True,
                          text=True, timeout=120, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout == braid_weave(cycles=4, angles=(0, 90)).program
    bad = subprocess.run([BWSD, "program", "braid-weave", "--angles", "0,30"],
                         capture_output=True, text=True, timeout=60, check=False)  # fmt: skip
    assert bad.returncode == 2 and "weft angles are among 0, 90, 45, -45" in bad.stderr
