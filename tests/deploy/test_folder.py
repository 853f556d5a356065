"""`bwsd init DIR`: a loom folder that runs from anywhere, made whole or not at all."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from bwsd.config import SCHEMA, load_config
from bwsd.deploy.folder import init_folder
from bwsd.errors import BwsdError
from bwsd.paths import state_folder
from bwsd.shipped import examples

ROOT = Path(__file__).resolve().parents[2]


def _bwsd(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd, "the bwsd console script is not installed beside this Python"
    return subprocess.run([bwsd, *args], capture_output=True, text=True, timeout=120, cwd=cwd)


def test_init_makes_the_folder_and_says_what_it_made(tmp_path):
    done = _bwsd("init", "loom", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    folder = tmp_path / "loom"
    assert sorted(p.name for p in folder.iterdir()) == ["examples", "loom.toml", "state", "systemd"]
    assert (folder / "state").stat().st_mode & 0o077 == 0
    shipped = {e.name for e in examples()} - {"loom.toml"}
    assert {p.name for p in (folder / "examples").iterdir()} == shipped
    assert sorted(p.name for p in (folder / "systemd").iterdir()) == [
        "bwsd-simulator.service",
        "bwsd.service",
    ]
    for path in ("loom.toml", "state", "examples", "systemd/bwsd.service"):
        assert str(folder / path) in done.stdout


def test_the_config_sets_every_key_with_a_comment(tmp_path):
    made = init_folder(tmp_path / "loom")
    text = made.config.read_text()
    data = tomllib.loads(text)
    for table, keys in SCHEMA.items():
        node = data
        for part in table.split("."):
            node = node[part]
        for key in keys:
            assert key in node, f"[{table}] {key} is not set"
            line = next(ln for ln in text.splitlines() if re.match(rf"{key}\s*=", ln))
            assert "#" in line, f"[{table}] {key} has no comment: {line}"
    config = load_config(made.config)
    for port in ("port",):
        assert config.table("api")[port] and config.table("plc")[port]
    assert data["daemon"]["state_dir"] == "state"


def test_the_state_folder_is_the_folders_own_from_anywhere(tmp_path, monkeypatch):
    made = init_folder(tmp_path / "loom")
    monkeypatch.chdir(tmp_path)
    assert state_folder(load_config("loom/loom.toml")) == made.folder / "state"
    monkeypatch.chdir(made.folder / "examples")
    assert state_folder(load_config("../loom.toml")) == made.folder / "state"


def test_the_units_name_the_folder_and_this_installation(tmp_path):
    made = init_folder(tmp_path / "loom", user="loom-operator")
    daemon = (made.folder / "systemd" / "bwsd.service").read_text()
    bwsd = Path(sys.executable).parent / "bwsd"
    assert f"ExecStart={bwsd} serve --config {made.config}\n" in daemon
    assert f"ReadWritePaths={made.folder}/state\n" in daemon
    assert f"WorkingDirectory={made.folder}/state\n" in daemon
    assert "User=loom-operator\n" in daemon and "DynamicUser" not in daemon
    assert "StateDirectory" not in daemon and "ConfigurationDirectory" not in daemon
    mock = (made.folder / "systemd" / "bwsd-simulator.service").read_text()
    program = made.folder / "examples" / "braid-2x2.bws"
    assert f"ExecStart={bwsd} mock --config {made.config} --program {program}\n" in mock


def test_a_folder_that_is_not_empty_is_refused_and_left_alone(tmp_path):
    folder = tmp_path / "loom"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(BwsdError, match=r"loom: is not empty.*nothing written"):
        init_folder(folder)
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loom"]  # no half-made folder
    (tmp_path / "file").write_text("x")
    with pytest.raises(BwsdError, match="exists and is not a folder"):
        init_folder(tmp_path / "file")


def test_an_empty_folder_is_used_and_a_failure_leaves_nothing(tmp_path, monkeypatch):
    (tmp_path / "empty").mkdir()
    assert init_folder(tmp_path / "empty").config.is_file()

    def broken(*args: object) -> str:
        raise OSError("disk full")

    monkeypatch.setattr("bwsd.deploy.folder.render", broken)
    with pytest.raises(OSError, match="disk full"):
        init_folder(tmp_path / "second")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty"]


def test_a_user_that_does_not_exist_is_refused(tmp_path):
    done = _bwsd("init", "loom", "--user", "no-such-user-here", cwd=tmp_path)
    assert done.returncode == 2
    assert "--user no-such-user-here: no such user" in done.stderr
    assert list(tmp_path.iterdir()) == []
