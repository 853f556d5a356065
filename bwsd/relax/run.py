"""The relaxation driver: separate, add crimp nodes, tighten (docs/relax.md)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from bwsd.relax import _step
from bwsd.relax.solver import CAP, REACH, Layout, Pairs, energy, list_pairs, measure
from bwsd.relax.state import Chains
from bwsd.twin.skeleton import FloatArray

PASSES = 4  # Gauss-Seidel sweeps over the pairs in a step
SKIN = 0.5  # pairs are pushed apart to d and this share of the overlap tolerance
RELIST = 0.5  # the pairs are listed again when a node has used this share of the reach
TOUCHING = 1.05  # a segment touches another yarn within this share of one diameter
Progress = Callable[[str, int, int], None]
Trace = Callable[[FloatArray, FloatArray, Chains], None]


@dataclass(frozen=True)
class Options:
    """What the solver aims at, and how long it may try (docs/relax.md, "Stopping rule")."""

    warp_tension: float = 1.0
    weft_tension: float = 1.0
    overlap: float = 0.005  # worst overlap kept under this share of d
    max_separate: int = 400  # steps of phase 1
    max_steps: int = 600  # steps of phase 2
    crimp_every: int = 50  # tighten steps between two rounds of crimp nodes
    spacing: float = 0.5  # crimp nodes no closer than this share of d to another node
    stall: float = 1e-9  # phase 2 ends when a step lowers the energy by less than this share


@dataclass
class Figures:
    """What the solver did, for the relaxed skeleton's ``relaxed`` block."""

    separate_steps: int = 0
    steps: int = 0
    rejected: int = 0
    added_nodes: int = 0
    energy_twin: float = 0.0
    energy_separated: float = 0.0
    energy: float = 0.0
    worst_overlap: float = 0.0
    seconds: float = 0.0
    energies: list[float] = field(default_factory=list)  # after each tightening step


class Solver:
    """One relaxation run over ``chains`` of yarn diameter ``d``."""

    def __init__(
        self, chains: Chains, d: float, options: Options, trace: Trace | None = None
    ) -> None:
        self.chains, self.d, self.options, self.trace = chains, d, options, trace
        self.next_id = int(chains.ids.max()) + 1
        self.figures = Figures()
        self.alpha = 1.0
        self._relayout()

    def _relayout(self) -> None:
        self.lay = Layout.of(self.chains)
        self._relist()

    def _relist(self) -> None:
        self.pairs = list_pairs(self.chains.pos, self.lay, self.d)
        self.room = np.full(len(self.chains.pos), CAP * self.d * (1 + REACH))

    def kernel(self, most: int, pull: bool, passes: int) -> tuple[int, float, float, int]:
        """Up to ``most`` compiled steps from the current positions (relisting the pairs
        when their reach is used up): steps kept, energy, worst overlap and the kernel's
        status (0 stalled or separated, 1 out of steps, 3 no step kept)."""
        taken, energy, worst, status = 0, 0.0, 0.0, 1
        while taken < most:
            count = 1 if self.trace is not None else most - taken
            pos = np.ascontiguousarray(self.chains.pos).copy()
            old = self.chains.pos
            energies = np.zeros(count)
            steps, rejected, energy, worst, status, self.alpha = _step.steps(
                pos,
                self.lay.a,
                self.lay.b,
                self.lay.tension,
                self.lay.free,
                self.pairs.i,
                self.pairs.j,
                self.room,
                energies,
                self.d,
                self.d + SKIN * self.limit,
                self.limit,
                self.options.stall,
                RELIST * CAP * self.d * (1 + REACH),
                passes,
                pull,
                self.alpha,
            )
            self.figures.rejected += rejected
            if pull:  # the separation may raise it; the tightening never does
                self.figures.energies.extend(energies[:steps].tolist())
            if steps and self.trace is not None:
                self.trace(old, pos, self.chains)
            self.chains = self.chains.with_pos(pos)
            taken += steps
            if status == 2:
                self._relist()
            elif status != 1 or self.trace is None:
                break
        return taken, energy, worst, status

    @property
    def limit(self) -> float:
        """The worst overlap a step may leave: the tolerance, in mm."""
        return self.options.overlap * self.d

    def separate(self, progress: Progress | None) -> None:
        """Phase 1: push overlapping pairs apart until the worst overlap is in tolerance."""
        taken, _, _, _ = self.kernel(self.options.max_separate, False, PASSES)
        self.figures.separate_steps = taken
        if progress is not None:
            progress("separating", taken, self.options.max_separate)

    def tighten(self, progress: Progress | None) -> None:
        """Phase 2: steps that never raise the tension-weighted length, with a round of
        crimp nodes every ``crimp_every`` steps while nodes are added."""
        opts, done = self.options, 0
        while done < opts.max_steps:
            chunk = min(opts.crimp_every, opts.max_steps - done)
            taken, _, _, status = self.kernel(chunk, True, PASSES)
            done += taken
            self.figures.steps = done
            if progress is not None:
                progress("tightening", done, opts.max_steps)
            added = self.add_crimp() if self.d > 0 else 0
            if status in (0, 3) and added == 0:
                break

    def add_crimp(self) -> int:
        """A node at the closest point of each segment that touches another yarn inside it,
        far enough from its ends (``Options.spacing``): where the yarn will bend round.
        Returns how many were added."""
        pairs = measure(self.chains.pos, self.lay, self.pairs)
        spacing = self.options.spacing * self.d
        touching = pairs.dist < self.d * TOUCHING
        seg_len = np.linalg.norm(self.chains.pos[self.lay.b] - self.chains.pos[self.lay.a], axis=1)
        seg = np.concatenate([pairs.i[touching], pairs.j[touching]])
        par = np.concatenate([pairs.s[touching], pairs.t[touching]])
        room = np.minimum(par, 1 - par) * seg_len[seg]
        keep = room > spacing
        seg, first = np.unique(seg[keep], return_index=True)
        if len(seg) == 0:
            return 0
        par = par[keep][first]
        a, b = self.lay.a[seg], self.lay.b[seg]
        pos = self.chains.pos
        points = pos[a] + par[:, None] * (pos[b] - pos[a])
        self.chains = self.chains.insert(a, points, self.next_id)
        self.next_id += len(seg)
        self.figures.added_nodes += len(seg)
        self._relayout()
        return len(seg)


def solve(
    chains: Chains,
    d: float,
    options: Options,
    progress: Progress | None = None,
    trace: Trace | None = None,
) -> tuple[Chains, Figures]:
    """Relax ``chains`` of yarn diameter ``d``: the new chains and the solver's figures."""
    start = time.perf_counter()
    solver = Solver(chains, d, options, trace)
    solver.figures.energy_twin = energy(chains.pos, solver.lay)
    if d > 0:
        solver.separate(progress)
    solver.figures.energy_separated = energy(solver.chains.pos, solver.lay)
    if d > 0:
        solver.add_crimp()
    solver.tighten(progress)
    solver.figures.energy = energy(solver.chains.pos, solver.lay)
    solver._relist()
    solver.figures.worst_overlap = worst_overlap(solver.chains.pos, solver.lay, solver.pairs, d)
    solver.figures.seconds = time.perf_counter() - start
    return solver.chains, solver.figures


def worst_overlap(pos: FloatArray, lay: Layout, pairs: Pairs, d: float) -> float:
    """The deepest overlap of the listed pairs, in mm (0 when none is closer than d)."""
    found = measure(pos, lay, pairs)
    return float(np.maximum(d - found.dist, 0.0).max(initial=0.0))
