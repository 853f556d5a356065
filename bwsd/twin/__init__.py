"""The digital twin: the collision model of docs/twin.md, on an exact grid, in compiled code.

Its names are imported when first used: ``bwsd.twin.machine`` and
``bwsd.twin.instructions`` (what the config, the program parser and the generators need)
stay light, and numpy and the compiled kernel are loaded only with the model itself.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bwsd.twin.instructions import Instruction, Program, Shift, TakeUp, Weft
    from bwsd.twin.machine import Machine
    from bwsd.twin.model import Twin, replay, simulate
    from bwsd.twin.prediction import NodeInsert, Prediction, Snapshot
    from bwsd.twin.skeleton import ContactData, SkeletonData, YarnData

_WHERE = {
    "Instruction": "instructions",
    "Program": "instructions",
    "Shift": "instructions",
    "TakeUp": "instructions",
    "Weft": "instructions",
    "Machine": "machine",
    "Twin": "model",
    "replay": "model",
    "simulate": "model",
    "NodeInsert": "prediction",
    "Prediction": "prediction",
    "Snapshot": "prediction",
    "ContactData": "skeleton",
    "SkeletonData": "skeleton",
    "YarnData": "skeleton",
}

__all__ = [
    "ContactData",
    "Instruction",
    "Machine",
    "NodeInsert",
    "Prediction",
    "Program",
    "Shift",
    "SkeletonData",
    "Snapshot",
    "TakeUp",
    "Twin",
    "Weft",
    "YarnData",
    "replay",
    "simulate",
]


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
    globals()[name] = value  # found once
    return value
