"""Routes of the records: programs (load, history), the skeleton, the journal's logs."""

from __future__ import annotations

import asyncio
import json
import shutil
import tempfile
import threading
from collections.abc import Awaitable
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Literal, TypeVar

from fastapi import Depends, Query, Request
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, Response
from starlette.background import BackgroundTask

from bwsd.controller.errors import Busy, ControllerError
from bwsd.errors import ProgramError
from bwsd.export import ExportError, export
from bwsd.export.skeleton_json import skeleton_to_dict
from bwsd.gate import Caller, Gate, Refused
from bwsd.twin import SkeletonData

from .auth import Principal, require
from .context import Ctx
from .models import (
    AUTH_ERRORS,
    BODY_ERRORS,
    INVALID,
    Error,
    EventRecordOut,
    HistoryOut,
    InvalidOut,
    LoadedOut,
    LogLineOut,
    LogOut,
    OutcomeTotal,
    ProgramDetailOut,
    ProgramErrorOut,
    ProgramIn,
    ProgramOut,
    StateRecordOut,
    TotalsOut,
)
from .problems import ApiError, refused
from .routing import RouteTable

router = RouteTable()
READ = [Depends(require("viewer"))]
Operator = Annotated[Principal, Depends(require("operator"))]
T = TypeVar("T")
MAX_ID = 2**62  # ids are SQLite integers; keeps ``id + 1`` in range
Limit = Annotated[int, Query(ge=1, le=1000)]
After = Annotated[int, Query(ge=0, le=MAX_ID)]
MEDIA = {"tg3": "application/xml", "vtp": "application/xml"}
SKELETON_CONTENT: dict[str, dict[str, str]] = {"application/json": {}, "application/xml": {}}


@router.post(
    "/programs",
    status_code=201,
    response_model=LoadedOut,
    responses={
        200: {"model": LoadedOut, "description": "a dry run (nothing loaded)"},
        **AUTH_ERRORS,
        **BODY_ERRORS,
        409: {"model": Error},
        422: {"model": ProgramErrorOut | InvalidOut},
        429: {"model": Error},
    },
)
async def post_program(
    body: ProgramIn,
    ctx: Ctx,
    response: Response,
    request: Request,
    who: Operator,
    dry_run: Annotated[bool, Query(description="only check the program: load nothing")] = False,
) -> LoadedOut:
    """Parse, validate and dry-run a program, and (unless ``dry_run``) make it the one to run.

    The check runs off the event loop, one at a time (429 while another runs), and stops when
    the client goes away.
    """
    ctl = ctx.controller
    gate: Gate = request.app.state.gate
    caller = Caller("rest", who.name, who.token, who.role)
    cancel = threading.Event()
    try:
        if dry_run:
            checking = gate.check(caller, body.name, body.text, cancel)
            totals = await _until_gone(request, cancel, checking)
            pid = None
            response.status_code = 200
        else:
            pid = await _until_gone(
                request, cancel, gate.load(caller, body.name, body.text, cancel)
            )
            assert ctl.dry_run is not None
            totals = ctl.dry_run
    except Refused as exc:
        raise refused(exc) from None
    except ProgramError as exc:  # a refusal names its line and column (ProgramRefused too)
        raise _program_error(exc) from None
    except Busy as exc:
        raise ApiError(429, str(exc), headers={"Retry-After": "1"}) from None
    except ControllerError as exc:
        raise ApiError(409, str(exc)) from None
    return LoadedOut(id=pid, name=body.name, **asdict(totals))


async def _until_gone(request: Request, cancel: threading.Event, work: Awaitable[T]) -> T:
    """Await ``work``; if the client disconnects meanwhile, set ``cancel`` (the check stops)."""
    task = asyncio.ensure_future(work)
    while True:
        done, _ = await asyncio.wait({task}, timeout=0.25)
        if done:
            return task.result()
        if await request.is_disconnected():
            cancel.set()


def _program_error(exc: ProgramError) -> ApiError:
    return ApiError(422, exc.reason, line=exc.line, column=exc.column)


@router.get(
    "/programs",
    response_model=list[ProgramOut],
    dependencies=READ,
    responses={**AUTH_ERRORS, **INVALID},
)
async def get_programs(
    ctx: Ctx, limit: Limit = 50, before: Annotated[int | None, Query(ge=1, le=MAX_ID)] = None
) -> list[ProgramOut]:
    """Programs loaded, newest first; page with ``before`` (the last id seen)."""
    records = await ctx.controller.history(limit, before)
    return [ProgramOut(**asdict(r)) for r in records]


@router.get("/programs/totals", response_model=TotalsOut, dependencies=READ, responses=AUTH_ERRORS)
async def get_totals(ctx: Ctx) -> TotalsOut:
    """The journal's programs counted by outcome, with their run time."""
    found = await asyncio.to_thread(ctx.controller.journal.totals)
    outcomes = {k: OutcomeTotal(programs=n, run_s=s) for k, (n, s) in found.items()}
    return TotalsOut(
        outcomes=outcomes,
        programs=sum(n for n, _ in found.values()),
        run_s=sum(s for _, s in found.values()),
    )


@router.get("/log", response_model=LogOut, dependencies=READ, responses={**AUTH_ERRORS, **INVALID})
async def get_log(
    ctx: Ctx, after: Annotated[int, Query(ge=0, le=MAX_ID)] = 0, limit: Limit = 500
) -> LogOut:
    """The daemon's recent log lines (the last 500 kept), oldest first, numbered after
    ``after``; the same lines come as ``log`` events on the stream."""
    lines, last = ctx.console.lines(after, limit)
    return LogOut(lines=[LogLineOut(**asdict(line)) for line in lines], last=last)


@router.get(
    "/programs/{program_id}",
    response_model=ProgramDetailOut,
    dependencies=READ,
    responses={**AUTH_ERRORS, **INVALID, 404: {"model": Error}},
)
async def get_program(
    ctx: Ctx, program_id: Annotated[int, PathParam(ge=1, le=MAX_ID)]
) -> ProgramDetailOut:
    """One program's record and its text."""
    found = await ctx.controller.program_record(program_id)
    if found is None:
        raise ApiError(404, f"no program {program_id}")
    return ProgramDetailOut(**asdict(found[0]), text=found[1])


@router.post(
    "/programs/{program_id}/load",
    status_code=201,
    response_model=LoadedOut,
    responses={
        **AUTH_ERRORS,
        **INVALID,
        409: {"model": Error},
        422: {"model": ProgramErrorOut | InvalidOut},
    },
)
async def load_stored(
    ctx: Ctx,
    request: Request,
    who: Operator,
    program_id: Annotated[int, PathParam(ge=1, le=MAX_ID)],
) -> LoadedOut:
    """Load again a program the journal stores, by its id, as the PLC's ``LoadRequest``
    does; the load is stored under a new id, which the answer gives."""
    gate: Gate = request.app.state.gate
    caller = Caller("rest", who.name, who.token, who.role)
    try:
        pid = await gate.load_stored(caller, program_id)
    except Refused as exc:
        raise refused(exc) from None
    except ProgramError as exc:
        raise _program_error(exc) from None
    except ControllerError as exc:
        raise ApiError(409, str(exc)) from None
    ctl = ctx.controller
    assert ctl.dry_run is not None
    return LoadedOut(id=pid, name=ctl.status().program_name or "", **asdict(ctl.dry_run))


@router.get(
    "/history", response_model=HistoryOut, dependencies=READ, responses={**AUTH_ERRORS, **INVALID}
)
async def get_history(
    ctx: Ctx, after_state: After = 0, after_event: After = 0, limit: Limit = 100
) -> HistoryOut:
    """The journal's PackML state changes and events, oldest first, after the ids given."""
    states, events = await ctx.controller.records(after_state, after_event, limit)
    return HistoryOut(
        states=[StateRecordOut(**asdict(s)) for s in states],
        events=[EventRecordOut(**asdict(e)) for e in events],
    )


@router.get(
    "/skeleton",
    dependencies=READ,
    responses={**AUTH_ERRORS, **INVALID, 200: {"content": SKELETON_CONTENT}, 409: {"model": Error}},
)
async def get_skeleton(
    ctx: Ctx,
    fmt: Annotated[Literal["json", "tg3", "vtp"], Query(alias="format")] = "json",
    relaxed: Annotated[
        bool, Query(description="the relaxed preform (docs/relax.md), JSON")
    ] = False,
) -> Response:
    """The predicted skeleton: JSON (docs/skeleton-json.md), TexGen .tg3 or VTK .vtp; with
    ``relaxed``, the relaxed preform of the same instruction (JSON, computed off the control
    path in a worker process, kept per instruction)."""
    if relaxed:
        if fmt != "json":
            raise ApiError(409, "the relaxed preform is served as JSON only (format=json)")
        document = await ctx.relaxed.current()
        if document is None:
            raise ApiError(409, "no program is loaded")
        return Response(document, media_type="application/json")
    sk = await ctx.view.current()
    if sk is None:
        raise ApiError(409, "no program is loaded")
    if fmt == "json":
        body = await asyncio.to_thread(_json, sk)  # the size of the preform: not on the loop
        return Response(body, media_type="application/json")
    folder = Path(tempfile.mkdtemp(prefix="bwsd-skeleton-"))
    target = folder / f"skeleton.{fmt}"
    try:
        await asyncio.to_thread(export, sk, target)
    except ExportError as exc:
        shutil.rmtree(folder, ignore_errors=True)
        raise ApiError(409, f"the skeleton cannot be written as .{fmt}: {exc}") from None
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    return FileResponse(
        target,
        media_type=MEDIA[fmt],
        filename=target.name,
        background=BackgroundTask(_remove, folder),
    )


def _json(sk: SkeletonData) -> bytes:
    """The skeleton document, encoded yarn by yarn: the C encoder holds the interpreter lock
    for a whole call, so one call for the whole preform would stall the event loop."""
    document = skeleton_to_dict(sk)
    yarns = document.pop("yarns")
    head = json.dumps(document, separators=(",", ":"))
    parts = [json.dumps(yarn, separators=(",", ":")) for yarn in yarns]
    return (head[:-1] + ',"yarns":[' + ",".join(parts) + "]}").encode()


def _remove(folder: Path) -> None:
    shutil.rmtree(folder, ignore_errors=True)
