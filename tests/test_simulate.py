"""`bwsd simulate` and `bwsd demo` through the installed console script."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.config import load_config
from bwsd.export.skeleton_json import read_skeleton_json
from bwsd.export.texgen import distinct_nodes, read_tg3
from bwsd.program import load_program
from bwsd.twin import simulate

ROOT = Path(__file__).resolve().parents[1]
BWSD = shutil.which("bwsd", path=str(Path(sys.executable).parent))


def bwsd(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    assert BWSD, "the bwsd console script is not installed beside this Python"
    return subprocess.run(
        [BWSD, *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )


def example(stem: str) -> tuple[str, str]:
    return str(ROOT / "examples" / f"{stem}.bws"), str(ROOT / "config" / f"{stem}.toml")


@pytest.mark.slow
@pytest.mark.parametrize(
    "stem", ["twist", "braid-2x2", "weave-plain", "braid-L", "weave-U", "paper-L", "paper-U"]
)
def test_simulate_json_matches_the_twin(stem):
    program, config = example(stem)
    done = bwsd("simulate", program, "--config", config, "--json")
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)  # stdout holds exactly one JSON object
    machine = load_config(config).machine
    twin = simulate(machine, load_program(program, machine))
    assert summary["yarns"] == twin.yarn_count
    assert summary["nodes"] == twin.node_count
    assert summary["contacts"] == twin.contact_count
    assert summary["instructions"] == twin.done
    assert summary["seconds"] > 0


@pytest.mark.slow
def test_simulate_writes_skeleton_and_exports_that_read_back(tmp_path):
    program, config = example("braid-L")
    skeleton, tg3, vtp = tmp_path / "s.json", tmp_path / "s.tg3", tmp_path / "s.vtp"
    done = bwsd(
        "simulate",
        program,
        "--config",
        config,
        "--json",
        "--skeleton",
        str(skeleton),
        "--export",
        str(tg3),
        "--export",
        str(vtp),
    )
    assert done.returncode == 0, done.stderr
    json.loads(done.stdout)  # TexGen's chatter must not reach stdout
    raw = json.loads(skeleton.read_text())
    assert {"yarns", "contacts"} <= set(raw)
    assert set(raw["yarns"][0]) >= {"id", "kind", "nodes"}
    assert set(raw["contacts"][0]) >= {"yarns", "instruction"}
    sk = read_skeleton_json(skeleton)
    yarns = read_tg3(tg3)  # read back with pytexgen itself
    assert len(yarns) == len(sk.yarns)
    for nodes, yarn in zip(yarns, sk.yarns, strict=True):
        written = distinct_nodes(yarn.nodes)  # two contacts at one point: one TexGen node
        assert nodes.shape == written.shape
        assert abs(nodes - written).max() < 1e-9
    assert sum(len(y.nodes) for y in sk.yarns) > sum(len(n) for n in yarns)  # such points
    assert vtp.stat().st_size > 0


def test_a_weft_into_a_closed_shed_names_its_line_and_writes_nothing(tmp_path):
    program = tmp_path / "bad.bws"
    program.write_text(
        "YARN diameter=1\nFILL row=0 col=0\nX.\n.X\nEND\n"
        "ROW 0:+1 1:-1\n"
        "# yarn 0 now runs from the fell (2.5, 2.5) to its guide (10, 0)\n"
        "WEFT x=6.25 y=1.25 z=50 angle=0 length=30\n"
    )
    out = tmp_path / "out.json"
    done = bwsd("simulate", str(program), "--config", example("twist")[1], "--skeleton", str(out))
    assert done.returncode == 2
    assert f"{program}:8:" in done.stderr
    assert "shed closed" in done.stderr
    assert not out.exists()


@pytest.mark.slow
def test_a_case_leaving_the_matrix_is_refused_with_line_and_column(tmp_path):
    program = tmp_path / "bad.bws"
    program.write_text("FILL row=0 col=0\nX.\n.X\nEND\nROW 0:+1\nROW 0:+1\n")
    done = bwsd("simulate", str(program), "--config", example("twist")[1])
    assert done.returncode == 2
    assert f"{program}:6:" in done.stderr
    assert done.stdout == ""


@pytest.mark.slow
def test_progress_bar_on_a_terminal_and_none_in_a_pipe():
    import os
    import pty

    assert BWSD, "the bwsd console script is not installed beside this Python"
    program, config = example("braid-L")
    leader, follower = pty.openpty()
    try:
        done = subprocess.run(
            [BWSD, "simulate", program, "--config", config],
            stdout=subprocess.PIPE,
            stderr=follower,
            text=True,
            timeout=300,
            check=False,
        )
        os.close(follower)
        chunks = []
        while True:
            try:
                chunk = os.read(leader, 65536)
            except OSError:
                break
            if not chunk:
                break
            chunks.append(chunk)
    finally:
        os.close(leader)
    assert done.returncode == 0
    assert b"simulating" in b"".join(chunks)  # rich drew its bar on the terminal
    piped = bwsd("simulate", program, "--config", config)
    assert piped.stderr == ""


@pytest.mark.slow
def test_simulate_takes_the_expansion_limit_from_the_config(tmp_path):
    program, config = example("braid-2x2")
    limited = tmp_path / "limited.toml"
    limited.write_text(Path(config).read_text() + "\n[controller]\nmax_instructions = 20\n")
    done = bwsd("simulate", program, "--config", str(limited), "--json")
    assert done.returncode == 2 and done.stdout == ""
    assert f"{program}:12:1: the program expands to more than 20 instructions" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.slow
@pytest.mark.parametrize(
    ("line", "where"),
    [
        ("TAKEUP 1e999", "6:8"),
        ("WEFT x=5 y=5 z=1 angle=1e999 length=5", "6:24"),
        ("WEFT x=5 y=5 z=1 angle=0 length=1e999", "6:33"),
        ("TAKEUP \u0661", "6:8"),
    ],
)
def test_simulate_json_refuses_hostile_numbers_at_their_place(tmp_path, line, where):
    """Once infinity, a traceback or ``Infinity`` on stdout; now one line naming line:col."""
    program = tmp_path / "p.bws"
    program.write_text(f"YARN diameter=1\nFILL row=0 col=0\nX.\n.X\nEND\n{line}\n")
    done = bwsd("simulate", str(program), "--config", example("twist")[1], "--json")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith(f"bwsd: error: {program}:{where}: "), done.stderr
    assert done.stderr.count("\n") == 1


@pytest.mark.slow
def test_a_jam_names_its_line_and_writes_nothing(tmp_path):
    """`bwsd program twist --turns 100` (no take-up) winds the yarns up to the guides: the
    twin refuses instruction 114 as a jam; simulate and metrics name its line."""
    from bwsd.program.generators import GENERATORS
    from bwsd.program.parser import parse_program

    generated = GENERATORS["twist"](turns=100)
    program = tmp_path / "winds.bws"
    program.write_text(generated.program)
    line = parse_program(generated.program).line_of(114)
    out = tmp_path / "out.json"
    for command in (["simulate", "--skeleton", str(out)], ["metrics"]):
        done = bwsd(command[0], str(program), "--config", example("twist")[1], *command[1:])
        assert done.returncode == 2
        assert f"{program}:{line}:1: instruction 114: jam: yarn " in done.stderr
        assert "below the guides" in done.stderr and "within one yarn diameter" in done.stderr
    assert not out.exists()


@pytest.mark.slow
def test_simulate_warns_about_a_loose_weft(tmp_path):
    """A hand-written 30 degree weft that nothing touches: accepted, but it lies loose."""
    program = tmp_path / "loose.bws"
    program.write_text(
        "YARN diameter=1\nFILL row=0 col=0\nX.\n.X\nEND\nTAKEUP 1\n"
        "WEFT x=5 y=5 z=50 angle=30 length=3\nROW 0:+1 1:-1\n"
    )
    done = bwsd("simulate", str(program), "--config", example("twist")[1], "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["loose_wefts"] == [2]
    assert f"warning: 1 weft(s) without any contact lie loose: yarn 2 ({program}:7)" in (
        done.stderr
    )
    weave, config = example("weave-plain")
    held = bwsd("simulate", weave, "--config", config, "--json")
    assert json.loads(held.stdout)["loose_wefts"] == [] and "warning" not in held.stderr


def test_simulate_runs_shipped_examples_by_name_and_makes_the_output_folder(tmp_path):
    """`example:NAME` for the program and the config (it worked for `bwsd sweep` only), and
    `--skeleton out/...` from a folder without out/ (it failed)."""
    done = bwsd(
        "simulate",
        "example:twist.bws",
        "--config",
        "example:twist.toml",
        "--skeleton",
        "out/twist.json",
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    written = json.loads((tmp_path / "out" / "twist.json").read_text())
    machine = load_config(ROOT / "config" / "twist.toml").machine
    twin = simulate(machine, load_program(ROOT / "examples" / "twist.bws", machine))
    assert len(written["yarns"]) == twin.yarn_count
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
