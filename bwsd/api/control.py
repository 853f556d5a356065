"""Routes of the running machine: state, the machine's read-back, commands, preview."""

from __future__ import annotations

import time
from collections.abc import Iterable
from typing import Annotated, Any

from fastapi import Depends, Query, Request

from bwsd.controller.errors import ControllerError
from bwsd.controller.facade import Controller
from bwsd.controller.packml import Command, InvalidCommand, PackMLError, State
from bwsd.controller.programs import instruction_dict, step_dict
from bwsd.fieldbus.base import FAULT_NAMES, FieldbusError, MachineState
from bwsd.gate import Caller, Gate, Refused
from bwsd.journal import JournalError
from bwsd.twin import Prediction

from .auth import Principal, require
from .context import Ctx
from .models import (
    AUTH_ERRORS,
    BODY_ERRORS,
    INVALID,
    AxisOut,
    BusHealth,
    CommandErrorOut,
    CommandIn,
    CommandName,
    CommandOut,
    ContactOut,
    Error,
    FreeNodeOut,
    LengthOut,
    MachineOut,
    ManualIn,
    ManualOut,
    ModeIn,
    ModeOut,
    NextOut,
    NodeOut,
    PreviewOut,
    StateOut,
    WhoOut,
)
from .problems import ApiError, describe, refused
from .routing import RouteTable

router = RouteTable()
READ = [Depends(require("viewer"))]
WRITE = [Depends(require("operator"))]
Operator = Annotated[Principal, Depends(require("operator"))]
Admin = Annotated[Principal, Depends(require("admin"))]
Viewer = Annotated[Principal, Depends(require("viewer"))]


def _next_out(step: dict[str, Any] | None) -> NextOut | None:
    return NextOut(**step) if step is not None else None


def command_names(commands: Iterable[Command]) -> list[str]:
    return [c.name.lower() for c in commands]


@router.get("/state", response_model=StateOut, dependencies=READ, responses=AUTH_ERRORS)
async def get_state(ctx: Ctx) -> StateOut:
    """PackML state and mode, the loaded program and how far it is, the machine as last read."""
    st = ctx.controller.status()
    bus = st.bus
    return StateOut(
        state=int(st.state),
        name=st.state.label,
        mode=int(st.mode),
        mode_name=st.mode.label,
        program_id=st.program_id,
        program_name=st.program_name,
        index=st.index,
        count=st.count,
        reason=st.reason,
        stop_cause=st.stop_cause.label,
        allowed=command_names(st.allowed),
        recovering=st.recovering,
        resumable=st.resumable,
        resume_allowed=st.resume_allowed,
        manual=st.manual,
        bus=BusHealth(
            connected=bus.connected,
            last_error=bus.last_error,
            checked=bus.checked,
            estop=bus.estop,
            faulted=list(bus.faulted),
            differs=list(bus.differs),
        ),
        last_fault=ctx.last_fault,
        next=_next_out(step_dict(st.next)),
    )


@router.get("/whoami", response_model=WhoOut, responses=AUTH_ERRORS)
async def get_whoami(who: Viewer) -> WhoOut:
    """Whose token this is and its role: a client learns what it may do before it tries."""
    return WhoOut(name=who.name, role=who.role)


@router.get(
    "/machine",
    response_model=MachineOut,
    dependencies=READ,
    responses={**AUTH_ERRORS, 503: {"model": Error}},
)
async def get_machine(
    ctx: Ctx,
    last: Annotated[
        bool, Query(description="the last read (no request on the bus; a lost bus too)")
    ] = False,
) -> MachineOut:
    """The axes, occupancy sensors and e-stop as the bus reports them now, or (``last``) as
    it last reported them: what a display polls, adding nothing to the bus's traffic."""
    ctl = ctx.controller
    state, at = ctl.seen.last, ctl.seen.last_at
    if last and state is not None and at is not None:  # none yet: it is read now
        return await _machine_out(ctx, state, at, ctl.seen.status.connected is True)
    try:
        state = await ctl.read_machine()
    except ControllerError as exc:
        raise ApiError(503, str(exc)) from None
    return await _machine_out(ctx, state, ctl.seen.last_at or time.time(), True)


async def _machine_out(
    ctx: Ctx, state: MachineState, read_at: float, connected: bool
) -> MachineOut:
    ctl = ctx.controller
    axes = [
        AxisOut(
            index=axis.index,
            name=axis.name,
            kind=axis.kind,
            position=got.position,
            setpoint=ctl.bus.setpoint(axis.index),
            relative=axis.relative,
            busy=got.busy,
            fault=got.fault,
            fault_name=FAULT_NAMES.get(got.fault, f"fault {got.fault}"),
        )
        for axis, got in zip(ctl.axes, state.axes, strict=True)
    ]
    sk = await ctx.view.current()
    return MachineOut(
        axes=axes,
        occupancy=state.occupancy.tolist(),
        estop=state.estop,
        twin_occupancy=sk.occupancy.tolist() if sk is not None else None,
        read_at=read_at,
        connected=connected,
    )


@router.post(
    "/commands/{name}",
    response_model=CommandOut,
    responses={**AUTH_ERRORS, **INVALID, **BODY_ERRORS, 409: {"model": CommandErrorOut}},
)
async def post_command(
    name: CommandName, ctx: Ctx, who: Operator, request: Request, body: CommandIn | None = None
) -> CommandOut:
    """Send a PackML command; answers once the acting state it enters has done its work."""
    ctl = ctx.controller
    gate: Gate = request.app.state.gate
    reason, resume = (body.reason, body.resume) if body is not None else ("", False)
    try:
        await gate.command(
            Caller("rest", who.name, who.token, who.role), name, reason=reason, resume=resume
        )
    except Refused as exc:
        raise refused(exc) from None
    except InvalidCommand as exc:
        raise _refused(str(exc), exc.state, ctl.allowed()) from None
    except (ControllerError, JournalError) as exc:
        raise _refused(describe(exc), ctl.status().state, ctl.allowed()) from None
    return _command_out(ctl)


@router.put(
    "/mode",
    response_model=ModeOut,
    responses={**AUTH_ERRORS, **INVALID, **BODY_ERRORS, 409: {"model": Error}},
)
async def put_mode(body: ModeIn, ctx: Ctx, who: Admin, request: Request) -> ModeOut:
    """Change the unit mode (PackML allows it in Stopped, Idle and Aborted); needs admin."""
    ctl = ctx.controller
    gate: Gate = request.app.state.gate
    try:
        await gate.set_mode(Caller("rest", who.name, who.token, who.role), body.mode)
    except Refused as exc:
        raise refused(exc) from None
    except PackMLError as exc:
        raise ApiError(409, str(exc)) from None
    mode = ctl.status().mode
    return ModeOut(mode=int(mode), mode_name=mode.label)


@router.post(
    "/manual",
    response_model=ManualOut,
    responses={
        **AUTH_ERRORS,
        **INVALID,
        **BODY_ERRORS,
        409: {"model": Error},
        503: {"model": Error},
    },
)
async def post_manual(body: ManualIn, ctx: Ctx, who: Operator, request: Request) -> ManualOut:
    """A manual move: one stroke of a shift axis, a take-up or a fault reset, in unit mode
    Manual or Maintenance with the machine at rest (``manual`` in the state says why not)."""
    gate: Gate = request.app.state.gate
    caller = Caller("rest", who.name, who.token, who.role)
    try:
        move, state = await gate.manual(
            caller, body.kind, axis=body.axis, step=body.step, length=body.length
        )
    except Refused as exc:
        raise refused(exc) from None
    except FieldbusError as exc:
        raise ApiError(503 if exc.lost else 409, f"the manual move failed: {exc}") from None
    except (ControllerError, JournalError) as exc:
        raise ApiError(409, describe(exc)) from None
    return ManualOut(done=move.text(), machine=await _machine_out(ctx, state, time.time(), True))


def _refused(message: str, state: State, allowed: Iterable[Command]) -> ApiError:
    return ApiError(409, message, state=state.label, allowed=command_names(allowed))


def _command_out(ctl: Controller) -> CommandOut:
    st = ctl.status()
    return CommandOut(
        state=int(st.state),
        name=st.state.label,
        reason=st.reason,
        allowed=command_names(st.allowed),
    )


@router.post(
    "/preview",
    response_model=PreviewOut,
    dependencies=WRITE,
    responses={**AUTH_ERRORS, 409: {"model": Error}},
)
async def post_preview(ctx: Ctx) -> PreviewOut:
    """Predict the next instruction on the twin without committing it (nothing changes)."""
    try:
        found = await ctx.controller.preview()
    except ControllerError as exc:
        raise ApiError(409, str(exc)) from None
    if found.prediction is None:
        return PreviewOut(
            index=found.index,
            line=found.line,
            instruction=instruction_dict(found.instruction),
            refused=found.refused,
            contacts=[],
            inserted=[],
            free_nodes=[],
            occupancy=found.occupancy.tolist(),
            takeup=found.takeup,
            new_yarns=[],
            length_change=[],
        )
    return _preview_out(found.prediction, found.line, found.refused)


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
