"""Settings every test shares: the time scale (tests/timing.py) is read and shown here.

Tiers: `pytest` alone runs the quick tier (`-m "not slow"` in pyproject.toml); `.ci/run`
runs every tier (`-m "slow or not slow"`). A test is in the slow tier (`@pytest.mark.slow`,
or `pytestmark` for a whole module) when it starts a daemon, a mock loom or a browser,
builds or installs the package, or takes more than about half a second.
"""

from __future__ import annotations

import pytest

from tests import timing


def pytest_report_header(config: pytest.Config) -> str:
    return f"{timing.VARIABLE}={timing.TIME_SCALE:g} (tests/timing.py)"
