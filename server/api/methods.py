"""405 with the API's own `Allow` for a wrong method on an API path, JSON 404 for no path.

Starlette's router takes the first route that matches fully, and the editor's static mount
at "/" matches every path: without this, `DELETE /api/runs` reached the mount and got its
405 with `Allow: GET, HEAD`, and `GET /api/nothing` its plain-text 404. The paths and
methods are the routes the OpenAPI document is made of (its API routes in the schema), so
`Allow` says what the document says (tests/server/api/test_api_methods.py compares them),
read from the routes themselves: building the document costs about 1.5 s of CPU, which
every service paid on its first API request when this read it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from fastapi import routing
from starlette.routing import BaseRoute
from starlette.types import ASGIApp, Receive, Scope, Send

from server.api.asgi import send_error

API_PREFIX = "/api/"
_HTTP_METHODS = {"get", "put", "post", "delete", "patch", "options", "head", "trace"}
Operations = list[tuple[re.Pattern[str], frozenset[str]]]
"""Each API path as a regex, with its methods (upper-case); paths without parameters first.

OpenAPI matches a concrete path before a templated one (`/api/networks/import` before
`/api/networks/{name}`), and so does `ApiMethods`: the first path that matches decides.
"""


def _compiled(paths: Iterable[tuple[str, Iterable[str]]]) -> Operations:
    methods_of: dict[str, set[str]] = {}
    for path, methods in paths:
        if path.startswith(API_PREFIX):
            methods_of.setdefault(path, set()).update(m.upper() for m in methods)
    out = []
    for path, methods in sorted(methods_of.items(), key=lambda item: "{" in item[0]):
        pattern = re.sub(r"\\{[^/]+?\\}", "[^/]+", re.escape(path))
        out.append((re.compile(pattern + "$"), frozenset(methods)))
    return out


def operations(schema: dict[str, Any]) -> Operations:
    """The API paths of an OpenAPI document, with their methods."""
    return _compiled(
        (path, [m for m in item if m in _HTTP_METHODS])
        for path, item in schema.get("paths", {}).items()
    )


def route_operations(routes: Sequence[BaseRoute]) -> Operations:
    """The API paths of the routes FastAPI puts in its OpenAPI document, with their methods."""
    return _compiled(
        (context.path_format, context.methods or ())
        for context in routing.iter_route_contexts(routes)
        if isinstance(context.original_route, routing.APIRoute)
        and context.include_in_schema
        and context.path_format is not None
    )


class ApiMethods:
    """Answers for the API's paths what the static mount would answer wrongly."""

    def __init__(self, app: ASGIApp, routes: Callable[[], Sequence[BaseRoute]]) -> None:
        self.app = app
        self.routes = routes
        self._operations: Operations | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass through when an API operation takes the request."""
        if scope["type"] != "http" or not scope["path"].startswith(API_PREFIX):
            await self.app(scope, receive, send)
            return
        if self._operations is None:
            self._operations = route_operations(self.routes())
        method = scope["method"]
        allowed: set[str] = set()
        for pattern, methods in self._operations:
            if pattern.match(scope["path"]):
                if method in methods:
                    await self.app(scope, receive, send)
                    return
                allowed = set(methods)
                break
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
