"""What the controller last saw of the machine: read, remembered, compared with the twin."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import replace

from bwsd.controller.recovery import differing_cells
from bwsd.controller.status import BusChanged, BusStatus, Event
from bwsd.fieldbus.base import (
    BoolGrid,
    EStopError,
    Fieldbus,
    FieldbusConnectionError,
    FieldbusError,
    MachineState,
)

log = logging.getLogger("bwsd.controller")


class MachineView:
    """The machine as last read over ``bus``; every change is published as ``BusChanged``."""

    def __init__(
        self,
        bus: Fieldbus,
        publish: Callable[[Event], None],
        worse: Callable[[BusStatus, BusStatus], None] | None = None,
    ) -> None:
        self.bus = bus
        self._publish = publish
        self._worse = worse  # told (old, new) when the machine is lost or its e-stop pressed
        self.status = BusStatus()
        self.last: MachineState | None = None
        self.last_at: float | None = None  # when ``last`` was read (epoch seconds)

    async def read(self) -> MachineState:
        """Read the machine now, connecting (again) if needed; FieldbusError when it cannot."""
        try:
            if not self.bus.connected:
                await self.bus.connect()
            try:
                return await self.bus.state()
            except FieldbusConnectionError as exc:
                self.failed(exc)  # lost, if only for a moment: said, then connected again
                await self.bus.connect()
                return await self.bus.state()
        except FieldbusError as exc:
            self.failed(exc)
            raise

    def failed(self, exc: FieldbusError) -> None:
        """A failure: lost (no answer, no connection) or answered (a fault, the e-stop)."""
        lost = exc.lost
        estop = True if isinstance(exc, EStopError) else self.status.estop
        self._set(
            replace(
                self.status,
                connected=not lost,
                last_error=str(exc),
                checked=time.time(),
                estop=estop,
            )
        )

    def observe(self, state: MachineState, twin: BoolGrid | None) -> None:
        """A good read; ``twin``: the twin's occupancy to compare with (None while moving)."""
        self.last, self.last_at = state, time.time()
        faulted = tuple(self.bus.axes[i].name for i, a in enumerate(state.axes) if a.fault)
        self._set(
            BusStatus(
                connected=True,
                last_error=None,
                checked=time.time(),
                estop=bool(state.estop),
                faulted=faulted,
                differs=self._differs(state, twin),
            )
        )

    def compare(self, twin: BoolGrid | None) -> None:
        """The twin changed at rest: compare it again with the last read."""
        if self.last is not None:
            self._set(replace(self.status, differs=self._differs(self.last, twin)))

    @staticmethod
    def _differs(state: MachineState, twin: BoolGrid | None) -> tuple[tuple[int, int], ...]:
        if twin is None:
            return ()
        if state.occupancy.shape != twin.shape:
            return ((-1, -1),)
        return tuple(differing_cells(state.occupancy, twin))

    def _set(self, status: BusStatus) -> None:
        old, self.status = self.status, status
        if replace(old, checked=None) != replace(status, checked=None):
            if status.estop != old.estop and None not in (status.estop, old.estop):
                log.warning("emergency stop %s", "pressed" if status.estop else "released")
            self._publish(BusChanged(status))
            lost = status.connected is False and old.connected is not False
            if (lost or (status.estop and not old.estop)) and self._worse is not None:
                self._worse(old, status)
