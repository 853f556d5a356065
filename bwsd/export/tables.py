"""`bwsd metrics` as tables (rich): one table per group of docs/exports.md's metrics."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table


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
    console.print(_formed_table(result["formed"]))
    if result["angles"] is not None:
        console.print(_formed_angle_table(result["angles"]))
    console.print(_overlap_table(result["interpenetration"], result["diameter"]))
    if result["volume_fraction"] is not None:
        console.print(_fraction_table(result["volume_fraction"]))
    if result["wefts"]["count"]:
        console.print(_weft_table(result["wefts"]))
    console.print(_section_table(result["section"]))
    console.print(
        _angle_table(
            result["skeleton_angles"],
            "Yarn angle to the production axis, whole skeleton (length-weighted)",
        )
    )
    console.print(_cycle_table(result["cycles"]))
    console.print(_groups_table(result["groups"], result["unconnected"]))
    if result["mixing"] is not None:
        console.print(_mixing_table(result["mixing"], result["section_spec"]))
    if result["footprint"] is not None:
        console.print(_footprint_table(result["footprint"]))
    if "relaxed" in result:
        console.print(_relaxed_table(result["relaxed"], result["crimp"]))


def _relaxed_table(relaxed: dict[str, Any], crimp: dict[str, Any]) -> Table:
    table = Table(title="Relaxation (docs/relax.md)", show_header=False)
    length = relaxed["tension_length"]
    table.add_row("steps", f"{relaxed['separate_steps']} separating, {relaxed['steps']} tightening")
    table.add_row("nodes added", str(relaxed["added_nodes"]))
    table.add_row(
        "tension x length",
        f"{length['twin']:.6g} (twin), {length['separated']:.6g} "
        f"(separated), {length['relaxed']:.6g} (relaxed)",
    )
    table.add_row("worst overlap", _number(relaxed["worst_overlap"], " mm"))
    table.add_row("force residual", f"{relaxed['force_residual']:.3g} of the tension")
    table.add_row("contact sides kept", f"{relaxed['sides']['kept']} of {relaxed['sides']['told']}")
    table.add_row(
        "weft crimp",
        "n/a"
        if crimp["mean"] is None
        else f"mean {100 * crimp['mean']:.2f} %, max {100 * crimp['max']:.2f} %",
    )
    table.add_row("seconds", f"{relaxed['seconds']:.3f}")
    return table


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


def _angle_table(angles: dict[str, dict[str, Any]], title: str) -> Table:
    table = Table(title=title)
    for name in ("family", "segments", "length [mm]", "mean [deg]", "spread [deg]"):
        table.add_column(escape(name), justify="left" if name == "family" else "right")
    for family, a in angles.items():
        table.add_row(
            family, str(a["segments"]), _number(a["length"]), _number(a["mean"]), _number(a["std"])
        )
    return table


def _formed_table(formed: dict[str, Any]) -> Table:
    table = Table(
        title="Formed zone (complete cycles below the one still forming)", show_header=False
    )
    if not formed["found"]:
        table.add_row("none", escape(formed["reason"]))
        return table
    low, high = formed["z"]
    first, last = formed["cycles"]
    table.add_row("z", f"{low:.3f} .. {high:.3f} mm")
    table.add_row("cycles", f"{first} to {last} of {formed['complete_cycles']} complete")
    return table


def _formed_angle_table(angles: dict[str, dict[str, Any]]) -> Table:
    table = Table(title="Yarn angle to the production axis in the formed zone (length-weighted)")
    for name in ("family", "part", "length [mm]", "mean [deg]", "spread [deg]"):
        table.add_column(escape(name), justify="left" if name in ("family", "part") else "right")
    for family, parts in angles.items():
        for part, a in parts.items():
            table.add_row(family, part, _number(a["length"]), _number(a["mean"]), _number(a["std"]))
    return table


def _overlap_table(found: dict[str, dict[str, Any]], diameter: float) -> Table:
    table = Table(
        title=f"Interpenetration: yarn closer than one diameter ({diameter:g} mm) to another yarn"
    )
    for name in ("where", "family", "length [mm]", "share", "worst [mm]", "p95 [mm]"):
        table.add_column(escape(name), justify="left" if name in ("where", "family") else "right")
    for where, families in found.items():
        for family, m in families.items():
            share = "n/a" if m["share"] is None else f"{100 * m['share']:.1f} %"
            table.add_row(
                where, family, _number(m["length"]), share, _number(m["worst"]), _number(m["p95"])
            )
    return table


def _fraction_table(heights: list[dict[str, Any]]) -> Table:
    table = Table(
        title="Yarn volume fraction in the formed zone (section: convex hull of the yarn discs)"
    )
    for name in ("z [mm]", "crossings", "yarn [mm^2]", "section [mm^2]", "fraction"):
        table.add_column(escape(name), justify="right")
    for h in heights:
        fraction = "n/a" if h["fraction"] is None else f"{100 * h['fraction']:.2f} %"
        table.add_row(
            f"{h['z']:.3f}",
            str(h["crossings"]),
            _number(h["yarn_area"]),
            _number(h["section_area"]),
            fraction,
        )
    return table


def _weft_table(wefts: dict[str, Any]) -> Table:
    table = Table(title="Weft contacts", show_header=False)
    spread = wefts["contacts"]
    table.add_row("wefts", str(wefts["count"]))
    table.add_row(
        "contacts per weft",
        f"min {spread['min']}, median {spread['median']:g}, max {spread['max']}",
    )
    table.add_row("loose (no contact)", _listed(wefts["loose"]))
    table.add_row("held at one contact", _listed(wefts["held_once"]))
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
    table = Table(
        title=f"Carrier mixing, section {mixing['section']} (from {source})", show_header=False
    )
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
        table.add_row(
            f"  yarn {miss['yarn']} (filled at {row}, {col})", "missed " + ", ".join(miss["zones"])
        )
    if mixing["incomplete"] > len(mixing["missing"]):
        table.add_row("  ...", f"{mixing['incomplete'] - len(mixing['missing'])} more")
    table.add_row("K (cycles until all mixed)", _k(mixing))
    return table


def _k(mixing: dict[str, Any]) -> str:
    if mixing["k"] is None:
        return "never within the program"
    if mixing["k"] == 0:
        return "0 (all mixed at the fill)"
    return (
        f"{mixing['k']} (after instruction {mixing['instruction']}, "
        f"cycles of {mixing['cycle_length']})"
    )


def _range(values: list[float] | None) -> str:
    return "-" if values is None else f"{values[0]:.3f} .. {values[1]:.3f} mm"


def _footprint_table(foot: dict[str, Any]) -> Table:
    table = Table(
        title=f"Footprint at z = {foot['z']:g} mm (discs of the yarn diameter)", show_header=False
    )
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
