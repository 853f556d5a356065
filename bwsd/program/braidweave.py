"""Braiding with wefts: a 4-step braid (rectangle or L, T, I) with a layer of wefts every N
cycles, at any angle (0, 90, +-45 by default), each layer in one plane, each weft through
an open shed and held by at least two contacts.

The shed comes from the braid's own steps (docs/program.md, "braid-weave"): a step moves
every other line one way and its neighbours the other, so right after it the yarns of two
neighbouring lines run apart from where they were pinned last. A weft along x (0 degrees)
or a diagonal one (+-45) goes in after a ROW step, between two neighbouring rows or
diagonals of the section, and the COL step that follows sweeps the columns across it and
closes the shed; a weft along y (90 degrees) goes in after a COL step and the next ROW step
closes it. Another angle a has lines of its own: the cells whose distance across the
direction a, counted in steps of max(|cos a|, |sin a|) cells, rounds to one number (a row
for 0, a diagonal for 45); it opens after a ROW step when it lies within 45 degrees of x,
else after a COL step. Each weft lies on the line halfway between its two lines of warps;
the layer goes in at the lowest height where every weft is let in by the twin's exact shed
check and held by at least two contacts of the moves that follow (``layers.place_layer``).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable, Sequence

from bwsd.program import render
from bwsd.program.braid import Block, braid_rule, describe, section
from bwsd.program.layers import place_layer
from bwsd.program.render import Generated
from bwsd.program.sections import WEFT_ANGLES, Cell, Section
from bwsd.program.wefts import Item, Shed, woven
from bwsd.twin.instructions import Shift, TakeUp
from bwsd.twin.machine import Machine

ANGLES = WEFT_ANGLES
# A line family: the key of a cell's line and its place along the line.
FAMILY: dict[int, tuple[Callable[[Cell], int], Callable[[Cell], int]]] = {
    0: (lambda c: c[0], lambda c: c[1]),  # rows, along x
    90: (lambda c: c[1], lambda c: c[0]),  # columns, along y
    45: (lambda c: c[1] - c[0], lambda c: c[0] + c[1]),  # diagonals, along (1, 1)
    -45: (lambda c: c[1] + c[0], lambda c: c[1] - c[0]),  # anti-diagonals, along (1, -1)
}


def family(angle: float) -> tuple[Callable[[Cell], int], Callable[[Cell], float]]:
    """The lines of weft angle ``angle``: a cell's line and its place along the line."""
    if angle in FAMILY:
        return FAMILY[int(angle)]
    a = math.radians(angle)
    cos, sin = math.cos(a), math.sin(a)
    step = max(abs(cos), abs(sin))  # one row (column) across a line, as for 0, 90 and 45
    return (lambda c: round((c[0] * cos - c[1] * sin) / step), lambda c: c[1] * cos + c[0] * sin)


def opening(angle: float) -> str:
    """The step that opens the shed of ``angle``: ROW within 45 degrees of x, else COL."""
    folded = abs((angle + 90) % 180 - 90)  # 0 .. 90 degrees from x
    return "row" if folded <= 45 else "col"


def sheds(sec: Section, angle: float) -> list[Shed]:
    """One weft per pair of neighbouring lines of the family ``angle`` and per run of the
    section's cells along them: between the cells of one line and those of the next."""
    key, along = family(angle)
    lines: dict[int, list[Cell]] = defaultdict(list)
    for cell in sec.cells:
        lines[key(cell)].append(cell)
    out = []
    for m in sorted(lines):
        if m + 1 not in lines:
            continue
        pair = sorted(lines[m] + lines[m + 1], key=along)
        run: list[Cell] = []
        for cell in pair:
            if run and along(cell) - along(run[-1]) > 1 + 1e-9:
                out += _shed(angle, m, run, key)
                run = []
            run.append(cell)
        out += _shed(angle, m, run, key)
    return out


def _shed(angle: float, m: int, run: list[Cell], key: Callable[[Cell], int]) -> list[Shed]:
    one = tuple(c for c in run if key(c) == m)
    other = tuple(c for c in run if key(c) == m + 1)
    if len(one) < 2 or len(other) < 2:
        return []  # a corner of the section: one yarn a side holds no weft
    return [
        Shed(
            angle,
            one,
            other,
            f"{render.num(angle)} degree weft between lines {m} and "
            f"{m + 1} (cells {run[0]} to {run[-1]})",
        )
    ]


def _cycle(
    steps: Sequence[Shift], takeup: float, wefts: list[Shed], weft_every: int, opening: str
) -> list[Item]:
    """``weft_every`` cycles of the rule, the wefts after its first ``opening`` step."""
    first = next(i for i, s in enumerate(steps) if s.axis == opening)
    body: list[Item] = []
    for n in range(weft_every):
        for i, step in enumerate(steps, start=1):
            body.append(step)
            if n == 0 and i - 1 == first:
                body += wefts
            if i % 4 == 0 or i == len(steps):
                body.append(TakeUp(takeup))
    return body


def braid_weave(
    rows: int = 3,
    cols: int = 3,
    cycles: int = 8,
    *,
    shape: str = "rect",
    flange: Block = (2, 6),
    web: Block = (4, 2),
    segments: bool = True,
    weft_every: int = 2,
    angles: Sequence[float] = ANGLES,
    takeup: float = 3.0,
    pitch: float = 10.0,
    d_mat: float = 150.0,
    c_mat: float = 0.4,
    diameter: float = 0.5,
) -> Generated:
    """A 4-step braid of ``cycles`` cycles with a layer of wefts every ``weft_every`` cycles,
    the layers' angles taken from ``angles`` in turn."""
    if cycles < 1 or weft_every < 1:
        raise ValueError("cycles and weft-every must be at least 1")
    if cycles % weft_every:
        raise ValueError(f"cycles ({cycles}) must be a multiple of weft-every ({weft_every})")
    if not angles or not all(math.isfinite(a) for a in angles):
        raise ValueError("give at least one weft angle, each a finite number of degrees")
    if takeup <= 0:
        raise ValueError("take-up must be positive")
    sec = section(shape, rows, cols, flange, web)
    rule, check = braid_rule(sec, segments)
    machine = Machine(*sec.size, pitch, pitch, d_mat, c_mat, diameter, segments=rule.segments)
    layers = cycles // weft_every
    plan = [angles[k % len(angles)] for k in range(layers)]
    bodies: list[list[list[Item]]] = []
    for angle in plan:
        wefts = sheds(sec, angle)
        if not wefts:
            raise ValueError(
                f"{sec.spec} has no two neighbouring lines for {render.num(angle)} degree wefts"
            )
        order = ("row", "col") if opening(angle) == "row" else ("col", "row")
        bodies.append([_cycle(rule.steps, takeup, wefts, weft_every, step) for step in order])
    comment = f"{weft_every} cycles of {rule.name}, a layer of wefts"
    title, command = _names(
        sec, rule.carriers, cycles, weft_every, angles, takeup, segments, machine
    )
    lines = [
        *render.header(title, command, machine),
        *describe(sec, rule, check),
        f"# a layer of wefts every {weft_every} cycles, at "
        f"{', '.join(map(render.num, plan))} degrees",
        *render.fill_block(*sec.size, rule.carriers),
        *woven(machine, tuple(sorted(rule.carriers)), bodies, comment, place_layer, "layer"),
    ]
    return Generated("braid-weave", title, command, machine, "\n".join(lines) + "\n")


def _names(
    sec: Section,
    carriers: Sequence[Cell],
    cycles: int,
    weft_every: int,
    angles: Sequence[float],
    takeup: float,
    segments: bool,
    machine: Machine,
) -> tuple[str, str]:
    if sec.shape == "rect":
        rows, cols = sec.size[0] - 2, sec.size[1] - 2
        what = [render.option("rows", rows), render.option("cols", cols)]
        title = f"Braid-weave, {rows} x {cols} body"
    else:
        _, flange, web = sec.spec.split(":")
        what = [
            render.option("shape", sec.shape),
            render.option("flange", flange),
            render.option("web", web),
        ]
        what += [] if segments else ["--no-segments"]
        title = f"Braid-weave, {sec.shape} section, flange {flange}, web {web}"
    title += f", {len(carriers)} carriers, {cycles} cycles, wefts every {weft_every}"
    options = [
        *what,
        render.option("cycles", cycles),
        render.option("weft-every", weft_every),
        "--angles=" + ",".join(map(render.num, angles)),
        render.option("takeup", takeup),
        *render.machine_options(machine),
    ]
    return title, " ".join(["bwsd program braid-weave", *options])


__all__ = ["ANGLES", "braid_weave", "sheds"]
