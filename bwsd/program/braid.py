"""Two-yarn twist and 4-step (track-and-column) braids of rectangular, L, T and I sections."""

from __future__ import annotations

from bwsd.program import render
from bwsd.program.braidrules import find_rule, nearby_sizes
from bwsd.program.carriers import Rule, RuleCheck
from bwsd.program.render import Generated
from bwsd.program.sections import SHAPES, Block, Section, rect, shaped
from bwsd.twin.machine import Machine

__all__ = ["SHAPES", "Block", "braid4", "braid_rule", "describe", "layout", "section", "twist"]


def twist(
    turns: int = 4,
    *,
    takeup: float = 0.0,
    pitch: float = 10.0,
    d_mat: float = 100.0,
    c_mat: float = 0.5,
    diameter: float = 1.0,
) -> Generated:
    """Two yarns in a 2 x 2 matrix wound round each other, one turn per four moves, and
    ``takeup`` mm of take-up after each turn (none by default: the worked example)."""
    if turns < 1:
        raise ValueError("turns must be at least 1")
    if takeup < 0:
        raise ValueError("take-up must not be negative")
    machine = Machine(2, 2, pitch, pitch, d_mat, c_mat, diameter)
    options = [render.option("turns", turns)]
    options += [render.option("takeup", takeup)] if takeup else []
    command = " ".join(["bwsd program twist", *options, *render.machine_options(machine)])
    title = f"Two-yarn twist, {turns} turns" + (
        f", {render.num(takeup)} mm take-up a turn" if takeup else ""
    )
    turn = ["ROW 0:+1 1:-1", "COL 1:+1 0:-1", "ROW 1:-1 0:+1", "COL 0:-1 1:+1"]
    turn += [f"TAKEUP {render.num(takeup)}"] if takeup else []
    lines = [
        *render.header(title, command, machine),
        *render.fill_block(2, 2, [(0, 0), (1, 1)]),
        *render.repeat(turns, turn, "one turn: each yarn goes once round the square"),
    ]
    return Generated("twist", title, command, machine, "\n".join(lines) + "\n")


def section(
    shape: str = "rect", rows: int = 2, cols: int = 2, flange: Block = (2, 6), web: Block = (4, 2)
) -> Section:
    """The section a braid4 call names: a rows x cols rectangle, or an L, T or I."""
    if shape == "rect":
        return rect(rows, cols)
    return shaped(shape, flange, web)


def braid_rule(sec: Section, segments: bool) -> tuple[Rule, RuleCheck]:
    """The rule ``find_rule`` gives, or ValueError naming nearby sizes that mix."""
    found = find_rule(sec, segments)
    if found is not None:
        return found
    kind = "corner segments" if segments else "whole lines only"
    others = nearby_sizes(sec, segments)
    hint = (
        f"; nearby sizes that mix: {'; '.join(others)}"
        if others
        else "; no nearby size mixes either"
    )
    if not segments and sec.shape == "I":
        hint += "; an I section needs a machine with corner segments (--segments)"
    raise ValueError(
        f"no braid rule with {kind} mixes every carrier through every zone of {sec.spec}{hint}"
    )


def braid4(
    rows: int = 2,
    cols: int = 2,
    cycles: int = 10,
    *,
    shape: str = "rect",
    flange: Block = (2, 6),
    web: Block = (4, 2),
    segments: bool = True,
    takeup: float = 6.0,
    pitch: float = 10.0,
    d_mat: float = 150.0,
    c_mat: float = 0.4,
    diameter: float = 1.0,
) -> Generated:
    """A 4-step braid of a rectangular (rows x cols) or L, T, I (flange, web) section.

    A shaped section gets a rule that mixes every carrier through every zone, checked for
    the size asked: on corner segments of the machine (``segments``) or on whole lines only
    (L and T). The take-up comes after every four steps. The defaults keep the contacts more
    than a yarn diameter below the guides for the default sections and rectangles up to
    6 x 6 over 20 cycles; less take-up, a thicker yarn or a larger section can jam.
    """
    if cycles < 1:
        raise ValueError("cycles must be at least 1")
    if takeup <= 0:
        raise ValueError("take-up must be positive")
    sec = section(shape, rows, cols, flange, web)
    rule, check = braid_rule(sec, segments)
    size = sec.size
    machine = Machine(*size, pitch, pitch, d_mat, c_mat, diameter, segments=rule.segments)
    if shape == "rect":
        what = [render.option("rows", rows), render.option("cols", cols)]
        title = f"4-step braid, {rows} x {cols} body"
    else:
        what = [
            render.option("shape", shape),
            render.option("flange", _size(flange)),
            render.option("web", _size(web)),
        ]
        what += [] if segments else ["--no-segments"]
        title = f"4-step braid, {shape} section, flange {_size(flange)}, web {_size(web)}"
    title += f", {len(rule.carriers)} carriers, {cycles} cycles of {len(rule.steps)} steps"
    options = [*what, render.option("cycles", cycles), render.option("takeup", takeup)]
    command = " ".join(["bwsd program braid4", *options, *render.machine_options(machine)])
    body = []
    for i, step in enumerate(rule.steps, start=1):
        body.append(step.text())
        if i % 4 == 0 or i == len(rule.steps):
            body.append(f"TAKEUP {render.num(takeup)}")
    lines = [
        *render.header(title, command, machine),
        *describe(sec, rule, check),
        *render.fill_block(*size, rule.carriers),
        *render.repeat(cycles, body, f"{rule.name}, a take-up every four steps"),
    ]
    return Generated("braid4", title, command, machine, "\n".join(lines) + "\n")


ZONE_MARK = {"all": "#", "web": "W"}  # others: J for a junction, F for a flange or wing


def layout(sec: Section, rule: Rule) -> list[str]:
    """The matrix at the start: section cells by zone, e edge carrier, o empty track cell."""
    rows, cols = sec.size
    edges = set(rule.carriers) - sec.cells
    out = []
    for r in range(rows):
        line = ""
        for c in range(cols):
            zone = sec.zone_of((r, c))
            if zone is not None:
                line += ZONE_MARK.get(zone, "J" if "junction" in zone else "F")
            else:
                line += "e" if (r, c) in edges else "o" if (r, c) in rule.track else "."
        out.append(line)
    return out


def describe(sec: Section, rule: Rule, check: RuleCheck) -> list[str]:
    """Comment lines: the section, its carrier layout and what the rule's check found."""
    lines = [f"# section: {sec.spec}"]
    if sec.shape == "rect":
        return lines
    lines += [
        f"# zones: {', '.join(sec.zones)}; every carrier must visit {', '.join(sec.required)}",
        "# carriers at the start (F flange, J junction, W web, e edge carrier, o track):",
        *(f"#   {line}" for line in layout(sec, rule)),
        f"# rule: {rule.name}; checked on the cell grid: legal, occupancy back after every"
        f" cycle, every carrier in every zone by cycle {check.k} (period {check.period})",
    ]
    if rule.segments:
        lines.append("# needs the segments " + ", ".join(seg.text() for seg in rule.segments))
    return lines


def _size(block: Block) -> str:
    return f"{block[0]}x{block[1]}"
