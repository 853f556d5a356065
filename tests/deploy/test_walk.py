"""docs/service.md followed literally by a new user who has only the wheel: installed into a
fresh venv standing for /opt/bwsd, then the "A loom in the foreground" block run as written
from an empty folder (no source tree anywhere near), in a network namespace of its own."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
from pathlib import Path

import pytest

from tests.support.build import core_venv
from tests.test_readme import _namespaced

ROOT = Path(__file__).resolve().parents[2]


def section_blocks(text: str, title: str) -> str:
    """The shell blocks of the ``## title`` section, in order, as one script."""
    section = text.split(f"\n## {title}\n", 1)[1].split("\n## ", 1)[0]
    return "".join(re.findall(r"^```sh\n(.*?)^```$", section, re.MULTILINE | re.DOTALL))


def test_the_install_block_is_a_venv_in_opt_and_the_walk_uses_it():
    text = (ROOT / "docs" / "service.md").read_text()
    install = section_blocks(text, "Install")
    assert "python3 -m venv /opt/bwsd" in install
    assert "/opt/bwsd/bin/pip install bwsd" in install
    assert "pip install bwsd" not in install.replace("/opt/bwsd/bin/pip install bwsd", "")
    walk = section_blocks(text, "A loom in the foreground")
    assert walk.startswith("export PATH=/opt/bwsd/bin:$PATH\n")
    assert "bwsd init loom" in walk and "bwsd token add" in walk and "/#token=" in walk
    service = section_blocks(text, "As a service")
    assert "--config /etc/bwsd/bwsd.toml" in service


@pytest.mark.slow
def test_docs_service_walk_runs_from_the_wheel_alone(tmp_path_factory, tmp_path):
    bin_dir, env = core_venv(tmp_path_factory)  # the wheel in a fresh venv of its own
    opt = bin_dir.parent
    walk = section_blocks((ROOT / "docs" / "service.md").read_text(), "A loom in the foreground")
    script = tmp_path / "walk.sh"
    script.write_text(walk.replace("/opt/bwsd", str(opt)))  # the venv stands for /opt/bwsd
    here = tmp_path / "empty"
    here.mkdir()
    env["HOME"] = str(tmp_path)
    command = [*_namespaced(), "bash", "-euo", "pipefail", str(script)]
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
    assert state["name"] == "Complete" and state["index"] == state["count"] == 50, state
    assert re.search(r"^open http://127\.0\.0\.1:8080/#token=\S{32,}$", out, re.MULTILINE)
    assert "bwsd: warning" not in err
    daemon_log = (here / "daemon.log").read_text()
    assert str(opt) in (here / "loom" / "systemd" / "bwsd.service").read_text()
    assert "Traceback" not in daemon_log + (here / "mock.log").read_text()
    assert ROOT.as_posix() not in daemon_log  # nothing of the source tree was used
