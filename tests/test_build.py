"""The package's own build compiles the twin's kernel, and says clearly when it cannot."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from packaging.version import Version

from tests.support.build import (
    THREE,
    THREE_ROOT,
    built_wheel,
    clean_tree,
    core_venv,
    fresh_venv,
    installed,
    normal_name,
    pip_install,
    unavailable,
)

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
    run = subprocess.run(
        [sys.executable, "setup.py", "-q", "build_ext"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode != 0
    assert "bwsd: cannot build its twin kernel" in run.stderr
    assert "C compiler (gcc or clang) and the Python headers" in run.stderr
    assert "no-such-compiler" in run.stderr
    assert "Traceback" not in run.stderr


def test_the_compiled_kernel_has_no_fused_multiply_add():
    """Built with -ffp-contract=off: a fused multiply-add would change the float filters'
    error bounds (docs/twin.md, "Exactness")."""
    from bwsd.twin import _kernel

    code = subprocess.run(
        ["objdump", "-d", _kernel.__file__], capture_output=True, text=True, check=True
    ).stdout
    assert "cvtsi2sd" in code or "scvtf" in code  # it is the float code we think it is
    assert not re.search(r"\b(v?fn?m(add|sub)\w*)\b", code)


# The extras' distributions, and meshio, which nothing needs any more.
NOT_CORE = ("vtk", "pytexgen", "matplotlib", "canopen", "python-can", "meshio")
ALL_FREE = [
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
]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The run's wheel (tests/support/build.py); what the build printed is in build.log."""
    return built_wheel(tmp_path_factory)


def run_demo(bin_dir: Path, env: dict[str, str], cwd: Path) -> str:
    """``bwsd demo --exit-when-done`` on free ports in ``cwd`` (made if missing): its output,
    once it completed."""
    cwd.mkdir(exist_ok=True)
    before = {p.name for p in cwd.iterdir()}
    done = subprocess.run(
        [str(bin_dir / "bwsd"), "demo", "--exit-when-done", *ALL_FREE],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
        cwd=cwd,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert re.search(
        r"^mock loom: modbus=127\.0\.0\.1:\d+ .*control=127\.0\.0\.1:\d+$",
        done.stdout,
        re.MULTILINE,
    ), done.stdout
    assert re.search(r"^api: http://127\.0\.0\.1:\d+$", done.stdout, re.MULTILINE)
    assert re.search(r"^plc: modbus-tcp://127\.0\.0\.1:\d+$", done.stdout, re.MULTILINE)
    assert "Complete: 50 instructions done, 73 contacts" in done.stdout
    assert sorted({p.name for p in cwd.iterdir()} - before) == ["out"]  # its journal alone
    return done.stdout


@pytest.mark.slow
def test_the_build_warns_of_nothing_and_the_license_is_an_spdx_expression(wheel):
    """No deprecation (setuptools' table-form license stops building in 2027), the license
    as its SPDX expression with its file, setuptools bounded both ways."""
    log = (wheel.parent / "build.log").read_text()
    assert "Deprecat" not in log, [line for line in log.splitlines() if "eprecat" in line]
    assert "bwsd: warning" not in log  # three.js was there
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        meta = next(n for n in names if n.endswith(".dist-info/METADATA"))
        metadata = archive.read(meta).decode()
    assert "License-Expression: Apache-2.0" in metadata.splitlines()
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    requires = tomllib.loads((ROOT / "pyproject.toml").read_text())["build-system"]["requires"]
    (setuptools,) = [r for r in requires if r.startswith("setuptools")]
    assert re.fullmatch(r"setuptools>=[\d.]+,<\d+", setuptools), setuptools


@pytest.mark.slow
def test_the_kernels_compile_without_a_warning(wheel):
    """Every C file of both kernels compiled with -Wall -Wextra -Wconversion (setup.py), and
    the compiler said nothing: what it says is in the build's log (pip wheel -v)."""
    log = (wheel.parent / "build.log").read_text()
    compiled = {
        match[1]: match[0] for match in re.finditer(r"^.*\s-c (\S+\.c)\s.*$", log, re.MULTILINE)
    }
    sources = [*(ROOT / "bwsd/twin/csrc").glob("*.c"), ROOT / "bwsd/relax/csrc/step.c"]
    assert set(compiled) == {str(p.relative_to(ROOT)) for p in sources}
    for line in compiled.values():
        assert {"-Wall", "-Wextra", "-Wconversion"} <= set(line.split()), line
    warnings = re.findall(r"^\s*\S+:\d+(?::\d+)?: warning: .*$", log, re.MULTILINE)
    assert not warnings


@pytest.mark.slow
def test_a_build_without_three_js_warns(tmp_path):
    """The page cannot draw without it: the build says so (and the page, see tests/web)."""
    tree = tmp_path / "tree"
    tree.mkdir()
    shutil.copy(ROOT / "setup.py", tree / "setup.py")
    (tree / "bwsd" / "twin" / "csrc").mkdir(parents=True)
    command = [sys.executable, "setup.py", "--name"]
    run = subprocess.run(command, cwd=tree, capture_output=True, text=True, timeout=120)
    assert "bwsd: warning: three.js is not in bwsd/web/node_modules" in run.stderr
    assert "npm ci --prefix bwsd/web" in run.stderr
    here = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert "three.js" not in here.stderr  # the source tree's, with three.js installed


@pytest.mark.slow
def test_the_wheel_carries_its_type_information(wheel):
    """``py.typed`` and the kernel's stub ship in the wheel, so the hints reach users."""
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {"bwsd/py.typed", "bwsd/twin/_kernel.pyi"} <= names


@pytest.mark.slow
def test_the_wheel_carries_the_demo_and_the_page(wheel):
    """config/ and examples/ as package data (``bwsd demo`` runs them), the page, and the
    files of three.js it imports when ``npm ci`` had installed them before the build."""
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {f"bwsd/shipped/config/{p.name}" for p in (ROOT / "config").glob("*.toml")}
    shipped |= {f"bwsd/shipped/examples/{p.name}" for p in (ROOT / "examples").glob("*.bws")}
    shipped |= {f"bwsd/shipped/systemd/{p.name}" for p in (ROOT / "systemd").glob("*.service")}
    assert len(shipped) >= 2 and shipped <= names
    page = {f"bwsd/web/static/{p.name}" for p in (ROOT / "bwsd/web/static").iterdir()}
    assert page | {"bwsd/web/index.html"} <= names
    three = {f"bwsd/web/node_modules/three/{name}" for name in THREE}
    if not (THREE_ROOT / "build" / "three.module.js").is_file():
        assert not three & names
        unavailable("three.js is not installed: run npm ci --prefix bwsd/web")
    assert three <= names
    assert not {n for n in names if "node_modules" in n} - three  # nothing else of it


@pytest.mark.slow
def test_the_wheel_runs_the_demo_in_a_fresh_venv_from_an_empty_folder(tmp_path_factory, tmp_path):
    """Installed with pip and its core dependencies only, from nothing but the wheel."""
    bin_dir, env = core_venv(tmp_path_factory)
    assert not set(installed(bin_dir, env)) & {normal_name(name) for name in NOT_CORE}
    run_demo(bin_dir, env, tmp_path / "empty")
    export = subprocess.run(
        [
            str(bin_dir / "bwsd"),
            "simulate",
            str(ROOT / "examples/twist.bws"),
            "--config",
            str(ROOT / "config/twist.toml"),
            "--export",
            "x.vtu",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        cwd=tmp_path,
    )
    assert export.returncode == 2
    assert export.stderr == "bwsd: error: writing .vtu needs VTK: pip install 'bwsd[export]'\n"
    page = subprocess.run(
        [
            str(bin_dir / "python"),
            "-c",
            "from bwsd.api.web import WEB_ROOT, missing; print(WEB_ROOT, missing(WEB_ROOT))",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        cwd=tmp_path,
        check=True,
    )
    root, lacking = page.stdout.split(" ", 1)
    assert Path(root).is_relative_to(bin_dir.parent)
    if (THREE_ROOT / "build" / "three.module.js").is_file():
        assert lacking.strip() == "[]"


def _lower_bounds() -> list[str]:
    """``name==X`` for every core dependency, X the lowest version pyproject.toml admits."""
    pins = []
    for requirement in tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "dependencies"
    ]:
        match = re.fullmatch(
            r"([A-Za-z0-9_.-]+)(\[[^\]]*\])?\s*(>=|~=|==)\s*([0-9][^,;\s]*)", requirement.strip()
        )
        assert match, f"no lower bound in {requirement!r}"
        pins.append(f"{match[1]}=={match[4]}")
    return pins


@pytest.mark.slow
def test_the_wheel_runs_the_demo_from_inside_an_unbuilt_source_tree(tmp_path_factory, tmp_path):
    """Installed from the wheel, run in a clone's folder: the mock loom the demo starts
    imports the installed package, not the clone's unbuilt one (no compiled kernel). Here
    the clone's packages refuse to be imported, so using them would show."""
    bin_dir, env = core_venv(tmp_path_factory)
    clone = clean_tree(tmp_path / "clone")
    assert not list(clone.rglob("*.so"))
    for package in ("bwsd", "simulator_hw"):
        with (clone / package / "__init__.py").open("a") as init:
            init.write(f"\nraise ImportError('the clone\\'s {package} was imported')\n")
    said = run_demo(bin_dir, env, clone)
    assert "the mock loom did not start" not in said


@pytest.mark.slow
def test_the_wheel_runs_on_the_lowest_versions_it_admits(wheel, tmp_path):
    """Every core dependency at its lower bound, and Starlette at the lowest that FastAPI
    admits: the demo (daemon, API, PLC tags, mock loom) still runs to complete."""
    pins = _lower_bounds()
    constraints = tmp_path / "lowest.txt"
    constraints.write_text("\n".join(pins) + "\n")
    bin_dir, env = fresh_venv(tmp_path / "venv", "-c", str(constraints), str(wheel))
    code = (
        "import importlib.metadata as m, re\n"
        "print(next(re.search(r'>=\\s*([0-9][^,;\\s]*)', r)[1] for r in m.requires('fastapi')"
        " if re.match(r'starlette\\b', r)))"
    )
    found = subprocess.run(
        [str(bin_dir / "python"), "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        check=True,
    )
    starlette = found.stdout.strip()
    pip_install(bin_dir, env, "-c", str(constraints), f"starlette=={starlette}")
    versions = installed(bin_dir, env)
    for pin in [*pins, f"starlette=={starlette}"]:
        name, version = pin.split("==")
        assert Version(versions[normal_name(name)]) == Version(version), (pin, versions)
    run_demo(bin_dir, env, tmp_path / "empty")
