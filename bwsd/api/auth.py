"""The API's side of the bearer tokens (bwsd.tokens): FastAPI dependencies that check a
request's token and role, and the 401/403 they answer."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from bwsd.api.problems import ApiError
from bwsd.logs import Summary
from bwsd.tokens import (
    RANK,
    ROLES,
    Role,
    TokenEntry,
    TokenError,
    TokenStore,
    check_role,
    digest,
)

__all__ = [
    "LOGINS",
    "RANK",
    "ROLES",
    "Auth",
    "Principal",
    "Role",
    "TokenEntry",
    "TokenError",
    "TokenStore",
    "check_role",
    "digest",
    "require",
]

log = logging.getLogger("bwsd.api")
# Every refused login of the REST API and its event stream, whatever the method: one line,
# then at most one a minute (a client can repeat them at will).
LOGINS = Summary(log, "refused logins")


def note_refusal(client: str, exc: ApiError) -> None:
    """Log a refused request (401 or 403) from ``client``, rate-limited."""
    LOGINS.note("refused a request from %s: %s", client, exc.detail)


def client_of(request: Request) -> str:
    return request.client.host if request.client else "an unknown client"


@dataclass(frozen=True)
class Principal:
    """Who made a request: the token's name (``anonymous`` for an open read) and role, and
    the token itself (checked again by the gate at a command: it may have been removed)."""

    name: str
    role: Role
    token: str | None = None


# ----- FastAPI -----
BEARER = HTTPBearer(
    auto_error=False,
    description="A token made with `bwsd token add NAME --role ROLE`.",
)


@dataclass
class Auth:
    """The token store and whether reads are open to anyone."""

    tokens: TokenStore
    open_reads: bool

    def authorize(self, token: str | None, role: Role) -> Principal:
        """The holder of ``token`` if its role is ``role`` or above; ApiError 401/403 if not."""
        if not token:
            if role == "viewer" and self.open_reads:
                return Principal("anonymous", "viewer")
            raise unauthorized("a bearer token is needed (Authorization: Bearer TOKEN)")
        holder = self.tokens.check(token)
        if holder is None:
            raise unauthorized("the bearer token is not known")
        name, held = holder
        if RANK[held] < RANK[role]:
            raise ApiError(
                403,
                f"token {name!r} has role {held}; this needs {role} or above",
                role=held,
                needs=role,
            )
        return Principal(name, held, token)


def unauthorized(message: str) -> ApiError:
    return ApiError(401, message, headers={"WWW-Authenticate": "Bearer"})


Credentials = Annotated[HTTPAuthorizationCredentials | None, Depends(BEARER)]


class Require:
    """A FastAPI dependency: the request's token must hold ``role`` or above."""

    def __init__(self, role: Role) -> None:
        self.role = role

    async def __call__(self, request: Request, credentials: Credentials) -> Principal:
        return authorize_request(request, credentials, self.role)


def authorize_request(
    request: Request, credentials: HTTPAuthorizationCredentials | None, role: Role
) -> Principal:
    auth: Auth = request.app.state.auth
    try:
        return auth.authorize(credentials.credentials if credentials else None, role)
    except ApiError as exc:
        note_refusal(client_of(request), exc)
        raise


def require(role: Role) -> Require:
    """The dependency for a route needing ``role`` (``viewer``: a read, open if configured)."""
    return Require(role)


def refused_token(request: Request) -> ApiError | None:
    """The 401/403 the route's own token check would give, or None: for a malformed request.

    FastAPI judges a body before the dependencies run; this keeps "who are you" first.
    """
    auth: Auth = request.app.state.auth
    dependant = getattr(request.scope.get("route"), "dependant", None)
    exc = refusal(auth, dependant, request.headers.get("authorization", ""))
    if exc is not None:
        note_refusal(client_of(request), exc)
    return exc


def refusal(auth: Auth, dependant: Any, header: str) -> ApiError | None:
    """The 401/403 that a route's ``Require`` dependencies give for this Authorization header."""
    checks = [d.call for d in dependant.dependencies] if dependant is not None else []
    scheme, _, token = header.partition(" ")
    clear = token.strip() if scheme.lower() == "bearer" else None
    for check in checks:
        if isinstance(check, Require):
            try:
                auth.authorize(clear, check.role)
            except ApiError as exc:
                return exc
    return None
