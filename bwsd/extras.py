"""Optional libraries: imported where they are used, and a missing one named by its extra.

The core (the twin, the daemon, its API, the Modbus backend) needs none of them. The
extras of the package bring them: ``export`` (VTK, TexGen's pytexgen, matplotlib) for the
.vtp, .vtu and .tg3 exports and ``bwsd slice``; ``canopen`` (canopen, python-can) for the
CANopen backend and the mock loom's CANopen drives; ``opcua`` (asyncua) for the OPC UA
server.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from bwsd.errors import BwsdError, ExtraMissingError

__all__ = ["CANOPEN", "MATPLOTLIB", "OPCUA", "TEXGEN", "VTK", "Library", "missing_message", "needs"]


@dataclass(frozen=True)
class Library:
    """An optional library: its name for people, its top-level modules, the extra with it."""

    name: str
    modules: tuple[str, ...]
    extra: str


VTK = Library("VTK", ("vtkmodules", "vtk"), "export")
TEXGEN = Library("TexGen (pytexgen)", ("pytexgen",), "export")
MATPLOTLIB = Library("matplotlib", ("matplotlib",), "export")
CANOPEN = Library("canopen and python-can", ("canopen", "can"), "canopen")
OPCUA = Library("asyncua", ("asyncua",), "opcua")


def missing_message(what: str, library: Library) -> str:
    """``writing .vtu needs VTK: pip install 'bwsd[export]'``."""
    return f"{what} needs {library.name}: pip install 'bwsd[{library.extra}]'"


@contextmanager
def needs(
    library: Library, what: str, error: Callable[[str], BwsdError] = ExtraMissingError
) -> Iterator[None]:
    """Turn the import of a missing ``library`` inside the block into ``error``.

    Only a module of ``library`` counts as missing: any other failed import is raised as
    it is, so a broken install is not taken for a missing extra.
    """
    try:
        yield
    except ModuleNotFoundError as exc:
        if (exc.name or "").partition(".")[0] not in library.modules:
            raise
        raise error(missing_message(what, library)) from exc
