"""Every error the API answers is JSON: ``{"error": "<what is wrong>", ...details}``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Receive, Scope, Send

from bwsd.errors import BwsdError
from bwsd.fieldbus import FieldbusError
from bwsd.gate import Refused
from bwsd.journal import JournalError


class ApiError(HTTPException):
    """An HTTP error with a message and extra fields for the JSON body."""

    def __init__(
        self, status: int, message: str, *, headers: dict[str, str] | None = None, **extra: Any
    ) -> None:
        super().__init__(status, message, headers)
        self.extra = extra


def error_body(message: str, **extra: Any) -> dict[str, Any]:
    return {"error": message, **extra}


async def _http_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, HTTPException)
    extra = exc.extra if isinstance(exc, ApiError) else {}
    return JSONResponse(
        error_body(str(exc.detail), **extra), status_code=exc.status_code, headers=exc.headers
    )


def _where(loc: Any) -> str:
    return ".".join(str(part) for part in loc) if isinstance(loc, list | tuple) else str(loc)


Gate = Callable[[Request], HTTPException | None]
"""Says whether a request's token is refused (checked before its body is judged)."""


def _invalid_request(gate: Gate) -> Callable[[Request, Exception], Any]:
    async def handler(request: Request, exc: Exception) -> JSONResponse:
        """422 naming the first bad field (400 for a body that is not JSON), unless the token
        is refused (then 401/403)."""
        assert isinstance(exc, RequestValidationError)
        refused = gate(request)
        if refused is not None:
            return await _http_error(request, refused)
        errors = [_short(e) for e in exc.errors()]
        first = errors[0] if errors else {}
        if first.get("type") == "json_invalid":  # not a malformed request: no JSON at all
            at = first.get("loc", ())[-1]
            return JSONResponse(
                error_body(f"the body is not valid JSON (at character {at})"), status_code=400
            )
        where = _where(first.get("loc", ()))
        message = f"invalid request: {where}: {first.get('msg', 'invalid')}"
        return JSONResponse(error_body(message, details=jsonable_encoder(errors)), status_code=422)

    return handler


EXCERPT = 80  # characters of a refused input quoted back


def _short(error: Any) -> dict[str, Any]:
    """A validation error with at most an excerpt of the input it quotes (never the whole
    body back), and no lone surrogate (which no JSON encoder can write as UTF-8)."""
    out = dict(error)
    if "input" in out:
        text = repr(out["input"])
        text = text if len(text) <= EXCERPT else f"{text[:EXCERPT]}... ({len(text)} characters)"
        out["input"] = text.encode("utf-8", "backslashreplace").decode("utf-8")
    out.pop("ctx", None)
    return out


def refused(exc: Refused) -> ApiError:
    """The gate's refusal as HTTP: a token no longer known 401, a role too low 403, a value
    of the wrong type or out of range 422 naming the field."""
    if exc.kind == "who":
        return ApiError(401, str(exc), headers={"WWW-Authenticate": "Bearer"})
    if exc.kind == "role":
        return ApiError(403, str(exc))
    details = [
        {"loc": ["body", exc.field] if exc.field else ["body"], "msg": str(exc), "type": exc.kind}
    ]
    return ApiError(422, f"invalid request: {exc}", details=details)


def describe(exc: Exception) -> str:
    """The message for a client: a journal error without the journal's path on the server."""
    if isinstance(exc, JournalError):
        return f"the journal refused: {exc.reason}"
    return str(exc)


async def _bwsd_error(request: Request, exc: Exception) -> JSONResponse:
    """A fault the request ran into that no route mapped: the bus or journal (503), else 409."""
    status = 503 if isinstance(exc, FieldbusError | JournalError) else 409
    return JSONResponse(error_body(describe(exc)), status_code=status)


def install(app: FastAPI, gate: Gate) -> None:
    """Make every error answer JSON; ``gate`` puts a refused token before a malformed body."""
    app.add_exception_handler(HTTPException, _http_error)
    app.add_exception_handler(RequestValidationError, _invalid_request(gate))
    app.add_exception_handler(BwsdError, _bwsd_error)


class BodyLimit:
    """ASGI middleware: a request whose Content-Length passes ``limit`` gets a JSON 413.

    (A chunked body is cut at the same size by FastAPI's own limit.)
    """

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and self._length(scope) > self.limit:
            message = f"the request body is too large (limit: {self.limit} bytes)"
            await JSONResponse(error_body(message), status_code=413)(scope, receive, send)
            return
        await self.app(scope, receive, send)

    @staticmethod
    def _length(scope: Scope) -> int:
        for name, value in scope.get("headers", []):
            if name == b"content-length":
                return int(value) if value.isdigit() else 0
        return 0
