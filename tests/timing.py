"""One factor for the tests' waits on a slow or loaded machine: ``BWSD_TEST_TIME_SCALE``.

A bound a test waits up to (a deadline for a condition, a bus's I/O timeout, a pause that
lets another process catch up) is written ``scaled(seconds)``. ``BWSD_TEST_TIME_SCALE=3``
makes every such bound three times as long; unset, it is 1. What a test asserts about
time (a stall published within a second, a stop within a stroke) is never scaled: a
slower machine gives more room to wait, never a weaker claim.
"""

from __future__ import annotations

import os

VARIABLE = "BWSD_TEST_TIME_SCALE"


def _scale(text: str | None) -> float:
    if text is None or not text.strip():
        return 1.0
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not 1.0 <= value <= 100.0:
        raise ValueError(f"{VARIABLE} must be a number from 1 to 100, got {text!r}")
    return value


TIME_SCALE = _scale(os.environ.get(VARIABLE))


def scaled(seconds: float) -> float:
    """``seconds`` times the machine's factor (``BWSD_TEST_TIME_SCALE``, default 1)."""
    return seconds * TIME_SCALE
