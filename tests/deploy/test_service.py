"""`bwsd service install`: the units of this installation and a config whose state folder is
the service's, written whole after every check, or nothing."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.config import load_config
from bwsd.deploy.service import install
from bwsd.errors import BwsdError
from bwsd.paths import configured_state_folder


def _bwsd(*args: str) -> subprocess.CompletedProcess[str]:
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd, "the bwsd console script is not installed beside this Python"
    return subprocess.run([bwsd, *args], capture_output=True, text=True, timeout=120)


def test_install_writes_the_units_and_a_config_and_says_what_it_did(tmp_path):
    done = _bwsd("service", "install", "--prefix", str(tmp_path))
    assert done.returncode == 0, done.stderr
    config = tmp_path / "etc" / "bwsd" / "bwsd.toml"
    units = tmp_path / "etc" / "systemd" / "system"
    assert f"wrote {config}" in done.stdout
    for name in ("bwsd.service", "bwsd-simulator.service"):
        assert f"wrote {units / name}" in done.stdout
    assert "systemctl enable --now bwsd.service" in done.stdout
    assert configured_state_folder(load_config(config)) == Path("/var/lib/bwsd")
    daemon = (units / "bwsd.service").read_text()
    bwsd = Path(sys.executable).parent / "bwsd"
    assert f"ExecStart={bwsd} serve --config /etc/bwsd/bwsd.toml\n" in daemon
    assert "DynamicUser=yes\n" in daemon and "StateDirectory=bwsd\n" in daemon
    mock = (units / "bwsd-simulator.service").read_text()
    assert f"ExecStart={bwsd} mock --config /etc/bwsd/bwsd.toml --program " in mock


def test_a_config_already_there_is_kept_and_the_units_updated(tmp_path):
    install(prefix=tmp_path)
    config = tmp_path / "etc" / "bwsd" / "bwsd.toml"
    config.write_text(config.read_text().replace("port = 8080", "port = 8081"))
    unit = tmp_path / "etc" / "systemd" / "system" / "bwsd.service"
    unit.write_text("stale")
    done = install(user="root", prefix=tmp_path)
    assert (done[0].path, done[0].kept) == (config, True)
    assert "port = 8081" in config.read_text()
    assert "User=root\n" in unit.read_text() and "DynamicUser" not in unit.read_text()


def test_a_config_with_another_state_folder_is_refused_and_nothing_written(tmp_path):
    config = tmp_path / "etc" / "bwsd" / "bwsd.toml"
    config.parent.mkdir(parents=True)
    shipped = load_config("example:loom.toml").path
    config.write_text(Path(shipped).read_text())  # state_dir = "state": /etc/bwsd/state
    with pytest.raises(
        BwsdError,
        match=r"state_dir is .state., but the service keeps its "
        r'state in /var/lib/bwsd: set state_dir = "/var/lib/bwsd"',
    ):
        install(prefix=tmp_path)
    assert not (tmp_path / "etc" / "systemd").exists()


def test_an_unknown_user_is_refused_before_anything_is_written(tmp_path, monkeypatch):
    import bwsd.deploy.service as service

    monkeypatch.setattr(service, "_under", lambda root, path: tmp_path / path.relative_to("/"))
    with pytest.raises(BwsdError, match="--user no-such-user-here: no such user"):
        install(user="no-such-user-here")
    assert list(tmp_path.iterdir()) == []


def test_an_installation_in_a_home_folder_is_refused(monkeypatch):
    from bwsd.deploy import service

    with pytest.raises(BwsdError, match=r"/home/ann/venv, which the service's ProtectHome=yes"):
        service._check_installation(Path("/home/ann/venv/bin"))
    service._check_installation(Path("/opt/bwsd/bin"))
