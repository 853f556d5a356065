"""The twin: predict, commit, snapshot and restore over the compiled kernel (docs/twin.md).

``predict`` runs an instruction in the kernel, in place and with the interpreter lock
released, copies the record of what changed, and rolls the state back: the committed state is
all any reader ever sees, and no read changes anything. ``commit`` replays that record, in the
size of the change. A prediction names the state it was made on; any other is refused.
"""

from __future__ import annotations

import math
import threading
import time
from array import array
from collections.abc import Callable, Iterable
from fractions import Fraction
from typing import Any

import numpy as np

from bwsd.errors import JamError, MoveError, ShedClosedError, TwinError
from bwsd.twin import _kernel
from bwsd.twin.exact import MAX_DIAMETER, MIN_LENGTH, SCALE, as_bytes, exact
from bwsd.twin.geometry import Geometry, Point, weft_ends
from bwsd.twin.instructions import Instruction, Program, Shift, TakeUp
from bwsd.twin.machine import Machine, unknown_segment, weft_off_fixed
from bwsd.twin.prediction import NodeInsert, Prediction, Snapshot, mm
from bwsd.twin.shed import closest
from bwsd.twin.skeleton import ContactData, IntArray, SkeletonData, YarnData

__all__ = ["NodeInsert", "Prediction", "Snapshot", "Twin", "replay", "simulate"]


class Twin:
    """The geometric model of the machine (docs/twin.md), over the compiled kernel.

    Safe to share between threads: calls are serialised by a lock; ``takeup`` and ``done``
    are plain attributes that a running prediction never touches.
    """

    def __init__(
        self, machine: Machine, fill: Iterable[tuple[int, int]], diameter: float | None = None
    ) -> None:
        self.machine = machine
        self.diameter = float(machine.yarn_diameter if diameter is None else diameter)
        d = exact(self.diameter)
        if not (d == 0 or MIN_LENGTH <= d < MAX_DIAMETER):
            raise TwinError(
                f"yarn diameter {self.diameter:g} mm: it must be 0 or lie in "
                f"[{float(MIN_LENGTH):g}, {MAX_DIAMETER}) mm"
            )
        fault = machine.diameter_fault(self.diameter)
        if fault is not None:
            raise TwinError(fault)
        self._geo = Geometry(machine)
        grid_d = d * SCALE
        self._kernel = _kernel.Kernel(
            array("q", self._geo.gx).tobytes(),
            array("q", self._geo.gy).tobytes(),
            self._geo.guide_z(Fraction(0)),
            self._geo.cell_shift(),
            float(grid_d),
            as_bytes(grid_d.numerator),
            as_bytes(grid_d.denominator),
        )
        self._fill: list[tuple[int, int]] = []
        for row, col in fill:
            self._add_warp(row, col)
        self._angles: list[float | None] = [None] * len(self._fill)
        self._takeup = Fraction(0)
        self.done = 0
        self._lock = threading.Lock()
        self._changed()

    def _add_warp(self, row: int, col: int) -> None:
        if not self.machine.inside(row, col):
            raise TwinError(f"fill cell ({row}, {col}) is outside the matrix")
        if (row, col) in self._fill:
            raise TwinError(f"fill cell ({row}, {col}) is filled twice")
        self._kernel.add_warp(row, col, *self._geo.fell(row, col, Fraction(0)))
        self._fill.append((row, col))

    @classmethod
    def from_program(cls, machine: Machine, program: Program) -> Twin:
        """A twin filled as the program says, before its first instruction."""
        return cls(machine, program.fill, program.diameter)

    def _changed(self) -> None:
        """A new committed state: predictions made before it no longer apply."""
        self._state = object()
        nodes, yarns, _, contacts, _ = self._kernel.counts()
        self.node_count, self.yarn_count, self.contact_count = nodes, yarns, contacts
        self._warps: tuple[IntArray, IntArray] | None = None

    # ----- instructions -----
    def predict(self, instruction: Instruction) -> Prediction:
        """The result of ``instruction`` from the committed state, which stays as it is.

        Raises MoveError, ShedClosedError or TwinError (naming the instruction) if refused.
        """
        with self._lock:
            index = self.done + 1
            result, takeup, angles = self._run(instruction, index, predict=True)
            return Prediction.build(
                index, instruction, result, takeup, angles, self._state, self.machine
            )

    def commit(self, prediction: Prediction) -> None:
        """Make ``prediction`` the committed state; it must have been made on this one."""
        with self._lock:
            if prediction.state is not self._state:
                raise TwinError(
                    "prediction is stale: it was not made on the twin's current state",
                    instruction=prediction.index,
                )
            self._kernel.replay(prediction.record)
            self._advance(prediction.takeup_exact, prediction.angles)

    def apply(self, instruction: Instruction) -> Prediction:
        """Predict and commit in one step."""
        prediction = self.predict(instruction)
        self.commit(prediction)
        return prediction

    def advance(self, instruction: Instruction) -> None:
        """Apply ``instruction`` without describing it (the fast path of simulate and replay)."""
        with self._lock:
            _, takeup, angles = self._run(instruction, self.done + 1, predict=False)
            self._advance(takeup, angles)

    def _advance(self, takeup: Fraction, angles: tuple[float, ...]) -> None:
        self._takeup = takeup
        self._angles.extend(angles)
        self.done += 1
        self._changed()

    def _run(
        self, instruction: Instruction, index: int, predict: bool
    ) -> tuple[Any, Fraction, tuple[float, ...]]:
        takeup = self._takeup
        angles: tuple[float, ...] = ()
        try:
            if isinstance(instruction, Shift):
                moves = array("i", self._quads(instruction)).tobytes()
                axis = 0 if instruction.axis == "row" else 1
                result = self._kernel.shift(axis, moves, index, predict)
            elif isinstance(instruction, TakeUp):
                takeup = self._takeup + exact(instruction.length)
                result = self._kernel.takeup(self._geo.guide_z(takeup), index, predict)
            else:
                off = weft_off_fixed(self.machine, instruction.x, instruction.y, instruction.z)
                if off is not None:
                    raise MoveError(off)
                p0, p1 = weft_ends(instruction, takeup)
                self._check_shed(p0, p1)
                result = self._kernel.weft(*p0, *p1, predict)
                angles = (instruction.angle,)
        except _kernel.KernelError as exc:
            raise _refusal(exc.args, instruction, index, self.diameter) from None
        except TwinError as exc:
            if exc.instruction:
                raise
            raise type(exc)(exc.reason, instruction=index) from None
        return result, takeup, angles

    def _quads(self, shift: Shift) -> list[int]:
        """The kernel's (line, k, first, last) per entry; a span must be a declared segment."""
        along = self.machine.cols if shift.axis == "row" else self.machine.rows
        out: list[int] = []
        for line, k, span in shift.moves:
            if span is not None and self.machine.segment(shift.axis, line, span) is None:
                raise MoveError(unknown_segment(self.machine, shift.axis, line, span))
            out += [line, k, *(span if span is not None else (0, along - 1))]
        return out

    def _check_shed(self, p0: Point, p1: Point) -> None:
        """Refuse a weft passing closer than the yarn diameter to a yarn (exactly d is fine)."""
        limit = exact(self.diameter) * SCALE
        if limit == 0:
            return
        reach = math.ceil(limit)
        lo = [min(p0[k], p1[k]) - reach for k in range(3)]
        hi = [max(p0[k], p1[k]) + reach for k in range(3)]
        table = np.frombuffer(self._kernel.near(*lo, *hi), dtype=np.int32).reshape(-1, 3)
        ends = np.frombuffer(self._kernel.points(table[:, :2].tobytes()), dtype=np.int64)
        xyz = ends.reshape(-1, 2, 3).tolist()
        segments = [(int(y), c, d) for y, (c, d) in zip(table[:, 2].tolist(), xyz, strict=True)]
        found = closest(p0, p1, segments, limit)
        if found is not None:
            yarn, gap2 = found
            gap = math.sqrt(gap2) / SCALE
            raise ShedClosedError(
                f"shed closed: the weft passes {gap:.6g} mm from yarn {yarn} "
                f"(yarn diameter {self.diameter:g} mm)"
            )

    # ----- snapshots -----
    def snapshot(self) -> Snapshot:
        """The committed state as an immutable value (``Snapshot.to_bytes`` to store it)."""
        with self._lock:
            return Snapshot.make(
                self.machine,
                self.diameter,
                self._fill,
                self._angles,
                self._takeup,
                self.done,
                self._kernel.dump(),
            )

    def restore(self, snapshot: Snapshot) -> None:
        """Return to ``snapshot`` (taken of a twin of the same machine and diameter)."""
        snapshot.check(self.machine, self.diameter)
        kernel = _load(snapshot)
        with self._lock:
            self._kernel = kernel
            self._fill = [tuple(cell) for cell in snapshot.header["fill"]]
            self._angles = [None if a is None else float(a) for a in snapshot.header["angles"]]
            self._takeup = Fraction(snapshot.header["takeup"])
            self.done = snapshot.done
            self._changed()

    @classmethod
    def from_snapshot(cls, machine: Machine, snapshot: Snapshot) -> Twin:
        """A twin in the state of ``snapshot``."""
        twin = cls(machine, [], snapshot.header["diameter"])
        twin.restore(snapshot)
        return twin

    # ----- reading (never changes anything) -----
    @property
    def takeup(self) -> float:
        """Total take-up so far (mm)."""
        return float(self._takeup)

    @property
    def takeup_exact(self) -> Fraction:
        """Total take-up so far, exactly (mm)."""
        return self._takeup

    def _warp_table(self) -> tuple[IntArray, IntArray]:
        """Per warp (row, col, free node, last fixed node), and the occupancy."""
        with self._lock:
            return self._warp_table_locked()

    def _warp_table_locked(self) -> tuple[IntArray, IntArray]:
        if self._warps is None:
            table, occupancy = self._kernel.warps()
            m = self.machine
            self._warps = (
                np.frombuffer(table, dtype=np.int32).reshape(-1, 4).astype(np.int64),
                np.frombuffer(occupancy, dtype=np.int32).reshape(m.rows, m.cols).astype(np.int64),
            )
        return self._warps

    @property
    def occupancy(self) -> IntArray:
        """Yarn id of the case in each cell, -1 where empty (a copy)."""
        return self._warp_table()[1].copy()

    def free_node(self, warp: int) -> int:
        """The node id of a warp's free node (the one at its guide)."""
        return int(self._warp_table()[0][warp, 2])

    def yarn(self, yarn: int) -> YarnData:
        """A read-only copy of one yarn."""
        with self._lock:
            ids_raw, _ = self._kernel.chains(yarn, yarn + 1)
            ids = np.frombuffer(ids_raw, dtype=np.int32).astype(np.int64)
            pos = np.frombuffer(self._kernel.points(ids_raw), dtype=np.int64).reshape(-1, 3)
        return self._yarn_data(yarn, ids, mm(pos))

    def _yarn_data(self, yarn: int, ids: IntArray, pos: np.ndarray[Any, Any]) -> YarnData:
        if yarn < len(self._fill):
            return YarnData(yarn, "warp", ids, pos, self._fill[yarn], None)
        return YarnData(yarn, "weft", ids, pos, None, self._angles[yarn])

    def skeleton(self) -> SkeletonData:
        """A read-only copy of the whole skeleton."""
        with self._lock:
            occupancy = self._warp_table_locked()[1].copy()
            ids_raw, starts_raw = self._kernel.chains(0, self.yarn_count)
            pos = mm(np.frombuffer(self._kernel.positions(), dtype=np.int64).reshape(-1, 3))
            table = np.frombuffer(self._kernel.contacts(), dtype=np.int32).reshape(-1, 5)
            ids = np.frombuffer(ids_raw, dtype=np.int32).astype(np.int64)
            starts = np.frombuffer(starts_raw, dtype=np.int64)
            takeup, done = self.takeup, self.done
        yarns = tuple(
            self._yarn_data(i, ids[starts[i] : starts[i + 1]], pos[ids[starts[i] : starts[i + 1]]])
            for i in range(len(starts) - 1)
        )
        contacts = tuple(ContactData(*row) for row in table.tolist())
        return SkeletonData(self.machine, self.diameter, takeup, done, yarns, contacts, occupancy)

    def path_length(self, yarn: int) -> float:
        """Length of a yarn's polyline (mm), a warp's free segment included."""
        with self._lock:
            lengths = np.frombuffer(self._kernel.lengths(), dtype=np.float64)
        return float(lengths[yarn]) / SCALE


def _load(snapshot: Snapshot) -> Any:
    try:
        return _kernel.Kernel.load(snapshot.kernel)
    except ValueError as exc:
        raise TwinError(str(exc)) from None


def _refusal(
    args: tuple[int, ...], instruction: Instruction, index: int, diameter: float
) -> TwinError:
    """The error of a refused instruction, from the kernel's code and details."""
    code, a, b, c, d = args
    if code == _kernel.E_JAM:
        return jam_error(a, b, c, d, diameter, index)
    if code == _kernel.E_LINE:
        axis = instruction.axis.upper() if isinstance(instruction, Shift) else "LINE"
        return MoveError(f"{axis} {b} is outside the matrix", instruction=index)
    if code == _kernel.E_MOVE_OUT:
        return MoveError(
            f"case of yarn {a} would leave the matrix at cell ({b}, {c})", instruction=index
        )
    if code == _kernel.E_MOVE_SPAN and isinstance(instruction, Shift):
        move = instruction.moves[d]
        return MoveError(
            f"case of yarn {a} would leave the segment {instruction.axis.upper()} "
            f"{move.text().partition(':')[0]} at cell ({b}, {c})",
            instruction=index,
        )
    if code == _kernel.E_MOVE_BUSY:
        return MoveError(
            f"case of yarn {a} would land on cell ({b}, {c}), occupied by yarn {d}",
            instruction=index,
        )
    if code == _kernel.E_LIMIT:
        return TwinError(
            "a contact node would lie beyond the twin's range of 2^20 mm", instruction=index
        )
    if code == _kernel.E_CONTACTS:
        return TwinError(f"yarn {a}: more than 100000 contacts in one sweep", instruction=index)
    return TwinError(f"the twin's kernel failed (code {code}): please report it", instruction=index)


def jam_error(moving: int, hit: int, z: int, guides: int, diameter: float, index: int) -> JamError:
    """A jam (docs/twin.md): the contact of ``moving`` on ``hit`` at grid height ``z``, too
    close to the guides at grid height ``guides``."""
    at, below = z / SCALE, (guides - z) / SCALE
    where = f"{below:.4g} mm below the guides" if below > 0 else "at or above the guides"
    return JamError(
        f"jam: yarn {moving} would rest on yarn {hit} at z = {at:.4f} mm, {where} "
        f"(z = {guides / SCALE:.4f} mm), within one yarn diameter ({diameter:g} mm) "
        "of them: the yarns would lock at the guides (more take-up per cycle moves "
        "the contacts down)",
        instruction=index,
        yarns=(moving, hit),
        z=at,
    )


ProgressFn = Callable[[int, int], None]


def simulate(
    machine: Machine,
    program: Program,
    progress: ProgressFn | None = None,
    timings: list[float] | None = None,
) -> Twin:
    """Run every instruction of ``program``; TwinError carries the failing instruction.

    With ``timings``, each instruction is predicted and committed as the daemon does, and the
    seconds of each ``predict`` are appended to it.
    """
    twin = Twin.from_program(machine, program)
    total = len(program.instructions)
    for i, instruction in enumerate(program.instructions):
        if timings is None:
            twin.advance(instruction)
        else:
            start = time.perf_counter()
            prediction = twin.predict(instruction)
            timings.append(time.perf_counter() - start)
            twin.commit(prediction)
        if progress is not None:
            progress(i + 1, total)
    return twin


def replay(machine: Machine, program: Program, count: int | None = None) -> Twin:
    """The twin after the first ``count`` instructions (all when None)."""
    sub = program.instructions if count is None else program.instructions[:count]
    twin = Twin.from_program(machine, program)
    for instruction in sub:
        twin.advance(instruction)
    return twin
