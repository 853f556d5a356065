"""A jam (docs/twin.md) is refused by the daemon like any twin refusal: before anything moves."""

from __future__ import annotations

import asyncio

import pytest

from bwsd.controller.errors import ControllerError
from bwsd.controller.facade import Controller
from bwsd.fieldbus import open_bus
from bwsd.journal import Journal
from simulator_hw.control import request
from tests.support.fieldbus import client_config

pytestmark = pytest.mark.slow  # every test here is in the slow tier

# The mock loom's four cases (1, 1), (1, 2), (2, 1), (2, 2) wound round each other with no
# take-up: the contacts climb to the guides and an instruction jams.
TURN = "ROW 1:+1 2:-1\nCOL 1:+1 2:-1\nROW 1:-1 2:+1\nCOL 1:-1 2:+1\n"
WINDS_UP = f"YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 60\n{TURN}END\n"


def test_a_program_that_jams_is_refused_at_load_and_nothing_moves(mock, tmp_path):
    async def scenario() -> None:
        config = client_config("modbus", mock.ports)
        bus = open_bus(config)
        await bus.connect()
        journal = Journal.open(tmp_path / "journal.db")
        ctl = Controller(config.machine, bus, journal)
        jam = (
            r"winds\.bws:10:1: instruction 1\d\d: jam: yarn \d would rest on yarn \d "
            r"at z = [\d.]+ mm, [\d.]+ mm below the guides"
        )
        with pytest.raises(ControllerError, match=jam):
            await ctl.load("winds.bws", WINDS_UP)
        assert ctl.program is None and journal.history() == []
        answer = await request("127.0.0.1", mock.ports["control"], {"cmd": "state"})
        assert answer["occupancy"] == [[0, 0, 0, 0], [0, 1, 1, 0], [0, 1, 1, 0], [0, 0, 0, 0]]
        await bus.close()
        journal.close()

    asyncio.run(asyncio.wait_for(scenario(), 120))
