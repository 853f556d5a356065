"""Generated programs on the twin: every yarn interlaces and every weft finds an open shed."""

from __future__ import annotations

from pathlib import Path

import pytest

from bwsd.config import load_config
from bwsd.program import load_program, parse_program
from bwsd.program.generators import Generated, braid4, weave_3d, weave_plain
from bwsd.twin.instructions import Program
from bwsd.twin.machine import Machine

ROOT = Path(__file__).resolve().parents[2]


def _untouched(machine: Machine, program: Program) -> list[int]:
    """Yarns without any contact after the whole program (raises if the twin refuses it)."""
    from bwsd.twin import simulate

    sk = simulate(machine, program).skeleton()
    touched = {c.moving_yarn for c in sk.contacts} | {c.hit_yarn for c in sk.contacts}
    return [y.id for y in sk.yarns if y.id not in touched]


def test_twist_example_is_the_worked_example():
    from bwsd.twin import simulate

    machine = load_config(ROOT / "config" / "twist.toml").machine
    program = load_program(ROOT / "examples" / "twist.bws", machine)
    sk = simulate(machine, program).skeleton()
    assert (len(sk.yarns), len(sk.contacts), sk.node_count) == (2, 15, 34)


@pytest.mark.parametrize(
    "stem",
    [
        "braid-2x2",
        "braid-L",
        "weave-plain",
        "weave-U",
        pytest.param("braid-24x24", marks=pytest.mark.slow),
    ],
)
def test_example_every_yarn_interlaces(stem: str):
    machine = load_config(ROOT / "config" / f"{stem}.toml").machine
    program = load_program(ROOT / "examples" / f"{stem}.bws", machine)
    assert _untouched(machine, program) == []


GENERATED = {
    "braid-1x3": lambda: braid4(1, 3, cycles=6),
    "braid-3x4": lambda: braid4(3, 4, cycles=6),
    "braid-L-thin": lambda: braid4(shape="L", flange=(1, 3), web=(2, 1), cycles=6),
    "braid-T": lambda: braid4(shape="T", flange=(2, 6), web=(2, 2), cycles=6),
    "braid-I": lambda: braid4(shape="I", flange=(2, 8), web=(4, 2), cycles=6),
    "weave-plain-2": lambda: weave_plain(2, cycles=3),
    "weave-3d": lambda: weave_3d(3, 4, cycles=3),
    "weave-3d-wide": lambda: weave_3d(2, 7, cycles=3),
    "weave-3d-2x2": lambda: weave_3d(2, 2, cycles=3),
    "weave-U-default": lambda: weave_3d(cycles=3, shape="U"),
    "weave-U-deep": lambda: weave_3d(4, 7, cycles=3, shape="U", leg=2, base=2),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", GENERATED)
def test_generated_every_yarn_interlaces(name: str):
    gen: Generated = GENERATED[name]()
    assert _untouched(gen.machine, parse_program(gen.program)) == []
