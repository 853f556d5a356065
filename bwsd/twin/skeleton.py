"""Plain, read-only views of the twin's state for exports, metrics and the API."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from bwsd.twin.machine import Machine

YarnKind = Literal["warp", "weft"]
FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class YarnData:
    """One yarn as a polyline in the preform frame.

    ``node_ids`` are the stable ids of its nodes in order; ``nodes`` their coordinates
    (shape (n, 3)). For a warp the last node is the free node at its guide, ``cell`` the
    cell it was filled into and ``angle`` is None; for a weft ``cell`` is None and
    ``angle`` is its insertion angle in degrees.
    """

    id: int
    kind: YarnKind
    node_ids: IntArray
    nodes: FloatArray
    cell: tuple[int, int] | None = None
    angle: float | None = None

    @property
    def family(self) -> str:
        """Family used for colouring and metrics: ``warp`` or ``weft-<angle>``."""
        if self.kind == "warp":
            return "warp"
        return f"weft-{self.angle:g}"


@dataclass(frozen=True)
class ContactData:
    """A contact made by instruction ``instruction`` (1-based).

    The moving yarn got node ``moving_node``, the hit yarn node ``hit_node``.
    """

    instruction: int
    moving_yarn: int
    moving_node: int
    hit_yarn: int
    hit_node: int


@dataclass(frozen=True)
class SkeletonData:
    """The whole predicted yarn architecture at one moment."""

    machine: Machine
    diameter: float
    takeup: float
    instructions: int
    yarns: tuple[YarnData, ...]
    contacts: tuple[ContactData, ...]
    occupancy: IntArray

    @property
    def node_count(self) -> int:
        """Total number of nodes, free nodes included."""
        return sum(len(y.node_ids) for y in self.yarns)

    def node_positions(self) -> dict[int, FloatArray]:
        """Map from node id to its coordinates."""
        out: dict[int, FloatArray] = {}
        for yarn in self.yarns:
            for nid, xyz in zip(yarn.node_ids.tolist(), yarn.nodes, strict=True):
                out[int(nid)] = xyz
        return out


def index_from_end(nodes: Any, node: int) -> int:
    """Position of ``node`` in a yarn's node list, searched from the free end."""
    for i in range(len(nodes) - 1, -1, -1):
        if nodes[i] == node:
            return i
    raise ValueError(node)
