"""The package's own build compiles the twin's kernel, and says clearly when it cannot."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_without_a_compiler_the_build_fails_with_a_clear_message(tmp_path):
    for name in ("setup.py", "pyproject.toml", "README.md", "MANIFEST.in"):
        shutil.copy(ROOT / name, tmp_path / name)
    shutil.copytree(
        ROOT / "bwsd",
        tmp_path / "bwsd",
        ignore=shutil.ignore_patterns("*.so", "node_modules", "__pycache__"),
    )
    env = {**os.environ, "CC": str(tmp_path / "no-such-compiler")}
    run = subprocess.run([sys.executable, "setup.py", "-q", "build_ext"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert run.returncode != 0
    assert "bwsd: cannot build its twin kernel" in run.stderr
    assert "C compiler (gcc or clang) and the Python headers" in run.stderr
    assert "no-such-compiler" in run.stderr
    assert "Traceback" not in run.stderr


def test_the_compiled_kernel_has_no_fused_multiply_add():
    """Built with -ffp-contract=off: a fused multiply-add would change the float filters'
    error bounds (docs/twin.md, "Exactness")."""
    from bwsd.twin import _kernel

    code = subprocess.run(["objdump", "-d", _kernel.__file__], capture_output=True, text=True,
                          check=True).stdout  # fmt: skip
    assert "cvtsi2sd" in code or "scvtf" in code  # it is the float code we think it is
    assert not re.search(r"\b(v?fn?m(add|sub)\w*)\b", code)


@pytest.mark.slow
def test_the_wheel_carries_its_type_information(tmp_path):
    """``py.typed`` and the kernel's stub ship in the wheel, so the hints reach users."""
    import zipfile

    tree = tmp_path / "tree"  # a clean copy: no build/ folder left by an earlier build
    tree.mkdir()
    for name in ("setup.py", "pyproject.toml", "README.md", "MANIFEST.in"):
        shutil.copy(ROOT / name, tree / name)
    skip = shutil.ignore_patterns("*.so", "node_modules", "__pycache__")
    for package in ("bwsd", "simulator_hw"):
        shutil.copytree(ROOT / package, tree / package, ignore=skip)
    run = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w",
                          str(tmp_path), str(tree)], capture_output=True, text=True,
                         timeout=600)  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    (wheel,) = tmp_path.glob("bwsd-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {"bwsd/py.typed", "bwsd/twin/_kernel.pyi"} <= names
