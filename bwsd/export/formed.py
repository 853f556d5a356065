"""The formed zone of a preform, and the yarn angles there (docs/exports.md, "formed").

The twin lays the structure a few take-ups below the guides and climbs there from the fell
in the first cycles. The **formed zone** is the slab of the preform that the run has
finished: below the cycle still forming, above the cycles that were still climbing. It is
found from the depth below the guides at which each cycle made its contacts:

1. the depth of cycle k is the guides' height at its end minus the median height of the
   nodes its contacts made;
2. the steady depth is the median of the depths of the last half of the complete cycles;
   the run has settled when each of those lies within 25 % of it and they no longer
   trend: the mean of the later ones differs from that of the earlier ones (the last half
   split in two, its middle cycle left out) by at most 15 % of it;
3. the first formed cycle is the one after the last cycle deeper than 1.25 times the
   steady depth; the last complete cycle is the one still forming;
4. the slab runs from the lowest node the first formed cycle made to the lowest node made
   by the cycle still forming (or after it).

The yarn measured there lies between two contact nodes (no warp's run from its start at the
fell, no weft end beyond its last contact), cut to the slab.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bwsd.export.arrays import Arrays
from bwsd.twin.instructions import Program, TakeUp
from bwsd.twin.skeleton import FloatArray

MIN_CYCLES = 4  # to see the depth settle: a steady last half, a formed cycle, one forming
SETTLED = 0.25  # a cycle's depth within this share of the steady depth has settled
TREND = 0.15  # ... and the last half's depths drift by at most this share of it


@dataclass(frozen=True)
class Zone:
    """The formed zone: its slab and cycles, or why there is none."""

    z: tuple[float, float] | None
    cycles: tuple[int, int] | None  # first and last formed cycle
    complete: int  # complete cycles in the run
    depths: tuple[float | None, ...]  # per complete cycle, mm below the guides
    reason: str | None = None  # why there is no formed zone
    needs: int | None = None  # complete cycles a formed zone would need, at least

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready builtins."""
        return {
            "found": self.z is not None,
            "z": None if self.z is None else list(self.z),
            "cycles": None if self.cycles is None else list(self.cycles),
            "complete_cycles": self.complete,
            "depths": list(self.depths),
            "reason": self.reason,
            "needs_cycles": self.needs,
        }


def takeups_of(program: Program) -> list[float]:
    """Each instruction's take-up: its length for a TAKEUP, 0 for the others."""
    return [i.length if isinstance(i, TakeUp) else 0.0 for i in program.instructions]


def guide_heights(d_mat: float, takeups: Sequence[float]) -> FloatArray:
    """The guides' height after each instruction (index 0: before the first), given each
    instruction's take-up (0 for all but TAKEUP)."""
    out: FloatArray = d_mat + np.concatenate([[0.0], np.cumsum(np.asarray(takeups, float))])
    return out


def find_zone(arrays: Arrays, length: int, guides: FloatArray | None) -> Zone:
    """The formed zone of a run of cycles of ``length`` instructions (``guides``: the guides'
    heights after each instruction, None when unknown)."""
    run = arrays.sk.instructions
    complete = run // length if length > 0 else 0
    if guides is None:
        return Zone(None, None, complete, (), "the guides' heights are not known")
    if complete < MIN_CYCLES:
        return Zone(
            None,
            None,
            complete,
            (),
            f"too short: {complete} complete cycles of "
            f"{length} instructions, a formed zone needs at least {MIN_CYCLES}",
            MIN_CYCLES,
        )
    depths = _depths(arrays, length, complete, guides)
    last = depths[complete // 2 :]
    steady = float(np.median(last)) if np.isfinite(last).all() else math.nan
    shown = tuple(None if math.isnan(v) else round(float(v), 6) for v in depths)
    if not _settled(last, steady):
        return Zone(None, None, complete, shown, _unsettled(last, complete), 2 * complete)
    deep = np.flatnonzero(~(depths <= (1 + SETTLED) * steady))
    first = int(deep.max()) + 2 if len(deep) else 1
    cycle = (arrays.made - 1) // length + 1
    made = arrays.made > 0
    low = float(arrays.pos[made & (cycle == first), 2].min())
    high = float(arrays.pos[made & (cycle >= complete), 2].min())
    if high <= low:
        return Zone(
            None,
            None,
            complete,
            shown,
            f"the cycle still forming reaches below the first formed cycle (cycle {first})",
            complete + 1,
        )
    return Zone((low, high), (first, complete - 1), complete, shown)


def _settled(last: FloatArray, steady: float) -> bool:
    """Whether the depths ``last`` (the last half of the cycles) are steady about ``steady``."""
    if not steady > 0 or not np.all(np.abs(last - steady) <= SETTLED * steady):
        return False
    half = len(last) // 2
    drift = float(last[:half].mean() - last[len(last) - half :].mean())
    return abs(drift) <= TREND * steady


def _depths(arrays: Arrays, length: int, complete: int, guides: FloatArray) -> FloatArray:
    """Per complete cycle: the guides' height at its end minus the median height of the
    nodes its contacts made (NaN for a cycle without contacts)."""
    nodes = arrays.contact_nodes()
    cycle = (arrays.made[nodes] - 1) // length
    z = arrays.pos[nodes, 2]
    out = np.full(complete, math.nan)
    for k in np.unique(cycle[cycle < complete]).tolist():
        out[k] = guides[(k + 1) * length] - float(np.median(z[cycle == k]))
    return out


def _unsettled(last: FloatArray, complete: int) -> str:
    shown = ", ".join("none" if math.isnan(v) else f"{v:.1f}" for v in last.tolist())
    return (
        f"the contacts have not settled at one depth below the guides within {complete} "
        f"complete cycles (depths of the last half, mm: {shown}); run more cycles, at "
        f"least {2 * complete}"
    )


@dataclass(frozen=True)
class Pieces:
    """The yarn of the formed zone: the part ``s0``..``s1`` (0 to 1) of each fixed segment
    listed in ``segment``."""

    segment: FloatArray
    s0: FloatArray
    s1: FloatArray

    def points(self, arrays: Arrays) -> tuple[FloatArray, FloatArray]:
        """Start and end points of the pieces."""
        seg = self.segment.astype(np.int64)
        p0, d = arrays.seg_p0[seg], arrays.seg_p1[seg] - arrays.seg_p0[seg]
        return p0 + self.s0[:, None] * d, p0 + self.s1[:, None] * d


def pieces(arrays: Arrays, zone: Zone) -> Pieces:
    """The parts of the fixed segments between two contact nodes that lie in the slab."""
    if zone.z is None:
        empty = np.zeros(0)
        return Pieces(empty, empty, empty)
    low, high = zone.z
    between = (arrays.made[arrays.seg_a] > 0) & (arrays.made[arrays.seg_b] > 0)
    za, zb = arrays.seg_p0[:, 2], arrays.seg_p1[:, 2]
    s0, s1 = clip_to_slab(za, zb, low, high)
    keep = between & (s1 > s0)
    return Pieces(np.flatnonzero(keep).astype(float), s0[keep], s1[keep])


def clip_to_slab(
    za: FloatArray, zb: FloatArray, low: float, high: float
) -> tuple[FloatArray, FloatArray]:
    """For segments from height ``za`` to ``zb``, the part (s0, s1) within [low, high]
    (s0 >= s1 when none); a horizontal segment is in or out whole."""
    dz = zb - za
    flat = dz == 0
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (low - za) / dz, (high - za) / dz
    lo = np.where(flat, np.where((za >= low) & (za <= high), 0.0, 1.0), np.minimum(ta, tb))
    hi = np.where(flat, 1.0, np.maximum(ta, tb))
    return np.clip(lo, 0.0, 1.0), np.clip(hi, 0.0, 1.0)
