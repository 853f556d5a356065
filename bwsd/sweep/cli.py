"""`bwsd sweep SPEC -o results.parquet` and `bwsd sweep plot results.parquet --x --y`."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bwsd.sweep.errors import SweepError

USAGE = """bwsd sweep SPEC.toml -o results.parquet [--csv] [--scheduler tcp://HOST:PORT]
                  [--workers N] [--batch N] [--resume] [--progress | --no-progress]
       bwsd sweep plot results.parquet --x PARAM --y METRIC [--hue PARAM] -o plot.png"""
EXAMPLE = "example:"  # SPEC written example:NAME is a spec shipped with the package


def configure(sub: Any) -> None:
    """Register `bwsd sweep` (and its `plot`) on the top-level subcommand action."""
    p = sub.add_parser(
        "sweep",
        help="run the twin over a grid or random sample of parameters (Dask); plot results",
        usage=USAGE,
        description="Design sweeps (docs/sweeps.md): the first form runs every candidate "
        "of the spec, the second draws a metric of the results.",
        epilog=f"{sweep_parser().format_help()}\n{plot_parser().format_help()}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("words", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    p.set_defaults(handler=run)


def sweep_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bwsd sweep", description="Run a design sweep.")
    p.add_argument("spec", help="the sweep spec (TOML), or example:NAME for a shipped one")
    p.add_argument("-o", "--output", required=True, help="results file (Parquet)")
    p.add_argument("--csv", action="store_true", help="also write the rows as CSV beside it")
    p.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="a running Dask scheduler (default: a local cluster)",
    )
    p.add_argument(
        "--workers",
        type=_positive,
        metavar="N",
        help="local cluster: worker processes (default: one per core)",
    )
    p.add_argument(
        "--batch",
        type=_positive,
        metavar="N",
        help="candidates per task (default: sized to about 0.25 s a task)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="go on with an unfinished (killed) sweep of the same output",
    )
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="progress bar on stderr (default: when stderr is a terminal)",
    )
    return p


def plot_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bwsd sweep plot", description="Plot sweep results.")
    p.add_argument("results", help="a sweep's results (Parquet, or its CSV)")
    p.add_argument("--x", required=True, metavar="PARAM", help="column along x")
    p.add_argument("--y", required=True, metavar="METRIC", help="column along y")
    p.add_argument("--hue", metavar="PARAM", help="one line per value of this column")
    p.add_argument("-o", "--output", default="sweep.png", help="image file (sweep.png)")
    return p


def _positive(text: str) -> int:
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return int(text)


def spec_path(text: str) -> Path:
    """The spec's file: a path, or ``example:NAME`` for one shipped with the package."""
    if not text.startswith(EXAMPLE):
        return Path(text)
    from bwsd.shipped import example_file

    return example_file(text.removeprefix(EXAMPLE))


def run(args: argparse.Namespace) -> int:
    """Dispatch `bwsd sweep ...` to the sweep itself or to `plot`."""
    words: Sequence[str] = args.words
    if words and words[0] == "plot":
        return run_plot(plot_parser().parse_args(words[1:]))
    return run_sweep(sweep_parser().parse_args(words))


def run_sweep(args: argparse.Namespace) -> int:
    from bwsd.sweep.runner import Options
    from bwsd.sweep.runner import run_sweep as sweep
    from bwsd.sweep.spec import load_spec

    if args.workers is not None and args.scheduler is not None:
        raise SweepError("--workers sizes the local cluster: a scheduler has its own workers")
    output = Path(args.output)
    if args.csv and output.suffix.lower() == ".csv":
        raise SweepError(
            f"-o {output}: the results are Parquet (e.g. -o results.parquet); "
            "--csv writes the CSV beside them"
        )
    spec = load_spec(spec_path(args.spec))
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    options = Options(args.scheduler, args.workers, args.batch, args.resume, args.csv, progress)
    print(sweep(spec, output, options).text(output))
    return 0


def run_plot(args: argparse.Namespace) -> int:
    from bwsd.sweep.plot import plot

    lines = plot(Path(args.results), Path(args.output), args.x, args.y, args.hue)
    print(f"{args.output}: {args.y} against {args.x}, {lines} line{'s' * (lines != 1)}")
    return 0
