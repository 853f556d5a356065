"""The event fan-out (drop the oldest, count, report) and the skeleton deltas, without a server."""

from __future__ import annotations

import asyncio
import json
import re
from pathlib import Path

import pytest

from bwsd.api.events import EventHub, Subscriber
from bwsd.api.view import skeleton_delta
from bwsd.export.skeleton_json import skeleton_to_dict
from bwsd.program import parse_program
from bwsd.twin import Machine, Twin
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
    text = (ROOT / "examples" / example).read_text()
    header = text.split("# machine: ")[1].split("\n")[0]
    machine = _machine(header)
    program = parse_program(text)
    twin = Twin.from_program(machine, program)
    before = twin.skeleton()
    yarns = yarns_of(skeleton_to_dict(before))
    kinds: set[str] = set()
    for instruction in program.instructions[:40]:
        twin.apply(instruction)
        after = twin.skeleton()
        delta = skeleton_delta(before, after)
        assert delta["since"] == before.instructions
        kinds.update(k for k in ("inserted", "moved", "new_yarns", "contacts") if delta[k])
        apply_delta(yarns, json.loads(json.dumps(delta)))
        assert yarns == yarns_of(skeleton_to_dict(after))
        before = after
    assert {"inserted", "moved", "contacts"} <= kinds
    assert ("new_yarns" in kinds) == ("WEFT" in text)


def test_a_delta_from_nothing_holds_every_yarn():
    machine = Machine(rows=4, cols=4, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5)
    twin = Twin(machine, [(1, 1), (2, 2)])
    delta = skeleton_delta(None, twin.skeleton())
    assert [y["id"] for y in delta["new_yarns"]] == [0, 1]
    assert delta["inserted"] == [] and delta["moved"] == [] and delta["since"] == 0


def _machine(header: str) -> Machine:
    """The machine of an example's "# machine:" line."""
    found = re.fullmatch(r"(\d+) x (\d+) cells, pitch (\S+) x (\S+) mm, d_mat (\S+) mm, "
                         r"c_mat (\S+)", header.strip())  # fmt: skip
    assert found is not None, header
    rows, cols = int(found[1]), int(found[2])
    pitch_x, pitch_y, d_mat, c_mat = (float(found[i]) for i in range(3, 7))
    return Machine(rows=rows, cols=cols, pitch_x=pitch_x, pitch_y=pitch_y, d_mat=d_mat,
                   c_mat=c_mat, yarn_diameter=1.0)  # fmt: skip
