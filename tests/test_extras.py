"""The core without its extras: VTK, pytexgen, matplotlib, canopen and python-can blocked.

Everything but the exports, `bwsd slice` and the CANopen backend works; those end with one
line naming the extra to install.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from bwsd.errors import ExtraMissingError
from bwsd.extras import CANOPEN, VTK, needs
from tests.support.fieldbus import toml

ROOT = Path(__file__).resolve().parents[1]
BLOCKED = ("vtk", "vtkmodules", "pytexgen", "matplotlib", "meshio", "canopen", "can")
CONFIG = str(ROOT / "config" / "loom.toml")
PROGRAM = str(ROOT / "examples" / "braid-2x2.bws")


@pytest.fixture(scope="module")
def blocked(tmp_path_factory) -> dict[str, str]:
    """An environment whose Pythons (and their child processes) cannot import the extras."""
    folder = tmp_path_factory.mktemp("no-extras")
    (folder / "sitecustomize.py").write_text(
        "import sys\n"
        f"for name in {BLOCKED!r}:\n"
        "    sys.modules[name] = None  # import fails: ModuleNotFoundError\n"
    )
    path = os.pathsep.join(p for p in (str(folder), os.environ.get("PYTHONPATH", "")) if p)
    return {**os.environ, "PYTHONPATH": path, "PYTHONUNBUFFERED": "1"}


def bwsd(
    env: dict[str, str], *args: str, cwd: Path, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "bwsd.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=cwd,
        check=False,
    )


def test_the_block_holds(blocked, tmp_path):
    code = (
        "import importlib, sys\n"
        "for name in sys.argv[1:]:\n"
        "    try:\n"
        "        importlib.import_module(name)\n"
        "    except ModuleNotFoundError:\n"
        "        continue\n"
        "    raise SystemExit(name)\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code, *BLOCKED],
        env=blocked,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0, run.stdout + run.stderr


@pytest.mark.slow
def test_the_core_imports_and_simulates_without_the_extras(blocked, tmp_path):
    code = (
        "import sys\n"
        "import bwsd.api.app, bwsd.cli, bwsd.daemon, bwsd.daemon_cli, bwsd.export\n"
        "import bwsd.export.cli, bwsd.fieldbus.modbus, bwsd.plc.tags, bwsd.simulate\n"
        "import simulator_hw.app, simulator_hw.__main__\n"
        "loaded = sorted(n for n, m in sys.modules.items()\n"
        f"                if m is not None and n.partition('.')[0] in {BLOCKED!r})\n"
        "print(loaded)\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code],
        env=blocked,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"
    done = bwsd(
        blocked,
        "simulate",
        PROGRAM,
        "--config",
        CONFIG,
        "--json",
        "--export",
        str(tmp_path / "s.json"),
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert '"contacts": 73' in done.stdout
    assert (tmp_path / "s.json").is_file()
    metrics = bwsd(blocked, "metrics", PROGRAM, "--config", CONFIG, "--json", cwd=tmp_path)
    assert metrics.returncode == 0, metrics.stderr
    assert '"contacts": 73' in metrics.stdout


@pytest.mark.slow
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["simulate", "--export", "x.vtu"], "writing .vtu needs VTK: pip install 'bwsd[export]'"),
        (["simulate", "--export", "x.vtp"], "writing .vtp needs VTK: pip install 'bwsd[export]'"),
        (
            ["simulate", "--export", "x.tg3"],
            "writing .tg3 needs TexGen (pytexgen): pip install 'bwsd[export]'",
        ),
        (
            ["slice", "--z", "10", "-o", "x.png"],
            "drawing a slice needs matplotlib: pip install 'bwsd[export]'",
        ),
    ],
)
def test_an_export_without_the_extra_is_one_line_naming_it(blocked, tmp_path, args, message):
    run = bwsd(blocked, args[0], PROGRAM, "--config", CONFIG, *args[1:], cwd=tmp_path)
    assert run.returncode == 2
    assert run.stderr == f"bwsd: error: {message}\n"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_the_canopen_backend_without_the_extra_is_one_line_naming_it(blocked, tmp_path):
    config = tmp_path / "canopen.toml"
    config.write_text(CONFIG_TEXT.replace('backend = "modbus"', 'backend = "canopen"'))
    run = bwsd(blocked, "hw", "status", "--config", str(config), cwd=tmp_path)
    assert run.returncode == 2
    assert run.stderr == (
        f"bwsd: error: {config}: [fieldbus.backend]: backend 'canopen' needs "
        "canopen and python-can: pip install 'bwsd[canopen]'\n"
    )
    mock = subprocess.run(
        [sys.executable, "-m", "simulator_hw", "--config", str(config)],
        env=blocked,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert mock.returncode == 2
    assert mock.stderr == (
        "simulator_hw: error: the CANopen side of the mock loom needs canopen "
        "and python-can: pip install 'bwsd[canopen]'\n"
    )


@pytest.mark.slow
def test_the_mock_loom_serves_modbus_alone_without_the_canopen_extra(blocked, tmp_path):
    config = tmp_path / "mock.toml"
    config.write_text(
        toml(
            {
                "machine": {
                    "rows": 2,
                    "cols": 2,
                    "pitch_x": 10.0,
                    "pitch_y": 10.0,
                    "d_mat": 100.0,
                    "c_mat": 0.5,
                }
            }
        )
    )
    command = [
        sys.executable,
        "-m",
        "simulator_hw",
        "--config",
        str(config),
        "--modbus-port",
        "0",
        "--socketcand-port",
        "0",
        "--control-port",
        "0",
    ]
    pipe = subprocess.PIPE
    mock = subprocess.Popen(
        command,
        env=blocked,
        cwd=tmp_path,
        stdout=pipe,
        stderr=pipe,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert mock.stdout is not None and mock.stderr is not None
        line = mock.stdout.readline()
        assert line.startswith("ready "), line + mock.stderr.read()
        assert [p.split("=")[0] for p in line.split()[1:]] == ["modbus", "control"]
        assert mock.stderr.readline() == (
            "simulator_hw: serving Modbus only: the CANopen side "
            "of the mock loom needs canopen and python-can: pip "
            "install 'bwsd[canopen]'\n"
        )
    finally:
        mock.terminate()
        mock.communicate(timeout=20)


@pytest.mark.slow
def test_the_demo_runs_without_the_extras(blocked, tmp_path):
    """The daemon, its API and PLC tags, and the mock loom over Modbus: all of the core."""
    run = bwsd(
        blocked,
        "demo",
        "--exit-when-done",
        "--state-dir",
        "state",
        "--api-port",
        "0",
        "--plc-port",
        "0",
        "--modbus-port",
        "0",
        "--socketcand-port",
        "0",
        "--control-port",
        "0",
        cwd=tmp_path,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "Complete: 50 instructions done, 73 contacts" in run.stdout
    assert "socketcand=" not in run.stdout


def test_needs_names_the_extra_only_for_its_own_modules():
    message = r"^writing \.vtu needs VTK: pip install 'bwsd\[export\]'$"
    with pytest.raises(ExtraMissingError, match=message), needs(VTK, "writing .vtu"):
        raise ModuleNotFoundError("No module named 'vtkmodules.x'", name="vtkmodules.x")
    # another module missing is a fault of its own, not a missing extra
    with pytest.raises(ModuleNotFoundError), needs(CANOPEN, "backend 'canopen'"):
        raise ModuleNotFoundError("No module named 'numpy'", name="numpy")


def test_the_core_requires_none_of_the_extras():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    names = {_name(r) for r in project["dependencies"]}
    assert names == {
        "numpy",
        "scipy",
        "pymodbus",
        "rich",
        "fastapi",
        "uvicorn",
        "prometheus-client",
    }
    extras = {k: {_name(r) for r in v} for k, v in project["optional-dependencies"].items()}
    assert extras["export"] == {"vtk", "pytexgen", "matplotlib"}
    assert extras["canopen"] == {"canopen", "python-can"}
    everything = set().union(*extras.values(), names)
    assert "meshio" not in everything


def _name(requirement: str) -> str:
    for stop in "[<>=~!; ":
        requirement = requirement.split(stop, 1)[0]
    return requirement.strip().lower()


CONFIG_TEXT = (ROOT / "config" / "loom.toml").read_text()
