"""Routes of the running machine: state, the machine's read-back, commands, preview."""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from typing import Any

from fastapi import Depends

from bwsd.controller.packml import WAITING, Command, InvalidCommand, PackML, State
from bwsd.controller.plan import Limits, RefusedMove, check_limits
from bwsd.controller.runner import ControllerError
from bwsd.errors import TwinError
from bwsd.fieldbus import FieldbusError
from bwsd.fieldbus.base import FAULT_NAMES
from bwsd.journal import JournalError
from bwsd.twin import Machine, Prediction, Program, replay

from .auth import require
from .context import Ctx
from .models import (
    AUTH_ERRORS,
    BODY_ERRORS,
    INVALID,
    AxisOut,
    CommandErrorOut,
    CommandIn,
    CommandName,
    CommandOut,
    ContactOut,
    Error,
    FreeNodeOut,
    LengthOut,
    MachineOut,
    NextOut,
    NodeOut,
    PreviewOut,
    StateOut,
)
from .problems import ApiError, describe
from .routing import RouteTable
from .view import instruction_dict, next_step

router = RouteTable()
READ = [Depends(require("viewer"))]
WRITE = [Depends(require("operator"))]
_RUNS = frozenset({Command.START, Command.UNHOLD, Command.UNSUSPEND})


def _next_out(step: dict[str, Any] | None) -> NextOut | None:
    return NextOut(**step) if step is not None else None


def command_names(commands: Iterable[Command]) -> list[str]:
    return [c.name.lower() for c in commands]


@router.get("/state", response_model=StateOut, dependencies=READ, responses=AUTH_ERRORS)
async def get_state(ctx: Ctx) -> StateOut:
    """PackML state and mode, the loaded program and how far it is, the bus's health."""
    ctl = ctx.controller
    name = await ctx.program_name(ctl.program_id)
    name = await ctx.program_name(ctl.program_id)  # the same, unless a load came meanwhile
    pk, program = ctl.packml, ctl.program
    return StateOut(
        state=int(pk.state),
        name=pk.state.label,
        mode=int(pk.mode),
        mode_name=pk.mode.label,
        program_id=ctl.program_id,
        program_name=name,
        index=ctl.index,
        count=len(program.instructions) if program is not None else 0,
        reason=pk.reason,
        allowed=command_names(pk.allowed()),
        bus=ctx.health.out(),
        last_fault=ctx.last_fault,
        next=_next_out(next_step(ctl)),
    )


@router.get("/machine", response_model=MachineOut, dependencies=READ,
            responses={**AUTH_ERRORS, 503: {"model": Error}})  # fmt: skip
async def get_machine(ctx: Ctx) -> MachineOut:
    """The axes, occupancy sensors and e-stop as the bus reports them now."""
    bus = ctx.controller.bus
    try:
        state = await bus.state()
    except FieldbusError as exc:
        ctx.health.failed(exc)
        raise ApiError(503, f"the bus cannot be read: {exc}") from None
    ctx.health.ok()
    axes = [
        AxisOut(
            index=axis.index,
            name=axis.name,
            kind=axis.kind,
            position=got.position,
            busy=got.busy,
            fault=got.fault,
            fault_name=FAULT_NAMES.get(got.fault, f"fault {got.fault}"),
        )
        for axis, got in zip(bus.axes, state.axes, strict=True)
    ]
    sk = await ctx.view.current()
    return MachineOut(
        axes=axes,
        occupancy=state.occupancy.tolist(),
        estop=state.estop,
        twin_occupancy=sk.occupancy.tolist() if sk is not None else None,
    )


@router.post("/commands/{name}", response_model=CommandOut, dependencies=WRITE,
             responses={**AUTH_ERRORS, **INVALID, **BODY_ERRORS,
                        409: {"model": CommandErrorOut}})  # fmt: skip
async def post_command(name: CommandName, ctx: Ctx, body: CommandIn | None = None) -> CommandOut:
    """Send a PackML command; answers once the acting state it enters has done its work."""
    ctl = ctx.controller
    command = Command[name.upper()]
    if command in _RUNS and ctl.packml.state in WAITING:
        await ctx.view.current()  # a fresh copy, so the run's first event is a small delta
    try:
        await ctl.command(command, body.reason if body is not None else "")
    except InvalidCommand as exc:
        raise _refused(str(exc), exc.state, exc.allowed) from None
    except (ControllerError, JournalError) as exc:
        raise _refused(describe(exc), ctl.packml.state, ctl.packml.allowed()) from None
    return _command_out(ctl.packml)


def _refused(message: str, state: State, allowed: Iterable[Command]) -> ApiError:
    return ApiError(409, message, state=state.label, allowed=command_names(allowed))


def _command_out(pk: PackML) -> CommandOut:
    return CommandOut(state=int(pk.state), name=pk.state.label, reason=pk.reason,
                      allowed=command_names(pk.allowed()))  # fmt: skip


@router.post("/preview", response_model=PreviewOut, dependencies=WRITE,
             responses={**AUTH_ERRORS, 409: {"model": Error}})  # fmt: skip
async def post_preview(ctx: Ctx) -> PreviewOut:
    """Dry-run the next instruction on a copy of the twin (the controller's is not touched)."""
    ctl = ctx.controller
    program, twin = ctl.program, ctl.twin
    if program is None or twin is None:
        raise ApiError(409, "no program is loaded")
    done = twin.done
    if done >= len(program.instructions):
        raise ApiError(409, f"all {len(program.instructions)} instructions are done")
    return await asyncio.to_thread(preview, ctl.machine, program, done, ctl.limits)


def preview(machine: Machine, program: Program, done: int, limits: Limits) -> PreviewOut:
    """Instruction ``done + 1`` predicted on a twin replayed aside, checked against ``limits``."""
    instruction = program.instructions[done]
    line = program.lines[done] if done < len(program.lines) else 0
    twin = replay(machine, program, done)
    try:
        pred = twin.predict(instruction)
    except TwinError as exc:
        return PreviewOut(index=done + 1, line=line, instruction=instruction_dict(instruction),
                          refused=str(exc), contacts=[], inserted=[], free_nodes=[],
                          occupancy=twin.occupancy.tolist(), takeup=twin.takeup, new_yarns=[],
                          length_change=[])  # fmt: skip
    try:
        check_limits(pred, limits)
        refused = None
    except RefusedMove as exc:
        refused = str(exc)
    return _preview_out(pred, line, refused)


def _preview_out(pred: Prediction, line: int, refused: str | None) -> PreviewOut:
    return PreviewOut(
        index=pred.index,
        line=line,
        instruction=instruction_dict(pred.instruction),
        refused=refused,
        contacts=[
            ContactOut(yarns=(c.moving_yarn, c.hit_yarn), nodes=(c.moving_node, c.hit_node))
            for c in pred.contacts
        ],
        inserted=[
            NodeOut(yarn=n.yarn, node=n.node, after=n.after, xyz=n.xyz) for n in pred.inserted
        ],
        free_nodes=[FreeNodeOut(yarn=y, xyz=xyz) for y, xyz in sorted(pred.free_nodes.items())],
        occupancy=pred.occupancy.tolist(),
        takeup=pred.takeup,
        new_yarns=list(pred.new_yarns),
        length_change=[LengthOut(yarn=y, change=c) for y, c in sorted(pred.length_change.items())],
    )
