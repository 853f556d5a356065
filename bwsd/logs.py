"""The daemon's log: one timestamped line per record, for an operator to read.

Every command (with the token name, or ``plc``, that gave it), every state change with its
cause, holds, aborts and recovery decisions are logged at INFO or above by
``bwsd.controller``. Library records keep their first line only: pymodbus appends the raw
frames of a failed transaction to its error, which is noise in an operator's log (the
controller logs the failure in its own words); and a kind of library record is logged at
most once a minute, with a count, so garbage sent to a port cannot fill the log.
"""

from __future__ import annotations

import logging
import math
import re
import sys
import time

FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"
# ``extra=REFUSAL`` marks a record as a request refused (by the gate or the controller): the
# page's console tells refusals apart by this mark, never by the words of the line.
REFUSAL = {"refusal": True}
QUIET = ("pymodbus", "canopen", "can.")


class FirstLine(logging.Filter):
    """Keeps a library record's first line, drops its traceback, and lets through at most
    one record of a kind per ``every`` seconds (garbage on a port is a record per frame).

    A kind is the library and the first line with its numbers blanked; the next record of
    a kind after a quiet spell says how many went unlogged.
    """

    KINDS = 256  # kinds remembered; more are forgotten all at once

    def __init__(self, every: float = 60.0) -> None:
        super().__init__()
        self.every = every
        self._kinds: dict[str, tuple[float, int]] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        if not record.name.startswith(QUIET):
            return True
        text = record.getMessage().split("\n", 1)[0]
        kind = record.name.split(".", 1)[0] + ":" + re.sub(r"\d+", "#", text)[:60]
        now = time.monotonic()
        last, unlogged = self._kinds.get(kind, (-math.inf, 0))
        if now - last < self.every:
            self._kinds[kind] = (last, unlogged + 1)
            return False
        if unlogged:
            text += f" (and {unlogged} more like it in the last {now - last:.0f} s)"
        if len(self._kinds) >= self.KINDS and kind not in self._kinds:
            self._kinds.clear()
        self._kinds[kind] = (now, 0)
        record.msg, record.args = text, None
        record.exc_info, record.exc_text, record.stack_info = None, None, None
        return True


def setup(level: int = logging.INFO) -> None:
    """Log to standard error (journald under systemd), one line per record."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter(FORMAT))
    handler.addFilter(FirstLine())
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
    # Libraries that narrate their routine work at INFO (asyncua: a line for every node of
    # the standard address space it builds at start; canopen: every NMT state change of every
    # node): their warnings and errors only.
    for name in ("pymodbus", "asyncua", "canopen", "can"):
        logging.getLogger(name).setLevel(logging.WARNING)


class Summary:
    """One INFO line for the first of a kind of event, then at most one per ``every`` s.

    For what a hostile or broken client can repeat at will (refused logins, refused
    connections, garbage on a port): the log stays readable and small. A line after a
    quiet spell says how many like it went unlogged since the last one.
    """

    def __init__(self, logger: logging.Logger, kind: str, every: float = 60.0) -> None:
        self.logger = logger
        self.kind = kind
        self.every = every
        self._last = -math.inf
        self._unlogged = 0

    def reset(self) -> None:
        """Forget the last line: the next event is logged at once."""
        self._last, self._unlogged = -math.inf, 0

    def note(self, message: str, *args: object) -> None:
        now = time.monotonic()
        if now - self._last < self.every:
            self._unlogged += 1
            return
        if self._unlogged:
            message += f" (and {self._unlogged} more {self.kind} unlogged in the last %.0f s)"
            args = (*args, now - self._last)
        self.logger.info(message, *args)
        self._last, self._unlogged = now, 0
