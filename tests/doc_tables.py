"""The wire maps as the docs write them: a Markdown table read back, cell by cell.

The docs are the reference for every address and node id a PLC or a loom relies on; the
tests read them from there, so a change of the code that the docs do not follow fails.
"""

from __future__ import annotations

import re
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1] / "docs"


def doc_table(doc: str, *header: str, after: str = "") -> list[dict[str, str]]:
    """The rows of the first table in ``docs/<doc>`` after the line starting with ``after``
    whose header row begins with the cells ``header``, as {column: cell} (code quotes
    stripped). A missing table is an AssertionError naming what was looked for."""
    lines = (DOCS / doc).read_text().splitlines()
    start = (
        next((i for i, line in enumerate(lines) if line.startswith(after)), None) if after else 0
    )
    assert start is not None, f"docs/{doc}: no line starting {after!r}"
    for at in range(start, len(lines) - 1):
        cells = _cells(lines[at])
        if cells[: len(header)] == list(header) and set(lines[at + 1]) <= set("|-: "):
            rows = []
            for line in lines[at + 2 :]:
                if not line.startswith("|"):
                    break
                rows.append(dict(zip(cells, _cells(line), strict=True)))
            return rows
    raise AssertionError(f"docs/{doc}: no table with columns {header} after {after!r}")


def _cells(line: str) -> list[str]:
    if not line.startswith("|"):
        return []
    return [cell.strip().replace("`", "") for cell in line.strip().strip("|").split("|")]


def addresses(cell: str) -> list[int]:
    """``8, 9`` or ``6`` or ``+0, +1`` as the numbers it names."""
    return [int(n) for n in re.findall(r"\d+", cell)]
