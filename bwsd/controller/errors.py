"""The controller's refusals."""

from __future__ import annotations

from bwsd.errors import BwsdError


class ControllerError(BwsdError):
    """A request the controller cannot take in its present state (names why)."""


class Busy(ControllerError):
    """Another program check is running: one at a time."""


class Cancelled(ControllerError):
    """A program check was cancelled (its client went away)."""
