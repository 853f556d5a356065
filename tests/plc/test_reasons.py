"""The stop reason codes, from the error in flight and the reason text (pure)."""

from __future__ import annotations

import pytest

from bwsd.config import parse_config
from bwsd.controller.plan import Mismatch, RefusedMove
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
from bwsd.plc import StopReason, stop_reason
from tests.fieldbus.conftest import MACHINE

AXIS = machine_axes(parse_config({"machine": MACHINE}).machine)[5]
RESTARTED = "restarted: instruction 1 started and not done: occupancy differs"


@pytest.mark.parametrize(
    ("error", "reason", "code"),
    [
        (None, "", StopReason.OPERATOR),
        (None, "by the PLC", StopReason.OPERATOR),
        (None, "restarted at instruction 7: resume with Unhold", StopReason.RESTART),
        (Mismatch("instruction 1: occupancy differs"), RESTARTED, StopReason.RESTART),
        (RefusedMove("beyond the tensioner's stroke"), "x", StopReason.REFUSED_MOVE),
        (MoveError("a case would leave the matrix", instruction=3), "x", StopReason.REFUSED_MOVE),
        (TwinError("no such line"), "x", StopReason.REFUSED_MOVE),
        (DriveFault(AXIS, FAULT_DRIVE), "x", StopReason.DRIVE_FAULT),
        (DriveFault(AXIS, FAULT_STALL), "x", StopReason.DRIVE_FAULT),
        (DriveFault(AXIS, FAULT_ESTOP), "x", StopReason.ESTOP),
        (EStopError("emergency stop is pressed"), "x", StopReason.ESTOP),
        (FieldbusTimeout("axes col2 did not complete in time"), "x", StopReason.BUS),
        (FieldbusConnectionError("connection lost"), "x", StopReason.BUS),
        (FieldbusError("address 7: refused"), "x", StopReason.BUS),
        (Mismatch("take-up at 3 um, predicted 4 um"), "x", StopReason.MISMATCH),
        (KeyError("not one of ours"), "x", StopReason.OPERATOR),
    ],
)
def test_stop_reason_codes(error, reason, code):
    assert stop_reason(error, reason) is code
