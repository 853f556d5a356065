"""`bwsd simulate`: run a program through the twin and write its exports."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bwsd.errors import ProgramError, TwinError

if TYPE_CHECKING:
    from bwsd.twin import Machine, Program, Twin
    from bwsd.twin.model import ProgressFn


def configure(sub: Any) -> None:
    """Register `simulate`."""
    p = sub.add_parser("simulate", help="run a program through the twin")
    p.add_argument("program", help="a .bws program, or example:NAME (`bwsd examples`)")
    p.add_argument("--config", required=True, help="machine config (TOML), or example:NAME")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("--skeleton", metavar="FILE", help="write the skeleton as JSON")
    p.add_argument(
        "--export",
        metavar="FILE",
        action="append",
        default=[],
        help="write FILE.tg3 (TexGen), FILE.vtp (ParaView) or FILE.json; repeatable",
    )
    p.add_argument(
        "--relax",
        action="store_true",
        help="write the relaxed preform (docs/relax.md) to --skeleton and --export",
    )
    p.set_defaults(handler=_simulate_cmd)


def load_and_simulate(
    program_path: str,
    config_path: str,
    progress: ProgressFn | None = None,
    timings: list[float] | None = None,
) -> tuple[Machine, Program, Twin]:
    """Load config and program, run the program; a refused instruction names its line."""
    from bwsd.config import load_config
    from bwsd.program.validate import load_program
    from bwsd.twin import simulate

    config = load_config(config_path)
    machine = config.machine
    program = load_program(program_path, machine, config.table("controller")["max_instructions"])
    with refused_at_line(program, program_path):
        twin = simulate(machine, program, progress, timings)
    return machine, program, twin


@contextmanager
def refused_at_line(program: Program, source: str) -> Iterator[None]:
    """An instruction the twin refuses in the block, as a ProgramError naming its line."""
    try:
        yield
    except TwinError as exc:
        raise ProgramError(
            f"instruction {exc.instruction}: {exc.reason}",
            line=program.line_of(exc.instruction),
            column=1,
            source=source,
        ) from None


@contextmanager
def _progress(enabled: bool) -> Iterator[ProgressFn | None]:
    if not enabled:
        yield None
        return
    from rich.console import Console
    from rich.progress import Progress

    with Progress(console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("simulating", total=None)

        def report(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield report


def _summary(
    twin: Twin, seconds: float, timings: list[float], loose: list[tuple[int, int]]
) -> dict[str, Any]:
    return {
        "yarns": twin.yarn_count,
        "nodes": twin.node_count,
        "contacts": twin.contact_count,
        "instructions": twin.done,
        "takeup": twin.takeup,
        "seconds": round(seconds, 6),
        "predict_ms": _percentiles(timings),
        "loose_wefts": [yarn for yarn, _ in loose],
    }


def loose_wefts(twin: Twin, program: Program) -> list[tuple[int, int]]:
    """The wefts no contact holds, as (yarn, program line): they lie loose in the preform."""
    from bwsd.twin import Weft

    sk = twin.skeleton()
    touched = {y for c in sk.contacts for y in (c.moving_yarn, c.hit_yarn)}
    inserted = [i for i, ins in enumerate(program.instructions, start=1) if isinstance(ins, Weft)]
    wefts = [y.id for y in sk.yarns if y.kind == "weft"]
    return [
        (yarn, program.line_of(index))
        for yarn, index in zip(wefts, inserted, strict=False)
        if yarn not in touched
    ]


def _warn_loose(loose: list[tuple[int, int]], source: str) -> None:
    if loose:
        shown = ", ".join(f"yarn {yarn} ({source}:{line})" for yarn, line in loose[:10])
        more = f" and {len(loose) - 10} more" if len(loose) > 10 else ""
        print(
            f"bwsd: warning: {len(loose)} weft(s) without any contact lie loose: {shown}{more}",
            file=sys.stderr,
        )


def _percentiles(seconds: list[float]) -> dict[str, float]:
    """p50, p99 and max of per-instruction times, in milliseconds (all 0 for none)."""
    if not seconds:
        return {"p50": 0.0, "p99": 0.0, "max": 0.0}
    import numpy as np

    ms = 1e3 * np.array(seconds)
    p50, p99 = np.percentile(ms, [50, 99])
    return {
        "p50": round(float(p50), 4),
        "p99": round(float(p99), 4),
        "max": round(float(ms.max()), 4),
    }


def _write_exports(
    twin: Twin, skeleton: str | None, exports: list[str], relaxed: Any = None
) -> None:
    from bwsd.export import export
    from bwsd.export.skeleton_json import write_skeleton_json

    if relaxed is not None:
        from bwsd.relax.document import write_relaxed

        for path in ([skeleton] if skeleton else []) + exports:
            write_relaxed(relaxed, path)
        return
    sk = twin.skeleton()
    for path in ([skeleton] if skeleton else []) + exports:
        Path(path).parent.mkdir(parents=True, exist_ok=True)  # out/x.json makes out/
    if skeleton:
        write_skeleton_json(sk, skeleton)
    for path in exports:
        export(sk, path)


def _simulate_cmd(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    timings: list[float] = []
    with _progress(sys.stderr.isatty() and not args.json) as progress:
        _, program, twin = load_and_simulate(args.program, args.config, progress, timings)
    seconds = time.perf_counter() - start
    relaxed = None
    if args.relax:
        from bwsd.relax.cli import options_of, relax_skeleton

        relaxed = relax_skeleton(twin.skeleton(), options_of(args.config), not args.json)
    _write_exports(twin, args.skeleton, args.export, relaxed)
    loose = loose_wefts(twin, program)
    _warn_loose(loose, args.program)
    summary = _summary(twin, seconds, timings, loose)
    if relaxed is not None:
        summary["relaxed"] = relaxed.summary()
    if args.json:
        print(json.dumps(summary, allow_nan=False))  # never NaN or Infinity
    else:
        ms = summary.pop("predict_ms")
        summary.pop("loose_wefts")
        if relaxed is not None:
            from bwsd.relax.cli import summary_line

            print("relaxed: " + summary_line(summary.pop("relaxed")))
        print(
            ", ".join(f"{k} {v}" for k, v in summary.items()) + ", predict ms p50 "
            f"{ms['p50']} p99 {ms['p99']} max {ms['max']}"
        )
    return 0
