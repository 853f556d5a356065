"""Command line: `bwsd slice` and `bwsd metrics`, both on a simulated program."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from bwsd.twin.instructions import Program
from bwsd.twin.machine import Machine
from bwsd.twin.skeleton import SkeletonData

if TYPE_CHECKING:
    from bwsd.export.mixing import NamedSection


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
        help="section, yarn angles, contacts per cycle, contact groups, carrier mixing, footprint",
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
    p.add_argument("program", help="program file (.bws)")
    p.add_argument("--config", required=True, help="machine configuration (TOML)")


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
    from bwsd.twin import simulate

    machine, parsed = load_inputs(config, program)
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
    from bwsd.export.mixing import check_fits, section_option, simulate_with_visits
    from bwsd.twin import simulate

    named = section_option(args.section) if args.section is not None else None
    machine, program = load_inputs(args.config, args.program)
    named = named or _header_section(args.program)
    cycle = args.cycle_length if args.cycle_length is not None else program.cycle_length
    if named is None:
        result = metrics(simulate(machine, program).skeleton(), cycle, z=args.z)
    else:
        check_fits(named.section, machine)
        twin, visits = simulate_with_visits(machine, program, named.section)
        result = metrics(twin.skeleton(), cycle, z=args.z, named=named, visits=visits)
    if args.json:
        print(json.dumps(result, indent=2, allow_nan=False))  # never NaN or Infinity
    else:
        print_metrics(result, Console())
    return 0


def _header_section(program: str) -> NamedSection | None:
    """The section named by the program's ``# section:`` line (the program reads as UTF-8)."""
    from bwsd.export.mixing import section_header

    return section_header(Path(program).read_text(encoding="utf-8"), program)


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
    if result["mixing"] is not None:
        console.print(_mixing_table(result["mixing"], result["section_spec"]))
    if result["footprint"] is not None:
        console.print(_footprint_table(result["footprint"]))


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


def _mixing_table(mixing: dict[str, Any], spec: dict[str, Any]) -> Table:
    source = "--section" if spec["source"] == "option" else f"program line {spec['line']}"
    table = Table(title=f"Carrier mixing, section {mixing['section']} (from {source})",
                  show_header=False)  # fmt: skip
    table.add_row("carriers", f"{mixing['carriers']} ({mixing['edge']} filled outside the section)")
    if mixing["empty_body_cells"]:
        table.add_row("body cells empty at the fill", str(mixing["empty_body_cells"]))
    for zone in mixing["zones"]:
        need = "required" if zone["required"] else "not required"
        visited = f"{zone['carriers']} carriers visited ({zone['cells']} cells, {need})"
        table.add_row(f"zone {zone['name']}", visited)
    table.add_row("visited every required zone", str(mixing["complete"]))
    table.add_row("did not", str(mixing["incomplete"]))
    for miss in mixing["missing"]:
        row, col = miss["cell"]
        table.add_row(f"  yarn {miss['yarn']} (filled at {row}, {col})",
                      "missed " + ", ".join(miss["zones"]))  # fmt: skip
    if mixing["incomplete"] > len(mixing["missing"]):
        table.add_row("  ...", f"{mixing['incomplete'] - len(mixing['missing'])} more")
    table.add_row("K (cycles until all mixed)", _k(mixing))
    return table


def _k(mixing: dict[str, Any]) -> str:
    if mixing["k"] is None:
        return "never within the program"
    if mixing["k"] == 0:
        return "0 (all mixed at the fill)"
    return (f"{mixing['k']} (after instruction {mixing['instruction']}, "
            f"cycles of {mixing['cycle_length']})")  # fmt: skip


def _range(values: list[float] | None) -> str:
    return "-" if values is None else f"{values[0]:.3f} .. {values[1]:.3f} mm"


def _footprint_table(foot: dict[str, Any]) -> Table:
    table = Table(title=f"Footprint at z = {foot['z']:g} mm (discs of the yarn diameter)",
                  show_header=False)  # fmt: skip
    free = f", {foot['free']} on free segments" if foot["free"] else ""
    table.add_row("crossings", f"{foot['crossings']}{free}")
    measured = foot["measured"]
    table.add_row("measured area", _number(measured["area"], " mm^2"))
    table.add_row("measured x / y", f"{_range(measured['x'])} / {_range(measured['y'])}")
    nominal = foot["nominal"]
    if nominal is None:
        return table
    table.add_row(f"nominal area ({nominal['section']})", _number(nominal["area"], " mm^2"))
    table.add_row("nominal x / y", f"{_range(nominal['x'])} / {_range(nominal['y'])}")
    table.add_row("measured / nominal", _number(foot["ratio"]))
    table.add_row("nominal covered", _number(foot["coverage"]))
    table.add_row("measured outside nominal", _number(foot["outside"], " mm^2"))
    return table
