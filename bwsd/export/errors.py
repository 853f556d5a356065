"""Errors of the export phase."""

from __future__ import annotations

from bwsd.errors import BwsdError


class ExportError(BwsdError):
    """An export or import of a skeleton failed: names the file and what to do."""

    def __init__(self, message: str, *, path: str = "") -> None:
        super().__init__(f"{path}: {message}" if path else message)
        self.reason = message
        self.path = path
