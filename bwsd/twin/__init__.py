"""The digital twin: the collision model of docs/twin.md, on an exact grid, in compiled code."""

from bwsd.twin.instructions import Instruction, Program, Shift, TakeUp, Weft
from bwsd.twin.machine import Machine
from bwsd.twin.model import Twin, replay, simulate
from bwsd.twin.prediction import NodeInsert, Prediction, Snapshot
from bwsd.twin.skeleton import ContactData, SkeletonData, YarnData

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
