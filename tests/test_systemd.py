"""The systemd units, as `bwsd service install` and `bwsd init` write them: valid (no warning
at all, every executable there) and hardened, checked offline by systemd-analyze."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from bwsd.deploy.folder import init_folder
from bwsd.deploy.service import install

ROOT = Path(__file__).resolve().parents[1]
UNITS = ["bwsd.service", "bwsd-simulator.service"]
THRESHOLD = "20"  # tenths of the exposure level (0 safest .. 100): both units stay under 2.0


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The units of `bwsd service install --prefix`: this venv's, a dynamic user."""
    root = tmp_path_factory.mktemp("root")
    install(prefix=root)
    return root / "etc" / "systemd" / "system"


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The units of `bwsd init`: a loom folder's, run as a named user."""
    made = init_folder(tmp_path_factory.mktemp("looms") / "loom", user="loom-operator")
    return made.folder / "systemd"


def _verify(unit: Path) -> subprocess.CompletedProcess[str]:
    assert shutil.which("systemd-analyze"), "systemd-analyze is missing (.ci/run installs it)"
    command = ["systemd-analyze", "verify", str(unit)]
    return subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)


@pytest.mark.parametrize("unit", UNITS)
def test_installed_unit_verifies_without_a_single_warning(installed, unit):
    done = _verify(installed / unit)
    assert done.returncode == 0
    assert done.stderr == ""


@pytest.mark.parametrize("unit", UNITS)
def test_a_loom_folders_unit_verifies_without_a_single_warning(folder, unit):
    done = _verify(folder / unit)
    assert done.returncode == 0
    assert done.stderr == ""


@pytest.mark.parametrize("unit", UNITS)
def test_installed_unit_is_hardened(installed, unit):
    done = subprocess.run(
        [
            "systemd-analyze",
            "security",
            "--offline=true",
            f"--threshold={THRESHOLD}",
            str(installed / unit),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stdout[-2000:]
    assert "Overall exposure level" in done.stdout


def test_a_unit_naming_a_missing_executable_is_caught(installed, tmp_path):
    """What the verify tests rest on: a unit whose ExecStart is not there fails them."""
    text = (installed / "bwsd.service").read_text()
    broken = tmp_path / "bwsd.service"
    broken.write_text(text.replace("/bin/bwsd serve", "/bin/no-such-bwsd serve"))
    assert _verify(broken).stderr != ""


def test_daemon_unit_is_a_notify_service_with_a_watchdog_and_a_state_folder():
    text = (ROOT / "systemd" / "bwsd.service").read_text()
    for line in (
        "Type=notify",
        "WatchdogSec=",
        "StateDirectory=bwsd",
        "DynamicUser=yes",
        "ProtectSystem=strict",
        "AF_CAN",
    ):
        assert line in text
