"""The stop reason code of the PLC tags: why the machine last stopped, held or aborted (pure).

The controller enters Stopping, Aborting or Holding with a reason text. When its run loop
stops on an error it does so while handling that error, so the error's class is at hand
and names the cause exactly; a stop without an error in flight came from a caller (an
operator, the REST API or the PLC), unless its reason says the daemon restarted.
"""

from __future__ import annotations

from enum import IntEnum

from bwsd.controller.plan import Mismatch, RefusedMove
from bwsd.errors import TwinError
from bwsd.fieldbus.base import FAULT_ESTOP, DriveFault, EStopError, FieldbusError

RESTART_PREFIX = "restarted"
"""How the controller's reasons begin after ``recover()`` (bwsd.controller.runner)."""


class StopReason(IntEnum):
    """The codes of the stop reason register (docs/plc.md)."""

    NONE = 0
    REFUSED_MOVE = 1
    DRIVE_FAULT = 2
    ESTOP = 3
    BUS = 4
    MISMATCH = 5
    OPERATOR = 6
    RESTART = 7


def stop_reason(error: BaseException | None, reason: str) -> StopReason:
    """The code of a stop given the error being handled when it came (if any) and its reason."""
    if reason.startswith(RESTART_PREFIX):
        return StopReason.RESTART
    if isinstance(error, EStopError):
        return StopReason.ESTOP
    if isinstance(error, DriveFault):
        return StopReason.ESTOP if error.code == FAULT_ESTOP else StopReason.DRIVE_FAULT
    if isinstance(error, FieldbusError):
        return StopReason.BUS
    if isinstance(error, RefusedMove | TwinError):
        return StopReason.REFUSED_MOVE
    if isinstance(error, Mismatch):
        return StopReason.MISMATCH
    return StopReason.OPERATOR
