"""`bwsd token add|list|remove`: the token printed once, only its hash on disk."""

from __future__ import annotations

import argparse
import hashlib
import json

import pytest

from bwsd.api import TokenError, TokenStore
from bwsd.api.cli import configure

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
    config = tmp_path / "bwsd.toml"
    config.write_text(CONFIG)
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)
    assert _run("token", "add", "a", "--role", "viewer", "--config", str(config)) == 0
    assert [e.name for e in TokenStore.load(tmp_path / "state" / "tokens.json").entries] == ["a"]
    assert not (tmp_path / "tokens.json").exists()
    monkeypatch.setenv("STATE_DIRECTORY", f"{tmp_path}/sd:{tmp_path}/other")
    assert _run("token", "add", "b", "--role", "admin", "--config", str(config)) == 0
    assert [e.name for e in TokenStore.load(tmp_path / "sd" / "tokens.json").entries] == ["b"]
    where = ("--config", str(config), "--state-dir", str(tmp_path / "given"))
    assert _run("token", "add", "c", "--role", "operator", *where) == 0
    assert [e.name for e in TokenStore.load(tmp_path / "given" / "tokens.json").entries] == ["c"]
    assert not (tmp_path / "other").exists()


def test_list_does_not_create_the_state_folder(tmp_path, capsys):
    config = tmp_path / "bwsd.toml"
    config.write_text(CONFIG)
    where = ("--config", str(config), "--state-dir", str(tmp_path / "missing"))
    assert _run("token", "list", *where) == 0
    assert capsys.readouterr().out == ""
    assert not (tmp_path / "missing").exists()
