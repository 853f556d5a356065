"""The mock loom fixtures (tests/support/fieldbus.py)."""

from tests.support.fieldbus import mock, slow_mock

__all__ = ["mock", "slow_mock"]
