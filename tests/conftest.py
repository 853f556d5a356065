"""Settings every test shares: the time scale (tests/timing.py) is read and shown here."""

from __future__ import annotations

import pytest

from tests import timing


def pytest_report_header(config: pytest.Config) -> str:
    return f"{timing.VARIABLE}={timing.TIME_SCALE:g} (tests/timing.py)"
