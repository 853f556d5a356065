"""Without the opcua extra (asyncua blocked), the commands that need it say which to install."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.fieldbus import MACHINE, toml

pytestmark = pytest.mark.slow  # every test here is in the slow tier

NEEDS = "needs asyncua: pip install 'bwsd[opcua]'"


@pytest.fixture
def blocked(tmp_path: Path) -> dict[str, str]:
    folder = tmp_path / "no-asyncua"
    folder.mkdir()
    (folder / "sitecustomize.py").write_text("import sys\nsys.modules['asyncua'] = None\n")
    path = os.pathsep.join(p for p in (str(folder), os.environ.get("PYTHONPATH", "")) if p)
    return {**os.environ, "PYTHONPATH": path}


def bwsd(env: dict[str, str], *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "bwsd.cli", *args],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        cwd=cwd,
        check=False,
    )


def test_cert_and_serve_without_the_extra_name_it(blocked, tmp_path):
    config = tmp_path / "bwsd.toml"
    config.write_text(
        toml(
            {
                "machine": MACHINE,
                "api": {"port": 0},
                "plc": {"port": 0},
                "opcua": {"enabled": True, "port": 0},
            }
        )
    )
    state = tmp_path / "state"
    cert = bwsd(
        blocked, "opcua", "cert", "--config", str(config), "--state-dir", str(state), cwd=tmp_path
    )
    assert (cert.returncode, cert.stderr) == (2, f"bwsd: error: bwsd opcua cert {NEEDS}\n")
    served = bwsd(
        blocked, "serve", "--config", str(config), "--state-dir", str(state), cwd=tmp_path
    )
    assert served.returncode == 2, served.stderr
    assert served.stderr.endswith(f"bwsd: error: [opcua] enabled = true {NEEDS}\n")
    assert served.stdout == ""  # never reported ready
    assert not (state / "opcua").exists()
