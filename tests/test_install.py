"""What the install commands bring: the README's and CI's name every extra, and the configs
and examples shipped with the package are those of the source tree."""

from __future__ import annotations

import ast
import importlib.metadata
import re
import sys
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


def test_the_readme_installs_every_extra_but_dev_and_bench():
    first_block = (ROOT / "README.md").read_text().split("```sh\n", 1)[1].split("```", 1)[0]
    assert _installed_extras(first_block) == [EXTRAS - {"dev", "bench"}]
    assert {"export", "canopen"} <= EXTRAS


def test_ci_installs_every_extra():
    assert _installed_extras((ROOT / ".ci" / "run").read_text()) == [EXTRAS]


def _distribution(requirement: str) -> str:
    return _normal(re.split(r"[\[<>=~!;\s]", requirement, maxsplit=1)[0])


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _imported(script: Path) -> set[str]:
    """The top-level modules a script imports, wherever in it."""
    found = set()
    for node in ast.walk(ast.parse(script.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name.partition(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.partition(".")[0])
    return found


@pytest.mark.slow
def test_the_bench_extra_carries_what_the_benchmarks_import():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    offered = {_distribution(r) for r in project["dependencies"]}
    offered |= {_distribution(r) for r in project["optional-dependencies"]["bench"]}
    scripts = sorted((ROOT / "bench").glob("*.py"))
    ours = {"bwsd", "simulator_hw", "tests", "bench", "__future__"} | {p.stem for p in scripts}
    owners = importlib.metadata.packages_distributions()
    assert len(scripts) >= 10
    for script in scripts:
        for module in _imported(script) - ours - set(sys.stdlib_module_names):
            dists = {_normal(d) for d in owners.get(module, [])}
            assert dists & offered, f"{script.name} imports {module} ({dists}), not in bench"


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
