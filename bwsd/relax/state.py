"""A skeleton as the solver's flat arrays, and back (numpy only).

Nodes are laid out yarn by yarn, in order along each yarn. A node's movable components are
``free`` (True: the solver may move it along that axis): a warp's first node (at the fell)
and its last (at its guide) are fixed, a weft's two ends move in z only, every other node
moves freely.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from bwsd.twin.skeleton import FloatArray, IntArray, SkeletonData, YarnData

BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Chains:
    """Node positions, ids and owners, the movable components, and each yarn's tension."""

    pos: FloatArray  # (n, 3)
    ids: IntArray  # (n,) the skeleton's node ids; added nodes get new ones
    yarn: IntArray  # (n,) index of the owning yarn in the skeleton's order
    free: BoolArray  # (n, 3)
    tension: FloatArray  # (yarns,)

    @classmethod
    def of(cls, sk: SkeletonData, warp_tension: float, weft_tension: float) -> Chains:
        """The chains of ``sk``, warps under ``warp_tension``, wefts under ``weft_tension``."""
        pos = np.vstack([np.asarray(y.nodes, np.float64).reshape(-1, 3) for y in sk.yarns])
        ids = np.concatenate([np.asarray(y.node_ids, np.int64) for y in sk.yarns])
        sizes = np.array([len(y.node_ids) for y in sk.yarns], np.int64)
        yarn = np.repeat(np.arange(len(sk.yarns)), sizes)
        free = np.ones((len(pos), 3), dtype=bool)
        last = np.cumsum(sizes) - 1
        first = last - sizes + 1
        weft = np.array([y.kind == "weft" for y in sk.yarns], dtype=bool)
        free[first[~weft]] = False
        free[last[~weft]] = False
        free[first[weft], :2] = False
        free[last[weft], :2] = False
        tension = np.where(weft, weft_tension, warp_tension).astype(np.float64)
        return cls(pos, ids, yarn, free, tension)

    @property
    def seg_a(self) -> IntArray:
        """First node of each segment (a node and the next one of the same yarn)."""
        out: IntArray = np.flatnonzero(self.yarn[:-1] == self.yarn[1:])
        return out

    def with_pos(self, pos: FloatArray) -> Chains:
        """The same chains at other positions."""
        return replace(self, pos=pos)

    def insert(self, after: IntArray, points: FloatArray, first_id: int) -> Chains:
        """New free nodes at ``points``, each after node ``after`` (indices into the current
        layout, increasing), with ids from ``first_id`` on."""
        where = after + 1
        ids = np.arange(first_id, first_id + len(after), dtype=np.int64)
        return Chains(
            np.insert(self.pos, where, points, axis=0),
            np.insert(self.ids, where, ids),
            np.insert(self.yarn, where, self.yarn[after]),
            np.insert(self.free, where, True, axis=0),
            self.tension,
        )

    def skeleton(self, sk: SkeletonData) -> SkeletonData:
        """``sk`` with these positions and nodes (yarns, contacts and the rest unchanged)."""
        bounds = np.searchsorted(self.yarn, np.arange(len(sk.yarns) + 1))
        yarns = tuple(
            _yarn(y, self.ids[a:b], self.pos[a:b])
            for y, a, b in zip(sk.yarns, bounds[:-1], bounds[1:], strict=True)
        )
        return replace(sk, yarns=yarns)


def _yarn(y: YarnData, ids: IntArray, pos: FloatArray) -> YarnData:
    return replace(y, node_ids=ids.copy(), nodes=pos.copy())
