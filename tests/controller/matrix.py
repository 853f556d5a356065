"""The fault-injection matrix: each fault injected in each of Idle, Execute, Held and Stopped.

A cell runs the controller against the mock loom in its own process, over Modbus TCP, with
a real journal file: it brings the machine to the state, injects the fault, gives the
command the state calls for (Idle: Start; Held: Unhold; Stopped: Reset then Start with
resume; Execute: none) and waits until the controller has published a Fault and rests in
a state with commands accepted. Then the fault is cleared and the same program is resumed
to Complete; its skeleton must be the one the twin predicts for an uninterrupted run.
Used by tests/controller/test_fault_matrix.py and bench/faults.py (which times the cells).
"""

from __future__ import annotations

import asyncio
import logging
import signal
import sqlite3
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bwsd.controller.errors import ControllerError
from bwsd.controller.facade import Controller, Settings
from bwsd.controller.packml import ACTING, Command, State
from bwsd.controller.status import Event, Fault, InstructionDone
from bwsd.errors import BwsdError
from bwsd.fieldbus import open_bus
from bwsd.journal import Journal
from bwsd.program import parse_program
from bwsd.twin import simulate
from simulator_hw.control import request
from tests.support.fieldbus import Mock, client_config, start_mock

CYCLE = "ROW 1:+1 2:-1\nCOL 1:+1 2:-1\nROW 1:-1 2:+1\nCOL 1:-1 2:+1\nTAKEUP 2\n"
TEXT = f"YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 3\n{CYCLE}END\n"
FAULTS = (
    "mute",
    "drop",
    "loom killed",
    "stall",
    "drive fault",
    "wrong position",
    "e-stop",
    "full disk",
    "journal locked",
    "task raising",
)
STATES = (State.IDLE, State.EXECUTE, State.HELD, State.STOPPED)
SPEEDS = {"stroke_speed": 200.0, "takeup_speed": 200.0, "state_file": "loom.json"}
AFTER = 1  # the instruction done when a run is held, stopped or faulted
SETTLED = 10.0  # s a cell may take to publish its Fault and rest (a wedge, not a measure)
RESUMED = 60.0  # s the resume to Complete may take


@dataclass
class Cell:
    """What one cell showed."""

    fault: str
    state: State
    ended: State | None = None  # where it rested after the fault
    allowed: tuple[Command, ...] = ()  # (for the e-stop: once it is released)
    seconds: float = 0.0  # from the injection to the Fault and a state that rests
    faults: list[str] = field(default_factory=list)  # the Fault events' reasons
    logged: list[str] = field(default_factory=list)  # warnings and errors logged
    completed: bool = False
    same_skeleton: bool = False


class Rig:
    """The mock loom, the controller on it, its journal and what it published and logged."""

    def __init__(self, tmp: Path, speeds: dict[str, Any] = SPEEDS) -> None:
        self.tmp = tmp
        self.speeds = speeds
        self.mock: Mock = start_mock(tmp, speeds)
        self.events: list[tuple[float, Event]] = []
        self.records: list[tuple[float, logging.LogRecord]] = []
        self.other: sqlite3.Connection | None = None

    async def start(self) -> Controller:
        config = client_config("modbus", self.mock.ports)
        bus = open_bus(config)
        await bus.connect()
        self.journal = Journal.open(self.tmp / "journal.db")
        ctl = Controller(config.machine, bus, self.journal, settings=Settings(poll_interval=0.1))
        ctl.events.subscribe(lambda event: self.events.append((time.monotonic(), event)))
        await ctl.start()
        self.ctl = ctl
        return ctl

    def faults_since(self, since: float) -> list[str]:
        return [e.reason for t, e in self.events if t >= since and isinstance(e, Fault)]

    async def control(self, message: dict[str, Any]) -> None:
        answer = await request("127.0.0.1", self.mock.ports["control"], message)
        assert answer["ok"], answer

    async def done(self, index: int) -> None:
        """Until instruction ``index`` is done."""
        while not any(isinstance(e, InstructionDone) and e.index >= index for _, e in self.events):
            await asyncio.sleep(0.005)

    async def close(self) -> None:
        await self.ctl.close()
        await self.ctl.bus.close()
        self.journal.close()
        if self.other is not None:
            self.other.close()
        self.mock.stop()


class Records(logging.Handler):
    def __init__(self, rig: Rig) -> None:
        super().__init__(logging.WARNING)
        self.rig = rig

    def emit(self, record: logging.LogRecord) -> None:
        self.rig.records.append((time.monotonic(), record))


# ----- the faults -----
async def inject(rig: Rig, fault: str) -> None:
    if fault in ("mute", "drop"):
        await rig.control({"cmd": "fault", "kind": fault})
    elif fault == "loom killed":
        rig.mock.proc.send_signal(signal.SIGKILL)
        rig.mock.proc.wait(10)
    elif fault in ("stall", "drive fault", "wrong position"):
        kind = fault.split()[0] if fault != "wrong position" else "wrong_position"
        await rig.control({"cmd": "fault", "kind": kind, "axis": "row1"})
    elif fault == "e-stop":
        await rig.control({"cmd": "estop", "pressed": True})
    elif fault == "full disk":
        _refuse_writes(rig.journal, True)
    elif fault == "journal locked":
        rig.other = sqlite3.connect(rig.journal.path, isolation_level=None)
        rig.other.execute("BEGIN IMMEDIATE")
    elif fault == "task raising":
        _raise_once(rig.ctl)
    else:
        raise ValueError(fault)


async def clear(rig: Rig, fault: str) -> None:
    if fault == "loom killed":
        rig.mock.stop()
        rig.mock = start_mock(rig.tmp, rig.speeds, rig.mock.ports)
    elif fault == "e-stop":
        await rig.control({"cmd": "estop", "pressed": False})
    elif fault == "full disk":
        _refuse_writes(rig.journal, False)
    elif fault == "journal locked":
        assert rig.other is not None
        rig.other.execute("ROLLBACK")
    elif fault not in ("drop", "task raising"):
        await rig.control({"cmd": "clear"})


def _refuse_writes(journal: Journal, refused: bool) -> None:
    """The journal's disk full: every write refused (or taken again). Set on the journal's
    own connection, the one the daemon writes with: SQLite then refuses every write, as a
    full disk refuses the writes that need room (``query_only``; a limit on its pages would
    still take the records that fit in the room its pages have left)."""
    with journal._mutex:  # fault injection into the real file
        conn = journal._conn
        assert conn is not None  # the journal is open
        conn.execute(f"PRAGMA query_only = {int(refused)}")


def _raise_once(ctl: Controller) -> None:
    """The next read of the machine raises an error nothing expects (a bug's stand-in)."""
    real = ctl.bus.state

    async def state() -> Any:
        ctl.bus.state = real  # type: ignore[method-assign]  # the real read again
        raise RuntimeError("injected: an error nothing expects")

    ctl.bus.state = state  # type: ignore[method-assign]  # the fault, injected once


# ----- one cell -----
async def reach(rig: Rig, state: State) -> None:
    """Load the program and bring the controller to ``state``."""
    ctl = rig.ctl
    await ctl.load("braid.bws", TEXT)
    await ctl.command(Command.RESET)
    if state is State.IDLE:
        return
    await ctl.command(Command.START)
    await rig.done(AFTER)
    if state is State.HELD:
        await ctl.command(Command.HOLD)
    elif state is State.STOPPED:
        await ctl.command(Command.STOP)
        await ctl.wait()
    assert ctl.packml.state is state, (state, ctl.packml.state, ctl.packml.reason)


async def go(ctl: Controller, state: State) -> None:
    """The command the state calls for (a refusal is an answer too: nothing changes)."""
    steps: dict[State, list[tuple[Command, bool]]] = {
        State.IDLE: [(Command.START, False)],
        State.HELD: [(Command.UNHOLD, False)],
        State.STOPPED: [(Command.RESET, False), (Command.START, True)],
    }
    for command, resume in steps.get(state, []):
        try:
            await ctl.command(command, resume=resume)
        except BwsdError:
            return


async def settled(rig: Rig, since: float) -> float:
    """Seconds until a Fault is published and the state is one that waits for a command,
    with commands accepted (an exit), or Execute going on."""
    ctl = rig.ctl
    while True:
        now = time.monotonic()
        pressed = bool(ctl.seen.status.estop)  # then the exit is its release (Clear waits)
        acting = ctl.packml.state in ACTING  # it ends by itself (Aborting, Holding, ...)
        if rig.faults_since(since) and not acting and (ctl.allowed() or pressed):
            return now - since
        assert now - since < SETTLED, (ctl.packml.state, ctl.packml.reason, rig.faults_since(since))
        await asyncio.sleep(0.005)


async def resume(ctl: Controller) -> None:
    """Clear, reset, unhold or start with resume, whichever the state takes, to Complete."""
    deadline = time.monotonic() + RESUMED
    steps: dict[State, Callable[[], Awaitable[Any]]] = {
        State.HELD: lambda: ctl.command(Command.UNHOLD),
        State.SUSPENDED: lambda: ctl.command(Command.UNSUSPEND),
        State.ABORTED: lambda: ctl.command(Command.CLEAR),
        State.STOPPED: lambda: ctl.command(Command.RESET),
        State.IDLE: lambda: ctl.command(Command.START, resume=ctl.resumable()),
    }
    while ctl.packml.state is not State.COMPLETE and not complete(ctl):
        assert time.monotonic() < deadline, (ctl.packml.state, ctl.packml.reason)
        step = steps.get(ctl.packml.state)
        try:
            if step is not None:
                await step()
        except ControllerError:
            pass  # the machine is not read back yet, a journal write is retried: again
        await asyncio.sleep(0.05)


def complete(ctl: Controller) -> bool:
    """The program has run to its end (a Stop or an Abort that came after its last
    instruction leaves PackML there, and the program complete)."""
    return ctl.job is not None and ctl.job.ended == "complete"


async def run_cell(tmp: Path, fault: str, state: State) -> Cell:
    rig = Rig(tmp)
    cell = Cell(fault, state)
    handler = Records(rig)
    logging.getLogger("bwsd").addHandler(handler)
    try:
        ctl = await rig.start()
        await reach(rig, state)
        since = time.monotonic()
        await inject(rig, fault)
        commanding = asyncio.ensure_future(go(ctl, state))
        cell.seconds = await settled(rig, since)
        await commanding  # (a command waits for a locked journal: the Fault came first)
        cell.ended, cell.allowed = ctl.packml.state, tuple(ctl.allowed())
        cell.faults = rig.faults_since(since)
        cell.logged = [r.getMessage() for t, r in rig.records if t >= since]
        await clear(rig, fault)
        if fault == "e-stop":  # released: the machine is read again, and Clear is offered
            await ctl.read_machine()
            cell.allowed = tuple(ctl.allowed())
        await resume(ctl)
        await ctl.wait()
        cell.completed = complete(ctl)
        whole = simulate(ctl.machine, parse_program(TEXT))
        cell.same_skeleton = _bits(ctl.twin) == _bits(whole)
        answer = await request("127.0.0.1", rig.mock.ports["control"], {"cmd": "state"})
        assert ctl.twin is not None
        assert np.array_equal(np.array(answer["occupancy"], dtype=bool), ctl.twin.occupancy >= 0)
        record = rig.journal.program(ctl.program_id or 0)
        assert (record.outcome, record.done) == ("complete", 15), record
    finally:
        logging.getLogger("bwsd").removeHandler(handler)
        await rig.close()
    return cell


def _bits(twin: Any) -> list[Any]:
    sk = twin.skeleton()
    return [(y.node_ids.tobytes(), y.nodes.tobytes()) for y in sk.yarns] + list(sk.contacts)
