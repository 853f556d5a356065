"""Each node's yarn section: an ellipse flattened by its neighbours' contact directions.

At a node, the directions from which other yarns touch it (closest-point directions of the
pairs of segments within ``TOUCH`` of one diameter, each weighted by how near the contact
lies to the node along its segment) are projected on the plane normal to the yarn and summed
as a 2 x 2 scatter. Its main axis is where the neighbours press from; the **flattening**
f = (l1 - l2) / (l1 + l2) of its two eigenvalues is 0 when they press all round (or not at
all) and 1 when they press from one line. The section keeps the yarn's area pi d^2 / 4: its
height along the main axis is d (1 - FLAT f), its width d / (1 - FLAT f).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from bwsd.export.texgen import up_vectors
from bwsd.relax.solver import Layout, Pairs
from bwsd.relax.state import Chains
from bwsd.twin.skeleton import FloatArray

TOUCH = 1.02  # a pair touches within this share of one diameter
FLAT = 1 / 3  # the most a section flattens: height 2/3 d, width 3/2 d


@dataclass(frozen=True)
class Sections:
    """Per node (in the chains' layout): width, height (mm), and the unit "up" vector of
    the height axis, normal to the yarn."""

    width: FloatArray
    height: FloatArray
    up: FloatArray


def tangents(chains: Chains) -> FloatArray:
    """Unit tangent of each node's yarn (mean of its segments' directions)."""
    pos, yarn = chains.pos, chains.yarn
    same = yarn[:-1] == yarn[1:]
    seg = np.where(same[:, None], pos[1:] - pos[:-1], 0.0)
    norm = np.linalg.norm(seg, axis=1, keepdims=True)
    unit = np.divide(seg, norm, out=np.zeros_like(seg), where=norm > 0)
    out = np.zeros_like(pos)
    out[:-1] += unit
    out[1:] += unit
    size = np.linalg.norm(out, axis=1, keepdims=True)
    result: FloatArray = np.divide(out, size, out=np.zeros_like(out), where=size > 0)
    return result


def scatter(chains: Chains, lay: Layout, pairs: Pairs, d: float) -> FloatArray:
    """Per node, the weighted scatter (3 x 3) of its contact directions normal to its yarn."""
    count = len(chains.pos)
    out = np.zeros((count, 3, 3))
    near = np.flatnonzero(pairs.dist < TOUCH * d)
    if len(near) == 0:
        return out
    n, s, t = pairs.normal[near], pairs.s[near], pairs.t[near]
    tangent = tangents(chains)
    sides = (
        (lay.a[pairs.i[near]], 1 - s, n),
        (lay.b[pairs.i[near]], s, n),
        (lay.a[pairs.j[near]], 1 - t, -n),
        (lay.b[pairs.j[near]], t, -n),
    )
    for node, weight, direction in sides:
        tan = tangent[node]
        flat = direction - np.einsum("ij,ij->i", direction, tan)[:, None] * tan
        np.add.at(out, node, weight[:, None, None] * flat[:, :, None] * flat[:, None, :])
    return out


def sections(chains: Chains, lay: Layout, pairs: Pairs, d: float) -> Sections:
    """The section of every node (docs/relax.md, "Sections")."""
    values, vectors = np.linalg.eigh(scatter(chains, lay, pairs, d))
    l1, l2 = values[:, 2], values[:, 1]
    total = l1 + l2
    flat = np.divide(l1 - l2, total, out=np.zeros_like(total), where=total > 0)
    squeeze = 1 - FLAT * flat
    up = default_up(chains)
    pressed = total > 0
    up[pressed] = vectors[pressed, :, 2]
    return Sections(d / squeeze, d * squeeze, up)


def default_up(chains: Chains) -> FloatArray:
    """The exports' up vector of each node (normal to the yarn), yarn by yarn."""
    bounds = np.searchsorted(chains.yarn, np.arange(int(chains.yarn.max()) + 2))
    parts = [up_vectors(chains.pos[a:b]) for a, b in itertools.pairwise(bounds)]
    return np.vstack(parts) if parts else np.zeros((0, 3))
