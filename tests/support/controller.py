"""A Controller on the mock loom with a real journal file, and what its tests compare."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable
from pathlib import Path
from typing import Any, TypeVar

from bwsd.controller.facade import Controller, Settings
from bwsd.controller.packml import State, UnitMode
from bwsd.controller.plan import Limits
from bwsd.fieldbus import open_bus
from bwsd.journal import Journal
from bwsd.twin import Twin
from bwsd.twin.skeleton import ContactData
from tests.support.fieldbus import Mock, client_config

T = TypeVar("T")

# The mock loom's fill (tests/support/fieldbus.py): cases at (1, 1), (1, 2), (2, 1), (2, 2).
CYCLE = "ROW 1:+1 2:-1\nCOL 1:+1 2:-1\nROW 1:-1 2:+1\nCOL 1:-1 2:+1\nTAKEUP 2\n"
TEXT = f"YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 3\n{CYCLE}END\n"


def run(scenario: Awaitable[T]) -> T:
    """The scenario on a fresh event loop, bounded at two minutes."""
    return asyncio.run(asyncio.wait_for(scenario, 120))


async def controller(
    mock: Mock, tmp_path: Path, *, limits: Limits | None = None, settings: Settings | None = None
) -> tuple[Controller, Journal, list[dict[str, Any]]]:
    """A Controller over Modbus on ``mock``, its journal and the events it published."""
    config = client_config("modbus", mock.ports)
    bus = open_bus(config)
    await bus.connect()
    journal = Journal.open(tmp_path / "journal.db")
    events: list[dict[str, Any]] = []
    ctl = Controller(
        config.machine, bus, journal, limits=limits, publish=events.append, settings=settings
    )
    return ctl, journal, events


def bits(twin: Twin | None) -> list[tuple[bytes, bytes] | ContactData]:
    """The twin's skeleton as bytes: equal only when every node and contact is. A
    controller's twin is taken as it is (``ctl.twin``): the test has loaded a program."""
    assert twin is not None
    sk = twin.skeleton()
    yarns: list[tuple[bytes, bytes] | ContactData] = [
        (y.node_ids.tobytes(), y.nodes.tobytes()) for y in sk.yarns
    ]
    return yarns + list(sk.contacts)


def state_now(ctl: Controller) -> State:
    """The PackML state, read anew. A test reads it again after awaiting a change, and mypy
    would keep ``ctl.packml.state`` narrowed to what an earlier ``assert ... is`` saw."""
    return ctl.packml.state


def mode_now(ctl: Controller) -> UnitMode:
    """The unit mode, read anew (as ``state_now``)."""
    return ctl.packml.mode
