"""The OPC UA address space checked against docs/opcua.md's node id table: the code's tags
and methods, and a live server browsed by users of each role.

The node ids, types, access and arguments come from the doc: a node renamed, retyped or
added in the code without the doc fails here.
"""

from __future__ import annotations

import re
from typing import Any

import pytest
from asyncua import Client, Node, ua

from bwsd.opcua import space
from bwsd.opcua.space import NAMESPACE
from tests.doc_tables import doc_table
from tests.opcua.conftest import rig, run

TABLE = doc_table("opcua.md", "node id (ns=2;s=...)", "type", "access", "meaning")
NODES = {row["node id (ns=2;s=...)"]: row for row in TABLE}
VARIABLES = {
    n: r
    for n, r in NODES.items()
    if r["type"] not in ("object",) and not r["type"].startswith("method")
}
METHODS = {n: r for n, r in NODES.items() if r["type"].startswith("method")}
RANK = {"viewer": 0, "operator": 1, "admin": 2}
PROPERTIES = tuple(
    ua.QualifiedName(name, 0) for name in ("EngineeringUnits", "InputArguments", "OutputArguments")
)


def documented_type(tag: space.Tag) -> str:
    """A tag's type as the doc writes it: ``Int32``, ``String[]``, ``Double[18]``."""
    if not isinstance(tag.start, list):
        return tag.kind.name
    return f"{tag.kind.name}[{len(tag.start) or ''}]"


def arguments(text: str) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """``method (Name: String, Text: String) -> ProgramId: UInt32`` as (inputs, outputs)."""
    found = re.fullmatch(r"method \((.*)\)(?: -> (.*))?", text)
    assert found, text

    def pairs(part: str | None) -> list[tuple[str, str]]:
        named = []
        for p in (part or "").split(", "):
            if p:
                name, kind = p.split(": ")
                named.append((name, kind))
        return named

    return pairs(found[1]), pairs(found[2])


def test_the_code_declares_exactly_the_documented_nodes():
    tags = {"Loom." + t.path.replace("/", "."): t for t in space.TAGS}
    assert set(tags) == set(VARIABLES), "a variable the doc lacks, or one the code lacks"
    for node, tag in tags.items():
        row = VARIABLES[node]
        assert row["type"] == documented_type(tag), node
        assert row["access"] == ("R" if tag.writer is None else f"RW {tag.writer}"), node
    needs = {str(n.Identifier): role for n, role in space.needs(2).items()}
    methods = {f"Loom.{c.label}" for c in space.COMMAND_METHODS}
    methods |= {f"Loom.{space.RESUME}", f"Loom.{space.LOAD_PROGRAM}", f"Loom.{space.SET_UNIT_MODE}"}
    assert methods == set(METHODS)
    for node, row in METHODS.items():
        assert needs[node] == row["access"], node
    for node, row in VARIABLES.items():
        writer = row["access"].removeprefix("RW ") if row["access"] != "R" else None
        assert needs.get(node) == writer, node


async def browse(client: Client, node: ua.NodeId) -> set[str]:
    """Every object, variable and method under ``node`` (properties left out), by id."""
    found: set[str] = set()
    for child in await client.get_node(node).get_children():
        if await child.read_browse_name() in PROPERTIES:
            continue
        found.add(str(child.nodeid.Identifier))
        found |= await browse(client, child.nodeid)
    return found


@pytest.mark.slow
def test_a_live_server_serves_every_documented_node_as_documented(mock, tmp_path):
    async def scenario() -> None:
        async with rig(mock, tmp_path) as r:
            for role in RANK:
                async with r.session(role) as client:
                    idx = await client.get_namespace_index(NAMESPACE)
                    assert idx == 2  # as the doc's node ids write it
                    root = ua.NodeId(ua.String("Loom"), ua.Int16(idx))
                    assert {"Loom"} | await browse(client, root) == set(NODES)
                    for name, row in NODES.items():
                        await check_node(
                            client, ua.NodeId(ua.String(name), ua.Int16(idx)), row, role
                        )

    run(scenario())


async def attribute(node: Node, which: ua.AttributeIds) -> Any:
    """The value of the node's attribute ``which`` (read with a value: the test asks for
    attributes the node has)."""
    value = (await node.read_attribute(which)).Value
    assert value is not None, which
    return value.Value


def _type_name(data_type: ua.NodeId) -> str:
    """A standard data type's name (its node id is numeric in namespace 0)."""
    assert isinstance(data_type.Identifier, int), data_type
    return ua.ObjectIdNames[data_type.Identifier]


async def check_node(client: Client, node_id: ua.NodeId, row: dict[str, str], role: str) -> None:
    node = client.get_node(node_id)
    kind = await node.read_node_class()
    typed = row["type"]
    if typed == "object":
        assert kind == ua.NodeClass.Object, row
        return
    if typed.startswith("method"):
        assert kind == ua.NodeClass.Method, row
        inputs, outputs = arguments(typed)
        for prop, expected in (("InputArguments", inputs), ("OutputArguments", outputs)):
            try:
                held = await (await node.get_child(f"0:{prop}")).read_value()
            except ua.UaStatusCodeError:
                held = []
            got = [(a.Name, _type_name(a.DataType)) for a in held]
            assert got == expected, (row, prop)
        executable = await attribute(node, ua.AttributeIds.UserExecutable)
        assert executable is (RANK[role] >= RANK[row["access"]]), (row, role)
        return
    assert kind == ua.NodeClass.Variable, row
    base, _, length = typed.partition("[")
    data_type = await node.read_data_type()
    assert _type_name(data_type) == base, row
    rank = await attribute(node, ua.AttributeIds.ValueRank)
    assert rank == (1 if length else -1), row
    if length:
        dims = await attribute(node, ua.AttributeIds.ArrayDimensions)
        assert dims == [int(length.rstrip("]") or 0)], row
    level = await attribute(node, ua.AttributeIds.UserAccessLevel)
    writes = bool(level & ua.AccessLevel.CurrentWrite.mask)
    writer = row["access"].removeprefix("RW ") if row["access"] != "R" else None
    assert writes is (writer is not None and RANK[role] >= RANK[writer]), (row, role)
