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
import tomllib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from decimal import Decimal
from typing import TYPE_CHECKING, Any

from bwsd.config import Config, parse_config
from bwsd.errors import BwsdError, TwinError
from bwsd.export.arrays import Arrays
from bwsd.export.formed import takeups_of
from bwsd.export.metrics import metrics, section
from bwsd.export.mixing import NamedSection, ZoneVisits, section_header, simulate_with_visits
from bwsd.program.generators import GENERATORS
from bwsd.program.parser import MAX_INSTRUCTIONS, parse_program_with_positions
from bwsd.program.validate import validate
from bwsd.twin import Machine, Program, Twin, simulate

if TYPE_CHECKING:
    from bwsd.relax import Options

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
    relax: bool = False  # measure the relaxed preform (the spec's ``relax = true``)


def candidate_id(source: Source, columns: Mapping[str, Any], relax: bool = False) -> str:
    """A stable id: the same source and parameter values give the same id in every run; a
    relaxed candidate's differs from the same candidate's without relaxation."""
    key: dict[str, Any] = {"source": source.fingerprint(), "params": dict(columns)}
    if relax:  # only then, so that the ids of sweeps without it stay as they were
        key["relax"] = True
    text = json.dumps(key, sort_keys=True, allow_nan=False)
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


def _configured(source: ProgramSource, params: Mapping[str, Any]) -> Config:
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
    return parse_config(data, source.config_name)


@dataclass(frozen=True)
class Built:
    """A candidate ready to run: its machine, program text and name, and its config's
    relaxation options (None unless the candidate is relaxed)."""

    machine: Machine
    text: str
    name: str
    relax: Options | None = None


def _build(candidate: Candidate) -> Built:
    """The candidate's machine, program and, when relaxed, its config's tensions."""
    source = candidate.source
    if isinstance(source, GeneratorSource):
        with stage("generate", ValueError):
            generated = GENERATORS[source.kind](**candidate.params)
        name = f"<{source.kind}>"
        options = None
        if candidate.relax:  # the config the generator writes beside its program
            data = tomllib.loads(generated.config_toml(), parse_float=Decimal)
            with stage("config"):
                options = _options(parse_config(data, name))
        return Built(generated.machine, generated.program, name, options)
    with stage("config", ValueError):
        config = _configured(source, candidate.params)
    return Built(
        config.machine, source.text, source.name, _options(config) if candidate.relax else None
    )


def _options(config: Config) -> Options:
    from bwsd.relax.cli import options_from

    return options_from(config)


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
    """The metrics of one candidate as flat columns (of its relaxed preform when the
    candidate is relaxed, and the solver's figures after them); a refusal raises
    ``Refused``."""
    built = _build(candidate)
    twin, program, visits, named = _run(built.machine, built.text, built.name)
    sk = twin.skeleton()
    added: Mapping[str, Any] | None = None
    if built.relax is not None:  # as `bwsd metrics --relaxed` does
        from bwsd.relax.cli import relaxed_metrics

        sk, added = relaxed_metrics(sk, built.relax)
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
    row = flatten(found, z)
    if added is not None:
        row.update(relaxed_columns(added))
    return row


def relaxed_columns(added: Mapping[str, Any]) -> Row:
    """The solver's figures and the weft crimp (`bwsd metrics --relaxed`) as columns."""
    solver, crimp = added["relaxed"], added["crimp"]
    return {
        "relax_separate_steps": solver["separate_steps"],
        "relax_steps": solver["steps"],
        "relax_rejected_steps": solver["rejected_steps"],
        "relax_added_nodes": solver["added_nodes"],
        "relax_tension_length_twin": solver["tension_length"]["twin"],
        "relax_tension_length": solver["tension_length"]["relaxed"],
        "relax_worst_overlap": solver["worst_overlap"],
        "relax_worst_overlap_share": solver["worst_overlap_share"],
        "relax_force_residual": solver["force_residual"],
        "relax_sides_kept": solver["sides"]["kept"],
        "relax_sides_told": solver["sides"]["told"],
        "relax_seconds": solver["seconds"],
        "weft_crimp": crimp["mean"],
        "weft_crimp_max": crimp["max"],
    }


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
