"""The controller's refusals."""

from __future__ import annotations

from bwsd.errors import BwsdError, ProgramError


class ControllerError(BwsdError):
    """A request the controller cannot take in its present state (names why)."""


class ProgramRefused(ControllerError, ProgramError):
    """The controller refuses a program at its check: names the instruction, and the line
    and column where the program writes it."""

    def __init__(
        self, message: str, *, instruction: int, line: int, column: int, source: str
    ) -> None:
        ProgramError.__init__(self, message, line=line, column=column, source=source)
        self.instruction = instruction


class Busy(ControllerError):
    """Another program check is running: one at a time."""


class Cancelled(ControllerError):
    """A program check was cancelled (its client went away)."""
