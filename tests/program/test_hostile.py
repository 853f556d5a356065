"""Hostile programs: the only exception a program can raise is a ProgramError naming line:col.

The fixed cases are the ones found by probing (an integer of thousands of digits, REPEATs
nested hundreds deep, digits of other scripts); the fuzz builds programs from the language's
own words and from arbitrary text.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bwsd.errors import ProgramError
from bwsd.program import parse_program
from bwsd.program.lexer import MAX_DIGITS
from bwsd.program.parser import MAX_NESTING

FILL = "FILL row=0 col=0\nXX\nEND\n"


@pytest.mark.parametrize(
    ("text", "where", "words"),
    [
        ("REPEAT " + "9" * 5000 + "\nTAKEUP 1\nEND\n", "1:8", f"more than {MAX_DIGITS}"),
        (FILL + "ROW 0:+" + "9" * 5000 + "\n", "4:7", "(5001 characters)"),
        (FILL + "ROW " + "9" * 5000 + ":+1\n", "4:5", "(5000 characters)"),
        (
            "REPEAT 2\n" * 600 + "TAKEUP 1\n" + "END\n" * 600,
            f"{MAX_NESTING + 1}:1",
            f"nested more than {MAX_NESTING} deep",
        ),
        (FILL + "ROW 0:+\u0661\n", "4:7", "bad shift"),
        ("REPEAT \u0662\nTAKEUP 1\nEND\n", "1:8", "expected an integer"),
        ("TAKEUP \u0661\n", "1:8", "expected a number"),
        ("TAKEUP 1e999\n", "1:8", "cannot be kept exactly"),
        ("WEFT x=0 y=0 z=1 angle=1e999 length=1\n", "1:24", "cannot be kept exactly"),
        ("WEFT x=0 y=0 z=1 angle=30 length=1e999\n", "1:34", "cannot be kept exactly"),
        ("YARN diameter=1e999\n", "1:15", "cannot be kept exactly"),
        ("YARN diameter=inf\n", "1:15", "expected a number"),
        ("TAKEUP \u00b9\n", "1:8", "expected a number"),
    ],
)
def test_each_probe_is_a_program_error_at_its_place(text, where, words):
    with pytest.raises(ProgramError) as caught:
        parse_program(text)
    message = str(caught.value)
    assert f"<program>:{where}:" in message and words in message, message
    assert len(message) < 300  # a short excerpt, never the input back whole


WORDS = [
    "YARN",
    "FILL",
    "ROW",
    "COL",
    "TAKEUP",
    "WEFT",
    "REPEAT",
    "END",
    "diameter=1",
    "row=0",
    "col=0",
    "X",
    ".",
    "XX",
    "0:+1",
    "1:-1",
    "0:+",
    ":",
    "x=0",
    "y=0",
    "z=1",
    "angle=30",
    "length=5",
    "1",
    "0",
    "-1",
    "2.5",
    "1e999",
    "nan",
    "inf",
    "9" * 40,
    "\u0661",
    "#",
    "=",
    "\t",
]
lines = st.lists(st.sampled_from(WORDS), max_size=6).map(" ".join)


@pytest.mark.slow
@settings(max_examples=500, deadline=None)
@given(st.lists(lines, max_size=12).map("\n".join) | st.text(max_size=200))
def test_any_program_parses_or_is_a_program_error(text):
    try:
        parse_program(text)
    except ProgramError as exc:
        assert exc.line >= 0 and exc.column >= 0


def test_the_expansion_limit_is_the_callers_and_stops_before_expanding():
    text = FILL + "REPEAT 1000\nREPEAT 1000\nREPEAT 1000\nTAKEUP 1\nEND\nEND\nEND\n"
    with pytest.raises(
        ProgramError,
        match=r"<program>:4:1: the program expands to more than "
        r"1000000 instructions",
    ):
        parse_program(text)
    with pytest.raises(ProgramError, match=r"<program>:4:1: .* more than 50 instructions"):
        parse_program(FILL + "REPEAT 10\nREPEAT 10\nTAKEUP 1\nEND\nEND\n", most=50)
    assert len(parse_program(FILL + "REPEAT 50\nTAKEUP 1\nEND\n", most=50).instructions) == 50
