"""The seed paper's two case studies on the twin: prints the tables of docs/paper.md.

    python bench/paper.py                      # both paper examples, 20 runs each, one core
    python bench/paper.py --repeat 50 --skip reference
    python bench/paper.py --neighbours         # also the sizes and settings around them

The paper ("A novel braiding-weaving system ... collision detection", Journal of Industrial
Textiles, 2013) reports 504 interferences in 138.15 s for 10 cycles of an L-section 4-step
braid, and 610 in 376 s for 10 cycles of a U-section dual-direction 3D weave. The two counts
are the only constants the tables use (the times are the paper's, on its hardware; docs/paper.md
quotes them apart). Everything else is measured in this run, pinned to one
core: ``simulate`` of examples/paper-L.bws and paper-U.bws (median and 99th percentile over
the repetitions), and as a baseline the test suite's exact reference (tests/twin/reference.py,
brute force in Python integers and fractions), run once each.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# numpy's OpenBLAS threads would spin on another core; the twin uses no BLAS
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.twin import load, p99, timed  # noqa: E402
from bwsd.errors import JamError  # noqa: E402
from bwsd.export.formed import takeups_of  # noqa: E402
from bwsd.export.metrics import metrics  # noqa: E402
from bwsd.export.mixing import section_header, simulate_with_visits  # noqa: E402
from bwsd.program import parse_program  # noqa: E402
from bwsd.program.generators import Generated, braid4, weave_3d  # noqa: E402
from bwsd.twin import Machine, Program, Twin, simulate  # noqa: E402
from tests.twin.reference import RefTwin  # noqa: E402


@dataclass(frozen=True)
class Case:
    """One of the paper's case studies and the example that stands for it."""

    stem: str
    what: str
    interferences: int
    seconds: float


CASES = (
    Case("paper-L", "L-section 4-step braid", 504, 138.15),
    Case("paper-U", "U-section dual-direction 3D weave", 610, 376.0),
)


def one_core() -> str:
    """Pin this process to one CPU; say which."""
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned (no sched_setaffinity here)"
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return f"pinned to CPU {cpu}"


def reference_seconds(machine: Machine, program: Program) -> float:
    """Seconds the exact reference takes for the whole program (its contacts must agree)."""
    diameter = machine.yarn_diameter if program.diameter is None else program.diameter
    start = time.perf_counter()
    ref = RefTwin(machine, list(program.fill), diameter)
    for ins in program.instructions:
        ref.run(ins)
    seconds = time.perf_counter() - start
    assert len(ref.contacts) == simulate(machine, program).contact_count
    return seconds


def paper_table(repeat: int, reference: bool) -> list[str]:
    rows = [
        "| case | example | yarns | instructions | interferences (paper) | contacts (bwsd) "
        "| nodes (bwsd) | bwsd median s | p99 s | reference s |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for case in CASES:
        machine, program = load(case.stem)
        twin = simulate(machine, program)
        times = timed(lambda m=machine, p=program: simulate(m, p), repeat)  # type: ignore[misc]
        median = statistics.median(times)
        ref = f"{reference_seconds(machine, program):.1f}" if reference else ""
        rows.append(
            f"| {case.what} | {case.stem} | {twin.yarn_count} | {twin.done} "
            f"| {case.interferences} | {twin.contact_count} | {twin.node_count} "
            f"| {median:.4f} | {p99(times):.4f} | {ref} |"
        )
        print(rows[-1], file=sys.stderr)
    return rows


def rule_k(stem: str) -> str:
    """K as the braid rule's check states it in the program's header, if it does."""
    found = re.search(r"every zone by cycle (\d+)", (ROOT / "examples" / f"{stem}.bws").read_text())
    return f"cycle {found[1]}" if found else ""


def preform(stem: str) -> dict[str, Any]:
    """``bwsd metrics`` of an example, with its section's mixing when it names one."""
    machine, program = load(stem)
    named = section_header((ROOT / "examples" / f"{stem}.bws").read_text(encoding="utf-8"))
    takeups = takeups_of(program)
    if named is None:
        return metrics(simulate(machine, program).skeleton(), program.cycle_length, takeups=takeups)
    twin, visits = simulate_with_visits(machine, program, named.section)
    return metrics(
        twin.skeleton(), program.cycle_length, takeups=takeups, named=named, visits=visits
    )


def preform_table() -> list[str]:
    rows = [
        "| example | contact groups | yarns without contact | carriers mixed | K reached "
        "| K of the rule | measuring band z mm | width mm | thickness mm |",
        "|---|---:|---:|---|---|---|---|---:|---:|",
    ]
    for case in CASES:
        m = preform(case.stem)
        mix, sec = m["mixing"], m["section"]
        mixed = f"{mix['complete']} of {mix['carriers']}" if mix else "(no section)"
        k = ("no" if mix["k"] is None else f"cycle {mix['k']}") if mix else ""
        band = f"{sec['z'][0]:.1f} to {sec['z'][1]:.1f}"
        rows.append(
            f"| {case.stem} | {m['groups']['count']} | {m['unconnected']['count']} "
            f"| {mixed} | {k} | {rule_k(case.stem)} | {band} "
            f"| {sec['width']:.1f} | {sec['thickness']:.1f} |"
        )
    return rows


def formed_table() -> list[str]:
    """The formed zone of each example: its warp angle, interpenetration, volume fraction."""
    rows = [
        "| example | formed cycles | formed z mm | warp angle | whole-skeleton warp angle "
        "| within d of another yarn | worst mm | p95 mm | yarn volume fraction |",
        "|---|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for case in CASES:
        m = preform(case.stem)
        zone, over = m["formed"], m["interpenetration"]["formed"]["all"]
        if not zone["found"]:
            rows.append(f"| {case.stem} | none: {zone['reason']} | | | | | | | |")
            continue
        fractions = ", ".join(f"{100 * h['fraction']:.1f}" for h in m["volume_fraction"])
        rows.append(
            f"| {case.stem} | {zone['cycles'][0]} to {zone['cycles'][1]} "
            f"| {zone['z'][0]:.1f} to {zone['z'][1]:.1f} "
            f"| {m['angles']['warp']['all']['mean']:.1f} "
            f"| {m['skeleton_angles']['warp']['mean']:.1f} | {100 * over['share']:.1f} % "
            f"| {over['worst']:.2f} | {over['p95']:.2f} | {fractions} % |"
        )
    return rows


# The sizes and settings considered around the chosen ones (docs/paper.md): the chosen
# machine is pitch 10, d_mat 100, c_mat 0.4, yarn 1 mm; 6 mm of take-up per four steps of the
# braid, 3 mm per pick of the weave.
MACHINE = {"pitch": 10.0, "d_mat": 100.0, "c_mat": 0.4, "diameter": 1.0}
L_CHOSEN = {"flange": (3, 8), "web": (7, 3), "takeup": 6.0}
U_CHOSEN = {"layers": 3, "warps": 6, "leg": 2, "base": 2, "takeup": 3.0}
L_AROUND: list[dict[str, Any]] = [
    {},
    {"flange": (3, 7), "web": (7, 4)},
    {"flange": (5, 8), "web": (3, 3)},
    {"flange": (5, 5), "web": (7, 4)},
    {"flange": (2, 11), "web": (7, 3)},
    {"flange": (3, 10), "web": (6, 2)},
    {"flange": (3, 7), "web": (7, 3)},
    {"flange": (3, 8), "web": (6, 4)},
    {"takeup": 5.0},
    {"takeup": 8.0},
    {"takeup": 3.0},
    {"diameter": 0.8},
    {"diameter": 1.2},
    {"c_mat": 0.35},
    {"c_mat": 0.45},
    {"d_mat": 110.0},
    {"segments": False},
    {"cycles": 10},
]
U_AROUND: list[dict[str, Any]] = [
    {},
    {"warps": 5},
    {"warps": 7},
    {"layers": 4, "warps": 5},
    {"takeup": 2.5},
    {"takeup": 3.5},
    {"takeup": 4.0},
    {"diameter": 0.9},
    {"diameter": 1.2},
    {"c_mat": 0.45},
    {"c_mat": 0.5},
    {"takeup": 5.0, "c_mat": 0.6},  # the weave-3d defaults
]


def _braid(change: dict[str, Any]) -> Generated:
    kw = {**MACHINE, **L_CHOSEN, "cycles": 5, "shape": "L", **change}
    return braid4(**kw)


def _weave(change: dict[str, Any]) -> Generated:
    kw = {**MACHINE, **U_CHOSEN, "cycles": 10, "shape": "U", **change}
    return weave_3d(**kw)


def _changed(change: dict[str, Any]) -> str:
    if not change:
        return "**chosen**"
    return ", ".join(
        f"{k} {'x'.join(map(str, v)) if isinstance(v, tuple) else v}" for k, v in change.items()
    )


def neighbours_table() -> list[str]:
    rows = [
        "| case | change from the chosen | warps | instructions | contacts | against the paper |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for case, make, around in ((CASES[0], _braid, L_AROUND), (CASES[1], _weave, U_AROUND)):
        for change in around:
            try:
                generated = make(change)
            except ValueError as exc:
                rows.append(f"| {case.stem} | {_changed(change)} | refused: {exc} | | | |")
                continue
            program = parse_program(generated.program)
            try:
                twin: Twin = simulate(generated.machine, program)
            except JamError as exc:
                rows.append(
                    f"| {case.stem} | {_changed(change)} | {len(program.fill)} "
                    f"| refused: a jam at instruction {exc.instruction} | | |"
                )
                continue
            delta = twin.contact_count - case.interferences
            rows.append(
                f"| {case.stem} | {_changed(change)} | {len(program.fill)} "
                f"| {twin.done} | {twin.contact_count} | {delta:+d} |"
            )
            print(rows[-1], file=sys.stderr)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--skip", default="", help="comma list: reference,preform")
    parser.add_argument(
        "--neighbours",
        action="store_true",
        help="also the sizes and settings around the chosen ones",
    )
    args = parser.parse_args()
    skip = set(filter(None, args.skip.split(",")))
    pinned = one_core()
    print(
        f"Python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}, "
        f"{pinned}, {args.repeat} runs each\n"
    )
    print("### The paper's case studies against bwsd\n")
    print("\n".join(paper_table(args.repeat, "reference" not in skip)) + "\n")
    if "preform" not in skip:
        print("### The preforms (bwsd metrics)\n")
        print("\n".join(preform_table()) + "\n")
        print("\n".join(formed_table()) + "\n")
    if args.neighbours:
        print("### Around the chosen sizes and settings\n")
        print("\n".join(neighbours_table()) + "\n")


if __name__ == "__main__":
    main()
