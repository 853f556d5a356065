"""The systemd units: valid (no warning at all) and hardened, checked offline."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
UNITS = ["bwsd.service", "bwsd-simulator.service"]
THRESHOLD = "20"  # tenths of the exposure level (0 safest .. 100): both units stay under 2.0


def _installed(tmp_path: Path, unit: str) -> Path:
    """The unit with its executables pointing at this environment's, as an install would."""
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd, "the bwsd console script is not installed beside this Python"
    text = (ROOT / "systemd" / unit).read_text()
    text = text.replace("/usr/local/bin/bwsd", bwsd)
    text = text.replace("/usr/local/bin/python3", sys.executable)
    path = tmp_path / unit
    path.write_text(text)
    return path


@pytest.mark.parametrize("unit", UNITS)
def test_unit_verifies_without_a_single_warning(tmp_path, unit):
    assert shutil.which("systemd-analyze"), "systemd-analyze is missing (.ci/run installs it)"
    done = subprocess.run(["systemd-analyze", "verify", str(_installed(tmp_path, unit))],
                          capture_output=True, text=True, timeout=60, check=False)  # fmt: skip
    assert done.returncode == 0
    assert done.stderr == ""


@pytest.mark.parametrize("unit", UNITS)
def test_unit_is_hardened(tmp_path, unit):
    done = subprocess.run(
        ["systemd-analyze", "security", "--offline=true", f"--threshold={THRESHOLD}",
         str(_installed(tmp_path, unit))],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:]
    assert "Overall exposure level" in done.stdout


def test_daemon_unit_is_a_notify_service_with_a_watchdog_and_a_state_folder():
    text = (ROOT / "systemd" / "bwsd.service").read_text()
    for line in ("Type=notify", "WatchdogSec=", "StateDirectory=bwsd", "DynamicUser=yes",
                 "ProtectSystem=strict", "AF_CAN"):  # fmt: skip
        assert line in text
