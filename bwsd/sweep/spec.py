"""A sweep's spec (TOML): where its programs come from and which values its parameters take.

Read once and checked whole before anything runs; every error names the table and key
(``[vary.takeup]``). The candidates it lists are the same, with the same ids, in every run.
"""

from __future__ import annotations

import hashlib
import inspect
import itertools
import math
import tomllib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import Any

from bwsd.errors import BwsdError
from bwsd.program.generators import GENERATORS
from bwsd.program.parser import parse_program
from bwsd.sweep.candidate import Candidate, GeneratorSource, ProgramSource, Source, candidate_id
from bwsd.sweep.errors import SpecError

SAMPLES = ("grid", "random")
MAX_CANDIDATES = 1_000_000  # each is a row in memory at the end: about a kB
# The keys of a fixed program's config a sweep may change ("pitch" sets pitch_x and pitch_y).
CONFIG_PARAMS = {
    "rows": "int",
    "cols": "int",
    "pitch": "float",
    "pitch_x": "float",
    "pitch_y": "float",
    "d_mat": "float",
    "c_mat": "float",
    "diameter": "float",
}
SWEEP_KEYS = ("generator", "program", "config", "sample", "count", "seed", "relax")


@dataclass(frozen=True)
class Range:
    """A random parameter drawn uniformly from [low, high] (integers: both ends included)."""

    low: float
    high: float


Values = list[Any] | Range


@dataclass(frozen=True)
class Spec:
    """A checked spec: the source, the kinds of its parameters and their values."""

    path: str
    source: Source
    kinds: Mapping[str, str]  # every parameter the source takes -> its kind
    fixed: Mapping[str, Any]
    vary: Mapping[str, Values]
    sample: str = "grid"
    count: int = 0
    seed: int = 0
    relax: bool = False  # measure each candidate's relaxed preform (docs/relax.md)

    def candidates(self) -> list[Candidate]:
        """Every candidate, in order, each once (a random draw repeated is run once)."""
        out: list[Candidate] = []
        seen: set[str] = set()
        for values in self._points():
            params = {**self.fixed, **values}
            columns = {name: column(value, self.kinds[name]) for name, value in params.items()}
            cid = candidate_id(self.source, columns, self.relax)
            if cid not in seen:
                seen.add(cid)
                out.append(Candidate(len(out), cid, self.source, params, columns, self.relax))
        return out

    def _points(self) -> Iterator[dict[str, Any]]:
        names = list(self.vary)
        if self.sample == "grid":
            lists = [self.vary[n] for n in names]
            for combo in itertools.product(*lists):  # type: ignore[arg-type]
                yield dict(zip(names, combo, strict=True))
            return
        import numpy as np

        rng = np.random.default_rng(self.seed)
        for _ in range(self.count):
            yield {n: draw(rng, self.vary[n], self.kinds[n]) for n in names}


def draw(rng: Any, values: Values, kind: str) -> Any:
    """One random value: a choice from a list, or uniform in a range."""
    if isinstance(values, Range):
        if kind == "int":
            return int(rng.integers(int(values.low), int(values.high), endpoint=True))
        return float(rng.uniform(values.low, values.high))
    return values[int(rng.integers(len(values)))]


def column(value: Any, kind: str) -> Any:
    """A parameter as the result table writes it: a block ``2x6``, angles ``0,90,45``."""
    if kind == "block":
        return f"{value[0]}x{value[1]}"
    if kind == "ints":
        return ",".join(str(v) for v in value)
    return value


def generator_kinds(kind: str) -> dict[str, str]:
    """The parameters of a generator and their kinds, from its defaults."""
    out = {}
    for name, param in inspect.signature(GENERATORS[kind]).parameters.items():
        default = param.default
        if isinstance(default, bool):
            out[name] = "bool"
        elif isinstance(default, int | float | str):
            out[name] = type(default).__name__
        else:  # a tuple: a block (rows, cols) or the weft angles
            out[name] = "block" if name in ("flange", "web") else "ints"
    return out


class _Reader:
    """Reads one spec file; every error names the file, table and key."""

    def __init__(self, path: str) -> None:
        self.path = path

    def error(self, message: str, table: str = "", key: str = "") -> SpecError:
        return SpecError(message, path=self.path, table=table, key=key)

    def table(self, data: Mapping[str, Any], name: str) -> dict[str, Any]:
        raw = data.get(name, {})
        if not isinstance(raw, dict):
            raise self.error("must be a table", name)
        return raw

    def value(self, raw: Any, kind: str, table: str, key: str) -> Any:
        """A parameter's value, checked against its kind; integers are taken for floats."""
        if kind == "float" and isinstance(raw, int | float | Decimal) and not isinstance(raw, bool):
            value = float(raw)
            if not math.isfinite(value):
                raise self.error(f"must be a finite number, got {raw!r}", table, key)
            return value
        if kind == "int" and isinstance(raw, int) and not isinstance(raw, bool):
            return raw
        if kind in ("bool", "str") and type(raw).__name__ == kind:
            return raw
        if kind == "block":
            return self._block(raw, table, key)
        if kind == "ints" and isinstance(raw, list) and raw and all(type(v) is int for v in raw):
            return tuple(raw)
        wanted = {
            "float": "a number",
            "int": "an integer",
            "bool": "true or false",
            "str": "a string",
            "ints": "a list of integers like [0, 90]",
        }
        raise self.error(f"must be {wanted[kind]}, got {raw!r}", table, key)

    def _block(self, raw: Any, table: str, key: str) -> tuple[int, int]:
        if isinstance(raw, str):
            rows, sep, cols = raw.lower().partition("x")
            if sep and rows.isdigit() and cols.isdigit():
                return int(rows), int(cols)
        elif isinstance(raw, list) and len(raw) == 2 and all(type(v) is int for v in raw):
            return raw[0], raw[1]
        raise self.error(f'must be a block like "2x6" or [2, 6], got {raw!r}', table, key)

    def values(self, raw: Any, kind: str, key: str, sample: str) -> Values:
        """A varied parameter: a list of values, or (random only) a table {low, high}."""
        if isinstance(raw, dict):
            return self._range(raw, kind, key, sample)
        if not isinstance(raw, list) or not raw:
            raise self.error("must be a non-empty list of values", "vary", key)
        if kind in ("block", "ints") and not all(isinstance(v, list | str) for v in raw):
            raise self.error("must be a list of values, each a list or text", "vary", key)
        out = [self.value(v, kind, "vary", key) for v in raw]
        if len(set(out)) != len(out):
            raise self.error("lists a value twice", "vary", key)
        return out

    def _range(self, raw: dict[str, Any], kind: str, key: str, sample: str) -> Range:
        if sample != "random":
            raise self.error(
                "a grid needs a list of values ({low, high} is for random samples)", "vary", key
            )
        if kind not in ("int", "float") or set(raw) != {"low", "high"}:
            raise self.error(
                "a range is {low = ..., high = ...} of a number parameter", "vary", key
            )
        low, high = (self.value(raw[k], kind, "vary", key) for k in ("low", "high"))
        if not low <= high:
            raise self.error(f"low ({low}) must not exceed high ({high})", "vary", key)
        return Range(low, high)


def _source(reader: _Reader, sweep: dict[str, Any], folder: Path) -> tuple[Source, dict[str, str]]:
    generator, program = sweep.get("generator"), sweep.get("program")
    if (generator is None) == (program is None):
        raise reader.error("name either a generator or a program (with its config)", "sweep")
    if generator is not None:
        if generator not in GENERATORS:
            raise reader.error(
                f"unknown generator {generator!r} (known: {', '.join(GENERATORS)})",
                "sweep",
                "generator",
            )
        if "config" in sweep:
            raise reader.error("a generator writes its own config", "sweep", "config")
        return GeneratorSource(generator), generator_kinds(generator)
    if not isinstance(program, str) or not isinstance(sweep.get("config"), str):
        raise reader.error("a program needs a config: both are file names", "sweep", "config")
    return _program_source(reader, folder / program, folder / sweep["config"]), CONFIG_PARAMS


def _program_source(reader: _Reader, program: Path, config: Path) -> ProgramSource:
    from bwsd.config import load_config

    try:
        text = program.read_text(encoding="utf-8")
        raw = config.read_bytes()
    except OSError as exc:
        raise reader.error(f"cannot read {exc.filename}: {exc.strerror}", "sweep") from None
    except UnicodeDecodeError:
        raise reader.error(f"{program} is not UTF-8 text", "sweep", "program") from None
    try:
        load_config(config)  # the config as it stands must load
        data = tomllib.loads(raw.decode("utf-8"), parse_float=Decimal)
        parse_program(text, str(program))
    except BwsdError as exc:
        raise reader.error(str(exc), "sweep") from None
    digest = hashlib.sha256(raw).hexdigest()
    return ProgramSource(str(program), text, str(config), data, digest)


def _sample(reader: _Reader, sweep: dict[str, Any]) -> tuple[str, int, int]:
    sample = sweep.get("sample", "grid")
    if sample not in SAMPLES:
        raise reader.error(
            f"must be one of {', '.join(SAMPLES)}, got {sample!r}", "sweep", "sample"
        )
    if sample == "grid":
        for key in ("count", "seed"):
            if key in sweep:
                raise reader.error("only a random sample has it", "sweep", key)
        return sample, 0, 0
    count, seed = sweep.get("count"), sweep.get("seed", 0)
    if type(count) is not int or not 1 <= count <= MAX_CANDIDATES:
        raise reader.error(f"must be an integer in [1, {MAX_CANDIDATES}]", "sweep", "count")
    if type(seed) is not int or seed < 0:
        raise reader.error("must be a non-negative integer", "sweep", "seed")
    return sample, count, seed


def _relax(reader: _Reader, sweep: dict[str, Any]) -> bool:
    relax = sweep.get("relax", False)
    if type(relax) is not bool:
        raise reader.error(f"must be true or false, got {relax!r}", "sweep", "relax")
    return relax


def _check_tables(reader: _Reader, data: Mapping[str, Any]) -> dict[str, Any]:
    for name in data:
        if name not in ("sweep", "fixed", "vary"):
            raise reader.error("unknown table (known: sweep, fixed, vary)", name)
    if "sweep" not in data:
        raise reader.error("missing table", "sweep")
    sweep = reader.table(data, "sweep")
    for key in sweep:
        if key not in SWEEP_KEYS:
            raise reader.error(f"unknown key (known: {', '.join(SWEEP_KEYS)})", "sweep", key)
    return sweep


def parse_spec(data: Mapping[str, Any], path: str = "<spec>", folder: Path = Path()) -> Spec:
    """Check an already-parsed spec; file names in it are relative to ``folder``."""
    reader = _Reader(path)
    sweep = _check_tables(reader, data)
    source, kinds = _source(reader, sweep, folder)
    sample, count, seed = _sample(reader, sweep)
    relax = _relax(reader, sweep)
    fixed, vary = reader.table(data, "fixed"), reader.table(data, "vary")
    for table, names in (("fixed", fixed), ("vary", vary)):
        for name in names:
            if name not in kinds:
                raise reader.error(f"not a parameter here (known: {', '.join(kinds)})", table, name)
    for name in vary:
        if name in fixed:
            raise reader.error("is also in [fixed]", "vary", name)
    checked_fixed = {n: reader.value(v, kinds[n], "fixed", n) for n, v in fixed.items()}
    checked_vary = {n: reader.values(v, kinds[n], n, sample) for n, v in vary.items()}
    if "diameter" in fixed or "diameter" in vary:
        _check_program_diameter(reader, source, "fixed" if "diameter" in fixed else "vary")
    if sample == "grid":
        size = math.prod(len(v) for v in checked_vary.values() if isinstance(v, list))
        if size > MAX_CANDIDATES:
            raise reader.error(f"{size} candidates: at most {MAX_CANDIDATES}", "vary")
    return Spec(path, source, kinds, checked_fixed, checked_vary, sample, count, seed, relax)


def _check_program_diameter(reader: _Reader, source: Source, table: str) -> None:
    """A program's YARN statement overrides the config's diameter: changing it does nothing."""
    if isinstance(source, ProgramSource) and parse_program(source.text).diameter is not None:
        raise reader.error(
            f"the program {source.name} sets its own YARN diameter, which "
            "overrides the config's: remove that line to sweep it",
            table,
            "diameter",
        )


def load_spec(path: str | Path) -> Spec:
    """Read and check a spec file."""
    name = str(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise SpecError(f"cannot read: {exc.strerror}", path=name) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SpecError(f"not valid TOML: {exc}", path=name) from None
    return parse_spec(data, name, Path(path).parent)
