"""The page's scripts pass ESLint and TypeScript's checker (`npm run lint`, `npm run typecheck`
in bwsd/web, docs/preview.md), and both checks find the mistakes they are there for."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # every test here is in the slow tier

WEB = Path(__file__).resolve().parents[2] / "bwsd" / "web"
BIN = WEB / "node_modules" / ".bin"


def npm() -> str:
    """npm, with ESLint and TypeScript installed by ``npm ci``; without them the tests are
    skipped, except under CI (``CI=true``), where they fail."""
    found = shutil.which("npm")
    if found is None:
        reason = "npm is not installed (Node.js and npm run the page's checks)"
    elif not all((BIN / tool).exists() for tool in ("eslint", "tsc")):
        reason = "ESLint and TypeScript are not installed: run npm ci --prefix bwsd/web"
    else:
        return found
    if os.environ.get("CI") == "true":
        pytest.fail(reason)
    pytest.skip(reason)


def run(
    command: list[str], cwd: Path = WEB, stdin: str | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        command, cwd=cwd, input=stdin, capture_output=True, text=True, timeout=600
    )


@pytest.mark.parametrize("script", ["lint", "typecheck"])
def test_the_pages_scripts_pass(script):
    done = run([npm(), "run", "--silent", script])
    assert done.returncode == 0, (done.stdout + done.stderr)[-6000:]


def test_eslint_finds_a_loose_comparison_an_unknown_name_and_an_unused_variable():
    npm()  # skips or fails as above
    probe = "const unused = 1;\nexport function f(a) {\n  if (a == 2) missing();\n}\n"
    done = run(
        [str(BIN / "eslint"), "--format", "json", "--stdin", "--stdin-filename", "static/probe.js"],
        stdin=probe,
    )
    assert done.returncode == 1, done.stdout + done.stderr
    (report,) = json.loads(done.stdout)
    rules = {message["ruleId"] for message in report["messages"]}
    assert {"eqeqeq", "no-undef", "no-unused-vars"} <= rules, report["messages"]


def test_the_type_check_is_strict(tmp_path):
    """The page's settings (extended) on a probe: an untyped parameter and a wrong method."""
    npm()
    (tmp_path / "probe.js").write_text(
        "// @ts-check\n"
        "export function untyped(x) {\n  return x;\n}\n"
        "/** @param {number} n */\nexport function wrong(n) {\n  return n.toUpperCase();\n}\n"
    )
    settings = {"extends": str(WEB / "tsconfig.json"), "include": ["probe.js"]}
    (tmp_path / "tsconfig.json").write_text(json.dumps(settings))
    done = run([str(BIN / "tsc"), "-p", str(tmp_path / "tsconfig.json"), "--pretty", "false"])
    assert done.returncode != 0
    assert "probe.js(2,25): error TS7006" in done.stdout, done.stdout  # noImplicitAny (strict)
    assert "probe.js(7,12): error TS2339" in done.stdout, done.stdout  # no toUpperCase on a number
