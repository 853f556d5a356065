"""The fault-injection matrix, timed: prints the table of docs/benchmarks.md.

    python bench/faults.py

Each fault of tests/controller/matrix.py injected in each of Idle, Execute, Held and
Stopped (the controller on the mock loom in its own process, a real journal file). Per
cell: the state it rested in, the commands it accepted there, the seconds from the
injection to a Fault published with the controller at rest (or still executing), and
whether the same program then resumed to Complete with the predicted skeleton.
"""

from __future__ import annotations

import asyncio
import logging
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.controller.matrix import FAULTS, STATES, Cell, run_cell  # noqa: E402


def cell_text(cell: Cell) -> str:
    allowed = ", ".join(c.label for c in cell.allowed) or "none"
    ok = "yes" if cell.completed and cell.same_skeleton else "NO"
    ended = cell.ended.label if cell.ended is not None else "?"
    return f"{ended} ({allowed}) {cell.seconds:.2f} s, resumed: {ok}"


def main() -> None:
    logging.basicConfig(level=logging.WARNING)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # its frame dumps
    rows = []
    slowest = 0.0
    for fault in FAULTS:
        cells = []
        for state in STATES:
            with tempfile.TemporaryDirectory() as tmp:
                cell = asyncio.run(run_cell(Path(tmp), fault, state))
            slowest = max(slowest, cell.seconds)
            cells.append(cell_text(cell))
        rows.append(f"| {fault} | " + " | ".join(cells) + " |")
    print("| fault | " + " | ".join(s.label for s in STATES) + " |")
    print("|---|" + "---|" * len(STATES))
    print("\n".join(rows))
    print(
        f"\nSlowest cell to a Fault at rest: {slowest:.2f} s. The e-stop's commands are "
        "those accepted once it is released (while pressed, Aborted accepts none)."
    )


if __name__ == "__main__":
    main()
