"""The state folder and the token file and journal in it (bwsd.paths): the config says where,
beside itself by default, never the current folder."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

from bwsd.config import Config, load_config, parse_config
from bwsd.errors import ConfigError
from bwsd.paths import journal_file, state_folder, tokens_file

MACHINE = {"rows": 2, "cols": 2, "pitch_x": 1.0, "pitch_y": 1.0, "d_mat": 10.0, "c_mat": 0.5}


@pytest.fixture(autouse=True)
def _no_state_directory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)


def _config(folder: Path, daemon: str = "") -> Config:
    """A config file in ``folder`` (made), with ``daemon`` as its [daemon] table."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "loom.toml"
    path.write_text(
        "[machine]\nrows = 2\ncols = 2\npitch_x = 1.0\npitch_y = 1.0\nd_mat = 10.0\n"
        f"c_mat = 0.5\n[daemon]\n{daemon}\n"
    )
    return load_config(path)


def test_the_default_lies_beside_the_config_not_in_the_current_folder(tmp_path, monkeypatch):
    config = _config(tmp_path / "loom")
    monkeypatch.chdir(tmp_path)
    assert state_folder(config) == tmp_path / "loom" / "state"
    assert (tmp_path / "loom" / "state").is_dir() and not (tmp_path / "state").exists()
    relative = load_config("loom/loom.toml")  # named from elsewhere: the same folder
    assert state_folder(relative) == tmp_path / "loom" / "state"


def test_state_dir_in_the_config_is_taken_from_the_config_folder(tmp_path):
    up = _config(tmp_path / "etc", 'state_dir = "../var/x"')
    assert state_folder(up, create=False) == tmp_path / "var" / "x"
    absolute = _config(tmp_path / "a", f'state_dir = "{tmp_path}/abs"')
    assert state_folder(absolute) == tmp_path / "abs"


def test_the_given_folder_comes_before_the_config(tmp_path):
    config = _config(tmp_path)
    assert state_folder(config, tmp_path / "given") == tmp_path / "given"
    assert state_folder(config, str(tmp_path / "text")) == tmp_path / "text"
    assert not (tmp_path / "state").exists()


def test_a_state_directory_from_systemd_must_be_the_configured_folder(tmp_path, monkeypatch):
    config = _config(tmp_path, f'state_dir = "{tmp_path}/sd"')
    monkeypatch.setenv("STATE_DIRECTORY", f"{tmp_path}/sd:{tmp_path}/second")
    assert state_folder(config) == tmp_path / "sd"
    other = _config(tmp_path / "etc")  # state beside it: not what systemd gave
    wanted = (
        r"\[daemon\.state_dir\]: the state folder would be .*etc/state, but systemd gives this "
        r'service .*/sd \(StateDirectory=\): set state_dir = ".*/sd"'
    )
    with pytest.raises(ConfigError, match=wanted):
        state_folder(other)
    assert not (tmp_path / "etc" / "state").exists()


def test_a_shipped_config_needs_a_state_folder_given(tmp_path):
    config = load_config("example:loom.toml")
    with pytest.raises(ConfigError, match=r"shipped with bwsd.*give --state-dir DIR.*bwsd init"):
        state_folder(config)
    assert state_folder(config, tmp_path / "s") == tmp_path / "s"


def test_a_missing_folder_is_created_private_with_its_parents(tmp_path):
    folder = state_folder(_config(tmp_path), tmp_path / "a" / "b")
    assert folder.is_dir()
    assert stat.S_IMODE(folder.stat().st_mode) & 0o077 == 0


def test_an_existing_folder_is_kept_as_it_is(tmp_path):
    folder = tmp_path / "shared"
    folder.mkdir(mode=0o755)
    folder.chmod(0o755)
    (folder / "journal.db").write_text("kept")
    assert state_folder(_config(tmp_path), folder) == folder
    assert stat.S_IMODE(folder.stat().st_mode) == 0o755
    assert (folder / "journal.db").read_text() == "kept"


def test_create_false_only_names_the_folder(tmp_path):
    assert state_folder(_config(tmp_path), tmp_path / "later", create=False) == tmp_path / "later"
    assert not (tmp_path / "later").exists()


def test_relative_files_are_taken_from_the_state_folder(tmp_path):
    config = parse_config({"machine": MACHINE})
    assert tokens_file(config, tmp_path) == tmp_path / "tokens.json"
    assert journal_file(config, tmp_path) == tmp_path / "journal.db"
    nested = parse_config(
        {"machine": MACHINE, "api": {"tokens_file": "keys/t.json"}, "journal": {"path": "db/j.db"}}
    )
    assert tokens_file(nested, tmp_path) == tmp_path / "keys" / "t.json"
    assert journal_file(nested, tmp_path) == tmp_path / "db" / "j.db"


def test_absolute_files_are_kept(tmp_path):
    config = parse_config(
        {
            "machine": MACHINE,
            "api": {"tokens_file": str(tmp_path / "t.json")},
            "journal": {"path": str(tmp_path / "j.db")},
        }
    )
    assert tokens_file(config, Path("/elsewhere")) == tmp_path / "t.json"
    assert journal_file(config, Path("/elsewhere")) == tmp_path / "j.db"
