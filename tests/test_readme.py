"""The README's walk-through, run as written: its Commands blocks, literally, one after the
other in one shell, from an empty folder.

The commands name the shipped config's fixed ports (8080, 15020, ...), as a user's do. They
run in a network namespace of their own (``unshare --net``), where every port is free and
nothing of theirs reaches another test's, so the text needs no change to run here.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import NoReturn

import pytest

ROOT = Path(__file__).resolve().parents[1]
STEPS = (
    "bwsd init loom",
    "bwsd mock ",
    "bwsd serve ",
    "/healthz",
    "bwsd token add",
    '"$API/programs"',
    "commands/reset",
    "commands/start",
    '"name":"(Complete',
    "/#token=$TOKEN",
)


def readme_commands(text: str) -> str:
    """The shell blocks of the README's "Commands" section, in order, as one script."""
    section = text.split("\n## Commands\n", 1)[1].split("\n## ", 1)[0]
    return "".join(re.findall(r"^```sh\n(.*?)^```$", section, re.MULTILINE | re.DOTALL))


def test_the_commands_are_an_ordered_walk_through():
    script = readme_commands((ROOT / "README.md").read_text())
    where = [script.find(step) for step in STEPS]
    assert -1 not in where, [s for s, at in zip(STEPS, where, strict=True) if at == -1]
    assert where == sorted(where), "the walk-through is out of order"
    assert not re.search(r"(?<![\w/])(config|examples)/\S+\.(toml|bws)", script)  # source tree


def _namespaced() -> list[str]:
    """A command prefix giving what follows a network of its own, with loopback up."""
    unshare, ip = shutil.which("unshare"), shutil.which("ip")
    if not unshare or not ip:
        _unavailable("unshare and ip (util-linux, iproute2) are needed")
    prefix = [unshare, "--net", "--map-root-user"] if os.geteuid() else [unshare, "--net"]
    probe = subprocess.run(
        [*prefix, ip, "link", "set", "lo", "up"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    if probe.returncode != 0:
        _unavailable(f"no network namespace here: {probe.stderr.strip()}")
    return [*prefix, "sh", "-c", f'{ip} link set lo up && exec "$@"', "sh"]


def _unavailable(message: str) -> NoReturn:
    if os.environ.get("CI") == "true":
        pytest.fail(message)
    pytest.skip(message)


@pytest.mark.slow
def test_the_readme_commands_run_as_written_from_an_empty_folder(tmp_path):
    script = readme_commands((ROOT / "README.md").read_text())
    (tmp_path / "walk.sh").write_text(script)
    home = tmp_path / "home"
    home.mkdir()
    venv = str(Path(sys.executable).parent)
    env = {**os.environ, "PATH": f"{venv}{os.pathsep}{os.environ['PATH']}", "HOME": str(home)}
    here = tmp_path / "empty"
    here.mkdir()
    command = [*_namespaced(), "bash", "-euo", "pipefail", str(tmp_path / "walk.sh")]
    run = subprocess.Popen(
        command,
        cwd=here,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        out, err = run.communicate(timeout=600)
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
            run.communicate()
    logs = "".join(f"\n--- {p.name}\n{p.read_text()[-3000:]}" for p in here.glob("*.log"))
    assert run.returncode == 0, out[-3000:] + err[-3000:] + logs
    state = json.loads(re.findall(r'^\{"state".*\}$', out, re.MULTILINE)[-1])
    assert state["name"] == "Complete", state
    token = re.search(r"^open http://127\.0\.0\.1:8080/#token=(\S+)$", out, re.MULTILINE)
    assert token and len(token[1]) >= 32
    loaded = json.loads(re.findall(r'^\{"id".*$', out, re.MULTILINE)[0])
    assert loaded["name"] == "braid-2x2.bws" and loaded["instructions"] == 50
    for made in (
        "loom/loom.toml",
        "loom/state/journal.db",
        "loom/state/tokens.json",
        "out/braid-L.json",
        "out/braid-L.vtp",
        "slice.png",
        "my.bws",
        "braid-angle.parquet",
    ):
        assert (here / made).is_file(), made
    assert "bwsd: warning" not in err  # the token went where the daemon reads it
