"""`GET /api/v1/skeleton?relaxed=true`: the relaxed preform of the committed instruction,
made in a worker process, kept per instruction, never changing the twin (docs/relax.md)."""

from __future__ import annotations

import json
import time

import pytest

from bwsd.program import parse_program
from bwsd.relax import Options, relax
from bwsd.relax.document import relaxed_to_dict
from bwsd.twin import simulate
from tests.api.conftest import BRAID, BRAID_STEPS, WAIT, Live
from tests.support.fieldbus import client_config

pytestmark = pytest.mark.slow  # every test here is in the slow tier


def _run_to_complete(live: Live) -> None:
    operator = live.client("operator")
    assert operator.post("/programs", json={"name": "b.bws", "text": BRAID}).status_code == 201
    for command in ("reset", "start"):
        assert operator.post(f"/commands/{command}").status_code == 200
    deadline = time.monotonic() + WAIT
    while operator.get("/state").json()["name"] != "Complete":
        assert time.monotonic() < deadline, "the braid did not complete"
        time.sleep(0.05)


def test_the_relaxed_preform_of_the_done_index_is_served_and_kept(live: Live, mock):
    viewer = live.client("viewer")
    assert viewer.get("/skeleton", params={"relaxed": "true"}).status_code == 409  # none loaded
    _run_to_complete(live)
    predicted = viewer.get("/skeleton").content
    answer = viewer.get("/skeleton", params={"relaxed": "true"}, timeout=WAIT)
    assert answer.status_code == 200, answer.text
    document = answer.json()
    assert document["instructions"] == BRAID_STEPS
    assert set(document) >= {"yarns", "relaxed", "crimp"}
    assert all(len(y["sections"]) == len(y["nodes"]) for y in document["yarns"])
    # an independent run of the relaxation on the same program gives the same document
    machine = client_config("modbus", mock.ports).machine
    sk = simulate(machine, parse_program(BRAID)).skeleton()
    expected = relaxed_to_dict(relax(sk, Options()))
    expected["relaxed"]["seconds"] = document["relaxed"]["seconds"]  # the one clock reading
    assert document == json.loads(json.dumps(expected))
    again = viewer.get("/skeleton", params={"relaxed": "true"}, timeout=WAIT)
    assert again.content == answer.content
    assert live.app.state.ctx.relaxed.computed == 1  # kept per instruction
    assert viewer.get("/skeleton").content == predicted  # the twin is not touched
    wrong = viewer.get("/skeleton", params={"relaxed": "true", "format": "tg3"})
    assert wrong.status_code == 409
