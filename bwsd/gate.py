"""One gate for every door: a door's wire input becomes one typed request, checked for type,
range and the caller's current role, before the controller sees it.

REST, the WebSocket, the PLC tags and OPC UA turn what they received into a call of
``Gate.command``, ``Gate.set_mode``, ``Gate.manual``, ``Gate.load`` or ``Gate.load_stored``
with the values as
they came (an int, a name, a bool...), and a ``Caller``: which door, who, and the token to
check again now (or the door's fixed role). The gate refuses a value of the wrong type, a
number out of range, a caller whose token was removed or whose role does not suffice, with
``Refused`` naming the field and why; nothing acts then. What passes goes to the
controller's facade, whose own refusals (PackML, the machine) come back as they are. So a
refusal means the same thing whatever the door, and is logged once, at INFO, here.

What each request needs (docs/api.md, "Roles"): a command, a resume, a manual move or a
load: operator; a unit mode change: admin; a read: viewer.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING, Any, Literal, TypeVar

from bwsd.controller.manual import MAX_TAKEUP_MM, FaultReset, ManualMove, Stroke, TakeUpMove
from bwsd.controller.packml import Command, State, UnitMode
from bwsd.errors import BwsdError
from bwsd.fieldbus.base import FieldbusError, MachineState
from bwsd.journal import JournalError
from bwsd.logs import REFUSAL
from bwsd.tokens import RANK, Role, TokenStore

if TYPE_CHECKING:
    from bwsd.controller.facade import Controller
    from bwsd.controller.programs import DryRun

log = logging.getLogger("bwsd.gate")
MAX_REASON_CHARS = 500
MAX_NAME_CHARS = 200
MAX_PROGRAM_CHARS = 1_000_000
Kind = Literal["type", "range", "who", "role"]
NEEDS: dict[str, Role] = {
    "command": "operator",
    "load": "operator",
    "manual": "operator",
    "mode": "admin",
    "read": "viewer",
}


class Refused(BwsdError):
    """The gate refuses a request before anything acts: ``kind`` is why (a value of the
    wrong ``type``, out of ``range``, a caller not known (``who``) or without the ``role``),
    ``field`` which value."""

    def __init__(self, kind: Kind, message: str, field: str = "") -> None:
        super().__init__(message)
        self.kind: Kind = kind
        self.field = field


@dataclass(frozen=True)
class Caller:
    """Who asks, through which door: ``token`` is checked again at every request (removed,
    or its role changed, it no longer counts); a door without tokens has a fixed ``role``."""

    door: str  # rest, websocket, plc, opcua
    name: str  # for the log: the token's name, plc, ...
    token: str | None = None
    role: Role | None = None

    @property
    def said(self) -> str:
        return f"{self.name} ({self.door})"

    @property
    def who(self) -> str:
        """Who gave a command, as the log and the journal say it: the token's name over
        REST, ``plc`` for the PLC tags, ``opcua:NAME`` for an OPC UA user."""
        return self.name if self.door in ("rest", self.name) else f"{self.door}:{self.name}"


class Gate:
    """The one way from a door to the controller (see the module's docstring)."""

    def __init__(self, controller: Controller, tokens: TokenStore | None = None) -> None:
        self.controller = controller
        self.tokens = tokens

    # ----- who -----
    def role(self, caller: Caller) -> Role:
        """The caller's role now; Refused("who") when its token is not (or no longer) known."""
        if caller.token is None:
            if caller.role is None:
                raise Refused("who", f"{caller.said}: no token and no role")
            return caller.role
        held = self.tokens.check(caller.token) if self.tokens is not None else None
        if held is None or held[0] != caller.name:
            raise Refused("who", f"the token of {caller.name!r} is not known (removed?)")
        return held[1]

    def allow(self, caller: Caller, what: str) -> Role:
        """The caller's role if it may do ``what`` (a key of NEEDS); Refused otherwise."""
        needs = NEEDS[what]
        role = self.role(caller)
        if RANK[role] < RANK[needs]:
            raise Refused("role", f"{caller.name!r} has role {role}; this needs {needs} or above")
        return role

    # ----- requests -----
    async def command(
        self, caller: Caller, command: Any, *, reason: Any = "", resume: Any = False
    ) -> State:
        """A PackML command (a Command, its number or its name), with its reason and resume."""
        try:
            typed = command_of(command)
            said = text_of(reason, "reason", MAX_REASON_CHARS)
            wanted = flag_of(resume, "resume")
            if wanted and typed is not Command.START:
                raise Refused("range", "resume goes with start only", "resume")
            self.allow(caller, "command")
        except Refused as exc:
            log.info("%s: command refused: %s", caller.said, exc, extra=REFUSAL)
            raise
        return await self.controller.command(typed, said, caller.who, resume=wanted)

    async def set_mode(self, caller: Caller, mode: Any) -> UnitMode:
        """A unit mode change (a UnitMode, its number or its name)."""
        try:
            typed = mode_of(mode)
            self.allow(caller, "mode")
        except Refused as exc:
            log.info("%s: mode change refused: %s", caller.said, exc, extra=REFUSAL)
            raise
        await self.controller.set_mode(typed, caller.who)
        return typed

    async def manual(
        self, caller: Caller, kind: Any, *, axis: Any = None, step: Any = None, length: Any = None
    ) -> tuple[ManualMove, MachineState]:
        """A manual move: ``stroke`` (a shift ``axis`` by name, ``step`` +1 or -1),
        ``takeup`` (``length`` mm, either way) or ``reset_faults``; the move as typed and
        the machine read back after it."""
        try:
            move = self._manual_of(kind, axis, step, length)
            self.allow(caller, "manual")
        except Refused as exc:
            log.info("%s: manual move refused: %s", caller.said, exc, extra=REFUSAL)
            raise
        return move, await self.controller.manual(move, caller.who)

    def _manual_of(self, kind: Any, axis: Any, step: Any, length: Any) -> ManualMove:
        what = text_of(kind, "kind", 20, empty=False)
        if what == "reset_faults":
            return FaultReset()
        if what == "takeup":
            mm = number_of(length, "length", -MAX_TAKEUP_MM, MAX_TAKEUP_MM)
            if mm == 0:
                raise Refused("range", "length: 0 moves nothing", "length")
            return TakeUpMove(mm)
        if what != "stroke":
            raise Refused(
                "range", f"kind: {_shown(what)} is not one of stroke, takeup, reset_faults", "kind"
            )
        name = text_of(axis, "axis", 40, empty=False)
        found = [a for a in self.controller.axes if a.name == name]
        shifts = ", ".join(a.name for a in self.controller.axes if a.kind in ("row", "col"))
        if not found or found[0].kind not in ("row", "col"):
            raise Refused("range", f"axis: {_shown(name)} is not a shift axis ({shifts})", "axis")
        cells = whole_of(step, "step", -1, 1)
        if cells == 0:
            raise Refused("range", "step: 0 moves nothing (+1 or -1)", "step")
        return Stroke(found[0], cells)

    async def load(
        self, caller: Caller, name: Any, text: Any, cancel: threading.Event | None = None
    ) -> int:
        """Check and load a program's text (refusals name the line and column)."""
        try:
            program = text_of(name, "name", MAX_NAME_CHARS, empty=False)
            source = text_of(text, "text", MAX_PROGRAM_CHARS)
            self.allow(caller, "load")
        except Refused as exc:
            log.info("%s: load refused: %s", caller.said, exc, extra=REFUSAL)
            raise
        with _logged(caller, f"load of {program!r}"):
            return await self.controller.load(program, source, caller.who, cancel)

    async def check(
        self, caller: Caller, name: Any, text: Any, cancel: threading.Event | None = None
    ) -> DryRun:
        """Check a program without loading it (a dry run)."""
        try:
            program = text_of(name, "name", MAX_NAME_CHARS, empty=False)
            source = text_of(text, "text", MAX_PROGRAM_CHARS)
            self.allow(caller, "load")
        except Refused as exc:
            log.info("%s: check refused: %s", caller.said, exc, extra=REFUSAL)
            raise
        with _logged(caller, f"check of {program!r}"):
            _, totals = await self.controller.check(program, source, cancel)
        return totals

    async def load_stored(self, caller: Caller, program_id: Any) -> int:
        """Load again a program the journal holds, by its id (the plant's PLC selects one)."""
        try:
            number = whole_of(program_id, "program_id", 1, 2**31 - 1)
            self.allow(caller, "load")
        except Refused as exc:
            log.info("%s: load refused: %s", caller.said, exc, extra=REFUSAL)
            raise
        with _logged(caller, f"load of program {number}"):
            loaded: int = await self.controller.load_stored(number, caller.who)
        return loaded


@contextlib.contextmanager
def _logged(caller: Caller, what: str) -> Iterator[None]:
    """Log the controller's refusal of a load or check (a routine refusal: INFO; the journal
    or the bus failing: ERROR); the command refusals are logged by the controller itself."""
    try:
        yield
    except (JournalError, FieldbusError) as exc:
        log.error("%s: %s failed: %s", caller.said, what, exc)
        raise
    except BwsdError as exc:
        log.info("%s: %s refused: %s", caller.said, what, exc, extra=REFUSAL)
        raise


# ----- the wire's values, typed (pure) -----
def whole_of(value: Any, field: str, low: int, high: int) -> int:
    """An integer (not a bool, not a float) in [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise Refused("type", f"{field}: {_shown(value)} is not an integer", field)
    if not low <= value <= high:
        raise Refused("range", f"{field}: {value} is out of range ({low} to {high})", field)
    return value


def number_of(value: Any, field: str, low: float, high: float) -> float:
    """A finite number (an int or a float, not a bool) in [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise Refused("type", f"{field}: {_shown(value)} is not a number", field)
    if not low <= value <= high:  # a NaN is out of every range
        raise Refused("range", f"{field}: {value} is out of range ({low:g} to {high:g})", field)
    return float(value)


E = TypeVar("E", bound=IntEnum)  # Command, UnitMode


def command_of(value: Any) -> Command:
    """A Command from itself, its number (1 Reset .. 9 Clear) or its name."""
    return _member_of(Command, value, "command")


def mode_of(value: Any) -> UnitMode:
    """A UnitMode from itself, its number (1 Production .. 3 Manual) or its name."""
    return _member_of(UnitMode, value, "mode")


def _member_of(kind: type[E], value: Any, field: str) -> E:
    """A member of the numbered enum ``kind`` from itself, its number or its name."""
    if isinstance(value, kind):
        return value
    if isinstance(value, str):
        try:
            return kind[value.strip().upper()]
        except KeyError:
            names = ", ".join(m.name.lower() for m in kind)
            raise Refused(
                "range", f"{field}: {_shown(value)} is not one of {names}", field
            ) from None
    return kind(whole_of(value, field, min(kind), max(kind)))


def flag_of(value: Any, field: str) -> bool:
    if not isinstance(value, bool):
        raise Refused("type", f"{field}: {_shown(value)} is not true or false", field)
    return value


def text_of(value: Any, field: str, most: int, empty: bool = True) -> str:
    if not isinstance(value, str):
        raise Refused("type", f"{field}: {_shown(value)} is not text", field)
    if len(value) > most or (not empty and not value):
        size = f"{len(value)} characters" if value else "empty"
        raise Refused("range", f"{field}: {size} (1 to {most} characters)", field)
    return value


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:40]}..."
