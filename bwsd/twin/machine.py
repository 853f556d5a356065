"""Machine geometry: the matrix of guides, the fell and the convergence."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from itertools import pairwise
from typing import Any, Literal

from bwsd.twin.exact import exact

WEFT_AXES = ("x", "y", "z")  # the inserter's positioning axes a machine may have, in wire order


@dataclass(frozen=True, order=True)
class Segment:
    """A separately actuated part of a row or column: its cells ``lo``..``hi`` along the line.

    A ROW (COL) entry ``line[lo..hi]:k`` moves only the cases on those cells, by its own
    actuator, and keeps them there. Written ``ROW 3[0..3]`` in configs and messages.
    """

    axis: Literal["row", "col"]
    line: int
    lo: int
    hi: int

    def text(self) -> str:
        return f"{self.axis.upper()} {self.line}[{self.lo}..{self.hi}]"

    def overlaps(self, other: Segment) -> bool:
        """True when both are on the same line and share a cell."""
        same = (self.axis, self.line) == (other.axis, other.line)
        return same and self.lo <= other.hi and other.lo <= self.hi


@dataclass(frozen=True)
class Machine:
    """Geometry of a braiding-weaving machine (docs/twin.md, "Model in one page").

    Lengths in millimetres. Cell (r, c) has its guide at x = c * pitch_x, y = r * pitch_y.
    """

    rows: int
    cols: int
    pitch_x: float
    pitch_y: float
    d_mat: float
    c_mat: float
    yarn_diameter: float = 0.0
    segments: tuple[Segment, ...] = ()
    # The weft inserter's positioning axes (a subset of WEFT_AXES, kept in that order), and
    # where it stands along a coordinate it has no axis for (mm: x, y in the guide plane, z
    # above the fell; None: fixed_weft()'s default). Not geometry: as_dict leaves them out.
    weft_axes: tuple[str, ...] = WEFT_AXES
    weft_fixed: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.rows < 1 or self.cols < 1:
            raise ValueError("rows and cols must be at least 1")
        if self.pitch_x <= 0 or self.pitch_y <= 0:
            raise ValueError("pitch_x and pitch_y must be positive")
        if self.d_mat <= 0:
            raise ValueError("d_mat must be positive")
        if not 0 <= self.c_mat <= 1:
            raise ValueError("c_mat must lie in [0, 1]")
        if self.yarn_diameter < 0:
            raise ValueError("yarn diameter must not be negative")
        fault = self.diameter_fault(self.yarn_diameter)
        if fault is not None:
            raise ValueError(fault)
        object.__setattr__(self, "segments", tuple(self.segments))
        for seg in self.segments:
            self._check_segment(seg)
        overlap = first_overlap(self.segments)
        if overlap is not None:
            raise ValueError(f"segment {overlap[0].text()} overlaps {overlap[1].text()}")
        self._check_weft_axes()

    def _check_weft_axes(self) -> None:
        axes = tuple(self.weft_axes)
        unknown = [a for a in axes if a not in WEFT_AXES]
        if unknown or len(set(axes)) != len(axes):
            raise ValueError(
                f"weft axes must be distinct ones of {', '.join(WEFT_AXES)}, got "
                f"{', '.join(map(str, axes)) or 'none'}"
            )
        object.__setattr__(self, "weft_axes", tuple(a for a in WEFT_AXES if a in axes))
        if self.weft_fixed is not None:
            object.__setattr__(self, "weft_fixed", tuple(float(v) for v in self.weft_fixed))
            if len(self.weft_fixed) != 3:
                raise ValueError("the weft's fixed position needs x, y and z")

    def _check_segment(self, seg: Segment) -> None:
        lines, along = (self.rows, self.cols) if seg.axis == "row" else (self.cols, self.rows)
        if not 0 <= seg.line < lines:
            raise ValueError(
                f"segment {seg.text()}: {seg.axis} {seg.line} is outside the "
                f"matrix (0 to {lines - 1})"
            )
        if not 0 <= seg.lo < seg.hi < along:
            raise ValueError(f"segment {seg.text()}: needs 0 <= first < last <= {along - 1}")

    def diameter_fault(self, diameter: float) -> str | None:
        """Why yarns of ``diameter`` cannot fit this machine, or None (docs/twin.md).

        Neighbouring warps start c_mat x pitch apart at the fell, so a diameter of that or
        more makes them overlap from the start; compared on the exact decimals. A diameter
        of 0 (centrelines only) always fits.
        """
        d, gap = exact(diameter), exact(self.c_mat) * min(exact(self.pitch_x), exact(self.pitch_y))
        if d == 0 or d < gap:
            return None
        return (
            f"a yarn diameter of {diameter:g} mm does not fit: it must be less than c_mat x "
            f"the smaller pitch ({float(gap):g} mm), where neighbouring yarns start at the "
            "fell"
        )

    def as_dict(self) -> dict[str, Any]:
        """The machine as plain data (snapshots, skeleton JSON); ``segments`` only when it
        has some, so that files of a machine without them read as before."""
        data = asdict(self)
        data["segments"] = [asdict(seg) for seg in self.segments]  # lists, as JSON reads back
        if not self.segments:
            del data["segments"]
        del data["weft_axes"], data["weft_fixed"]  # actuators, not geometry
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Machine:
        """The inverse of ``as_dict``."""
        fields = dict(data)
        fields["segments"] = tuple(Segment(**seg) for seg in fields.get("segments", ()))
        return cls(**fields)

    def segment(self, axis: str, line: int, span: tuple[int, int]) -> Segment | None:
        """The declared segment of ``axis`` ``line`` over exactly ``span``, or None."""
        for seg in self.segments:
            if (seg.axis, seg.line, seg.lo, seg.hi) == (axis, line, *span):
                return seg
        return None

    def fixed_weft(self) -> tuple[float, float, float]:
        """Where the inserter stands along a coordinate it has no axis for (mm): the
        configured ``weft_fixed``, else x, y of the convergence point O and z half way from
        the fell to the guides (d_mat / 2)."""
        if self.weft_fixed is not None:
            return self.weft_fixed
        ox, oy = self.convergence_xy()
        return ox, oy, self.d_mat / 2

    def inside(self, row: int, col: int) -> bool:
        """True when (row, col) is a cell of the matrix."""
        return 0 <= row < self.rows and 0 <= col < self.cols

    def guide_xy(self, row: int, col: int) -> tuple[float, float]:
        """Guide centre of cell (row, col) in the plane of the matrix."""
        return col * self.pitch_x, row * self.pitch_y

    def convergence_xy(self) -> tuple[float, float]:
        """The convergence point O: the centre of the matrix."""
        return (self.cols - 1) / 2 * self.pitch_x, (self.rows - 1) / 2 * self.pitch_y

    def fell_xy(self, row: int, col: int) -> tuple[float, float]:
        """Where a warp filled into (row, col) meets the fell: O + c_mat * (guide - O)."""
        ox, oy = self.convergence_xy()
        gx, gy = self.guide_xy(row, col)
        return ox + self.c_mat * (gx - ox), oy + self.c_mat * (gy - oy)


def first_overlap(segments: Sequence[Segment]) -> tuple[Segment, Segment] | None:
    """Two segments that share a cell, the later declared first (of the pairs found, the one
    declared earliest); None when no two do.

    Sorted by line and first cell, a segment that overlaps any other overlaps its neighbour
    in that order, so comparing neighbours finds every line with an overlap: O(n log n).
    """
    order = sorted(range(len(segments)), key=segments.__getitem__)  # axis, line, first, last
    found = [
        (max(i, j), min(i, j)) for i, j in pairwise(order) if segments[i].overlaps(segments[j])
    ]
    if not found:
        return None
    later, earlier = min(found)
    return segments[later], segments[earlier]


def unknown_segment(machine: Machine, axis: str, line: int, span: tuple[int, int]) -> str:
    """Why ``axis line[span]`` cannot move on ``machine``: it declares no such segment."""
    declared = ", ".join(seg.text() for seg in machine.segments) or "none"
    return (
        f"{axis.upper()} {line}[{span[0]}..{span[1]}] is not a segment of this machine "
        f"(declared in [machine] segments: {declared})"
    )


def weft_off_fixed(machine: Machine, x: float, y: float, z: float) -> str | None:
    """Why a weft centred at (x, y) and z above the fell cannot be inserted by ``machine``:
    along a coordinate it has no axis for, the weft must lie at the inserter's fixed value
    (compared on the wire's micrometres). None when it can."""
    for name, value, fixed in zip(WEFT_AXES, (x, y, z), machine.fixed_weft(), strict=True):
        if name not in machine.weft_axes and round(value * 1000) != round(fixed * 1000):
            has = ", ".join(f'"{a}"' for a in machine.weft_axes)
            return (
                f"the weft's {name} = {value:g} mm is off the inserter's fixed {name} = "
                f"{fixed:g} mm: this machine has no weft_{name} axis ([machine] weft_axes "
                f"= [{has}])"
            )
    return None
