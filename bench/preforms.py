"""The shipped examples' preforms, as `bwsd metrics` measures them: prints the tables of
docs/exports.md ("The shipped examples") in markdown.

    python bench/preforms.py

Not a timing: the formed zone, its braid angle, interpenetration and yarn volume fraction
of every example, and the interpenetration of the whole skeleton. tests/export/test_overlap.py
reads the interpenetration table back and checks it against a brute-force computation.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.config import load_config  # noqa: E402
from bwsd.export.formed import takeups_of  # noqa: E402
from bwsd.export.metrics import metrics  # noqa: E402
from bwsd.program import load_program  # noqa: E402
from bwsd.program.generators import EXAMPLES  # noqa: E402
from bwsd.twin import simulate  # noqa: E402

# The 24 x 24 braid is left out: its brute-force check would take hours.
STEMS = [stem for stem in EXAMPLES if stem != "braid-24x24"]


def measured(stem: str) -> dict[str, Any]:
    """`bwsd metrics --json` of one shipped example."""
    machine = load_config(ROOT / "config" / f"{stem}.toml").machine
    program = load_program(ROOT / "examples" / f"{stem}.bws", machine)
    sk = simulate(machine, program).skeleton()
    return metrics(sk, program.cycle_length, takeups=takeups_of(program))


def _pct(value: float | None) -> str:
    return "" if value is None else f"{100 * value:.1f} %"


def overlap_row(stem: str, m: dict[str, Any]) -> str:
    whole, formed = m["interpenetration"]["skeleton"]["all"], m["interpenetration"]["formed"]["all"]
    cells = [
        stem,
        f"{m['diameter']:g}",
        f"{whole['length']:.0f}",
        _pct(whole["share"]),
        f"{whole['worst']:.3f}",
        f"{whole['p95']:.3f}",
        _pct(formed["share"]),
        f"{formed['worst']:.3f}" if formed["length"] else "",
        f"{formed['p95']:.3f}" if formed["length"] else "",
    ]
    return "| " + " | ".join(cells) + " |"


def _angle(part: dict[str, Any]) -> str:
    return "" if part["mean"] is None else f"{part['mean']:.1f}"


def formed_row(stem: str, m: dict[str, Any]) -> str:
    zone = m["formed"]
    if not zone["found"]:
        return f"| {stem} | none: needs {zone['needs_cycles']} cycles | | | | | | | |"
    warp = m["angles"]["warp"]
    fractions = ", ".join(f"{100 * h['fraction']:.1f}" for h in m["volume_fraction"])
    wefts = m["wefts"]["contacts"]
    held = "" if wefts is None else f"{wefts['min']}, {wefts['median']:g}"
    cells = [
        stem,
        f"{zone['cycles'][0]} to {zone['cycles'][1]}",
        f"{zone['z'][0]:.1f} to {zone['z'][1]:.1f}",
        _angle(warp["all"]),
        _angle(warp["interior"]),
        _angle(warp["surface"]),
        f"{m['skeleton_angles']['warp']['mean']:.1f}",
        fractions + " %",
        held,
    ]
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    found = {stem: measured(stem) for stem in STEMS}
    print(
        "| example | d mm | yarn mm | within d of another yarn | worst mm | p95 mm "
        "| formed: within d | formed: worst mm | formed: p95 mm |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for stem in STEMS:
        print(overlap_row(stem, found[stem]))
    print(
        "\n| example | formed cycles | formed z mm | warp angle | interior | surface "
        "| whole-skeleton angle | yarn volume fraction at 1/4, 1/2, 3/4 | weft contacts "
        "min, median |"
    )
    print("|---|---|---|---:|---:|---:|---:|---|---|")
    for stem in STEMS:
        print(formed_row(stem, found[stem]))


if __name__ == "__main__":
    main()
