"""The skeleton as a TexGen model (.tg3) through pytexgen."""

from __future__ import annotations

import importlib
import os
import threading
from pathlib import Path
from typing import Any

import numpy as np

from bwsd.export._quiet import NATIVE_LOCK, quiet_stdout
from bwsd.export.errors import ExportError
from bwsd.extras import TEXGEN, needs
from bwsd.twin.skeleton import FloatArray, SkeletonData

# TexGen needs a section of non-zero size; a centreline-only skeleton (d = 0) gets this one (mm).
ZERO_DIAMETER_SECTION = 0.01

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
    if len(nodes) < 2:
        return nodes
    keep = np.concatenate([[True], np.any(nodes[1:] != nodes[:-1], axis=1)])
    kept: FloatArray = nodes[keep]
    return kept


def _build_textile(tg: Any, sk: SkeletonData) -> Any:
    textile = tg.CTextile()
    diameter = sk.diameter if sk.diameter > 0 else ZERO_DIAMETER_SECTION
    zero = tg.XYZ(0.0, 0.0, 0.0)
    for yarn in sk.yarns:
        nodes = distinct_nodes(np.asarray(yarn.nodes, dtype=np.float64))
        ty = tg.CYarn()
        for xyz, up in zip(nodes.tolist(), up_vectors(nodes).tolist(), strict=True):
            ty.AddNode(tg.CNode(tg.XYZ(*xyz), zero, tg.XYZ(*up)))
        ty.AssignInterpolation(tg.CInterpolationLinear(False))
        ty.AssignSection(tg.CYarnSectionConstant(tg.CSectionEllipse(diameter, diameter)))
        textile.AddYarn(ty)
    return textile


def write_tg3(sk: SkeletonData, path: str | Path, name: str = "bwsd") -> None:
    """Write the skeleton as a TexGen model: one open, linear yarn per yarn, round section.

    The file is written next to ``path`` and renamed into place, so a failed save
    leaves any previous file untouched. Nothing is printed on stdout.
    """
    target = Path(path)
    if not target.parent.is_dir():
        raise ExportError("directory does not exist", path=str(target))
    tmp = target.with_name(f".{target.name}.{os.getpid()}-{threading.get_ident()}.tmp")
    tmp.unlink(missing_ok=True)
    try:
        _save(sk, str(tmp), name)
        if not tmp.is_file() or tmp.stat().st_size == 0:
            raise ExportError("TexGen could not write the model here", path=str(target))
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def _save(sk: SkeletonData, tmp: str, name: str) -> None:
    tg = _texgen("writing .tg3")
    with NATIVE_LOCK, quiet_stdout():
        if name in list(tg.GetTextiles()):
            raise ExportError(f"a TexGen textile named {name!r} is already loaded")
        if not tg.AddTextile(name, _build_textile(tg, sk)):
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
