"""Settings every test shares: the time scale (tests/timing.py) is read and shown here, and
the slow tier is marked.

`pytest` alone runs the quick tier (`-m "not slow"` in pyproject.toml); `.ci/run` runs every
tier (`-m "slow or not slow"`). A test is slow when it starts a daemon, a mock loom or a
browser, builds or installs the package, or takes more than a few seconds. A module all of
whose tests are slow is listed here; a single slow test elsewhere has `@pytest.mark.slow`.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests import timing

TESTS = Path(__file__).resolve().parent

SLOW_MODULES: frozenset[str] = frozenset()


def pytest_report_header(config: pytest.Config) -> str:
    return f"{timing.VARIABLE}={timing.TIME_SCALE:g} (tests/timing.py)"


@pytest.hookimpl(tryfirst=True)  # before pytest's own -m deselects
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    stale = sorted(name for name in SLOW_MODULES if not (TESTS / name).is_file())
    if stale:
        raise pytest.UsageError(f"tests/conftest.py: SLOW_MODULES lists no such file: {stale}")
    for item in items:
        if item.path.relative_to(TESTS).as_posix() in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)
