"""A generated braid-weave program through the whole daemon: `bwsd serve` on the mock loom.

An L section braided on its corner segments, with a layer of 0 degree wefts and then one of
90 degree wefts, runs to Complete over HTTP; the served skeleton equals `simulate`'s, the
mock loom's cases are where the twin has them, and the loom's weft inserter went in at
each layer's angle.
"""

from __future__ import annotations

import asyncio
import threading
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bwsd.api.auth import TokenStore
from bwsd.export.skeleton_json import skeleton_to_dict
from bwsd.fieldbus.axes import MDEG_PER_DEG
from bwsd.program import parse_program
from bwsd.program.braidweave import braid_weave
from bwsd.program.render import Generated
from bwsd.twin import simulate
from simulator_hw.control import request
from tests.support.fieldbus import BUS, Mock, start_mock, toml
from tests.test_daemon import Served, same_geometry

pytestmark = pytest.mark.slow  # every test here is in the slow tier

# Strokes take time (a 10 mm shift 50 ms, the shortest weft, 14 mm, 70 ms out and as long
# back), so that the watcher below sees every insert stroke under way.
SPEEDS = {"stroke_speed": 200.0, "takeup_speed": 400.0}


@pytest.fixture(scope="module")
def generated() -> Generated:
    return braid_weave(shape="L", flange=(2, 6), web=(4, 2), cycles=4, weft_every=2, angles=(0, 90))


def machine_table(generated: Generated) -> dict[str, Any]:
    """The ``[machine]`` table of the program's config, its segments included."""
    table: dict[str, Any] = tomllib.loads(generated.config_toml())["machine"]
    return table


def daemon_config(tmp: Path, mock: Mock, machine: dict[str, Any]) -> Path:
    path = tmp / "bwsd.toml"
    path.write_text(
        toml(
            {
                "machine": machine,
                "fieldbus": {"backend": "modbus", **BUS},
                "fieldbus.modbus": {"port": mock.ports["modbus"]},
                "api": {"port": 0},
                "plc": {"port": 0},
            }
        )
    )
    return path


class InsertWatch(threading.Thread):
    """Polls the mock loom's control channel while the program runs: the weft angle (and
    whether it was still turning) each time the insert axis is seen out of home."""

    def __init__(self, control: tuple[str, int]) -> None:
        super().__init__(daemon=True, name="insert-watch")
        self.control = control
        self.seen: list[tuple[int, bool]] = []  # (weft_angle position in mdeg, turning)
        self.stop = threading.Event()
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            asyncio.run(self._watch())
        except BaseException as exc:
            self.error = exc

    async def _watch(self) -> None:
        while not self.stop.is_set():
            answer = await request(*self.control, {"cmd": "state"})
            axes = answer["axes"]
            if axes["weft_insert"]["position"] != 0:
                angle = axes["weft_angle"]
                self.seen.append((angle["position"], angle["busy"]))
            await asyncio.sleep(0.003)

    def angles(self) -> list[int]:
        """The angles seen during insert strokes, each run of equal ones once."""
        runs = [angle for angle, _ in self.seen]
        return [a for i, a in enumerate(runs) if i == 0 or runs[i - 1] != a]


@pytest.fixture
def rig(tmp_path: Path, generated: Generated) -> Iterator[tuple[Served, Mock]]:
    machine = machine_table(generated)
    mock = start_mock(tmp_path, SPEEDS, machine=machine, program=generated.program)
    state = tmp_path / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    served = Served(daemon_config(tmp_path, mock, machine), state, token)
    try:
        yield served, mock
    finally:
        served.stop()
        mock.stop()


def test_the_config_carries_the_corner_segments(generated: Generated):
    table = machine_table(generated)
    assert table["segments"] == ["COL 3[0..3]", "ROW 3[0..3]"]
    assert "ROW 1:+1 2:-1 3[0..3]:+1" in generated.program
    wefts = [line.split() for line in generated.program.splitlines() if "WEFT" in line]
    assert {w[4] for w in wefts} == {"angle=0", "angle=90"}


@pytest.mark.slow
def test_a_braid_weave_on_segments_runs_to_complete_and_equals_simulate(rig, generated):
    served, mock = rig
    program = parse_program(generated.program)
    twin = simulate(generated.machine, program)
    loaded = served.http.post(
        "/programs", json={"name": "braid-weave.bws", "text": generated.program}
    )
    assert loaded.status_code == 201, loaded.text
    served.command("reset")
    watch = InsertWatch(("127.0.0.1", mock.ports["control"]))
    watch.start()
    try:
        served.command("start")
        final = served.wait_for({"Complete", "Aborted", "Held", "Stopped"})
    finally:
        watch.stop.set()
        watch.join(30)
    assert final["name"] == "Complete", final["reason"]
    assert final["index"] == final["count"] == len(program.instructions)
    skeleton = served.http.get("/skeleton", params={"format": "json"}).json()
    assert same_geometry(skeleton, skeleton_to_dict(twin.skeleton()))
    assert skeleton["occupancy"] == twin.occupancy.tolist()

    loom = asyncio.run(request("127.0.0.1", mock.ports["control"], {"cmd": "state"}))
    assert np.array_equal(np.array(loom["occupancy"]) == 1, twin.occupancy >= 0)
    machine = served.http.get("/machine").json()
    assert machine["occupancy"] == (twin.occupancy >= 0).tolist()
    assert machine["twin_occupancy"] == twin.occupancy.tolist()

    # The loom's inserter: each layer at its angle, never while the inserter still turned.
    assert watch.error is None, watch.error
    assert watch.angles() == [0, 90 * MDEG_PER_DEG]
    assert not any(turning for _, turning in watch.seen)
    axes = loom["axes"]
    assert axes["weft_angle"]["position"] == 90 * MDEG_PER_DEG  # the last layer's
    assert axes["weft_insert"]["position"] == 0  # home after its last stroke
    assert not any(axis["fault"] for axis in axes.values())
