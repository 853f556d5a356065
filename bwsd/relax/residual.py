"""The force residual of a relaxed preform: what no contact force balances (scipy).

At every free node the yarn pulls with T (u_prev + u_next). Contacts push: each pair of
segments within ``TOUCH`` of one diameter pushes its two closest points apart along their
direction with a force f >= 0, shared by the four ends with the closest points' weights.
The contact forces are those (all >= 0) that balance the pulls best in least squares
(``scipy.optimize.lsq_linear``); the residual of a node is the length of the force left on
its free components, over its yarn's tension.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear
from scipy.sparse import coo_matrix

from bwsd.relax.sections import TOUCH
from bwsd.relax.solver import Layout, Pairs, forces
from bwsd.relax.state import Chains
from bwsd.twin.skeleton import FloatArray, IntArray

MAX_ITER = 10  # iterations of the bounded least squares (each of at most LSMR_ITER inner ones);
LSMR_ITER = 200  # any forces >= 0 where it stops give an upper bound of the residual


def residuals(chains: Chains, lay: Layout, pairs: Pairs, d: float) -> FloatArray:
    """Per node: the unbalanced force over its yarn's tension (0 on fixed components)."""
    count = len(chains.pos)
    pull = forces(chains.pos, lay, count).reshape(-1)
    near = np.flatnonzero(pairs.dist < TOUCH * d) if d > 0 else np.zeros(0, np.int64)
    if len(near):
        push = _contact_matrix(pairs, lay, near, count)
        found = lsq_linear(
            push,
            -pull,
            bounds=(0.0, np.inf),
            method="trf",
            lsmr_tol="auto",
            tol=1e-12,
            max_iter=MAX_ITER,
            lsmr_maxiter=LSMR_ITER,
        )
        pull = pull + push @ found.x
    left = np.linalg.norm(pull.reshape(-1, 3), axis=1)
    out: FloatArray = left / chains.tension[chains.yarn]
    return out


def _contact_matrix(pairs: Pairs, lay: Layout, near: IntArray, count: int) -> coo_matrix:
    """Columns: the force of a unit push of each pair on the nodes' free components."""
    s, t, n = pairs.s[near], pairs.t[near], pairs.normal[near]
    ends = (lay.a[pairs.i[near]], lay.b[pairs.i[near]], lay.a[pairs.j[near]], lay.b[pairs.j[near]])
    weights = (1 - s, s, -(1 - t), -t)
    rows, cols, vals = [], [], []
    column = np.arange(len(near))
    for node, w in zip(ends, weights, strict=True):
        for k in range(3):
            rows.append(3 * node + k)
            cols.append(column)
            vals.append(w * n[:, k] * lay.free[node, k])
    return coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(3 * count, len(near)),
    ).tocsr()
