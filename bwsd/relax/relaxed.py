"""The relaxed preform: the twin's skeleton under yarn tension, tight, without
interpenetration, its topology kept (docs/relax.md). ``bwsd.relax`` gives these names,
importing this module on first use."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from bwsd.relax.residual import residuals
from bwsd.relax.run import Figures, Options, Progress, Trace, solve
from bwsd.relax.sections import Sections, sections
from bwsd.relax.solver import Layout, list_pairs
from bwsd.relax.state import Chains
from bwsd.relax.topology import contact_sides
from bwsd.twin.skeleton import FloatArray, SkeletonData

__all__ = ["Options", "Relaxed", "crimp", "relax"]

APART = 2.0  # a contact whose yarns end farther apart (in d) has been undone: its side is not told


@dataclass(frozen=True)
class Relaxed:
    """A relaxed skeleton, each node's section (per yarn: (n, 5) of width, height and the
    up vector) and what the solver did."""

    skeleton: SkeletonData
    sections: tuple[FloatArray, ...]
    figures: Figures
    residual: float  # the largest force residual at a free node, over its yarn's tension
    sides_kept: int
    sides_told: int

    def summary(self) -> dict[str, Any]:
        """The solver's figures as JSON-ready builtins (the document's ``relaxed`` block)."""
        f = self.figures
        return {
            "separate_steps": f.separate_steps,
            "steps": f.steps,
            "rejected_steps": f.rejected,
            "added_nodes": f.added_nodes,
            "tension_length": {
                "twin": f.energy_twin,
                "separated": f.energy_separated,
                "relaxed": f.energy,
            },
            "worst_overlap": f.worst_overlap,
            "worst_overlap_share": f.worst_overlap / self.skeleton.diameter
            if self.skeleton.diameter > 0
            else 0.0,
            "force_residual": self.residual,
            "sides": {"kept": self.sides_kept, "told": self.sides_told},
            "seconds": f.seconds,
        }


def relax(
    sk: SkeletonData,
    options: Options | None = None,
    progress: Progress | None = None,
    trace: Trace | None = None,
) -> Relaxed:
    """Relax ``sk`` (docs/relax.md). ``trace`` sees every step's motion (old and new
    positions, and the chains); ``progress`` each step's phase and number."""
    opts = options or Options()
    if not sk.yarns:  # nothing to relax (a program whose fill holds no case)
        return Relaxed(sk, (), Figures(), 0.0, 0, 0)
    chains = Chains.of(sk, opts.warp_tension, opts.weft_tension)
    out, figures = solve(chains, sk.diameter, opts, progress, trace)
    relaxed = out.skeleton(sk)
    lay = Layout.of(out)
    pairs = list_pairs(out.pos, lay, sk.diameter)
    found = sections(out, lay, pairs, sk.diameter)
    residual = residuals(out, lay, pairs, sk.diameter)
    free = out.free.any(axis=1)
    before, _, _ = contact_sides(sk)
    after, _, apart = contact_sides(relaxed)
    told = (before != 0) & (after != 0) & (apart < APART * sk.diameter)
    return Relaxed(
        relaxed,
        _per_yarn(out, found),
        figures,
        float(residual[free].max()) if free.any() else 0.0,
        int((before[told] == after[told]).sum()),
        int(told.sum()),
    )


def _per_yarn(chains: Chains, found: Sections) -> tuple[FloatArray, ...]:
    table = np.column_stack([found.width, found.height, found.up])
    bounds = np.searchsorted(chains.yarn, np.arange(int(chains.yarn.max()) + 2))
    return tuple(table[a:b] for a, b in itertools.pairwise(bounds))


def crimp(sk: SkeletonData) -> dict[str, Any]:
    """Weft crimp: (yarn length - end-to-end distance) / end-to-end distance, per weft (in
    yarn order) and on average; ``mean`` None without wefts."""
    values = []
    for yarn in sk.yarns:
        if yarn.kind != "weft":
            continue
        nodes = np.asarray(yarn.nodes)
        length = float(np.linalg.norm(np.diff(nodes, axis=0), axis=1).sum())
        span = float(np.linalg.norm(nodes[-1] - nodes[0]))
        values.append((length - span) / span if span > 0 else 0.0)
    return {
        "per_weft": values,
        "mean": float(np.mean(values)) if values else None,
        "max": max(values) if values else None,
    }
