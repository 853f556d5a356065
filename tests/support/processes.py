"""Processes the tests start (mock looms, daemons) never outlive the test run: whatever one
a failing test did not stop is killed when its worker process exits."""

from __future__ import annotations

import atexit
import subprocess
from typing import TypeVar

_started: list[subprocess.Popen[str]] = []
P = TypeVar("P", bound="subprocess.Popen[str]")


def owned(proc: P) -> P:
    """``proc``, killed at this process's exit if it still runs then."""
    _started[:] = [p for p in _started if p.poll() is None]
    _started.append(proc)
    return proc


@atexit.register
def _kill_leftovers() -> None:
    for proc in _started:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
