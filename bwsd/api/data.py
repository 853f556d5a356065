"""Routes of the records: programs (load, history), the skeleton, the journal's logs."""

from __future__ import annotations

import asyncio
import shutil
import tempfile
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Literal

from fastapi import Depends, Query
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, JSONResponse, Response
from starlette.background import BackgroundTask

from bwsd.controller.runner import ControllerError
from bwsd.errors import ProgramError, TwinError
from bwsd.export import ExportError, export
from bwsd.export.skeleton_json import skeleton_to_dict
from bwsd.program import parse_program_with_positions, validate
from bwsd.twin import Machine

from .auth import require
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
    ProgramDetailOut,
    ProgramErrorOut,
    ProgramIn,
    ProgramOut,
    StateRecordOut,
)
from .problems import ApiError
from .routing import RouteTable

router = RouteTable()
READ = [Depends(require("viewer"))]
WRITE = [Depends(require("operator"))]
MAX_ID = 2**62  # ids are SQLite integers; keeps ``id + 1`` in range
Limit = Annotated[int, Query(ge=1, le=1000)]
After = Annotated[int, Query(ge=0, le=MAX_ID)]
MEDIA = {"tg3": "application/xml", "vtp": "application/xml"}
SKELETON_CONTENT: dict[str, dict[str, str]] = {"application/json": {}, "application/xml": {}}


@router.post("/programs", status_code=201, response_model=LoadedOut, dependencies=WRITE,
             responses={200: {"model": LoadedOut, "description": "a dry run (nothing loaded)"},
                        **AUTH_ERRORS, **BODY_ERRORS, 409: {"model": Error},
                        422: {"model": ProgramErrorOut | InvalidOut}})  # fmt: skip
async def post_program(
    body: ProgramIn, ctx: Ctx, response: Response,
    dry_run: Annotated[bool, Query(description="only check the program: load nothing")] = False,
) -> LoadedOut:  # fmt: skip
    """Parse, validate and dry-run a program, and (unless ``dry_run``) make it the one to run."""
    ctl = ctx.controller
    try:
        if dry_run:
            _, totals = await ctl.check(body.name, body.text)
            pid = None
            response.status_code = 200
        else:
            pid = await ctl.load(body.name, body.text)
            ctx.remember(pid, body.name)
            assert ctl.dry_run is not None
            totals = ctl.dry_run
    except ProgramError as exc:
        raise _program_error(_located(exc, body, ctl.machine)) from None
    except ControllerError as exc:
        if isinstance(exc.__cause__, TwinError):
            raise _program_error(_refused_at(exc.__cause__, body)) from None
        raise ApiError(409, str(exc)) from None
    return LoadedOut(id=pid, name=body.name, **asdict(totals))


def _program_error(exc: ProgramError) -> ApiError:
    return ApiError(422, exc.reason, line=exc.line, column=exc.column)


def _located(exc: ProgramError, body: ProgramIn, machine: Machine) -> ProgramError:
    """The same error with its column, when only the line was known."""
    if exc.column or not exc.line:
        return exc
    try:
        program, positions = parse_program_with_positions(body.text, body.name)
        validate(program, machine, body.name, positions)
    except ProgramError as located:
        return located
    return exc


def _refused_at(exc: TwinError, body: ProgramIn) -> ProgramError:
    """A dry-run refusal as a program error at the refused instruction's keyword."""
    program, positions = parse_program_with_positions(body.text, body.name)
    i = exc.instruction - 1
    line = program.lines[i] if 0 <= i < len(program.lines) else 0
    column = positions.keywords[i] if 0 <= i < len(positions.keywords) else 0
    return ProgramError(str(exc), line=line, column=column, source=body.name)


@router.get("/programs", response_model=list[ProgramOut], dependencies=READ,
            responses={**AUTH_ERRORS, **INVALID})  # fmt: skip
async def get_programs(
    ctx: Ctx, limit: Limit = 50, before: Annotated[int | None, Query(ge=1, le=MAX_ID)] = None
) -> list[ProgramOut]:
    """Programs loaded, newest first; page with ``before`` (the last id seen)."""
    records = await asyncio.to_thread(ctx.controller.journal.history, limit, before)
    return [ProgramOut(**asdict(r)) for r in records]


@router.get("/programs/{program_id}", response_model=ProgramDetailOut, dependencies=READ,
            responses={**AUTH_ERRORS, **INVALID, 404: {"model": Error}})  # fmt: skip
async def get_program(
    ctx: Ctx, program_id: Annotated[int, PathParam(ge=1, le=MAX_ID)]
) -> ProgramDetailOut:
    """One program's record and its text."""
    journal = ctx.controller.journal
    found = await asyncio.to_thread(journal.history, 1, program_id + 1)
    if not found or found[0].id != program_id:
        raise ApiError(404, f"no program {program_id}")
    text = await asyncio.to_thread(journal.program_text, program_id)
    return ProgramDetailOut(**asdict(found[0]), text=text)


@router.get("/history", response_model=HistoryOut, dependencies=READ,
            responses={**AUTH_ERRORS, **INVALID})  # fmt: skip
async def get_history(
    ctx: Ctx, after_state: After = 0, after_event: After = 0, limit: Limit = 100
) -> HistoryOut:
    """The journal's PackML state changes and events, oldest first, after the ids given."""
    journal = ctx.controller.journal
    states = await asyncio.to_thread(journal.states, after_state, limit)
    events = await asyncio.to_thread(journal.events, after_event, limit)
    return HistoryOut(states=[StateRecordOut(**asdict(s)) for s in states],
                      events=[EventRecordOut(**asdict(e)) for e in events])  # fmt: skip


@router.get("/skeleton", dependencies=READ,
            responses={**AUTH_ERRORS, **INVALID, 200: {"content": SKELETON_CONTENT},
                       409: {"model": Error}})  # fmt: skip
async def get_skeleton(
    ctx: Ctx, fmt: Annotated[Literal["json", "tg3", "vtp"], Query(alias="format")] = "json"
) -> Response:
    """The predicted skeleton: JSON (docs/skeleton-json.md), TexGen .tg3 or VTK .vtp."""
    sk = await ctx.view.current()
    if sk is None:
        raise ApiError(409, "no program is loaded")
    if fmt == "json":
        return JSONResponse(skeleton_to_dict(sk))
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
    return FileResponse(target, media_type=MEDIA[fmt], filename=target.name,
                        background=BackgroundTask(_remove, folder))  # fmt: skip


def _remove(folder: Path) -> None:
    shutil.rmtree(folder, ignore_errors=True)
