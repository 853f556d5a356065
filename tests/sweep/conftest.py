"""Specs, the reference run of one candidate, and the `bwsd` command in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from bwsd.export.formed import takeups_of
from bwsd.export.metrics import metrics, section
from bwsd.export.mixing import section_header, simulate_with_visits
from bwsd.program.generators import GENERATORS
from bwsd.program.parser import parse_program

ROOT = Path(__file__).resolve().parents[2]
WEAVE = ROOT / "examples" / "weave-plain.bws"
WEAVE_CONFIG = ROOT / "config" / "weave-plain.toml"

# 20 candidates: 5 take-ups x 2 convergence ratios x 2 cycle counts of a 3 x 3 braid, each
# long enough for a formed zone.
BRAID_SPEC = """
[sweep]
generator = "braid4"
[fixed]
rows = 3
cols = 3
diameter = 0.5
[vary]
takeup = [2, 3.0, 4.5, 6.0, 8.0]
c_mat = [0.3, 0.6]
cycles = [12, 14]
"""

# A fixed program on its config: a pitch of 5 mm closes the shed (the twin refuses it), two
# rows make a case leave the matrix (the validation refuses it).
WEAVE_SPEC = f"""
[sweep]
program = "{WEAVE}"
config = "{WEAVE_CONFIG}"
[vary]
rows = [3, 2]
pitch = [10.0, 5.0]
"""


def write(folder: Path, text: str, name: str = "spec.toml") -> Path:
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


def reference(kind: str, params: dict[str, Any]) -> dict[str, Any]:
    """``bwsd metrics`` of one generated candidate, run here on its own, without the sweep."""
    generated = GENERATORS[kind](**params)
    program = parse_program(generated.program)
    named = section_header(generated.program)
    assert named is not None
    twin, visits = simulate_with_visits(generated.machine, program, named.section)
    sk = twin.skeleton()
    band = section(sk)
    z = None if band is None else (band["z"][0] + band["z"][1]) / 2
    return metrics(
        sk, program.cycle_length, takeups=takeups_of(program), z=z, named=named, visits=visits
    )


def bwsd(*args: str, cwd: Path, timeout: float = 180) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.run(
        [sys.executable, "-m", "bwsd.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
        env=env,
        check=False,
    )


TIMINGS = ("seconds", "relax_seconds")  # the columns that differ from run to run


def without_timing(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows without ``seconds`` (and ``relax_seconds``), which differ from run to run."""
    return [{k: v for k, v in row.items() if k not in TIMINGS} for row in rows]
