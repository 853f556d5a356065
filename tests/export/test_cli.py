"""`bwsd slice` and `bwsd metrics`: argument parsing, output, and a real simulated program."""

from __future__ import annotations

import argparse
import json

import pytest
from rich.console import Console

from bwsd.export import cli
from bwsd.export.metrics import metrics
from bwsd.export.tables import print_metrics

from .conftest import build, warp

CONFIG = """\
[machine]
rows = 2
cols = 2
pitch_x = 10.0
pitch_y = 10.0
d_mat = 100.0
c_mat = 0.5

[yarn]
diameter = 1.0
"""

# The worked example of the twin's reference semantics: 2 yarns, 15 contacts, 34 nodes.
PROGRAM = """\
YARN diameter=1
FILL row=0 col=0
X.
.X
END
REPEAT 4
ROW 0:+1 1:-1
COL 1:+1 0:-1
ROW 1:-1 0:+1
COL 0:-1 1:+1
END
"""


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bwsd")
    cli.configure(p.add_subparsers(dest="command", required=True))
    return p


def run(argv: list[str]) -> int:
    args = parser().parse_args(argv)
    status: int = args.handler(args)
    return status


def test_slice_arguments():
    args = parser().parse_args(["slice", "p.bws", "--config", "c.toml", "--z", "2.5"])
    assert (args.handler, args.program, args.config, args.z) == (
        cli.run_slice,
        "p.bws",
        "c.toml",
        2.5,
    )
    assert args.output == "slice.png"
    with pytest.raises(SystemExit):
        parser().parse_args(["slice", "p.bws", "--config", "c.toml"])


def test_metrics_arguments():
    args = parser().parse_args(["metrics", "p.bws", "--config", "c.toml", "--json"])
    assert (args.handler, args.json, args.cycle_length) == (cli.run_metrics, True, None)
    with pytest.raises(SystemExit):
        parser().parse_args(["metrics", "p.bws"])


def test_tables_render(small):
    console = Console(record=True, width=120)
    print_metrics(metrics(small, 3), console)
    text = console.export_text()
    for expected in (
        "Skeleton",
        "3 warp, 1 weft",
        "21.000 mm",
        "weft-0",
        "90.000",
        "1 1",
        "mean [deg]",
    ):
        assert expected in text


def test_tables_without_section():
    console = Console(record=True, width=120)
    print_metrics(metrics(build([warp([(0, 0, 0), (0, 0, 9)])]), None), console)
    assert "no contacts" in console.export_text()


@pytest.fixture
def files(tmp_path):
    (tmp_path / "machine.toml").write_text(CONFIG, encoding="utf-8")
    (tmp_path / "example.bws").write_text(PROGRAM, encoding="utf-8")
    return tmp_path


def test_metrics_json_of_the_worked_example(files, capsys):
    status = run(
        ["metrics", str(files / "example.bws"), "--config", str(files / "machine.toml"), "--json"]
    )
    assert status == 0
    result = json.loads(capsys.readouterr().out)
    assert (result["yarns"], result["contacts"], result["nodes"]) == (
        {"warp": 2, "weft": 0},
        15,
        34,
    )
    assert result["instructions"] == 16
    assert result["cycles"]["length"] == 4
    assert sum(result["cycles"]["counts"]) == 15


@pytest.mark.slow
def test_slice_of_the_worked_example(files, capsys):
    out = files / "cut.png"
    status = run(
        [
            "slice",
            str(files / "example.bws"),
            "--config",
            str(files / "machine.toml"),
            "--z",
            "20",
            "-o",
            str(out),
        ]
    )
    assert status == 0
    assert out.read_bytes()[:4] == b"\x89PNG"
    assert capsys.readouterr().out.startswith(f"{out}: 2 yarn crossings")
