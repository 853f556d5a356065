"""The mock loom's mechanics: axes with travel time, the matrix of cases, faults (pure).

No I/O and no clock of its own: the bus servers call ``command`` and friends with the
current time and ``tick(now)`` before every read, so the same loom answers both buses.
Units as on the wire: micrometres, millidegrees. Every weft the inserter puts in is recorded
where it went (``wefts``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

from bwsd.fieldbus.axes import MDEG_PER_DEG, UM_PER_MM, Axis, machine_axes, moved_cells
from bwsd.fieldbus.base import (
    FAULT_DRIVE,
    FAULT_ESTOP,
    FAULT_JAM,
    FAULT_NONE,
    FAULT_STALL,
    OWNER_LEASE,
    STROKES_WRAP,
)
from bwsd.twin.machine import WEFT_AXES, Machine

WRONG_POSITION_OFFSET = 500  # µm a drive with an injected position fault is off by


@dataclass
class Owner:
    """The client that claimed the loom: its id, its pid, when it last claimed."""

    ident: int = 0  # 0: nobody
    pid: int = 0
    claimed: float = 0.0


@dataclass(frozen=True)
class Speeds:
    """Travel speeds; 0 means instant."""

    stroke: float = 0.0  # mm/s, shift and insert actuators
    takeup: float = 0.0  # mm/s
    weft: float = 0.0  # deg/s, weft angle
    travel: float = 0.0  # mm/s, the inserter's positioning axes (weft_x, weft_y, weft_z)


@dataclass(frozen=True)
class WeftMade:
    """A weft the inserter put in: the inserter's place when its stroke reached the far end
    (x, y in the guide plane, z above the fell: um; the angle: mdeg), the stroke (um) and
    the take-up axis's position then (um). A coordinate without an axis is the fixed one."""

    x: int
    y: int
    z: int
    angle: int
    length: int
    takeup: int


@dataclass
class AxisSim:
    """One simulated actuator."""

    axis: Axis
    position: int = 0
    busy: bool = False
    homed: bool = True
    seq: int = 0  # sequence of the running set-point
    done_seq: int = 0
    fault: int = FAULT_NONE
    last_stroke: int = 0
    strokes: int = 0  # set-points completed since power-on (wraps at 65536; homing keeps it)
    # a running motion: legs of (start time, from, to); a stroke goes out then back home
    legs: list[tuple[float, int, int]] = field(default_factory=list)
    stroke: int = 0
    latched: bool = True


@dataclass
class Faults:
    """Faults injected through the control channel."""

    mute: bool = False  # the buses stop answering
    drops: int = 0  # incremented to ask the servers to drop their connections
    stall: set[str] = field(default_factory=set)  # axes that stop mid-stroke
    wrong_position: set[str] = field(default_factory=set)  # axes that end off target
    drive: set[str] = field(default_factory=set)  # axes whose drive faults on the next command
    sensors: set[tuple[int, int]] = field(default_factory=set)  # cells whose sensor reads wrong


class Loom:
    """The whole mock machine."""

    def __init__(self, machine: Machine, fill: Iterable[tuple[int, int]], speeds: Speeds) -> None:
        self.machine = machine
        self.speeds = speeds
        self.axes = [AxisSim(a) for a in machine_axes(machine)]
        self.occupied = [[False] * machine.cols for _ in range(machine.rows)]
        for r, c in fill:
            self.occupied[r][c] = True
        self.estop = False
        self.faults = Faults()
        self.owner = Owner()
        self.on_change: Callable[[], None] | None = None  # the mechanics changed (state file)
        self.quick_stopped: float | None = None  # monotonic time of the last quick stop
        self.wefts: list[WeftMade] = []  # every weft put in since power-on, in order

    # ----- what survives a power cut -----
    def mechanics(self) -> dict[str, Any]:
        """What a power cut leaves as it is: where the cases are, the absolute axes'
        positions and every axis's stroke counter (a relative axis is home at power-on)."""
        return {
            "occupied": [row[:] for row in self.occupied],
            "axes": {
                sim.axis.name: {
                    "position": 0 if sim.axis.relative else sim.position,
                    "strokes": sim.strokes,
                    "done_seq": sim.done_seq,
                }
                for sim in self.axes
            },
        }

    def restore(self, saved: dict[str, Any]) -> None:
        """Power on with the mechanics a ``mechanics()`` saved (ValueError if they are not of
        this machine)."""
        occupied = saved.get("occupied")
        if (
            not isinstance(occupied, list)
            or [len(row) for row in occupied] != [self.machine.cols] * self.machine.rows
        ):
            raise ValueError("the saved occupancy is not of this machine's matrix")
        self.occupied = [[bool(cell) for cell in row] for row in occupied]
        axes = saved.get("axes", {})
        for sim in self.axes:
            kept = axes.get(sim.axis.name, {})
            sim.position = int(kept.get("position", 0))
            sim.strokes = int(kept.get("strokes", 0)) % STROKES_WRAP
            sim.done_seq = sim.seq = int(kept.get("done_seq", 0))

    def _changed(self) -> None:
        if self.on_change is not None:
            self.on_change()

    # ----- the owner -----
    def claim(self, ident: int, pid: int, now: float) -> Owner | None:
        """Give the loom to client ``ident`` (pid 0: its holder lets it go); the live owner
        who refuses it, or None.

        A claim is granted when nobody holds the loom, when ``ident`` already does, or when
        the holder has not claimed for ``OWNER_LEASE`` seconds (a claim is renewed by
        claiming again).
        """
        held = self.owner
        if held.ident and held.ident != ident and now - held.claimed < OWNER_LEASE:
            return held
        self.owner = Owner(ident, pid, now) if pid else Owner()
        return None

    # ----- commands -----
    def command(self, index: int, target: int, seq: int, now: float) -> None:
        """Start a set-point; ignored while the axis is busy or faulted or the e-stop is on."""
        sim = self.axes[index]
        self.tick(now)
        if sim.busy or sim.fault or self.estop:
            return
        sim.seq = seq
        if sim.axis.name in self.faults.drive:
            sim.fault = FAULT_DRIVE
            return
        if sim.axis.kind in ("row", "col") and not self._can_shift(sim.axis, target):
            sim.fault = FAULT_JAM
            return
        sim.busy, sim.stroke, sim.latched = True, target, False
        if sim.axis.relative:
            sim.legs = [(now, 0, target), (now + self._duration(sim, target), target, 0)]
        else:
            sim.legs = [(now, sim.position, target)]
        self.tick(now)

    def sensor(self, row: int, col: int) -> bool:
        """What the occupancy sensor of a cell reports (inverted where a sensor fault is)."""
        return self.occupied[row][col] != ((row, col) in self.faults.sensors)

    def sensed(self) -> list[list[bool]]:
        """Every occupancy sensor, row by row."""
        return [
            [self.sensor(r, c) for c in range(self.machine.cols)] for r in range(self.machine.rows)
        ]

    def quick_stop(self, now: float) -> None:
        """Stop every axis where it is; moving axes are left faulted (stall)."""
        self.tick(now)
        self.quick_stopped = now
        for sim in self.axes:
            if sim.busy:
                self._stop(sim, FAULT_STALL)

    def press_estop(self, pressed: bool, now: float) -> None:
        self.tick(now)
        self.estop = pressed
        if pressed:
            for sim in self.axes:
                if sim.busy:
                    self._stop(sim, FAULT_ESTOP)

    def set_speeds(self, speeds: Speeds, now: float) -> None:
        """Travel at ``speeds`` from now on: a move under way goes on from where it is."""
        self.tick(now)
        self.speeds = speeds
        for sim in self.axes:
            if sim.busy and sim.legs:
                _, _, dst = sim.legs[0]
                sim.legs[0] = (now, sim.position, dst)

    def reset_faults(self) -> None:
        for sim in self.axes:
            sim.fault = FAULT_NONE
        self._changed()

    def home(self, now: float) -> None:
        """Home the shift and weft axes (instantly: they are at rest between strokes)."""
        self.tick(now)
        for sim in self.axes:
            if sim.axis.kind != "takeup" and not sim.busy and not sim.fault:
                sim.position, sim.done_seq, sim.homed = 0, 0, True
        self._changed()

    # ----- time -----
    def tick(self, now: float) -> None:
        """Advance every moving axis to time ``now``."""
        for sim in self.axes:
            if sim.busy:
                self._advance(sim, now)

    def _advance(self, sim: AxisSim, now: float) -> None:
        while sim.legs:
            start, src, dst = sim.legs[0]
            span = self._duration(sim, dst - src)
            if sim.axis.name in self.faults.stall and not sim.latched and src != dst:
                sim.position = src + (dst - src) // 2  # stuck half way out
                self._stop(sim, FAULT_STALL)
                return
            if now < start + span:
                frac = (now - start) / span if span > 0 else 1.0
                sim.position = round(src + frac * (dst - src))
                return
            sim.position = dst
            sim.legs.pop(0)
            if sim.legs:
                self._latch(sim)
                _, src2, dst2 = sim.legs[0]
                sim.legs[0] = (start + span, src2, dst2)
        self._finish(sim)

    def _finish(self, sim: AxisSim) -> None:
        if not sim.latched:
            self._latch(sim)
        if sim.axis.name in self.faults.wrong_position:
            sim.position += WRONG_POSITION_OFFSET
        sim.busy = False
        sim.done_seq = sim.seq
        sim.last_stroke = sim.stroke if sim.axis.relative else 0
        sim.strokes = (sim.strokes + 1) % STROKES_WRAP
        self._changed()

    def _stop(self, sim: AxisSim, code: int) -> None:
        sim.legs.clear()
        sim.busy = False
        sim.fault = code

    def _duration(self, sim: AxisSim, distance: int) -> float:
        kind = sim.axis.kind
        speeds = {"takeup": self.speeds.takeup, "weft_angle": self.speeds.weft}
        speeds |= dict.fromkeys(("weft_x", "weft_y", "weft_z"), self.speeds.travel)
        speed = speeds.get(kind, self.speeds.stroke)
        scale = MDEG_PER_DEG if kind == "weft_angle" else UM_PER_MM
        return abs(distance) / (speed * scale) if speed > 0 else 0.0

    # ----- the matrix -----
    def _cells(self, axis: Axis, target: int) -> tuple[int, list[int]]:
        """The stroke in cells and the cases it carries: those on the cells the axis moves
        (the whole line, or a segment's cells), as positions along the line."""
        m = self.machine
        pitch = m.pitch_x if axis.kind == "row" else m.pitch_y
        k = round(target / (pitch * UM_PER_MM))
        line = axis.line if axis.line is not None else 0
        lo, hi = moved_cells(m, axis)
        return k, [i for i in range(lo, hi + 1) if self._get(axis.kind, line, i)]

    def _can_shift(self, axis: Axis, target: int) -> bool:
        """A rigid stroke fails when a case would leave the cells the axis moves (the matrix
        for a whole line, its cells for a segment) or land on a case that stays put."""
        k, at = self._cells(axis, target)
        lo, hi = moved_cells(self.machine, axis)
        line = axis.line if axis.line is not None else 0
        carried = set(at)
        return all(
            lo <= i + k <= hi and (i + k in carried or not self._get(axis.kind, line, i + k))
            for i in at
        )

    def _latch(self, sim: AxisSim) -> None:
        """The stroke reached its far end: the cases of the line sit in their new cells (an
        insert stroke: the weft is in, where the inserter stands)."""
        sim.latched = True
        axis = sim.axis
        if axis.kind == "weft_insert" and sim.stroke:
            self.wefts.append(self._weft_made(sim.stroke))
        if axis.kind not in ("row", "col"):
            return
        k, at = self._cells(axis, sim.stroke)
        line = axis.line if axis.line is not None else 0
        for i in at:
            self._set(axis.kind, line, i, False)
        for i in at:
            self._set(axis.kind, line, i + k, True)
        self._changed()

    def _weft_made(self, stroke: int) -> WeftMade:
        """The weft an insert stroke of ``stroke`` um puts in now."""
        where: dict[str, int] = {sim.axis.kind: sim.position for sim in self.axes}
        fixed = self.machine.fixed_weft()
        x, y, z = (
            where.get(f"weft_{name}", round(value * UM_PER_MM))
            for name, value in zip(WEFT_AXES, fixed, strict=True)
        )
        return WeftMade(x, y, z, where["weft_angle"], stroke, where["takeup"])

    def _get(self, kind: str, line: int, i: int) -> bool:
        return self.occupied[line][i] if kind == "row" else self.occupied[i][line]

    def _set(self, kind: str, line: int, i: int, value: bool) -> None:
        if kind == "row":
            self.occupied[line][i] = value
        else:
            self.occupied[i][line] = value
