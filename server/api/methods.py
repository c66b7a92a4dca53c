"""405 with the API's own `Allow` for a wrong method on an API path, JSON 404 for no path.

Starlette's router takes the first route that matches fully, and the editor's static mount
at "/" matches every path: without this, `DELETE /api/runs` reached the mount and got its
405 with `Allow: GET, HEAD`, and `GET /api/nothing` its plain-text 404. The paths and
methods come from the OpenAPI document itself, so `Allow` always says what it says.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

from starlette.types import ASGIApp, Receive, Scope, Send

from server.asgi import send_error

API_PREFIX = "/api/"
_HTTP_METHODS = {"get", "put", "post", "delete", "patch", "options", "head", "trace"}


def operations(schema: dict[str, Any]) -> list[tuple[re.Pattern[str], frozenset[str]]]:
    """Each API path of an OpenAPI document as a regex, with its methods (upper-case)."""
    out = []
    for path, item in schema.get("paths", {}).items():
        if not path.startswith(API_PREFIX):
            continue
        pattern = re.sub(r"\\{[^/]+?\\}", "[^/]+", re.escape(path))
        methods = frozenset(m.upper() for m in item if m in _HTTP_METHODS)
        out.append((re.compile(pattern + "$"), methods))
    return out


class ApiMethods:
    """Answers for the API's paths what the static mount would answer wrongly."""

    def __init__(self, app: ASGIApp, schema: Callable[[], dict[str, Any]]) -> None:
        self.app = app
        self.schema = schema
        self._operations: list[tuple[re.Pattern[str], frozenset[str]]] | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass through when an API operation takes the request."""
        if scope["type"] != "http" or not scope["path"].startswith(API_PREFIX):
            await self.app(scope, receive, send)
            return
        if self._operations is None:
            self._operations = operations(self.schema())
        method = scope["method"]
        allowed: set[str] = set()
        for pattern, methods in self._operations:
            if pattern.match(scope["path"]):
                if method in methods:
                    await self.app(scope, receive, send)
                    return
                allowed |= methods
        if method == "OPTIONS" and _preflight(scope):
            await self.app(scope, receive, send)  # CORS answers it
            return
        if allowed:
            allow = ", ".join(sorted(allowed))
            detail = f"{scope['method']} is not an operation of {scope['path']}: use {allow}"
            await send_error(send, 405, detail, [(b"allow", allow.encode())])
        else:
            await send_error(send, 404, f"no API path {scope['path']} (see /openapi.json)")


def _preflight(scope: Scope) -> bool:
    names = {k for k, _ in scope["headers"]}
    return b"origin" in names and b"access-control-request-method" in names
