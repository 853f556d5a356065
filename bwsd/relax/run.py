"""The relaxation driver: separate, add crimp nodes, tighten (docs/relax.md)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from bwsd.relax import _step
from bwsd.relax.solver import CAP, REACH, Layout, energy, list_pairs, measure
from bwsd.relax.state import Chains
from bwsd.twin.skeleton import FloatArray

PASSES = 3  # separation passes after each tightening move
MIN_ALPHA = 1e-6  # the smallest step size tried before phase 2 ends
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
    energies: list[float] = field(default_factory=list)


class Solver:
    """One relaxation run over ``chains`` of yarn diameter ``d``."""

    def __init__(
        self, chains: Chains, d: float, options: Options, trace: Trace | None = None
    ) -> None:
        self.chains, self.d, self.options, self.trace = chains, d, options, trace
        self.next_id = int(chains.ids.max()) + 1
        self.figures = Figures()
        self._relayout()

    def _relayout(self) -> None:
        self.lay = Layout.of(self.chains)
        self._relist()

    def _relist(self) -> None:
        self.pairs = list_pairs(self.chains.pos, self.lay, self.d)
        self.room = np.full(len(self.chains.pos), CAP * self.d * (1 + REACH))

    def kernel(self, alpha: float, passes: int) -> tuple[FloatArray, float, float]:
        """One compiled step from the current positions: new positions, their tension-weighted
        length and worst overlap (``alpha`` 0 and no passes: the current ones)."""
        pos = np.ascontiguousarray(self.chains.pos)
        out = np.empty_like(pos)
        energy, worst = _step.step(
            pos,
            out,
            self.lay.a,
            self.lay.b,
            self.lay.tension,
            self.lay.free,
            self.pairs.i,
            self.pairs.j,
            self.room,
            self.d,
            alpha,
            passes,
        )
        return out, energy, worst

    def move(self, new: FloatArray) -> None:
        """Take ``new`` positions (a step within every node's cap) and relist when needed."""
        old = self.chains.pos
        if self.trace is not None:
            self.trace(old, new, self.chains)
        self.room = self.room - np.sqrt(np.einsum("ij,ij->i", new - old, new - old))
        self.chains = self.chains.with_pos(new)
        if self.room.min() < 0.5 * CAP * self.d * (1 + REACH):
            self._relist()

    def separate(self, progress: Progress | None) -> None:
        """Phase 1: push overlapping pairs apart until the worst overlap is in tolerance."""
        tol = self.options.overlap * self.d
        worst = self.kernel(0.0, 0)[2]
        for k in range(self.options.max_separate):
            if worst <= tol:
                break
            new, _, worst = self.kernel(0.0, 1)
            self.move(new)
            self.figures.separate_steps = k + 1
            if progress is not None:
                progress("separating", k + 1, self.options.max_separate)

    def tighten(self, progress: Progress | None) -> None:
        """Phase 2: steps that never raise the tension-weighted length."""
        opts, alpha = self.options, 1.0
        _, e, worst = self.kernel(0.0, 0)
        self.figures.energies.append(e)
        for k in range(opts.max_steps):
            if k and k % opts.crimp_every == 0:
                self.add_crimp()
            limit = max(opts.overlap * self.d, worst)
            trial, e_new, w_new = self.kernel(alpha, PASSES)
            while (e_new > e or w_new > limit) and alpha > MIN_ALPHA:
                alpha /= 2
                self.figures.rejected += 1
                trial, e_new, w_new = self.kernel(alpha, PASSES)
            if e_new > e or w_new > limit:
                break
            self.move(trial)
            self.figures.steps = k + 1
            self.figures.energies.append(e_new)
            done = e - e_new <= opts.stall * e
            e, worst, alpha = e_new, w_new, min(1.0, 2 * alpha)
            if progress is not None:
                progress("tightening", k + 1, opts.max_steps)
            if done:
                break

    def add_crimp(self) -> None:
        """A node at the closest point of each segment that touches another yarn inside it,
        far enough from its ends (``Options.spacing``): where the yarn will bend round."""
        pairs = measure(self.chains.pos, self.lay, self.pairs)
        spacing = self.options.spacing * self.d
        touching = pairs.dist < self.d * (1 + 0.05)
        seg_len = np.linalg.norm(self.chains.pos[self.lay.b] - self.chains.pos[self.lay.a], axis=1)
        seg = np.concatenate([pairs.i[touching], pairs.j[touching]])
        par = np.concatenate([pairs.s[touching], pairs.t[touching]])
        length = seg_len[seg]
        room = np.minimum(par, 1 - par) * length
        keep = room > spacing
        seg, par = seg[keep], par[keep]
        seg, first = np.unique(seg, return_index=True)
        if len(seg) == 0:
            return
        par = par[first]
        a, b = self.lay.a[seg], self.lay.b[seg]
        pos = self.chains.pos
        points = pos[a] + par[:, None] * (pos[b] - pos[a])
        self.chains = self.chains.insert(a, points, self.next_id)
        self.next_id += len(seg)
        self.figures.added_nodes += len(seg)
        self._relayout()


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
    solver.add_crimp() if d > 0 else None
    solver.tighten(progress)
    solver.figures.energy = energy(solver.chains.pos, solver.lay)
    solver._relist()
    solver.figures.worst_overlap = solver.kernel(0.0, 0)[2]
    solver.figures.seconds = time.perf_counter() - start
    return solver.chains, solver.figures
