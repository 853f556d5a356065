"""Keep native libraries' chatter on file descriptor 1 away from the caller's stdout."""

from __future__ import annotations

import ctypes
import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager, suppress

# One lock for every redirection: fd 1 is process-wide, and TexGen keeps a global registry.
NATIVE_LOCK = threading.RLock()


def _flush_c_stdio() -> None:
    """Flush the C library's stdout buffer (it is fully buffered when stdout is a pipe)."""
    with suppress(OSError, AttributeError, TypeError):
        ctypes.CDLL(None).fflush(None)


def _dup_stdout() -> int | None:
    try:
        return os.dup(1)
    except OSError:
        return None


@contextmanager
def quiet_stdout() -> Iterator[None]:
    """Send everything written to fd 1 inside the block to the null device."""
    with NATIVE_LOCK:
        if sys.stdout is not None:
            sys.stdout.flush()
        _flush_c_stdio()
        saved = _dup_stdout()
        if saved is None:  # no fd 1 at all: nothing to protect
            yield
            return
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        try:
            yield
        finally:
            _flush_c_stdio()
            os.dup2(saved, 1)
            os.close(saved)
            os.close(null)
