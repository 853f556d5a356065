"""Two-yarn twist and 4-step (track-and-column) braids of rectangular, L, T and I sections."""

from __future__ import annotations

from dataclasses import dataclass

from bwsd.program import render
from bwsd.program.render import Cell, Generated
from bwsd.twin.machine import Machine

SHAPES = ("rect", "L", "T", "I")
Block = tuple[int, int]  # (rows, cols) of a rectangular block of the section


def twist(
    turns: int = 4,
    *,
    pitch: float = 10.0,
    d_mat: float = 100.0,
    c_mat: float = 0.5,
    diameter: float = 1.0,
) -> Generated:
    """Two yarns in a 2 x 2 matrix wound round each other, one turn per four moves."""
    if turns < 1:
        raise ValueError("turns must be at least 1")
    machine = Machine(2, 2, pitch, pitch, d_mat, c_mat, diameter)
    command = " ".join(
        ["bwsd program twist", render.option("turns", turns), *render.machine_options(machine)]
    )
    title = f"Two-yarn twist, {turns} turns"
    turn = ["ROW 0:+1 1:-1", "COL 1:+1 0:-1", "ROW 1:-1 0:+1", "COL 0:-1 1:+1"]
    lines = [
        *render.header(title, command, machine),
        *render.fill_block(2, 2, [(0, 0), (1, 1)]),
        *render.repeat(turns, turn, "one turn: each yarn goes once round the square"),
    ]
    return Generated("twist", title, command, machine, "\n".join(lines) + "\n")


def section_cells(
    shape: str, rows: int = 2, cols: int = 2, flange: Block = (2, 6), web: Block = (4, 2)
) -> tuple[frozenset[Cell], set[int], set[int]]:
    """The body cells of a section (bounding box from (0, 0)) and its held rows and columns.

    rect: rows x cols. L: the web (a vertical leg) on top of the flange, both flush left.
    T: the flange on top, the web centred below. I: flange, centred web, flange. The held
    lines are those at the junctions: the web rows touching a flange and the flange
    columns flanking the web (docs/program.md explains why).
    """
    for name, (r, c) in (("body", (rows, cols)), ("flange", flange), ("web", web)):
        if r < 1 or c < 1:
            raise ValueError(f"{name} must be at least 1 x 1")
    if shape == "rect":
        return _block(0, 0, rows, cols), set(), set()
    (fr, fc), (wr, wc) = flange, web
    if shape == "L":
        if fc - wc < 2 or wr < 2:
            raise ValueError(
                "an L section needs a flange at least 2 cells wider than its"
                " web and a web of at least 2 rows"
            )
        return _block(0, 0, wr, wc) | _block(wr, 0, fr, fc), {wr - 1}, {wc}
    if shape not in ("T", "I"):
        raise ValueError(f"unknown shape {shape!r} (known: {', '.join(SHAPES)})")
    min_web = 2 if shape == "T" else 3
    if fc - wc < 4 or wr < min_web:
        raise ValueError(
            f"a {shape} section needs a flange at least 4 cells wider than its"
            f" web and a web of at least {min_web} rows"
        )
    off = (fc - wc) // 2
    cells = _block(0, 0, fr, fc) | _block(fr, off, wr, wc)
    held_cols = {off - 1, off + wc}
    if shape == "T":
        return cells, {fr}, held_cols
    return cells | _block(fr + wr, 0, fr, fc), {fr, fr + wr - 1}, held_cols


def _block(row: int, col: int, rows: int, cols: int) -> frozenset[Cell]:
    return frozenset((row + r, col + c) for r in range(rows) for c in range(cols))


@dataclass(frozen=True)
class BraidPlan:
    """Carriers and line directions of a 4-step braid in a matrix of ``rows`` x ``cols``.

    Step 1 shifts each row of ``row_dirs`` by its direction, step 2 each column of
    ``col_dirs``, steps 3 and 4 undo them in the same order. Body lines missing from the
    two maps are held: they never shift and carry no edge carrier.
    """

    rows: int
    cols: int
    body: frozenset[Cell]
    carriers: frozenset[Cell]
    row_dirs: dict[int, int]
    col_dirs: dict[int, int]


def _lines(body: frozenset[Cell], axis: int) -> dict[int, list[tuple[int, int]]]:
    """Body runs of every row (axis 0) or column (axis 1)."""
    members: dict[int, list[int]] = {}
    for cell in body:
        members.setdefault(cell[axis], []).append(cell[1 - axis])
    return {i: render.runs(v) for i, v in members.items()}


def _ends(runs: list[tuple[int, int]]) -> list[int]:
    return [e for lo, hi in runs for e in (lo - 1, hi + 1)]


def _conflicts(
    row_runs: dict[int, list[tuple[int, int]]],
    col_runs: dict[int, list[tuple[int, int]]],
    rows: set[int],
    cols: set[int],
) -> set[Cell]:
    """Cells where a shifted line's window ends on a shifted perpendicular line."""
    found = {(r, c) for r in rows for c in _ends(row_runs[r]) if c in cols}
    return found | {(r, c) for c in cols for r in _ends(col_runs[c]) if r in rows}


def plan_braid(
    cells: frozenset[Cell], held_rows: set[int] | None = None, held_cols: set[int] | None = None
) -> BraidPlan:
    """Place a section in a matrix with a one-cell margin and plan its 4-step braid.

    Every body line shifts except the held ones (given in the coordinates of ``cells``).
    Each shifted line gets one edge carrier per body run: at the run's low end when the
    line moves +1 in step 1 (odd matrix index), at its high end otherwise. Refused when a
    shifted line's window would end on a shifted perpendicular line (the cycle would then
    not bring every case back) or when a case could never move.
    """
    body = frozenset((r + 1, c + 1) for r, c in cells)
    row_runs, col_runs = _lines(body, 0), _lines(body, 1)
    rows = set(row_runs) - {r + 1 for r in held_rows or set()}
    cols = set(col_runs) - {c + 1 for c in held_cols or set()}
    clash = sorted(_conflicts(row_runs, col_runs, rows, cols))
    if clash:
        raise ValueError(
            f"cannot plan: row {clash[0][0]} and column {clash[0][1]} both shift"
            " and one ends its run on the other"
        )
    stuck = sorted(cell for cell in body if cell[0] not in rows and cell[1] not in cols)
    if stuck:
        raise ValueError(f"section too thin: the case in {stuck[0]} could never move")
    row_dirs = {r: 1 if r % 2 else -1 for r in sorted(rows)}
    col_dirs = {c: 1 if c % 2 else -1 for c in sorted(cols)}
    edges = set()
    for dirs, runs, axis in ((row_dirs, row_runs, 0), (col_dirs, col_runs, 1)):
        for i, d in dirs.items():
            for lo, hi in runs[i]:
                end = lo - 1 if d > 0 else hi + 1
                edges.add((i, end) if axis == 0 else (end, i))
    size_r = max(r for r, _ in body) + 2
    size_c = max(c for _, c in body) + 2
    return BraidPlan(size_r, size_c, body, frozenset(body | edges), row_dirs, col_dirs)


def _cycle(plan: BraidPlan, takeup: float) -> list[str]:
    rows, cols = plan.row_dirs.items(), plan.col_dirs.items()
    steps = [
        ("row", [(i, d) for i, d in rows]),
        ("col", [(i, d) for i, d in cols]),
        ("row", [(i, -d) for i, d in rows]),
        ("col", [(i, -d) for i, d in cols]),
    ]
    body = [render.shift(axis, moves) for axis, moves in steps if moves]
    return [*body, f"TAKEUP {render.num(takeup)}"]


def braid4(
    rows: int = 2,
    cols: int = 2,
    cycles: int = 10,
    *,
    shape: str = "rect",
    flange: Block = (2, 6),
    web: Block = (4, 2),
    takeup: float = 3.0,
    pitch: float = 10.0,
    d_mat: float = 150.0,
    c_mat: float = 0.4,
    diameter: float = 1.5,
) -> Generated:
    """A 4-step braid of a rectangular (rows x cols) or L, T, I (flange, web) section."""
    if cycles < 1:
        raise ValueError("cycles must be at least 1")
    if takeup <= 0:
        raise ValueError("take-up must be positive")
    plan = plan_braid(*section_cells(shape, rows, cols, flange, web))
    machine = Machine(plan.rows, plan.cols, pitch, pitch, d_mat, c_mat, diameter)
    if shape == "rect":
        what = [render.option("rows", rows), render.option("cols", cols)]
        title = f"4-step braid, {rows} x {cols} body"
    else:
        what = [
            render.option("shape", shape),
            render.option("flange", _size(flange)),
            render.option("web", _size(web)),
        ]
        title = f"4-step braid, {shape} section, flange {_size(flange)}, web {_size(web)}"
    title += f", {len(plan.carriers)} carriers, {cycles} cycles"
    command = " ".join(
        [
            "bwsd program braid4",
            *what,
            render.option("cycles", cycles),
            render.option("takeup", takeup),
            *render.machine_options(machine),
        ]
    )
    held = _held_note(plan)
    lines = [
        *render.header(title, command, machine),
        *held,
        *render.fill_block(plan.rows, plan.cols, plan.carriers),
        *render.repeat(
            cycles, _cycle(plan, takeup), "rows, columns, rows back, columns back, take-up"
        ),
    ]
    return Generated("braid4", title, command, machine, "\n".join(lines) + "\n")


def _size(block: Block) -> str:
    return f"{block[0]}x{block[1]}"


def _held_note(plan: BraidPlan) -> list[str]:
    rows = sorted({r for r, _ in plan.body} - set(plan.row_dirs))
    cols = sorted({c for _, c in plan.body} - set(plan.col_dirs))
    if not rows and not cols:
        return []
    listed = [", ".join(map(str, v)) or "none" for v in (rows, cols)]
    return [f"# held (never shifted): rows {listed[0]}; columns {listed[1]}"]
