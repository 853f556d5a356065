"""Benchmark of the twin: prints the markdown tables of docs/benchmarks.md.

    python bench/twin.py                 # examples, ratio to the exact reference, latency
    python bench/twin.py --cycles 10,100,1000 --repeat 5

Wall times are medians (and the slowest, as p99) over ``--repeat`` runs on one core; peak
memory is what tracemalloc saw during one more run; the exact reference is the test suite's
(tests/twin/reference.py), measured in the same run.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
import tracemalloc
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.config import load_config  # noqa: E402
from bwsd.program import load_program, parse_program  # noqa: E402
from bwsd.program.generators import braid4  # noqa: E402
from bwsd.twin import Machine, Program, Twin, simulate  # noqa: E402
from tests.twin.reference import RefTwin  # noqa: E402

EXAMPLES = ["twist", "braid-2x2", "weave-plain", "braid-L", "weave-U", "braid-24x24"]
TARGETS = {"braid-L": "< 0.1 s", "weave-U": "< 0.3 s"}
REFERENCE_CASES = ["twist", "braid-2x2", "weave-plain"]


def load(stem: str) -> tuple[Machine, Program]:
    machine = load_config(ROOT / "config" / f"{stem}.toml").machine
    return machine, load_program(ROOT / "examples" / f"{stem}.bws", machine)


def timed(fn: Callable[[], object], repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        out.append(time.perf_counter() - start)
    return out


def p99(values: Sequence[float]) -> float:
    return float(np.percentile(values, 99))


def peak_mb(fn: Callable[[], object]) -> float:
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


def run_reference(machine: Machine, program: Program) -> RefTwin:
    ref = RefTwin(machine.rows, machine.cols, machine.pitch_x, machine.pitch_y, machine.d_mat,
                  machine.c_mat, machine.yarn_diameter if program.diameter is None
                  else program.diameter)  # fmt: skip
    ref.fill(list(program.fill))
    for ins in program.instructions:
        ref.run(ins)
    return ref


def examples_table(repeat: int) -> list[str]:
    rows = ["| example | yarns | instructions | contacts | median s | p99 s | peak MB | target |",
            "|---|---:|---:|---:|---:|---:|---:|---|"]  # fmt: skip
    for stem in EXAMPLES:
        machine, program = load(stem)
        n = 1 if stem == "braid-24x24" else repeat
        twin = simulate(machine, program)
        times = timed(lambda m=machine, p=program: simulate(m, p), n)  # type: ignore[misc]
        peak = peak_mb(lambda m=machine, p=program: simulate(m, p))  # type: ignore[misc]
        rows.append(
            f"| {stem} | {twin.yarn_count} | {twin.done} | {twin.contact_count} "
            f"| {statistics.median(times):.4f} | {p99(times):.4f} | {peak:.1f} "
            f"| {TARGETS.get(stem, '')} |"
        )
        print(rows[-1], file=sys.stderr)
    return rows


def reference_table(repeat: int) -> list[str]:
    rows = ["| example | contacts | reference s | twin median s | speed-up |",
            "|---|---:|---:|---:|---:|"]  # fmt: skip
    for stem in REFERENCE_CASES:
        machine, program = load(stem)
        start = time.perf_counter()
        ref = run_reference(machine, program)
        ref_s = time.perf_counter() - start
        times = timed(lambda m=machine, p=program: simulate(m, p), repeat)  # type: ignore[misc]
        fast = statistics.median(times)
        rows.append(f"| {stem} | {len(ref.contacts)} | {ref_s:.3f} | {fast:.4f} "
                    f"| {ref_s / fast:.0f}x |")  # fmt: skip
        print(rows[-1], file=sys.stderr)
    return rows


def rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        pages = int(fh.read().split()[1])
    return pages * 4096 / 2**20


def latency_table(checkpoints: list[int], samples: int) -> list[str]:
    generated = braid4(24, 24, cycles=max(checkpoints) + samples, takeup=3.0, pitch=10.0,
                       d_mat=300.0, c_mat=0.3, diameter=1.5)  # fmt: skip
    program = parse_program(generated.program)
    machine = generated.machine
    per_cycle = program.cycle_length or 1
    twin = Twin.from_program(machine, program)
    rows = ["| cycle | p50 ms | p99 ms | p99 / p99 at first | contacts | nodes | RSS MB |",
            "|---:|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    first = 0.0
    for cycle in checkpoints:
        while twin.done < cycle * per_cycle:
            twin.apply(program.instructions[twin.done])
        lat = []
        for _ in range(samples * per_cycle):
            ins = program.instructions[twin.done]
            start = time.perf_counter()
            pred = twin.predict(ins)
            lat.append(time.perf_counter() - start)
            twin.commit(pred)
        first = first or p99(lat)
        rows.append(f"| {cycle} | {1e3 * statistics.median(lat):.1f} | {1e3 * p99(lat):.1f} "
                    f"| {p99(lat) / first:.2f} | {twin.contact_count} | {twin.node_count} "
                    f"| {rss_mb():.0f} |")  # fmt: skip
        print(rows[-1], file=sys.stderr)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--cycles", default="10,100", help="latency checkpoints (24x24 braid)")
    parser.add_argument("--samples", type=int, default=4, help="cycles measured per checkpoint")
    parser.add_argument("--skip", default="", help="comma list: examples,reference,latency")
    args = parser.parse_args()
    skip = set(filter(None, args.skip.split(",")))
    print(f"Python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}, "
          "one core\n")  # fmt: skip
    if "examples" not in skip:
        print("### Examples\n")
        print("\n".join(examples_table(args.repeat)) + "\n")
    if "reference" not in skip:
        print("### Against the exact reference (same run)\n")
        print("\n".join(reference_table(args.repeat)) + "\n")
    if "latency" not in skip:
        print("### Predict latency, 24x24 braid (624 carriers), per instruction\n")
        checkpoints = [int(c) for c in args.cycles.split(",")]
        print("\n".join(latency_table(checkpoints, args.samples)) + "\n")


if __name__ == "__main__":
    main()
