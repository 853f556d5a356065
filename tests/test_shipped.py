"""The shipped examples and configs by name (``example:NAME``) in every command, from any
folder, and `bwsd examples` listing them."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.config import load_config
from bwsd.errors import BwsdError
from bwsd.program import load_program
from bwsd.shipped import EXAMPLE, examples, is_shipped, resolve

ROOT = Path(__file__).resolve().parents[1]


def _bwsd(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd, "the bwsd console script is not installed beside this Python"
    return subprocess.run([bwsd, *args], capture_output=True, text=True, timeout=300, cwd=cwd)


@pytest.mark.slow
def test_simulate_runs_a_shipped_example_with_its_shipped_config_from_an_empty_folder(tmp_path):
    files = ("example:braid-L.bws", "--config", "example:braid-L.toml")
    done = _bwsd("simulate", *files, "--json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    machine = load_config(ROOT / "config" / "braid-L.toml").machine
    count = len(load_program(ROOT / "examples" / "braid-L.bws", machine).instructions)
    assert json.loads(done.stdout)["instructions"] == count > 0
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_metrics_and_the_mock_loom_take_them_too(tmp_path):
    done = _bwsd("metrics", "example:twist.bws", "--config", "example:twist.toml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    help_text = _bwsd("mock", "--help", cwd=tmp_path).stdout
    assert "example:NAME" in help_text


def test_every_example_resolves_to_the_source_trees_file():
    found = examples()
    assert {e.name for e in found} == {p.name for p in (ROOT / "examples").iterdir()} | {
        p.name for p in (ROOT / "config").glob("*.toml")
    }
    for example in found:
        assert resolve(EXAMPLE + example.name).read_bytes() == example.path.read_bytes()
        assert is_shipped(resolve(EXAMPLE + example.name))
    assert resolve("config/loom.toml") == Path("config/loom.toml")
    assert not is_shipped(ROOT / "config" / "loom.toml")  # the source tree's own file


def test_loaders_take_example_names():
    config = load_config("example:braid-2x2.toml")
    assert config.path == str(resolve("example:braid-2x2.toml"))
    assert load_program("example:braid-2x2.bws", config.machine).instructions


@pytest.mark.parametrize("name", ["nothing.bws", "", "../config/loom.toml", "config/loom.toml"])
def test_an_unknown_example_is_an_error_that_lists_them(name):
    with pytest.raises(BwsdError, match=rf"example:{name}: no such example \(shipped: .*braid-2x2"):
        resolve(EXAMPLE + name)


def test_examples_lists_each_with_what_it_is(tmp_path):
    done = _bwsd("examples", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "example:braid-L.bws" in done.stdout and "example:braid-L.toml" in done.stdout
    for example in examples():
        line = next(ln for ln in done.stdout.splitlines() if ln.startswith(EXAMPLE + example.name))
        assert f"{example.kind}: {example.title}" in line
