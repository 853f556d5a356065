"""`bwsd relax` and `bwsd simulate --relax`: the config's tensions, the solver's figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.relax import Options, relax
from tests.relax.conftest import ROOT, twin_of

pytestmark = pytest.mark.slow  # every test here is in the slow tier

WEAVE = ROOT / "examples" / "weave-plain.bws"


def _run(*args: str) -> dict[str, object]:
    done = subprocess.run(
        [sys.executable, "-m", "bwsd.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    found: dict[str, object] = json.loads(done.stdout)
    return found


def _without_seconds(summary: dict[str, object]) -> dict[str, object]:
    return {k: v for k, v in summary.items() if k != "seconds"}


def test_relax_and_simulate_relax_take_the_tensions_of_the_config(tmp_path: Path) -> None:
    text = (ROOT / "config" / "weave-plain.toml").read_text(encoding="utf-8")
    config = tmp_path / "weave.toml"
    config.write_text(text.replace("[yarn]\n", "[yarn]\nweft_tension = 0.25\n"), "utf-8")
    sk = twin_of("weave-plain")
    expected = _without_seconds(relax(sk, Options(weft_tension=0.25)).summary())
    equal = _without_seconds(relax(sk, Options()).summary())
    assert expected != equal  # the tensions' ratio changes the relaxed weave
    alone = _run("relax", str(WEAVE), "--config", str(config), "--json")
    assert _without_seconds(alone) == expected
    during = _run("simulate", str(WEAVE), "--config", str(config), "--relax", "--json")
    assert isinstance(during["relaxed"], dict)
    assert _without_seconds(during["relaxed"]) == expected
