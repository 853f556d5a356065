"""What the controller last saw of the machine: a failure is lost or answered by its type."""

from __future__ import annotations

from typing import Any

from bwsd.controller.machine import MachineView
from bwsd.controller.status import BusChanged
from bwsd.fieldbus.base import (
    BusHeld,
    EStopError,
    FieldbusConnectionError,
    FieldbusError,
    FieldbusTimeout,
)


def test_whether_the_machine_is_lost_is_decided_by_the_error_not_its_words():
    events: list[Any] = []
    worse: list[tuple[Any, Any]] = []
    # no bus: only how the view judges the errors is under test
    view = MachineView(None, events.append, lambda old, new: worse.append((old, new)))  # type: ignore[arg-type]
    answered = [
        BusHeld("another client holds the loom: pid 7 (claim id 1234abcd)"),
        FieldbusTimeout("axes col1 did not complete in time", lost=False),
        FieldbusError("address 196 refused (exception code 2)"),
        EStopError("emergency stop is pressed"),
    ]
    for error in answered:
        view.failed(error)
        assert view.status.connected is not False, error
    assert view.status.estop is True and len(worse) == 1  # the e-stop, once
    for error in (FieldbusConnectionError("connection lost"), FieldbusTimeout("no answer")):
        view.failed(error)
        assert view.status.connected is False, error
    assert len(worse) == 2  # lost: said once, not at every failed read
    assert all(isinstance(e, BusChanged) for e in events)
