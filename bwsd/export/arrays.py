"""A skeleton as flat arrays, built once for the metrics (numpy only).

Nodes are indexed by their id; a *fixed segment* joins two consecutive fixed nodes of one
yarn (a warp's free segment, from its last fixed node to its guide, is never one).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from bwsd.export.families import family_codes
from bwsd.twin.skeleton import FloatArray, IntArray, SkeletonData


@dataclass(frozen=True)
class Arrays:
    """Node positions by id, fixed segments, contacts, and what made each node."""

    sk: SkeletonData
    pos: FloatArray  # (nodes, 3) by node id
    seg_a: IntArray  # first node of each fixed segment
    seg_b: IntArray  # second node
    seg_yarn: IntArray
    contacts: IntArray  # (contacts, 5): instruction, moving yarn, X, hit yarn, Y
    made: IntArray  # the instruction whose contact made each node; 0 for the others
    family: IntArray  # family code per yarn (``families.family_codes``)
    names: tuple[str, ...]  # family name per code

    @classmethod
    def of(cls, sk: SkeletonData) -> Arrays:
        """The arrays of ``sk``."""
        size = 1 + max((int(y.node_ids.max()) for y in sk.yarns if len(y.node_ids)), default=-1)
        pos = np.zeros((size, 3))
        firsts, seconds, owners = [], [], []
        for yarn in sk.yarns:
            pos[yarn.node_ids] = yarn.nodes
            fixed = yarn.node_ids[:-1] if yarn.kind == "warp" else yarn.node_ids
            firsts.append(fixed[:-1])
            seconds.append(fixed[1:])
            owners.append(np.full(max(len(fixed) - 1, 0), yarn.id, dtype=np.int64))
        contacts = np.array(
            [
                (c.instruction, c.moving_yarn, c.moving_node, c.hit_yarn, c.hit_node)
                for c in sk.contacts
            ],
            dtype=np.int64,
        ).reshape(-1, 5)
        made = np.zeros(size, dtype=np.int64)
        made[contacts[:, 2]] = contacts[:, 0]
        made[contacts[:, 4]] = contacts[:, 0]
        codes = family_codes(sk)
        family = np.array([codes[y.family] for y in sk.yarns], dtype=np.int64)
        return cls(
            sk, pos, _cat(firsts), _cat(seconds), _cat(owners), contacts, made, family, tuple(codes)
        )

    @cached_property
    def seg_p0(self) -> FloatArray:
        """Start point of each fixed segment."""
        out: FloatArray = self.pos[self.seg_a]
        return out

    @cached_property
    def seg_p1(self) -> FloatArray:
        """End point of each fixed segment."""
        out: FloatArray = self.pos[self.seg_b]
        return out

    @cached_property
    def seg_t0(self) -> FloatArray:
        """Start points as a (3, segments) array: fast row-wise arithmetic."""
        return np.ascontiguousarray(self.seg_p0.T)

    @cached_property
    def seg_t1(self) -> FloatArray:
        """End points as a (3, segments) array."""
        return np.ascontiguousarray(self.seg_p1.T)

    @cached_property
    def seg_length(self) -> FloatArray:
        """Length of each fixed segment."""
        out: FloatArray = np.linalg.norm(self.seg_p1 - self.seg_p0, axis=1)
        return out

    @cached_property
    def seg_family(self) -> IntArray:
        """Family code of each fixed segment's yarn."""
        out: IntArray = self.family[self.seg_yarn]
        return out

    def contact_nodes(self) -> IntArray:
        """Ids of the nodes that contacts made (X and Y)."""
        return np.flatnonzero(self.made)

    def present(self) -> list[int]:
        """The family codes that have yarns, in code order."""
        return sorted(set(self.family.tolist()))


def _cat(parts: list[IntArray]) -> IntArray:
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)
