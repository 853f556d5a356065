"""`bwsd hw`: commissioning commands a technician runs at the loom.

    bwsd hw status --config C          axes, positions, faults, occupancy grid, e-stop
    bwsd hw shift row|col LINE K --config C
    bwsd hw shift row|col 'LINE[FIRST..LAST]' K --config C   a segment's own actuator
    bwsd hw takeup MM --config C       advance the take-up by MM millimetres
    bwsd hw reset --config C           clear faults and home the shift and weft axes

Each exits non-zero with a clear message on any fault (status too, when an axis is faulted
or the e-stop is pressed). The commands that move (shift, takeup, reset) refuse while a
`bwsd serve` holds the bus, naming it: its lock in the state folder (found as `bwsd serve`
finds it: ``--state-dir``, else the config's ``[daemon] state_dir``), and its claim on the
loom. ``status`` only reads and stays allowed.
"""

from __future__ import annotations

import argparse
import asyncio
import re
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.console import Console

    from bwsd.fieldbus import Fieldbus, MachineState
    from bwsd.twin.machine import Machine

Action = Callable[["Fieldbus", argparse.Namespace], Awaitable["MachineState"]]
_LINE = re.compile(
    r"\s*([0-9]{1,6})\s*(?:\[\s*([0-9]{1,6})\s*\.\.\s*([0-9]{1,6})\s*\])?\s*", re.ASCII
)


def shift_line(text: str) -> tuple[int, tuple[int, int] | None]:
    """A LINE argument: ``3`` (the whole line) or ``3[0..3]`` (a segment of it)."""
    match = _LINE.fullmatch(text)
    if match is None:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a line (3) or a segment of one (3[0..3])"
        )
    span = None if match[2] is None else (int(match[2]), int(match[3]))
    return int(match[1]), span


def configure(sub: Any) -> None:
    """Register `bwsd hw` and its commands."""
    hw = sub.add_parser("hw", help="commissioning: talk to the loom's actuators directly")
    cmds = hw.add_subparsers(dest="hw_command", required=True)
    status = cmds.add_parser("status", help="axes, positions, faults and the occupancy grid")
    shift = cmds.add_parser("shift", help="shift one row or column, or a segment, by K cells")
    shift.add_argument("axis", choices=["row", "col"])
    shift.add_argument(
        "line",
        type=shift_line,
        metavar="LINE",
        help="a line (3) or a declared segment of one ('3[0..3]', quoted)",
    )
    shift.add_argument("cells", type=int)
    takeup = cmds.add_parser("takeup", help="advance the take-up by MM millimetres")
    takeup.add_argument("mm", type=float)
    reset = cmds.add_parser("reset", help="clear faults and home the shift and weft axes")
    for parser, action in ((status, _status), (shift, _shift), (takeup, _takeup), (reset, _reset)):
        parser.add_argument("--config", required=True, help="machine config (TOML)")
        parser.add_argument(
            "--state-dir",
            help="the daemon's state folder, whose bus lock is checked (default: the config's "
            "[daemon] state_dir)",
        )
        parser.set_defaults(handler=lambda args, act=action: _run(args, act))


def _run(args: argparse.Namespace, action: Action) -> int:
    from rich.console import Console

    from bwsd.config import load_config
    from bwsd.fieldbus.owner import refuse_if_held
    from bwsd.paths import state_folder

    config = load_config(args.config)
    if action is not _status:
        refuse_if_held(state_folder(config, args.state_dir, create=False))
    state = asyncio.run(_session(config, args, action))
    _print(config.machine, state, Console())
    faulted = [i for i, axis in enumerate(state.axes) if axis.fault]
    if state.estop or faulted:
        Console(stderr=True).print("[red]loom not ready: e-stop or faulted axes[/red]")
        return 1
    return 0


async def _session(config: Any, args: argparse.Namespace, action: Action) -> MachineState:
    from bwsd.fieldbus import open_bus

    bus = open_bus(config)
    await bus.connect()
    try:
        return await action(bus, args)
    finally:
        await bus.close()


async def _status(bus: Fieldbus, args: argparse.Namespace) -> MachineState:
    return await bus.state()


async def _shift(bus: Fieldbus, args: argparse.Namespace) -> MachineState:
    from bwsd.fieldbus import AxisMove, FieldbusError
    from bwsd.fieldbus.axes import segment_axis_name, shift_stroke_um

    line, span = args.line
    name = f"{args.axis}{line}" if span is None else segment_axis_name(args.axis, line, span)
    axis = _axis(bus, name)
    if args.cells == 0:
        raise FieldbusError("a shift of 0 cells does nothing")
    stroke = shift_stroke_um(bus.machine, axis, args.cells)
    return await bus.execute([AxisMove(axis.index, stroke)])


async def _takeup(bus: Fieldbus, args: argparse.Namespace) -> MachineState:
    from bwsd.fieldbus import AxisMove, FieldbusError
    from bwsd.fieldbus.axes import UM_PER_MM

    if args.mm <= 0:
        raise FieldbusError("the take-up only advances: MM must be positive")
    axis = _axis(bus, "takeup")
    now = (await bus.state()).axes[axis.index].position
    return await bus.execute([AxisMove(axis.index, now + round(args.mm * UM_PER_MM))])


async def _reset(bus: Fieldbus, args: argparse.Namespace) -> MachineState:
    await bus.reset_faults()
    return await bus.home()


def _axis(bus: Fieldbus, name: str) -> Any:
    from bwsd.fieldbus import FieldbusError
    from bwsd.fieldbus.axes import axis_by_name

    try:
        return axis_by_name(bus.machine, name)
    except ValueError as exc:
        raise FieldbusError(str(exc)) from None


def _print(machine: Machine, state: MachineState, console: Console) -> None:
    from rich.markup import escape
    from rich.table import Table

    from bwsd.fieldbus.axes import machine_axes
    from bwsd.fieldbus.base import FAULT_NAMES

    table = Table(title="axes")
    for column in ("axis", "position", "busy", "fault", "last stroke"):
        table.add_column(column)
    for axis, report in zip(machine_axes(machine), state.axes, strict=True):
        fault = FAULT_NAMES.get(report.fault, str(report.fault)) if report.fault else ""
        busy = "yes" if report.busy else ""
        table.add_row(escape(axis.name), str(report.position), busy, fault, str(report.last_stroke))
    console.print(table)
    grid = "\n".join("".join("X" if v else "." for v in row) for row in state.occupancy)
    console.print(f"occupancy (row 0 first):\n{grid}")
    console.print(f"e-stop: {'PRESSED' if state.estop else 'released'}")
