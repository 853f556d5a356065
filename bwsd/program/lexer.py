"""Tokens of the .bws language: words with their columns, numbers, key=value and i:k entries."""

from __future__ import annotations

import re
from dataclasses import dataclass

from bwsd.errors import ProgramError
from bwsd.twin.exact import decimal_float
from bwsd.twin.instructions import Move

_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_INDEX = re.compile(r"[0-9]{1,18}")
_SHIFT = re.compile(r"[+-]?[0-9]{1,18}")  # ASCII digits only, at most MAX_DIGITS


@dataclass(frozen=True)
class Token:
    """A whitespace-separated word of one source line; ``column`` is 1-based."""

    text: str
    column: int


@dataclass(frozen=True)
class Where:
    """The place errors of one statement are reported at: source name and line number."""

    source: str
    line: int

    def error(self, message: str, column: int) -> ProgramError:
        """A ProgramError at ``column`` of this line."""
        return ProgramError(message, line=self.line, column=column, source=self.source)


def strip_comment(line: str) -> str:
    """The line without its ``#`` comment (columns of what is left are unchanged)."""
    cut = line.find("#")
    return line if cut < 0 else line[:cut]


def tokenize(line: str) -> list[Token]:
    """The words of a line, comment removed."""
    return [Token(m.group(), m.start() + 1) for m in re.finditer(r"\S+", strip_comment(line))]


def number(text: str, column: int, where: Where, what: str) -> float:
    """A decimal number (integer, fraction or exponent form), kept exactly (docs/twin.md):
    nan, inf and a decimal no float carries exactly are refused."""
    if not _NUMBER.fullmatch(text, 0) or not text.isascii():
        raise where.error(f"{what}: expected a number, got {text!r}", column)
    try:
        return decimal_float(text)
    except ValueError as exc:
        raise where.error(f"{what}: {exc}", column) from None


MAX_DIGITS = 18  # an integer of the language (a count, a shift) fits in 64 bits


def _shown(text: str) -> str:
    """A token quoted in an error, cut to its first 20 characters."""
    return repr(text) if len(text) <= 20 else f"{text[:20]!r}... ({len(text)} characters)"


def integer(text: str, column: int, where: Where, what: str) -> int:
    """A signed decimal integer of ASCII digits, at most MAX_DIGITS of them."""
    digits = text.lstrip("+-")
    if len(digits) > MAX_DIGITS and digits.isascii() and digits.isdigit():
        raise where.error(
            f"{what}: {text[:20]}... has {len(digits)} digits, more than {MAX_DIGITS}", column
        )
    if not _SHIFT.fullmatch(text):
        raise where.error(f"{what}: expected an integer, got {_shown(text)}", column)
    return int(text)


def key_values(
    tokens: list[Token], keys: tuple[str, ...], where: Where, keyword: Token
) -> dict[str, tuple[str, int]]:
    """Parse ``key=value`` tokens: every key of ``keys`` exactly once, nothing else.

    Returns key -> (value text, value column). Keys are case-insensitive.
    """
    found: dict[str, tuple[str, int]] = {}
    for tok in tokens:
        key, sep, value = tok.text.partition("=")
        if not sep or not key:
            raise where.error(f"malformed entry {tok.text!r}: expected key=value", tok.column)
        name = key.lower()
        if name not in keys:
            raise where.error(f"unknown key {key!r} (expected {', '.join(keys)})", tok.column)
        if name in found:
            raise where.error(f"key {key!r} given twice", tok.column)
        value_column = tok.column + len(key) + 1
        if not value:
            raise where.error(f"key {key!r} has no value", value_column)
        found[name] = (value, value_column)
    missing = [k for k in keys if k not in found]
    if missing:
        raise where.error(
            f"{keyword.text} needs {', '.join(k + '=' for k in missing)}", keyword.column
        )
    return found


_SPAN = re.compile(r"([0-9]{1,18})\.\.([0-9]{1,18})")


def shift_entry(tok: Token, where: Where, axis: str) -> tuple[Move, int]:
    """Parse an ``i:k`` or ``i[a..b]:k`` entry: returns the move and the column of the index."""
    head, sep, shift_text = tok.text.partition(":")
    if not sep:
        raise where.error(
            f"malformed entry {_shown(tok.text)}: expected {axis}:shift or "
            f"{axis}[first..last]:shift",
            tok.column,
        )
    index_text, bracket, span_text = head.partition("[")
    if not _INDEX.fullmatch(index_text):
        raise where.error(
            f"bad {axis} index {_shown(index_text)}: expected an integer >= 0", tok.column
        )
    span = None
    if bracket:
        span_column = tok.column + len(index_text) + 1
        match = _SPAN.fullmatch(span_text.removesuffix("]")) if span_text.endswith("]") else None
        if match is None:
            raise where.error(
                f"bad segment [{_shown(span_text)}: expected [first..last], cells along the line",
                span_column,
            )
        span = (int(match[1]), int(match[2]))
        if span[0] >= span[1]:
            raise where.error(
                f"bad segment [{span_text}: the first cell must come before the last", span_column
            )
    shift_column = tok.column + len(head) + 1
    if not _SHIFT.fullmatch(shift_text):
        raise where.error(
            f"bad shift {_shown(shift_text)}: expected a signed integer of at most "
            f"{MAX_DIGITS} digits",
            shift_column,
        )
    shift = int(shift_text)
    if shift == 0:
        raise where.error("shift must not be zero", shift_column)
    return Move(int(index_text), shift, span), tok.column
