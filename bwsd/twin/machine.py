"""Machine geometry: the matrix of guides, the fell and the convergence."""

from __future__ import annotations

from dataclasses import dataclass


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
