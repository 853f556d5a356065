"""The PackML object's address space: every variable and method, and who may write or call it.

The layout follows OPC 30050 (PackML): one object with Status, Command and Admin, PackTags
names (ISA-TR88.00.02), the commands also as methods; what PackML does not cover is in
``Machine``. Node ids are strings in the bwsd namespace (``ns=<bwsd>;s=Loom.Status.
StateCurrent``), fixed, so a PLC can address them without browsing. docs/opcua.md shows
the tree.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from asyncua import Node, Server, ua

from bwsd.controller.packml import Command, State, UnitMode
from bwsd.tokens import Role

NAMESPACE = "urn:bwsd:packml"
ROOT = "Loom"
UNITS_NAMESPACE = "http://www.opcfoundation.org/UA/units/un/cefact"

V = ua.VariantType


@dataclass(frozen=True)
class Tag:
    """One variable: its path under the PackML object, type, start value, unit, writer."""

    path: str
    kind: ua.VariantType
    start: Any
    about: str
    unit: tuple[str, str] = ("", "")  # (UNECE code, symbol)
    writer: Role | None = None  # who may write it (None: read-only)


SECONDS = ("SEC", "s")
TAGS: tuple[Tag, ...] = (
    Tag("Status/StateCurrent", V.Int32, int(State.STOPPED), "PackML state number (1..17)"),
    Tag(
        "Status/UnitModeCurrent",
        V.Int32,
        int(UnitMode.PRODUCTION),
        "unit mode: 1 Production, 2 Maintenance, 3 Manual",
    ),
    Tag(
        "Status/CurMachSpeed",
        V.Double,
        0.0,
        "instructions done in the last minute",
        ("C94", "1/min"),
    ),
    Tag("Status/InstructionsDone", V.UInt32, 0, "instructions of the loaded program done"),
    Tag("Status/InstructionCount", V.UInt32, 0, "instructions of the loaded program"),
    Tag("Status/CurrentInstruction", V.UInt32, 0, "the instruction that runs next (0: none)"),
    Tag("Status/CurrentLine", V.UInt32, 0, "its line in the program text (0: none)"),
    Tag("Status/Program", V.String, "", "name of the loaded program"),
    Tag("Status/ProgramId", V.UInt32, 0, "its id in the journal (0: none)"),
    Tag(
        "Status/StateRequested",
        V.Int32,
        int(State.STOPPED),
        "the state the machine is going to: the one an acting state ends in, else the state",
    ),
    Tag(
        "Status/StateChangeInProcess",
        V.Boolean,
        False,
        "an acting state (Resetting, Starting, Holding...) is doing its work",
    ),
    Tag(
        "Status/UnitModeRequested",
        V.Int32,
        int(UnitMode.PRODUCTION),
        "the unit mode last requested (by any door)",
    ),
    Tag("Status/CmdInvalid", V.Boolean, False, "the last command or mode request was refused"),
    Tag("Status/CmdInvalidReason", V.String, "", "why it was refused"),
    Tag(
        "Command/CntrlCmd",
        V.Int32,
        0,
        "PackML command number (1 Reset .. 9 Clear)",
        writer="operator",
    ),
    Tag(
        "Command/CmdChangeRequest",
        V.Boolean,
        False,
        "write true to apply CntrlCmd; reads false once taken",
        writer="operator",
    ),
    Tag(
        "Command/UnitMode", V.Int32, int(UnitMode.PRODUCTION), "requested unit mode", writer="admin"
    ),
    Tag(
        "Command/UnitModeChangeRequest",
        V.Boolean,
        False,
        "write true to apply UnitMode; reads false once taken",
        writer="admin",
    ),
    Tag("Admin/StopReason/ID", V.Int32, 0, "stop reason code (docs/plc.md)"),
    Tag("Admin/StopReason/Value", V.String, "none", "stop reason code's name"),
    Tag("Admin/StopReason/Message", V.String, "", "the reason as the controller gave it"),
    Tag("Admin/Warning", V.String, [], "what an operator should know now"),
    Tag("Admin/StateCurrentTime", V.Double, 0.0, "time in the current state", SECONDS),
    Tag(
        "Admin/StateCumulativeTime",
        V.Double,
        [0.0] * (len(State) + 1),
        "time in each state since the start, by state number",
        SECONDS,
    ),
    Tag("Admin/AccTimeSinceReset", V.Double, 0.0, "time since the door started", SECONDS),
    Tag("Admin/ProdProcessedCount", V.UInt32, 0, "programs that ended after they ran"),
    Tag("Admin/ProdGoodCount", V.UInt32, 0, "programs that reached Complete"),
    Tag("Admin/ProdDefectiveCount", V.UInt32, 0, "programs stopped or aborted after they ran"),
    Tag("Admin/ProgramHistory", V.String, [], "the last programs: id name outcome done/count"),
    Tag("Machine/EStop", V.Boolean, False, "the emergency stop is pressed (as last read)"),
    Tag("Machine/BusConnected", V.Boolean, False, "the machine answered the last read"),
    Tag("Machine/BusLastError", V.String, "", "the last bus failure"),
    Tag("Machine/FaultedAxes", V.String, [], "axes reporting a fault"),
    Tag("Machine/SensorsDiffer", V.String, [], "cells 'row,col' where sensors and twin differ"),
    Tag("Machine/Recovering", V.String, "", "why commands wait after a restart"),
    Tag(
        "Status/Resumable",
        V.Boolean,
        False,
        "the Resume method continues the loaded program where an Abort or a Stop left it",
    ),
    Tag("Machine/Rows", V.UInt32, 0, "rows of the matrix"),
    Tag("Machine/Cols", V.UInt32, 0, "columns of the matrix"),
    Tag("Machine/TwinOccupancy", V.Int32, [], "yarn id per cell, row by row, -1 where empty"),
    Tag("Machine/TakeUp", V.Double, 0.0, "take-up of the loaded program so far", ("MMT", "mm")),
    Tag("Machine/Contacts", V.UInt32, 0, "yarn contacts of the loaded program so far"),
)

# The methods: the PackML commands, Resume and LoadProgram (operator), SetUnitMode (admin).
COMMAND_METHODS: tuple[Command, ...] = tuple(Command)
RESUME = "Resume"  # Start, continuing the loaded program where an Abort or a Stop left it
LOAD_PROGRAM = "LoadProgram"  # (Name: String, Text: String) -> ProgramId: UInt32
SET_UNIT_MODE = "SetUnitMode"
MethodCall = Callable[..., Awaitable[Any]]


def node_id(idx: int, path: str) -> ua.NodeId:
    """``Loom.Status.StateCurrent`` in the bwsd namespace; ``Loom`` for the object itself."""
    return ua.NodeId(ua.String(".".join((ROOT, *path.split("/"))) if path else ROOT), ua.Int16(idx))


def standard_id(number: int) -> ua.NodeId:
    """A node of OPC UA's own namespace (0) by its number (``ua.ObjectIds``)."""
    return ua.NodeId(ua.Int32(number))


def status(code: int) -> ua.StatusCode:
    return ua.StatusCode(ua.UInt32(code))


def unit_id(code: str) -> int:
    """The UNECE code as OPC UA's EUInformation.UnitId (OPC 10000-8)."""
    value = 0
    for char in code:
        value = (value << 8) | ord(char)
    return value


def needs(idx: int) -> dict[ua.NodeId, Role]:
    """The role each writable variable and each method needs."""
    table: dict[ua.NodeId, Role] = {node_id(idx, t.path): t.writer for t in TAGS if t.writer}
    for command in COMMAND_METHODS:
        table[node_id(idx, command.label)] = "operator"
    table[node_id(idx, RESUME)] = "operator"
    table[node_id(idx, LOAD_PROGRAM)] = "operator"
    table[node_id(idx, SET_UNIT_MODE)] = "admin"
    return table


@dataclass
class Space:
    """The built address space: the namespace index and the variables by path."""

    idx: int
    variables: dict[str, Node]


@dataclass(frozen=True)
class Methods:
    """What the object's methods call."""

    command: Callable[[Command], MethodCall]
    set_mode: MethodCall
    resume: MethodCall
    load: MethodCall


async def build(server: Server, methods: Methods) -> Space:
    """Add the PackML object under Objects with its variables and methods."""
    idx = await server.register_namespace(NAMESPACE)
    root = await server.nodes.objects.add_object(node_id(idx, ""), ua.QualifiedName(ROOT, idx))
    objects: dict[str, Node] = {"": root}
    variables: dict[str, Node] = {}
    for tag in TAGS:
        parent = await _parent(objects, idx, tag.path.rpartition("/")[0])
        variables[tag.path] = await _variable(parent, idx, tag)
    for command in COMMAND_METHODS:
        await root.add_method(
            node_id(idx, command.label),
            ua.QualifiedName(command.label, idx),
            methods.command(command),
            [],
            [],
        )
    await root.add_method(
        node_id(idx, RESUME), ua.QualifiedName(RESUME, idx), methods.resume, [], []
    )
    about = ua.LocalizedText("1 Production, 2 Maintenance, 3 Manual")
    mode = ua.Argument(
        Name="UnitMode", DataType=standard_id(ua.ObjectIds.Int32), ValueRank=-1, Description=about
    )
    await root.add_method(
        node_id(idx, SET_UNIT_MODE),
        ua.QualifiedName(SET_UNIT_MODE, idx),
        methods.set_mode,
        [mode],
        [],
    )
    load_in = [
        _argument("Name", ua.ObjectIds.String, "the program's name"),
        _argument("Text", ua.ObjectIds.String, "the program's .bws text"),
    ]
    load_out = [_argument("ProgramId", ua.ObjectIds.UInt32, "its id in the journal")]
    await root.add_method(
        node_id(idx, LOAD_PROGRAM),
        ua.QualifiedName(LOAD_PROGRAM, idx),
        methods.load,
        load_in,
        load_out,
    )
    return Space(idx, variables)


def _argument(name: str, kind: int, about: str) -> ua.Argument:
    return ua.Argument(
        Name=name, DataType=standard_id(kind), ValueRank=-1, Description=ua.LocalizedText(about)
    )


async def _parent(objects: dict[str, Node], idx: int, path: str) -> Node:
    """The object at ``path``, made (with its parents) on first use."""
    if path not in objects:
        above, _, name = path.rpartition("/")
        parent = await _parent(objects, idx, above)
        objects[path] = await parent.add_object(node_id(idx, path), ua.QualifiedName(name, idx))
    return objects[path]


async def _variable(parent: Node, idx: int, tag: Tag) -> Node:
    name = tag.path.rpartition("/")[2]
    node = await parent.add_variable(
        node_id(idx, tag.path), ua.QualifiedName(name, idx), ua.Variant(tag.start, tag.kind)
    )
    if isinstance(tag.start, list):  # an array: one dimension, its length where fixed (else 0)
        rank, length = ua.Variant(1, V.Int32), ua.Variant([len(tag.start)], V.UInt32)
        await node.write_attribute(ua.AttributeIds.ValueRank, ua.DataValue(rank))
        await node.write_attribute(ua.AttributeIds.ArrayDimensions, ua.DataValue(length))
    await node.write_attribute(
        ua.AttributeIds.Description, ua.DataValue(ua.Variant(ua.LocalizedText(tag.about)))
    )
    if tag.writer:
        await node.set_writable()
    if tag.unit[0]:
        code, symbol = tag.unit
        units = ua.EUInformation(
            NamespaceUri=UNITS_NAMESPACE,
            UnitId=unit_id(code),
            DisplayName=ua.LocalizedText(symbol),
            Description=ua.LocalizedText(symbol),
        )
        await node.add_property(
            node_id(idx, f"{tag.path}/EngineeringUnits"),
            ua.QualifiedName("EngineeringUnits", 0),
            units,
        )
    return node
