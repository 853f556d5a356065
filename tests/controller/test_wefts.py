"""Wefts on the mock loom: placed, inserted, and each where the twin put it.

The controller runs generated programs with wefts (a braid-weave L on its corner segments,
a woven U of weave-3d) against the mock loom in its own process, over Modbus TCP and over
CANopen (the mock's socketcand hub). The loom records every weft its inserter put in, from
its own axes' positions. Each must equal the twin's weft node for node: the loom's integers
(um, mdeg), rounded to the twin's grid as docs/twin.md defines a weft's ends, give the
twin's nodes exactly where the program's weft is in whole micrometres (the wire's
resolution), and within a micrometre where it is finer (the generators write 0.1 um).
A fault of an axis placing the inserter holds the run, and Unhold resumes it to the
skeleton of an uninterrupted run, every weft in once.
"""

from __future__ import annotations

import asyncio
import itertools
import math
import tomllib
from collections.abc import Iterator
from fractions import Fraction
from pathlib import Path
from typing import Any

import pytest

from bwsd.config import parse_config
from bwsd.controller.facade import Controller
from bwsd.controller.packml import Command, State
from bwsd.controller.status import StopCause
from bwsd.errors import ProgramError
from bwsd.fieldbus import open_bus
from bwsd.journal import Journal
from bwsd.program import parse_program
from bwsd.program.braidweave import braid_weave
from bwsd.program.render import Generated
from bwsd.program.weave import weave_3d
from bwsd.twin import Twin, Weft, simulate
from simulator_hw.app import canopen_installed
from simulator_hw.control import request
from tests.controller.test_faults import after, poke
from tests.support.controller import bits, state_now
from tests.support.fieldbus import MACHINE, Mock, client_config, start_mock, wants_canopen
from tests.timing import scaled

pytestmark = pytest.mark.slow  # every test here is in the slow tier

Point = tuple[int, int, int]
Ends = tuple[Point, Point]
GRID = 1 << 32  # grid points per millimetre (docs/twin.md)
QUARTERS = [(Fraction(c), Fraction(s)) for c, s in ((1, 0), (0, 1), (-1, 0), (0, -1))]
SPEEDS = {"weft_travel_speed": 2000.0}  # mm/s: the inserter's axes travel, briefly
FAULTS = [("drive", "weft_x"), ("stall", "weft_z"), ("wrong_position", "weft_y")]
BACKENDS = [
    "modbus",
    pytest.param(
        "canopen",
        marks=pytest.mark.skipif(not canopen_installed(), reason="needs the canopen extra"),
    ),
]
PROGRAMS = {
    "braid-weave L": lambda: braid_weave(
        shape="L", flange=(2, 6), web=(4, 2), cycles=4, weft_every=2, angles=(0, 90)
    ),
    "weave-3d U": lambda: weave_3d(5, 6, 2, shape="U", leg=2, base=2),
}


def machine_table(generated: Generated) -> dict[str, Any]:
    table: dict[str, Any] = tomllib.loads(generated.config_toml())["machine"]
    return table


@pytest.fixture(scope="module", params=list(PROGRAMS))
def generated(request: pytest.FixtureRequest) -> Generated:
    made: Generated = PROGRAMS[request.param]()
    return made


@pytest.fixture
def loom(tmp_path: Path, generated: Generated, request: pytest.FixtureRequest) -> Iterator[Mock]:
    machine = machine_table(generated)
    canopen = wants_canopen(request)
    mock = start_mock(tmp_path, SPEEDS, machine=machine, program=generated.program, canopen=canopen)
    yield mock
    mock.stop()


async def controller(
    mock: Mock, tmp: Path, backend: str, generated: Generated, **settings: Any
) -> Controller:
    """A Controller on ``mock`` for ``generated``'s machine (``settings``: [fieldbus] keys)."""
    config = client_config(backend, mock.ports, machine=machine_table(generated), **settings)
    bus = open_bus(config)
    await bus.connect()
    return Controller(config.machine, bus, Journal.open(tmp / "journal.db"))


def twin_wefts(twin: Twin) -> list[Ends]:
    """The twin's wefts in insertion order: their end nodes, on the grid (2^-32 mm units)."""

    def grid(node: Any) -> Point:
        x, y, z = (int(float(v) * GRID) for v in node)  # grid values are exact floats
        return x, y, z

    wefts = [yarn for yarn in twin.skeleton().yarns if yarn.kind == "weft"]
    return [(grid(yarn.nodes[0]), grid(yarn.nodes[-1])) for yarn in wefts]


def loom_wefts(records: list[dict[str, int]], origin_um: int = 0) -> list[Ends]:
    """The wefts the loom made, from its axes' integers (um, mdeg): centre (x, y), z above
    the fell plus the take-up since the program began, the stroke along the angle; each end
    rounded once to the grid as docs/twin.md defines a weft's ends."""
    made = []
    for w in records:
        degrees = Fraction(w["angle"], 1000)
        if degrees % 90 == 0:
            cos, sin = QUARTERS[int(degrees // 90) % 4]
        else:
            rad = math.radians(float(degrees))
            cos, sin = Fraction(math.cos(rad)), Fraction(math.sin(rad))
        half = Fraction(w["length"], 2000)
        x, y = Fraction(w["x"], 1000), Fraction(w["y"], 1000)
        z = round(Fraction(w["z"] + w["takeup"] - origin_um, 1000) * GRID)
        minus = (round((x - half * cos) * GRID), round((y - half * sin) * GRID), z)
        made.append((minus, (round((x + half * cos) * GRID), round((y + half * sin) * GRID), z)))
    return made


def same_wefts(records: list[dict[str, int]], twin: Twin, program: Any) -> int:
    """Assert the loom's wefts are the twin's, node for node; how many compared exactly."""
    wefts = [ins for ins in program.instructions if isinstance(ins, Weft)]
    made, predicted = loom_wefts(records), twin_wefts(twin)
    assert len(made) == len(predicted) == len(wefts) > 0
    exact = 0
    for n, (weft, loom_ends, twin_ends) in enumerate(zip(wefts, made, predicted, strict=True)):
        if on_the_wire(weft):
            assert loom_ends == twin_ends, (n, weft)
            exact += 1
        else:
            pairs = zip(itertools.chain(*loom_ends), itertools.chain(*twin_ends), strict=True)
            off = max(abs(a - b) for a, b in pairs)
            assert off <= GRID // 1000, (n, weft, off / GRID * 1000)  # within the wire's um
    return exact


def on_the_wire(weft: Weft) -> bool:
    """The weft's numbers are whole micrometres (millidegrees): the wire carries them."""
    values = (weft.x, weft.y, weft.z, weft.length, weft.angle)
    return all((Fraction(str(v)) * 1000).denominator == 1 for v in values)


async def loom_state(mock: Mock) -> dict[str, Any]:
    return await request("127.0.0.1", mock.ports["control"], {"cmd": "state"})


@pytest.mark.parametrize("backend", BACKENDS)
def test_every_weft_lands_where_the_twin_put_it(loom, tmp_path, backend, generated):
    program = parse_program(generated.program)

    async def scenario() -> None:
        ctl = await controller(loom, tmp_path, backend, generated)
        try:
            await ctl.load("wefts.bws", generated.program)
            assert ctl.twin is not None
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await ctl.wait()
            assert ctl.packml.state is State.COMPLETE, ctl.packml.reason
            assert bits(ctl.twin) == bits(simulate(ctl.machine, program))
            records = (await loom_state(loom))["wefts"]
            assert same_wefts(records, ctl.twin, program) > 0
            assert len({centre(w) for w in loom_wefts(records)}) > 1  # the inserter moved
        finally:
            await ctl.close()

    asyncio.run(asyncio.wait_for(scenario(), 300))


def centre(ends: Ends) -> Point:
    (x0, y0, z0), (x1, y1, _) = ends
    return (x0 + x1) // 2, (y0 + y1) // 2, z0


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("kind", "axis"), FAULTS)
def test_a_weft_axis_fault_holds_and_unhold_resumes_to_the_predicted_skeleton(
    loom, tmp_path, backend, generated, kind, axis
):
    program = parse_program(generated.program)
    later = moving(program, axis)

    async def scenario() -> None:
        ctl = await controller(loom, tmp_path, backend, generated)
        try:
            await ctl.load("wefts.bws", generated.program)
            assert ctl.twin is not None
            await ctl.command(Command.RESET)
            # a weft placed away from where the weft before left the inserter: it must move
            after(ctl, later - 1, lambda: poke(loom, {"cmd": "fault", "kind": kind, "axis": axis}))
            await ctl.command(Command.START)
            await ctl.wait()
            assert ctl.packml.state is State.HELD, (ctl.packml.state, ctl.packml.reason)
            assert ctl.stop_cause is StopCause.DRIVE_FAULT
            assert f"instruction {later}: axis {axis}: " in ctl.packml.reason
            assert ctl.twin.done == later - 1
            state = await loom_state(loom)
            assert state["axes"]["weft_insert"]["strokes"] == later_wefts(program, later) - 1
            assert len(state["wefts"]) == later_wefts(program, later) - 1  # not inserted
            poke(loom, {"cmd": "clear"})  # the cause is gone; a latched fault stays
            await ctl.command(Command.UNHOLD)
            await ctl.wait()
            assert state_now(ctl) is State.COMPLETE, ctl.packml.reason
            assert bits(ctl.twin) == bits(simulate(ctl.machine, program))
            made = (await loom_state(loom))["wefts"]
            assert same_wefts(made, ctl.twin, program) > 0  # each in once, where predicted
        finally:
            await ctl.close()

    asyncio.run(asyncio.wait_for(scenario(), 300))


@pytest.mark.parametrize("backend", BACKENDS)
def test_unhold_while_a_placing_axis_still_travels_waits_for_it(tmp_path, backend):
    """A stall of weft_z holds the run while weft_x still travels to the weft's place (a
    drive takes no new set-point while it moves). Unhold at once waits for weft_x to come to
    rest before it places the weft again: the run completes, every weft in once."""
    generated = PROGRAMS["weave-3d U"]()
    program = parse_program(generated.program)
    later = moving(program, "weft_z")  # a stall of weft_z shows at the first weft it moves for
    wefts = [ins for ins in program.instructions[:later] if isinstance(ins, Weft)]
    assert wefts[-1].x != wefts[-2].x  # weft_x travels for that weft too
    slow = {"cmd": "speeds", "travel": 10.0}  # mm/s: 3.4 s to instruction 13's place
    loom = start_mock(
        tmp_path,
        SPEEDS,
        machine=machine_table(generated),
        program=generated.program,
        canopen=backend == "canopen",
    )

    def sluggish_then_stall() -> None:
        poke(loom, slow)
        poke(loom, {"cmd": "fault", "kind": "stall", "axis": "weft_z"})

    async def scenario() -> None:
        ctl = await controller(loom, tmp_path, backend, generated, timeout=scaled(10.0))
        try:
            await ctl.load("wefts.bws", generated.program)
            await ctl.command(Command.RESET)
            after(ctl, later - 1, sluggish_then_stall)
            await ctl.command(Command.START)
            await ctl.wait()
            assert ctl.packml.state is State.HELD, (ctl.packml.state, ctl.packml.reason)
            assert (await loom_state(loom))["axes"]["weft_x"]["busy"]  # still on its way
            poke(loom, {"cmd": "clear"})
            await ctl.command(Command.UNHOLD)  # returns once weft_x is at rest and it moves
            poke(loom, {"cmd": "speeds", "travel": SPEEDS["weft_travel_speed"]})
            await ctl.wait()
            assert state_now(ctl) is State.COMPLETE, ctl.packml.reason
            assert bits(ctl.twin) == bits(simulate(ctl.machine, program))
            assert ctl.twin is not None
            assert same_wefts((await loom_state(loom))["wefts"], ctl.twin, program) > 0
        finally:
            await ctl.close()

    try:
        asyncio.run(asyncio.wait_for(scenario(), 300))
    finally:
        loom.stop()


def later_wefts(program: Any, index: int) -> int:
    """Wefts among instructions 1 .. ``index``."""
    return sum(isinstance(ins, Weft) for ins in program.instructions[:index])


def moving(program: Any, axis: str) -> int:
    """The first weft after the first whose place along ``axis`` differs from the weft's
    before it: the inserter must move that axis to place it."""
    c = axis.removeprefix("weft_")
    wefts = [(i, ins) for i, ins in enumerate(program.instructions, 1) if isinstance(ins, Weft)]
    pairs = itertools.pairwise(wefts)
    return next(i for (_, was), (i, weft) in pairs if getattr(weft, c) != getattr(was, c))


def test_on_map_2_a_weft_goes_in_at_the_fixed_position_and_one_elsewhere_is_refused(tmp_path):
    """Map 2 has no positioning axes: the inserter stands at the fixed position (the
    matrix's centre, 15 mm, and d_mat / 2 = 50 mm up); a weft there runs and the loom makes
    it there, a weft elsewhere is refused when the program is loaded, naming its line."""
    fill = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\n"
    there = fill + "WEFT x=15 y=15 z=50 angle=0 length=20\nTAKEUP 2\n"
    elsewhere = fill + "TAKEUP 1\nWEFT x=15 y=-5 z=2 angle=0 length=20\n"
    mock = start_mock(tmp_path, {}, tables={"fieldbus.modbus": {"map": 2}})

    async def scenario() -> None:
        modbus = {"port": mock.ports["modbus"], "map": 2}
        config = parse_config({"machine": MACHINE, "fieldbus": {"modbus": modbus}})
        assert config.machine.weft_axes == ()
        bus = open_bus(config)
        await bus.connect()
        ctl = Controller(config.machine, bus, Journal.open(tmp_path / "journal.db"))
        try:
            said = r"elsewhere\.bws:7:1: .* the weft's y = -5 mm is off the inserter's fixed y = 15"
            with pytest.raises(ProgramError, match=said):
                await ctl.load("elsewhere.bws", elsewhere)
            await ctl.load("there.bws", there)
            assert ctl.twin is not None
            await ctl.command(Command.RESET)
            await ctl.command(Command.START)
            await ctl.wait()
            assert ctl.packml.state is State.COMPLETE, ctl.packml.reason
            records = (await loom_state(mock))["wefts"]
            made = {"x": 15_000, "y": 15_000, "z": 50_000, "angle": 0, "length": 20_000}
            assert records == [{**made, "takeup": 0}]
            assert same_wefts(records, ctl.twin, parse_program(there)) == 1
        finally:
            await ctl.close()

    try:
        asyncio.run(asyncio.wait_for(scenario(), 120))
    finally:
        mock.stop()
