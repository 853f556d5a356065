"""What the install commands bring: the README's and CI's name every extra, and the configs
and examples shipped with the package are those of the source tree."""

from __future__ import annotations

import ast
import base64
import hashlib
import http.server
import importlib.metadata
import os
import re
import subprocess
import sys
import threading
import tomllib
import zipfile
from pathlib import Path

import pytest

from bwsd.errors import BwsdError
from bwsd.shipped import DEMO_CONFIG, DEMO_PROGRAM, config_file, example_file
from tests.support.build import fresh_venv, installed, pip_install

ROOT = Path(__file__).resolve().parents[1]
EXTRAS = set(
    tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
)


def _installed_extras(text: str) -> list[set[str]]:
    """The extras of every ``pip install ... -e TARGET`` of the project in ``text``."""
    found = []
    for match in re.finditer(r"pip install [^\n&|;]*?-e ('?)\.(\[([a-z,-]+)\])?\1(?=\s|$)", text):
        found.append(set(match[3].split(",")) if match[3] else set())
    return found


def test_the_readme_installs_every_extra_but_dev_and_bench():
    first_block = (ROOT / "README.md").read_text().split("```sh\n", 1)[1].split("```", 1)[0]
    assert _installed_extras(first_block) == [EXTRAS - {"dev", "bench"}]
    assert {"export", "canopen"} <= EXTRAS


def test_ci_installs_every_extra():
    assert _installed_extras((ROOT / ".ci" / "run").read_text()) == [EXTRAS]


def _distribution(requirement: str) -> str:
    return _normal(re.split(r"[\[<>=~!;\s]", requirement, maxsplit=1)[0])


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _imported(script: Path) -> set[str]:
    """The top-level modules a script imports, wherever in it."""
    found = set()
    for node in ast.walk(ast.parse(script.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name.partition(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.partition(".")[0])
    return found


@pytest.mark.slow
def test_the_bench_extra_carries_what_the_benchmarks_import():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    offered = {_distribution(r) for r in project["dependencies"]}
    offered |= {_distribution(r) for r in project["optional-dependencies"]["bench"]}
    scripts = sorted((ROOT / "bench").glob("*.py"))
    ours = {"bwsd", "simulator_hw", "tests", "bench", "__future__"} | {p.stem for p in scripts}
    owners = importlib.metadata.packages_distributions()
    assert len(scripts) >= 10
    for script in scripts:
        for module in _imported(script) - ours - set(sys.stdlib_module_names):
            dists = {_normal(d) for d in owners.get(module, [])}
            assert dists & offered, f"{script.name} imports {module} ({dists}), not in bench"


def test_the_shipped_configs_and_examples_are_those_of_the_source_tree():
    configs = sorted((ROOT / "config").glob("*.toml"))
    examples = sorted((ROOT / "examples").glob("*.bws"))
    assert configs and examples
    for path in configs:
        assert config_file(path.name).read_bytes() == path.read_bytes()
    for path in examples:
        assert example_file(path.name).read_bytes() == path.read_bytes()
    assert config_file() == config_file(DEMO_CONFIG)
    assert example_file() == example_file(DEMO_PROGRAM)


def test_a_file_that_is_not_shipped_is_a_bwsd_error():
    with pytest.raises(BwsdError, match=r"config/nothing\.toml is not shipped"):
        config_file("nothing.toml")


class _CuttingIndex:
    """A package index on loopback serving one small wheel, whose first ``cuts`` downloads
    stop halfway through (the full length announced, half of it sent, the connection
    closed), as a registry's CDN sometimes does."""

    NAME = "cutwheel"

    def __init__(self, folder: Path, cuts: int) -> None:
        self.wheel = _tiny_wheel(folder, self.NAME)
        self.cuts = cuts
        self.downloads = 0
        index = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                if self.path.rstrip("/") == f"/simple/{index.NAME}":
                    body = f'<a href="/files/{index.wheel.name}">{index.wheel.name}</a>'.encode()
                    self._send(body, "text/html")
                elif self.path == f"/files/{index.wheel.name}":
                    index.downloads += 1
                    cut = index.downloads <= index.cuts
                    self._send(index.wheel.read_bytes(), "application/octet-stream", cut)
                else:
                    self.send_error(404)

            def _send(self, body: bytes, kind: str, cut: bool = False) -> None:
                self.send_response(200)
                self.send_header("Content-Type", kind)
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body[: len(body) // 2] if cut else body)
                self.close_connection = cut

            def log_message(self, *args: object) -> None:
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/simple/"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def _tiny_wheel(folder: Path, name: str) -> Path:
    """A pure-Python wheel of ``name`` 1.0, 200 kB of it a data file, with its RECORD."""
    files: dict[str, bytes | str] = {
        f"{name}/__init__.py": b"VERSION = '1.0'\n",
        f"{name}/padding.bin": os.urandom(200_000),
        f"{name}-1.0.dist-info/METADATA": f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n",
        f"{name}-1.0.dist-info/WHEEL": (
            "Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\nTag: py3-none-any\n"
        ),
    }
    record = []
    for path, content in files.items():
        data = content if isinstance(content, bytes) else content.encode()
        digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
        record.append(f"{path},sha256={digest},{len(data)}")
    record.append(f"{name}-1.0.dist-info/RECORD,,")
    files[f"{name}-1.0.dist-info/RECORD"] = "\n".join(record) + "\n"
    wheel = folder / f"{name}-1.0-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as archive:
        for path, content in files.items():
            archive.writestr(path, content)
    return wheel


@pytest.fixture
def cutting_index(tmp_path):
    """An index that cuts the first 3 downloads of its wheel: more than one pip run resumes
    with ``--resume-retries 1`` (2 tries), fewer than two such runs make."""
    index = _CuttingIndex(tmp_path, cuts=3)
    yield index
    index.close()


def _pip_from(index: _CuttingIndex) -> list[str]:
    """pip's options for installing from ``index`` alone, resuming a cut download once."""
    return ["--isolated", "--no-cache-dir", "--resume-retries", "1", "--index-url", index.url]


@pytest.mark.slow
def test_ci_installs_again_what_the_index_cut_midway(cutting_index, tmp_path):
    target = tmp_path / "target"
    pip = [sys.executable, "-m", "pip", "install", "-q", *_pip_from(cutting_index)]
    pip += ["--target", str(target), cutting_index.NAME]
    env = {**os.environ, "BWSD_RETRY_PAUSE": "0"}
    once = subprocess.run(pip, capture_output=True, text=True, timeout=300, env=env)
    assert once.returncode != 0 and "incomplete-download" in once.stderr
    assert cutting_index.downloads == 2
    cutting_index.downloads = 0  # the same cuts again, for .ci/retry
    again = subprocess.run(
        [str(ROOT / ".ci" / "retry"), *pip], capture_output=True, text=True, timeout=300, env=env
    )
    assert again.returncode == 0, again.stderr[-2000:]
    assert "retry: " in again.stderr and "attempt 1 of 4" in again.stderr
    assert cutting_index.downloads == 4
    assert (target / cutting_index.NAME / "__init__.py").read_text() == "VERSION = '1.0'\n"
    fetching = re.compile(r"(pip install|npm ci|apt-get (update|install)) ")
    commands = [
        line.strip()
        for line in (ROOT / ".ci" / "run").read_text().splitlines()
        if fetching.search(line) and not line.lstrip().startswith("#")
    ]
    assert len(commands) == 5
    for command in commands:
        assert re.search(r"(^|\s)\.ci/retry (\S+ -m )?" + fetching.pattern, command), command


@pytest.mark.slow
def test_the_tests_install_again_what_the_index_cut_midway(cutting_index, tmp_path):
    bin_dir, env = fresh_venv(tmp_path / "venv")
    pip_install(bin_dir, env, *_pip_from(cutting_index), cutting_index.NAME, pause_s=0)
    assert cutting_index.downloads == 4
    assert installed(bin_dir, env)[cutting_index.NAME] == "1.0"
