"""The CANopen drives checked against docs/fieldbus-canopen.md's "Drives" table.

bwsd's backend and the mock loom number their nodes from the same axes, so a test through
either cannot see a node that moved in both. These tests read the node of every axis from
the doc, check bwsd's node ids against it, and drive the positioning axes of a live mock
loom (its own process, over its socketcand hub) with a bare canopen master at the nodes
written there.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterator
from pathlib import Path

import canopen
import pytest

from bwsd.config import parse_config
from bwsd.fieldbus.axes import machine_axes
from bwsd.fieldbus.canopen import CanopenBus
from bwsd.fieldbus.cia402 import DRIVE_OBJECTS, Cia402, dictionary
from bwsd.twin.machine import Machine, Segment
from simulator_hw.control import request
from tests.doc_tables import doc_table
from tests.support.fieldbus import MACHINE, Mock, start_mock

DOC = "fieldbus-canopen.md"
DRIVES = doc_table(DOC, "axis", "node", "target (0x607A)", after="## Drives")
DRIVE_OBJECT = {
    row["name"]: int(row["index"], 16)
    for row in doc_table(DOC, "index", "name", "type", after="## Drive objects")
}


def node_of(expression: str, **names: int) -> int:
    """A node as the table writes it (``node_base + R + C + S + 3``), for ``names``."""
    terms = [term.strip() for term in expression.split("+")]
    return sum(int(t) if t.isdigit() else names[t] for t in terms)


def documented_nodes(machine: Machine, node_base: int) -> dict[int, str]:
    """{node: axis name} for every drive of ``machine`` the table places."""
    sizes = dict(node_base=node_base, R=machine.rows, C=machine.cols, S=len(machine.segments))
    found: dict[int, str] = {}
    for row in DRIVES:
        name, expression = row["axis"], row["node"]
        if name == "row r":
            found |= {node_of(expression, r=r, **sizes): f"row{r}" for r in range(machine.rows)}
        elif name == "col c":
            found |= {node_of(expression, c=c, **sizes): f"col{c}" for c in range(machine.cols)}
        elif name == "segment j":
            for j, seg in enumerate(machine.segments):
                found[node_of(expression, j=j, **sizes)] = (
                    f"{seg.axis}{seg.line}[{seg.lo}..{seg.hi}]"
                )
        else:
            found[node_of(expression, **sizes)] = name
    return found


def test_every_drive_has_the_node_the_table_gives_it():
    corner = ["ROW 3[0..3]", "COL 3[0..3]"]
    machine = {"rows": 8, "cols": 8, "pitch_x": 10, "pitch_y": 12, "d_mat": 100, "c_mat": 0.5}
    for segments, base in (([], 1), (corner, 1), (corner, 40)):
        bus_table = {"backend": "canopen", "canopen": {"node_base": base}}
        config = parse_config({"machine": {**machine, "segments": segments}, "fieldbus": bus_table})
        bus = CanopenBus.from_config(config)
        names = [axis.name for axis in machine_axes(config.machine)]
        assert dict(zip(bus.drive_ids, names, strict=True)) == documented_nodes(
            config.machine, base
        )
    corner_axes = (Segment("row", 3, 0, 3), Segment("col", 3, 0, 3))
    nodes = documented_nodes(Machine(8, 8, 10, 12, 100, 0.5, segments=corner_axes), 1)
    example = ["row3[0..3]", "col3[0..3]", "weft_x", "weft_y", "weft_z"]  # the doc's
    assert [nodes[n] for n in (20, 21, 22, 23, 24)] == example
    absolute = [row["axis"] for row in DRIVES if row["target (0x607A)"].startswith("absolute")]
    assert absolute == ["weft_angle", "takeup", "weft_x", "weft_y", "weft_z"]


@pytest.fixture
def mock(tmp_path: Path) -> Iterator[Mock]:
    running = start_mock(tmp_path, {"weft_travel_speed": 500.0}, canopen=True)
    yield running
    running.stop()


@pytest.mark.slow
def test_a_live_loom_places_the_inserter_at_the_documented_nodes(mock):
    """Each positioning drive at its documented node: enabled, given an absolute target by
    SDO (0x607A, 0x2003, controlword 0x1F then 0x0F), it travels there and stays."""
    nodes = {name: node for node, name in documented_nodes(Machine(**MACHINE), 1).items()}
    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.05
    drives = {
        name: canopen.RemoteNode(nodes[name], dictionary(DRIVE_OBJECTS))
        for name in ("weft_x", "weft_y", "weft_z")
    }
    for drive in drives.values():
        network.add_node(drive)
    port = mock.ports["socketcand"]
    network.connect(interface="socketcand", host="127.0.0.1", port=port, channel="can0")
    try:
        network.nmt.send_command(0x01)  # start remote nodes: operation enabled needs it
        time.sleep(0.2)
        targets = {"weft_x": 36_000, "weft_y": -8_250, "weft_z": 30_000}
        for seq, (name, target) in enumerate(targets.items(), start=1):
            move(drives[name], target, seq)
        state = asyncio.run(request("127.0.0.1", mock.ports["control"], {"cmd": "state"}))
        assert {name: state["axes"][name]["position"] for name in targets} == targets
        assert not any(state["axes"][name]["busy"] for name in targets)
    finally:
        network.disconnect()


def move(node: canopen.RemoteNode, target: int, seq: int) -> None:
    """An absolute set-point by SDO, as the doc writes it; waits for its done sequence."""
    obj = DRIVE_OBJECT
    node.sdo[obj["modes of operation"]].raw = 1
    for word in (0x06, 0x07, 0x0F):
        node.sdo[obj["controlword"]].raw = word
    assert Cia402.of(node.sdo[obj["statusword"]].raw) is Cia402.OPERATION_ENABLED
    node.sdo[obj["target position"]].raw = target
    node.sdo[obj["set-point sequence"]].raw = seq
    node.sdo[obj["controlword"]].raw = 0x1F  # new set-point, absolute
    node.sdo[obj["controlword"]].raw = 0x0F
    deadline = time.monotonic() + 10
    while node.sdo[obj["done sequence"]].raw != seq:
        assert time.monotonic() < deadline, f"node {node.id} never completed"
        time.sleep(0.01)
    assert node.sdo[obj["position actual"]].raw == target
    assert node.sdo[obj["last stroke"]].raw == 0  # absolute: no stroke
