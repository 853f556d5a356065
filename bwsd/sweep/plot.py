"""`bwsd sweep plot`: a metric against a parameter, one line per value of another (matplotlib).

Refused candidates and empty values are left out. Where several candidates share an x and
a hue value (other parameters varied too), the line goes through their mean and the title
says how many candidates a point stands for at most.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from bwsd.extras import needs
from bwsd.sweep.errors import MATPLOTLIB, PYARROW, SweepError

Row = Mapping[str, Any]
MM = (
    "takeup",
    "pitch",
    "pitch_x",
    "pitch_y",
    "d_mat",
    "diameter",
    "width",
    "thickness",
    "takeup_total",
    "footprint_z",
    "formed_z_low",
    "formed_z_high",
    "overlap_worst",
    "overlap_p95",
    "skeleton_overlap_worst",
    "skeleton_overlap_p95",
)


def axis_label(column: str) -> str:
    """An axis label: the column's name and its unit, when it has one."""
    if column in MM:
        return f"{column} (mm)"
    if column.startswith(("angle_", "skeleton_angle_")):
        return f"{column} (degrees)"
    if column in ("footprint_area", "footprint_outside"):
        return f"{column} (mm²)"
    return f"{column} (s)" if column == "seconds" else column


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def check_columns(rows: Sequence[Row], names: Mapping[str, str | None]) -> None:
    """Refuse an option naming no column, or an axis whose column holds no numbers."""
    known = list(rows[0]) if rows else []
    for option, name in names.items():
        if name is not None and name not in known:
            raise SweepError(f"{option} {name}: no such column (columns: {', '.join(known)})")
    for option in ("--x", "--y"):
        name = names[option] or ""
        values = [row[name] for row in rows if row.get("status") == "ok"]
        if not any(_number(v) for v in values):
            raise SweepError(f"{option} {name}: the column holds no numbers to plot")


def series(
    rows: Sequence[Row], x: str, y: str, hue: str | None
) -> dict[Any, list[tuple[float, float, int]]]:
    """Per hue value (None without --hue): the points (x, mean y, candidates), by x."""
    groups: dict[Any, dict[float, list[float]]] = defaultdict(lambda: defaultdict(list))
    for row in rows:
        if row.get("status") == "ok" and _number(row[x]) and _number(row[y]):
            groups[row[hue] if hue else None][float(row[x])].append(float(row[y]))
    return {
        key: [(px, sum(ys) / len(ys), len(ys)) for px, ys in sorted(points.items())]
        for key, points in sorted(groups.items(), key=lambda item: str(item[0]))
    }


def figure(rows: Sequence[Row], x: str, y: str, hue: str | None = None) -> Any:
    """The figure: one line with markers per hue value, axes named after the columns."""
    with needs(MATPLOTLIB, "bwsd sweep plot", SweepError):
        from matplotlib.figure import Figure
    check_columns(rows, {"--x": x, "--y": y, "--hue": hue})
    fig = Figure(figsize=(7.0, 4.5), dpi=120, layout="constrained")
    ax = fig.add_subplot()
    lines = series(rows, x, y, hue)
    for key, points in lines.items():
        label = None if hue is None else f"{key}"
        ax.plot([p[0] for p in points], [p[1] for p in points], marker="o", label=label)
    ax.set_xlabel(axis_label(x))
    ax.set_ylabel(axis_label(y))
    ax.grid(True, alpha=0.3)
    most = max((p[2] for points in lines.values() for p in points), default=1)
    title = f"{y} against {x}" + (f", by {hue}" if hue else "")
    ax.set_title(title + (f" (mean of up to {most} candidates a point)" if most > 1 else ""))
    if hue is not None:
        ax.legend(title=hue)
    return fig


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of a sweep's Parquet (or CSV) output."""
    with needs(PYARROW, "bwsd sweep plot", SweepError):
        import pyarrow.csv as pcsv
        import pyarrow.parquet as pq
    try:
        table = pcsv.read_csv(path) if path.suffix.lower() == ".csv" else pq.read_table(path)
    except (OSError, ValueError) as exc:
        raise SweepError(f"{path}: cannot read sweep results: {exc}") from None
    rows: list[dict[str, Any]] = table.to_pylist()
    return rows


def plot(results: Path, output: Path, x: str, y: str, hue: str | None = None) -> int:
    """Write the PNG; returns the number of lines drawn."""
    fig = figure(read_rows(results), x, y, hue)
    try:
        fig.savefig(output)
    except OSError as exc:
        raise SweepError(f"cannot write {output}: {exc.strerror or exc}") from None
    return len(fig.axes[0].get_lines())
