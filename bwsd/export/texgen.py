"""The skeleton as a TexGen model (.tg3) through pytexgen."""

from __future__ import annotations

import importlib
import os
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from bwsd.export._quiet import NATIVE_LOCK, quiet_stdout
from bwsd.export.errors import ExportError
from bwsd.extras import TEXGEN, needs
from bwsd.twin.skeleton import FloatArray, SkeletonData

# TexGen needs a section of non-zero size; a centreline-only skeleton (d = 0) gets this one (mm).
ZERO_DIAMETER_SECTION = 0.01
SECTION_POINTS = 40  # outline points read back per section: the ellipse's axis ends among them

_Z = np.array([0.0, 0.0, 1.0])
_X = np.array([1.0, 0.0, 0.0])


def _texgen(what: str) -> Any:
    """pytexgen.Core, imported on first use (it is large and untyped; the `export` extra)."""
    with needs(TEXGEN, what, ExportError), quiet_stdout():
        return importlib.import_module("pytexgen.Core")


def _directions(nodes: FloatArray) -> FloatArray:
    """Unit direction of the polyline at each node (mean of the adjacent segments)."""
    seg = np.diff(nodes, axis=0)
    lengths = np.linalg.norm(seg, axis=1, keepdims=True)
    unit = np.divide(seg, lengths, out=np.zeros_like(seg), where=lengths > 0)
    pad = np.zeros((1, 3))
    out: FloatArray = np.vstack([unit, pad]) + np.vstack([pad, unit])
    return out


def up_vectors(nodes: FloatArray) -> FloatArray:
    """An up vector per node, normal to the yarn there (TexGen orients sections by it).

    TexGen's default up is +z, which is undefined for a yarn along z: warps get up
    vectors from +x, yarns mostly across z from +z, each made orthogonal to the yarn.
    """
    overall = nodes[-1] - nodes[0] if len(nodes) > 1 else _Z
    norm = float(np.linalg.norm(overall))
    reference = _X if norm > 0 and abs(overall[2]) / norm > 0.5 else _Z
    out = np.empty_like(nodes)
    for i, tangent in enumerate(_directions(nodes)):
        out[i] = _orthogonal(reference, tangent)
    return out


def _orthogonal(reference: FloatArray, tangent: FloatArray) -> FloatArray:
    """``reference`` made orthogonal to ``tangent``; the other axis when they are nearly parallel.

    Of +x and +z at least one keeps a component of length > 0.1 normal to any direction.
    """
    t_norm = float(np.linalg.norm(tangent))
    if t_norm == 0:
        return reference
    t = tangent / t_norm
    up = reference - np.dot(reference, t) * t
    if np.linalg.norm(up) <= 0.1:
        other = _Z if reference is _X else _X
        up = other - np.dot(other, t) * t
    result: FloatArray = up / np.linalg.norm(up)
    return result


def distinct_nodes(nodes: FloatArray) -> FloatArray:
    """``nodes`` without a node at the same point as the one before it.

    Two contacts at one point give a yarn two nodes there (the model allows it); TexGen
    refuses a duplicate node, so the .tg3 holds it once.
    """
    kept: FloatArray = nodes[distinct(nodes)]
    return kept


def distinct(nodes: FloatArray) -> npt.NDArray[np.bool_]:
    """Which nodes ``distinct_nodes`` keeps."""
    if len(nodes) < 2:
        return np.ones(len(nodes), dtype=bool)
    return np.concatenate([[True], np.any(nodes[1:] != nodes[:-1], axis=1)])


def _build_textile(tg: Any, sk: SkeletonData, sections: Sequence[FloatArray] | None) -> Any:
    textile = tg.CTextile()
    diameter = sk.diameter if sk.diameter > 0 else ZERO_DIAMETER_SECTION
    zero = tg.XYZ(0.0, 0.0, 0.0)
    for k, yarn in enumerate(sk.yarns):
        raw = np.asarray(yarn.nodes, dtype=np.float64)
        keep = distinct(raw)
        nodes = raw[keep]
        own = None if sections is None else np.asarray(sections[k])[keep]
        ups = up_vectors(nodes) if own is None else own[:, 2:5]
        ty = tg.CYarn()
        for xyz, up in zip(nodes.tolist(), ups.tolist(), strict=True):
            ty.AddNode(tg.CNode(tg.XYZ(*xyz), zero, tg.XYZ(*up)))
        ty.AssignInterpolation(tg.CInterpolationLinear(False))
        if own is None:
            ty.AssignSection(tg.CYarnSectionConstant(tg.CSectionEllipse(diameter, diameter)))
        else:
            ty.AssignSection(_node_sections(tg, own))
        textile.AddYarn(ty)
    return textile


def _node_sections(tg: Any, own: FloatArray) -> Any:
    """An oriented ellipse at every node: width, height (along the node's up vector)."""
    section = tg.CYarnSectionInterpNode(False, False)
    for width, height in own[:, :2].tolist():
        section.AddSection(tg.CSectionEllipse(width, height))
    return section


def write_tg3(
    sk: SkeletonData,
    path: str | Path,
    name: str = "bwsd",
    sections: Sequence[FloatArray] | None = None,
) -> None:
    """Write the skeleton as a TexGen model: one open, linear yarn per yarn, round section,
    or with ``sections`` (per yarn, (nodes, 5): width, height, up vector) an oriented
    ellipse at every node.

    The file is written next to ``path`` and renamed into place, so a failed save
    leaves any previous file untouched. Nothing is printed on stdout.
    """
    target = Path(path)
    if not target.parent.is_dir():
        raise ExportError("directory does not exist", path=str(target))
    tmp = target.with_name(f".{target.name}.{os.getpid()}-{threading.get_ident()}.tmp")
    tmp.unlink(missing_ok=True)
    try:
        _save(sk, str(tmp), name, sections)
        if not tmp.is_file() or tmp.stat().st_size == 0:
            raise ExportError("TexGen could not write the model here", path=str(target))
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def _save(sk: SkeletonData, tmp: str, name: str, sections: Sequence[FloatArray] | None) -> None:
    tg = _texgen("writing .tg3")
    with NATIVE_LOCK, quiet_stdout():
        if name in list(tg.GetTextiles()):
            raise ExportError(f"a TexGen textile named {name!r} is already loaded")
        if not tg.AddTextile(name, _build_textile(tg, sk, sections)):
            raise ExportError(f"TexGen refused the textile {name!r}")
        try:
            tg.SaveToXML(tmp, name, tg.OUTPUT_STANDARD)
        finally:
            tg.DeleteTextile(name)


def _node_lists(tg: Any, name: str) -> list[FloatArray]:
    out: list[FloatArray] = []
    for yarn in tg.GetTextile(name).GetYarns():
        points = [(p.x, p.y, p.z) for p in (n.GetPosition() for n in yarn.GetMasterNodes())]
        out.append(np.array(points, dtype=np.float64).reshape(-1, 3))
    return out


def read_tg3(path: str | Path) -> list[FloatArray]:
    """The node coordinates of every yarn in a .tg3 file, in yarn order.

    All textiles of the file are read (in name order) and removed from TexGen again.
    """
    if not Path(path).is_file():
        raise ExportError("no such file", path=str(path))
    tg = _texgen("reading .tg3")
    with NATIVE_LOCK, quiet_stdout():
        before = set(tg.GetTextiles())
        loaded = bool(tg.ReadFromXML(str(path)))
        added = sorted(set(tg.GetTextiles()) - before)
        try:
            if not loaded or not added:
                raise ExportError("TexGen could not read a new textile from it", path=str(path))
            return [nodes for name in added for nodes in _node_lists(tg, name)]
        finally:
            for name in added:
                tg.DeleteTextile(name)


def _section_lists(tg: Any, name: str) -> list[FloatArray]:
    """Per yarn, (nodes, 5): each node's section width and height (the extents of its
    outline in the section's own axes) and its up vector."""
    out: list[FloatArray] = []
    for yarn in tg.GetTextile(name).GetYarns():
        section = yarn.GetYarnSection().GetSectionInterpNode()
        rows = []
        for i, node in enumerate(yarn.GetMasterNodes()):
            points = section.GetNodeSection(i).GetPoints(SECTION_POINTS)
            xs, ys = [p.x for p in points], [p.y for p in points]
            up = node.GetUp()
            rows.append((max(xs) - min(xs), max(ys) - min(ys), up.x, up.y, up.z))
        out.append(np.array(rows, dtype=np.float64).reshape(-1, 5))
    return out


def read_tg3_sections(path: str | Path) -> list[FloatArray]:
    """The node sections of every yarn of a .tg3 written with ``sections``, in yarn order."""
    if not Path(path).is_file():
        raise ExportError("no such file", path=str(path))
    tg = _texgen("reading .tg3")
    with NATIVE_LOCK, quiet_stdout():
        before = set(tg.GetTextiles())
        loaded = bool(tg.ReadFromXML(str(path)))
        added = sorted(set(tg.GetTextiles()) - before)
        try:
            if not loaded or not added:
                raise ExportError("TexGen could not read a new textile from it", path=str(path))
            return [table for name in added for table in _section_lists(tg, name)]
        finally:
            for name in added:
                tg.DeleteTextile(name)
