"""The README's commands as a user runs them: `bwsd demo`, and `bwsd token add` then `serve`."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import httpx

from bwsd.config import load_config
from bwsd.program import load_program
from bwsd.twin import simulate
from tests.fieldbus.conftest import start_mock
from tests.test_daemon import daemon_config

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


def _readme_commands(section: str) -> list[list[str]]:
    """The README's `bwsd ...` lines (comments dropped) from its ``## section``."""
    text = (ROOT / "README.md").read_text().split(f"## {section}\n", 1)[1].split("\n## ")[0]
    return [line.split("#")[0].split() for line in text.splitlines() if line.startswith("bwsd ")]


def test_the_readme_token_steps_give_a_token_that_serve_accepts(tmp_path):
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    commands = _readme_commands("Commands")
    serve = next(c for c in commands if c[1] == "serve")
    add = next(c for c in commands if c[1:3] == ["token", "add"])
    assert serve[serve.index("--config") + 1] == add[add.index("--config") + 1]
    assert "--state-dir" not in serve + add  # each finds the state folder on its own
    work = tmp_path / "work"  # a fresh working folder holding only the config
    config = work / add[add.index("--config") + 1]
    config.parent.mkdir(parents=True)
    mock = start_mock(tmp_path, {})
    daemon_config(tmp_path, mock, config)
    env = {k: v for k, v in os.environ.items() if k != "STATE_DIRECTORY"}
    try:
        added = subprocess.run([bwsd, *add[1:]], capture_output=True, text=True, timeout=60,
                               check=False, cwd=work, env=env)  # fmt: skip
        assert added.returncode == 0, added.stderr
        token = added.stdout.strip()
        assert re.fullmatch(r"[A-Za-z0-9_-]{40,}", token), added.stdout
        served = subprocess.Popen([bwsd, *serve[1:]], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
                                  cwd=work, env=env)  # fmt: skip
        try:
            assert served.stdout is not None
            line = served.stdout.readline()
            assert line.startswith("ready "), line + served.communicate(timeout=30)[1]
            urls = dict(part.split("=", 1) for part in line.split()[1:])
            answer = httpx.get(f"{urls['api']}/api/v1/state", timeout=30,
                               headers={"Authorization": f"Bearer {token}"})  # fmt: skip
            assert answer.status_code == 200, answer.text
        finally:
            served.terminate()
            served.communicate(timeout=30)
    finally:
        mock.stop()
    assert (work / "state" / "tokens.json").is_file()
    assert sorted(p.name for p in work.iterdir()) == ["config", "state"]
