"""What the install commands bring: the README's and CI's name every extra, and the configs
and examples shipped with the package are those of the source tree."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from bwsd.errors import BwsdError
from bwsd.shipped import DEMO_CONFIG, DEMO_PROGRAM, config_file, example_file

ROOT = Path(__file__).resolve().parents[1]
EXTRAS = set(
    tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
)


def _installed_extras(text: str) -> list[set[str]]:
    """The extras of every ``pip install ... -e TARGET`` of the project in ``text``."""
    found = []
    for match in re.finditer(r"pip install [^\n&|;]*?-e ('?)\.(\[([a-z,-]+)\])?\1(?=\s|$)", text):
        found.append(set(match[3].split(",")) if match[3] else set())
    return found


def test_the_readme_installs_every_extra_but_dev():
    first_block = (ROOT / "README.md").read_text().split("```sh\n", 1)[1].split("```", 1)[0]
    assert _installed_extras(first_block) == [EXTRAS - {"dev"}]
    assert {"export", "canopen"} <= EXTRAS


def test_ci_installs_every_extra():
    assert _installed_extras((ROOT / ".ci" / "run").read_text()) == [EXTRAS]


def test_the_shipped_configs_and_examples_are_those_of_the_source_tree():
    configs = sorted((ROOT / "config").glob("*.toml"))
    examples = sorted((ROOT / "examples").glob("*.bws"))
    assert configs and examples
    for path in configs:
        assert config_file(path.name).read_bytes() == path.read_bytes()
    for path in examples:
        assert example_file(path.name).read_bytes() == path.read_bytes()
    assert config_file() == config_file(DEMO_CONFIG)
    assert example_file() == example_file(DEMO_PROGRAM)


def test_a_file_that_is_not_shipped_is_a_bwsd_error():
    with pytest.raises(BwsdError, match=r"config/nothing\.toml is not shipped"):
        config_file("nothing.toml")
