"""Every malformed config is a ConfigError naming the file (and table and key where known).

Fuzzed over bytes (any file) and over TOML-like structures (any tables, any values), plus
the cases found by probing: a file that is not UTF-8, and arrays nested a thousand deep.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bwsd.config import load_config, parse_config
from bwsd.errors import ConfigError
from tests.support.fieldbus import MACHINE, toml

GOOD = toml({"machine": MACHINE})
FIXTURE = HealthCheck.function_scoped_fixture  # the file is rewritten by every example


def load(tmp: Path, data: bytes) -> None:
    path = tmp / "bwsd.toml"
    path.write_bytes(data)
    try:
        load_config(path)
    except ConfigError as exc:
        assert str(path) in str(exc)


def test_a_file_that_is_not_utf8_is_a_config_error(tmp_path):
    path = tmp_path / "bwsd.toml"
    path.write_bytes(GOOD.encode().replace(b"rows = 4", b"rows = 4 # \xff\xfe"))
    with pytest.raises(ConfigError, match=r"bwsd\.toml: not UTF-8 text: byte 0xff at offset"):
        load_config(path)


def test_arrays_nested_a_thousand_deep_are_a_config_error(tmp_path):
    path = tmp_path / "bwsd.toml"
    path.write_text(GOOD + "[api]\nhost = " + "[" * 1000 + "]" * 1000 + "\n")
    with pytest.raises(ConfigError, match=r"bwsd\.toml: not valid TOML: nested too deeply"):
        load_config(path)


@pytest.mark.slow
@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(st.binary(max_size=300) | st.text(max_size=300).map(str.encode))
def test_any_bytes_are_a_config_or_a_config_error(tmp_path, data):
    load(tmp_path, data)


@pytest.mark.slow
@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(st.binary(max_size=40), st.integers(0, len(GOOD)))
def test_a_good_file_with_bytes_spliced_in_is_a_config_or_a_config_error(tmp_path, junk, at):
    raw = GOOD.encode()
    load(tmp_path, raw[:at] + junk + raw[at:])


values: Any = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats()
    | st.text(max_size=10)
    | st.decimals(allow_nan=True, allow_infinity=True),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3)
    ),
    max_leaves=10,
)
tables = st.dictionaries(
    st.sampled_from(
        ["machine", "yarn", "fieldbus", "controller", "api", "plc", "journal", "simulator", "bogus"]
    ),
    st.dictionaries(
        st.sampled_from(
            [*MACHINE, "port", "host", "backend", "max_contacts", "diameter", "modbus", "x"]
        ),
        values,
        max_size=4,
    )
    | values,
    max_size=4,
)


@pytest.mark.slow
@settings(max_examples=400, deadline=None)
@given(tables)
def test_any_structure_is_a_config_or_a_config_error(data):
    with contextlib.suppress(ConfigError):
        parse_config({"machine": dict(MACHINE), **data})
