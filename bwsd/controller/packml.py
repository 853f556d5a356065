"""The PackML state machine (ISA-TR88.00.02): states, commands, unit modes.

Pure: no I/O, no asyncio, no clock. The daemon feeds it commands (from REST, the PLC tags
or the preview page) and events (an acting state's work is done, the program has run out);
the machine answers with the new state or refuses with an error naming what is accepted.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from enum import IntEnum

from bwsd.errors import BwsdError


class _Labelled:
    """Display names for the enums: ``State.EXECUTE.label == "Execute"``."""

    name: str

    @property
    def label(self) -> str:
        return self.name.capitalize()


class State(_Labelled, IntEnum):
    """The 17 PackML states with their standard numbers (PackTags ``StateCurrent``)."""

    CLEARING = 1
    STOPPED = 2
    STARTING = 3
    IDLE = 4
    SUSPENDED = 5
    EXECUTE = 6
    STOPPING = 7
    ABORTING = 8
    ABORTED = 9
    HOLDING = 10
    HELD = 11
    UNHOLDING = 12
    SUSPENDING = 13
    UNSUSPENDING = 14
    RESETTING = 15
    COMPLETING = 16
    COMPLETE = 17


class Command(_Labelled, IntEnum):
    """The PackML state commands with their standard numbers (PackTags ``CntrlCmd``)."""

    RESET = 1
    START = 2
    STOP = 3
    HOLD = 4
    UNHOLD = 5
    SUSPEND = 6
    UNSUSPEND = 7
    ABORT = 8
    CLEAR = 9


class UnitMode(_Labelled, IntEnum):
    """The unit modes with their standard numbers (PackTags ``UnitMode``)."""

    PRODUCTION = 1
    MAINTENANCE = 2
    MANUAL = 3


# An acting state does work and leaves by "state complete"; where it goes next:
_COMPLETES_TO: dict[State, State] = {
    State.RESETTING: State.IDLE,
    State.STARTING: State.EXECUTE,
    State.COMPLETING: State.COMPLETE,
    State.HOLDING: State.HELD,
    State.UNHOLDING: State.EXECUTE,
    State.SUSPENDING: State.SUSPENDED,
    State.UNSUSPENDING: State.EXECUTE,
    State.STOPPING: State.STOPPED,
    State.ABORTING: State.ABORTED,
    State.CLEARING: State.STOPPED,
}

ACTING: frozenset[State] = frozenset(_COMPLETES_TO)


def completes_to(state: State) -> State | None:
    """The state an acting state goes to when its work is done (None for another state)."""
    return _COMPLETES_TO.get(state)


"""The "...ing" states: they end by ``state_complete()`` (or a command that leaves them)."""

WAITING: frozenset[State] = frozenset(
    {State.STOPPED, State.IDLE, State.SUSPENDED, State.HELD, State.COMPLETE, State.ABORTED}
)
"""The states that stay until a command comes. Execute is in neither set: it ends by
``execute_done()`` when the program has run out."""

MODE_CHANGE_STATES: frozenset[State] = frozenset({State.STOPPED, State.IDLE, State.ABORTED})
"""Where ``set_mode`` is accepted: the machine is at rest and no production cycle is open."""

_STOP_REFUSED = frozenset(
    {State.STOPPING, State.STOPPED, State.CLEARING, State.ABORTING, State.ABORTED}
)
_ABORT_REFUSED = frozenset({State.ABORTING, State.ABORTED})

# Every command but Stop and Abort, by the state that accepts it. Hold from Starting,
# Unholding, Suspending, Suspended and Unsuspending is the optional part of the standard's
# model, taken here (see docs/packml.md).
_COMMANDS: dict[State, dict[Command, State]] = {
    State.STOPPED: {Command.RESET: State.RESETTING},
    State.IDLE: {Command.START: State.STARTING},
    State.STARTING: {Command.HOLD: State.HOLDING},
    State.EXECUTE: {Command.HOLD: State.HOLDING, Command.SUSPEND: State.SUSPENDING},
    State.COMPLETE: {Command.RESET: State.RESETTING},
    State.HELD: {Command.UNHOLD: State.UNHOLDING},
    State.UNHOLDING: {Command.HOLD: State.HOLDING},
    State.SUSPENDING: {Command.HOLD: State.HOLDING},
    State.SUSPENDED: {Command.HOLD: State.HOLDING, Command.UNSUSPEND: State.UNSUSPENDING},
    State.UNSUSPENDING: {Command.HOLD: State.HOLDING},
    State.ABORTED: {Command.CLEAR: State.CLEARING},
}

# Commands whose reason is kept in ``PackML.reason``; every other command clears it (what
# stopped the machine is no longer true once it is reset, cleared or resumed).
_REASONED = frozenset({Command.STOP, Command.ABORT, Command.HOLD, Command.SUSPEND})


def _labels(items: Iterable[_Labelled]) -> str:
    return ", ".join(item.label for item in items) or "none"


def transitions(state: State) -> dict[Command, State]:
    """The commands accepted in ``state`` and where each leads, Stop and Abort last."""
    table = dict(sorted(_COMMANDS.get(state, {}).items()))
    if state not in _STOP_REFUSED:
        table[Command.STOP] = State.STOPPING
    if state not in _ABORT_REFUSED:
        table[Command.ABORT] = State.ABORTING
    return table


class PackMLError(BwsdError):
    """The state machine refuses a command, an event or a mode change in its current state."""


class InvalidCommand(PackMLError):
    """A command the current state does not accept: names both and what is accepted there."""

    def __init__(self, command: Command, state: State) -> None:
        self.command = command
        self.state = state
        self.allowed = tuple(transitions(state))
        super().__init__(
            f"{command.label} is not accepted in state {state.label} "
            f"(accepted there: {_labels(self.allowed)})"
        )


class InvalidEvent(PackMLError):
    """A "state complete" outside an acting state, or "execute done" outside Execute."""

    def __init__(self, event: str, state: State, expected: Iterable[State]) -> None:
        self.event = event
        self.state = state
        super().__init__(
            f"{event} is not possible in state {state.label} (only in: {_labels(sorted(expected))})"
        )


class InvalidModeChange(PackMLError):
    """A unit mode change outside the states where the mode may change."""

    def __init__(self, mode: UnitMode, state: State) -> None:
        self.mode = mode
        self.state = state
        super().__init__(
            f"change to mode {mode.label} is not accepted in state {state.label} "
            f"(only in: {_labels(sorted(MODE_CHANGE_STATES))})"
        )


Listener = Callable[[State, State, str], None]
"""Called as ``listener(old, new, cause)`` after every state change."""


class PackML:
    """One unit's PackML state and unit mode."""

    def __init__(self, state: State = State.STOPPED, mode: UnitMode = UnitMode.PRODUCTION) -> None:
        self._state = State(state)
        self._mode = UnitMode(mode)
        self.reason = ""
        self.on_change: list[Listener] = []

    @property
    def state(self) -> State:
        return self._state

    @property
    def mode(self) -> UnitMode:
        return self._mode

    def accepts(self, command: Command) -> bool:
        return command in transitions(self._state)

    def allowed(self) -> list[Command]:
        """The commands accepted now: the state's own in number order, then Stop, Abort."""
        return list(transitions(self._state))

    def command(self, command: Command, reason: str = "") -> State:
        """Apply ``command`` or raise InvalidCommand, leaving the state as it was."""
        target = transitions(self._state).get(command)
        if target is None:
            raise InvalidCommand(command, self._state)
        self.reason = reason if command in _REASONED else ""
        cause = f"{command.label}: {reason}" if reason else command.label
        return self._enter(target, cause)

    def state_complete(self) -> State:
        """The acting state's work is done: move to the state that follows it."""
        target = _COMPLETES_TO.get(self._state)
        if target is None:
            raise InvalidEvent("state complete", self._state, ACTING)
        return self._enter(target, "state complete")

    def execute_done(self) -> State:
        """The program has run out: Execute goes to Completing."""
        if self._state is not State.EXECUTE:
            raise InvalidEvent("execute done", self._state, {State.EXECUTE})
        return self._enter(State.COMPLETING, "execute done")

    def restore(self, state: State, reason: str) -> State:
        """Take up ``state`` (a waiting state) after a restart, with why; heard as a change."""
        if state not in WAITING:
            raise InvalidEvent("restore", state, WAITING)
        self.reason = reason
        return self._enter(state, "restart")

    def set_mode(self, mode: UnitMode) -> None:
        """Change the unit mode (only in MODE_CHANGE_STATES; the same mode is always fine)."""
        mode = UnitMode(mode)
        if mode is not self._mode and self._state not in MODE_CHANGE_STATES:
            raise InvalidModeChange(mode, self._state)
        self._mode = mode

    def _enter(self, target: State, cause: str) -> State:
        old, self._state = self._state, target
        for listener in list(self.on_change):
            listener(old, target, cause)
        return target
