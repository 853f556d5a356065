"""The mock loom fixtures of the fieldbus tests, shared here."""

from tests.fieldbus.conftest import mock, slow_mock

__all__ = ["mock", "slow_mock"]
