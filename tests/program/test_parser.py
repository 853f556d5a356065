"""The .bws parser: statements, blocks, REPEAT expansion and every error with its place."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bwsd.errors import ProgramError
from bwsd.program.parser import MAX_INSTRUCTIONS, parse_program, parse_program_with_positions
from bwsd.twin.instructions import Shift, TakeUp, Weft

WORKED = """\
YARN diameter=1
FILL row=0 col=0
X.
.X
END
REPEAT 4
ROW 0:+1 1:-1
COL 1:+1 0:-1
ROW 1:-1 0:+1
COL 0:-1 1:+1
END
"""


def test_worked_example_program():
    program = parse_program(WORKED)
    assert program.diameter == 1.0
    assert program.fill == ((0, 0), (1, 1))
    assert len(program.instructions) == 16
    assert program.instructions[0] == Shift("row", ((0, 1), (1, -1)))
    assert program.instructions[5] == Shift("col", ((1, 1), (0, -1)))
    assert program.lines == (7, 8, 9, 10) * 4
    assert program.cycle_length == 4


def test_comments_blank_lines_and_case():
    text = "# a program\n\n  yarn DIAMETER=0   # centre lines only\nrow 0:+1 # shift\nTakeUp 2.5\n"
    program = parse_program(text)
    assert program.diameter == 0.0
    assert program.instructions == (Shift("row", ((0, 1),)), TakeUp(2.5))
    assert program.lines == (4, 5)
    assert program.cycle_length is None


def test_weft_keys_in_any_order_and_number_forms():
    program = parse_program("WEFT length=1e2 ANGLE=-90 z=.5 y=+8 x=36.25\n")
    assert program.instructions == (Weft(36.25, 8.0, 0.5, -90.0, 100.0),)


def test_nested_repeat_lines_and_cycle_of_last_top_level_repeat():
    text = "TAKEUP 1\nREPEAT 2\nTAKEUP 2\nEND\nREPEAT 3\nROW 0:+1\nREPEAT 2\nROW 0:-1\nEND\nEND\n"
    program = parse_program(text)
    assert program.lines == (1, 3, 3) + (6, 8, 8) * 3
    assert program.cycle_length == 3
    assert len(program.instructions) == 1 + 2 + 9


def test_ragged_and_indented_fill_blocks_and_union_order():
    text = "FILL row=2 col=3\n  X\n  .XX   # a comment\nEND\nFILL row=0 col=0\n..x\nEND\n"
    program, where = parse_program_with_positions(text)
    assert program.fill == ((0, 2), (2, 3), (3, 4), (3, 5))
    assert where.fill == ((6, 3), (2, 3), (3, 4), (3, 5))


def test_comment_line_inside_fill_is_not_a_row():
    program = parse_program("FILL row=0 col=0\nX\n# gap\n.X\nEND\n")
    assert program.fill == ((0, 0), (1, 1))


def test_source_map_of_entries_and_keywords():
    program, where = parse_program_with_positions("REPEAT 2\n  ROW 0:+1   12:-3\nEND\n")
    assert program.instructions[0] == Shift("row", ((0, 1), (12, -3)))
    assert where.entries == ((7, 14), (7, 14))
    assert where.keywords == (3, 3)


def test_error_names_source_line_and_column():
    with pytest.raises(ProgramError) as info:
        parse_program("TAKEUP 1\nFOO\n", source="a.bws")
    assert str(info.value).startswith("a.bws:2:1: ")
    assert (info.value.line, info.value.column, info.value.source) == (2, 1, "a.bws")


ERRORS = [
    # (program text, line, column, part of the message)
    ("FOO 1", 1, 1, "unknown keyword"),
    ("TAKEUP 1\n   Rows 0:+1", 2, 4, "unknown keyword"),
    ("ROW", 1, 1, "at least one"),
    ("ROW 1+1", 1, 5, "malformed entry"),
    ("ROW a:1", 1, 5, "bad row index"),
    ("COL -1:1", 1, 5, "bad col index"),
    ("ROW 1:x", 1, 7, "bad shift"),
    ("ROW 12:1.5", 1, 8, "bad shift"),
    ("ROW 1:0", 1, 7, "must not be zero"),
    ("ROW 1:+1 2:-1 1:+2", 1, 15, "listed twice"),
    ("TAKEUP", 1, 1, "needs a length"),
    ("TAKEUP 0", 1, 8, "positive"),
    ("TAKEUP -2", 1, 8, "positive"),
    ("TAKEUP abc", 1, 8, "expected a number"),
    ("TAKEUP nan", 1, 8, "expected a number"),
    ("TAKEUP 1 2", 1, 10, "unexpected"),
    ("WEFT x=1 y=2 z=3 angle=0", 1, 1, "length="),
    ("WEFT x=1 x=2 y=2 z=3 angle=0 length=5", 1, 10, "given twice"),
    ("WEFT x=1 y=2 z=3 angle=0 length=5 w=1", 1, 35, "unknown key"),
    ("WEFT x=1 y=2 z=3 angle 0 length=5", 1, 18, "malformed entry"),
    ("WEFT x=1 y=2e z=3 angle=0 length=5", 1, 12, "expected a number"),
    ("WEFT x= y=2 z=3 angle=0 length=5", 1, 8, "no value"),
    ("WEFT x=1 y=2 z=3 angle=0 length=0", 1, 33, "length must be positive"),
    ("WEFT x=1 y=2 z=-3 angle=0 length=5", 1, 16, "z must be positive"),
    ("WEFT x=1 y=2 z=3 angle=inf length=5", 1, 24, "expected a number"),
    ("END", 1, 1, "without an open"),
    ("TAKEUP 1\n  end", 2, 3, "without an open"),
    ("REPEAT", 1, 1, "needs a count"),
    ("REPEAT 0", 1, 8, "at least 1"),
    ("REPEAT 2.5", 1, 8, "expected an integer"),
    ("REPEAT 2 3", 1, 10, "unexpected"),
    ("REPEAT 2\nEND", 1, 1, "no instructions"),
    ("REPEAT 2\nTAKEUP 1\nEND now", 3, 5, "unexpected"),
    ("REPEAT 2\nTAKEUP 1", 1, 1, "not closed"),
    ("TAKEUP 1\n  REPEAT 2\n  REPEAT 3\n  TAKEUP 1\n  END\n", 2, 3, "not closed"),
    ("REPEAT 1000\nREPEAT 1000\nREPEAT 1001\nTAKEUP 1\nEND\nEND\nEND", 2, 1, "more than"),
    ("YARN diameter=1\nYARN diameter=2", 2, 1, "given twice"),
    ("YARN diameter=-1", 1, 15, "must not be negative"),
    ("YARN", 1, 1, "diameter="),
    ("YARN width=1", 1, 6, "unknown key"),
    ("TAKEUP 1\nYARN diameter=1", 2, 1, "before the first instruction"),
    ("REPEAT 2\n  YARN diameter=1\nEND", 2, 3, "inside REPEAT"),
    ("FILL row=0", 1, 1, "col="),
    ("FILL row=-1 col=0\nX\nEND", 1, 10, "must not be negative"),
    ("FILL row=0 col=1.5\nX\nEND", 1, 16, "expected an integer"),
    ("FILL row=0 col=0\nX.Q\nEND", 2, 3, "bad fill character"),
    ("FILL row=0 col=0\n  X.\n  .X X\nEND", 3, 5, "bad fill character"),
    ("FILL row=0 col=0\nX\n\n.X\nEND", 3, 1, "blank line"),
    ("FILL row=0 col=0\nEND", 2, 1, "no rows"),
    ("FILL row=0 col=0\nX\nEND X", 3, 5, "unexpected"),
    ("FILL row=0 col=0\nX\n", 1, 1, "not closed"),
    ("FILL row=0 col=0\nXX\nEND\nFILL row=0 col=0\n .X\nEND", 5, 3, "already filled"),
    ("FILL row=0 col=0\nX\nEND\nTAKEUP 1\nFILL row=3 col=0\nX\nEND", 5, 1, "before the first"),
    ("REPEAT 2\n FILL row=0 col=0\nX\nEND\nEND", 2, 2, "inside REPEAT"),
]


@pytest.mark.parametrize(("text", "line", "column", "message"), ERRORS)
def test_errors_point_at_the_fault(text: str, line: int, column: int, message: str):
    with pytest.raises(ProgramError) as info:
        parse_program(text, source="t.bws")
    err = info.value
    assert (err.line, err.column) == (line, column), err
    assert message in err.reason
    assert str(err).startswith(f"t.bws:{line}:{column}: ")


@pytest.mark.slow
def test_expansion_at_the_bound_is_accepted():
    side = 1000
    assert side * side == MAX_INSTRUCTIONS
    program = parse_program(f"REPEAT {side}\nREPEAT {side}\nTAKEUP 1\nEND\nEND\n")
    assert len(program.instructions) == MAX_INSTRUCTIONS


# Round trip: random instruction lists written as text read back unchanged.

_shift = st.builds(
    lambda axis, moves: Shift(axis, tuple(moves.items())),
    st.sampled_from(["row", "col"]),
    st.dictionaries(st.integers(0, 40), st.integers(-5, 5).filter(bool), min_size=1),
)
_float = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
_positive = st.floats(1e-6, 1e6, allow_nan=False, allow_infinity=False)
_instruction = st.one_of(
    _shift,
    st.builds(TakeUp, _positive),
    st.builds(Weft, _float, _float, _positive, _float, _positive),
)


def _text(item: Shift | TakeUp | Weft) -> str:
    if isinstance(item, Shift):
        return " ".join([item.axis.upper(), *(f"{i}:{k:+d}" for i, k, _ in item.moves)])
    if isinstance(item, TakeUp):
        return f"TAKEUP {item.length!r}"
    return (
        f"WEFT x={item.x!r} y={item.y!r} z={item.z!r} angle={item.angle!r} length={item.length!r}"
    )


@pytest.mark.slow
@given(st.lists(_instruction, min_size=1, max_size=20), st.integers(1, 4))
def test_round_trip(instructions: list[Shift | TakeUp | Weft], count: int):
    body = "\n".join(_text(i) for i in instructions)
    program = parse_program(f"REPEAT {count}\n{body}\nEND\n")
    assert program.instructions == tuple(instructions) * count
    assert program.lines == tuple(range(2, 2 + len(instructions))) * count
    assert program.cycle_length == len(instructions)


def test_crlf_and_form_feed_keep_line_numbers():
    program = parse_program("TAKEUP 1\r\n# a\x0cb\r\nTAKEUP 2\r\n")
    assert program.lines == (1, 3)
    with pytest.raises(ProgramError) as info:
        parse_program("TAKEUP 1\r\n\r\nBAD\r\n")
    assert (info.value.line, info.value.column) == (3, 1)


@pytest.mark.parametrize(
    ("text", "column", "message"),
    [
        ("TAKEUP 0.30000000000000001", 8, "take-up: '0.30000000000000001' cannot be kept exactly"),
        ("TAKEUP 1e999", 8, "take-up: '1e999' cannot be kept exactly"),
        ("TAKEUP \u0661", 8, "take-up: expected a number"),
        ("WEFT x=1 y=2 z=3 angle=1e-400 length=5", 24, "angle: '1e-400' cannot be kept"),
        ("YARN diameter=2.000000000000000001", 15, "diameter: '2.000000000000000001' cannot"),
    ],
)
def test_numbers_are_exact_decimals_or_refused(text, column, message):
    with pytest.raises(ProgramError, match=message) as info:
        parse_program(text)
    assert (info.value.line, info.value.column) == (1, column)


def test_a_number_is_the_decimal_written():
    from fractions import Fraction

    from bwsd.twin.exact import exact

    (takeup,) = parse_program("TAKEUP 2.54").instructions
    assert isinstance(takeup, TakeUp) and exact(takeup.length) == Fraction(254, 100)
