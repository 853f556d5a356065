"""The shipped units filled in for a layout (bwsd.deploy.units)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bwsd.deploy import units
from bwsd.deploy.units import UNITS, Layout, render
from bwsd.errors import BwsdError
from bwsd.shipped import unit_file


def test_the_shipped_units_hold_every_line_render_fills_in():
    for name in UNITS:
        text = unit_file(name)
        assert units.SHIPPED_BIN in text and units.SHIPPED_CONFIG in text
        for line in ("DynamicUser=yes", "ProtectHome=yes", "PrivateTmp=yes"):
            assert f"\n{line}\n" in text
    daemon = unit_file("bwsd.service")
    for line in ("StateDirectory=bwsd", "StateDirectoryMode=0700", "WorkingDirectory=%S/bwsd"):
        assert f"\n{line}\n" in daemon
    assert units.SHIPPED_PROGRAM in unit_file("bwsd-simulator.service")


def test_the_default_layout_keeps_the_shipped_unit_but_its_paths_and_header():
    layout = Layout(Path("/srv/venv/bin"), Path("/etc/bwsd/bwsd.toml"))
    text = render("bwsd.service", layout, "a test")
    shipped = unit_file("bwsd.service")
    assert text.startswith("# bwsd.service, written by a test (docs/service.md).\n[Unit]\n")
    body = shipped[shipped.index("[Unit]") :].replace("/opt/bwsd/bin/", "/srv/venv/bin/")
    assert text.endswith(body)


def test_a_loom_folder_in_a_home_or_tmp_is_reachable():
    folder = Path("/home/ann/loom")
    home = Layout(Path("/opt/bwsd/bin"), folder / "loom.toml", state_dir=folder / "state")
    text = render("bwsd.service", home, "a test")
    assert "\nProtectHome=read-only\n" in text and "\nPrivateTmp=yes\n" in text
    temp = Layout(Path("/opt/bwsd/bin"), Path("/tmp/loom/loom.toml"), state_dir=Path("/tmp/s"))
    text = render("bwsd.service", temp, "a test")
    assert "\nPrivateTmp=no\n" in text and "\nProtectHome=yes\n" in text


def test_a_unit_without_a_line_to_fill_in_is_an_error(monkeypatch):
    monkeypatch.setattr(units, "unit_file", lambda name: "[Unit]\nExecStart=/usr/bin/x\n")
    with pytest.raises(BwsdError, match="the shipped unit has no '/opt/bwsd/bin/' to fill in"):
        render("bwsd.service", Layout(Path("/b"), Path("/c")), "a test")
