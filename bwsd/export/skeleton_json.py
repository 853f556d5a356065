"""The skeleton as plain JSON (schema in docs/skeleton-json.md)."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bwsd.export.errors import ExportError
from bwsd.twin.machine import Machine
from bwsd.twin.model import Twin
from bwsd.twin.prediction import Prediction
from bwsd.twin.skeleton import ContactData, SkeletonData, YarnData

SCHEMA = "bwsd-skeleton"
VERSION = 1


def yarn_to_dict(yarn: YarnData) -> dict[str, Any]:
    """One yarn as in the document's ``yarns``."""
    return {
        "id": yarn.id,
        "kind": yarn.kind,
        "family": yarn.family,
        "cell": list(yarn.cell) if yarn.cell is not None else None,
        "angle": yarn.angle,
        "node_ids": [int(n) for n in yarn.node_ids],
        "nodes": np.asarray(yarn.nodes, dtype=np.float64).tolist(),
    }


def contact_to_dict(contact: ContactData) -> dict[str, Any]:
    """One contact as in the document's ``contacts``."""
    return {
        "yarns": [contact.moving_yarn, contact.hit_yarn],
        "nodes": [contact.moving_node, contact.hit_node],
        "instruction": contact.instruction,
    }


def skeleton_to_dict(sk: SkeletonData) -> dict[str, Any]:
    """The skeleton as JSON-ready builtins, coordinates in the preform frame (mm)."""
    return {
        "schema": SCHEMA,
        "version": VERSION,
        "frame": "preform",
        "units": "mm",
        "machine": sk.machine.as_dict(),
        "diameter": sk.diameter,
        "takeup": sk.takeup,
        "instructions": sk.instructions,
        "occupancy": np.asarray(sk.occupancy).tolist(),
        "yarns": [yarn_to_dict(y) for y in sk.yarns],
        "contacts": [contact_to_dict(c) for c in sk.contacts],
    }


def write_skeleton_json(sk: SkeletonData, path: str | Path) -> None:
    """Write ``skeleton_to_dict(sk)`` to ``path`` as UTF-8 JSON."""
    try:
        text = json.dumps(skeleton_to_dict(sk), indent=1, allow_nan=False)
    except ValueError as exc:
        raise ExportError("the skeleton holds a non-finite number", path=str(path)) from exc
    try:
        Path(path).write_text(text + "\n", encoding="utf-8")
    except OSError as exc:
        raise ExportError(f"cannot write: {exc.strerror}", path=str(path)) from exc


def delta_to_dict(twin: Twin, pred: Prediction) -> dict[str, Any]:
    """The skeleton's change by ``pred``, just committed to ``twin`` (nothing committed since).

    As in the "instruction" event of docs/api.md: apply it to a copy at ``since`` instructions.
    """
    return delta_from(pred, *committed_parts(twin, pred))


def committed_parts(twin: Twin, pred: Prediction) -> tuple[dict[int, int], list[YarnData], int]:
    """What a delta needs of the twin right after ``pred`` was committed (a few small reads):
    the free node of each moved warp, the new yarns, the yarn count."""
    first_new = min(pred.new_yarns, default=twin.yarn_count)
    free = {w: twin.free_node(w) for w in pred.free_nodes if w < first_new}
    return free, [twin.yarn(i) for i in pred.new_yarns], twin.yarn_count


def delta_from(
    pred: Prediction, free_nodes: Mapping[int, int], new_yarns: Sequence[YarnData], yarn_count: int
) -> dict[str, Any]:
    """The delta from the prediction and ``committed_parts`` (no twin needed: any thread).

    ``inserted`` nodes come in yarn order, so each one's ``after`` is in place before it.
    """
    first_new = min(pred.new_yarns, default=yarn_count)
    return {
        "since": pred.index - 1,
        "inserted": [
            {"yarn": n.yarn, "node": n.node, "after": n.after, "xyz": _xyz(n.xyz)}
            for n in pred.inserted
            if n.yarn < first_new
        ],
        "moved": [
            {"yarn": w, "node": free_nodes[w], "xyz": _xyz(xyz)}
            for w, xyz in sorted(pred.free_nodes.items())
            if w < first_new
        ],
        "new_yarns": [yarn_to_dict(yarn) for yarn in new_yarns],
        "contacts": [contact_to_dict(c) for c in pred.contacts],
        "takeup": float(pred.takeup),
        "occupancy": pred.occupancy.tolist(),
    }


def _xyz(xyz: Sequence[float]) -> list[float]:
    """A point as a list (the predictions' points are Python floats already)."""
    return list(xyz)


def _yarn_from_dict(d: Mapping[str, Any]) -> YarnData:
    cell = d.get("cell")
    angle = d.get("angle")
    nodes = np.asarray(d["nodes"], dtype=np.float64).reshape(-1, 3)
    node_ids = np.asarray(d["node_ids"], dtype=np.int64)
    kind = d["kind"]
    if kind not in ("warp", "weft"):
        raise ValueError(f"yarn kind must be 'warp' or 'weft', got {kind!r}")
    if len(node_ids) != len(nodes):
        raise ValueError(f"yarn {d['id']}: {len(node_ids)} node ids for {len(nodes)} nodes")
    return YarnData(
        id=int(d["id"]),
        kind=kind,
        node_ids=node_ids,
        nodes=nodes,
        cell=(int(cell[0]), int(cell[1])) if cell is not None else None,
        angle=float(angle) if angle is not None else None,
    )


def _contact_from_dict(d: Mapping[str, Any]) -> ContactData:
    moving_yarn, hit_yarn = d["yarns"]
    moving_node, hit_node = d["nodes"]
    return ContactData(
        instruction=int(d["instruction"]),
        moving_yarn=int(moving_yarn),
        moving_node=int(moving_node),
        hit_yarn=int(hit_yarn),
        hit_node=int(hit_node),
    )


def _skeleton_from_dict(d: Mapping[str, Any], machine: Machine | None) -> SkeletonData:
    if d.get("schema") != SCHEMA or d.get("version") != VERSION:
        raise ValueError(f"not a {SCHEMA} version {VERSION} document")
    geometry = machine if machine is not None else Machine.from_dict(d["machine"])
    return SkeletonData(
        machine=geometry,
        diameter=float(d["diameter"]),
        takeup=float(d["takeup"]),
        instructions=int(d["instructions"]),
        yarns=tuple(_yarn_from_dict(y) for y in d["yarns"]),
        contacts=tuple(_contact_from_dict(c) for c in d["contacts"]),
        occupancy=np.asarray(d["occupancy"], dtype=np.int64),
    )


def skeleton_from_dict(d: Mapping[str, Any], machine: Machine | None = None) -> SkeletonData:
    """Rebuild a skeleton from ``skeleton_to_dict`` output.

    ``machine`` overrides the geometry stored in the document.
    """
    try:
        return _skeleton_from_dict(d, machine)
    except (KeyError, TypeError, ValueError) as exc:
        raise ExportError(f"malformed skeleton document: {exc}") from exc


def read_skeleton_json(path: str | Path, machine: Machine | None = None) -> SkeletonData:
    """Read a skeleton written by ``write_skeleton_json``."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise ExportError(f"cannot read: {exc.strerror}", path=str(path)) from exc
    except json.JSONDecodeError as exc:
        raise ExportError(f"not valid JSON: {exc}", path=str(path)) from exc
    try:
        return _skeleton_from_dict(data, machine)
    except (KeyError, TypeError, ValueError) as exc:
        raise ExportError(f"malformed skeleton document: {exc}", path=str(path)) from exc
