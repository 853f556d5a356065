"""Validation on the occupancy grid: every impossible fill or move refused at its place."""

from __future__ import annotations

import pytest

from bwsd.errors import ProgramError
from bwsd.program import load_program, parse_program, parse_program_with_positions, validate
from bwsd.program.validate import Occupancy
from bwsd.twin.instructions import Program, Shift
from bwsd.twin.machine import Machine

M2 = Machine(2, 2, 10, 10, 100, 0.5, 1.0)
M3 = Machine(3, 4, 10, 10, 100, 0.5, 1.0)
WORKED = (
    "YARN diameter=1\nFILL row=0 col=0\nX.\n.X\nEND\nREPEAT 4\n"
    "ROW 0:+1 1:-1\nCOL 1:+1 0:-1\nROW 1:-1 0:+1\nCOL 0:-1 1:+1\nEND\n"
)


def _check(text: str, machine: Machine) -> ProgramError:
    program, where = parse_program_with_positions(text, "v.bws")
    with pytest.raises(ProgramError) as info:
        validate(program, machine, "v.bws", where)
    return info.value


def test_worked_example_is_valid():
    validate(parse_program(WORKED), M2)


def test_a_yarn_just_thinner_than_the_gap_at_the_fell_is_valid():
    validate(parse_program("YARN diameter=4.999\nFILL row=0 col=0\nX\nEND"), M3)
    validate(parse_program("YARN diameter=0\nFILL row=0 col=0\nX\nEND"), M3)


FAULTS = [
    # (program, machine, line, column, part of the message)
    ("FILL row=0 col=0\nX.\n.X..X\nEND", M3, 3, 5, "outside"),
    ("FILL row=2 col=1\n.X\nX\nEND", M3, 3, 1, "outside"),
    ("FILL row=0 col=0\nX\nEND\nROW 5:+1", M3, 4, 5, "row 5 is outside"),
    ("FILL row=0 col=0\nX\nEND\nCOL 0:+1 4:+1", M3, 4, 10, "col 4 is outside"),
    ("FILL row=0 col=0\nX\nEND\nCOL 0:-1", M3, 4, 5, "leave the matrix"),
    ("FILL row=0 col=0\n.XX\nEND\nROW 0:+1 1:+1\n ROW 1:-1   0:+1", M3, 5, 13, "instruction 2"),
    ("FILL row=0 col=0\nX\nEND\nREPEAT 5\n  COL 0:+1\nEND", M3, 5, 7, "instruction 3"),
    # a YARN the machine cannot hold: c_mat 0.5 x pitch 10 = 5 mm between neighbours at the fell
    (
        "# thick\nYARN  diameter=5\nFILL row=0 col=0\nX\nEND",
        M3,
        2,
        16,
        "a yarn diameter of 5 mm does not fit: it must be less than c_mat x the smaller pitch",
    ),
]


@pytest.mark.parametrize(("text", "machine", "line", "column", "message"), FAULTS)
def test_faults_point_at_their_place(text, machine, line, column, message):
    err = _check(text, machine)
    assert (err.line, err.column) == (line, column), err
    assert message in err.reason
    assert str(err).startswith(f"v.bws:{line}:{column}: ")


def test_whole_row_shift_leading_case_first():
    """XXX. shifted +1 and .XXX shifted -1 are fine: the leading case makes room."""
    program = parse_program("FILL row=0 col=0\nXXX.\n.XXX\nEND\nROW 0:+1 1:-1\nROW 0:-1 1:+1\n")
    validate(program, M3)


def test_occupancy_refuses_an_occupied_cell_and_a_cell_outside():
    grid = Occupancy(M3)
    assert grid.fill((0, 0)) is None
    assert grid.fill((0, 1)) is None
    assert "filled twice" in (grid.fill((0, 1)) or "")
    assert "outside" in (grid.fill((3, 0)) or "")
    assert "occupied" in (grid.move((0, 0), (0, 1)) or "")
    assert "leave" in (grid.move((0, 0), (-1, 0)) or "")
    assert grid.cells == {(0, 0), (0, 1)}


def test_program_built_in_code_without_positions():
    program = Program(None, ((0, 0), (0, 0)), ())
    with pytest.raises(ProgramError, match="filled twice"):
        validate(program, M3)
    program = Program(None, ((0, 0),), (Shift("row", ((0, -1),)),), lines=(7,))
    with pytest.raises(ProgramError) as info:
        validate(program, M3)
    assert (info.value.line, info.value.column) == (7, 0)


def test_load_program_reads_parses_and_validates(tmp_path):
    path = tmp_path / "ok.bws"
    path.write_text(WORKED)
    assert len(load_program(path, M2).instructions) == 16
    bad = tmp_path / "bad.bws"
    bad.write_text(WORKED.replace("ROW 1:-1 0:+1", "ROW 1:-1 0:+2"))
    with pytest.raises(ProgramError) as info:
        load_program(bad, M2)
    assert (info.value.line, info.value.column, info.value.source) == (9, 10, str(bad))


def test_load_program_unreadable(tmp_path):
    with pytest.raises(ProgramError, match="cannot read"):
        load_program(tmp_path / "missing.bws", M2)
    binary = tmp_path / "bin.bws"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ProgramError, match="UTF-8"):
        load_program(binary, M2)


def test_a_weft_off_the_fixed_position_of_a_missing_axis_is_refused_at_its_line():
    """Without weft_y the inserter stands at the fixed y (the matrix's centre, 10 mm here):
    a weft elsewhere along y is refused naming its line; x and z have axes, so any goes."""
    machine = Machine(3, 3, 10, 10, 100, 0.5, weft_axes=("x", "z"))
    at_fixed = "FILL row=0 col=0\nX\nEND\nWEFT x=3 y=10 z=7 angle=0 length=5\n"
    validate(parse_program(at_fixed), machine)
    off = at_fixed + "REPEAT 2\n  TAKEUP 1\n  WEFT x=3 y=10.001 z=7 angle=0 length=5\nEND\n"
    program, positions = parse_program_with_positions(off, "w.bws")
    said = (
        r"w\.bws:7:3: instruction 3: the weft's y = 10\.001 mm is off the inserter's fixed "
        r'y = 10 mm: this machine has no weft_y axis \(\[machine\] weft_axes = \["x", "z"\]\)'
    )
    with pytest.raises(ProgramError, match=said):
        validate(program, machine, "w.bws", positions)
    first = parse_program(at_fixed)
    validate(first, Machine(3, 3, 10, 10, 100, 0.5, weft_axes=(), weft_fixed=(3, 10, 7)))
    higher = Machine(3, 3, 10, 10, 100, 0.5, weft_axes=(), weft_fixed=(3, 10, 7.001))
    with pytest.raises(ProgramError, match=r"the weft's z = 7 mm is off the inserter's fixed z"):
        validate(first, higher)  # one micrometre off on the wire
