"""A layer of wefts at one height, each held by at least two contacts (braid-weave).

A weaver lays one layer of wefts in one plane, and a weft held at one point, or at none, is
loose. ``place_layer`` tries the heights of ``wefts.heights`` from the lowest where a warp
of the layer's sheds can catch them: at each, every weft of the layer goes in (the twin's
exact shed check must let it in, on the warps' cone or else through the middle of its
shed), then the moves that close the sheds run; the first height where no move jams and
each weft has at least ``HELD`` contacts is taken. Where none is, the layer is refused,
naming the weft held least at its best height.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from bwsd.errors import JamError
from bwsd.program import render
from bwsd.program.wefts import Pick, Placer, Shed
from bwsd.twin.instructions import Instruction, Weft

HELD = 2  # contacts a weft needs, at least


@dataclass(frozen=True)
class Try:
    """One height tried: the wefts put in, and per weft its contacts; None when the shed of
    weft ``closed`` was closed, or a move jammed."""

    z: float
    wefts: tuple[Weft, ...]
    held: tuple[int, ...] | None
    closed: int | None = None


def place_layer(placer: Placer, pick: Pick, closing: Sequence[Instruction]) -> list[str]:
    """The WEFT lines of one layer, all at the lowest height where each is held by at least
    ``HELD`` contacts of ``closing``; ValueError naming the weft held least where none is."""
    sheds = [shed for _, shed in pick]
    start = placer.twin.snapshot()
    lowest = min(placer.lowest_fixed(shed) for shed in sheds)
    best: tuple[int, Try, Shed] | None = None
    closed: list[int] = []
    for z in placer.heights:
        if z < lowest:
            continue
        tried = _try(placer, sheds, closing, z)
        placer.twin.restore(start)
        if tried.held is None:
            closed += [] if tried.closed is None else [tried.closed]
            continue
        least = min(range(len(sheds)), key=tried.held.__getitem__)
        if tried.held[least] >= HELD:
            for weft in tried.wefts:
                placer.insert(weft)
            return [render.weft(w.x, w.y, w.z, w.angle, w.length) for w in tried.wefts]
        if best is None or tried.held[least] > best[0]:
            best = (tried.held[least], tried, sheds[least])
    raise ValueError(_refusal(sheds, best, closed))


def _try(placer: Placer, sheds: list[Shed], closing: Sequence[Instruction], z: float) -> Try:
    """Put every weft of the layer in at height ``z`` and run the closing moves."""
    wefts, yarns = [], []
    for shed in sheds:
        for weft in placer.candidates(shed, z):
            yarn = placer.insert(weft)
            if yarn is not None:
                wefts.append(weft)
                yarns.append(yarn)
                break
        else:
            return Try(z, tuple(wefts), None, sheds.index(shed))
    held = dict.fromkeys(yarns, 0)
    for move in closing:
        try:
            table = placer.twin.apply(move).contact_table
        except JamError:
            return Try(z, tuple(wefts), None)
        for yarn in (*table[:, 1].tolist(), *table[:, 3].tolist()):
            if yarn in held:
                held[yarn] += 1
    return Try(z, tuple(wefts), tuple(held[y] for y in yarns))


def _refusal(sheds: list[Shed], best: tuple[int, Try, Shed] | None, closed: list[int]) -> str:
    angle = render.num(sheds[0].angle)
    if best is None and closed:
        worst = max(set(closed), key=closed.count)
        return (
            f"{sheds[worst].name}: no height below the guides lets the whole {angle} "
            f"degree layer in: this weft's shed is closed (a yarn lies closer than one "
            f"diameter to its line) at {closed.count(worst)} of the heights tried, and "
            "the layer jams at the others (leave out this angle, or raise the pitch)"
        )
    if best is None:
        return (
            f"{sheds[0].name}: no height below the guides lets the {angle} degree layer "
            "in without a jam (raise the take-up or the pitch)"
        )
    held, tried, shed = best
    return (
        f"{shed.name}: no height below the guides holds every weft of the {angle} degree "
        f"layer by at least {HELD} contacts: at best (z = {render.num(tried.z)} mm above "
        f"the fell) this one has {held} (raise the take-up or the pitch, or leave out "
        "this angle)"
    )
