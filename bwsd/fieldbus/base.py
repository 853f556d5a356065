"""The one small async interface to the actuators; a backend per bus fills its hooks.

A backend implements the ``_``-prefixed hooks (open, close, write a set-point, read the
machine's state, quick stop, reset, home). The base class does what every bus shares:
reconnecting with exponential backoff, waiting for completion with a timeout, checking the
read-back, and raising errors by phase (connection, timeout, drive fault, e-stop).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import time
import zlib
from abc import ABC, abstractmethod
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bwsd.errors import BwsdError
from bwsd.fieldbus.axes import Axis, machine_axes
from bwsd.twin.machine import Machine

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    BoolGrid = npt.NDArray[np.bool_]
else:

    def __getattr__(name: str) -> Any:
        """``BoolGrid`` made at its first use: the mock loom, which imports this module,
        never needs numpy, and spares the import (a tenth of a second at each start)."""
        if name == "BoolGrid":
            import numpy as np
            import numpy.typing as npt

            return npt.NDArray[np.bool_]
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# Fault codes, the same on every bus (docs/fieldbus-modbus.md, docs/fieldbus-canopen.md).
FAULT_NONE = 0
FAULT_JAM = 1  # a case was blocked by the matrix bound or an occupied cell
FAULT_STALL = 2  # the actuator stopped mid-stroke (following error)
FAULT_DRIVE = 3  # the drive reports an internal fault
FAULT_POSITION = 4  # the drive reached a position other than commanded
FAULT_ESTOP = 5  # the move was cut by the emergency stop
FAULT_NAMES = {
    FAULT_NONE: "none",
    FAULT_JAM: "jam",
    FAULT_STALL: "stall",
    FAULT_DRIVE: "drive fault",
    FAULT_POSITION: "wrong position",
    FAULT_ESTOP: "emergency stop",
}


class FieldbusError(BwsdError):
    """Base of the errors of the actuator bus.

    ``lost``: the machine did not answer (no connection, no reply), as opposed to an answer
    that refused or reported a fault. Decided where the error is raised, never from its text.
    """

    lost = False

    def __init__(self, message: str, *, lost: bool | None = None) -> None:
        super().__init__(message)
        if lost is not None:
            self.lost = lost


class FieldbusConnectionError(FieldbusError):
    """The bus cannot be reached, or the connection was lost (after the retries)."""

    lost = True


class FieldbusTimeout(FieldbusError):
    """The bus stopped answering (``lost``), or an axis that answers did not complete within
    the timeout (``lost=False``)."""

    lost = True


class DriveFault(FieldbusError):
    """An axis reports a fault (jam, stall, drive fault, wrong position)."""

    def __init__(self, axis: Axis, code: int, detail: str = "") -> None:
        name = FAULT_NAMES.get(code, f"fault {code}")
        super().__init__(f"axis {axis.name}: {name}" + (f" ({detail})" if detail else ""))
        self.axis = axis
        self.code = code


class EStopError(FieldbusError):
    """The emergency stop is pressed."""


class BusHeld(FieldbusError):
    """Another client owns the bus: nothing is moved."""


# The loom's claim (docs/fieldbus-modbus.md, docs/fieldbus-canopen.md): a client claims the
# loom before it moves it; the claim lasts OWNER_LEASE seconds after the holder's last one.
OWNER_LEASE = 2.0  # s, the loom's
STROKES_WRAP = 0x10000  # an axis's stroke counter is 16 bits on every bus (AxisState.strokes)
CLAIM_RENEW = 0.5  # s: a claim older than this is renewed before the next command


def owner_id(name: str) -> int:
    """The 32-bit claim id of a client called ``name`` (never 0)."""
    return zlib.crc32(name.encode()) or 1


def process_owner_id() -> int:
    """The claim id of this process alone (``bwsd hw``, a test, a benchmark)."""
    return owner_id(f"{socket.gethostname()}:pid {os.getpid()}")


@dataclass(frozen=True)
class AxisMove:
    """A set-point for one axis, in wire units.

    Shift and insert axes: a relative stroke in micrometres (the axis ends back home).
    Weft angle: absolute millidegrees. Take-up: absolute micrometres.
    """

    axis: int
    target: int


@dataclass(frozen=True)
class AxisState:
    """What one axis reports."""

    position: int  # micrometres (millidegrees for the weft angle)
    busy: bool
    done_seq: int  # sequence number of the last completed set-point
    fault: int  # FAULT_* code
    last_stroke: int  # micrometres of the last completed stroke (relative axes)
    strokes: int | None = None  # set-points completed, mod 65536 (None: the bus has no counter)


@dataclass(frozen=True)
class MachineState:
    """The whole machine as the bus reports it."""

    axes: tuple[AxisState, ...]
    occupancy: BoolGrid  # (rows, cols)
    estop: bool


@dataclass(frozen=True)
class BusSettings:
    """Settings every backend shares (table [fieldbus] of the config)."""

    timeout: float = 5.0  # s: completion of a move
    io_timeout: float = 1.0  # s: one request on the bus
    reconnect_delay: float = 0.1  # s: first backoff
    reconnect_delay_max: float = 2.0  # s: backoff ceiling
    reconnect_attempts: int = 5  # before FieldbusConnectionError
    position_tolerance: int = 10  # micrometres (millidegrees) accepted on read-back
    poll_max: float = 0.01  # s: the longest wait between two reads while axes move


FIRST_POLL = 0.002  # s: the first wait between two reads of a move under way


def poll_waits(most: float) -> Iterator[float]:
    """The waits between the reads of a move under way: 2 ms, doubling up to ``most``. A
    short move is seen done within a few ms; a long stroke costs the bus (and the loom's
    server) a read every ``most``, not every 2 ms."""
    wait = min(FIRST_POLL, most)
    while True:
        yield wait
        wait = min(wait * 2, most)


class Fieldbus(ABC):
    """Async access to the machine's actuators over one bus."""

    def __init__(self, machine: Machine, settings: BusSettings) -> None:
        self.machine = machine
        self.settings = settings
        self.axes = machine_axes(machine)
        self._seq = [0] * len(self.axes)
        self._expected: dict[int, int] = {}
        self._setpoints: dict[int, int] = {}  # the last set-point written, by axis
        self._connected = False
        self._seeded = False
        self._known = [AxisState(0, False, 0, 0, 0)] * len(self.axes)
        self.owner_id = process_owner_id()  # the daemon sets its own (one per state folder)
        self.holds = False  # claim the loom on connecting, not only before moving (the daemon)
        self._claimed_at: float | None = None

    # ----- hooks for a backend -----
    @abstractmethod
    async def _open(self) -> None:
        """Open the connection (raise FieldbusConnectionError when it cannot)."""

    @abstractmethod
    async def _close(self) -> None:
        """Close the connection; never raises."""

    @abstractmethod
    async def _write_setpoint(self, axis: Axis, target: int, seq: int) -> None:
        """Send one set-point with its sequence number and start it."""

    @abstractmethod
    async def _read_state(self, axes: Sequence[int] | None = None) -> MachineState:
        """Read the axes ``axes`` (every axis when None), the occupancy sensors and the e-stop.

        A backend may read only the axes asked for and build the rest with ``_merge``.
        """

    @abstractmethod
    async def _quick_stop(self) -> None:
        """Stop every axis at once."""

    @abstractmethod
    async def _reset_faults(self) -> None:
        """Clear latched faults on every axis."""

    @abstractmethod
    async def _home(self) -> None:
        """Start homing every axis."""

    @abstractmethod
    async def _claim(self, ident: int, pid: int) -> tuple[int, int] | None:
        """Claim the loom for ``ident`` (pid 0: let it go); the holder's (id, pid) when the
        loom refuses, None when granted (or when the bus has no claim)."""

    # ----- shared behaviour -----
    async def connect(self) -> None:
        """Connect, retrying with exponential backoff.

        On the first connection the sequence numbers go on from what the axes report as
        done, so a restarted daemon never reuses a number an axis has already completed.
        """
        delay = self.settings.reconnect_delay
        attempts = max(1, self.settings.reconnect_attempts)
        for attempt in range(attempts):
            try:
                await self._open()
                break
            except FieldbusConnectionError as exc:
                if attempt == attempts - 1:
                    raise FieldbusConnectionError(f"cannot reach the bus: {exc}") from exc
                await asyncio.sleep(delay)
                delay = min(2 * delay, self.settings.reconnect_delay_max)
        self._connected = True
        self._claimed_at = None  # a restarted loom has forgotten it
        if not self._seeded:
            state = await self._read_state()
            self._seq = [axis.done_seq for axis in state.axes]
            self._seeded = True
        if self.holds:
            await self.claim()

    @property
    def connected(self) -> bool:
        """Connected at least once and not closed since (the link may still have dropped)."""
        return self._connected

    async def close(self) -> None:
        """Let the claim go (when the loom still answers) and close."""
        claimed, self._claimed_at = self._claimed_at, None
        if claimed is not None and self._connected:
            with contextlib.suppress(FieldbusError, OSError, asyncio.TimeoutError):
                await asyncio.wait_for(self._claim(self.owner_id, 0), self.settings.io_timeout)
        self._connected = False
        await self._close()

    async def claim(self) -> None:
        """Hold the loom for this client before a command that moves it (renewed when older
        than CLAIM_RENEW); BusHeld names the holder when another client has it."""
        if self._claimed_at is not None and time.monotonic() - self._claimed_at < CLAIM_RENEW:
            return
        held = await self._claim(self.owner_id, os.getpid())
        if held is not None:
            raise BusHeld(
                f"the loom is held by another client: pid {held[1]} (claim id "
                f"{held[0]:08x}; a claim lapses {OWNER_LEASE:g} s after its holder's "
                "last); nothing was moved"
            )
        self._claimed_at = time.monotonic()

    async def move(self, moves: Sequence[AxisMove]) -> None:
        """Start every move at once.

        The drives refuse a set-point while the e-stop is pressed; ``wait`` reports it.
        """
        if not self._seeded:
            await self.connect()  # the sequence numbers go on from the axes' own
        await self.claim()
        setpoints = []
        for move in moves:
            axis = self.axes[move.axis]
            self._seq[move.axis] = (self._seq[move.axis] + 1) % 0x8000 or 1
            self._expected[move.axis] = 0 if axis.relative else move.target
            self._setpoints[move.axis] = move.target
            setpoints.append((axis, move.target, self._seq[move.axis]))
        await self._write_setpoints(setpoints)

    async def _write_setpoints(self, setpoints: Sequence[tuple[Axis, int, int]]) -> None:
        """Send the set-points (axis, target, sequence) one after the other; a backend may
        send them together."""
        for axis, target, seq in setpoints:
            await self._write_setpoint(axis, target, seq)

    async def wait(self, axes: Sequence[int], timeout: float | None = None) -> MachineState:
        """Wait until every axis in ``axes`` completed its last set-point; check the read-back."""
        limit = time.monotonic() + (self.settings.timeout if timeout is None else timeout)
        waits = poll_waits(self.settings.poll_max)
        while True:
            state = await self._read_state(axes)
            self._check(state, axes)
            if all(state.axes[i].done_seq == self._seq[i] and not state.axes[i].busy for i in axes):
                self._check_positions(state, axes)
                return state
            if time.monotonic() > limit:
                late = [self.axes[i].name for i in axes if state.axes[i].done_seq != self._seq[i]]
                raise FieldbusTimeout(
                    f"axes {', '.join(late)} did not complete in time", lost=False
                )
            await asyncio.sleep(next(waits))

    async def rest(self, timeout: float | None = None) -> MachineState:
        """The machine once no axis moves: a drive takes no set-point while it moves, so a
        command that moves after a stop (a resume) waits for a stroke still under way to end.
        FieldbusTimeout names the axes still moving after ``timeout`` (the move timeout)."""
        wait = self.settings.timeout if timeout is None else timeout
        limit = time.monotonic() + wait
        waits = poll_waits(self.settings.poll_max)
        while True:
            state = await self.state()
            moving = [self.axes[i].name for i, axis in enumerate(state.axes) if axis.busy]
            if not moving:
                return state
            if time.monotonic() > limit:
                raise FieldbusTimeout(
                    f"axes {', '.join(moving)} still move after {wait:g} s",
                    lost=False,
                )
            await asyncio.sleep(next(waits))

    async def execute(
        self, moves: Sequence[AxisMove], timeout: float | None = None
    ) -> MachineState:
        """Start the moves and wait for all of them."""
        await self.move(moves)
        return await self.wait([m.axis for m in moves], timeout)

    def setpoint(self, axis: int) -> int | None:
        """The last set-point this client wrote to axis ``axis`` (a stroke for a relative
        axis, a position for an absolute one; 0 after homing); None when it wrote none."""
        return self._setpoints.get(axis)

    def known(self, axis: int) -> AxisState:
        """What axis ``axis`` reported at the last read (nothing is read now)."""
        return self._known[axis]

    async def state(self) -> MachineState:
        """The machine as the bus reports it now (a held claim is renewed when due)."""
        if self._claimed_at is not None:
            await self.claim()
        return await self._read_state()

    async def quick_stop(self) -> None:
        """Stop every axis; never refused for want of the claim."""
        await self._quick_stop()

    async def reset_faults(self) -> None:
        await self.claim()
        await self._reset_faults()

    async def home(self, timeout: float | None = None) -> MachineState:
        """Home the shift and weft axes and wait for them (the take-up keeps its position)."""
        await self.claim()
        await self._home()
        homed = [axis.index for axis in self.axes if axis.kind != "takeup"]
        for i in homed:
            self._seq[i] = 0
            self._expected[i] = 0
            self._setpoints[i] = 0
        return await self.wait(homed, timeout)

    def _merge(self, read: dict[int, AxisState], occupancy: BoolGrid, estop: bool) -> MachineState:
        """A whole machine state from the axes just read and the last known of the others."""
        for i, axis in read.items():
            self._known[i] = axis
        return MachineState(axes=tuple(self._known), occupancy=occupancy, estop=estop)

    def _check(self, state: MachineState, axes: Sequence[int]) -> None:
        if state.estop:
            raise EStopError("emergency stop is pressed")
        for i in axes:
            if state.axes[i].fault:
                raise DriveFault(self.axes[i], state.axes[i].fault)

    def _check_positions(self, state: MachineState, axes: Sequence[int]) -> None:
        tol = self.settings.position_tolerance
        for i in axes:
            want = self._expected.get(i)
            got = state.axes[i].position
            if want is not None and abs(got - want) > tol:
                raise DriveFault(self.axes[i], FAULT_POSITION, f"at {got}, commanded {want}")
