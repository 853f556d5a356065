"""Preform metrics from a skeleton (docs/exports.md): the formed zone and its yarn angles,
interpenetration and yarn volume fraction; weft contacts; section, contacts per cycle,
contact groups, carrier mixing and footprint."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bwsd.export.angles import formed_angles, skeleton_angles
from bwsd.export.arrays import Arrays
from bwsd.export.errors import ExportError
from bwsd.export.footprint import footprint
from bwsd.export.formed import Zone, find_zone, guide_heights, pieces
from bwsd.export.fraction import volume_fraction
from bwsd.export.mixing import NamedSection, ZoneVisits
from bwsd.export.overlap import interpenetration
from bwsd.twin.skeleton import FloatArray, SkeletonData, YarnData


def fixed_nodes(yarn: YarnData) -> FloatArray:
    """The yarn's fixed nodes: all of a weft's, all but the free (last) node of a warp."""
    nodes = np.asarray(yarn.nodes, dtype=np.float64)
    return nodes[:-1] if yarn.kind == "warp" else nodes


def contact_zone(sk: SkeletonData, arrays: Arrays | None = None) -> tuple[float, float] | None:
    """Lowest and highest z of the nodes that contacts created (both sides), or None."""
    arrays = arrays or Arrays.of(sk)
    z = arrays.pos[arrays.contact_nodes(), 2]
    return (float(z.min()), float(z.max())) if len(z) else None


def section(sk: SkeletonData, arrays: Arrays | None = None) -> dict[str, Any] | None:
    """Outer width (x) and thickness (y) of the fixed nodes in the middle half of the contact zone.

    None without contacts, or when no fixed node lies in that band.
    """
    zone = contact_zone(sk, arrays)
    if zone is None:
        return None
    quarter = (zone[1] - zone[0]) / 4
    low, high = zone[0] + quarter, zone[1] - quarter
    nodes = np.vstack([fixed_nodes(y) for y in sk.yarns])
    inside = nodes[(nodes[:, 2] >= low) & (nodes[:, 2] <= high)]
    if len(inside) == 0:
        return None
    lo, hi = inside.min(axis=0), inside.max(axis=0)
    return {
        "z": [low, high],
        "nodes": len(inside),
        "x": [float(lo[0]), float(hi[0])],
        "y": [float(lo[1]), float(hi[1])],
        "width": float(hi[0] - lo[0]) + sk.diameter,
        "thickness": float(hi[1] - lo[1]) + sk.diameter,
    }


def contact_groups(sk: SkeletonData, arrays: Arrays | None = None) -> list[list[int]]:
    """Connected groups of the contact graph (yarns, one edge per contact), largest first.

    A yarn without contacts is a group of its own. Groups of one size keep the order of
    their smallest yarn ids; each group lists its yarn ids in increasing order.
    """
    arrays = arrays or Arrays.of(sk)
    n, table = len(sk.yarns), arrays.contacts
    graph = coo_matrix((np.ones(len(table)), (table[:, 1], table[:, 3])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    ids = np.array([y.id for y in sk.yarns], dtype=np.int64)
    order = np.argsort(ids, kind="stable")
    label, ids = label[order], ids[order]
    _, first = np.unique(label, return_index=True)  # each group's smallest id comes first
    size = np.bincount(label)
    groups = sorted(np.unique(label).tolist(), key=lambda g: (-size[g], int(ids[first[g]])))
    return [ids[label == g].tolist() for g in groups]


def groups(sk: SkeletonData, arrays: Arrays | None = None) -> dict[str, Any]:
    """Number, sizes and members of the contact graph's connected groups."""
    found = contact_groups(sk, arrays)
    return {"count": len(found), "sizes": [len(g) for g in found], "members": found}


def unconnected(sk: SkeletonData) -> dict[str, Any]:
    """The yarns that take part in no contact, neither moving nor hit."""
    touched = {y for c in sk.contacts for y in (c.moving_yarn, c.hit_yarn)}
    ids = [y.id for y in sk.yarns if y.id not in touched]
    return {"count": len(ids), "ids": ids}


def weft_contacts(sk: SkeletonData, arrays: Arrays | None = None) -> dict[str, Any]:
    """Contacts per weft; the wefts with none are loose, those with one held at one point."""
    arrays = arrays or Arrays.of(sk)
    ids = np.array([y.id for y in sk.yarns if y.kind == "weft"], dtype=np.int64)
    table = arrays.contacts
    count = np.bincount(np.concatenate([table[:, 1], table[:, 3]]), minlength=len(sk.yarns))
    per = count[ids] if len(ids) else np.zeros(0, np.int64)
    spread = None
    if len(per):
        spread = {"min": int(per.min()), "median": float(np.median(per)), "max": int(per.max())}
    return {
        "count": len(ids),
        "contacts": spread,
        "per_weft": per.tolist(),
        "loose": ids[per == 0].tolist(),
        "held_once": ids[per == 1].tolist(),
    }


def cycle_length_or_whole(cycle_length: int | None, instructions: int) -> int:
    """``cycle_length``, or the whole run (at least 1) when None; refused below 1."""
    length = cycle_length if cycle_length is not None else max(instructions, 1)
    if length < 1:
        raise ExportError(f"cycle length must be at least 1, got {length}")
    return length


def contacts_per_cycle(
    sk: SkeletonData, cycle_length: int | None, arrays: Arrays | None = None
) -> dict[str, Any]:
    """Contacts per cycle of ``cycle_length`` instructions, counted from instruction 1.

    ``cycle_length`` None makes the whole run one cycle. The mean, min and max cover the
    complete cycles only; a trailing partial cycle is listed in ``counts`` all the same.
    """
    made = (arrays or Arrays.of(sk)).contacts[:, 0]
    n = max(sk.instructions, int(made.max()) if len(made) else 0)
    per_instruction = np.bincount(made, minlength=n + 1)[1:]
    length = cycle_length_or_whole(cycle_length, n)
    counts = np.add.reduceat(per_instruction, np.arange(0, n, length)).tolist() if n else []
    complete = counts[: n // length]
    return {
        "length": length,
        "cycles": len(counts),
        "complete": len(complete),
        "counts": counts,
        "mean": sum(complete) / len(complete) if complete else None,
        "min": min(complete, default=None),
        "max": max(complete, default=None),
        "per_instruction": per_instruction.astype(int).tolist(),
    }


def _named(named: NamedSection | None) -> dict[str, Any] | None:
    if named is None:
        return None
    line = named.line if named.source == "header" else None
    return {
        "spec": named.section.spec,
        "shape": named.section.shape,
        "source": named.source,
        "line": line,
    }


def formed(
    sk: SkeletonData,
    cycle_length: int | None,
    guides: FloatArray | None,
    arrays: Arrays | None = None,
) -> dict[str, Any]:
    """The formed zone, and its yarn angles, interpenetration and yarn volume fraction."""
    arrays = arrays or Arrays.of(sk)
    zone: Zone = find_zone(arrays, cycle_length_or_whole(cycle_length, sk.instructions), guides)
    found = pieces(arrays, zone)
    return {
        "formed": zone.as_dict(),
        "angles": formed_angles(arrays, found) if zone.z is not None else None,
        "interpenetration": interpenetration(arrays, found),
        "volume_fraction": volume_fraction(arrays, zone),
    }


def metrics(
    sk: SkeletonData,
    cycle_length: int | None,
    *,
    takeups: Sequence[float] | None = None,
    z: float | None = None,
    named: NamedSection | None = None,
    visits: ZoneVisits | None = None,
    arrays: Arrays | None = None,
) -> dict[str, Any]:
    """All metrics as JSON-ready builtins (definitions in docs/exports.md).

    ``takeups`` (each instruction's take-up, 0 for all but TAKEUP) places the guides, which
    the formed zone needs; without it there is none. ``visits`` (the carriers' zones,
    recorded while the twin ran) gives the mixing numbers; ``z`` the footprint at that
    height, against the nominal shape of ``named`` if given. ``arrays``: ``Arrays.of(sk)``,
    when the caller has it already.
    """
    arrays = arrays or Arrays.of(sk)
    length = cycle_length_or_whole(cycle_length, sk.instructions)
    guides = None if takeups is None else guide_heights(sk.machine.d_mat, takeups)
    section_ = named.section if named is not None else None
    return {
        "instructions": sk.instructions,
        "takeup": sk.takeup,
        "diameter": sk.diameter,
        "yarns": {
            "warp": sum(1 for y in sk.yarns if y.kind == "warp"),
            "weft": sum(1 for y in sk.yarns if y.kind == "weft"),
        },
        "nodes": sk.node_count,
        "contacts": len(sk.contacts),
        **formed(sk, cycle_length, guides, arrays),
        "skeleton_angles": skeleton_angles(arrays),
        "section": section(sk, arrays),
        "wefts": weft_contacts(sk, arrays),
        "cycles": contacts_per_cycle(sk, cycle_length, arrays),
        "groups": groups(sk, arrays),
        "unconnected": unconnected(sk),
        "section_spec": _named(named),
        "mixing": visits.summary(length) if visits is not None else None,
        "footprint": footprint(sk, z, section_) if z is not None else None,
    }
