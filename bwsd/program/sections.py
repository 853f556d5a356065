"""Braided sections: their cells in the matrix and their zones (pure).

A section is the set of body cells a 4-step braid keeps full (its "main" cells), placed
in the matrix with a one-cell margin for the edge carriers. Shaped sections are built of
blocks, and their zones are what a carrier must travel through for the yarns to form one
preform (docs/program.md, "Shaped sections"):

- ``rect``: rows x cols; one zone, ``all``.
- ``L``: the flange (rows x cols) on top, the web (rows x cols) below it, flush left.
  Zones ``flange`` and ``web``, and ``junction``, the flange cells above the web.
- ``T``: the flange on top, the web centred below it. Zones ``wing-left``, ``junction``,
  ``wing-right`` and ``web``.
- ``I``: flange, centred web, flange. Zones ``top-left``, ``top-junction``, ``top-right``,
  ``web``, ``bottom-left``, ``bottom-junction``, ``bottom-right``.

A junction holds the cells shared by two blocks; a carrier must visit every other zone
(``required``). A written section ``L:2x6:4x2`` is shape, flange and web (``rect:3x4``: rows
and cols), placed at row 1, column 1 unless ``@ROW,COL`` follows.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

Cell = tuple[int, int]
Block = tuple[int, int]  # (rows, cols)
SHAPES = ("rect", "L", "T", "I")
WEAVE_SHAPES = ("rect", "U")  # of bwsd.program.weave, here for a parser that imports no twin
WEFT_ANGLES = (0, 90, 45, -45)  # braid-weave's default weft angles, layer by layer
MARGIN = 1  # the body's first row and column in the matrix: room for the edge carriers


@dataclass(frozen=True)
class Section:
    """A section's body cells and zones, in matrix coordinates.

    ``spec`` is its written form (``L:2x6:4x2``); ``zones`` maps each zone's name to its
    cells, and ``required`` names the zones every carrier must visit.
    """

    shape: str
    spec: str
    zones: dict[str, frozenset[Cell]]
    required: tuple[str, ...]

    @property
    def cells(self) -> frozenset[Cell]:
        """Every body cell."""
        return frozenset().union(*self.zones.values())

    def zone_of(self, cell: Cell) -> str | None:
        """The zone ``cell`` belongs to, or None (an edge or empty cell)."""
        for name, cells in self.zones.items():
            if cell in cells:
                return name
        return None

    @property
    def size(self) -> tuple[int, int]:
        """Rows and columns of the matrix that holds the section and its margin."""
        rows = max(r for r, _ in self.cells) + 1 + MARGIN
        cols = max(c for _, c in self.cells) + 1 + MARGIN
        return rows, cols


def _block(row: int, col: int, size: Block) -> frozenset[Cell]:
    return frozenset((row + r, col + c) for r in range(size[0]) for c in range(size[1]))


def _text(size: Block) -> str:
    return f"{size[0]}x{size[1]}"


def rect(rows: int, cols: int, at: Cell = (MARGIN, MARGIN)) -> Section:
    """A rows x cols rectangle."""
    _positive(("body", (rows, cols)))
    return Section("rect", f"rect:{rows}x{cols}", {"all": _block(*at, (rows, cols))}, ("all",))


def shaped(shape: str, flange: Block, web: Block, at: Cell = (MARGIN, MARGIN)) -> Section:
    """An L, T or I section of ``flange`` and ``web`` blocks (rows x cols each)."""
    _positive(("flange", flange), ("web", web))
    (fr, fc), (wr, wc) = flange, web
    r0, c0 = at
    spec = f"{shape}:{_text(flange)}:{_text(web)}"
    if shape == "L":
        if fc <= wc:
            raise ValueError("an L section needs a flange wider than its web")
        junction = _block(r0, c0, (fr, wc))
        zones = {
            "flange": _block(r0, c0, flange) - junction,
            "junction": junction,
            "web": _block(r0 + fr, c0, web),
        }
        return Section("L", spec, zones, ("flange", "web"))
    if shape not in ("T", "I"):
        raise ValueError(f"unknown shape {shape!r} (known: {', '.join(SHAPES)})")
    if fc <= wc or (fc - wc) % 2:
        raise ValueError(
            f"a {shape} section needs a flange wider than its web by an even "
            "number of cells (the web is centred)"
        )
    wing = (fc - wc) // 2
    zones = _flange_zones("", r0, c0, flange, wing, wc)
    zones["web"] = _block(r0 + fr, c0 + wing, web)
    if shape == "T":
        names = {"left": "wing-left", "junction": "junction", "right": "wing-right"}
        zones = {names.get(k, k): v for k, v in zones.items()}
        return Section("T", spec, zones, ("wing-left", "wing-right", "web"))
    top = {f"top-{k}": v for k, v in zones.items() if k != "web"}
    bottom = _flange_zones("bottom-", r0 + fr + wr, c0, flange, wing, wc)
    zones = {**top, "web": zones["web"], **bottom}
    required = ("top-left", "top-right", "web", "bottom-left", "bottom-right")
    return Section("I", spec, zones, required)


def _flange_zones(
    prefix: str, row: int, col: int, flange: Block, wing: int, web_cols: int
) -> dict[str, frozenset[Cell]]:
    rows = flange[0]
    return {
        f"{prefix}left": _block(row, col, (rows, wing)),
        f"{prefix}junction": _block(row, col + wing, (rows, web_cols)),
        f"{prefix}right": _block(row, col + wing + web_cols, (rows, wing)),
    }


def _positive(*blocks: tuple[str, Block]) -> None:
    for name, (r, c) in blocks:
        if r < 1 or c < 1:
            raise ValueError(f"{name} must be at least 1 x 1")


_SPEC = re.compile(
    r"(rect|L|T|I):(\d{1,4})x(\d{1,4})(?::(\d{1,4})x(\d{1,4}))?"
    r"(?:@(\d{1,4}),(\d{1,4}))?",
    re.ASCII,
)


def parse_section(text: str) -> Section:
    """A section from its written form: ``rect:3x4``, ``L:2x6:4x2``, ``T:2x8:4x2@1,1``."""
    match = _SPEC.fullmatch(text.strip())
    if match is None or (match[1] == "rect") != (match[4] is None):
        raise ValueError(
            f"not a section: {text[:40]!r} (expected rect:RxC, or L, T or I "
            "followed by :FLANGE:WEB as RxC each, optionally @ROW,COL)"
        )
    at = (int(match[6]), int(match[7])) if match[6] else (MARGIN, MARGIN)
    first = (int(match[2]), int(match[3]))
    if match[1] == "rect":
        return rect(*first, at=at)
    return shaped(match[1], first, (int(match[4]), int(match[5])), at=at)
