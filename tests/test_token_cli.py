"""`bwsd token add|list|remove`: the token printed once, only its hash on disk, in the
daemon's state folder."""

from __future__ import annotations

import argparse
import hashlib
import json

import pytest

from bwsd.api import ROLES, TokenError, TokenStore
from bwsd.errors import ConfigError
from bwsd.journal import Journal
from bwsd.token_cli import ROLES_TEXT, configure

CONFIG = (
    "[machine]\nrows = 4\ncols = 4\npitch_x = 10.0\npitch_y = 10.0\nd_mat = 100.0\nc_mat = 0.5\n"
)


def _run(*argv: str) -> int:
    parser = argparse.ArgumentParser(prog="bwsd")
    configure(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return int(args.handler(args))


def test_add_prints_the_token_once_and_stores_its_hash(tmp_path, capsys):
    config = tmp_path / "bwsd.toml"
    config.write_text(CONFIG + '[api]\ntokens_file = "keys/tokens.json"\n')
    where = ("--config", str(config), "--state-dir", str(tmp_path / "state"))
    assert _run("token", "add", "line-3", "--role", "operator", *where) == 0
    out, err = capsys.readouterr()
    token = out.strip()
    assert len(out.splitlines()) == 1 and len(token) >= 40 and token not in err
    path = tmp_path / "state" / "keys" / "tokens.json"
    stored = json.loads(path.read_text())["tokens"]
    assert [(t["name"], t["role"]) for t in stored] == [("line-3", "operator")]
    assert stored[0]["sha256"] == hashlib.sha256(token.encode()).hexdigest()
    assert token not in path.read_text()
    assert TokenStore.load(path).check(token) == ("line-3", "operator")
    assert _run("token", "list", *where) == 0
    listed = capsys.readouterr().out
    assert listed.startswith("line-3\toperator\t") and token not in listed
    assert _run("token", "remove", "line-3", *where) == 0
    assert TokenStore.load(path).check(token) is None
    with pytest.raises(TokenError, match="no token named 'line-3'"):
        _run("token", "remove", "line-3", *where)


def test_add_finds_the_state_folder_as_serve_does_and_creates_it(tmp_path, monkeypatch):
    """Beside the config (its [daemon] state_dir), from whatever folder it is run; never a
    second token file in the current folder."""
    config = tmp_path / "loom" / "bwsd.toml"
    config.parent.mkdir()
    config.write_text(CONFIG)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert _run("token", "add", "a", "--role", "viewer", "--config", str(config)) == 0
    folder = tmp_path / "loom" / "state"
    assert [e.name for e in TokenStore.load(folder / "tokens.json").entries] == ["a"]
    assert list(elsewhere.iterdir()) == []
    where = ("--config", str(config), "--state-dir", str(tmp_path / "given"))
    assert _run("token", "add", "c", "--role", "operator", *where) == 0
    assert [e.name for e in TokenStore.load(tmp_path / "given" / "tokens.json").entries] == ["c"]


def test_under_systemd_a_config_naming_another_folder_is_refused(tmp_path, monkeypatch):
    config = tmp_path / "bwsd.toml"
    config.write_text(CONFIG)
    monkeypatch.setenv("STATE_DIRECTORY", str(tmp_path / "sd"))
    with pytest.raises(ConfigError, match=r'\[daemon\.state_dir\]: .* set state_dir = "'):
        _run("token", "add", "b", "--role", "admin", "--config", str(config))
    assert not (tmp_path / "sd").exists() and not (tmp_path / "state").exists()


def test_a_state_folder_without_a_daemon_journal_is_named(tmp_path, capsys):
    config = tmp_path / "bwsd.toml"
    config.write_text(CONFIG)
    assert _run("token", "add", "a", "--role", "viewer", "--config", str(config)) == 0
    err = capsys.readouterr().err
    assert f"no daemon has used the state folder {tmp_path}/state yet" in err
    Journal.open(tmp_path / "state" / "journal.db").close()
    assert _run("token", "list", "--config", str(config)) == 0
    assert "no daemon" not in capsys.readouterr().err


def test_the_roles_named_in_the_help_are_the_roles(capsys):
    with pytest.raises(SystemExit):
        _run("token", "add", "--help")
    shown = " ".join(capsys.readouterr().out.split())
    assert ROLES_TEXT in shown and f"{ROLES[0]}, {ROLES[1]} or {ROLES[2]}" == ROLES_TEXT
    with pytest.raises(SystemExit):
        _run("token", "add", "x", "--role", "boss", "--config", "c.toml")
    assert "'boss' is not a role: viewer, operator or admin" in capsys.readouterr().err


def test_list_does_not_create_the_state_folder(tmp_path, capsys):
    config = tmp_path / "bwsd.toml"
    config.write_text(CONFIG)
    where = ("--config", str(config), "--state-dir", str(tmp_path / "missing"))
    assert _run("token", "list", *where) == 0
    assert capsys.readouterr().out == ""
    assert not (tmp_path / "missing").exists()
