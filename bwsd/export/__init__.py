"""Exports of the predicted skeleton: JSON, TexGen .tg3, VTK .vtp and .vtu; slices and metrics."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from bwsd.export.errors import ExportError
from bwsd.extras import VTK, needs

if TYPE_CHECKING:
    from bwsd.twin.skeleton import SkeletonData

__all__ = ["FORMATS", "ExportError", "export"]

# Suffix -> what it writes. The writers are imported on use: pytexgen and VTK are large,
# and they come with the package's `export` extra (a missing one is an ExportError naming it).
FORMATS: dict[str, str] = {
    ".json": "skeleton JSON (docs/skeleton-json.md)",
    ".tg3": "TexGen model",
    ".vtp": "VTK PolyData: a polyline per yarn, a line per contact (ParaView)",
    ".vtu": "VTK unstructured grid of line cells (ParaView)",
}


def _writer(suffix: str) -> Callable[[SkeletonData, Path], None]:
    if suffix == ".json":
        from bwsd.export.skeleton_json import write_skeleton_json

        return write_skeleton_json
    if suffix == ".tg3":
        from bwsd.export.texgen import write_tg3  # pytexgen is imported when it writes

        return write_tg3
    with needs(VTK, f"writing {suffix}", ExportError):
        if suffix == ".vtp":
            from bwsd.export.vtp import write_vtp

            return write_vtp
        from bwsd.export.vtk import write_vtu

        return write_vtu


def export(sk: SkeletonData, path: str | Path) -> None:
    """Write the skeleton in the format its suffix names (see ``FORMATS``)."""
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in FORMATS:
        known = ", ".join(f"{s} ({what})" for s, what in FORMATS.items())
        raise ExportError(
            f"unknown export format {suffix or '(no suffix)'!r}; known: {known}", path=str(target)
        )
    _writer(suffix)(sk, target)
