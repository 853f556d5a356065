"""What the OPC UA variables say, computed from the controller's status and events (pure).

No asyncua here: the door (bwsd.opcua.server) writes these values into its nodes. The times
and the rate are kept by ``Tally`` from the event stream; everything else, the production
counts included, is read from the one status snapshot.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

from bwsd.controller.packml import ACTING, State, completes_to
from bwsd.controller.status import StatusSnapshot

RATE_WINDOW = 60.0  # s: CurMachSpeed counts the instructions done in the last minute
STATES = len(State) + 1  # StateCumulativeTime is indexed by the state's number (0 unused)


@dataclass
class Tally:
    """Time per state and the instruction rate, since the door started."""

    started: float  # when the door started (monotonic s)
    state: State = State.STOPPED
    entered: float = 0.0  # when ``state`` was entered (monotonic s)
    cumulative: list[float] = field(default_factory=lambda: [0.0] * STATES)
    _done: deque[float] = field(default_factory=deque)  # when each recent instruction ended

    def __post_init__(self) -> None:
        self.entered = self.started

    def state_changed(self, new: State, now: float) -> None:
        """A transition: close the old state's time."""
        self.cumulative[self.state] += now - self.entered
        self.state, self.entered = new, now

    def instruction_done(self, now: float) -> None:
        self._done.append(now)
        self._forget(now)

    def speed(self, now: float) -> float:
        """Instructions per minute, over the last RATE_WINDOW seconds."""
        self._forget(now)
        return len(self._done) * 60.0 / RATE_WINDOW

    def times(self, now: float) -> list[float]:
        """Seconds spent in each state (by number) up to ``now``."""
        out = list(self.cumulative)
        out[self.state] += now - self.entered
        return out

    def _forget(self, now: float) -> None:
        while self._done and self._done[0] < now - RATE_WINDOW:
            self._done.popleft()


def warnings(st: StatusSnapshot) -> list[str]:
    """What an operator should know that does not stop the machine by itself (yet)."""
    found = []
    bus = st.bus
    if bus.estop:
        found.append("the emergency stop is pressed")
    if bus.connected is False:
        found.append(f"the machine cannot be read: {bus.last_error}")
    if bus.faulted:
        found.append(f"axes report a fault: {', '.join(bus.faulted)}")
    if bus.differs:
        found.append(f"the occupancy sensors differ from the twin at {len(bus.differs)} cells")
    if st.recovering:
        found.append(f"recovering: {st.recovering}")
    return found


def status_values(st: StatusSnapshot, tally: Tally, now: float) -> dict[str, Any]:
    """Every variable read from the status snapshot and the tally, by its path."""
    step = st.next or {}
    return {
        "Status/StateCurrent": int(st.state),
        "Status/StateRequested": int(requested(st.state)),
        "Status/StateChangeInProcess": st.state in ACTING,
        "Status/UnitModeRequested": int(st.mode_requested),
        "Status/UnitModeCurrent": int(st.mode),
        "Status/CurMachSpeed": tally.speed(now),
        "Status/InstructionsDone": st.index,
        "Status/InstructionCount": st.count,
        "Status/CurrentInstruction": int(step.get("index", 0)),
        "Status/CurrentLine": int(step.get("line", 0)),
        "Status/Program": st.program_name or "",
        "Status/ProgramId": st.program_id or 0,
        "Admin/StopReason/ID": int(st.stop_cause),
        "Admin/StopReason/Value": st.stop_cause.label,
        "Admin/StopReason/Message": st.reason,
        "Admin/Warning": warnings(st),
        "Admin/StateCurrentTime": now - tally.entered,
        "Admin/StateCumulativeTime": tally.times(now),
        "Admin/AccTimeSinceReset": now - tally.started,
        "Admin/ProdProcessedCount": st.good + st.defective,
        "Admin/ProdGoodCount": st.good,
        "Admin/ProdDefectiveCount": st.defective,
        "Machine/EStop": bool(st.bus.estop),
        "Machine/BusConnected": bool(st.bus.connected),
        "Machine/BusLastError": st.bus.last_error or "",
        "Machine/FaultedAxes": list(st.bus.faulted),
        "Machine/SensorsDiffer": [f"{r},{c}" for r, c in st.bus.differs],
        "Machine/Recovering": st.recovering,
        "Status/Resumable": st.resumable,
    }


def history_lines(records: list[Any]) -> list[str]:
    """The program history summary: ``"12 braid.bws complete 20/20"``, newest first."""
    return [f"{r.id} {r.name} {r.outcome} {r.done}/{r.instructions}" for r in records]


def requested(state: State) -> State:
    """Where the machine is going: the state an acting state ends in, else the state."""
    return completes_to(state) or state
