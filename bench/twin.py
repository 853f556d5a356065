"""Benchmark of the twin: prints the markdown tables of docs/benchmarks.md.

    python bench/twin.py                          # everything, 24x24 braid at cycles 10, 100
    python bench/twin.py --cycles 10,100,1000     # the issue's checkpoints (about a minute more)
    python bench/twin.py --skip examples,reference

Wall times are medians and 99th percentiles over repeated runs on one core; the exact
reference is the test suite's (tests/twin/reference.py) and the idle event loop the
baseline of the responsiveness table, both measured in the same run.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import platform
import statistics
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

# numpy's OpenBLAS threads would spin on the other core; the twin uses no BLAS
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.config import load_config  # noqa: E402
from bwsd.program import load_program, parse_program  # noqa: E402
from bwsd.program.generators import braid4  # noqa: E402
from bwsd.twin import Machine, Program, Snapshot, Twin, simulate  # noqa: E402
from tests.twin.reference import RefTwin  # noqa: E402

EXAMPLES = [
    "twist",
    "braid-2x2",
    "weave-plain",
    "braid-L",
    "weave-U",
    "paper-L",
    "paper-U",
    "braid-24x24",
]
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


def rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        pages = int(fh.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def predict_times(machine: Machine, program: Program) -> list[float]:
    """Seconds of each ``predict`` when the program runs as the daemon runs it."""
    out: list[float] = []
    simulate(machine, program, timings=out)
    return out


def examples_table(repeat: int) -> tuple[list[str], dict[str, tuple[int, float]]]:
    """The table, and each example's contacts and median simulate time (for the paper line)."""
    rows = [
        "| example | yarns | instructions | contacts | simulate median s | p99 s "
        "| predict p50 ms | p99 ms | max ms |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    measured: dict[str, tuple[int, float]] = {}
    for stem in EXAMPLES:
        machine, program = load(stem)
        twin = simulate(machine, program)
        times = timed(lambda m=machine, p=program: simulate(m, p), repeat)  # type: ignore[misc]
        ms = [1e3 * t for t in predict_times(machine, program)]
        measured[stem] = (twin.contact_count, statistics.median(times))
        rows.append(
            f"| {stem} | {twin.yarn_count} | {twin.done} | {twin.contact_count} "
            f"| {statistics.median(times):.4f} | {p99(times):.4f} "
            f"| {statistics.median(ms):.3f} | {p99(ms):.3f} | {max(ms):.3f} |"
        )
        print(rows[-1], file=sys.stderr)
    return rows, measured


def run_reference(machine: Machine, program: Program) -> RefTwin:
    diameter = machine.yarn_diameter if program.diameter is None else program.diameter
    ref = RefTwin(machine, list(program.fill), diameter)
    for ins in program.instructions:
        ref.run(ins)
    return ref


def reference_table(repeat: int) -> list[str]:
    rows = [
        "| program | contacts | reference s | twin median s | speed-up | target |",
        "|---|---:|---:|---:|---:|---|",
    ]
    cases: list[tuple[str, Machine, Program, str]] = [
        (stem, *load(stem), "at least 3000x" if stem == "braid-2x2" else "")
        for stem in REFERENCE_CASES
    ]
    generated = braid4(4, 4, cycles=10)
    cases.append(
        (
            "braid4 4x4, 24 carriers",
            generated.machine,
            parse_program(generated.program),
            "twin under 20 ms",
        )
    )
    for name, machine, program, target in cases:
        start = time.perf_counter()
        ref = run_reference(machine, program)
        ref_s = time.perf_counter() - start
        times = timed(lambda m=machine, p=program: simulate(m, p), repeat)  # type: ignore[misc]
        fast = statistics.median(times)
        rows.append(
            f"| {name} | {len(ref.contacts)} | {ref_s:.3f} | {fast:.5f} "
            f"| {ref_s / fast:.0f}x | {target} |"
        )
        print(rows[-1], file=sys.stderr)
    return rows


def big_braid(cycles: int) -> tuple[Machine, Program]:
    generated = braid4(
        24, 24, cycles=cycles, takeup=8.0, pitch=10.0, d_mat=300.0, c_mat=0.3, diameter=0.5
    )
    return generated.machine, parse_program(generated.program)


def latency_table(checkpoints: list[int], samples: int) -> list[str]:
    machine, program = big_braid(max(checkpoints) + samples)
    per_cycle = program.cycle_length or 1
    twin = Twin.from_program(machine, program)
    rows = [
        "| cycle | p50 ms | p99 ms | max ms | p99 / p99 at first | contacts | nodes "
        "| RSS MB | snapshot MB | snapshot ms | restore ms |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    first = 0.0
    for cycle in checkpoints:
        while twin.done < cycle * per_cycle:
            twin.advance(program.instructions[twin.done])
        lat = []
        for _ in range(samples * per_cycle):
            ins = program.instructions[twin.done]
            start = time.perf_counter()
            pred = twin.predict(ins)
            lat.append(1e3 * (time.perf_counter() - start))
            twin.commit(pred)
        first = first or p99(lat)
        rss = rss_mb()
        start = time.perf_counter()
        data = twin.snapshot().to_bytes()
        taken = time.perf_counter() - start
        start = time.perf_counter()
        Twin.from_snapshot(machine, Snapshot.from_bytes(data))
        restored = time.perf_counter() - start
        rows.append(
            f"| {cycle} | {statistics.median(lat):.2f} | {p99(lat):.2f} | {max(lat):.2f} "
            f"| {p99(lat) / first:.2f} | {twin.contact_count} | {twin.node_count} "
            f"| {rss:.0f} | {len(data) / 2**20:.1f} | {1e3 * taken:.0f} "
            f"| {1e3 * restored:.0f} |"
        )
        print(rows[-1], file=sys.stderr)
    return rows


async def _lateness(seconds: float) -> list[float]:
    """How late a 1 ms asyncio timer fires (ms), for ``seconds``."""
    loop = asyncio.get_running_loop()
    late = []
    end = loop.time() + seconds
    while loop.time() < end:
        start = time.perf_counter()
        await asyncio.sleep(0.001)
        late.append(1e3 * (time.perf_counter() - start - 0.001))
    return late


def responsiveness_table(seconds: float) -> list[str]:
    machine, program = big_braid(40)
    twin = Twin.from_program(machine, program)
    for ins in program.instructions[:50]:
        twin.advance(ins)
    start = twin.snapshot()
    stop = threading.Event()
    predicts = [0]

    def predict_forever() -> None:
        while not stop.is_set():
            if twin.done == len(program.instructions):
                twin.restore(start)
            twin.commit(twin.predict(program.instructions[twin.done]))
            predicts[0] += 1

    idle = asyncio.run(_lateness(seconds))
    worker = threading.Thread(target=predict_forever)
    worker.start()
    busy = asyncio.run(_lateness(seconds))
    stop.set()
    worker.join()
    rows = [
        "| event loop | timer late p50 ms | p99 ms | max ms | predicts meanwhile | target |",
        "|---|---:|---:|---:|---:|---|",
    ]
    for name, late, count, target in (
        ("idle (baseline)", idle, 0, ""),
        ("a 24x24 predict always running in a thread", busy, predicts[0], "p99 under 2 ms"),
    ):
        rows.append(
            f"| {name} | {statistics.median(late):.3f} | {p99(late):.3f} "
            f"| {max(late):.3f} | {count} | {target} |"
        )
        print(rows[-1], file=sys.stderr)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--cycles", default="10,100", help="latency checkpoints (24x24 braid)")
    parser.add_argument("--samples", type=int, default=10, help="cycles measured per checkpoint")
    parser.add_argument("--seconds", type=float, default=5.0, help="per responsiveness run")
    parser.add_argument(
        "--skip", default="", help="comma list: examples,reference,latency,responsiveness"
    )
    args = parser.parse_args()
    skip = set(filter(None, args.skip.split(",")))
    print(
        f"Python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}, "
        f"switch interval {sys.getswitchinterval() * 1e3:g} ms\n"
    )
    if "examples" not in skip:
        print("### Examples\n")
        rows, _ = examples_table(args.repeat)
        print("\n".join(rows) + "\n")
    if "reference" not in skip:
        print("### Against the exact reference (same run)\n")
        print("\n".join(reference_table(args.repeat)) + "\n")
    if "latency" not in skip:
        print("### Predict latency, 24x24 braid (624 carriers), per instruction\n")
        checkpoints = [int(c) for c in args.cycles.split(",")]
        print("\n".join(latency_table(checkpoints, args.samples)) + "\n")
    if "responsiveness" not in skip:
        print("### The interpreter while a predict runs in a thread\n")
        print("\n".join(responsiveness_table(args.seconds)) + "\n")


if __name__ == "__main__":
    main()
