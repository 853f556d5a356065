"""Command line: `bwsd relax`, and the relaxation behind `simulate --relax` and
`metrics --relaxed`."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the parser imports nothing heavy: the handlers import what they need
    from bwsd.config import Config
    from bwsd.relax import Options, Relaxed
    from bwsd.twin.skeleton import SkeletonData

QUIET_SECONDS = 2.0  # progress shows on a terminal once a run has taken this long


def configure(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register `relax`."""
    p = sub.add_parser(
        "relax",
        help="the tight preform: the twin's skeleton relaxed under "
        "yarn tension, without interpenetration, its topology kept",
    )
    p.add_argument("program", help="a .bws program")
    p.add_argument("--config", required=True, help="machine config (TOML)")
    p.add_argument("-o", "--output", metavar="FILE", help="write the relaxed skeleton as JSON")
    p.add_argument(
        "--export",
        metavar="FILE",
        action="append",
        default=[],
        help="write FILE.tg3 (TexGen, a section per node), FILE.vtp (ParaView) or "
        "FILE.json; repeatable",
    )
    p.add_argument("--json", action="store_true", help="print the solver's figures as JSON")
    p.set_defaults(handler=run_relax)


def options_of(config: str) -> Options:
    """The relaxation's options from the ``[yarn]`` tensions of the config file ``config``."""
    from bwsd.config import load_config

    return options_from(load_config(config))


def options_from(config: Config) -> Options:
    """The relaxation's options from a loaded config's ``[yarn]`` tensions."""
    from bwsd.relax import Options

    yarn = config.table("yarn")
    return Options(warp_tension=yarn["tension"], weft_tension=yarn["weft_tension"])


@contextmanager
def progress(enabled: bool) -> Iterator[Callable[[str, int, int], None] | None]:
    """A progress bar on standard error for runs over ``QUIET_SECONDS`` (when enabled)."""
    if not enabled:
        yield None
        return
    from rich.console import Console
    from rich.progress import Progress

    start = time.perf_counter()
    with Progress(console=Console(stderr=True), transient=True, auto_refresh=False) as bar:
        task = bar.add_task("relaxing", total=None, visible=False)

        def report(phase: str, done: int, total: int) -> None:
            if time.perf_counter() - start >= QUIET_SECONDS:
                bar.update(task, description=phase, completed=done, total=total, visible=True)
                bar.refresh()

        yield report


def relax_skeleton(sk: SkeletonData, options: Options, show: bool = False) -> Relaxed:
    """Relax ``sk`` with ``options`` (a config's tensions: ``options_of``), with progress on
    a terminal when ``show``."""
    from bwsd.relax import relax

    with progress(show and sys.stderr.isatty()) as report:
        return relax(sk, options, report)


def relaxed_metrics(
    sk: SkeletonData, options: Options, show: bool = False
) -> tuple[SkeletonData, dict[str, Any]]:
    """What `bwsd metrics --relaxed` measures: the relaxed skeleton (its metrics are taken as
    the twin's are), and what it adds to them: weft crimp and the solver's figures. A sweep
    with ``relax = true`` measures each candidate with it too."""
    from bwsd.relax import crimp

    relaxed = relax_skeleton(sk, options, show)
    return relaxed.skeleton, {"crimp": crimp(relaxed.skeleton), "relaxed": relaxed.summary()}


def run_relax(args: argparse.Namespace) -> int:
    """`bwsd relax`: simulate, relax, write, report."""
    from bwsd.export.cli import simulate_program
    from bwsd.relax.document import write_relaxed

    sk, _ = simulate_program(args.config, args.program)
    relaxed = relax_skeleton(sk, options_of(args.config), not args.json)
    for path in ([args.output] if args.output else []) + list(args.export):
        write_relaxed(relaxed, path)
    summary = relaxed.summary()
    if args.json:
        print(json.dumps(summary, allow_nan=False))
    else:
        print(summary_line(summary))
    return 0


def summary_line(summary: dict[str, Any]) -> str:
    """The solver's figures on one line."""
    length = summary["tension_length"]
    return (
        f"steps {summary['separate_steps']} + {summary['steps']}, added nodes "
        f"{summary['added_nodes']}, tension x length {length['twin']:.6g} -> "
        f"{length['relaxed']:.6g}, worst overlap {summary['worst_overlap']:.4g} mm, "
        f"force residual {summary['force_residual']:.3g} T, sides kept "
        f"{summary['sides']['kept']} of {summary['sides']['told']}, "
        f"{summary['seconds']:.3f} s"
    )
