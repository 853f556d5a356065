"""A stop's cause, decided once from the error that made it; the event stream (pure)."""

from __future__ import annotations

import pytest

from bwsd.config import parse_config
from bwsd.controller.packml import State
from bwsd.controller.plan import Mismatch, RefusedMove
from bwsd.controller.status import Event, EventStream, Fault, StateChanged, StopCause, cause_of
from bwsd.errors import MoveError, TwinError
from bwsd.fieldbus.axes import machine_axes
from bwsd.fieldbus.base import (
    FAULT_DRIVE,
    FAULT_ESTOP,
    FAULT_STALL,
    DriveFault,
    EStopError,
    FieldbusConnectionError,
    FieldbusError,
    FieldbusTimeout,
)
from bwsd.plc import StopReason
from tests.support.fieldbus import MACHINE

AXIS = machine_axes(parse_config({"machine": MACHINE}).machine)[5]


@pytest.mark.parametrize(
    ("error", "cause"),
    [
        (RefusedMove("beyond the tensioner's stroke"), StopCause.REFUSED_MOVE),
        (MoveError("a case would leave the matrix", instruction=3), StopCause.REFUSED_MOVE),
        (TwinError("no such line"), StopCause.REFUSED_MOVE),
        (DriveFault(AXIS, FAULT_DRIVE), StopCause.DRIVE_FAULT),
        (DriveFault(AXIS, FAULT_STALL), StopCause.DRIVE_FAULT),
        (DriveFault(AXIS, FAULT_ESTOP), StopCause.ESTOP),
        (EStopError("emergency stop is pressed"), StopCause.ESTOP),
        (FieldbusTimeout("axes col2 did not complete in time"), StopCause.BUS),
        (FieldbusConnectionError("connection lost"), StopCause.BUS),
        (FieldbusError("address 7: refused"), StopCause.BUS),
        (Mismatch("take-up at 3 um, predicted 4 um"), StopCause.MISMATCH),
        (KeyError("not one of ours"), StopCause.INTERNAL),
        (OSError(28, "No space left on device"), StopCause.INTERNAL),
    ],
)
def test_the_cause_of_a_stop_by_its_error(error, cause):
    assert cause_of(error) is cause


def test_the_plc_stop_reason_codes_are_the_causes():
    assert StopReason is StopCause
    assert [int(c) for c in StopCause] == list(range(10))


def test_a_failing_subscriber_is_logged_and_the_others_still_hear(caplog):
    stream = EventStream()
    heard: list[Event] = []

    def broken(event):
        raise RuntimeError("subscriber bug")

    stream.subscribe(broken)
    stream.subscribe(heard.append)
    event = StateChanged(State.EXECUTE, State.HOLDING, "Hold", "jam")
    stream.publish(event)
    assert heard == [event]
    assert "subscriber failed on the state event" in caplog.text
    wire = Fault("instruction 2: stall", StopCause.DRIVE_FAULT).wire()
    assert (wire["event"], wire["cause"], wire["reason"]) == (
        "fault",
        "drive_fault",
        "instruction 2: stall",
    )
