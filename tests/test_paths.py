"""The state folder and the token file and journal in it (bwsd.paths)."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

from bwsd.config import parse_config
from bwsd.paths import journal_file, state_folder, tokens_file

MACHINE = {"rows": 2, "cols": 2, "pitch_x": 1.0, "pitch_y": 1.0, "d_mat": 10.0, "c_mat": 0.5}


@pytest.fixture(autouse=True)
def _no_state_directory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)


def test_the_given_folder_comes_before_state_directory(tmp_path, monkeypatch):
    monkeypatch.setenv("STATE_DIRECTORY", str(tmp_path / "sd"))
    assert state_folder(tmp_path / "given") == tmp_path / "given"
    assert state_folder(str(tmp_path / "text")) == tmp_path / "text"
    assert not (tmp_path / "sd").exists()


def test_state_directory_is_used_when_no_folder_is_given(tmp_path, monkeypatch):
    monkeypatch.setenv("STATE_DIRECTORY", f"{tmp_path}/first:{tmp_path}/second")
    assert state_folder() == tmp_path / "first"
    assert state_folder("") == tmp_path / "first"
    assert (tmp_path / "first").is_dir() and not (tmp_path / "second").exists()


def test_the_default_is_state_in_the_current_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("STATE_DIRECTORY", "")
    assert state_folder() == Path("state")
    assert (tmp_path / "state").is_dir()


def test_a_missing_folder_is_created_private_with_its_parents(tmp_path):
    folder = state_folder(tmp_path / "a" / "b")
    assert folder.is_dir()
    assert stat.S_IMODE(folder.stat().st_mode) & 0o077 == 0


def test_an_existing_folder_is_kept_as_it_is(tmp_path):
    folder = tmp_path / "shared"
    folder.mkdir(mode=0o755)
    folder.chmod(0o755)
    (folder / "journal.db").write_text("kept")
    assert state_folder(folder) == folder
    assert stat.S_IMODE(folder.stat().st_mode) == 0o755
    assert (folder / "journal.db").read_text() == "kept"


def test_create_false_only_names_the_folder(tmp_path):
    assert state_folder(tmp_path / "later", create=False) == tmp_path / "later"
    assert not (tmp_path / "later").exists()


def test_relative_files_are_taken_from_the_state_folder(tmp_path):
    config = parse_config({"machine": MACHINE})
    assert tokens_file(config, tmp_path) == tmp_path / "tokens.json"
    assert journal_file(config, tmp_path) == tmp_path / "journal.db"
    nested = parse_config({"machine": MACHINE, "api": {"tokens_file": "keys/t.json"},
                           "journal": {"path": "db/j.db"}})  # fmt: skip
    assert tokens_file(nested, tmp_path) == tmp_path / "keys" / "t.json"
    assert journal_file(nested, tmp_path) == tmp_path / "db" / "j.db"


def test_absolute_files_are_kept(tmp_path):
    config = parse_config({"machine": MACHINE, "api": {"tokens_file": str(tmp_path / "t.json")},
                           "journal": {"path": str(tmp_path / "j.db")}})  # fmt: skip
    assert tokens_file(config, Path("/elsewhere")) == tmp_path / "t.json"
    assert journal_file(config, Path("/elsewhere")) == tmp_path / "j.db"
