"""Shared relaxations of the shipped examples (each relaxed once per test run)."""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path
from typing import Any

from bwsd.export.arrays import Arrays
from bwsd.export.cli import simulate_program
from bwsd.export.formed import Zone, find_zone, pieces, takeups_of
from bwsd.export.metrics import metrics
from bwsd.export.overlap import interpenetration
from bwsd.relax import Options, Relaxed, relax
from bwsd.twin.instructions import Program
from bwsd.twin.skeleton import SkeletonData

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ["twist", "braid-2x2", "weave-U", "paper-U", "braid-L", "paper-L"]


@cache
def simulated(name: str) -> tuple[SkeletonData, Program]:
    """The twin's skeleton of a shipped example, and its program."""
    return simulate_program(
        str(ROOT / "config" / f"{name}.toml"), str(ROOT / "examples" / f"{name}.bws")
    )


def twin_of(name: str) -> SkeletonData:
    """The twin's skeleton of a shipped example."""
    return simulated(name)[0]


def metrics_of(name: str, sk: SkeletonData) -> dict[str, Any]:
    """The preform metrics of ``sk``, a skeleton of the example ``name`` (bwsd metrics)."""
    program = simulated(name)[1]
    return metrics(sk, program.cycle_length, takeups=takeups_of(program))


@cache
def relaxed_of(name: str) -> Relaxed:
    """The relaxed preform of a shipped example, with the solver's defaults."""
    return relax(twin_of(name), Options())


def overlap_share(sk: SkeletonData, within: float) -> float:
    """The share of the yarn length closer than ``within`` of one diameter to another yarn,
    by the metrics' own interpenetration measure (bwsd.export.overlap)."""
    narrowed = replace(sk, diameter=within * sk.diameter)
    arrays = Arrays.of(narrowed)
    zone = find_zone(arrays, max(sk.instructions, 1), None)
    found = interpenetration(arrays, pieces(arrays, zone))
    share = found["skeleton"]["all"]["share"]
    return float(share or 0.0)


__all__ = ["EXAMPLES", "ROOT", "Zone", "metrics_of", "overlap_share", "relaxed_of", "twin_of"]
