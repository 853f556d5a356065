"""Points and contact links of a skeleton as the VTK writers lay them out.

Points are the skeleton's nodes, yarn by yarn, in order along each yarn: the nodes of
yarn ``k`` are a contiguous run of point indices. A contact link joins the moving yarn's
new node to the hit yarn's new node.
"""

from __future__ import annotations

import numpy as np

from bwsd.export.errors import ExportError
from bwsd.twin.skeleton import FloatArray, IntArray, SkeletonData

# Value of the ``kind`` cell array.
KIND_SEGMENT = 0
KIND_CONTACT = 1


def require_yarns(sk: SkeletonData) -> None:
    """Refuse a skeleton without yarns: there is nothing to write."""
    if not sk.yarns:
        raise ExportError("the skeleton has no yarns to export")


def node_points(sk: SkeletonData) -> FloatArray:
    """Coordinates of every node, shape (n, 3), yarn by yarn."""
    parts = [np.asarray(y.nodes, dtype=np.float64).reshape(-1, 3) for y in sk.yarns]
    return np.vstack(parts) if parts else np.zeros((0, 3))


def point_arrays(sk: SkeletonData) -> dict[str, IntArray]:
    """Point data: ``node_id`` (the skeleton's node id) and ``yarn`` (its yarn's id)."""
    if not sk.yarns:
        return {"node_id": np.zeros(0, np.int64), "yarn": np.zeros(0, np.int64)}
    return {
        "node_id": np.concatenate([y.node_ids for y in sk.yarns]).astype(np.int64),
        "yarn": np.concatenate([np.full(len(y.node_ids), y.id, np.int64) for y in sk.yarns]),
    }


def contact_links(sk: SkeletonData, codes: dict[str, int]) -> tuple[IntArray, IntArray]:
    """Point-index pairs of every contact link, and (moving yarn, family, instruction).

    ``codes`` maps each family to its code (``families.family_codes``).
    """
    index: dict[int, int] = {}
    for yarn in sk.yarns:
        for nid in yarn.node_ids.tolist():
            index[int(nid)] = len(index)
    family = {y.id: codes[y.family] for y in sk.yarns}
    try:
        pairs = [(index[c.moving_node], index[c.hit_node]) for c in sk.contacts]
        info = [(c.moving_yarn, family[c.moving_yarn], c.instruction) for c in sk.contacts]
    except KeyError as exc:
        raise ExportError(f"a contact names node or yarn {exc.args[0]}, unknown here") from exc
    return (
        np.array(pairs, dtype=np.int64).reshape(-1, 2),
        np.array(info, dtype=np.int64).reshape(-1, 3),
    )
