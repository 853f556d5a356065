"""The .bws parser: text in, Program out; every fault a ProgramError with line and column."""

from __future__ import annotations

from dataclasses import dataclass, field

from bwsd.errors import ProgramError
from bwsd.program.lexer import Token, Where, integer, key_values, number, shift_entry, tokenize
from bwsd.twin.instructions import Axis, Instruction, Move, Program, Shift, TakeUp, Weft

# A bound on the expanded program, so that nested REPEATs cannot exhaust memory.
MAX_INSTRUCTIONS = 1_000_000
MAX_NESTING = 32  # REPEAT blocks inside one another
FILL_CASE = frozenset("Xx")
FILL_EMPTY = "."
_WEFT_KEYS = ("x", "y", "z", "angle", "length")


@dataclass(frozen=True)
class SourceMap:
    """Where each part of a parsed program was written, for errors found after parsing.

    ``fill`` gives (line, column) of each filled cell in fill order; ``keywords`` the
    column of each instruction's keyword; ``entries`` the column of each ROW/COL entry
    of each instruction (empty for other instructions). Lines are in ``Program.lines``.
    ``diameter`` is (line, column) of the YARN statement's value, (0, 0) without one.
    """

    fill: tuple[tuple[int, int], ...]
    keywords: tuple[int, ...]
    entries: tuple[tuple[int, ...], ...]
    diameter: tuple[int, int] = (0, 0)


@dataclass(frozen=True)
class _Statement:
    instruction: Instruction
    line: int
    column: int
    entries: tuple[int, ...] = ()


@dataclass
class _Repeat:
    count: int
    line: int
    column: int
    body: list[_Statement | _Repeat] = field(default_factory=list)


@dataclass
class _FillBlock:
    row: int
    col: int
    line: int
    column: int
    rows: int = 0


class _Parser:
    def __init__(self, source: str) -> None:
        self.source = source
        self.diameter: float | None = None
        self.diameter_line = 0
        self.diameter_column = 0
        self.fills: dict[tuple[int, int], tuple[int, int]] = {}
        self.stack: list[_Repeat] = [_Repeat(1, 0, 0)]
        self.block: _FillBlock | None = None
        self.started = False

    def feed(self, lineno: int, line: str) -> None:
        where = Where(self.source, lineno)
        if self.block is not None:
            self._fill_line(where, line, self.block)
            return
        tokens = tokenize(line)
        if not tokens:
            return
        keyword, rest = tokens[0], tokens[1:]
        handler = _HANDLERS.get(keyword.text.upper())
        if handler is None:
            raise where.error(f"unknown keyword {keyword.text!r}", keyword.column)
        handler(self, where, keyword, rest)

    def finish(self) -> _Repeat:
        if self.block is not None:
            raise ProgramError(
                "FILL block not closed (missing END)",
                line=self.block.line,
                column=self.block.column,
                source=self.source,
            )
        if len(self.stack) > 1:
            open_block = self.stack[-1]
            raise ProgramError(
                "REPEAT block not closed (missing END)",
                line=open_block.line,
                column=open_block.column,
                source=self.source,
            )
        return self.stack[0]

    # statements -------------------------------------------------------------------------

    def _yarn(self, where: Where, keyword: Token, rest: list[Token]) -> None:
        self._before_instructions(where, keyword)
        if self.diameter_line:
            raise where.error(
                f"YARN given twice (first at line {self.diameter_line})", keyword.column
            )
        text, column = key_values(rest, ("diameter",), where, keyword)["diameter"]
        value = number(text, column, where, "diameter")
        if value < 0:
            raise where.error("diameter must not be negative", column)
        self.diameter, self.diameter_line, self.diameter_column = value, where.line, column

    def _fill(self, where: Where, keyword: Token, rest: list[Token]) -> None:
        self._before_instructions(where, keyword)
        found = key_values(rest, ("row", "col"), where, keyword)
        start = []
        for key in ("row", "col"):
            text, column = found[key]
            value = integer(text, column, where, key)
            if value < 0:
                raise where.error(f"{key} must not be negative", column)
            start.append(value)
        self.block = _FillBlock(start[0], start[1], where.line, keyword.column)

    def _fill_line(self, where: Where, line: str, block: _FillBlock) -> None:
        tokens = tokenize(line)
        if tokens and tokens[0].text.upper() == "END":
            _no_more(where, tokens[1:])
            if block.rows == 0:
                raise where.error("FILL block has no rows", tokens[0].column)
            self.block = None
            return
        if not line.strip():
            raise where.error("blank line inside FILL block (write empty cells as '.')", 1)
        if not tokens:
            return  # a comment line inside the block
        first = tokens[0].column
        cells = line[first - 1 :].split("#", 1)[0].rstrip()
        row = block.row + block.rows
        for offset, char in enumerate(cells):
            if char in FILL_CASE:
                self._add_fill((row, block.col + offset), where, first + offset)
            elif char != FILL_EMPTY:
                raise where.error(
                    f"bad fill character {char!r} (expected '.' or 'X')", first + offset
                )
        block.rows += 1

    def _add_fill(self, cell: tuple[int, int], where: Where, column: int) -> None:
        if cell in self.fills:
            raise where.error(f"cell {cell} already filled at line {self.fills[cell][0]}", column)
        self.fills[cell] = (where.line, column)

    def _shift(self, where: Where, keyword: Token, rest: list[Token]) -> None:
        axis: Axis = "row" if keyword.text.upper() == "ROW" else "col"
        if not rest:
            raise where.error(
                f"{keyword.text} needs at least one {axis}:shift entry", keyword.column
            )
        moves: list[Move] = []
        columns: list[int] = []
        for tok in rest:
            move, column = shift_entry(tok, where, axis)
            for other in moves:
                if other.line == move.line and _overlap(other, move):
                    raise where.error(
                        f"{axis} {move.line} listed twice (as {other.text()} and {move.text()})",
                        column,
                    )
            moves.append(move)
            columns.append(column)
        self._add(Shift(axis, tuple(moves)), where, keyword, tuple(columns))

    def _takeup(self, where: Where, keyword: Token, rest: list[Token]) -> None:
        if not rest:
            raise where.error("TAKEUP needs a length in mm", keyword.column)
        _no_more(where, rest[1:])
        value = number(rest[0].text, rest[0].column, where, "take-up")
        if value <= 0:
            raise where.error("take-up must be positive", rest[0].column)
        self._add(TakeUp(value), where, keyword)

    def _weft(self, where: Where, keyword: Token, rest: list[Token]) -> None:
        found = key_values(rest, _WEFT_KEYS, where, keyword)
        values = {k: number(*found[k], where, k) for k in _WEFT_KEYS}
        if values["length"] <= 0:
            raise where.error("length must be positive", found["length"][1])
        if values["z"] <= 0:
            raise where.error("z must be positive (above the fell)", found["z"][1])
        self._add(Weft(**values), where, keyword)

    def _repeat(self, where: Where, keyword: Token, rest: list[Token]) -> None:
        if not rest:
            raise where.error("REPEAT needs a count", keyword.column)
        _no_more(where, rest[1:])
        count = integer(rest[0].text, rest[0].column, where, "count")
        if count < 1:
            raise where.error("count must be at least 1", rest[0].column)
        if len(self.stack) > MAX_NESTING:
            raise where.error(f"REPEAT nested more than {MAX_NESTING} deep", keyword.column)
        block = _Repeat(count, where.line, keyword.column)
        self.stack[-1].body.append(block)
        self.stack.append(block)

    def _end(self, where: Where, keyword: Token, rest: list[Token]) -> None:
        if len(self.stack) == 1:
            raise where.error("END without an open REPEAT or FILL block", keyword.column)
        _no_more(where, rest)
        block = self.stack.pop()
        if not block.body:
            raise ProgramError(
                "REPEAT block has no instructions",
                line=block.line,
                column=block.column,
                source=self.source,
            )

    # helpers ----------------------------------------------------------------------------

    def _before_instructions(self, where: Where, keyword: Token) -> None:
        name = keyword.text.upper()
        if len(self.stack) > 1:
            raise where.error(f"{name} is not allowed inside REPEAT", keyword.column)
        if self.started:
            raise where.error(f"{name} must come before the first instruction", keyword.column)

    def _add(
        self, instruction: Instruction, where: Where, keyword: Token, entries: tuple[int, ...] = ()
    ) -> None:
        self.started = True
        self.stack[-1].body.append(_Statement(instruction, where.line, keyword.column, entries))


def _overlap(a: Move, b: Move) -> bool:
    """Two entries of one line that would move the same cells (a whole line overlaps all)."""
    if a.span is None or b.span is None:
        return True
    return a.span[0] <= b.span[1] and b.span[0] <= a.span[1]


def _no_more(where: Where, extra: list[Token]) -> None:
    if extra:
        raise where.error(f"unexpected {extra[0].text!r}", extra[0].column)


_HANDLERS = {
    "YARN": _Parser._yarn,
    "FILL": _Parser._fill,
    "ROW": _Parser._shift,
    "COL": _Parser._shift,
    "TAKEUP": _Parser._takeup,
    "WEFT": _Parser._weft,
    "REPEAT": _Parser._repeat,
    "END": _Parser._end,
}


def _count(node: _Statement | _Repeat) -> int:
    """Expanded instruction count of a node, by arithmetic alone (nothing is expanded)."""
    if isinstance(node, _Statement):
        return 1
    return node.count * sum(_count(child) for child in node.body)


def _passing(node: _Repeat, most: int) -> _Statement | _Repeat:
    """Where a program of more than ``most`` instructions passes it: the innermost REPEAT
    that expands past it alone, else the top-level statement or REPEAT the count passes at."""
    running = 0
    for child in node.body:
        size = _count(child)
        if isinstance(child, _Repeat) and size > most:
            return _passing(child, most)
        running += size
        if node.line == 0 and running > most:  # the top level, which has no line of its own
            return child
    return node


def _check_size(root: _Repeat, source: str, most: int) -> None:
    """Refuse a program beyond ``most`` instructions, before anything is expanded."""
    total = _count(root)
    if total <= most:
        return
    place = _passing(root, most)
    shown = str(total) if total < 10**12 else "more than 10^12"  # nested counts multiply
    raise ProgramError(
        f"the program expands to more than {most} instructions ([controller] "
        f"max_instructions): {shown} in all",
        line=place.line,
        column=place.column,
        source=source,
    )


def _expand(body: list[_Statement | _Repeat], out: list[_Statement]) -> None:
    for node in body:
        if isinstance(node, _Statement):
            out.append(node)
        else:
            for _ in range(node.count):
                _expand(node.body, out)


def parse_program_with_positions(
    text: str,
    source: str = "<program>",
    most: int = MAX_INSTRUCTIONS,
) -> tuple[Program, SourceMap]:
    """Parse a .bws program; also return where each instruction and filled cell was written.

    A program that expands to more than ``most`` instructions is refused.
    """
    parser = _Parser(source)
    # Only "\n" ends a line (with an optional "\r" before it), as in every editor.
    lines = text.split("\n")
    if lines[-1] == "":
        lines.pop()  # the text's final newline does not start another line
    for lineno, line in enumerate(lines, start=1):
        parser.feed(lineno, line.removesuffix("\r"))
    root = parser.finish()
    _check_size(root, source, most)
    flat: list[_Statement] = []
    _expand(root.body, flat)
    cells = sorted(parser.fills)
    repeats = [node for node in root.body if isinstance(node, _Repeat)]
    cycle = sum(_count(n) for n in repeats[-1].body) if repeats else None
    program = Program(
        diameter=parser.diameter,
        fill=tuple(cells),
        instructions=tuple(s.instruction for s in flat),
        lines=tuple(s.line for s in flat),
        cycle_length=cycle,
    )
    where = SourceMap(
        fill=tuple(parser.fills[c] for c in cells),
        keywords=tuple(s.column for s in flat),
        entries=tuple(s.entries for s in flat),
        diameter=(parser.diameter_line, parser.diameter_column),
    )
    return program, where


def parse_program(text: str, source: str = "<program>", most: int = MAX_INSTRUCTIONS) -> Program:
    """Parse a .bws program (see docs/program.md); raises ProgramError at the fault."""
    return parse_program_with_positions(text, source, most)[0]
