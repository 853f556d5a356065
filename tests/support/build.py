"""Building the wheel and installing it in fresh venvs, as a user would: what the packaging
tests share. The wheel, and a venv with the wheel and its core dependencies only, are made
once for a whole test run (every xdist worker waits for the first to make them), since each
costs as much as hundreds of other tests."""

from __future__ import annotations

import fcntl
import os
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# The files of three.js the preview page imports (docs/preview.md), shipped in the wheel when
# `npm ci` has put them in bwsd/web/node_modules before the build.
THREE = (
    "LICENSE",
    "package.json",
    "build/three.module.js",
    "build/three.core.js",
    "examples/jsm/controls/OrbitControls.js",
)
THREE_ROOT = ROOT / "bwsd" / "web" / "node_modules" / "three"
_OFFLINE = (
    "NewConnectionError",
    "Temporary failure in name resolution",
    "Network is unreachable",
    "ConnectTimeout",
    "ReadTimeout",
    "Could not fetch URL",
)
# What pip says of a download cut midway, once it has given up resuming it.
_CUT = ("incomplete-download", "Connection interrupted", "ConnectionResetError")


def unavailable(message: str) -> None:
    """Skip for want of something the machine lacks; under CI (``CI=true``) that fails."""
    if os.environ.get("CI") == "true":
        pytest.fail(message)
    pytest.skip(message)


def clean_tree(tree: Path) -> Path:
    """A copy of what a checkout holds (no build/ left by an earlier build, no compiled
    kernel), with the three.js files the page needs when ``npm ci`` has installed them."""
    tree.mkdir()
    for name in ("setup.py", "pyproject.toml", "README.md", "MANIFEST.in", "LICENSE"):
        shutil.copy(ROOT / name, tree / name)
    skip = shutil.ignore_patterns("*.so", "node_modules", "__pycache__")
    for folder in ("bwsd", "simulator_hw", "config", "examples", "systemd"):
        shutil.copytree(ROOT / folder, tree / folder, ignore=skip, symlinks=True)
    for name in THREE:
        if (THREE_ROOT / name).is_file():
            target = tree / "bwsd" / "web" / "node_modules" / "three" / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(THREE_ROOT / name, target)
    return tree


def venv_env() -> dict[str, str]:
    """The environment for a venv's commands: this test run's Python left out of it."""
    env = {
        k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")
    }
    env.update(PIP_DISABLE_PIP_VERSION_CHECK="1", PIP_NO_INPUT="1", PYTHONUNBUFFERED="1")
    return env


def fresh_venv(folder: Path, *install: str) -> tuple[Path, dict[str, str]]:
    """A new venv at ``folder`` with ``install`` put in by pip from the package index; its
    bin folder and an environment that leaves this test run's Python out of it. The venv gets
    no pip of its own: this run's pip installs into it (``pip --python``)."""
    env = venv_env()
    made = subprocess.run(
        [sys.executable, "-m", "venv", "--without-pip", str(folder)],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    if made.returncode != 0:
        unavailable(f"python -m venv failed: {made.stderr.strip()[-500:]}")
    bin_dir = folder / "bin"
    if install:
        pip_install(bin_dir, env, *install)
    return bin_dir, env


def pip_install(
    bin_dir: Path, env: dict[str, str], *install: str, attempts: int = 3, pause_s: float = 15.0
) -> None:
    """``install`` into the venv of ``bin_dir`` by this run's pip. A download the index cut
    midway, that pip gave up resuming, is tried again after a pause (``pause_s`` times the
    attempt's number), at most ``attempts`` times in all."""
    command = [sys.executable, "-m", "pip", "--python", str(bin_dir / "python"), "install"]
    for attempt in range(1, attempts + 1):
        run = subprocess.run(
            [*command, "-q", *install],
            capture_output=True,
            text=True,
            timeout=900,
            env=env,
        )
        cut = run.returncode != 0 and any(sign in run.stderr for sign in _CUT)
        if not cut or attempt == attempts:
            break
        time.sleep(pause_s * attempt)
    if run.returncode != 0 and any(sign in run.stderr for sign in _OFFLINE + _CUT):
        unavailable(f"the package index cannot be reached: {run.stderr.strip()[-500:]}")
    assert run.returncode == 0, run.stderr[-3000:]


def installed(bin_dir: Path, env: dict[str, str]) -> dict[str, str]:
    """Name -> version of every distribution in the venv."""
    code = (
        "import importlib.metadata as m\n"
        "for d in m.distributions(): print(d.metadata['Name'].lower(), d.version)"
    )
    out = subprocess.run(
        [str(bin_dir / "python"), "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        check=True,
    ).stdout
    return {
        normal_name(name): version for name, version in (line.split() for line in out.splitlines())
    }


def normal_name(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def run_folder(factory: pytest.TempPathFactory) -> Path:
    """A folder of this test run that every xdist worker sees (each has a base of its own
    below it)."""
    base = factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def once(factory: pytest.TempPathFactory, name: str, make: Callable[[Path], object]) -> Path:
    """The folder ``name`` of this run, filled by ``make`` in whichever worker asks first;
    the others wait for it. A ``make`` that fails leaves nothing: the next asker tries again."""
    root = run_folder(factory)
    folder = root / name
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / ".done").exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            try:
                make(folder)
            except BaseException:
                shutil.rmtree(folder, ignore_errors=True)
                raise
            (folder / ".done").touch()
    return folder


def built_wheel(factory: pytest.TempPathFactory) -> Path:
    """The wheel built from a clean copy of the tree, once for the run; what the build
    printed is beside it in build.log."""

    def build(where: Path) -> None:
        tree = clean_tree(where / "tree")
        command = [sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "-w", str(where)]
        run = subprocess.run([*command, str(tree)], capture_output=True, text=True, timeout=900)
        assert run.returncode == 0, run.stderr[-2000:]
        (where / "build.log").write_text(run.stdout + run.stderr)

    (wheel,) = once(factory, "wheel", build).glob("bwsd-*.whl")
    return wheel


def core_venv(factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    """A venv with the wheel and its core dependencies only, made once for the run (the
    tests that use it only run what it installed): its bin folder and a fresh environment."""
    wheel = built_wheel(factory)
    folder = once(factory, "core-venv", lambda where: fresh_venv(where / "bwsd", str(wheel)))
    return folder / "bwsd" / "bin", venv_env()
