"""Routes declared in the modules and added to the app itself, so ``app.routes`` lists each."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from fastapi import FastAPI

Endpoint = Callable[..., Any]
Register = Callable[[Endpoint], Endpoint]


@dataclass
class RouteTable:
    """Collects ``@table.get(path, ...)``, ``.post`` and ``.put`` for ``install``."""

    routes: list[tuple[str, str, Endpoint, dict[str, Any]]] = field(default_factory=list)

    def get(self, path: str, **options: Any) -> Register:
        return self._add("GET", path, options)

    def post(self, path: str, **options: Any) -> Register:
        return self._add("POST", path, options)

    def put(self, path: str, **options: Any) -> Register:
        return self._add("PUT", path, options)

    def _add(self, method: str, path: str, options: dict[str, Any]) -> Register:
        def register(endpoint: Endpoint) -> Endpoint:
            self.routes.append((method, path, endpoint, options))
            return endpoint

        return register

    def install(self, app: FastAPI, prefix: str, tags: list[str], max_body: int) -> None:
        """Add every route under ``prefix``; a body of more than ``max_body`` bytes is a 413."""
        for method, path, endpoint, options in self.routes:
            app.add_api_route(
                prefix + path,
                endpoint,
                methods=[method],
                tags=list(tags),
                max_body_size=max_body,
                **options,
            )
