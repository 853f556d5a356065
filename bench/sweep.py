"""Benchmark of `bwsd sweep`: candidates per second on 1 and 2 worker processes, and the cost
per candidate over the bare twin run, measured in the same run. Prints markdown tables.

    python bench/sweep.py                  # 96 candidates of a 3 x 3 and of a 6 x 6 braid
    python bench/sweep.py --repeat 5 --sizes 3,6,12 --cycles 6,8,10,12,16

The candidates are those of examples/braid-angle.sweep.toml with the cycles varied too. The
baseline is the bare twin run (generate, parse, simulate; no metrics) of the same candidates,
one after the other in this process; "in-process" adds the metrics, as a worker runs them.
"No Dask" runs the candidates in 1 and 2 plain processes (multiprocessing), a share each:
the most the machine's cores give, to read the sweep's scaling against. The last table sets
the metrics alone (the skeleton read out of the twin and `metrics()` on it, as a worker runs
them) beside the twin alone (`simulate` of the parsed program), candidate by candidate.
A sweep's wall time includes starting its local cluster; the sweep reports that start and
its running time (first task sent to last row logged) apart.
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import statistics
import sys
import tempfile
import time
import tomllib
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.errors import BwsdError  # noqa: E402
from bwsd.export.arrays import Arrays  # noqa: E402
from bwsd.export.formed import takeups_of  # noqa: E402
from bwsd.export.metrics import metrics, section  # noqa: E402
from bwsd.export.mixing import section_header, simulate_with_visits  # noqa: E402
from bwsd.program.generators import GENERATORS  # noqa: E402
from bwsd.program.parser import parse_program  # noqa: E402
from bwsd.sweep.candidate import Candidate, evaluate  # noqa: E402
from bwsd.sweep.runner import Options, run_sweep  # noqa: E402
from bwsd.sweep.spec import Spec, parse_spec  # noqa: E402
from bwsd.twin import simulate  # noqa: E402

SPEC = ROOT / "examples" / "braid-angle.sweep.toml"


def spec(size: int, cycles: list[int]) -> Spec:
    data = tomllib.loads(SPEC.read_text())
    del data["fixed"]["cycles"]
    data["fixed"]["rows"] = data["fixed"]["cols"] = size
    data["vary"]["cycles"] = cycles
    return parse_spec(data, str(SPEC), SPEC.parent)


def bare(candidate: Candidate) -> float:
    """Seconds of the bare twin run: generate, parse, simulate (up to a refusal, if any)."""
    start = time.perf_counter()
    generated = GENERATORS["braid4"](**candidate.params)
    with contextlib.suppress(BwsdError):  # a refused candidate: its time up to the refusal
        simulate(generated.machine, parse_program(generated.program))
    return time.perf_counter() - start


def split(candidate: Candidate) -> tuple[float, float] | None:
    """Seconds of the twin alone and of the metrics alone for one candidate (None when the
    twin refuses it)."""
    generated = GENERATORS["braid4"](**candidate.params)
    program = parse_program(generated.program)
    start = time.perf_counter()
    try:
        simulate(generated.machine, program)
    except BwsdError:
        return None
    twin_s = time.perf_counter() - start
    named = section_header(generated.program)
    assert named is not None
    twin, visits = simulate_with_visits(generated.machine, program, named.section)
    start = time.perf_counter()
    sk = twin.skeleton()
    arrays = Arrays.of(sk)
    band = section(sk, arrays)
    z = None if band is None else (band["z"][0] + band["z"][1]) / 2
    metrics(
        sk,
        program.cycle_length,
        takeups=takeups_of(program),
        z=z,
        named=named,
        visits=visits,
        arrays=arrays,
    )
    return twin_s, time.perf_counter() - start


def split_table(candidates: list[Candidate], repeat: int) -> None:
    found = [split(c) for _ in range(repeat) for c in candidates]
    runs = [f for f in found if f is not None]
    twin, metric = [r[0] for r in runs], [r[1] for r in runs]
    print(
        "| per candidate that runs (the twin refuses "
        f"{(len(found) - len(runs)) // repeat} of {len(candidates)}) | n | p50 ms | p99 ms |"
    )
    print("|---|---:|---:|---:|")
    print(f"| the twin alone: simulate (baseline) | {len(twin)} | {' | '.join(ms(twin))} |")
    print(
        f"| the metrics alone: skeleton, section, metrics() | {len(metric)} | "
        f"{' | '.join(ms(metric))} |"
    )
    ratio = statistics.median(m / t for t, m in runs)
    print(
        f"\n- Metrics over the twin, median of the candidates' own ratios: {ratio:.2f}x "
        "(target: at most 1x).\n"
    )


def in_process(candidate: Candidate) -> float:
    start = time.perf_counter()
    evaluate(candidate)
    return time.perf_counter() - start


def sweep(the_spec: Spec, workers: int) -> tuple[float, float, float, float]:
    """Wall seconds of a whole sweep, of its cluster's start, of running the candidates, and
    the median of the candidates' own seconds in the workers."""
    with tempfile.TemporaryDirectory() as folder:
        output = Path(folder) / "r.parquet"
        start = time.perf_counter()
        done = run_sweep(the_spec, output, Options(workers=workers))
        wall = time.perf_counter() - start
        own = statistics.median(pq.read_table(output).column("seconds").to_pylist())
        return wall, done.start_seconds, done.run_seconds, own


def _evaluate_all(candidates: list[Candidate]) -> None:
    for candidate in candidates:
        evaluate(candidate)


def plain(candidates: list[Candidate], processes: int) -> float:
    """Seconds for ``processes`` plain processes (no Dask) to evaluate a share each, once
    started: what the machine's cores give at best."""
    shares = [candidates[i::processes] for i in range(processes)]
    with multiprocessing.get_context("spawn").Pool(processes) as pool:
        pool.map(_evaluate_all, [shares[0][:1]] * processes)  # started and imported
        start = time.perf_counter()
        pool.map(_evaluate_all, shares, chunksize=1)
        return time.perf_counter() - start


def ms(values: list[float]) -> tuple[str, str]:
    p50, p99 = np.percentile(1e3 * np.array(values), [50, 99])
    return f"{p50:.2f}", f"{p99:.2f}"


def table(size: int, cycles: list[int], repeat: int) -> None:
    the_spec = spec(size, cycles)
    candidates = the_spec.candidates()
    n = len(candidates)
    base = [bare(c) for _ in range(repeat) for c in candidates]
    full = [in_process(c) for _ in range(repeat) for c in candidates]
    runs = {w: [sweep(the_spec, w) for _ in range(repeat)] for w in (1, 2)}
    plains = {w: statistics.median(plain(candidates, w) for _ in range(repeat)) for w in (1, 2)}
    print(
        f"### {n} candidates: braid4 {size} x {size}, cycles {cycles}, 8 take-ups, "
        f"3 c_mat; {repeat} repeats\n"
    )
    print("| per candidate | n | p50 ms | p99 ms |\n|---|---:|---:|---:|")
    print(
        f"| bare twin run: generate, parse, simulate (baseline) | {len(base)} | "
        f"{' | '.join(ms(base))} |"
    )
    print(
        f"| in-process candidate: the same and the metrics | {len(full)} | "
        f"{' | '.join(ms(full))} |\n"
    )
    print(
        "| sweep (local cluster) | wall s | cluster start s | running s | candidates/s "
        "(wall) | candidates/s (running) | running, vs 1 process | a candidate in its "
        "worker, p50 ms |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    one = statistics.median(r[2] for r in runs[1])
    for w in (1, 2):
        wall, start, running, own = (statistics.median(r[i] for r in runs[w]) for i in range(4))
        print(
            f"| {w} process{'es' * (w > 1)} | {wall:.2f} | {start:.2f} | {running:.2f} | "
            f"{n / wall:.1f} | {n / running:.1f} | {one / running:.2f}x | "
            f"{1e3 * own:.2f} |"
        )
    for w in (1, 2):
        name, seconds = f"no Dask: {w} plain process{'es' * (w > 1)} (ceiling)", plains[w]
        print(
            f"| {name} | | | {seconds:.2f} | | {n / seconds:.1f} | {plains[1] / seconds:.2f}x | |"
        )
    bare_s, full_s, per = statistics.median(base), statistics.median(full), one / n
    print(
        f"\n- Per candidate on 1 process (running time / {n}): {1e3 * per:.2f} ms; over "
        f"the bare twin run ({1e3 * bare_s:.2f} ms): {1e3 * (per - bare_s):.2f} ms more "
        f"({per / bare_s:.2f}x), of which the metrics {1e3 * (full_s - bare_s):.2f} ms and "
        f"Dask, pickling and the row log {1e3 * (per - full_s):.2f} ms.\n"
    )
    split_table(candidates, repeat)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--sizes", default="3,6", help="braid sizes (N x N), comma-separated")
    parser.add_argument("--cycles", default="6,8,10,12")
    args = parser.parse_args()
    print(f"{os.cpu_count()} cores, Python {sys.version.split()[0]}\n")
    for size in (int(s) for s in args.sizes.split(",")):
        table(size, [int(c) for c in args.cycles.split(",")], args.repeat)


if __name__ == "__main__":
    main()
