"""The HTTP API: REST under /api/v1, the event WebSocket, bearer tokens, /metrics (docs/api.md)."""

from bwsd.api.app import PREFIX, create_app, server
from bwsd.api.auth import ROLES, Role, TokenError, TokenStore

__all__ = ["PREFIX", "ROLES", "Role", "TokenError", "TokenStore", "create_app", "server"]
