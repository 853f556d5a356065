"""Errors a user can cause, by phase, each naming the place of the fault."""

from __future__ import annotations


class BwsdError(Exception):
    """Base of every error bwsd reports to a user."""


class ConfigError(BwsdError):
    """A configuration file is malformed: names the file, table and key."""

    def __init__(self, message: str, *, path: str = "", table: str = "", key: str = "") -> None:
        where = ".".join(p for p in (table, key) if p)
        prefix = ": ".join(p for p in (path, f"[{where}]" if where else "") if p)
        super().__init__(f"{prefix}: {message}" if prefix else message)
        self.path = path
        self.table = table
        self.key = key


class ProgramError(BwsdError):
    """A program is malformed or impossible: names the line and column of the fault."""

    def __init__(self, message: str, *, line: int = 0, column: int = 0, source: str = "") -> None:
        where = f"{source or '<program>'}:{line}:{column}" if line else (source or "<program>")
        super().__init__(f"{where}: {message}")
        self.reason = message
        self.line = line
        self.column = column
        self.source = source


class TwinError(BwsdError):
    """The twin refuses an instruction (names the instruction, 1-based)."""

    def __init__(self, message: str, *, instruction: int = 0) -> None:
        super().__init__(f"instruction {instruction}: {message}" if instruction else message)
        self.reason = message
        self.instruction = instruction


class MoveError(TwinError):
    """A case would leave the matrix or land on an occupied cell."""


class ShedClosedError(TwinError):
    """A weft would pass within one yarn diameter of another yarn."""


class JamError(TwinError):
    """A contact would lie within one yarn diameter of the guides: the yarns would lock there.

    ``yarns`` are the moving and the hit yarn, ``z`` the contact's height (mm, preform frame).
    """

    def __init__(
        self,
        message: str,
        *,
        instruction: int = 0,
        yarns: tuple[int, int] = (-1, -1),
        z: float = 0.0,
    ) -> None:
        super().__init__(message, instruction=instruction)
        self.yarns = yarns
        self.z = z


class ExtraMissingError(BwsdError):
    """A command needs an optional library that is not installed: names the extra to install."""
