"""The event fan-out (drop the oldest, count, report) and the skeleton deltas, without a server."""

from __future__ import annotations

import asyncio
import json
import re
from pathlib import Path

import pytest

from bwsd.api.events import EventHub, Subscriber
from bwsd.export.skeleton_json import delta_to_dict as prediction_delta
from bwsd.export.skeleton_json import skeleton_to_dict
from bwsd.program import parse_program
from bwsd.twin import Machine, Program, Twin
from tests.api.skeletons import apply_delta, yarns_of

ROOT = Path(__file__).resolve().parents[2]


def test_a_full_queue_drops_the_oldest_and_says_how_many():
    async def scenario() -> None:
        sub = Subscriber(3)
        kept = [sub.push(json.dumps({"n": n})) for n in range(5)]
        assert kept == [True, True, True, False, False]
        assert sub.dropped == 2
        first = await sub.next()
        assert [json.loads(t) for t in first] == [
            {"event": "dropped", "count": 2, "total": 2},
            {"n": 2},
        ]
        assert [json.loads(t) for t in await sub.next()] == [{"n": 3}]  # told once
        sub.push(json.dumps({"n": 5}))
        assert [json.loads(t) for t in await sub.next()] == [{"n": 4}]

    asyncio.run(scenario())


def test_publish_never_waits_for_a_client_and_counts_every_drop():
    async def scenario() -> None:
        drops: list[int] = []
        hub = EventHub(size=2, on_drop=lambda: drops.append(1))
        slow, fast = hub.subscribe(), hub.subscribe()
        for n in range(4):
            hub.publish({"event": "state", "n": n})
            assert json.loads((await fast.next())[-1])["n"] == n
        assert slow.queue.qsize() == 2 and slow.dropped == 2 and fast.dropped == 0
        assert len(drops) == 2
        hub.unsubscribe(slow)
        hub.publish({"event": "state", "n": 4})
        assert hub.clients == 1 and slow.queue.qsize() == 2

    asyncio.run(scenario())


@pytest.mark.parametrize("example", ["braid-2x2.bws", "weave-plain.bws"])
def test_the_deltas_rebuild_every_skeleton_of_a_run(example):
    machine, program, text = _example(example)
    twin = Twin.from_program(machine, program)
    before = twin.skeleton()
    yarns = yarns_of(skeleton_to_dict(before))  # the tests' own reading of the deltas
    kinds: set[str] = set()
    for instruction in program.instructions[:40]:
        delta = json.loads(json.dumps(prediction_delta(twin, twin.apply(instruction))))
        after = twin.skeleton()
        assert delta["since"] == after.instructions - 1
        kinds.update(k for k in ("inserted", "moved", "new_yarns", "contacts") if delta[k])
        apply_delta(yarns, delta)
        assert yarns == yarns_of(skeleton_to_dict(after))
    assert {"inserted", "moved", "contacts"} <= kinds
    assert ("new_yarns" in kinds) == ("WEFT" in text)


def test_a_delta_lists_only_what_the_instruction_changed():
    machine, program, _ = _example("braid-2x2.bws")
    twin = Twin.from_program(machine, program)
    for instruction in program.instructions[:20]:
        before = twin.skeleton()
        pred = twin.apply(instruction)
        delta = prediction_delta(twin, pred)
        assert len(delta["inserted"]) == len(pred.inserted)
        assert len(delta["contacts"]) == len(pred.contacts)
        moved = {m["yarn"] for m in delta["moved"]}
        old = {y.id: y.nodes[-1].tolist() for y in before.yarns}
        new = {y.id: y.nodes[-1].tolist() for y in twin.skeleton().yarns}
        assert {y for y in old if old[y] != new[y]} <= moved <= set(pred.free_nodes)


def test_inserts_come_in_yarn_order_when_one_yarn_is_hit_twice():
    """A second hit before the first one on the same yarn still finds its predecessor."""
    machine, program, _ = _example("braid-2x2.bws")
    twin = Twin.from_program(machine, program)
    seen_twice = False
    for instruction in program.instructions:
        pred = twin.apply(instruction)
        by_yarn: dict[int, list[int]] = {}
        for node in pred.inserted:
            by_yarn.setdefault(node.yarn, []).append(node.node)
        order = {y.id: y.node_ids.tolist() for y in twin.skeleton().yarns}
        for yarn, nodes in by_yarn.items():
            where = [order[yarn].index(n) for n in nodes]
            assert where == sorted(where)
            seen_twice |= len(nodes) > 1 and nodes != sorted(nodes)
    assert seen_twice, "no instruction of the example inserted out of id order"


def _example(name: str) -> tuple[Machine, Program, str]:
    text = (ROOT / "examples" / name).read_text()
    header = text.split("# machine: ")[1].split("\n")[0]
    return _machine(header), parse_program(text), text


def _machine(header: str) -> Machine:
    """The machine of an example's "# machine:" line."""
    found = re.fullmatch(
        r"(\d+) x (\d+) cells, pitch (\S+) x (\S+) mm, d_mat (\S+) mm, "
        r"c_mat (\S+)",
        header.strip(),
    )
    assert found is not None, header
    rows, cols = int(found[1]), int(found[2])
    pitch_x, pitch_y, d_mat, c_mat = (float(found[i]) for i in range(3, 7))
    return Machine(
        rows=rows,
        cols=cols,
        pitch_x=pitch_x,
        pitch_y=pitch_y,
        d_mat=d_mat,
        c_mat=c_mat,
        yarn_diameter=1.0,
    )
