"""One candidate of a sweep: generated (or configured), simulated, measured, as one row.

Pure and self-contained, so that a Dask worker runs it as it is: no Dask, no files, no
daemon. A candidate the generator, the validation or the twin refuses is a row with
``status = "refused"``, the ``stage`` that refused it and the ``reason``.
"""

from __future__ import annotations

import functools
import hashlib
import json
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from bwsd.config import parse_config
from bwsd.errors import BwsdError, TwinError
from bwsd.export.arrays import Arrays
from bwsd.export.formed import takeups_of
from bwsd.export.metrics import metrics, section
from bwsd.export.mixing import NamedSection, ZoneVisits, section_header, simulate_with_visits
from bwsd.program.generators import GENERATORS
from bwsd.program.parser import MAX_INSTRUCTIONS, parse_program_with_positions
from bwsd.program.validate import validate
from bwsd.twin import Machine, Program, Twin, simulate

Row = dict[str, Any]
# Columns every row has, in this order; the parameters come after ``index``, the metrics
# after ``reason``, and ``seconds`` (the candidate's own run time) last.
HEAD = ("id", "index")
STATUS = ("status", "stage", "reason")


@dataclass(frozen=True)
class GeneratorSource:
    """Candidates written by a ``bwsd program`` generator."""

    kind: str

    def fingerprint(self) -> dict[str, str]:
        return {"generator": self.kind}


@dataclass(frozen=True)
class ProgramSource:
    """One fixed program, on its config with some keys of [machine] and [yarn] changed."""

    name: str
    text: str
    config_name: str
    config: Mapping[str, Any] = field(repr=False)
    config_digest: str = ""

    @functools.cached_property
    def program_digest(self) -> str:
        """The program's hash, taken once (a spec asks for it at every candidate)."""
        return hashlib.sha256(self.text.encode()).hexdigest()

    def fingerprint(self) -> dict[str, str]:
        return {"program": self.program_digest, "config": self.config_digest}


Source = GeneratorSource | ProgramSource


@dataclass(frozen=True)
class Candidate:
    """A point of the sweep: ``params`` as the generator (or config) takes them, ``columns``
    as the result table writes them (a block as ``2x6``, angles as ``0,90``)."""

    index: int
    id: str
    source: Source
    params: Mapping[str, Any]
    columns: Mapping[str, Any]


def candidate_id(source: Source, columns: Mapping[str, Any]) -> str:
    """A stable id: the same source and parameter values give the same id in every run."""
    text = json.dumps(
        {"source": source.fingerprint(), "params": dict(columns)}, sort_keys=True, allow_nan=False
    )
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class Refused(Exception):
    """A candidate refused at ``stage``, for ``reason``."""

    def __init__(self, stage: str, reason: str) -> None:
        super().__init__(reason)
        self.stage = stage
        self.reason = reason


@contextmanager
def stage(name: str, *also: type[Exception]) -> Iterator[None]:
    """Turn a user-facing error raised in the block into a refusal at stage ``name``."""
    caught: tuple[type[Exception], ...] = (BwsdError, *also)
    try:
        yield
    except caught as exc:
        raise Refused(name, str(exc)) from exc


def _configured(source: ProgramSource, params: Mapping[str, Any]) -> Machine:
    """The source's config with the candidate's keys changed, validated as a config file."""
    data = {table: dict(values) for table, values in source.config.items()}
    machine = data.setdefault("machine", {})
    for name, value in params.items():
        if name == "pitch":
            machine["pitch_x"] = machine["pitch_y"] = value
        elif name == "diameter":
            data.setdefault("yarn", {})["diameter"] = value
        else:
            machine[name] = value
    config = parse_config(data, source.config_name)
    return config.machine


def _build(candidate: Candidate) -> tuple[Machine, str, str]:
    """The candidate's machine, program text and program name."""
    source = candidate.source
    if isinstance(source, GeneratorSource):
        with stage("generate", ValueError):
            generated = GENERATORS[source.kind](**candidate.params)
        return generated.machine, generated.program, f"<{source.kind}>"
    with stage("config", ValueError):
        return _configured(source, candidate.params), source.text, source.name


def _run(
    machine: Machine, text: str, name: str
) -> tuple[Twin, Program, ZoneVisits | None, NamedSection | None]:
    """Parse, validate and simulate; the carriers' zones too when the program names its section."""
    with stage("program"):
        program, positions = parse_program_with_positions(text, name, MAX_INSTRUCTIONS)
        named = section_header(text, name)
    with stage("validate"):
        validate(program, machine, name, positions)
    try:
        if named is None or any(not machine.inside(*c) for c in named.section.cells):
            return simulate(machine, program), program, None, None
        twin, visits = simulate_with_visits(machine, program, named.section)
    except TwinError as exc:
        line = program.line_of(exc.instruction)
        raise Refused("simulate", f"{name}:{line}: {exc}" if line else str(exc)) from exc
    return twin, program, visits, named


def measure(candidate: Candidate) -> Row:
    """The metrics of one candidate as flat columns; a refusal raises ``Refused``."""
    machine, text, name = _build(candidate)
    twin, program, visits, named = _run(machine, text, name)
    sk = twin.skeleton()
    with stage("metrics"):
        arrays = Arrays.of(sk)
        band = section(sk, arrays)
        z = None if band is None else (band["z"][0] + band["z"][1]) / 2
        found = metrics(
            sk,
            program.cycle_length,
            takeups=takeups_of(program),
            z=z,
            named=named,
            visits=visits,
            arrays=arrays,
        )
    return flatten(found, z)


def flatten(found: Mapping[str, Any], z: float | None) -> Row:
    """``bwsd metrics`` output (docs/exports.md) as one row's columns (docs/sweeps.md)."""
    band = found["section"] or {}
    cycles = found["cycles"]
    groups = found["groups"]
    row: Row = {
        "instructions": found["instructions"],
        "takeup_total": found["takeup"],
        "yarns_warp": found["yarns"]["warp"],
        "yarns_weft": found["yarns"]["weft"],
        "nodes": found["nodes"],
        "contacts": found["contacts"],
        "cycle_length": cycles["length"],
        "contacts_per_cycle": cycles["mean"],
        "contacts_per_cycle_min": cycles["min"],
        "contacts_per_cycle_max": cycles["max"],
        "groups": groups["count"],
        "group_largest": groups["sizes"][0] if groups["sizes"] else 0,
        "unconnected": found["unconnected"]["count"],
        "width": band.get("width"),
        "thickness": band.get("thickness"),
    }
    row.update(_formed(found))
    for family, numbers in found["skeleton_angles"].items():
        row[f"skeleton_angle_{family}"] = numbers["mean"]
        row[f"skeleton_angle_{family}_std"] = numbers["std"]
    row.update(_wefts(found["wefts"]))
    row.update(_footprint(found["footprint"], z))
    row.update(_mixing(found["mixing"]))
    return row


def _formed(found: Mapping[str, Any]) -> Row:
    """The formed zone, its angles per family (all, interior, surface), interpenetration and
    yarn volume fraction; empty where there is no formed zone."""
    zone = found["formed"]
    cycles, z = zone["cycles"] or (None, None), zone["z"] or (None, None)
    row: Row = {
        "formed_z_low": z[0],
        "formed_z_high": z[1],
        "formed_first_cycle": cycles[0],
        "formed_last_cycle": cycles[1],
    }
    for family, parts in (found["angles"] or {}).items():
        row[f"angle_{family}"] = parts["all"]["mean"]
        row[f"angle_{family}_std"] = parts["all"]["std"]
        row[f"angle_{family}_interior"] = parts["interior"]["mean"]
        row[f"angle_{family}_surface"] = parts["surface"]["mean"]
    for where, prefix in (("formed", "overlap"), ("skeleton", "skeleton_overlap")):
        measured = found["interpenetration"][where]
        row[prefix] = measured["all"]["share"]
        row[f"{prefix}_worst"] = measured["all"]["worst"]
        row[f"{prefix}_p95"] = measured["all"]["p95"]
        for family, numbers in measured.items():
            if family != "all":
                row[f"{prefix}_{family}"] = numbers["share"]
    fractions = [h["fraction"] for h in found["volume_fraction"] or () if h["fraction"]]
    row["volume_fraction"] = sum(fractions) / len(fractions) if fractions else None
    row["volume_fraction_min"] = min(fractions, default=None)
    row["volume_fraction_max"] = max(fractions, default=None)
    return row


def _wefts(found: Mapping[str, Any]) -> Row:
    spread = found["contacts"]
    return {
        "wefts_loose": len(found["loose"]) if found["count"] else None,
        "weft_contacts_min": spread["min"] if spread else None,
        "weft_contacts_median": spread["median"] if spread else None,
    }


def _footprint(found: Mapping[str, Any] | None, z: float | None) -> Row:
    measured = found["measured"] if found else None
    return {
        "footprint_z": z,
        "crossings": found["crossings"] if found else None,
        "footprint_area": float(measured["area"]) if measured else None,
        "footprint_ratio": found["ratio"] if found else None,
        "footprint_coverage": found["coverage"] if found else None,
        "footprint_outside": found["outside"] if found else None,
    }


def _mixing(found: Mapping[str, Any] | None) -> Row:
    return {
        "section": found["section"] if found else None,
        "mixed_carriers": found["complete"] if found else None,
        "unmixed_carriers": found["incomplete"] if found else None,
        "mixed_by_cycle": found["k"] if found else None,
    }


def evaluate(candidate: Candidate) -> Row:
    """The candidate's row: its parameters, its status and, when it ran, its metrics."""
    start = time.perf_counter()
    row: Row = {"id": candidate.id, "index": candidate.index, **candidate.columns}
    try:
        found = measure(candidate)
    except Refused as refused:
        row.update(status="refused", stage=refused.stage, reason=refused.reason)
    else:
        row.update(status="ok", stage=None, reason=None, **found)
    row["seconds"] = time.perf_counter() - start
    return row


def evaluate_batch(batch: list[Candidate]) -> list[Row]:
    """The rows of a batch of candidates, in order: what a Dask task runs."""
    return [evaluate(candidate) for candidate in batch]
