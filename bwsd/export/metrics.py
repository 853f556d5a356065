"""Preform metrics from a skeleton: section, yarn angles, contacts per cycle, contact groups,
carrier mixing and footprint (docs/exports.md)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bwsd.export.errors import ExportError
from bwsd.export.families import family_codes
from bwsd.export.footprint import footprint
from bwsd.export.mixing import NamedSection, ZoneVisits
from bwsd.twin.skeleton import FloatArray, SkeletonData, YarnData


def fixed_nodes(yarn: YarnData) -> FloatArray:
    """The yarn's fixed nodes: all of a weft's, all but the free (last) node of a warp."""
    nodes = np.asarray(yarn.nodes, dtype=np.float64)
    return nodes[:-1] if yarn.kind == "warp" else nodes


def contact_zone(sk: SkeletonData) -> tuple[float, float] | None:
    """Lowest and highest z of the nodes that contacts created (both sides), or None."""
    positions = sk.node_positions()
    zs = [float(positions[n][2]) for c in sk.contacts for n in (c.moving_node, c.hit_node)]
    return (min(zs), max(zs)) if zs else None


def section(sk: SkeletonData) -> dict[str, Any] | None:
    """Outer width (x) and thickness (y) of the fixed nodes in the middle half of the contact zone.

    None without contacts, or when no fixed node lies in that band.
    """
    zone = contact_zone(sk)
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


def _segment_angles(yarn: YarnData) -> tuple[FloatArray, FloatArray]:
    """Length and angle to the z axis (degrees, 0..90) of each fixed segment of positive length."""
    seg = np.diff(fixed_nodes(yarn), axis=0)
    length = np.linalg.norm(seg, axis=1)
    keep = length > 0
    cos = np.clip(np.abs(seg[keep, 2]) / length[keep], 0.0, 1.0)
    return length[keep], np.degrees(np.arccos(cos))


def angles(sk: SkeletonData) -> dict[str, dict[str, Any]]:
    """Per family: fixed segments, their length, length-weighted mean and spread of the angle."""
    codes = family_codes(sk)
    out: dict[str, dict[str, Any]] = {}
    for family in sorted({y.family for y in sk.yarns}, key=codes.__getitem__):
        parts = [_segment_angles(y) for y in sk.yarns if y.family == family]
        length = np.concatenate([p[0] for p in parts])
        angle = np.concatenate([p[1] for p in parts])
        total = float(length.sum())
        if total == 0:
            out[family] = {"segments": 0, "length": 0.0, "mean": None, "std": None}
            continue
        mean = float(np.average(angle, weights=length))
        std = math.sqrt(float(np.average((angle - mean) ** 2, weights=length)))
        out[family] = {"segments": len(length), "length": total, "mean": mean, "std": std}
    return out


def contact_groups(sk: SkeletonData) -> list[list[int]]:
    """Connected groups of the contact graph (yarns, one edge per contact), largest first.

    A yarn without contacts is a group of its own. Groups of one size keep the order of
    their smallest yarn ids; each group lists its yarn ids in increasing order.
    """
    parent = {y.id: y.id for y in sk.yarns}

    def root(yarn: int) -> int:
        while parent[yarn] != yarn:
            parent[yarn] = parent[parent[yarn]]
            yarn = parent[yarn]
        return yarn

    for c in sk.contacts:
        a, b = root(c.moving_yarn), root(c.hit_yarn)
        parent[max(a, b)] = min(a, b)
    members: dict[int, list[int]] = {}
    for yarn in sorted(parent):
        members.setdefault(root(yarn), []).append(yarn)
    return sorted(members.values(), key=lambda group: (-len(group), group[0]))


def groups(sk: SkeletonData) -> dict[str, Any]:
    """Number, sizes and members of the contact graph's connected groups."""
    found = contact_groups(sk)
    return {"count": len(found), "sizes": [len(g) for g in found], "members": found}


def unconnected(sk: SkeletonData) -> dict[str, Any]:
    """The yarns that take part in no contact, neither moving nor hit."""
    touched = {y for c in sk.contacts for y in (c.moving_yarn, c.hit_yarn)}
    ids = [y.id for y in sk.yarns if y.id not in touched]
    return {"count": len(ids), "ids": ids}


def cycle_length_or_whole(cycle_length: int | None, instructions: int) -> int:
    """``cycle_length``, or the whole run (at least 1) when None; refused below 1."""
    length = cycle_length if cycle_length is not None else max(instructions, 1)
    if length < 1:
        raise ExportError(f"cycle length must be at least 1, got {length}")
    return length


def contacts_per_cycle(sk: SkeletonData, cycle_length: int | None) -> dict[str, Any]:
    """Contacts per cycle of ``cycle_length`` instructions, counted from instruction 1.

    ``cycle_length`` None makes the whole run one cycle. The mean, min and max cover the
    complete cycles only; a trailing partial cycle is listed in ``counts`` all the same.
    """
    made = [c.instruction for c in sk.contacts]
    n = max([sk.instructions, *made])
    per_instruction = np.bincount(np.asarray(made, dtype=np.int64), minlength=n + 1)[1:]
    length = cycle_length_or_whole(cycle_length, n)
    counts = [int(per_instruction[k : k + length].sum()) for k in range(0, n, length)]
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
    return {"spec": named.section.spec, "shape": named.section.shape, "source": named.source,
            "line": line}  # fmt: skip


def metrics(
    sk: SkeletonData,
    cycle_length: int | None,
    *,
    z: float | None = None,
    named: NamedSection | None = None,
    visits: ZoneVisits | None = None,
) -> dict[str, Any]:
    """All metrics as JSON-ready builtins (definitions in docs/exports.md).

    ``visits`` (the carriers' zones, recorded while the twin ran) gives the mixing numbers;
    ``z`` the footprint at that height, against the nominal shape of ``named`` if given.
    """
    length = cycle_length_or_whole(cycle_length, sk.instructions)
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
        "section": section(sk),
        "angles": angles(sk),
        "cycles": contacts_per_cycle(sk, cycle_length),
        "groups": groups(sk),
        "unconnected": unconnected(sk),
        "section_spec": _named(named),
        "mixing": visits.summary(length) if visits is not None else None,
        "footprint": footprint(sk, z, section_) if z is not None else None,
    }
