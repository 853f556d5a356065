"""`bwsd demo`: the README's first command, run to the end of its program."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from bwsd.config import load_config
from bwsd.program import load_program
from bwsd.twin import simulate

ROOT = Path(__file__).resolve().parents[1]


def test_demo_runs_the_example_braid_on_the_mock_loom_to_complete(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    done = subprocess.run(
        [bwsd, "demo", "--exit-when-done", "--state-dir", str(tmp_path / "state")],
        capture_output=True, text=True, timeout=300, check=False, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert "api: http://127.0.0.1:8080" in done.stdout
    assert "operator token: " in done.stdout
    machine = load_config(ROOT / "config/loom.toml").machine
    twin = simulate(machine, load_program(ROOT / "examples/braid-2x2.bws", machine))
    assert f"Complete: 50 instructions done, {twin.contact_count} contacts" in done.stdout
    assert (tmp_path / "state" / "journal.db").is_file()
