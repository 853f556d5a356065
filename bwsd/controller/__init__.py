"""Machine control: the PackML state machine the daemon's commands go through."""

from __future__ import annotations

from bwsd.controller.packml import (
    ACTING,
    MODE_CHANGE_STATES,
    WAITING,
    Command,
    InvalidCommand,
    InvalidEvent,
    InvalidModeChange,
    Listener,
    PackML,
    PackMLError,
    State,
    UnitMode,
    transitions,
)

__all__ = [
    "ACTING",
    "MODE_CHANGE_STATES",
    "WAITING",
    "Command",
    "InvalidCommand",
    "InvalidEvent",
    "InvalidModeChange",
    "Listener",
    "PackML",
    "PackMLError",
    "State",
    "UnitMode",
    "transitions",
]
