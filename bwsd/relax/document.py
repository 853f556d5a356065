"""The relaxed skeleton as a document and as files (docs/relax.md, "Output").

The document is the skeleton JSON (docs/skeleton-json.md), each yarn with its nodes'
``sections`` ([width, height, up x, up y, up z] per node), plus a ``relaxed`` block (the
solver's figures) and the wefts' ``crimp``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from bwsd.export import ExportError, export
from bwsd.export.skeleton_json import skeleton_to_dict
from bwsd.relax import Relaxed, crimp


def relaxed_to_dict(relaxed: Relaxed) -> dict[str, Any]:
    """The relaxed skeleton as JSON-ready builtins."""
    document = skeleton_to_dict(relaxed.skeleton)
    for yarn, table in zip(document["yarns"], relaxed.sections, strict=True):
        yarn["sections"] = table.tolist()
    document["relaxed"] = relaxed.summary()
    document["crimp"] = crimp(relaxed.skeleton)
    return document


def write_relaxed(relaxed: Relaxed, path: str | Path) -> None:
    """Write the relaxed skeleton: .json as the document above, .tg3 and .vtp with each
    node's section, .vtu as the plain skeleton."""
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix == ".json":
        _write_json(relaxed, target)
    elif suffix == ".tg3":
        from bwsd.export.texgen import write_tg3

        write_tg3(relaxed.skeleton, target, sections=relaxed.sections)
    elif suffix == ".vtp":
        from bwsd.extras import VTK, needs

        with needs(VTK, "writing .vtp", ExportError):
            from bwsd.export.vtp import write_vtp
        write_vtp(relaxed.skeleton, target, sections=relaxed.sections)
    else:
        export(relaxed.skeleton, target)  # .vtu; any other suffix is refused there


def _write_json(relaxed: Relaxed, target: Path) -> None:
    try:
        text = json.dumps(relaxed_to_dict(relaxed), indent=1, allow_nan=False)
    except ValueError as exc:
        raise ExportError("the skeleton holds a non-finite number", path=str(target)) from exc
    try:
        target.write_text(text + "\n", encoding="utf-8")
    except OSError as exc:
        raise ExportError(f"cannot write: {exc.strerror}", path=str(target)) from exc
