"""Command line: `bwsd slice` and `bwsd metrics`, both on a simulated program."""

from __future__ import annotations

import argparse
import json
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from bwsd.twin.instructions import Program
from bwsd.twin.skeleton import SkeletonData


def configure(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the `slice` and `metrics` subcommands."""
    p = sub.add_parser("slice", help="draw the preform's cross-section at one height")
    _common(p)
    p.add_argument("--z", type=float, required=True, help="height in the preform frame (mm)")
    p.add_argument(
        "-o",
        "--output",
        default="slice.png",
        help="image file; the suffix picks the format (default: slice.png)",
    )
    p.set_defaults(handler=run_slice)

    p = sub.add_parser("metrics", help="section, yarn angles, contacts per cycle, contact groups")
    _common(p)
    p.add_argument(
        "--cycle-length",
        type=int,
        default=None,
        metavar="N",
        help="instructions per cycle (default: one pass of the outermost REPEAT)",
    )
    p.add_argument("--json", action="store_true", help="print JSON instead of tables")
    p.set_defaults(handler=run_metrics)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("program", help="program file (.bws)")
    p.add_argument("--config", required=True, help="machine configuration (TOML)")


def simulate_program(config: str, program: str) -> tuple[SkeletonData, Program]:
    """Load the config and the program, run the twin, return the final skeleton."""
    # Imported here so that building the parser stays cheap.
    from bwsd.config import load_config
    from bwsd.program.validate import load_program
    from bwsd.twin import simulate

    loaded = load_config(config)
    machine = loaded.machine
    parsed = load_program(program, machine, loaded.table("controller")["max_instructions"])
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
    from bwsd.export.metrics import metrics

    sk, program = simulate_program(args.config, args.program)
    cycle = args.cycle_length if args.cycle_length is not None else program.cycle_length
    result = metrics(sk, cycle)
    if args.json:
        print(json.dumps(result, indent=2, allow_nan=False))  # never NaN or Infinity
    else:
        print_metrics(result, Console())
    return 0


def _number(value: float | None, unit: str = "") -> str:
    return "n/a" if value is None else f"{value:.3f}{unit}"


def print_metrics(result: dict[str, Any], console: Console) -> None:
    """Render ``metrics()`` output as rich tables."""
    general = Table(title="Skeleton", show_header=False)
    yarns = result["yarns"]
    for key, value in (
        ("instructions", str(result["instructions"])),
        ("take-up", _number(result["takeup"], " mm")),
        ("yarn diameter", _number(result["diameter"], " mm")),
        ("yarns", f"{yarns['warp']} warp, {yarns['weft']} weft"),
        ("nodes", str(result["nodes"])),
        ("contacts", str(result["contacts"])),
    ):
        general.add_row(key, value)
    console.print(general)
    console.print(_section_table(result["section"]))
    console.print(_angle_table(result["angles"]))
    console.print(_cycle_table(result["cycles"]))
    console.print(_groups_table(result["groups"], result["unconnected"]))


def _section_table(section: dict[str, Any] | None) -> Table:
    table = Table(title="Section (fixed nodes, middle half of the contact zone)", show_header=False)
    if section is None:
        table.add_row("n/a", "no contacts, or no fixed node in the band")
        return table
    low, high = section["z"]
    table.add_row("z band", f"{low:.3f} .. {high:.3f} mm")
    table.add_row("nodes", str(section["nodes"]))
    table.add_row("width (x)", _number(section["width"], " mm"))
    table.add_row("thickness (y)", _number(section["thickness"], " mm"))
    return table


def _angle_table(angles: dict[str, dict[str, Any]]) -> Table:
    table = Table(title="Yarn angle to the production axis (length-weighted)")
    for name in ("family", "segments", "length [mm]", "mean [deg]", "spread [deg]"):
        table.add_column(escape(name), justify="left" if name == "family" else "right")
    for family, a in angles.items():
        table.add_row(
            family, str(a["segments"]), _number(a["length"]), _number(a["mean"]), _number(a["std"])
        )
    return table


def _cycle_table(cycles: dict[str, Any]) -> Table:
    table = Table(title=f"Contacts per cycle of {cycles['length']} instructions", show_header=False)
    counts = cycles["counts"]
    shown = " ".join(str(c) for c in counts[:40]) + (" ..." if len(counts) > 40 else "")
    table.add_row("cycles", f"{cycles['cycles']} ({cycles['complete']} complete)")
    table.add_row("mean", _number(cycles["mean"]))
    table.add_row("min / max", f"{cycles['min']} / {cycles['max']}")
    table.add_row("counts", shown or "-")
    return table


def _listed(values: list[Any], most: int = 20) -> str:
    shown = ", ".join(str(v) for v in values[:most])
    return (shown + (f", ... ({len(values)} in all)" if len(values) > most else "")) or "-"


def _groups_table(groups: dict[str, Any], unconnected: dict[str, Any]) -> Table:
    table = Table(title="Contact graph (yarns joined by contacts)", show_header=False)
    table.add_row("groups", str(groups["count"]))
    table.add_row("sizes", _listed(groups["sizes"]))
    table.add_row("yarns without contact", str(unconnected["count"]))
    if unconnected["ids"]:
        table.add_row("their ids", _listed(unconnected["ids"]))
    return table
