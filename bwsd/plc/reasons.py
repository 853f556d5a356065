"""The stop reason code of the PLC tags: the controller's own ``StopCause``.

The cause is decided once, where the controller catches the error that stopped the run
(``bwsd.controller.status.cause_of``); the register carries its number (docs/plc.md).
"""

from __future__ import annotations

from bwsd.controller.status import StopCause

StopReason = StopCause
"""The codes of the stop reason register: NONE 0, REFUSED_MOVE 1, DRIVE_FAULT 2, ESTOP 3,
BUS 4, MISMATCH 5, OPERATOR 6, RESTART 7, INTERNAL 8."""

__all__ = ["StopReason"]
