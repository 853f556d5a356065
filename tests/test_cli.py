"""`bwsd` itself: every command listed in `bwsd --help`, and a parser that imports nothing
heavy (numpy, FastAPI, asyncua, Dask, VTK...) until a command runs."""

from __future__ import annotations

import argparse
import importlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.cli import COMMANDS

HEAVY = {"numpy", "fastapi", "starlette", "uvicorn", "asyncua", "dask", "distributed", "vtk"}
HEAVY |= {"vtkmodules", "pymodbus", "scipy", "matplotlib", "pyarrow", "canopen", "pytexgen"}
PROBE = """
import contextlib, io, json, sys
from bwsd.cli import main
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    try:
        main(json.loads(sys.argv[1]))
    except SystemExit:
        pass
print(json.dumps(sorted({m.partition(".")[0] for m in sys.modules})))
"""


def _imported(*argv: str) -> set[str]:
    """The top-level modules loaded by `bwsd ARGV`, in a fresh interpreter."""
    command = [sys.executable, "-c", PROBE, json.dumps(argv)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=True)
    return set(json.loads(done.stdout))


def test_help_lists_every_command_with_its_help():
    bwsd = shutil.which("bwsd", path=str(Path(sys.executable).parent))
    assert bwsd
    done = subprocess.run([bwsd, "--help"], capture_output=True, text=True, timeout=60)
    shown = done.stdout
    flat = " ".join(shown.split())
    for name, (_, text) in COMMANDS.items():
        assert f" {name} {text} " in flat + " ", name


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_the_table_says_what_each_module_registers(name):
    module, text = COMMANDS[name]
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    importlib.import_module(module).configure(sub)
    action = next(a for a in sub._choices_actions if a.dest == name)
    assert action.help == text


@pytest.mark.slow
def test_the_parser_imports_nothing_heavy():
    assert not _imported("--help") & HEAVY
    for name in COMMANDS:
        loaded = _imported(name, "--help")
        assert not loaded & HEAVY, f"bwsd {name} --help imports {loaded & HEAVY}"


@pytest.mark.slow
def test_generating_a_braid_imports_nothing_heavy(tmp_path):
    assert not _imported("program", "braid4", "--rows", "3", "--cols", "3") & HEAVY
    assert not _imported("program", "twist") & HEAVY


def test_a_command_runs_from_its_own_module():
    from bwsd.cli import build_parser

    args = build_parser("program").parse_args(["program", "twist", "--turns", "2"])
    assert args.handler.__module__ == "bwsd.program.cli"
    with pytest.raises(SystemExit):
        build_parser("nonsense").parse_args(["nonsense"])
