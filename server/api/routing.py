"""How the API's routers are made and put into an app.

Every resource's router carries the whole of what its routes need (the `/api` prefix, the
shared error answers, the short operation ids), so its routes are complete when a module
is imported and are put into each app as they are. FastAPI 0.165's `include_router` would
build every included route a second time, for each app, on the app's first request: about
0.2-0.3 s of CPU that each `srlab serve` and each API test's app paid.
"""

from __future__ import annotations

from collections.abc import Iterable

from fastapi import APIRouter, FastAPI

from server.api.access import Authorise
from server.api.contract import operation_id
from server.api.errors import ERRORS

PREFIX = "/api"


def resource_router(prefix: str = "", *, tag: str) -> APIRouter:
    """A resource's router: its routes under `/api{prefix}`, tagged `tag`."""
    return APIRouter(
        prefix=PREFIX + prefix,
        tags=[tag],
        responses=ERRORS,
        generate_unique_id_function=operation_id,
        # Who may call it: a participant's token only their run (`server.api.access`).
        dependencies=[Authorise],
    )


def add_routes(app: FastAPI, routers: Iterable[APIRouter]) -> None:
    """Put the routers' routes into `app`, in order, before it serves a request.

    The route objects are shared between apps: they hold no app state (a handler reaches
    its app through the request), as they did when included.
    """
    app.router.routes.extend(route for router in routers for route in router.routes)
