"""The relaxation's times and figures on the shipped examples: prints the table of
docs/benchmarks.md ("Relaxation").

    python bench/relax.py                   # the examples, 3 runs each, one core
    python bench/relax.py --repeat 5 --big  # also the 24 x 24 braid (10 cycles)
    python bench/relax.py --metrics --slices docs   # metrics before and after, and slices
    python bench/relax.py --unit-cell       # a relaxed 4-step braid against the unit cell

For each example, measured in this run: the twin's ``simulate`` (the baseline) and
``relax`` of its skeleton (median and 99th percentile of the runs), their ratio, the solver's
figures (steps, nodes added, worst overlap, force residual) and the share of yarn length
within 0.99 d of another yarn before and after, by the metrics' own measure. Peak memory of
one relaxation (tracemalloc, a run of its own) per node of the relaxed skeleton.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import tracemalloc
from dataclasses import replace
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.twin import load, p99, timed  # noqa: E402
from bwsd.export.arrays import Arrays  # noqa: E402
from bwsd.export.formed import find_zone, pieces, takeups_of  # noqa: E402
from bwsd.export.metrics import contact_zone, metrics  # noqa: E402
from bwsd.export.overlap import interpenetration  # noqa: E402
from bwsd.export.slice import draw_slice  # noqa: E402
from bwsd.relax import crimp, relax  # noqa: E402
from bwsd.relax.unitcell import compare  # noqa: E402
from bwsd.twin import simulate  # noqa: E402
from bwsd.twin.skeleton import SkeletonData  # noqa: E402

EXAMPLES = ["twist", "braid-2x2", "weave-U", "paper-U", "braid-L", "paper-L"]
TARGETS = {"braid-2x2": 0.1, "braid-L": 1.0, "paper-U": 2.0, "braid-24x24": 30.0}


def share(sk: SkeletonData, within: float) -> float:
    """Share of yarn length within ``within`` d of another yarn (bwsd.export.overlap)."""
    arrays = Arrays.of(replace(sk, diameter=within * sk.diameter))
    found = interpenetration(arrays, pieces(arrays, find_zone(arrays, 1, None)))
    return float(found["skeleton"]["all"]["share"] or 0.0)


def peak_bytes(sk: SkeletonData) -> int:
    tracemalloc.start()
    relax(sk)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def row(stem: str, repeat: int) -> str:
    machine, program = load(stem)
    twin_s = timed(lambda: simulate(machine, program), repeat)
    sk = simulate(machine, program).skeleton()
    runs = []
    for _ in range(repeat):
        start = time.perf_counter()
        relaxed = relax(sk)
        runs.append(time.perf_counter() - start)
    f, summary = relaxed.figures, relaxed.summary()
    nodes = relaxed.skeleton.node_count
    median, twin_median = statistics.median(runs), statistics.median(twin_s)
    target = TARGETS.get(stem)
    verdict = (
        ""
        if target is None
        else f"< {target:g} s: " + ("met" if p99(runs) < target else "**missed**")
    )
    return (
        f"| {stem} | {sk.node_count} | {nodes} | {twin_median:.4f} | {median:.3f} "
        f"| {p99(runs):.3f} | {median / twin_median:.0f}x | {f.separate_steps} + {f.steps} | "
        f"{summary['worst_overlap_share'] * 100:.2f} % | {summary['force_residual']:.3g} | "
        f"{share(sk, 0.99) * 100:.1f} % | {share(relaxed.skeleton, 0.99) * 100:.1f} % | "
        f"{peak_bytes(sk) / nodes / 1024:.1f} | {verdict} |"
    )


SLICED = ["braid-2x2", "braid-L", "paper-L", "weave-U", "paper-U"]


def _mean(values: list[dict[str, Any]] | None, key: str) -> float | None:
    return float(statistics.mean(v[key] for v in values)) if values else None


def _fmt(value: float | None, scale: float = 1.0, digits: int = 1, unit: str = "") -> str:
    return "-" if value is None else f"{value * scale:.{digits}f}{unit}"


def metrics_rows(stem: str, folder: Path | None) -> list[str]:
    """The metrics of the twin's skeleton and of the relaxed one; slices of both at the
    middle of the contact zone into ``folder``."""
    machine, program = load(stem)
    sk = simulate(machine, program).skeleton()
    relaxed = relax(sk).skeleton
    out = []
    for label, skel in (("twin", sk), ("relaxed", relaxed)):
        m = metrics(skel, program.cycle_length, takeups=takeups_of(program))
        angle = m["angles"]["warp"]["all"]["mean"] if m["angles"] else None
        sec = m["section"] or {}
        c = crimp(skel)
        out.append(
            f"| {stem} | {label} | {_fmt(angle)} | "
            f"{_fmt(m['interpenetration']['skeleton']['all']['share'], 100, 1, ' %')} | "
            f"{_fmt(_mean(m['volume_fraction'], 'fraction'), 100, 2, ' %')} | "
            f"{_fmt(sec.get('width'))} | {_fmt(sec.get('thickness'))} | "
            f"{_fmt(c['mean'], 100, 2, ' %')} |"
        )
        if folder is not None:
            zone = contact_zone(sk)
            z = 0.5 * (zone[0] + zone[1]) if zone else sk.takeup / 2
            draw_slice(skel, z, folder / f"relax-{stem}-{label}.png")
    return out


UNIT_CELL_TARGET = 0.25  # the relaxed fraction within this share of the model's


def unit_cell_rows() -> list[str]:
    """The relaxed formed-zone volume fraction of rectangular braid4 braids beside the jammed
    unit-cell model's at the same braid angle (docs/relax.md, "Against a unit-cell model")."""
    out = [
        "| braid | braid angle (formed, warp) deg | relaxed Vf | model Vf (whole section) "
        "| model Vf (interior) | ratio | target: within 25 % |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    found = compare(6, 6, 12)
    met = abs(found.ratio - 1) <= UNIT_CELL_TARGET
    out.append(
        f"| {found.braid} | {found.angle:.1f} | {found.relaxed * 100:.1f} % "
        f"| {found.model * 100:.1f} % | {found.interior * 100:.1f} % | {found.ratio:.2f} "
        f"| {'met' if met else '**missed**'} |"
    )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--big", action="store_true", help="also the 24 x 24 braid")
    parser.add_argument("--metrics", action="store_true", help="the metrics before and after")
    parser.add_argument("--slices", type=Path, help="draw slices before and after into DIR")
    parser.add_argument(
        "--unit-cell", action="store_true", help="a relaxed braid against the unit-cell model"
    )
    args = parser.parse_args()
    if args.unit_cell:
        print("\n".join(unit_cell_rows()), flush=True)
        return
    if args.metrics or args.slices:
        print(
            "| example | skeleton | braid angle (formed, warp) deg | within d | volume "
            "fraction (formed) | width mm | thickness mm | weft crimp |"
        )
        print("|---|---|---:|---:|---:|---:|---:|---:|")
        for stem in SLICED:
            print("\n".join(metrics_rows(stem, args.slices)), flush=True)
        return
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    print(
        "| example | twin nodes | relaxed nodes | twin s | relax median s | p99 s | relax / twin "
        "| steps (separate + tighten) | worst overlap / d | force residual / T "
        "| within 0.99 d before | after | peak KiB per node | target |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for stem in EXAMPLES + (["braid-24x24"] if args.big else []):
        print(row(stem, args.repeat), flush=True)


if __name__ == "__main__":
    main()
