"""Command line: `bwsd slice` and `bwsd metrics`, both on a simulated program."""

from __future__ import annotations

import argparse
import json
import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bwsd.export.mixing import NamedSection
    from bwsd.twin.instructions import Program
    from bwsd.twin.machine import Machine
    from bwsd.twin.skeleton import SkeletonData


def configure(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the `slice` and `metrics` subcommands."""
    p = sub.add_parser("slice", help="draw the preform's cross-section at one height")
    _common(p)
    p.add_argument("--z", type=height, required=True, help="height in the preform frame (mm)")
    p.add_argument(
        "-o",
        "--output",
        default="slice.png",
        help="image file; the suffix picks the format (default: slice.png)",
    )
    p.set_defaults(handler=run_slice)

    p = sub.add_parser(
        "metrics",
        help="formed zone: yarn angles, volume fraction, contacts, section",
        description="The formed zone's metrics: yarn angles, interpenetration, volume "
        "fraction; weft contacts, section, contacts per cycle, contact groups, carrier mixing, "
        "footprint.",
    )
    _common(p)
    p.add_argument(
        "--cycle-length",
        type=int,
        default=None,
        metavar="N",
        help="instructions per cycle (default: one pass of the outermost REPEAT)",
    )
    p.add_argument(
        "--section",
        default=None,
        metavar="SPEC",
        help="the braided section, e.g. rect:2x2 or L:2x6:4x2 (default: the program's "
        "'# section:' line, if any): carrier mixing and the nominal footprint",
    )
    p.add_argument(
        "--z",
        type=height,
        default=None,
        metavar="Z",
        help="measure the footprint at this height in the preform frame (mm)",
    )
    p.add_argument("--json", action="store_true", help="print JSON instead of tables")
    p.add_argument(
        "--relaxed",
        action="store_true",
        help="measure the relaxed preform (docs/relax.md) instead of the twin's",
    )
    p.set_defaults(handler=run_metrics)


def height(text: str) -> float:
    """A height on the command line: a finite number of mm (``nan`` and ``inf`` refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text[:20]!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite height in mm, got {text[:20]!r}")
    return value


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("program", help="program file (.bws), or example:NAME")
    p.add_argument("--config", required=True, help="machine configuration (TOML), or example:NAME")


def load_inputs(config: str, program: str) -> tuple[Machine, Program]:
    """Load the config and the program, validated for the config's machine."""
    # Imported here so that building the parser stays cheap.
    from bwsd.config import load_config
    from bwsd.program.validate import load_program

    loaded = load_config(config)
    machine = loaded.machine
    return machine, load_program(program, machine, loaded.table("controller")["max_instructions"])


def simulate_program(config: str, program: str) -> tuple[SkeletonData, Program]:
    """Load the config and the program, run the twin, return the final skeleton."""
    from bwsd.simulate import refused_at_line
    from bwsd.twin import simulate

    machine, parsed = load_inputs(config, program)
    with refused_at_line(parsed, program):
        return simulate(machine, parsed).skeleton(), parsed


def run_slice(args: argparse.Namespace) -> int:
    """`bwsd slice`: write the cross-section image, report the crossings."""
    from bwsd.export.errors import ExportError
    from bwsd.extras import MATPLOTLIB, needs

    with needs(MATPLOTLIB, "drawing a slice", ExportError):  # before the simulation
        from bwsd.export.slice import draw_slice

    sk, _ = simulate_program(args.config, args.program)
    count = draw_slice(sk, args.z, args.output)
    print(f"{args.output}: {count} yarn crossings at z = {args.z:g} mm")
    return 0


def run_metrics(args: argparse.Namespace) -> int:
    """`bwsd metrics`: print the metrics as tables or JSON."""
    from bwsd.export.formed import takeups_of
    from bwsd.export.metrics import metrics
    from bwsd.export.mixing import check_fits, section_option, simulate_with_visits
    from bwsd.simulate import refused_at_line
    from bwsd.twin import simulate

    named = section_option(args.section) if args.section is not None else None
    machine, program = load_inputs(args.config, args.program)
    named = named or _header_section(args.program)
    cycle = args.cycle_length if args.cycle_length is not None else program.cycle_length
    takeups = takeups_of(program)
    visits = None
    if named is None:
        with refused_at_line(program, args.program):
            sk = simulate(machine, program).skeleton()
    else:
        check_fits(named.section, machine)
        with refused_at_line(program, args.program):
            twin, visits = simulate_with_visits(machine, program, named.section)
        sk = twin.skeleton()
    extra: dict[str, Any] = {}
    if args.relaxed:
        sk, extra = _relaxed(sk, args.config, not args.json)
    result = metrics(sk, cycle, takeups=takeups, z=args.z, named=named, visits=visits)
    result.update(extra)
    if args.json:
        print(json.dumps(result, indent=2, allow_nan=False))  # never NaN or Infinity
    else:
        from rich.console import Console

        from bwsd.export.tables import print_metrics

        print_metrics(result, Console())
    return 0


def _relaxed(sk: SkeletonData, config: str, show: bool) -> tuple[SkeletonData, dict[str, Any]]:
    """The relaxed skeleton, and the metrics it adds: weft crimp and the solver's figures."""
    from bwsd.relax.cli import options_of, relaxed_metrics

    return relaxed_metrics(sk, options_of(config), show)


def _header_section(program: str) -> NamedSection | None:
    """The section named by the program's ``# section:`` line (the program reads as UTF-8)."""
    from bwsd.export.mixing import section_header
    from bwsd.shipped import resolve

    return section_header(resolve(program).read_text(encoding="utf-8"), program)
