"""The skeleton as a VTK unstructured grid (.vtu) of line cells, through meshio.

meshio writes no VTK PolyData (.vtp); a .vtu of line cells opens in ParaView the same way.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from bwsd.export.errors import ExportError
from bwsd.export.families import family_codes
from bwsd.twin.skeleton import IntArray, SkeletonData

KIND_SEGMENT = 0
KIND_CONTACT = 1


def _segments(sk: SkeletonData, codes: dict[str, int]) -> tuple[IntArray, IntArray]:
    """Point-index pairs of every yarn segment, and (yarn, family) per segment."""
    pairs, owners = [], []
    start = 0
    for yarn in sk.yarns:
        n = len(yarn.node_ids)
        idx = np.arange(start, start + n, dtype=np.int64)
        pairs.append(np.column_stack([idx[:-1], idx[1:]]))
        owners.append(np.tile([yarn.id, codes[yarn.family]], (max(n - 1, 0), 1)))
        start += n
    return np.vstack(pairs).reshape(-1, 2), np.vstack(owners).reshape(-1, 2)


def _links(sk: SkeletonData, codes: dict[str, int]) -> tuple[IntArray, IntArray]:
    """Point-index pairs of every contact link, and (moving yarn, family, instruction)."""
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


def skeleton_mesh(sk: SkeletonData) -> meshio.Mesh:
    """One point per node, one "line" cell per yarn segment and per contact link."""
    if not sk.yarns:
        raise ExportError("the skeleton has no yarns to export")
    codes = family_codes(sk)
    seg, seg_owner = _segments(sk, codes)
    link, link_info = _links(sk, codes)
    points = np.vstack([np.asarray(y.nodes, dtype=np.float64) for y in sk.yarns])
    n_seg, n_link = len(seg), len(link)
    kind = np.concatenate([np.full(n_seg, KIND_SEGMENT), np.full(n_link, KIND_CONTACT)])
    cell_data = {
        "yarn": np.concatenate([seg_owner[:, 0], link_info[:, 0]]),
        "family": np.concatenate([seg_owner[:, 1], link_info[:, 1]]),
        "kind": kind.astype(np.int64),
        "instruction": np.concatenate([np.zeros(n_seg, dtype=np.int64), link_info[:, 2]]),
    }
    point_data = {
        "node_id": np.concatenate([y.node_ids for y in sk.yarns]).astype(np.int64),
        "yarn": np.concatenate([np.full(len(y.node_ids), y.id) for y in sk.yarns]),
    }
    return meshio.Mesh(
        points,
        [("line", np.vstack([seg, link]))],
        point_data=point_data,
        cell_data={k: [v.astype(np.int64)] for k, v in cell_data.items()},
    )


def write_vtu(sk: SkeletonData, path: str | Path) -> None:
    """Write ``skeleton_mesh(sk)`` as a VTK XML unstructured grid (zlib-compressed)."""
    mesh = skeleton_mesh(sk)
    try:
        meshio.write(str(path), mesh, file_format="vtu")
    except OSError as exc:
        raise ExportError(f"cannot write: {exc.strerror}", path=str(path)) from exc
