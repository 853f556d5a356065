"""Every file the docs and the code's comments cite exists, and every module they name imports.

Scanned: the README and docs/*.md (all their text, and their links relative to the file), the
comments and docstrings of the Python files, and the comments of the C and JavaScript files.
A cited path starts at one of the project's top folders (``bwsd/twin/csrc/swept.c``,
``docs/relax.md``); a glob (``bwsd/twin/csrc/*.c``) must match something. A dotted name
(``bwsd.export.skeleton_json.delta_to_dict``) must import, down to its last attribute.
"""

from __future__ import annotations

import ast
import importlib
import io
import re
import subprocess
import tokenize
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TOP = r"(?:bwsd|docs|tests|bench|config|examples|simulator_hw|systemd|\.ci)"
PATH = re.compile(r"(?<![\w./-])(" + TOP + r"/[\w.*/-]*[\w*])")
DOTTED = re.compile(r"(?<![\w./-])((?:bwsd|simulator_hw)(?:\.[A-Za-z_]\w*)+)")
LINK = re.compile(r"\]\(([^)\s]+)\)")
C_COMMENT = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)
JS_COMMENT = C_COMMENT
# A placeholder segment, such as NAME in examples/NAME.bws or Z in paper-L-zZ.png.
PLACEHOLDER = re.compile(r"NAME|[a-z]Z\b|/m\.toml")
# Cited on purpose as files that do not exist, or that exist only elsewhere.
NOT_HERE = {
    "examples/jsm": "three.js's folder, inside node_modules/three",
    "examples/jsm/controls/OrbitControls.js": "three.js's file, inside node_modules/three",
}
# Dotted names that are not modules.
NOT_MODULES = {
    "bwsd.service": "the systemd unit's file name",
    "bwsd.token": "a key of the page's local storage",
    "bwsd.colourBy": "a key of the page's local storage",
    "bwsd.auth": "the event WebSocket's subprotocol (docs/api.md)",
}


def tracked() -> list[str]:
    out = subprocess.run(
        ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout
    return out.split()


def python_prose(text: str) -> Iterator[tuple[int, str]]:
    """Comments and docstrings of a Python file, with their first line numbers."""
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            yield tok.start[0], tok.string
    for node in ast.walk(ast.parse(text)):
        if isinstance(
            node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef
        ) and (doc := ast.get_docstring(node, clean=False)):
            first = node.body[0]
            yield first.lineno, doc


def c_prose(text: str) -> Iterator[tuple[int, str]]:
    for m in C_COMMENT.finditer(text):
        yield text.count("\n", 0, m.start()) + 1, m.group(0)


def prose(name: str) -> Iterator[tuple[int, str]]:
    text = (ROOT / name).read_text(encoding="utf-8")
    if name.endswith(".md"):
        yield 1, text
    elif name.endswith(".py"):
        yield from python_prose(text)
    elif name.endswith((".c", ".h", ".js")):
        yield from c_prose(text)


def sources() -> list[str]:
    keep = (".md", ".py", ".c", ".h", ".js")
    return [
        n
        for n in tracked()
        if n.endswith(keep) and not n.startswith("bwsd/web/node_modules/") and (ROOT / n).is_file()
    ]


def resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attr in parts[cut:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def cited() -> Iterator[tuple[str, int, str, str]]:
    """(file, line, kind, what) for each citation."""
    for name in sources():
        for line, text in prose(name):
            for m in PATH.finditer(text):
                yield name, line + text.count("\n", 0, m.start()), "path", m.group(1).rstrip(".")
            for m in DOTTED.finditer(text):
                yield name, line + text.count("\n", 0, m.start()), "module", m.group(1)
            if name.endswith(".md"):
                for m in LINK.finditer(text):
                    target = m.group(1).split("#")[0]
                    if target and not re.match(r"[a-z]+:", target):
                        yield name, line + text.count("\n", 0, m.start()), "link", target


def missing() -> list[str]:
    found = []
    for name, line, kind, what in cited():
        if kind == "module":
            ok = what in NOT_MODULES or resolves(what.rstrip("."))
        elif kind == "link":
            ok = ((ROOT / name).parent / what).exists()
        elif what in NOT_HERE or PLACEHOLDER.search(what):
            ok = True
        elif "*" in what:
            ok = any(ROOT.glob(what))
        else:
            ok = (ROOT / what).exists()
        if not ok:
            found.append(f"{name}:{line}: {kind} {what}")
    return found


@pytest.mark.slow
def test_every_cited_path_and_module_exists() -> None:
    assert missing() == []


@pytest.mark.slow
def test_the_scan_finds_citations_and_would_see_a_missing_one(tmp_path: Path) -> None:
    every = list(cited())
    kinds = {kind for _, _, kind, _ in every}
    assert kinds == {"path", "module", "link"}
    assert len(every) > 200
    assert not resolves("bwsd.export.skeleton_json.no_such_function")
    assert resolves("bwsd.export.skeleton_json.delta_to_dict")
    doc = "x = 1  # see bwsd/twin/csrc/kernel.py\n"
    assert [m.group(1) for _, t in python_prose(doc) for m in PATH.finditer(t)] == [
        "bwsd/twin/csrc/kernel.py"
    ]


@pytest.mark.parametrize("name", ["README.md", "docs/relax.md", "bwsd/twin/csrc/module.c"])
def test_the_main_documents_are_scanned(name: str) -> None:
    assert name in sources()
