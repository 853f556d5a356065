"""Impossible preforms are refused, not predicted (docs/twin.md): a jam (a contact node within
one yarn diameter of the guide plane, or above it) refuses the instruction, in the kernel and
in the exact reference alike, and nothing of it is applied; a yarn too thick to fit is refused."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from bwsd.errors import JamError, TwinError
from bwsd.program.generators import GENERATORS
from bwsd.program.parser import parse_program
from bwsd.twin import Machine, Shift, TakeUp, Twin, simulate
from bwsd.twin.instructions import Instruction
from tests.twin.conftest import WORKED_CYCLE, WORKED_FILL, assert_same
from tests.twin.reference import Jam, RefTwin


def _until_jam(
    machine: Machine, fill, diameter: float, instructions: list[Instruction]
) -> tuple[Twin, RefTwin, JamError]:
    """Run kernel and reference side by side up to the first jam, which both must refuse
    alike; then both hold the state before it."""
    twin, ref = Twin(machine, fill, diameter), RefTwin(machine, list(fill), diameter)
    for ins in instructions:
        try:
            twin.apply(ins)
        except JamError as exc:
            with pytest.raises(Jam) as found:
                ref.run(ins)
            assert exc.instruction == ref.done + 1 == twin.done + 1
            assert exc.yarns == (found.value.moving, found.value.hit)
            assert exc.z == math.ldexp(found.value.z, -32)
            assert_same(twin, ref)  # nothing of the refused instruction was applied
            return twin, ref, exc
        ref.run(ins)
    raise AssertionError("no jam")


def test_the_twist_that_winds_up_is_refused_as_a_jam_at_the_same_instruction_as_the_reference():
    """`bwsd program twist --turns 100` (no take-up): the two yarns wind up to the guides."""
    generated = GENERATORS["twist"](turns=100)
    program = parse_program(generated.program)
    machine = generated.machine
    twin, _, exc = _until_jam(
        machine, program.fill, machine.yarn_diameter, list(program.instructions)
    )
    assert exc.instruction == 114
    assert sorted(exc.yarns) == [0, 1]
    guides = machine.d_mat
    assert guides - machine.yarn_diameter <= exc.z
    moving, hit = exc.yarns
    assert f"instruction 114: jam: yarn {moving} would rest on yarn {hit}" in str(exc)
    # every contact kept lies more than one diameter below the guides
    sk = twin.skeleton()
    zs = [sk.node_positions()[n][2] for c in sk.contacts for n in (c.moving_node, c.hit_node)]
    assert max(zs) < guides - machine.yarn_diameter


def test_a_runaway_take_up_is_refused_as_a_jam_early():
    """braid-2x2 at 0.01 mm a cycle made some 2,100 contacts, ever higher above the guides,
    and ran for seconds an instruction; now it is refused within its first cycles."""
    generated = GENERATORS["braid4"](2, 2, cycles=200, takeup=0.01, diameter=1.5)
    program = parse_program(generated.program)
    with pytest.raises(JamError) as found:
        simulate(generated.machine, program)
    refused = found.value.instruction
    assert refused < 60
    twin, _, exc = _until_jam(
        generated.machine,
        program.fill,
        generated.machine.yarn_diameter,
        list(program.instructions[:refused]),
    )
    assert exc.instruction == refused
    assert twin.contact_count < 100


def _boundary(diameter: float) -> Twin:
    machine = Machine(2, 2, 10.0, 10.0, 6.0, 0.5)
    twin = Twin(machine, WORKED_FILL, diameter)
    for ins in WORKED_CYCLE[:2]:
        twin.apply(ins)
    return twin


@pytest.mark.parametrize("exact_only", [False, True])
def test_a_contact_exactly_one_diameter_below_the_guides_is_a_jam(exact_only, request):
    """The worked example's geometry on a 6 mm matrix-to-fell: the first contact's Y lies at
    z = 2 mm, the guides at 6 mm. A 4 mm yarn puts it exactly one diameter below: refused
    (z >= G - d, compared exactly); a yarn a nanometre thinner is not."""
    from bwsd.twin import _kernel

    _kernel.set_exact_only(exact_only)
    request.addfinalizer(lambda: _kernel.set_exact_only(False))
    first = _boundary(3.999999999).skeleton()
    y = first.node_positions()[first.contacts[0].hit_node]
    assert y.tolist() == [5.0, 5.0, 2.0]
    with pytest.raises(JamError) as found:
        _boundary(4.0)
    assert (found.value.instruction, found.value.yarns, found.value.z) == (2, (1, 0), 2.0)
    ref = RefTwin(Machine(2, 2, 10.0, 10.0, 6.0, 0.5), list(WORKED_FILL), 4.0)
    ref.run(WORKED_CYCLE[0])
    with pytest.raises(Jam):
        ref.run(WORKED_CYCLE[1])


def _jam_prone(seed: int) -> tuple[Machine, list[tuple[int, int]], float, list[Instruction]]:
    """A twist or an 8-carrier braid on a short matrix-to-fell with little take-up."""
    rng = random.Random(seed)
    pitch = rng.choice([2.0, 5.0, 10.0])
    c_mat = rng.choice([0.25, 0.5, 0.75])
    diameter = round(rng.uniform(0.05, 0.9) * c_mat * pitch, 3)
    takeups = [0.0, 0.1, 0.5, round(rng.uniform(0.05, 2.0), 3)]
    if rng.random() < 0.5:
        machine = Machine(2, 2, pitch, pitch, rng.choice([5.0, 20.0, 60.0]), c_mat)
        fill, cycle = list(WORKED_FILL), list(WORKED_CYCLE)
    else:
        from tests.twin.conftest import BRAID_CYCLE, BRAID_FILL

        machine = Machine(4, 4, pitch, pitch, rng.choice([10.0, 40.0]), c_mat)
        fill, cycle = list(BRAID_FILL), list(BRAID_CYCLE)
    instructions: list[Instruction] = []
    for _ in range(rng.randint(3, 12)):
        instructions += cycle
        takeup = rng.choice(takeups)
        if takeup:
            instructions.append(TakeUp(takeup))
    return machine, fill, diameter, instructions


@pytest.mark.slow
def test_kernel_and_reference_refuse_the_same_jams_on_random_programs():
    """Jam-prone programs: each instruction agrees until both refuse the same jam, and both
    stop in the same state."""
    jams = 0
    for seed in range(24):
        machine, fill, diameter, instructions = _jam_prone(seed)
        twin, ref = Twin(machine, fill, diameter), RefTwin(machine, fill, diameter)
        for ins in instructions:
            try:
                twin.apply(ins)
            except JamError as exc:
                with pytest.raises(Jam) as found:
                    ref.run(ins)
                assert exc.yarns == (found.value.moving, found.value.hit)
                assert exc.z == math.ldexp(found.value.z, -32)
                jams += 1
                break
            ref.run(ins)
        assert_same(twin, ref)
    assert jams >= 5  # the programs do reach the guides


def test_no_contact_kept_lies_within_a_diameter_of_the_guides_of_its_time():
    """Over random jam-prone programs, every contact the twin keeps lies more than one
    diameter below the guides as they stood when it was made."""
    for seed in range(12):
        machine, fill, diameter, instructions = _jam_prone(seed)
        twin, guides = Twin(machine, fill, diameter), {}
        for ins in instructions:
            try:
                twin.apply(ins)
            except JamError:
                break
            guides[twin.done] = machine.d_mat + twin.takeup
        sk = twin.skeleton()
        pos = sk.node_positions()
        for c in sk.contacts:
            top = max(pos[c.moving_node][2], pos[c.hit_node][2])
            assert top < guides[c.instruction] - diameter


def test_a_jam_in_a_prediction_leaves_the_twin_as_it_was():
    generated = GENERATORS["twist"](turns=100)
    program = parse_program(generated.program)
    twin = Twin.from_program(generated.machine, program)
    for ins in program.instructions[:113]:
        twin.apply(ins)
    before = twin.skeleton()
    with pytest.raises(JamError):
        twin.predict(program.instructions[113])
    after = twin.skeleton()
    assert twin.done == 113
    assert len(after.contacts) == len(before.contacts)
    for a, b in zip(before.yarns, after.yarns, strict=True):
        assert np.array_equal(a.nodes, b.nodes)
    assert isinstance(program.instructions[113], Shift)


@pytest.mark.parametrize("diameter", [5.0, 20.0, 1023.0])
def test_a_yarn_too_thick_for_the_gap_at_the_fell_is_refused_by_machine_twin_and_reference(
    diameter,
):
    """The warps start c_mat x pitch = 5 mm apart at the fell: d = 20 mm put nodes 19 mm
    outside the matrix and above the guides, d = 1023 mm 1 m out, and nothing refused them."""
    with pytest.raises(ValueError, match="does not fit: it must be less than c_mat x the smaller"):
        Machine(2, 2, 10.0, 10.0, 100.0, 0.5, diameter)
    with pytest.raises(TwinError, match=f"a yarn diameter of {diameter:g} mm does not fit"):
        Twin(Machine(2, 2, 10.0, 10.0, 100.0, 0.5), WORKED_FILL, diameter)
    with pytest.raises(ValueError, match="overlap where they start at the fell"):
        RefTwin(Machine(2, 2, 10.0, 10.0, 100.0, 0.5), list(WORKED_FILL), diameter)


def test_a_yarn_just_thinner_than_the_gap_fits():
    Twin(Machine(2, 2, 10.0, 10.0, 100.0, 0.5), WORKED_FILL, 4.999)
    RefTwin(Machine(2, 2, 10.0, 10.0, 100.0, 0.5), list(WORKED_FILL), 4.999)
